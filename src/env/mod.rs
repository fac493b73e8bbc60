//! Gymnasium-v5 MuJoCo locomotion environments on mujoco-rs.
//!
//! One generic [`Env`] runs every task; each task is a [`EnvSpec`] in its own file
//! ([`half_cheetah`], [`hopper`], [`walker2d`], [`ant`]) whose numbers are Gymnasium's v5
//! defaults.
//! Equivalence with Gymnasium (observations, each reward term, termination, truncation) is
//! checked by `tests/env_equivalence.rs`, which replays the same actions in both.
//!
//! Departures, none of which change a transition: Gymnasium calls `mj_rnePostConstraint`
//! after stepping, which only fills force outputs (`cacc`, `cfrc_*`); we call it only for
//! the task that reads them (Ant's contact forces); our reset noise comes from a seeded ChaCha8
//! generator, not numpy's, so seeds are reproducible here but not shared with Gymnasium.
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mujoco_rs::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::error::{Error, Result};

pub mod ant;
pub mod half_cheetah;
pub mod hopper;
mod horizon;
pub mod replay;
mod spec;
pub mod vec_env;
pub mod walker2d;

pub use horizon::Horizon;
pub use spec::{Contact, EnvSpec, Forward, Health, ResetNoise};
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
    #[serde(rename = "Ant-v5")]
    Ant,
    /// `Ant-v5` with `include_cfrc_ext_in_observation=False` (27 observations).
    #[serde(rename = "Ant-v5-no-cfrc")]
    AntNoCfrc,
}

impl EnvId {
    pub const ALL: [EnvId; 5] = [EnvId::HalfCheetah, EnvId::Hopper, EnvId::Walker2d, EnvId::Ant, EnvId::AntNoCfrc];
    /// Gymnasium's four tasks at their default options (what `bench env` measures).
    pub const TASKS: [EnvId; 4] = [EnvId::HalfCheetah, EnvId::Hopper, EnvId::Walker2d, EnvId::Ant];

    pub fn name(self) -> &'static str {
        self.spec().name
    }

    pub fn spec(self) -> &'static EnvSpec {
        match self {
            EnvId::HalfCheetah => &half_cheetah::SPEC,
            EnvId::Hopper => &hopper::SPEC,
            EnvId::Walker2d => &walker2d::SPEC,
            EnvId::Ant => &ant::SPEC,
            EnvId::AntNoCfrc => &ant::SPEC_NO_CFRC,
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

/// Each term of the reward as Gymnasium's `info` reports it;
/// `reward = forward + ctrl + survive + contact`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct RewardTerms {
    pub reward_forward: f64,
    /// Minus the control cost.
    pub reward_ctrl: f64,
    pub reward_survive: f64,
    /// Minus the contact cost (0 for the tasks without one).
    pub reward_contact: f64,
}

impl RewardTerms {
    pub fn total(&self) -> f64 {
        self.reward_forward + self.reward_ctrl + self.reward_survive + self.reward_contact
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
    /// Bodies in the model, the world included (Ant observes the other bodies' contact forces).
    nbody: usize,
    action_low: Vec<f64>,
    action_high: Vec<f64>,
    dt: f64,
    elapsed: usize,
    horizon: Horizon,
    rng: ChaCha8Rng,
}

impl Env {
    /// Loads the model from the default assets and returns an environment seeded with 0.
    pub fn new(id: EnvId) -> Result<Self> {
        Ok(Self::with_model(id, load_model(id, None)?))
    }

    /// Builds an environment on an already loaded model (vectorised envs share one).
    #[allow(unsafe_code)] // the model's actuator ranges, a raw array
    pub fn with_model(id: EnvId, model: Arc<MjModel>) -> Self {
        let spec = id.spec();
        let (nu, timestep, nbody) = (model.ffi().nu as usize, model.ffi().opt.timestep, model.ffi().nbody as usize);
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
            nbody,
            action_low,
            action_high,
            dt: timestep * spec.frame_skip as f64,
            elapsed: 0,
            horizon: Horizon::Task,
            rng: ChaCha8Rng::seed_from_u64(0),
        }
    }

    /// The same environment, its episodes ending where `horizon` says.
    pub fn with_horizon(mut self, horizon: Horizon) -> Self {
        self.horizon = horizon;
        self
    }

