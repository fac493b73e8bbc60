//! The stage kinds a pipeline is made of. Each kind has one file here (the iD-REX rollout
//! stages are in [`idrex`]) holding its typed parameters, its typed metrics and its
//! body. This root keeps the kind enum, the context a body gets and the dispatch.
//!
//! A stage reads its inputs' artifact directories and writes into its own staging
//! directory; the runner publishes it. A node's parameters are a [`Params`] value; their
//! canonical JSON goes into the node's key, and its metrics are stored in the manifest as
//! JSON and read back through the same [`Metrics`] structs by plots and the report.
//!
//! The versions are [`StageKind::version`]'s (a test compares them). Each kind's inputs are
//! a struct declared beside its body (`PpoInputs`, ...; [`Inputs`] is their union), which
//! the graph fills and the runner resolves; the table's names are their recorded roles.
//!
//! | kind | version | inputs | outputs | file |
//! |---|---|---|---|---|
//! | demonstrator | 3 | - | policy/ | demos.rs |
//! | demos | 1 | policy | rollouts.mcap | demos.rs |
//! | demos-import | 1 | - (a file) | rollouts.mcap | demos.rs |
//! | bc | 3 | demos | policy/ | bc.rs |
//! | noise-rollouts | 1 | policy | rollouts.mcap | noise.rs |
//! | trex | 3 | set0..setN, demos | reward/ | trex.rs |
//! | ppo | 3 | reward, floor? | policy/, curve.csv | ppo.rs |
//! | eval | 2 | policy, reward?, demos | rollouts.mcap | eval.rs |
//! | interpolation-rollouts | 1 | `policy<r>, older<r>` | rollouts.mcap | idrex/interpolation.rs |
//! | action-noise-rollouts | 1 | `policy<r>` | rollouts.mcap | idrex/action_noise.rs |
//! | multi-bc-rollouts | 4 | `policy<r>, baseline<i>, reward, judge?, demos, eval<r>` | rollouts.mcap, clones.mcap | idrex/multi_bc.rs |
//! | bank-policy | 1 | - | policy/, checkpoints/ | bank.rs |
//! | bank | 1 | forward, backward | rollouts.mcap, bank.json | bank.rs |
//! | bank-score | 1 | reward, bank | - | bank.rs |
//! | probe | 3 | reward, floor? | policy/, curve.csv | probe.rs |
pub mod bank;
pub mod bc;
pub mod demos;
pub mod eval;
pub mod idrex;
pub mod noise;
pub mod ppo;
pub mod probe;
pub mod trex;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use indicatif::ProgressStyle;
use serde::{Deserialize, Serialize};
use serde_json::Value;

pub use super::kind::StageKind;
use super::role::Role;

use crate::data::Trajectory;
use crate::env::{Env, EnvId};
use crate::error::{Error, Result};
use crate::nn::{ActorCritic, Device};
use crate::rollout::mcap;
use crate::stats::ReturnStats;

pub const ROLLOUTS: &str = "rollouts.mcap";
pub const POLICY: &str = "policy";
pub const REWARD: &str = "reward";

