//! HalfCheetah-v5: a planar cheetah of 9 links rewarded for running forward.
//!
//! | | |
//! |---|---|
//! | model | `half_cheetah.xml` (timestep 0.01) |
//! | action | 6 joint torques in [-1, 1] (bthigh, bshin, bfoot, fthigh, fshin, ffoot) |
//! | observation | 17 = `qpos[1:]` (rootz, rooty, 6 joint angles) + qvel (9), unclipped |
//! | reward | forward = dx/dt; ctrl = -0.1 * ‖a‖²; no survival term |
//! | termination | never; truncation after 1000 steps |
//! | reset | qpos0 + U(-0.1, 0.1), qvel0 + 0.1 * N(0, 1) |
use super::{EnvSpec, Forward, ResetNoise};

pub const SPEC: EnvSpec = EnvSpec {
    name: "HalfCheetah-v5",
    xml_file: "half_cheetah.xml",
    frame_skip: 5,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 0.1,
    health: None,
    obs_qvel_clip: None,
    obs_skip_qpos: 1,
    forward: Forward::Qpos0,
    contact: None,
    reset_noise: ResetNoise::UniformGaussian(0.1),
    max_episode_steps: 1000,
};
