//! The Gaussian policy with a state-independent log-std, its optional value network, and
//! their save/load. BC uses the actor alone (4 x 256 ReLU, deterministic mean), PPO the full
//! actor-critic (separate 64-64 tanh actor and critic, orthogonal initialisation).
use std::path::Path;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use tch::{Device, Kind, Tensor, nn, nn::Module};

use super::dense::Dense;
use super::sidecar::{check_size, load_weights, mlp_parameters, parse_json, save_weights, weights_bytes, write_json};
use super::{Activation, Init, Mlp, WeightInit};
use crate::data::normalize::RunningMeanStd;
use crate::error::{Error, Result};

pub const WEIGHTS: &str = "policy.safetensors";
pub const SIDECAR: &str = "policy.json";
const FORMAT: &str = "idrex-policy/1";

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PolicyConfig {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub hidden: Vec<usize>,
    pub activation: Activation,
    /// A separate value network with the same hidden sizes.
    pub critic: bool,
    /// Orthogonal initialisation (gains sqrt 2, 0.01 actor output, 1 critic output).
    pub orthogonal_init: bool,
    /// The initialisation otherwise.
    #[serde(default)]
    pub init: WeightInit,
    pub log_std_init: f64,
}

impl PolicyConfig {
    /// CleanRL's continuous-action PPO agent.
    pub fn ppo(obs_dim: usize, act_dim: usize) -> Self {
        PolicyConfig {
            obs_dim,
            act_dim,
            hidden: vec![64, 64],
            activation: Activation::Tanh,
            critic: true,
            orthogonal_init: true,
            init: WeightInit::TorchDefault,
            log_std_init: 0.0,
        }
    }
    /// D-REX's behavioural-cloning network.
    pub fn bc(obs_dim: usize, act_dim: usize) -> Self {
        PolicyConfig {
            obs_dim,
            act_dim,
            hidden: vec![256; 4],
            activation: Activation::Relu,
            critic: false,
            orthogonal_init: false,
            init: WeightInit::TorchDefault,
            log_std_init: 0.0,
        }
    }
    fn sizes(&self, out: usize) -> Vec<i64> {
        std::iter::once(self.obs_dim).chain(self.hidden.iter().copied()).chain([out]).map(|x| x as i64).collect()
    }
}

/// What `policy.json` holds.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Sidecar {
    format: String,
    config: PolicyConfig,
    env: Option<String>,
    obs_norm: Option<RunningMeanStd>,
    obs_clip: f64,
    hyper: serde_json::Value,
}

pub struct ActorCritic {
    pub vs: nn::VarStore,
    pub actor: Mlp,
    pub critic: Option<Mlp>,
    pub log_std: Tensor,
    pub config: PolicyConfig,
    /// Observations are normalised with these statistics (clipped to +-obs_clip) before the
    /// networks see them; None for raw observations.
    pub obs_norm: Option<RunningMeanStd>,
    pub obs_clip: f64,
    pub env: Option<String>,
}

impl ActorCritic {
    /// A fresh network; build it inside [`crate::nn::seeded`] for reproducible weights.
    pub fn new(config: PolicyConfig) -> Self {
        let vs = nn::VarStore::new(Device::Cpu);
        let root = vs.root();
        let init = |g| if config.orthogonal_init { Init::Orthogonal { out_gain: g } } else { config.init.init() };
        let actor = Mlp::new(&(&root / "actor"), &config.sizes(config.act_dim), config.activation, init(0.01));
        let critic = config.critic.then(|| Mlp::new(&(&root / "critic"), &config.sizes(1), config.activation, init(1.0)));
        let log_std = root.var("log_std", &[config.act_dim as i64], nn::Init::Const(config.log_std_init));
        ActorCritic { vs, actor, critic, log_std, config, obs_norm: None, obs_clip: 10.0, env: None }
    }

    pub fn mean(&self, obs: &Tensor) -> Tensor {
        self.actor.forward(obs)
    }

    pub fn value(&self, obs: &Tensor) -> Tensor {
        self.critic.as_ref().expect("this policy has no critic").forward(obs).squeeze_dim(-1)
    }

    /// log N(a; mean, exp(log_std)) summed over action dimensions, and the entropy.
    pub fn log_prob_entropy(&self, obs: &Tensor, actions: &Tensor) -> (Tensor, Tensor) {
        let mean = self.mean(obs);
        let log_std = self.log_std.expand_as(&mean);
        let z = (actions - &mean) / log_std.exp();
        let half_log_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
        let log_prob = (z.square() * -0.5 - &log_std - half_log_2pi).sum_dim_intlist(-1, false, Kind::Float);
        let entropy = (log_std + 0.5 + half_log_2pi).sum_dim_intlist(-1, false, Kind::Float);
        (log_prob, entropy)
    }