/// Declares each stage kind's typed parameters and metrics and the dispatch to its body, so
/// that adding a kind is one line here, one in [`StageKind`], plus its file (the matches
/// over `StageKind` are exhaustive: a kind missing here does not compile).
macro_rules! stage_kinds {
    ($($kind:ident: $params:ty => $metrics:ty, $inputs:ident, $body:path;)*) => {
        /// A node's parameters, typed per stage kind.
        #[derive(Debug, Clone, PartialEq)]
        pub enum Params {
            $($kind($params),)*
        }

        impl Params {
            pub fn kind(&self) -> StageKind {
                match self { $(Params::$kind(_) => StageKind::$kind,)* }
            }

            /// The canonical JSON of the parameters: what goes into the key and the manifest.
            pub fn to_json(&self) -> Value {
                match self { $(Params::$kind(p) => serde_json::to_value(p),)* }.expect("parameters serialise")
            }

            pub fn from_json(kind: StageKind, v: &Value) -> Result<Self> {
                Ok(match kind { $(StageKind::$kind => Params::$kind(parse(kind, "params", v)?),)* })
            }
        }

        /// What a stage reports, typed per stage kind; stored in the manifest as JSON.
        #[derive(Debug, Clone, PartialEq)]
        pub enum Metrics {
            $($kind($metrics),)*
        }

        impl Metrics {
            pub fn to_json(&self) -> Value {
                match self { $(Metrics::$kind(m) => serde_json::to_value(m),)* }.expect("metrics serialise")
            }

            pub fn from_json(kind: StageKind, v: &Value) -> Result<Self> {
                Ok(match kind { $(StageKind::$kind => Metrics::$kind(parse(kind, "metrics", v)?),)* })
            }
        }

        /// A node's inputs, typed per stage kind (each kind's struct is declared beside its
        /// body with [`crate::stage_inputs!`]): `T` is a node's name in the graph, and an
        /// artifact directory when the stage runs.
        #[derive(Debug, Clone, PartialEq)]
        pub enum Inputs<T> {
            $($kind($inputs<T>),)*
        }

        impl<T> Inputs<T> {
            pub fn kind(&self) -> StageKind {
                match self { $(Inputs::$kind(_) => StageKind::$kind,)* }
            }

            /// (role, input): the roles are the names keys and manifests record.
            pub fn roles(&self) -> Vec<(Role, &T)> {
                match self { $(Inputs::$kind(i) => i.roles(),)* }
            }

            /// A `kind`'s inputs from their recorded roles (`node` names it in messages): a
            /// missing, repeated or unknown role is refused.
            pub fn from_roles(kind: StageKind, node: &str, inputs: impl IntoIterator<Item = (Role, T)>) -> Result<Self> {
                let mut named = Named::new(node, inputs)?;
                let out = match kind { $(StageKind::$kind => Inputs::$kind(<$inputs<T> as StageInputs<T>>::take(&mut named)?),)* };
                named.finish(kind.name())?;
                Ok(out)
            }
        }

        /// Runs a stage body on its own kind's inputs. Its outputs depend only on its
        /// parameters, seed and inputs: `ctx.threads` is a budget for work whose result does
        /// not depend on it.
        pub fn run(params: &Params, ctx: &StageCtx) -> Result<Metrics> {
            crate::nn::single_threaded();
            match (params, &ctx.inputs) {
                $((Params::$kind(p), Inputs::$kind(i)) => $body(p, i, ctx).map(Metrics::$kind),)*
                (p, i) => Err(Error::Invalid(format!("a {} stage was given a {} stage's inputs", p.kind().name(), i.kind().name()))),
            }
        }
    };
}

pub use super::inputs::NoInputs;
use super::inputs::{Named, StageInputs};
pub use bank::{BankPolicyInputs, ScoreInputs};
pub use bc::BcInputs;
pub use demos::DemosInputs;
pub use eval::EvalInputs;
pub use idrex::action_noise::ActionNoiseInputs;
pub use idrex::interpolation::InterpolationInputs;
pub use idrex::multi_bc::MultiBcInputs;
pub use noise::NoiseInputs;
pub use ppo::PpoInputs;
pub use trex::TrexInputs;