    pub fn set_horizon(&mut self, horizon: Horizon) {
        self.horizon = horizon;
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
    /// qpos without its first `obs_skip_qpos` entries, qvel, and where the task observes
    /// them, the contact forces of every body but the world (6 each).
    pub fn obs_dim(&self) -> usize {
        let contact = if self.spec.observed_contact().is_some() { 6 * (self.nbody - 1) } else { 0 };
        self.nq() - self.spec.obs_skip_qpos + self.nv() + contact
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
        let skip = self.spec.obs_skip_qpos;
        let np = qpos.len() - skip;
        obs[..np].copy_from_slice(&qpos[skip..]);
        let vel = &mut obs[np..np + qvel.len()];
        vel.copy_from_slice(qvel);
        if let Some(c) = self.spec.obs_qvel_clip {
            for v in vel {
                *v = v.clamp(-c, c);
            }
        }
        if let Some(c) = self.spec.observed_contact() {
            let (lo, hi) = c.force_range;
            let forces = self.data.cfrc_ext()[1..].iter().flatten();
            for (o, f) in obs[np + qvel.len()..].iter_mut().zip(forces) {
                *o = f.clamp(lo, hi);
            }
        }
    }

    fn is_healthy(&self) -> bool {
        let q = self.data.qpos();
        let open = |(lo, hi): (f64, f64), x: f64| lo < x && x < hi;
        match self.spec.health {
            None => true,
            Some(Health::Planar { z_range, angle_range, state_range, .. }) => {
                let state_ok = state_range.is_none_or(|r| q[2..].iter().chain(self.data.qvel()).all(|&x| open(r, x)));
                state_ok && open(z_range, q[1]) && open(angle_range, q[2])
            }
            Some(Health::Upright { z_range: (lo, hi), .. }) => {
                q.iter().chain(self.data.qvel()).all(|x| x.is_finite()) && lo <= q[2] && q[2] <= hi
            }
        }
    }

    /// The coordinate the forward velocity is measured on (see [`Forward`]).
    fn forward_x(&self) -> f64 {
        match self.spec.forward {
            Forward::Qpos0 => self.data.qpos()[0],
            Forward::BodyXpos(b) => self.data.xpos()[b][0],
        }
    }

    /// Minus the contact cost: the weight times the squared clipped forces of every body.
    fn contact_reward(&self) -> f64 {
        let Some(c) = self.spec.contact else { return 0.0 };
        let (lo, hi) = c.force_range;
        -(c.cost_weight * sum_of_squares(self.data.cfrc_ext().iter().flatten().map(|f| f.clamp(lo, hi))))
    }

    /// One Gymnasium step. The action goes to `ctrl` as given (MuJoCo clamps it to the
    /// actuator ctrlrange, as in Gymnasium) and the control cost uses the unclamped action.
    pub fn step(&mut self, action: &[f64], obs: &mut [f64]) -> Result<StepInfo> {
        shape("action", self.act_dim(), action.len(), "")?;
        Ok(self.step_unchecked(action, obs))
    }

    pub(crate) fn step_unchecked(&mut self, action: &[f64], obs: &mut [f64]) -> StepInfo {
        let x_before = self.forward_x();
        self.data.ctrl_mut().copy_from_slice(action);
        for _ in 0..self.spec.frame_skip {
            self.data.step();
        }
        if self.spec.contact.is_some() {
            self.data.rne_post_constraint();
        }
        let x_position = self.data.qpos()[0];
        let x_velocity = (self.forward_x() - x_before) / self.dt;
        self.observe(obs);
        let healthy = self.is_healthy();
        let ctrl_cost = self.spec.ctrl_cost_weight * sum_of_squares(action.iter().copied());
        let survive = self.spec.health.map_or(0.0, |h| if healthy { h.reward() } else { 0.0 });
        let contact = self.contact_reward();
        let terms = RewardTerms {
            reward_forward: self.spec.forward_reward_weight * x_velocity,
            reward_ctrl: -ctrl_cost,
            reward_survive: survive,
            reward_contact: contact,
        };
        self.elapsed += 1;
        // Same order of operations as Gymnasium: (forward + survive) - ctrl, and Ant's
        // (forward + survive) - (ctrl + contact).
        let cost = if self.spec.contact.is_some() { ctrl_cost - contact } else { ctrl_cost };
        StepInfo {
            reward: (terms.reward_forward + survive) - cost,
            terminated: !healthy && self.horizon == Horizon::Task,
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

/// `np.sum(np.square(x))`, in a buffer on the stack (a step's actions and contact forces fit:
/// this runs on every step).
fn sum_of_squares(x: impl Iterator<Item = f64>) -> f64 {
    let mut buf = [0.0f64; 128];
    let mut n = 0;
    for v in x {
        assert!(n < buf.len(), "more than 128 values in one step's sum");
        buf[n] = v * v;
        n += 1;
    }
    numpy_sum(&buf[..n])
}

/// `np.sum` of a contiguous float64 array, bit for bit: numpy adds fewer than 8 numbers in
/// order, up to 128 in 8 interleaved partial sums, and more by halving (pairwise summation).
/// Ant's 8 actions and 84 contact forces take the second path.
fn numpy_sum(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 8 {
        x.iter().fold(0.0, |s, v| s + v)
    } else if n <= 128 {
        let mut r = [x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]];
        let whole = n - n % 8;
        for chunk in x[8..whole].chunks_exact(8) {
            for (acc, v) in r.iter_mut().zip(chunk) {
                *acc += v;
            }
        }
        let head = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        x[whole..].iter().fold(head, |s, v| s + v)
    } else {
        let half = n / 2;
        let half = half - half % 8;
        numpy_sum(&x[..half]) + numpy_sum(&x[half..])
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
        assert!(err.contains("HalfCheetah-v5, Hopper-v5, Walker2d-v5, Ant-v5"), "{err}");
    }

    #[test]
    fn numpy_sum_orders_additions_as_numpy_does() {
        // Values whose sum depends on the order of additions.
        let x: Vec<f64> = (0..300).map(|i| if i % 3 == 0 { 1e16 } else { 1.0 + i as f64 * 1e-3 }).collect();
        for n in [3, 8, 84, 300] {
            let seq = x[..n].iter().fold(0.0, |s, v| s + v);
            let got = numpy_sum(&x[..n]);
            assert!((got - seq).abs() <= 1e-12 * seq.abs(), "{n}");
        }
        // np.sum([1e16, 1, 1, 1, 1, 1, 1, 1, 1]) == 1.0000000000000008e16 (pairwise), where
        // adding in order gives 1e16.
        let mut nine = vec![1.0; 9];
        nine[0] = 1e16;
        assert_eq!(numpy_sum(&nine), 1.0000000000000008e16);
        assert_eq!(nine.iter().fold(0.0, |s, v| s + v), 1e16);
    }

    #[test]
    fn dimensions_match_gymnasium() {
        for (id, obs, act, dt) in [
            (EnvId::HalfCheetah, 17, 6, 0.05),
            (EnvId::Hopper, 11, 3, 0.008),
            (EnvId::Walker2d, 17, 6, 0.008),
            (EnvId::Ant, 105, 8, 0.05),
            (EnvId::AntNoCfrc, 27, 8, 0.05),
        ] {
            let env = Env::new(id).unwrap();
            assert_eq!((env.obs_dim(), env.act_dim()), (obs, act), "{id}");
            assert!((env.dt() - dt).abs() < 1e-12, "{id}");
            assert_eq!(env.action_bounds().0, vec![-1.0; act].as_slice());
            assert_eq!(env.action_bounds().1, vec![1.0; act].as_slice());
        }
    }

    /// A fixed horizon steps a fallen Hopper on to the time limit, paying no healthy reward
    /// while it lies there; the task's own ends the episode at the fall, after the same steps.
    #[test]
    fn a_fixed_horizon_runs_to_the_time_limit() {
        let run = |horizon: Horizon| {
            let mut env = Env::new(EnvId::Hopper).unwrap().with_horizon(horizon);
            let mut obs = vec![0.0; 11];
            env.reset(Some(3), &mut obs);
            let mut infos = Vec::new();
            loop {
                // Full torque on every joint: the Hopper falls within a few dozen steps.
                let info = env.step(&[1.0, 1.0, 1.0], &mut obs).unwrap();
                infos.push(info);
                if info.terminated || info.truncated {
                    return infos;
                }
            }
        };
        let (task, fixed) = (run(Horizon::Task), run(Horizon::Fixed));
        assert!(task.len() < 200 && task.last().unwrap().terminated, "{} steps", task.len());
        assert_eq!(fixed.len(), 1000);
        assert!(fixed.iter().all(|i| !i.terminated) && fixed.last().unwrap().truncated);
        assert_eq!(&fixed[..task.len() - 1], &task[..task.len() - 1], "the same transitions up to the fall");
        assert!(fixed[task.len()..].iter().any(|i| i.terms.reward_survive == 0.0), "no healthy reward once fallen");
        assert_eq!(Horizon::Fixed.on(EnvId::HalfCheetah), Horizon::Task);
        assert_eq!(Horizon::Fixed.on(EnvId::Ant), Horizon::Fixed);
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
