//! The T-REX reward network r(s) (optionally r(s, a)) and ensembles of them.
//!
//! For RL ([`RewardEnsemble::rl_reward`]) each model's output is normalised by that model's
//! own running mean and std and clipped to +-clip; the models combine as [`Combine`] says
//! (by default their mean; the original D-REX code used the last model's output divided by
//! the number of models, a bug kept there as "original code"), and the control cost
//! `ctrl_coeff * ||a||^2` is subtracted, on the clipped action by default or on the raw
//! sampled action as the original did ([`CtrlAction`]).
use std::path::Path;

use tch::{Device, Kind, Tensor, nn, nn::Module};

use super::dense::Dense;
use super::sidecar::{check_size, load_weights, mlp_parameters, parse_json, save_weights, weights_bytes, write_json};
use super::{Activation, Mlp, WeightInit};
use crate::data::normalize::RunningMeanStd;
use crate::error::{Error, Result};

pub const WEIGHTS: &str = "reward.safetensors";
pub const SIDECAR: &str = "reward.json";
const FORMAT: &str = "idrex-reward/1";

pub type RewardNet = Mlp;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RewardConfig {
    /// Observation entries the networks read: `obs_dim` of each observation, from
    /// `obs_offset`.
    pub obs_dim: usize,
    /// The observations' full length, where the networks read only part of each
    /// (`trex.observation`); absent: they read all of it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_stride: Option<usize>,
    /// The first observation entry the networks read (`trex.observation: velocities`);
    /// absent: the first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_offset: Option<usize>,
    /// Also feed the action, where set (the reference uses the observation only).
    pub act_dim: Option<usize>,
    pub hidden: Vec<usize>,
    pub models: usize,
    /// Clip of each model's normalised output.
    pub clip: f64,
    #[serde(default)]
    pub init: WeightInit,
}

impl RewardConfig {
    pub fn input_dim(&self) -> usize {
        self.obs_dim + self.act_dim.unwrap_or(0)
    }

    /// The length of one observation row as callers pass it.
    pub fn stride(&self) -> usize {
        self.obs_stride.unwrap_or(self.obs_dim)
    }

    /// The network's input rows for `obs` (rows of [`Self::stride`]) and, where the network
    /// reads them, `actions`; borrowed where they already are the rows.
    fn rows<'a>(&self, obs: &'a [f32], actions: &[f32]) -> (std::borrow::Cow<'a, [f32]>, usize) {
        let (od, stride, from) = (self.obs_dim, self.stride(), self.obs_offset.unwrap_or(0));
        let n = obs.len() / stride;
        if stride == od && self.act_dim.is_none() {
            return (obs.into(), n);
        }
        let a = self.act_dim.unwrap_or(0);
        let row = |i: usize| i * stride + from..i * stride + from + od;
        let x = (0..n).flat_map(|i| obs[row(i)].iter().chain(&actions[i * a..(i + 1) * a]).copied()).collect();
        (std::borrow::Cow::Owned(x), n)
    }
}

/// How the ensemble's normalised outputs combine into one reward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Combine {
    /// The mean of the models' normalised outputs.
    #[default]
    Mean,
    /// The last model's normalised output divided by the number of models (the original code).
    LastOverCount,
    /// At each step the lowest of the models' normalised outputs: a pessimistic reward, which
    /// pays only for what every member agrees is good.
    Min,
}

/// Which action the control cost is charged on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CtrlAction {
    /// The action sent to the environment, clipped to the box.
    Clipped,
    /// The raw sampled action (the original code, and idrex's default: the ablation in
    /// analysis/results/ablation/README.md found it decisive on HalfCheetah): saturating the
    /// actuators still costs, which keeps PPO's Gaussian inside the box.
    #[default]
    Raw,
}