stage_kinds! {
    Demonstrator: demos::DemonstratorParams => demos::DemonstratorMetrics, NoInputs, demos::demonstrator;
    Demos: demos::DemosParams => RolloutSummary, DemosInputs, demos::demos;
    DemosImport: demos::ImportParams => RolloutSummary, NoInputs, demos::import;
    Bc: bc::BcParams => crate::algo::bc::BcReport, BcInputs, bc::run;
    NoiseRollouts: noise::NoiseParams => noise::NoiseMetrics, NoiseInputs, noise::run;
    Trex: trex::TrexParams => trex::TrexMetrics, TrexInputs, trex::run;
    Ppo: ppo::PpoParams => ppo::PpoMetrics, PpoInputs, ppo::run;
    Eval: eval::EvalParams => eval::EvalMetrics, EvalInputs, eval::run;
    InterpolationRollouts: idrex::interpolation::Params => DegradationMetrics, InterpolationInputs, idrex::interpolation::run;
    ActionNoiseRollouts: idrex::action_noise::Params => DegradationMetrics, ActionNoiseInputs, idrex::action_noise::run;
    MultiBcRollouts: idrex::multi_bc::Params => idrex::multi_bc::Metrics, MultiBcInputs, idrex::multi_bc::run;
    BankPolicy: bank::BankPolicyParams => bank::BankPolicyMetrics, NoInputs, bank::policy;
    Bank: bank::BankParams => bank::BankMetrics, BankPolicyInputs, bank::run;
    BankScore: bank::ScoreParams => crate::algo::bank::BankScore, ScoreInputs, bank::score;
    Probe: probe::ProbeParams => probe::ProbeMetrics, PpoInputs, probe::run;
}

impl<T> Inputs<T> {
    /// (role, input), as [`Inputs::roles`].
    pub fn iter(&self) -> std::vec::IntoIter<(Role, &T)> {
        self.roles().into_iter()
    }

    pub fn is_empty(&self) -> bool {
        self.roles().is_empty()
    }

    /// The same inputs, each through `f` (node names to keys or directories).
    pub fn try_map<U>(&self, mut f: impl FnMut(&T) -> Result<U>) -> Result<Inputs<U>> {
        let mapped = self.iter().map(|(role, t)| Ok((role, f(t)?))).collect::<Result<Vec<_>>>()?;
        Inputs::from_roles(self.kind(), "", mapped)
    }

    pub fn map<U>(&self, mut f: impl FnMut(&T) -> U) -> Inputs<U> {
        self.try_map(|t| Ok(f(t))).expect("the same roles make the same kind's inputs")
    }

    /// A `kind`'s inputs from the names a manifest or a Slurm definition records (`what`
    /// names the node in messages).
    pub fn from_recorded<'a>(kind: StageKind, what: &str, recorded: impl IntoIterator<Item = (&'a String, T)>) -> Result<Self> {
        let named = recorded.into_iter().map(|(name, t)| Ok((Role::recorded(name, what)?, t))).collect::<Result<Vec<_>>>()?;
        Inputs::from_roles(kind, what, named)
    }
}

impl Params {
    /// What identifies the computation, for the key: the parameters, less the path an
    /// imported file was read from (its content's digest is in them), so that a moved file,
    /// another checkout or another machine of a shared store finds the same artifacts. The
    /// manifest keeps the path ([`Params::to_json`]) as provenance.
    pub fn key_json(&self) -> Value {
        match self {
            Params::DemosImport(p) => serde_json::json!({ "env": p.env, "sha256": p.sha256 }),
            _ => self.to_json(),
        }
    }
}

/// The key a recorded manifest's definition hashes to, from its parameters' text as written
/// (`params_text`, an archive line's): most kinds key on every parameter, hashed from that
/// text so no float moves by an ulp; the rest (an import keys on its file's digest, not its
/// path) on what their kind says.
pub fn recorded_key(m: &crate::store::Manifest, params_text: &str) -> Result<String> {
    let kind = StageKind::parse(&m.kind).ok_or_else(|| Error::Invalid(format!("unknown stage kind '{}'", m.kind)))?;
    let keyed = Params::from_json(kind, &m.params)?.key_json();
    Ok(if keyed == m.params {
        crate::store::key_of_text(&m.kind, m.version, params_text, m.seed, &m.inputs)
    } else {
        crate::store::key(&m.kind, m.version, &keyed, m.seed, &m.inputs)
    })
}