    /// Writes `policy.safetensors` and `policy.json` into `dir`.
    pub fn save(&self, dir: &Path, hyper: serde_json::Value) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        save_weights(&[&self.vs], &dir.join(WEIGHTS))?;
        let sidecar = Sidecar {
            format: FORMAT.into(),
            config: self.config.clone(),
            env: self.env.clone(),
            obs_norm: self.obs_norm.clone(),
            obs_clip: self.obs_clip,
            hyper,
        };
        write_json(&dir.join(SIDECAR), &sidecar)
    }

    /// A sidecar's text checked before anything is built: its format, its normalisation's
    /// dimensions, and that the weights file (`weights_bytes` long) can hold the network it
    /// describes.
    pub fn check_sidecar(side_path: &Path, text: &str, weights_bytes: u64) -> Result<Sidecar> {
        let side: Sidecar = parse_json(side_path, text)?;
        if side.format != FORMAT {
            return Err(Error::file(side_path, format!("format '{}' is not {FORMAT}", side.format)));
        }
        if let Some(n) = &side.obs_norm
            && n.dim() != side.config.obs_dim
        {
            return Err(Error::file(side_path, format!("obs_norm has {} dims, obs_dim is {}", n.dim(), side.config.obs_dim)));
        }
        let c = &side.config;
        let actor = mlp_parameters(&std::iter::once(c.obs_dim).chain(c.hidden.iter().copied()).chain([c.act_dim]).collect::<Vec<_>>());
        check_size(side_path, actor.and_then(|a| a.checked_add(c.act_dim as u64)), weights_bytes)?;
        Ok(side)
    }

    pub fn load(dir: &Path) -> Result<Self> {
        let side_path = dir.join(SIDECAR);
        let text = std::fs::read_to_string(&side_path).map_err(|e| Error::io(&side_path, e))?;
        let side = Self::check_sidecar(&side_path, &text, weights_bytes(&dir.join(WEIGHTS))?)?;
        let mut p = crate::nn::building(|| ActorCritic::new(side.config));
        load_weights(&[&p.vs], &dir.join(WEIGHTS), &side_path)?;
        p.obs_norm = side.obs_norm;
        p.obs_clip = side.obs_clip;
        p.env = side.env;
        Ok(p)
    }

    /// Fails with a clear message unless the policy fits an environment of these dimensions.
    pub fn expect_dims(&self, obs_dim: usize, act_dim: usize, what: &str) -> Result<()> {
        if (self.config.obs_dim, self.config.act_dim) != (obs_dim, act_dim) {
            return Err(Error::Invalid(format!(
                "{what}: the policy takes {} observations and gives {} actions, the environment has {obs_dim} and {act_dim}",
                self.config.obs_dim, self.config.act_dim
            )));
        }
        Ok(())
    }

    /// A frozen copy for fast per-step acting in rollouts.
    pub fn to_cpu(&self) -> CpuPolicy {
        CpuPolicy {
            actor: self.actor.to_cpu(),
            critic: self.critic.as_ref().map(|c| c.to_cpu()),
            log_std: Vec::try_from(self.log_std.detach()).expect("f32 log_std"),
            obs_norm: self.obs_norm.clone(),
            obs_clip: self.obs_clip,
        }
    }
}

/// A policy evaluated in plain Rust, one observation at a time.
#[derive(Debug, Clone)]
pub struct CpuPolicy {
    pub actor: Dense,
    pub critic: Option<Dense>,
    pub log_std: Vec<f32>,
    pub obs_norm: Option<RunningMeanStd>,
    pub obs_clip: f64,
}

impl CpuPolicy {
    pub fn obs_dim(&self) -> usize {
        self.actor.input_dim()
    }
    pub fn act_dim(&self) -> usize {
        self.actor.output_dim()
    }

    /// The network input for a raw observation.
    pub fn normalize(&self, obs: &[f32], out: &mut [f32]) {
        out.copy_from_slice(obs);
        if let Some(n) = &self.obs_norm {
            n.normalize(out, self.obs_clip);
        }
    }

    /// Mean action for an already normalised observation.
    pub fn mean(&self, nobs: &[f32], out: &mut [f32], scratch: &mut Vec<f32>) {
        self.actor.forward_row(nobs, out, scratch);
    }

    pub fn value(&self, nobs: &[f32], scratch: &mut Vec<f32>) -> f32 {
        let mut v = [0.0f32];
        self.critic.as_ref().expect("this policy has no critic").forward_row(nobs, &mut v, scratch);
        v[0]
    }

    /// Samples from N(mean, exp(log_std)) into `out`, returning the log-probability.
    pub fn sample(&self, mean: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) -> f32 {
        let mut logp = 0.0f32;
        let half_log_2pi = 0.5 * (2.0 * std::f32::consts::PI).ln();
        for ((o, &m), &ls) in out.iter_mut().zip(mean).zip(&self.log_std) {
            let z: f32 = rng.sample(StandardNormal);
            *o = m + ls.exp() * z;
            logp += -0.5 * z * z - ls - half_log_2pi;
        }
        logp
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn save_load_round_trip_and_dimension_check() {
        let dir = std::env::temp_dir().join(format!("idrex-policy-{}", std::process::id()));
        tch::manual_seed(1);
        let mut p = ActorCritic::new(PolicyConfig::ppo(11, 3));
        p.obs_norm = Some(RunningMeanStd::new(11));
        p.save(&dir, serde_json::json!({"lr": 3e-4})).unwrap();
        let q = ActorCritic::load(&dir).unwrap();
        let x = Tensor::randn([2, 11], (Kind::Float, Device::Cpu));
        assert!(p.mean(&x).allclose(&q.mean(&x), 0.0, 0.0, false));
        assert!(q.expect_dims(17, 6, "HalfCheetah-v5").unwrap_err().to_string().contains("takes 11 observations"));
        // A sidecar that does not describe the weights is refused with both file names.
        let other = ActorCritic::new(PolicyConfig::ppo(17, 6));
        other.save(&dir.join("other"), serde_json::json!({})).unwrap();
        std::fs::copy(dir.join("other").join(SIDECAR), dir.join(SIDECAR)).unwrap();
        let err = ActorCritic::load(&dir).err().unwrap().to_string();
        assert!(err.contains("policy.safetensors") && err.contains("do not belong together"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