/// Where each member's reward is centred and scaled for RL. A pipeline file's default is
/// `RankedFloor` (`RewardSettings`); the enum's `Default`, `Running`, is what a stage key that
/// does not name a level means (keys from before the level existed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum RewardLevel {
    /// By running statistics of PPO's own experience (the original code): the learned reward
    /// is centred on what the policy does, so on a task that ends, ending costs nothing.
    #[default]
    Running,
    /// Fixed before training: centred on the member's mean per-step reward over the noisiest
    /// level of D-REX's ranked set (the worst the ranking knows) and scaled by its per-step
    /// standard deviation over the whole set. Every better-ranked level then earns a positive
    /// reward per step, so living pays where the demonstrations live.
    RankedFloor,
}

impl RewardLevel {
    pub fn is_running(&self) -> bool {
        *self == RewardLevel::Running
    }
}

/// The reward PPO optimises, composed from a learned ensemble.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Composition {
    pub ctrl_coeff: f64,
    pub combine: Combine,
    pub ctrl_action: CtrlAction,
    /// Absent from the key when running (the original).
    #[serde(default, skip_serializing_if = "RewardLevel::is_running")]
    pub level: RewardLevel,
    /// A brake on exploitation: k x the members' standard deviation (of their normalised
    /// outputs, at each step) is subtracted, as the `imitation` library's ensemble does.
    /// Absent from the key at 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub disagreement: f64,
    /// A brake on exploitation: each member's raw reward per step is capped at this quantile
    /// of its values over D-REX's ranked set, so no state pays more than the ranking has
    /// seen. Absent (no cap) from the key when unset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ceiling: Option<f64>,
}

impl Composition {
    /// Whether PPO reads D-REX's ranked set (a `floor` input) to compose this reward: the
    /// ranked floor and the ceiling are measured on it. The graph wires the input and the
    /// PPO stage reads it by this one rule.
    pub fn needs_ranked_set(&self) -> bool {
        !self.level.is_running() || self.ceiling.is_some()
    }
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// What a reward ensemble's sidecar holds.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Sidecar {
    format: String,
    config: RewardConfig,
    norms: Vec<RunningMeanStd>,
    hyper: serde_json::Value,
}

pub struct RewardEnsemble {
    /// One store per model, so that each trains with its own optimiser state.
    pub stores: Vec<nn::VarStore>,
    pub nets: Vec<RewardNet>,
    pub config: RewardConfig,
    /// One running statistic of raw outputs per model.
    pub norms: Vec<RunningMeanStd>,
    /// Whether `norms` are fixed ([`RewardLevel::RankedFloor`]): RL then never updates them.
    pub fixed_norms: bool,
    /// Each member's cap on its raw reward ([`Composition::ceiling`]), where set.
    pub ceilings: Option<Vec<f32>>,
    /// Members' per-step values RL trained on, and of those the ones the ceiling capped.
    pub capped: (u64, u64),
}

impl RewardEnsemble {
    pub fn new(config: RewardConfig) -> Self {
        let sizes: Vec<i64> =
            std::iter::once(config.input_dim()).chain(config.hidden.iter().copied()).chain([1]).map(|x| x as i64).collect();
        let stores: Vec<nn::VarStore> = (0..config.models).map(|_| nn::VarStore::new(Device::Cpu)).collect();
        let nets = stores
            .iter()
            .enumerate()
            .map(|(m, vs)| Mlp::new(&(vs.root() / format!("m{m}")), &sizes, Activation::Relu, config.init.init()))
            .collect();
        let norms = (0..config.models).map(|_| RunningMeanStd::new(1)).collect();
        RewardEnsemble { stores, nets, config, norms, fixed_norms: false, ceilings: None, capped: (0, 0) }
    }

    /// Moves the networks to `device`, where [`RewardEnsemble::raw`] then computes (PPO's
    /// learned reward on the GPU).
    pub fn to_device(&mut self, device: crate::nn::Device) -> Result<()> {
        device.ensure_available()?;
        for store in &mut self.stores {
            store.set_device(device.tch());
        }
        Ok(())
    }

    /// Where the networks are (libtorch's device).
    fn tch_device(&self) -> Device {
        self.stores.first().map_or(Device::Cpu, nn::VarStore::device)
    }

