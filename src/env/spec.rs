//! What distinguishes one locomotion task from another: each task's file is one [`EnvSpec`].

/// The health conditions of the legged robots; outside them the episode terminates. Each
/// variant pays `reward` per step while healthy (v5 pays nothing once unhealthy).
#[derive(Debug, Clone, Copy)]
pub enum Health {
    /// The planar walkers (Hopper, Walker2d): open intervals for the torso height `qpos[1]`,
    /// the torso angle `qpos[2]` and, where the task checks it, every element of
    /// `state_vector()[2:]`.
    Planar { reward: f64, z_range: (f64, f64), angle_range: (f64, f64), state_range: Option<(f64, f64)> },
    /// Ant: every qpos and qvel finite and the torso height `qpos[2]` in a closed interval.
    Upright { reward: f64, z_range: (f64, f64) },
}

impl Health {
    pub fn reward(&self) -> f64 {
        match *self {
            Health::Planar { reward, .. } | Health::Upright { reward, .. } => reward,
        }
    }
}

/// Where the forward velocity dx/dt is measured.
#[derive(Debug, Clone, Copy)]
pub enum Forward {
    /// The root slide joint, `qpos[0]` (the planar robots).
    Qpos0,
    /// The Cartesian position of a body (`data.xpos`, which `mj_step` leaves at the last
    /// substep's kinematics, as Gymnasium reads it): Ant's `main_body`.
    BodyXpos(usize),
}

/// External contact forces on the bodies (`cfrc_ext`, after `mj_rnePostConstraint`), each
/// clipped to `force_range`: costed (all bodies) and, where `observed`, observed (all bodies
/// but the world; Gymnasium's `include_cfrc_ext_in_observation`).
#[derive(Debug, Clone, Copy)]
pub struct Contact {
    pub cost_weight: f64,
    pub force_range: (f64, f64),
    pub observed: bool,
}

/// How `reset` perturbs the initial state `qpos0`, `qvel = 0`.
#[derive(Debug, Clone, Copy)]
pub enum ResetNoise {
    /// qpos + U(-s, s) and qvel + U(-s, s).
    Uniform(f64),
    /// qpos + U(-s, s) and qvel + s * N(0, 1).
    UniformGaussian(f64),
}

/// Everything that distinguishes one locomotion task from another.
#[derive(Debug, Clone, Copy)]
pub struct EnvSpec {
    pub name: &'static str,
    pub xml_file: &'static str,
    pub frame_skip: usize,
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    pub health: Option<Health>,
    /// Velocities in the observation are clipped to +-this, where set.
    pub obs_qvel_clip: Option<f64>,
    /// Leading qpos entries left out of the observation (x; Ant's y too).
    pub obs_skip_qpos: usize,
    pub forward: Forward,
    pub contact: Option<Contact>,
    pub reset_noise: ResetNoise,
    pub max_episode_steps: usize,
}

impl EnvSpec {
    /// The contact forces, where the observation holds them.
    pub fn observed_contact(&self) -> Option<Contact> {
        self.contact.filter(|c| c.observed)
    }
}
