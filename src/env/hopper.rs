//! Hopper-v5: a one-legged planar robot rewarded for hopping forward without falling.
//!
//! | | |
//! |---|---|
//! | model | `hopper.xml` (timestep 0.002) |
//! | action | 3 joint torques in [-1, 1] (thigh, leg, foot) |
//! | observation | 11 = `qpos[1:]` (rootz, rooty, 3 joint angles) + clip(qvel, -10, 10) (6) |
//! | reward | forward = dx/dt; survive = 1 while healthy; ctrl = -1e-3 * ‖a‖² |
//! | termination | unhealthy: z ∉ (0.7, ∞), angle ∉ (-0.2, 0.2), or any of `state_vector()[2:]` ∉ (-100, 100) |
//! | reset | qpos0 + U(-5e-3, 5e-3), qvel0 + U(-5e-3, 5e-3) |
use super::{EnvSpec, Forward, Health, ResetNoise};

pub const SPEC: EnvSpec = EnvSpec {
    name: "Hopper-v5",
    xml_file: "hopper.xml",
    frame_skip: 4,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 1e-3,
    health: Some(Health::Planar {
        reward: 1.0,
        z_range: (0.7, f64::INFINITY),
        angle_range: (-0.2, 0.2),
        state_range: Some((-100.0, 100.0)),
    }),
    obs_qvel_clip: Some(10.0),
    obs_skip_qpos: 1,
    forward: Forward::Qpos0,
    contact: None,
    reset_noise: ResetNoise::Uniform(5e-3),
    max_episode_steps: 1000,
};
