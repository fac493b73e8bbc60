//! Gymnasium-v5 MuJoCo locomotion environments on mujoco-rs.
//!
//! One generic [`Env`] runs every task; each task is a [`EnvSpec`] in its own file
//! ([`half_cheetah`], [`hopper`], [`walker2d`]) whose numbers are Gymnasium's v5 defaults.
//! Equivalence with Gymnasium (observations, each reward term, termination, truncation) is
//! checked by `tests/env_equivalence.rs`, which replays the same actions in both.
//!
//! Departures, none of which change a transition: Gymnasium calls `mj_rnePostConstraint`
//! after stepping, which only fills force outputs (`cacc`, `cfrc_*`) that no observation or
//! reward of these tasks reads, so we skip it; our reset noise comes from a seeded ChaCha8
//! generator, not numpy's, so seeds are reproducible here but not shared with Gymnasium.
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mujoco_rs::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::error::{Error, Result};

pub mod half_cheetah;
pub mod hopper;
pub mod replay;
pub mod vec_env;
pub mod walker2d;

pub use vec_env::{VecEnv, VecStep};

/// The environments idrex knows, by their Gymnasium ids.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub enum EnvId {
    #[serde(rename = "HalfCheetah-v5")]
    HalfCheetah,
    #[serde(rename = "Hopper-v5")]
    Hopper,
    #[serde(rename = "Walker2d-v5")]
    Walker2d,
}

impl EnvId {
    pub const ALL: [EnvId; 3] = [EnvId::HalfCheetah, EnvId::Hopper, EnvId::Walker2d];

    pub fn name(self) -> &'static str {
        self.spec().name
    }

    pub fn spec(self) -> &'static EnvSpec {
        match self {
            EnvId::HalfCheetah => &half_cheetah::SPEC,
            EnvId::Hopper => &hopper::SPEC,
            EnvId::Walker2d => &walker2d::SPEC,
        }
    }
}

impl std::fmt::Display for EnvId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for EnvId {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        EnvId::ALL
            .into_iter()
            .find(|id| id.name() == s)
            .ok_or_else(|| Error::UnknownEnv { name: s.to_string(), known: EnvId::ALL.map(|id| id.name()).join(", ") })
    }
}

/// The health conditions of the legged robots; outside them the episode terminates.
#[derive(Debug, Clone, Copy)]
pub struct Health {
    /// Paid per step while healthy (v5 pays nothing once unhealthy).
    pub reward: f64,
    /// Open interval for the torso height qpos[1].
    pub z_range: (f64, f64),
    /// Open interval for the torso angle qpos[2].
    pub angle_range: (f64, f64),
    /// Open interval for every element of state_vector()[2:], where the task checks it.
    pub state_range: Option<(f64, f64)>,
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
    pub reset_noise: ResetNoise,
    pub max_episode_steps: usize,
}

/// Each term of the reward as Gymnasium's `info` reports it; `reward = forward + ctrl + survive`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct RewardTerms {
    pub reward_forward: f64,
    /// Minus the control cost.
    pub reward_ctrl: f64,
    pub reward_survive: f64,
}

impl RewardTerms {
    pub fn total(&self) -> f64 {
        self.reward_forward + self.reward_ctrl + self.reward_survive
    }
}

/// What one step reports besides the observation.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StepInfo {
    pub reward: f64,
    pub terminated: bool,
    pub truncated: bool,
    pub terms: RewardTerms,
    pub x_position: f64,
    pub x_velocity: f64,
}

/// Where the MuJoCo model files are: `IDREX_MUJOCO_ASSETS` if set, else gymnasium's assets
/// directory from the bootstrap environment this binary was built against.
pub fn assets_dir() -> Result<PathBuf> {
    if let Some(dir) = std::env::var_os("IDREX_MUJOCO_ASSETS") {
        return Ok(PathBuf::from(dir));
    }
    let built = env!("IDREX_BUILD_ASSETS");
    if built.is_empty() {
        return Err(Error::Invalid(
            "no MuJoCo model directory: set IDREX_MUJOCO_ASSETS to gymnasium's envs/mujoco/assets \
             directory, or build after scripts/bootstrap.sh"
                .into(),
        ));
    }
    Ok(PathBuf::from(built))
}

/// Loads a task's model from `dir` (or [`assets_dir`]).
pub fn load_model(id: EnvId, dir: Option<&Path>) -> Result<Arc<MjModel>> {
    let dir = match dir {
        Some(d) => d.to_path_buf(),
        None => assets_dir()?,
    };
    let path = dir.join(id.spec().xml_file);
    if !path.is_file() {
        return Err(Error::Model {
            path,
            reason: "no such file; point IDREX_MUJOCO_ASSETS at gymnasium's envs/mujoco/assets \
                     directory (scripts/bootstrap.sh installs it)"
                .into(),
        });
    }
    let model = MjModel::from_xml(&path).map_err(|e| Error::Model { path, reason: e.to_string() })?;
    Ok(Arc::new(model))
}

