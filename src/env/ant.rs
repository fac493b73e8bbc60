//! Ant-v5: a quadruped rewarded for walking forward (+x) without flipping over.
//!
//! | | |
//! |---|---|
//! | model | `ant.xml` (timestep 0.01) |
//! | action | 8 hip and ankle torques in [-1, 1] |
//! | observation | 105 = `qpos[2:]` (torso z, orientation quaternion, 8 joint angles: 13) + qvel (14) + clip(`cfrc_ext[1:]`, -1, 1) (13 bodies x 6: 78) |
//! | reward | forward = dx/dt of the torso body (`xpos`); survive = 1 while healthy; ctrl = -0.5 * ‖a‖²; contact = -5e-4 * ‖clip(cfrc_ext, -1, 1)‖² |
//! | termination | unhealthy: any qpos or qvel not finite, or torso z ∉ [0.2, 1.0] |
//! | reset | qpos0 + U(-0.1, 0.1), qvel0 + 0.1 * N(0, 1) |
//!
//! Gymnasium's defaults throughout (`use_contact_forces` is gone in v5: the contact cost is
//! always paid and, by default, the contact forces observed).
//!
//! `Ant-v5-no-cfrc` is `gym.make("Ant-v5", include_cfrc_ext_in_observation=False)`: the same
//! task (the contact cost still paid) observing its 27 positions and velocities only. PPO
//! learns it far faster: at 1M steps idrex's PPO walks there (returns 1740 and 2585 over 20
//! episodes, seeds 0 and 1) where on `Ant-v5` it runs and falls (584 and 480;
//! `analysis/results/ant/`).
use super::{Contact, EnvSpec, Forward, Health, ResetNoise};

const CONTACT: Contact = Contact { cost_weight: 5e-4, force_range: (-1.0, 1.0), observed: true };

pub const SPEC: EnvSpec = EnvSpec {
    name: "Ant-v5",
    xml_file: "ant.xml",
    frame_skip: 5,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 0.5,
    health: Some(Health::Upright { reward: 1.0, z_range: (0.2, 1.0) }),
    obs_qvel_clip: None,
    obs_skip_qpos: 2,
    forward: Forward::BodyXpos(1),
    contact: Some(CONTACT),
    reset_noise: ResetNoise::UniformGaussian(0.1),
    max_episode_steps: 1000,
};

/// Ant-v5 with `include_cfrc_ext_in_observation=False`.
pub const SPEC_NO_CFRC: EnvSpec = EnvSpec { name: "Ant-v5-no-cfrc", contact: Some(Contact { observed: false, ..CONTACT }), ..SPEC };