impl Params {
    /// The device the stage computes on (the CPU for kinds that have no choice).
    pub fn device(&self) -> Device {
        match self {
            Params::Bc(p) => p.device,
            Params::Trex(p) => p.device,
            Params::Ppo(p) => p.device,
            Params::Probe(p) => p.run.device,
            Params::MultiBcRollouts(p) => p.device,
            _ => Device::Cpu,
        }
    }

    /// The CPU code path the stage's products take, for the manifest (information only:
    /// every path gives the same bytes): the f32 kernel variant, and where the stage trains
    /// in bf16, the bf16 path.
    pub fn cpu_path(&self) -> String {
        let kernel = crate::kernels::gemm::Kernel::active().name();
        match self {
            Params::Trex(p) if p.trex.precision == crate::kernels::bf16::Precision::Bf16 => {
                format!("{kernel}; bf16 {}", crate::kernels::bf16::Bf16Path::active().name())
            }
            _ => kernel.to_string(),
        }
    }
}

fn parse<T: serde::de::DeserializeOwned>(kind: StageKind, what: &str, v: &Value) -> Result<T> {
    T::deserialize(v).map_err(|e| Error::Invalid(format!("stored {} {what} do not match this idrex version: {e}", kind.name())))
}

/// A stored artifact read back through its stage's types.
#[derive(Debug, Clone)]
pub struct Typed {
    pub params: Params,
    pub metrics: Metrics,
}

impl Typed {
    /// A manifest file's text read into its stage's types; every refusal names `path`.
    pub fn parse(path: &Path, text: &str) -> Result<(crate::store::Manifest, Typed)> {
        let m: crate::store::Manifest = serde_json::from_str(text).map_err(|e| Error::file(path, e.to_string()))?;
        let typed = Typed::of(&m).map_err(|e| Error::file(path, e.to_string()))?;
        Ok((m, typed))
    }

    pub fn of(m: &crate::store::Manifest) -> Result<Typed> {
        let kind =
            StageKind::parse(&m.kind).ok_or_else(|| Error::Invalid(format!("artifact {}: unknown stage kind '{}'", m.key, m.kind)))?;
        Ok(Typed { params: Params::from_json(kind, &m.params)?, metrics: Metrics::from_json(kind, &m.metrics)? })
    }
}

/// What a stage body gets besides its parameters.
pub struct StageCtx<'a> {
    pub seed: u64,
    /// The stage's inputs' artifact directories.
    pub inputs: Inputs<PathBuf>,
    pub out: &'a Path,
    /// Threads the stage may use for work whose result does not depend on their number.
    pub threads: usize,
    pub progress: &'a indicatif::ProgressBar,
}

impl StageCtx<'_> {
    pub fn write_rollouts(&self, env: EnvId, trajs: &[Trajectory], learned: Option<&[Vec<f64>]>) -> Result<()> {
        let dt = Env::new(env)?.dt();
        mcap::write(&self.out.join(ROLLOUTS), env.name(), dt, trajs, learned)
    }
}

/// The rollouts of a stored input artifact. The runner verified its digests before the
/// stage started, so a file that fails to read here was written wrong: idrex's bug, not the
/// store's damage.
pub fn read_rollouts(dir: &Path) -> Result<Vec<Trajectory>> {
    let path = dir.join(ROLLOUTS);
    mcap::read(&path).map(|r| r.trajectories).map_err(|e| {
        Error::Invalid(format!(
            "cannot read {}, although it matches its recorded digest (a bug in idrex; please report it): {e}",
            path.display()
        ))
    })
}

pub fn load_policy(dir: &Path) -> Result<ActorCritic> {
    ActorCritic::load(&dir.join(POLICY))
}

