//! The T-REX reward network r(s) (optionally r(s, a)) and ensembles of them.
//!
//! For RL each model's output is normalised by that model's own running mean and std,
//! clipped to +-clip and averaged over the ensemble (the original D-REX code used only the
//! last model, a bug we do not copy); the control cost `ctrl_coeff * ||a||^2` is subtracted.
use std::path::Path;

use tch::{Device, Kind, Tensor, nn, nn::Module};

use super::sidecar::{load_weights, read_json, save_weights, write_json};
use super::{Activation, Init, Mlp};
use crate::data::normalize::RunningMeanStd;
use crate::error::{Error, Result};

pub const WEIGHTS: &str = "reward.safetensors";
pub const SIDECAR: &str = "reward.json";
const FORMAT: &str = "idrex-reward/1";

pub type RewardNet = Mlp;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RewardConfig {
    pub obs_dim: usize,
    /// Also feed the action, where set (the reference uses the observation only).
    pub act_dim: Option<usize>,
    pub hidden: Vec<usize>,
    pub models: usize,
    /// Clip of each model's normalised output.
    pub clip: f64,
    pub ctrl_coeff: f64,
}

impl RewardConfig {
    /// D-REX's MuJoCo reward: 2 x 256 ReLU on the observation, 3 models.
    pub fn drex(obs_dim: usize, ctrl_coeff: f64) -> Self {
        RewardConfig { obs_dim, act_dim: None, hidden: vec![256, 256], models: 3, clip: 100.0, ctrl_coeff }
    }
    pub fn input_dim(&self) -> usize {
        self.obs_dim + self.act_dim.unwrap_or(0)
    }
}

#[derive(serde::Serialize, serde::Deserialize)]
struct Sidecar {
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
}

impl RewardEnsemble {
    pub fn new(config: RewardConfig) -> Self {
        let sizes: Vec<i64> =
            std::iter::once(config.input_dim()).chain(config.hidden.iter().copied()).chain([1]).map(|x| x as i64).collect();
        let stores: Vec<nn::VarStore> = (0..config.models).map(|_| nn::VarStore::new(Device::Cpu)).collect();
        let nets = stores
            .iter()
            .enumerate()
            .map(|(m, vs)| Mlp::new(&(vs.root() / format!("m{m}")), &sizes, Activation::Relu, Init::Default))
            .collect();
        let norms = (0..config.models).map(|_| RunningMeanStd::new(1)).collect();
        RewardEnsemble { stores, nets, config, norms }
    }

    /// Network input rows from observations and (if used) actions.
    pub fn inputs(&self, obs: &[f32], actions: &[f32]) -> Tensor {
        let n = obs.len() / self.config.obs_dim;
        let o = Tensor::from_slice(obs).view([n as i64, self.config.obs_dim as i64]);
        match self.config.act_dim {
            None => o,
            Some(a) => Tensor::cat(&[o, Tensor::from_slice(actions).view([n as i64, a as i64])], 1),
        }
    }

    /// Model `m`'s reward per row: `(b, in)` -> `(b)`.
    pub fn forward(&self, m: usize, x: &Tensor) -> Tensor {
        self.nets[m].forward(x).squeeze_dim(-1)
    }

    /// Raw per-model rewards of a batch of steps, `[model][row]`, without gradients.
    pub fn raw(&self, obs: &[f32], actions: &[f32]) -> Vec<Vec<f32>> {
        tch::no_grad(|| {
            let x = self.inputs(obs, actions);
            (0..self.nets.len()).map(|m| Vec::try_from(self.forward(m, &x).to_kind(Kind::Float)).expect("f32 rewards")).collect()
        })
    }

    /// Predicted return of one trajectory: the ensemble mean of each model's summed raw reward.
    pub fn predicted_return(&self, obs: &[f32], actions: &[f32]) -> f64 {
        let raw = self.raw(obs, actions);
        raw.iter().map(|r| r.iter().map(|&x| x as f64).sum::<f64>()).sum::<f64>() / raw.len() as f64
    }

    /// The reward RL optimises, for a batch of steps (`obs` are the next observations s').
    /// With `update`, each model's running statistics first absorb this batch.
    pub fn rl_reward(&mut self, next_obs: &[f32], actions: &[f32], act_dim: usize, update: bool) -> Vec<f64> {
        let raw = self.raw(next_obs, actions);
        if update {
            for (norm, r) in self.norms.iter_mut().zip(&raw) {
                norm.update(r);
            }
        }
        let n = raw[0].len();
        let mut out = vec![0.0; n];
        for (norm, r) in self.norms.iter().zip(&raw) {
            let (mean, std) = (norm.mean[0], (norm.var[0] + 1e-8).sqrt());
            for (o, &x) in out.iter_mut().zip(r) {
                *o += ((x as f64 - mean) / std).clamp(-self.config.clip, self.config.clip);
            }
        }
        let k = self.norms.len() as f64;
        for (i, o) in out.iter_mut().enumerate() {
            let a = &actions[i * act_dim..(i + 1) * act_dim];
            *o = *o / k - self.config.ctrl_coeff * a.iter().map(|&x| (x as f64).powi(2)).sum::<f64>();
        }
        out
    }

    pub fn save(&self, dir: &Path, hyper: serde_json::Value) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        save_weights(&self.stores.iter().collect::<Vec<_>>(), &dir.join(WEIGHTS))?;
        let side = Sidecar { format: FORMAT.into(), config: self.config.clone(), norms: self.norms.clone(), hyper };
        write_json(&dir.join(SIDECAR), &side)
    }

    pub fn load(dir: &Path) -> Result<Self> {
        let side_path = dir.join(SIDECAR);
        let side: Sidecar = read_json(&side_path)?;
        if side.format != FORMAT {
            return Err(Error::file(&side_path, format!("format '{}' is not {FORMAT}", side.format)));
        }
        let mut r = RewardEnsemble::new(side.config);
        load_weights(&r.stores.iter().collect::<Vec<_>>(), &dir.join(WEIGHTS), &side_path)?;
        if side.norms.len() == r.nets.len() {
            r.norms = side.norms;
        }
        Ok(r)
    }
}