    /// Network input rows from observations and (if used) actions, on the networks' device.
    pub fn inputs(&self, obs: &[f32], actions: &[f32]) -> Tensor {
        let (x, n) = self.config.rows(obs, actions);
        Tensor::from_slice(&x).view([n as i64, self.config.input_dim() as i64]).to_device(self.tch_device())
    }

    /// Model `m`'s reward per row: `(b, in)` -> `(b)`.
    pub fn forward(&self, m: usize, x: &Tensor) -> Tensor {
        self.nets[m].forward(x).squeeze_dim(-1)
    }

    /// Raw per-model rewards of a batch of steps, `[model][row]`, without gradients. On the
    /// CPU through [`Dense`] (the same bits on every processor), on a GPU through libtorch.
    pub fn raw(&self, obs: &[f32], actions: &[f32]) -> Vec<Vec<f32>> {
        if self.tch_device() != Device::Cpu {
            return tch::no_grad(|| {
                let x = self.inputs(obs, actions);
                (0..self.nets.len())
                    .map(|m| Vec::try_from(self.forward(m, &x).to_device(Device::Cpu).to_kind(Kind::Float)).expect("f32 rewards"))
                    .collect()
            });
        }
        let (x, n) = self.config.rows(obs, actions);
        self.nets
            .iter()
            .map(|net| {
                let mut out = Vec::with_capacity(n);
                Dense::from_mlp(net).predict(&x, n, &mut out);
                out
            })
            .collect()
    }

    /// Predicted return of one trajectory: the ensemble mean of each model's summed raw reward.
    pub fn predicted_return(&self, obs: &[f32], actions: &[f32]) -> f64 {
        let raw = self.raw(obs, actions);
        raw.iter().map(|r| r.iter().map(|&x| x as f64).sum::<f64>()).sum::<f64>() / raw.len() as f64
    }

    /// The reward RL optimises, for a batch of steps: `next_obs` are the next observations
    /// s', `actions` what the network reads (the clipped actions), `cost_actions` what the
    /// control cost is charged on. With `update`, each model's running statistics first
    /// absorb this batch.
    pub fn rl_reward(
        &mut self,
        next_obs: &[f32],
        actions: &[f32],
        cost_actions: &[f32],
        act_dim: usize,
        comp: &Composition,
        update: bool,
    ) -> Vec<f64> {
        let mut raw = self.raw(next_obs, actions);
        if let Some(ceilings) = &self.ceilings {
            for (r, &c) in raw.iter_mut().zip(ceilings) {
                for x in r.iter_mut().filter(|x| **x > c) {
                    *x = c;
                    if update {
                        self.capped.1 += 1;
                    }
                }
            }
        }
        if update {
            self.capped.0 += (raw[0].len() * raw.len()) as u64;
        }
        if update && !self.fixed_norms {
            for (norm, r) in self.norms.iter_mut().zip(&raw) {
                norm.update(r);
            }
        }
        let n = raw[0].len();
        let k = self.norms.len();
        let normalised = |m: usize, i: usize| {
            let (mean, std) = (self.norms[m].mean[0], (self.norms[m].var[0] + 1e-8).sqrt());
            ((raw[m][i] as f64 - mean) / std).clamp(-self.config.clip, self.config.clip)
        };
        (0..n)
            .map(|i| {
                let mut learned = match comp.combine {
                    Combine::Mean => (0..k).map(|m| normalised(m, i)).sum::<f64>() / k as f64,
                    Combine::LastOverCount => normalised(k - 1, i) / k as f64,
                    Combine::Min => (0..k).map(|m| normalised(m, i)).fold(f64::INFINITY, f64::min),
                };
                if comp.disagreement != 0.0 {
                    let mean = (0..k).map(|m| normalised(m, i)).sum::<f64>() / k as f64;
                    let var = (0..k).map(|m| (normalised(m, i) - mean).powi(2)).sum::<f64>() / k as f64;
                    learned -= comp.disagreement * var.sqrt();
                }
                let a = &cost_actions[i * act_dim..(i + 1) * act_dim];
                learned - comp.ctrl_coeff * a.iter().map(|&x| (x as f64).powi(2)).sum::<f64>()
            })
            .collect()
    }