/// One locomotion environment with Gymnasium's `TimeLimit` built in.
pub struct Env {
    spec: &'static EnvSpec,
    data: MjData<Arc<MjModel>>,
    init_qpos: Vec<f64>,
    init_qvel: Vec<f64>,
    action_low: Vec<f64>,
    action_high: Vec<f64>,
    dt: f64,
    elapsed: usize,
    rng: ChaCha8Rng,
}

impl Env {
    /// Loads the model from the default assets and returns an environment seeded with 0.
    pub fn new(id: EnvId) -> Result<Self> {
        Ok(Self::with_model(id, load_model(id, None)?))
    }

    /// Builds an environment on an already loaded model (vectorised envs share one).
    pub fn with_model(id: EnvId, model: Arc<MjModel>) -> Self {
        let spec = id.spec();
        let (nu, timestep) = (model.ffi().nu as usize, model.ffi().opt.timestep);
        // SAFETY: actuator_ctrlrange holds nu x 2 numbers for the model's lifetime.
        let range = unsafe { std::slice::from_raw_parts(model.ffi().actuator_ctrlrange, 2 * nu) };
        let action_low = range.iter().step_by(2).copied().collect();
        let action_high = range.iter().skip(1).step_by(2).copied().collect();
        let data = MjData::new(model);
        let init_qpos = data.qpos().to_vec();
        let init_qvel = data.qvel().to_vec();
        Env {
            spec,
            data,
            init_qpos,
            init_qvel,
            action_low,
            action_high,
            dt: timestep * spec.frame_skip as f64,
            elapsed: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
        }
    }

    pub fn spec(&self) -> &'static EnvSpec {
        self.spec
    }
    pub fn nq(&self) -> usize {
        self.init_qpos.len()
    }
    pub fn nv(&self) -> usize {
        self.init_qvel.len()
    }
    pub fn act_dim(&self) -> usize {
        self.action_low.len()
    }
    /// qpos[1:] and qvel: the x position is never observed.
    pub fn obs_dim(&self) -> usize {
        self.nq() - 1 + self.nv()
    }
    pub fn action_bounds(&self) -> (&[f64], &[f64]) {
        (&self.action_low, &self.action_high)
    }
    /// Simulated seconds per step (timestep x frame_skip).
    pub fn dt(&self) -> f64 {
        self.dt
    }
    pub fn qpos(&self) -> &[f64] {
        self.data.qpos()
    }
    pub fn qvel(&self) -> &[f64] {
        self.data.qvel()
    }
    pub fn elapsed_steps(&self) -> usize {
        self.elapsed
    }

    /// Resets to `qpos0`/`qvel0` plus the task's noise. A seed restarts the generator;
    /// without one the generator continues, as Gymnasium's does.
    pub fn reset(&mut self, seed: Option<u64>, obs: &mut [f64]) {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        self.data.reset();
        let mut qpos = self.init_qpos.clone();
        let mut qvel = self.init_qvel.clone();
        let (ResetNoise::Uniform(s) | ResetNoise::UniformGaussian(s)) = self.spec.reset_noise;
        for q in &mut qpos {
            *q += self.rng.random_range(-s..s);
        }
        for v in &mut qvel {
            *v += match self.spec.reset_noise {
                ResetNoise::Uniform(_) => self.rng.random_range(-s..s),
                ResetNoise::UniformGaussian(_) => s * self.rng.sample::<f64, _>(StandardNormal),
            };
        }
        self.write_state(&qpos, &qvel);
        self.elapsed = 0;
        self.observe(obs);
    }

    /// Puts the simulator in a given state (Gymnasium's `set_state`) and restarts the time limit.
    pub fn set_state(&mut self, qpos: &[f64], qvel: &[f64], obs: &mut [f64]) -> Result<()> {
        shape("qpos", self.nq(), qpos.len(), " (the model's nq)")?;
        shape("qvel", self.nv(), qvel.len(), " (the model's nv)")?;
        self.data.reset();
        self.write_state(qpos, qvel);
        self.elapsed = 0;
        self.observe(obs);
        Ok(())
    }

    fn write_state(&mut self, qpos: &[f64], qvel: &[f64]) {
        self.data.qpos_mut().copy_from_slice(qpos);
        self.data.qvel_mut().copy_from_slice(qvel);
        self.data.forward();
    }

    /// Writes the observation of the current state into `obs` (length [`Env::obs_dim`]).
    pub fn observe(&self, obs: &mut [f64]) {
        let (qpos, qvel) = (self.data.qpos(), self.data.qvel());
        let np = qpos.len() - 1;
        obs[..np].copy_from_slice(&qpos[1..]);
        let vel = &mut obs[np..np + qvel.len()];
        vel.copy_from_slice(qvel);
        if let Some(c) = self.spec.obs_qvel_clip {
            for v in vel {
                *v = v.clamp(-c, c);
            }
        }
    }

    fn is_healthy(&self) -> bool {
        let Some(h) = self.spec.health else { return true };
        let q = self.data.qpos();
        let inside = |(lo, hi): (f64, f64), x: f64| lo < x && x < hi;
        let state_ok = h.state_range.is_none_or(|r| q[2..].iter().chain(self.data.qvel()).all(|&x| inside(r, x)));
        state_ok && inside(h.z_range, q[1]) && inside(h.angle_range, q[2])
    }

    /// One Gymnasium step. The action goes to `ctrl` as given (MuJoCo clamps it to the
    /// actuator ctrlrange, as in Gymnasium) and the control cost uses the unclamped action.
    pub fn step(&mut self, action: &[f64], obs: &mut [f64]) -> Result<StepInfo> {
        shape("action", self.act_dim(), action.len(), "")?;
        Ok(self.step_unchecked(action, obs))
    }

    pub(crate) fn step_unchecked(&mut self, action: &[f64], obs: &mut [f64]) -> StepInfo {
        let x_before = self.data.qpos()[0];
        self.data.ctrl_mut().copy_from_slice(action);
        for _ in 0..self.spec.frame_skip {
            self.data.step();
        }
        let x_position = self.data.qpos()[0];
        let x_velocity = (x_position - x_before) / self.dt;
        self.observe(obs);
        let healthy = self.is_healthy();
        let ctrl_cost = self.spec.ctrl_cost_weight * action.iter().map(|a| a * a).sum::<f64>();
        let survive = self.spec.health.map_or(0.0, |h| if healthy { h.reward } else { 0.0 });
        let terms =
            RewardTerms { reward_forward: self.spec.forward_reward_weight * x_velocity, reward_ctrl: -ctrl_cost, reward_survive: survive };
        self.elapsed += 1;
        StepInfo {
            // Same order of operations as Gymnasium: (forward + survive) - ctrl.
            reward: (terms.reward_forward + survive) - ctrl_cost,
            terminated: !healthy,
            truncated: self.elapsed >= self.spec.max_episode_steps,
            terms,
            x_position,
            x_velocity,
        }
    }

    /// Only the simulator's share of a step (set ctrl, `frame_skip` mj_steps): the benchmark's
    /// mj_step-bound baseline over the same transitions as [`Env::step`].
    pub fn raw_step(&mut self, action: &[f64]) {
        self.data.ctrl_mut().copy_from_slice(action);
        for _ in 0..self.spec.frame_skip {
            self.data.step();
        }
    }
}

