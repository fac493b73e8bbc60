//! Pipeline files' schema, version 1: the structs a YAML file deserialises into, each field
//! documented here once (`docs/pipelines.md` is checked against them). Reading and checking
//! a file is [`crate::pipeline::load`].
mod bank;
pub mod error;
mod idrex;
pub mod schema;
pub mod settings;

use std::collections::BTreeMap;
use std::path::PathBuf;

use crate::algo::{bc::BcConfig, noise::NoiseToward, ppo::PpoConfig, trex::TrexConfig};
use crate::env::{EnvId, Horizon};
use crate::nn::DeviceChoice;
use crate::nn::reward::{Combine, CtrlAction, RewardLevel};
use crate::rollout::Acting;
pub use bank::BankConfig;
pub use idrex::{CloneConfig, CloneFilter, CloneLabels, CloneSource, IdrexConfig, SourceActing};

pub const SCHEMA_VERSION: u32 = 1;

/// The methods a pipeline can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    Bc,
    Drex,
    IdrexInterpolation,
    IdrexActionNoise,
    IdrexMultiBc,
}

impl Method {
    pub const ALL: [Method; 5] = [Method::Bc, Method::Drex, Method::IdrexInterpolation, Method::IdrexActionNoise, Method::IdrexMultiBc];
    pub fn name(self) -> &'static str {
        match self {
            Method::Bc => "bc",
            Method::Drex => "drex",
            Method::IdrexInterpolation => "idrex-interpolation",
            Method::IdrexActionNoise => "idrex-action-noise",
            Method::IdrexMultiBc => "idrex-multi-bc",
        }
    }

    /// The paper's column heading.
    pub fn label(self) -> &'static str {
        match self {
            Method::Bc => "BC",
            Method::Drex => "D-REX",
            Method::IdrexInterpolation => "iD-REX interp.",
            Method::IdrexActionNoise => "iD-REX action noise",
            Method::IdrexMultiBc => "iD-REX multi-BC",
        }
    }

    /// Its colour (RGB), the same in every figure and recording.
    pub fn colour(self) -> [u8; 3] {
        match self {
            Method::Bc => [127, 127, 127],
            Method::Drex => [31, 119, 180],
            Method::IdrexInterpolation => [255, 127, 14],
            Method::IdrexActionNoise => [44, 160, 44],
            Method::IdrexMultiBc => [214, 39, 40],
        }
    }

    /// The method whose stages a graph node belongs to (`r2/drex/ppo/0` -> D-REX).
    pub fn of_node(node: &str) -> Option<Method> {
        node.split('/').find_map(|part| Method::ALL.into_iter().find(|m| m.name() == part))
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DemonstratorConfig {
    /// PPO steps on the ground-truth reward (stopped early at target_return).
    pub steps: usize,
    /// Stop once an evaluation reaches this mean return, so the demonstrator stays mediocre.
    pub target_return: Option<f64>,
    /// Evaluate (5 episodes) every this many steps to check the target.
    pub eval_every: usize,
    /// The target's evaluation acts with the policy's mean action instead of sampling: the
    /// return then measures what a demonstrator acting with its mean (`demos.acting: mean`)
    /// or labelling with it (`sampled-mean-labels`) shows a cloner.
    pub eval_mean: bool,
}

impl Default for DemonstratorConfig {
    fn default() -> Self {
        DemonstratorConfig { steps: 200_000, target_return: None, eval_every: 20_480, eval_mean: false }
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DemosConfig {
    /// Rollouts of the demonstrator's policy.
    pub episodes: usize,
    /// How the demonstrator acts and what its steps record: `sampled` (its Gaussian, as the
    /// original code), `mean` (its mean action), or `sampled-mean-labels` (acts sampled,
    /// records the mean: DART's noise with noise-free labels).
    pub acting: Acting,
    /// Scales the demonstrator's sampled deviation from its mean action (1: its own standard
    /// deviation; 0.3 with `sampled-mean-labels` is DART's small noise around the mean).
    pub noise_scale: f64,
    /// Import instead: an MCAP in idrex's rollout schema or an NPZ with obs, actions,
    /// rewards, episode_lengths; a path relative to the pipeline file, or (for a study over
    /// several environments) a map from environment to path.
    pub from: Option<DemosFrom>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum DemosFrom {
    One(PathBuf),
    PerEnv(BTreeMap<String, PathBuf>),
}

impl DemosFrom {
    /// The file for `env`, relative to the pipeline file.
    pub fn for_env(&self, env: EnvId) -> Option<&PathBuf> {
        match self {
            DemosFrom::One(p) => Some(p),
            DemosFrom::PerEnv(m) => m.get(env.name()),
        }
    }
}

/// One environment, or a list: a study over several, each expanded with every method and seed.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Envs {
    One(String),
    Many(Vec<String>),
}

impl Envs {
    pub fn names(&self) -> Vec<&str> {
        match self {
            Envs::One(e) => vec![e.as_str()],
            Envs::Many(v) => v.iter().map(String::as_str).collect(),
        }
    }
}

impl Default for DemosConfig {
    fn default() -> Self {
        DemosConfig { episodes: 1, acting: Acting::Sampled, noise_scale: 1.0, from: None }
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseConfig {
    /// Epsilon levels of the D-REX epsilon-greedy schedule.
    pub schedule: Vec<f64>,
    /// Epsilon-greedy rollouts of BC per level.
    pub rollouts_per_level: usize,
    /// The BC that D-REX degrades (and iD-REX interpolation starts from). Absent: the `bc`
    /// stage's policy. Given and different from `bc`, a second BC stage, `drex/bc`: the BC
    /// baseline can then be the strongest BC while D-REX keeps the one it ranks best from
    /// (analysis/results/bc-levers/).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bc: Option<BcConfig>,
    /// Where D-REX's ranked rollouts, and every iD-REX iteration's, end: `task` (the task's
    /// termination, the original code's) or `fixed` (every rollout runs to the time limit;
    /// `ppo.horizon` is the same for PPO's training episodes). Evaluations use the task's.
    pub horizon: Horizon,
    /// What an epsilon-greedy step of D-REX's ranked rollouts takes instead of BC's action:
    /// `random` (a uniform random action, the original code's), `zero` (the zero action: the
    /// noisier, the stiller, so standing still ranks below moving as BC does) or `both` (both
    /// sets at every level). iD-REX's iterations keep `random`.
    pub toward: NoiseToward,
    /// Episodes of the zero action (the robot doing nothing) added to D-REX's ranked set below
    /// every level, labelled epsilon 1: ranked under each level at least `trex.min_margin` less
    /// noisy, and the floor of `reward.level: ranked-floor`, so standing still earns nothing.
    /// The D-REX code ranks no-op episodes lowest on Atari (`add_noop`); 0 (the default) adds
    /// none, as its MuJoCo code.
    pub still: usize,
    /// How the ranked rollouts are disturbed, each level its scale: `epsilon` (D-REX's; `toward`
    /// applies), or without its jitter `ou`, `held` or `weights` ([`crate::algo::noise::Disturbance`]).
    pub disturbance: crate::algo::noise::Disturbance,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        NoiseConfig {
            schedule: (0..20).map(|i| i as f64 * 0.05).collect(),
            rollouts_per_level: 5,
            bc: None,
            horizon: Horizon::Task,
            toward: NoiseToward::Random,
            still: 0,
            disturbance: Default::default(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Episodes per policy and per checkpoint (ground-truth reward, stochastic PPO
    /// policies; BC acts with its mean).
    pub episodes: usize,
    /// Warn (in the run's first and last lines and the report's answer) when BC's return ends
    /// below this fraction of its demonstrations' average, or below the average where that is
    /// negative: D-REX's ranking then has nothing near the demonstrations to extrapolate
    /// from. Not part of any key; `idrex report --bc-warning` sets the report's.
    pub bc_warning: f64,
}

impl Default for EvalConfig {
    fn default() -> Self {
        EvalConfig { episodes: 20, bc_warning: crate::algo::scoring::BC_WARNING }
    }
}

/// How PPO's reward is composed from the learned ensemble ([`crate::nn::reward::Composition`]). The defaults of
/// `level` and `ceiling` are the recommended reward (analysis/results/reward-level/, and
/// analysis/results/walker2d-reward/ for Walker2d), not the original code's:
/// `pipelines/*-original.yaml` spell the original's out.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RewardSettings {
    /// Control-cost coefficient subtracted from the learned reward (default per environment:
    /// 0.1 HalfCheetah, 0.001 Hopper and Walker2d, 0.5 Ant: D-REX's rule, each task's
    /// own control-cost weight; the original D-REX code sets none for Ant).
    pub ctrl_coeff: Option<f64>,
    /// mean, last-over-count (the original code), or min (pessimistic).
    pub combine: Combine,
    /// raw (the original code; the default), or clipped.
    pub ctrl_action: CtrlAction,
    /// Where each member is centred and scaled for RL: ranked-floor (fixed from D-REX's ranked
    /// set; the default) or running (PPO's own experience; the original code).
    pub level: RewardLevel,
    /// k in mean - k x the members' spread, a brake on exploitation (0: none, the default).
    pub disagreement: f64,
    /// A brake on exploitation: each member's raw reward per step is capped at the q-quantile
    /// of its values over D-REX's ranked set, for q in (0, 1] (default 0.75), or `none` (no
    /// cap: the original code).
    pub ceiling: Ceiling,
}

impl Default for RewardSettings {
    fn default() -> Self {
        RewardSettings {
            ctrl_coeff: None,
            combine: Combine::default(),
            ctrl_action: CtrlAction::default(),
            level: RewardLevel::RankedFloor,
            disagreement: 0.0,
            ceiling: Ceiling::Quantile(0.75),
        }
    }
}

/// `reward.ceiling`: a quantile, or the keyword `none`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Ceiling {
    /// No cap (the original code).
    Off(NoCeiling),
    /// The quantile q in (0, 1] at which each member is capped.
    Quantile(f64),
}

/// The keyword that turns the ceiling off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum NoCeiling {
    None,
}

impl Ceiling {
    /// The quantile, where there is a cap.
    pub fn quantile(self) -> Option<f64> {
        match self {
            Ceiling::Off(_) => None,
            Ceiling::Quantile(q) => Some(q),
        }
    }
}

/// Per-method overrides of the shared stage parameters (any subset of their fields).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct MethodOverrides {
    /// Any subset of `trex`'s fields, for this method's rewards.
    pub trex: Option<serde_json::Value>,
    /// Any subset of `ppo`'s fields, for this method's RL runs.
    pub ppo: Option<serde_json::Value>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PipelineFile {
    /// Schema version; must be 1.
    pub version: u32,
    /// Names the pipeline in reports (default: the file name).
    #[serde(default)]
    pub name: Option<String>,
    /// An environment, or a list of them (a study).
    pub env: Envs,
    /// Store directory, relative to the pipeline file (default: ./artifacts of the cwd), or
    /// an S3 URL `s3://bucket/prefix`.
    #[serde(default)]
    pub store: Option<String>,
    /// One RL run per seed (R = len).
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    /// Independent replicates of the whole pipeline, each with its own seeds for every stage
    /// ([`replicate_seed`]); a whole number from 1 to [`MAX_REPLICATES`] (default 1).
    #[serde(default)]
    pub replicates: Option<f64>,
    /// The index of this file's first replicate (default 0): files that share a `name` and
    /// split one study give disjoint ranges.
    #[serde(default)]
    pub first_replicate: Option<f64>,
    /// `test` declares the file a locked test set: once it has evaluated on its seeds, idrex
    /// refuses to evaluate any other configuration there (and this file on seeds another
    /// configuration used) without `--reuse-test-set`, and the report marks results
    /// obtained that way. Not part of any key.
    #[serde(default)]
    pub role: Purpose,
    /// The methods to run and report.
    #[serde(default = "default_methods")]
    pub methods: Vec<Method>,
    /// K: iD-REX runs iterations 1..K-1 after D-REX (K = 2 is the report's setting; at most
    /// 10).
    #[serde(default = "default_iterations")]
    pub iterations: usize,
    #[serde(default)]
    pub demonstrator: DemonstratorConfig,
    #[serde(default)]
    pub demos: DemosConfig,
    #[serde(default)]
    pub bc: BcConfig,
    #[serde(default)]
    pub noise: NoiseConfig,
    #[serde(default)]
    pub trex: TrexConfig,
    #[serde(default)]
    pub reward: RewardSettings,
    #[serde(default)]
    pub ppo: PpoConfig,
    #[serde(default)]
    pub eval: EvalConfig,
    #[serde(default)]
    pub idrex: IdrexConfig,
    /// The reward bench: a bank of gaits every learned reward of the file is scored on
    /// before PPO climbs it (`bank: {}` for the defaults; absent, none). Its stages' keys
    /// depend on the task and these settings only, so every study of a task shares one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bank: Option<BankConfig>,
    /// Per method, fields of `trex` and `ppo` that differ from the shared ones.
    #[serde(default)]
    pub overrides: BTreeMap<Method, MethodOverrides>,
    /// What each stage asks Slurm for (`--executor slurm`); not part of any key.
    #[serde(default)]
    pub slurm: SlurmConfig,
    /// Where BC, T-REX and PPO's learned reward compute: `auto` (the GPU where libtorch
    /// sees one), `cpu` or `cuda`. A GPU stage has `device: cuda` in its key.
    #[serde(default)]
    pub device: DeviceChoice,
    /// The variants the file runs as (`pipeline run` expands each into its own study,
    /// `[settings]` after the name; stages whose keys agree are computed once). Not part of
    /// any key: each variant's keys are those of the file with its settings written in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep: Option<settings::SweepConfig>,
}

/// What a pipeline file is for ([`PipelineFile::role`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Purpose {
    /// Tuning or exploration: its seeds may be reused.
    #[default]
    Study,
    /// A locked test set: its seeds are looked at once.
    Test,
}

/// A Slurm job's resources; unset fields fall back to `slurm.default`, then to the
/// cluster's defaults.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Resources {
    /// `--cpus-per-task`; also the stage's thread budget.
    pub cpus: Option<u32>,
    /// `--mem`, e.g. `4G`.
    pub mem: Option<String>,
    /// `--time`, e.g. `2:00:00`.
    pub time: Option<String>,
    /// `--gres=gpu:N`.
    pub gpus: Option<u32>,
}

impl Resources {
    /// `self`, with `base` filling what it leaves unset.
    pub fn or(&self, base: &Resources) -> Resources {
        Resources {
            cpus: self.cpus.or(base.cpus),
            mem: self.mem.clone().or_else(|| base.mem.clone()),
            time: self.time.clone().or_else(|| base.time.clone()),
            gpus: self.gpus.or(base.gpus),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SlurmConfig {
    pub default: Resources,
    /// Per stage kind (`trex`, `ppo`, `bc`, `eval`, `noise-rollouts`, ...).
    pub stages: BTreeMap<crate::pipeline::kind::StageKind, Resources>,
}

impl SlurmConfig {
    pub fn for_kind(&self, kind: crate::pipeline::kind::StageKind) -> Resources {
        self.stages.get(&kind).map_or_else(|| self.default.clone(), |r| r.or(&self.default))
    }
}

/// The most replicates one file may ask for.
pub const MAX_REPLICATES: usize = 1000;
/// The most iD-REX iterations a file may ask for (the report runs 2 and 3).
pub const MAX_ITERATIONS: usize = 10;

/// Seeds of replicate `r` are the file's seeds plus `r` times this: far beyond every offset
/// [`crate::seed::derive`] adds to a stage seed, so no replicate's streams meet another's.
pub const REPLICATE_STRIDE: u64 = 1_000_000_007;

/// The seed a stage of replicate `r` uses in place of the file's `seed`. Replicate 0 keeps
/// the file's seeds, so a file without replicates is its own replicate 0, and raising the
/// count reuses every stored replicate.
pub fn replicate_seed(seed: u64, r: usize) -> u64 {
    seed.wrapping_add(REPLICATE_STRIDE.wrapping_mul(r as u64))
}

fn default_seeds() -> Vec<u64> {
    vec![0, 1, 2]
}
fn default_methods() -> Vec<Method> {
    Method::ALL.to_vec()
}
fn default_iterations() -> usize {
    2
}