    /// Fixes each member's level from a ranked set ([`RewardLevel::RankedFloor`]): its mean
    /// per-step raw reward over the noisiest level's steps, its spread over every step.
    pub fn fix_levels_from(&mut self, set: &[crate::data::Trajectory]) -> Result<()> {
        let noisiest = set.iter().map(|t| t.meta.noise).fold(f64::NEG_INFINITY, f64::max);
        let k = self.nets.len();
        let (mut floor, mut all) = (vec![(0.0f64, 0usize); k], vec![(0.0f64, 0.0f64, 0usize); k]);
        for t in set.iter().filter(|t| !t.is_empty()) {
            for (m, r) in self.raw(t.next_obs(), &t.actions).into_iter().enumerate() {
                for x in r.into_iter().map(f64::from) {
                    if t.meta.noise == noisiest {
                        floor[m].0 += x;
                        floor[m].1 += 1;
                    }
                    all[m].0 += x;
                    all[m].1 += x * x;
                    all[m].2 += 1;
                }
            }
        }
        if floor.iter().any(|f| f.1 == 0) {
            return Err(Error::Invalid("reward.level ranked-floor needs a ranked set with steps at its noisiest level".into()));
        }
        for (m, norm) in self.norms.iter_mut().enumerate() {
            let n = all[m].2 as f64;
            let mean = all[m].0 / n;
            norm.mean[0] = floor[m].0 / floor[m].1 as f64;
            norm.var[0] = (all[m].1 / n - mean * mean).max(1e-12);
        }
        self.fixed_norms = true;
        Ok(())
    }