fn shape(what: &str, expected: usize, got: usize, hint: &str) -> Result<()> {
    if expected == got { Ok(()) } else { Err(Error::Shape { what: what.into(), expected, got, hint: hint.into() }) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_parse_and_unknown_names_list_the_known_ones() {
        assert_eq!("Hopper-v5".parse::<EnvId>().unwrap(), EnvId::Hopper);
        let err = "Hopper-v4".parse::<EnvId>().unwrap_err().to_string();
        assert!(err.contains("HalfCheetah-v5, Hopper-v5, Walker2d-v5"), "{err}");
    }

    #[test]
    fn dimensions_match_gymnasium() {
        for (id, obs, act, dt) in [(EnvId::HalfCheetah, 17, 6, 0.05), (EnvId::Hopper, 11, 3, 0.008), (EnvId::Walker2d, 17, 6, 0.008)] {
            let env = Env::new(id).unwrap();
            assert_eq!((env.obs_dim(), env.act_dim()), (obs, act), "{id}");
            assert!((env.dt() - dt).abs() < 1e-12, "{id}");
            assert_eq!(env.action_bounds().0, vec![-1.0; act].as_slice());
            assert_eq!(env.action_bounds().1, vec![1.0; act].as_slice());
        }
    }

    #[test]
    fn seeded_resets_are_reproducible_and_noisy() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let (mut a, mut b, mut c) = (vec![0.0; 11], vec![0.0; 11], vec![0.0; 11]);
        env.reset(Some(7), &mut a);
        env.reset(Some(7), &mut b);
        env.reset(None, &mut c);
        assert_eq!(a, b);
        assert_ne!(a, c);
        // Hopper's noise is U(-5e-3, 5e-3) around qpos0 = (0, 1.25, 0, ...).
        assert!((a[0] - 1.25).abs() <= 5e-3 && a[0] != 1.25);
        assert!(a[5..].iter().all(|v| v.abs() <= 5e-3));
    }

    #[test]
    fn wrong_widths_are_errors_not_panics() {
        let mut env = Env::new(EnvId::HalfCheetah).unwrap();
        let mut obs = vec![0.0; 17];
        let err = env.step(&[0.0; 3], &mut obs).unwrap_err().to_string();
        assert_eq!(err, "action: expected 6 values, got 3");
        assert!(env.set_state(&[0.0; 8], &[0.0; 9], &mut obs).is_err());
    }

    #[test]
    fn truncates_at_the_time_limit() {
        let mut env = Env::new(EnvId::HalfCheetah).unwrap();
        let mut obs = vec![0.0; 17];
        env.reset(Some(0), &mut obs);
        for t in 1..=1000 {
            let info = env.step(&[0.0; 6], &mut obs).unwrap();
            assert_eq!(info.truncated, t == 1000);
            assert!(!info.terminated);
        }
    }
}