/// A policy stored in `dir`, checked against the environment it will act in.
pub fn load_policy_for(dir: &Path, env: &Env, id: EnvId) -> Result<ActorCritic> {
    let p = load_policy(dir)?;
    p.expect_dims(env.obs_dim(), env.act_dim(), id.name())?;
    Ok(p)
}

/// The returns of a rollout set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolloutSummary {
    #[serde(flatten)]
    pub stats: ReturnStats,
    pub returns: Vec<f64>,
    pub lengths: Vec<usize>,
    /// Each episode's reward terms, where the stage knows them: evaluations and idrex's own
    /// demonstrations (absent from imported demonstrations and from stages before they were
    /// recorded; the report then reads the rollout files where it can).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terms: Option<EpisodeTerms>,
}

/// Per episode, the sum of each reward term ([`crate::env::RewardTerms`]).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeTerms {
    pub forward: Vec<f64>,
    pub ctrl: Vec<f64>,
    pub survive: Vec<f64>,
    pub contact: Vec<f64>,
}

impl EpisodeTerms {
    pub fn of(trajs: &[Trajectory]) -> Self {
        let sum = |f: fn(&crate::env::RewardTerms) -> f64| trajs.iter().map(|t| t.terms.iter().map(f).sum()).collect();
        EpisodeTerms {
            forward: sum(|s| s.reward_forward),
            ctrl: sum(|s| s.reward_ctrl),
            survive: sum(|s| s.reward_survive),
            contact: sum(|s| s.reward_contact),
        }
    }
}

impl RolloutSummary {
    pub fn of(trajs: &[Trajectory]) -> Self {
        let returns: Vec<f64> = trajs.iter().map(Trajectory::ret).collect();
        RolloutSummary { stats: ReturnStats::of(&returns), returns, lengths: trajs.iter().map(Trajectory::len).collect(), terms: None }
    }

    /// The same, with the episodes' reward terms.
    pub fn with_terms(self, trajs: &[Trajectory]) -> Self {
        RolloutSummary { terms: Some(EpisodeTerms::of(trajs)), ..self }
    }
}

/// Mean and std of the returns at one noise level: a point of a degradation curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DegradationLevel {
    pub noise: f64,
    pub mean: f64,
    pub std: f64,
    pub n: usize,
}

/// A count a stage key leaves out at 0 (`skip_serializing_if`), so that keys from before the
/// field existed stay as they were.
fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Per-noise-level mean and std of returns, in increasing noise.
pub fn degradation(trajs: &[Trajectory]) -> Vec<DegradationLevel> {
    let mut levels: BTreeMap<String, (f64, Vec<f64>)> = BTreeMap::new();
    for t in trajs {
        levels.entry(format!("{:.4}", t.meta.noise)).or_insert_with(|| (t.meta.noise, Vec::new())).1.push(t.ret());
    }
    levels
        .into_values()
        .map(|(noise, v)| {
            let s = ReturnStats::of(&v);
            DegradationLevel { noise, mean: s.mean, std: s.std, n: v.len() }
        })
        .collect()
}

/// The metrics of a rollout stage whose sets are ranked by noise level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DegradationMetrics {
    pub degradation: Vec<DegradationLevel>,
}

/// The progress callback PPO-based stages give [`crate::algo::ppo::train`].
pub fn ppo_progress<'a>(ctx: &'a StageCtx<'a>, total: usize) -> impl FnMut(&crate::algo::ppo::PpoProgress) + 'a {
    ctx.progress.set_length(total as u64);
    ctx.progress.set_style(bar_style());
    move |p| {
        ctx.progress.set_position(p.global_step as u64);
        if let Some(r) = p.episodic_return {
            ctx.progress.set_message(format!("true return {r:.0}"));
        }
    }
}

/// A running stage that knows its amount of work: a bar, percent and time left.
pub fn bar_style() -> ProgressStyle {
    ProgressStyle::with_template("  {spinner} {prefix:<30} {bar:20} {percent:>3}% eta {eta:>4} {wide_msg}").expect("template")
}