    /// Caps each member's raw reward at quantile `q` (nearest rank, in (0, 1]) of its
    /// per-step values over a ranked set ([`Composition::ceiling`]).
    pub fn fix_ceilings_from(&mut self, set: &[crate::data::Trajectory], q: f64) -> Result<()> {
        let mut values = vec![Vec::new(); self.nets.len()];
        for t in set.iter().filter(|t| !t.is_empty()) {
            for (m, r) in self.raw(t.next_obs(), &t.actions).into_iter().enumerate() {
                values[m].extend(r);
            }
        }
        if values[0].is_empty() || !(q > 0.0 && q <= 1.0) {
            return Err(Error::Invalid(format!("reward.ceiling {q} needs a quantile in (0, 1] and a ranked set with steps")));
        }
        let ceilings = values
            .into_iter()
            .map(|mut v| {
                v.sort_by(f32::total_cmp);
                v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1]
            })
            .collect();
        self.ceilings = Some(ceilings);
        Ok(())
    }

    /// The fraction of members' per-step values RL trained on that the ceiling capped.
    pub fn capped_fraction(&self) -> Option<f64> {
        self.ceilings.as_ref().map(|_| self.capped.1 as f64 / self.capped.0.max(1) as f64)
    }

    pub fn save(&self, dir: &Path, hyper: serde_json::Value) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        save_weights(&self.stores.iter().collect::<Vec<_>>(), &dir.join(WEIGHTS))?;
        let side = Sidecar { format: FORMAT.into(), config: self.config.clone(), norms: self.norms.clone(), hyper };
        write_json(&dir.join(SIDECAR), &side)
    }

    /// A sidecar's text checked before anything is built: its format, and that the weights
    /// file (`weights_bytes` long) can hold the ensemble it describes.
    pub fn check_sidecar(side_path: &Path, text: &str, weights_bytes: u64) -> Result<Sidecar> {
        let side: Sidecar = parse_json(side_path, text)?;
        if side.format != FORMAT {
            return Err(Error::file(side_path, format!("format '{}' is not {FORMAT}", side.format)));
        }
        let c = &side.config;
        let one = c
            .obs_dim
            .checked_add(c.act_dim.unwrap_or(0))
            .and_then(|input| mlp_parameters(&std::iter::once(input).chain(c.hidden.iter().copied()).chain([1]).collect::<Vec<_>>()));
        check_size(side_path, one.and_then(|n| n.checked_mul(c.models as u64)), weights_bytes)?;
        Ok(side)
    }

    pub fn load(dir: &Path) -> Result<Self> {
        let side_path = dir.join(SIDECAR);
        let text = std::fs::read_to_string(&side_path).map_err(|e| Error::io(&side_path, e))?;
        let side = Self::check_sidecar(&side_path, &text, weights_bytes(&dir.join(WEIGHTS))?)?;
        let mut r = crate::nn::building(|| RewardEnsemble::new(side.config));
        load_weights(&r.stores.iter().collect::<Vec<_>>(), &dir.join(WEIGHTS), &side_path)?;
        if side.norms.len() == r.nets.len() {
            r.norms = side.norms;
        }
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two members of one hidden layer of 3 on a one-entry observation.
    fn small_config() -> RewardConfig {
        RewardConfig {
            obs_dim: 1,
            obs_stride: None,
            obs_offset: None,
            act_dim: None,
            hidden: vec![3],
            models: 2,
            clip: 100.0,
            init: WeightInit::TorchDefault,
        }
    }

    const BASE: Composition = Composition {
        ctrl_coeff: 0.0,
        combine: Combine::Mean,
        ctrl_action: CtrlAction::Raw,
        level: RewardLevel::Running,
        disagreement: 0.0,
        ceiling: None,
    };

    /// A reward that reads two of three observation entries (the leading two, or the last two
    /// from an offset) scores whole rows as the same networks score the rows cut to those two,
    /// with or without actions, and keeps its stride and offset through a save and a load.
    #[test]
    fn reads_its_part_of_each_observation() {
        for (obs_offset, act_dim) in [(None, None), (None, Some(1)), (Some(1), None), (Some(1), Some(1))] {
            let config = RewardConfig {
                obs_dim: 2,
                obs_stride: Some(3),
                obs_offset,
                act_dim,
                hidden: vec![4],
                models: 2,
                clip: 100.0,
                init: WeightInit::TorchDefault,
            };
            let model = crate::nn::seeded(5, || RewardEnsemble::new(config.clone()));
            let obs = [0.1f32, -0.2, 9.0, 0.3, 0.4, -9.0];
            let actions = [0.5f32, -0.5];
            // The rows the networks should read: the two entries, then the action.
            let rows: Vec<f32> = match (obs_offset, act_dim) {
                (None, None) => vec![0.1, -0.2, 0.3, 0.4],
                (None, Some(_)) => vec![0.1, -0.2, 0.5, 0.3, 0.4, -0.5],
                (Some(_), None) => vec![-0.2, 9.0, 0.4, -9.0],
                (Some(_), Some(_)) => vec![-0.2, 9.0, 0.5, 0.4, -9.0, -0.5],
            };
            for (m, net) in model.nets.iter().enumerate() {
                let mut out = Vec::new();
                Dense::from_mlp(net).predict(&rows, 2, &mut out);
                assert_eq!(model.raw(&obs, &actions)[m], out);
            }
            assert_eq!(model.raw(&obs, &actions)[0].len(), 2);
            let tag = format!("{}-{:?}-{:?}", std::process::id(), obs_offset, act_dim);
            let dir = std::env::temp_dir().join(format!("idrex-stride-{tag}"));
            model.save(&dir, serde_json::Value::Null).unwrap();
            let back = RewardEnsemble::load(&dir).unwrap();
            assert_eq!(back.config, config);
            assert_eq!(back.raw(&obs, &actions), model.raw(&obs, &actions));
            std::fs::remove_dir_all(&dir).unwrap();
        }
    }

    #[test]
    fn composition_on_a_fixed_batch() {
        let config = RewardConfig {
            obs_dim: 2,
            obs_stride: None,
            obs_offset: None,
            act_dim: None,
            hidden: vec![4],
            models: 2,
            clip: 100.0,
            init: WeightInit::TorchDefault,
        };
        let mut model = crate::nn::seeded(0, || RewardEnsemble::new(config));
        // Model m normalises with mean m and std 2.
        for (m, norm) in model.norms.iter_mut().enumerate() {
            norm.mean[0] = m as f64;
            norm.var[0] = 4.0;
        }
        let obs = [0.5f32, -1.0, 2.0, 0.25];
        let clipped = [1.0f32, -1.0];
        let raw_action = [3.0f32, -0.5];
        let raw = model.raw(&obs, &clipped);
        let norm = |m: usize, i: usize| (raw[m][i] as f64 - m as f64) / (4.0f64 + 1e-8).sqrt();
        let comp = Composition { ctrl_coeff: 0.1, combine: Combine::Mean, ctrl_action: CtrlAction::Clipped, ..BASE };
        let mean = model.rl_reward(&obs, &clipped, &clipped, 1, &comp, false);
        for i in 0..2 {
            let want = (norm(0, i) + norm(1, i)) / 2.0 - 0.1 * (clipped[i] as f64).powi(2);
            assert!((mean[i] - want).abs() < 1e-9, "mean {i}: {} vs {want}", mean[i]);
        }
        // The original code: the last model over the count, the cost on the raw action.
        let original = Composition { ctrl_coeff: 0.1, combine: Combine::LastOverCount, ctrl_action: CtrlAction::Raw, ..BASE };
        let last = model.rl_reward(&obs, &clipped, &raw_action, 1, &original, false);
        for i in 0..2 {
            let want = norm(1, i) / 2.0 - 0.1 * (raw_action[i] as f64).powi(2);
            assert!((last[i] - want).abs() < 1e-9, "last-over-count {i}: {} vs {want}", last[i]);
        }
        assert!((last[0] - mean[0]).abs() > 1e-6, "the options change the reward");
        // Pessimistic: the lower of the two normalised outputs at each step.
        let pessimistic = Composition { ctrl_coeff: 0.1, combine: Combine::Min, ctrl_action: CtrlAction::Clipped, ..BASE };
        let low = model.rl_reward(&obs, &clipped, &clipped, 1, &pessimistic, false);
        for i in 0..2 {
            let want = norm(0, i).min(norm(1, i)) - 0.1 * (clipped[i] as f64).powi(2);
            assert!((low[i] - want).abs() < 1e-9, "min {i}: {} vs {want}", low[i]);
        }
        // The disagreement brake: the mean minus k x the members' standard deviation.
        let braked = Composition { disagreement: 2.0, ..comp };
        let b = model.rl_reward(&obs, &clipped, &clipped, 1, &braked, false);
        for i in 0..2 {
            let spread = (norm(0, i) - norm(1, i)).abs() / 2.0;
            assert!((b[i] - (mean[i] - 2.0 * spread)).abs() < 1e-9, "brake {i}: {} vs {}", b[i], mean[i] - 2.0 * spread);
        }
    }

    /// The ranked floor: each member centred on its mean over the noisiest level's steps and
    /// scaled by its spread over the set, fixed (RL's updates leave it); the running level
    /// moves with what it sees.
    #[test]
    fn the_ranked_floor_fixes_each_members_level() {
        use crate::data::{TrajMeta, Trajectory};
        let config = small_config();
        let mut model = crate::nn::seeded(4, || RewardEnsemble::new(config));
        let traj = |xs: &[f32], noise: f64| Trajectory {
            obs_dim: 1,
            act_dim: 1,
            obs: std::iter::once(0.0).chain(xs.iter().copied()).collect(),
            actions: vec![0.0; xs.len()],
            rewards: vec![0.0; xs.len()],
            terms: vec![Default::default(); xs.len()],
            meta: TrajMeta { noise, ..Default::default() },
            ..Default::default()
        };
        let set = vec![traj(&[1.0, 2.0], 0.0), traj(&[-1.0, -3.0, 0.5], 1.0)];
        model.fix_levels_from(&set).unwrap();
        let raw_at = |m: &RewardEnsemble, xs: &[f32]| m.raw(xs, &vec![0.0; xs.len()]);
        let (noisy, every) = (raw_at(&model, &[-1.0, -3.0, 0.5]), raw_at(&model, &[1.0, 2.0, -1.0, -3.0, 0.5]));
        for m in 0..2 {
            let floor = noisy[m].iter().map(|&x| x as f64).sum::<f64>() / 3.0;
            let mean = every[m].iter().map(|&x| x as f64).sum::<f64>() / 5.0;
            let var = every[m].iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / 5.0;
            assert!((model.norms[m].mean[0] - floor).abs() < 1e-6, "{m}: {} vs {floor}", model.norms[m].mean[0]);
            assert!((model.norms[m].var[0] - var).abs() < 1e-6 * var.max(1.0), "{m}");
        }
        // Fixed: an RL update leaves the levels where they were; the noisiest level's steps
        // average 0 and the set's spread is 1 per member.
        let before = model.norms.clone();
        let comp = BASE;
        let r = model.rl_reward(&[-1.0, -3.0, 0.5], &[0.0; 3], &[0.0; 3], 1, &comp, true);
        assert_eq!(model.norms, before);
        assert!(r.iter().sum::<f64>().abs() < 1e-4, "{r:?}");
        // The running level moves.
        model.fixed_norms = false;
        model.rl_reward(&[5.0, 6.0], &[0.0; 2], &[0.0; 2], 1, &comp, true);
        assert_ne!(model.norms, before);
    }

    /// The ceiling: each member's raw reward capped at a quantile of its values over the
    /// ranked set, before the level; values below it pass unchanged.
    #[test]
    fn the_ceiling_caps_each_member_at_a_quantile_of_the_ranked_set() {
        use crate::data::{TrajMeta, Trajectory};
        let config = small_config();
        let mut model = crate::nn::seeded(7, || RewardEnsemble::new(config));
        let xs: Vec<f32> = (0..10).map(|i| i as f32 - 4.5).collect();
        let set = vec![Trajectory {
            obs_dim: 1,
            act_dim: 1,
            obs: std::iter::once(0.0).chain(xs.iter().copied()).collect(),
            actions: vec![0.0; 10],
            rewards: vec![0.0; 10],
            terms: vec![Default::default(); 10],
            meta: TrajMeta::default(),
            ..Default::default()
        }];
        model.fix_ceilings_from(&set, 0.8).unwrap();
        let seen = model.raw(&xs, &[0.0; 10]);
        let ceilings = model.ceilings.clone().unwrap();
        for m in 0..2 {
            let mut v = seen[m].clone();
            v.sort_by(f32::total_cmp);
            assert_eq!(ceilings[m], v[7], "member {m}: the 8th of 10 values");
        }
        // Far outside the set a ReLU net extrapolates linearly; the cap holds it. (Levels
        // fixed at mean 0, spread 1, so the reward is the members' mean raw value.)
        model.fixed_norms = true;
        let probe = [-50.0f32, 50.0, 0.0];
        let capped = model.rl_reward(&probe, &[0.0; 3], &[0.0; 3], 1, &Composition { ceiling: Some(0.8), ..BASE }, true);
        let raw = model.raw(&probe, &[0.0; 3]);
        for i in 0..3 {
            let want = (0..2).map(|m| raw[m][i].min(ceilings[m]) as f64).sum::<f64>() / 2.0;
            assert!((capped[i] - want).abs() < 1e-6, "step {i}: {} vs {want}", capped[i]);
        }
        let over = (0..2).flat_map(|m| (0..3).map(move |i| (m, i))).filter(|&(m, i)| raw[m][i] > ceilings[m]).count();
        assert!(over > 0, "the probe reaches past the cap");
        assert_eq!(model.capped, (6, over as u64));
        assert!(model.fix_ceilings_from(&set, 0.0).is_err() && model.fix_ceilings_from(&[], 0.5).is_err());
    }
}
