//! Walker2d-v5: a two-legged planar walker rewarded for walking forward without falling.
//!
//! | | |
//! |---|---|
//! | model | `walker2d_v5.xml` (v5's model: both feet have friction 0.9) |
//! | action | 6 joint torques in [-1, 1] |
//! | observation | 17 = `qpos[1:]` (8) + clip(qvel, -10, 10) (9) |
//! | reward | forward = dx/dt; survive = 1 while healthy; ctrl = -1e-3 * ‖a‖² |
//! | termination | unhealthy: z ∉ (0.8, 2.0) or angle ∉ (-1, 1) |
//! | reset | qpos0 + U(-5e-3, 5e-3), qvel0 + U(-5e-3, 5e-3) |
use super::{EnvSpec, Forward, Health, ResetNoise};

pub const SPEC: EnvSpec = EnvSpec {
    name: "Walker2d-v5",
    xml_file: "walker2d_v5.xml",
    frame_skip: 4,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 1e-3,
    health: Some(Health::Planar { reward: 1.0, z_range: (0.8, 2.0), angle_range: (-1.0, 1.0), state_range: None }),
    obs_qvel_clip: Some(10.0),
    obs_skip_qpos: 1,
    forward: Forward::Qpos0,
    contact: None,
    reset_noise: ResetNoise::Uniform(5e-3),
    max_episode_steps: 1000,
};
