//! Reading a pipeline file: YAML into the schema ([`crate::pipeline::config`]), then every
//! check, each mistake reported with the file, line and column and what to write instead,
//! before anything runs.
use std::path::{Path, PathBuf};

use crate::algo::{ppo::Backend, ppo::PpoConfig, trex::TrexConfig, trex::TrexLoss};
use crate::env::EnvId;
use crate::nn::reward::Composition;
use crate::nn::{Device, DeviceChoice};
pub use crate::pipeline::config::error::{ConfigError, locate};
use crate::pipeline::config::settings::{self, Setting, Source};
use crate::pipeline::config::*;

/// Stored bytes are idrex's own kernels' (the same on every processor); libtorch's PPO
/// update is a reference for the tests, not a stage.
const TCH_BACKEND: &str = "ppo.backend tch computes with libtorch's kernels, whose bytes depend on the processor, so no stage uses it; \
                           remove it (fused, the default, computes the same update)";

/// A validated pipeline with everything resolved.
#[derive(Debug, Clone)]
pub struct Pipeline {
    pub file: PathBuf,
    pub name: String,
    /// The environment this pipeline runs on (the first of a study's; see [`Pipeline::for_env`]).
    pub env: EnvId,
    /// Every environment of the file, in its order.
    pub envs: Vec<EnvId>,
    pub store: crate::store::Location,
    pub spec: PipelineFile,
    /// The reward PPO optimises on a learned ensemble.
    pub composition: Composition,
    /// The replicates this file expands to (`first_replicate..first_replicate + replicates`).
    pub replicates: std::ops::Range<usize>,
    /// The replicate this pipeline is ([`Pipeline::replicate`]; 0 for the file itself).
    pub replicate: usize,
    /// The file's `device`, resolved on this machine ([`Pipeline::on`] overrides it).
    pub device: Device,
    /// Which variant of a sweep this is (recorded in its evaluations); None for the file
    /// itself.
    pub variant: Option<crate::pipeline::stage::eval::VariantTag>,
}

impl Pipeline {
    pub fn load(path: &Path) -> Result<Pipeline, ConfigError> {
        Self::parse(path, &crate::pipeline::config::error::read(path)?)
    }

    pub fn parse(path: &Path, text: &str) -> Result<Pipeline, ConfigError> {
        Self::parse_with(path, text, &[])
    }

    /// The file `text` with `settings` applied ([`settings::apply`]; a sweep's variant or the
    /// command line's `-S`): each check on a field a setting gave names that setting.
    pub fn parse_with(path: &Path, text: &str, settings: &[Setting]) -> Result<Pipeline, ConfigError> {
        let error = |s: &Setting, message: String| match s.source {
            Source::CommandLine => {
                ConfigError { file: path.into(), line: 0, column: 0, message, also: vec![], setting: Some(s.describe()) }
            }
            Source::Sweep { line, column } => ConfigError {
                file: path.into(),
                line,
                column,
                message: format!("{}: {message}", s.describe()),
                also: vec![],
                setting: None,
            },
        };
        let at = |keys: &[&str], message: String| match settings.iter().rev().find(|s| s.covers(keys)) {
            Some(s) => error(s, message),
            None => {
                let (line, column) = locate(text, keys);
                ConfigError { file: path.into(), line, column, message, also: vec![], setting: None }
            }
        };
        if let Ok(doc) = serde_yaml::from_str::<serde_yaml::Value>(text)
            && let Some(keys) = non_finite(&doc, &mut Vec::new())
        {
            let keys: Vec<&str> = keys.iter().map(String::as_str).collect();
            return Err(at(&keys, format!("{} is not a finite number; write a finite value", keys.join("."))));
        }
        let spec: PipelineFile = serde_yaml::from_str(text).map_err(|e| {
            let (line, column) = e.location().map_or((0, 0), |l| (l.line(), l.column()));
            let msg = e.to_string();
            // serde_yaml appends " at line L column C"; we print the location first. It may
            // quote the file: a short excerpt is enough.
            let msg = msg.split(" at line ").next().unwrap_or(&msg).to_string();
            let msg = if msg.chars().count() > 200 { format!("{}…", msg.chars().take(200).collect::<String>()) } else { msg };
            let hint = if msg.contains("unknown field") {
                "; remove it or fix its spelling (the README lists every field)"
            } else if msg.contains("invalid type") {
                "; see the README's schema for the expected type"
            } else if msg.contains("unknown variant") {
                "; write one of the names listed"
            } else {
                ""
            };
            ConfigError { file: path.into(), line, column, message: format!("{msg}{hint}"), also: vec![], setting: None }
        })?;
        let spec = match settings {
            [] => spec,
            _ => settings::apply(text, settings).map_err(|(i, message)| error(&settings[i], message))?,
        };
        // Every semantic mistake is collected, so that one run of the command lists them all.
        let mut problems: Vec<ConfigError> = Vec::new();
        let mut bad = |keys: &[&str], message: String| problems.push(at(keys, message));
        if spec.version != SCHEMA_VERSION {
            bad(&["version"], format!("schema version {} is not supported; write `version: {SCHEMA_VERSION}`", spec.version));
        }
        let mut envs: Vec<EnvId> = Vec::new();
        for name in spec.env.names() {
            match name.parse() {
                Ok(e) if envs.contains(&e) => bad(&["env"], format!("env lists {name} twice; list each environment once")),
                Ok(e) => envs.push(e),
                Err(e) => {
                    let e: crate::Error = e;
                    bad(&["env"], format!("{e}; write e.g. `env: Hopper-v5`"));
                }
            }
        }
        if spec.env.names().is_empty() {
            bad(&["env"], "env is an empty list; name at least one environment, e.g. `env: [Hopper-v5]`".into());
        }
        let env: Option<EnvId> = (envs.len() == spec.env.names().len()).then(|| envs.first().copied()).flatten();
        if spec.seeds.is_empty() {
            bad(&["seeds"], "seeds is empty; give at least one seed, e.g. `seeds: [0, 1, 2]`".into());
        }
        if spec.methods.is_empty() {
            bad(
                &["methods"],
                "methods is empty; list at least one of bc, drex, idrex-interpolation, idrex-action-noise, idrex-multi-bc".into(),
            );
        }
        let mut count = |v: Option<f64>, key: &str, least: f64| -> usize {
            match v {
                None => least as usize,
                Some(x) if x.fract() == 0.0 && x >= least && x <= MAX_REPLICATES as f64 => x as usize,
                Some(x) => {
                    bad(&[key], format!("{key} is {x}; give a whole number from {least} to {MAX_REPLICATES}"));
                    least as usize
                }
            }
        };
        let replicates = count(spec.replicates, "replicates", 1.0);
        let first_replicate = count(spec.first_replicate, "first_replicate", 0.0);
        if spec.iterations > super::config::MAX_ITERATIONS {
            // Found by the fuzz tests: K = 2075 expands to 39,416 stages.
            bad(
                &["iterations"],
                format!("iterations is {}; give at most {} (the report runs 2 and 3)", spec.iterations, super::config::MAX_ITERATIONS),
            );
        }
        let mut positive = |v: usize, keys: &[&str], what: &str| {
            if v == 0 {
                bad(keys, format!("{what} must be at least 1"));
            }
        };
        positive(spec.iterations, &["iterations"], "iterations (K)");
        if spec.demos.from.is_none() {
            positive(spec.demos.episodes, &["demos", "episodes"], "demos.episodes (or give demos.from)");
            positive(spec.demonstrator.steps, &["demonstrator", "steps"], "demonstrator.steps");
        }
        positive(spec.bc.iterations, &["bc", "iterations"], "bc.iterations");
        positive(spec.bc.batch_size, &["bc", "batch_size"], "bc.batch_size");
        if let Some(bc) = &spec.noise.bc {
            positive(bc.iterations, &["noise", "bc", "iterations"], "noise.bc.iterations");
            positive(bc.batch_size, &["noise", "bc", "batch_size"], "noise.bc.batch_size");
        }
        positive(spec.eval.episodes, &["eval", "episodes"], "eval.episodes");
        positive(spec.noise.rollouts_per_level, &["noise", "rollouts_per_level"], "noise.rollouts_per_level");
        positive(spec.trex.models, &["trex", "models"], "trex.models");
        positive(spec.trex.iterations, &["trex", "iterations"], "trex.iterations");
        positive(spec.trex.window, &["trex", "window"], "trex.window");
        positive(spec.trex.pairs_per_model, &["trex", "pairs_per_model"], "trex.pairs_per_model");
        let mut bad = |keys: &[&str], message: String| problems.push(at(keys, message));
        if spec.noise.schedule.is_empty() {
            bad(
                &["noise", "schedule"],
                "the noise schedule is empty; give epsilon levels, e.g. `schedule: [0.0, 0.25, 0.5, 0.75, 1.0]`".into(),
            );
        } else if let Some(out) = spec.noise.schedule.iter().find(|e| !(0.0..=1.0).contains(*e)) {
            bad(&["noise", "schedule"], format!("epsilon {out} is outside [0, 1]"));
        } else {
            let span = spec.noise.schedule.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - spec.noise.schedule.iter().copied().fold(f64::INFINITY, f64::min);
            if spec.trex.min_margin > span + 1e-12 {
                bad(
                    &["trex", "min_margin"],
                    format!(
                        "min_margin {} is larger than the noise schedule's span {span}, so no pair can be formed; use at most {span}",
                        spec.trex.min_margin
                    ),
                );
            }
        }
        let batch = spec.ppo.num_envs * spec.ppo.num_steps;
        if spec.ppo.total_steps < batch || batch == 0 {
            bad(
                &["ppo", "total_steps"],
                format!("ppo.total_steps {} is less than one rollout (num_envs x num_steps = {batch})", spec.ppo.total_steps),
            );
        }
        for (m, o) in &spec.overrides {
            if let Some(v) = &o.trex
                && let Err(e) = serde_json::from_value::<TrexConfig>(merge(serde_json::to_value(&spec.trex).expect("serialises"), v))
            {
                bad(&["overrides", m.name(), "trex"], format!("overrides.{}.trex: {e}", m.name()));
            }
            match o
                .ppo
                .as_ref()
                .map(|v| serde_json::from_value::<PpoConfig>(merge(serde_json::to_value(&spec.ppo).expect("serialises"), v)))
            {
                Some(Err(e)) => bad(&["overrides", m.name(), "ppo"], format!("overrides.{}.ppo: {e}", m.name())),
                Some(Ok(c)) if c.backend == Backend::Tch => bad(&["overrides", m.name(), "ppo"], TCH_BACKEND.into()),
                _ => {}
            }
        }
        if spec.role == Role::Test && (!settings.is_empty() || spec.sweep.is_some()) {
            bad(
                &["role"],
                "role: test locks its seeds to one configuration; run a sweep or -S settings on tuning seeds, \
                 and write the chosen settings into the test set's file"
                    .into(),
            );
        }
        if spec.ppo.backend == Backend::Tch {
            bad(&["ppo", "backend"], TCH_BACKEND.into());
        }
        // The regression learner fits one noise curve: D-REX's one ranked set.
        let regressing = spec.methods.iter().filter(|m| !matches!(m, Method::Bc | Method::Drex)).find(|m| {
            let o = spec.overrides.get(m).and_then(|o| o.trex.as_ref());
            let merged = o.map_or(Ok(spec.trex.clone()), |v| {
                serde_json::from_value::<TrexConfig>(merge(serde_json::to_value(&spec.trex).expect("serialises"), v))
            });
            merged.is_ok_and(|c| c.loss == TrexLoss::Regression)
        });
        if let Some(m) = regressing {
            let at: &[&str] = if spec.trex.loss == TrexLoss::Regression { &["trex", "loss"] } else { &["overrides", m.name(), "trex"] };
            bad(
                at,
                format!(
                    "trex.loss: regression learns D-REX's reward from its one ranked set, and {} ranks several; set it for D-REX \
                     alone (`overrides: {{drex: {{trex: {{loss: regression}}}}}}`) or run D-REX without the iD-REX methods",
                    m.name()
                ),
            );
        }
        if !(spec.eval.bc_warning.is_finite() && (0.0..=1.0).contains(&spec.eval.bc_warning)) {
            bad(
                &["eval", "bc_warning"],
                format!("eval.bc_warning {} is not a fraction; give one in [0, 1], e.g. 0.7", spec.eval.bc_warning),
            );
        }
        if !(spec.demos.noise_scale.is_finite() && spec.demos.noise_scale >= 0.0) {
            bad(
                &["demos", "noise_scale"],
                format!("demos.noise_scale {} is not a scale; give a number of at least 0, e.g. 0.3", spec.demos.noise_scale),
            );
        }
        if spec.demos.from.is_some() && !spec.demos.acting.is_sampled() {
            bad(
                &["demos", "acting"],
                "demos.acting says how idrex's demonstrator acts, but demos.from imports the demonstrations; remove one".into(),
            );
        }
        if spec.idrex.rollouts_per_level == 0 || spec.idrex.multi_bc_rollouts_per_level == 0 {
            bad(&["idrex"], "idrex rollouts per level must be at least 1".into());
        }
        if !(spec.reward.disagreement.is_finite() && spec.reward.disagreement >= 0.0) {
            bad(&["reward", "disagreement"], format!("reward.disagreement is {}; give k >= 0 (0: no brake)", spec.reward.disagreement));
        }
        if let Some(q) = spec.reward.ceiling.quantile().filter(|q| !(*q > 0.0 && *q <= 1.0)) {
            bad(&["reward", "ceiling"], format!("reward.ceiling is {q}; give a quantile in (0, 1], e.g. 0.75, or `none` for no cap"));
        }
        if let Err(e) = spec.idrex.multi_bc.check() {
            bad(&["idrex", "multi_bc"], e);
        }
        let base = path.parent().unwrap_or(Path::new("."));
        let store = match &spec.store {
            None => crate::store::Location::Local(PathBuf::from("artifacts")),
            Some(s) => match crate::store::Location::parse(s) {
                Ok(l) => l.relative_to(base),
                Err(e) => {
                    bad(&["store"], e.to_string());
                    crate::store::Location::Local(PathBuf::from("artifacts"))
                }
            },
        };
        let name = spec.name.clone().unwrap_or_else(|| path.file_stem().map_or("pipeline".into(), |s| s.to_string_lossy().into_owned()));
        if let Some(DemosFrom::PerEnv(m)) = &spec.demos.from {
            for e in m.keys().filter(|e| !envs.iter().any(|x| x.name() == e.as_str())) {
                bad(&["demos", "from"], format!("demos.from names {e}, which is not in env; remove it or add it to env"));
            }
        }
        for &e in spec.demos.from.as_ref().map_or(&[][..], |_| &envs[..]) {
            let Some(from) = spec.demos.from.as_ref().and_then(|f| f.for_env(e)) else {
                bad(&["demos", "from"], format!("demos.from has no file for {}; add `{}: PATH` under it", e.name(), e.name()));
                continue;
            };
            let p = base.join(from);
            if !p.is_file() {
                bad(
                    &["demos", "from"],
                    format!("demonstration file {} does not exist (the path is relative to the pipeline file)", p.display()),
                );
            } else if let Err(err) = crate::pipeline::stage::demos::load(&p, e) {
                // Bad data is refused now, before any stage runs.
                bad(&["demos", "from"], format!("demonstration file {err}"));
            }
        }
        let (Some(env), true) = (env, problems.is_empty()) else {
            let mut first = problems.remove(0);
            first.also = problems;
            return Err(first);
        };
        let ctrl_coeff = spec.reward.ctrl_coeff.unwrap_or(default_ctrl_coeff(env));
        let composition = Composition {
            ctrl_coeff,
            combine: spec.reward.combine,
            ctrl_action: spec.reward.ctrl_action,
            level: spec.reward.level,
            disagreement: spec.reward.disagreement,
            ceiling: spec.reward.ceiling.quantile(),
        };
        let device = spec.device.resolve();
        let replicates = first_replicate..first_replicate + replicates;
        Ok(Pipeline { file: path.into(), name, env, envs, store, spec, composition, replicates, replicate: 0, device, variant: None })
    }

    /// This pipeline computing on the device `choice` resolves to (the command line's
    /// `--device`), whatever its file says.
    pub fn on(self, choice: DeviceChoice) -> Pipeline {
        Pipeline { device: choice.resolve(), ..self }
    }

    /// This pipeline on one of its environments (with that environment's defaults).
    pub fn for_env(&self, env: EnvId) -> Pipeline {
        let ctrl_coeff = self.spec.reward.ctrl_coeff.unwrap_or(default_ctrl_coeff(env));
        Pipeline { env, composition: Composition { ctrl_coeff, ..self.composition }, ..self.clone() }
    }

    /// Whether the file is a study over several environments (node names then start with
    /// the environment's).
    pub fn is_study(&self) -> bool {
        self.envs.len() > 1
    }

    /// Whether the file expands to more than one replicate, or to one other than replicate 0
    /// (node names then start with the replicate's, `r3/`).
    pub fn is_replicated(&self) -> bool {
        self.replicates != (0..1)
    }

    /// This pipeline cut to its replicate `r` alone (the same keys as in the whole run).
    pub fn only_replicate(self, r: usize) -> std::result::Result<Pipeline, String> {
        if !self.replicates.contains(&r) {
            return Err(format!("the file's replicates are {}..={}; give one of them", self.replicates.start, self.replicates.end - 1));
        }
        Ok(Pipeline { replicates: r..r + 1, ..self })
    }

    /// Replicate `r` of this pipeline: every stage's seed moved by [`replicate_seed`].
    pub fn replicate(&self, r: usize) -> Pipeline {
        let mut p = self.clone();
        p.spec.seeds = self.spec.seeds.iter().map(|&s| replicate_seed(s, r)).collect();
        p.replicate = r;
        p
    }

    /// The pipeline file's directory, against which relative paths resolve.
    pub fn base_dir(&self) -> &Path {
        self.file.parent().unwrap_or(Path::new("."))
    }

    /// Shared trex/ppo parameters with the method's overrides applied.
    pub fn trex_for(&self, m: Method) -> TrexConfig {
        self.with_override(&self.spec.trex, self.spec.overrides.get(&m).and_then(|o| o.trex.as_ref()))
    }
    pub fn ppo_for(&self, m: Method) -> PpoConfig {
        let mut cfg: PpoConfig = self.with_override(&self.spec.ppo, self.spec.overrides.get(&m).and_then(|o| o.ppo.as_ref()));
        cfg.horizon = cfg.horizon.on(self.env);
        cfg
    }
    fn with_override<T: serde::Serialize + serde::de::DeserializeOwned + Clone>(&self, base: &T, o: Option<&serde_json::Value>) -> T {
        match o {
            None => base.clone(),
            Some(v) => serde_json::from_value(merge(serde_json::to_value(base).expect("serialises"), v)).expect("validated at load"),
        }
    }
}

/// The key path of the first non-finite number (`.nan`, `.inf`) in a YAML document.
fn non_finite(v: &serde_yaml::Value, path: &mut Vec<String>) -> Option<Vec<String>> {
    match v {
        serde_yaml::Value::Number(n) if n.as_f64().is_some_and(|x| !x.is_finite()) => Some(path.clone()),
        serde_yaml::Value::Mapping(m) => m.iter().find_map(|(k, v)| {
            path.push(k.as_str().unwrap_or_default().to_string());
            let found = non_finite(v, path);
            path.pop();
            found
        }),
        serde_yaml::Value::Sequence(s) => s.iter().find_map(|v| non_finite(v, path)),
        _ => None,
    }
}

/// The control-cost coefficient of the learned reward when the file gives none (D-REX's).
pub fn default_ctrl_coeff(env: EnvId) -> f64 {
    match env {
        EnvId::HalfCheetah => 0.1,
        EnvId::Hopper | EnvId::Walker2d => 1e-3,
        // Not in D-REX's code; its rule (each task's control-cost weight) gives Ant's 0.5.
        EnvId::Ant => 0.5,
    }
}

/// `over` merged into `base`, objects recursively.
pub fn merge(mut base: serde_json::Value, over: &serde_json::Value) -> serde_json::Value {
    match (&mut base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (k, v) in o {
                let merged = merge(b.remove(k).unwrap_or(serde_json::Value::Null), v);
                b.insert(k.clone(), merged);
            }
            base
        }
        _ => over.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(yaml: &str) -> String {
        Pipeline::parse(Path::new("p.yaml"), yaml).unwrap_err().to_string()
    }

    const OK: &str = "version: 1\nenv: Hopper-v5\nnoise:\n  schedule: [0.0, 0.5, 1.0]\n";

    #[test]
    fn a_minimal_file_gets_the_reference_defaults() {
        let p = Pipeline::parse(Path::new("p.yaml"), OK).unwrap();
        assert_eq!(p.spec.seeds, vec![0, 1, 2]);
        assert_eq!(p.spec.bc.iterations, 50_000);
        assert_eq!(p.spec.trex.window, 50);
        assert_eq!(p.composition.ctrl_coeff, 1e-3);
    }

    #[test]
    fn every_mistake_in_a_file_is_reported_at_once() {
        let e = err("version: 1\nenv: Hopper-v5\nseeds: []\neval:\n  episodes: 0\nppo:\n  total_steps: 10\n");
        let lines: Vec<&str> = e.lines().collect();
        assert_eq!(lines.len(), 3, "{e}");
        assert!(lines[0].starts_with("p.yaml:3:") && lines[0].contains("seeds is empty"), "{e}");
        assert!(lines.iter().any(|l| l.contains("eval.episodes must be at least 1")), "{e}");
        assert!(lines.iter().any(|l| l.contains("less than one rollout")), "{e}");
    }

    #[test]
    fn each_class_of_mistake_has_its_message() {
        assert_eq!(err("version: 1\nenv: Hopper-v5\nbc:\n  iteratons: 5\n").split(": unknown field").next().unwrap(), "p.yaml:4:3: bc");
        assert!(err("version: 1\nenv: Hopper-v5\nbc:\n  iteratons: 5\n").contains("remove it or fix its spelling"));
        assert!(err("version: 1\nenv: Hopper-v5\nseeds: zero\n").contains("p.yaml:3:8: seeds: invalid type"));
        for (bad, why) in
            [("0", "replicates is 0"), ("-2", "replicates is -2"), ("2.5", "replicates is 2.5"), ("1001", "replicates is 1001")]
        {
            let e = err(&format!("version: 1\nenv: Hopper-v5\nreplicates: {bad}\n"));
            assert!(e.starts_with("p.yaml:3:1: ") && e.contains(why) && e.contains("whole number from 1 to 1000"), "{e}");
        }
        assert!(err("version: 1\nenv: Hopper-v5\nfirst_replicate: -1\n").contains("first_replicate is -1"));
        // A quoted bad value with a line break stays on the one line (found by the fuzz tests).
        assert_eq!(err("version: 1\nenv: Hopper-v5\nmethods: [\"drex\\nx\"]\n").lines().count(), 1);
        assert!(err("version: 1\nenv: Hopper-v5\niterations: 2075\n").contains("p.yaml:3:1: iterations is 2075; give at most 10"));
        assert!(err("version: 1\nenv: Hopper-v5\nppo:\n  backend: tch\n").contains("p.yaml:4:3: ppo.backend tch"));
        assert!(err("version: 1\nenv: Hopper-v5\ntrex:\n  loss: regression\n").contains("p.yaml:4:3: trex.loss: regression learns"));
        assert!(
            err("version: 1\nenv: Hopper-v5\noverrides:\n  idrex-multi-bc:\n    trex:\n      loss: regression\n")
                .contains("idrex-multi-bc ranks several")
        );
        assert!(
            err("version: 1\nenv: Hopper-v5\neval:\n  bc_warning: 70\n").starts_with("p.yaml:4:3: eval.bc_warning 70 is not a fraction")
        );
        assert!(err("version: 1\nenv: Hopper-v5\ndemos:\n  acting: mean\n  from: x.npz\n").contains("p.yaml:4:3: demos.acting says how"));
        assert!(err("version: 1\nenv: Hopper-v5\ndemos:\n  acting: noisy\n").contains("unknown variant `noisy`"));
        assert!(err("version: 1\nenv: Hopper-v5\noverrides:\n  drex:\n    ppo:\n      backend: tch\n").contains("ppo.backend tch"));
        assert_eq!(
            err("version: 1\nenv: Hopper-v9\n"),
            "p.yaml:2:1: unknown environment 'Hopper-v9'; known environments: HalfCheetah-v5, Hopper-v5, Walker2d-v5, Ant-v5; write e.g. `env: Hopper-v5`"
        );
        assert!(err("version: 1\nenv: Hopper-v5\nppo:\n  total_steps: -5\n").contains("p.yaml:4:16"));
        assert_eq!(
            err("version: 1\nenv: Hopper-v5\nnoise:\n  schedule: []\n").split(':').take(3).collect::<Vec<_>>().join(":"),
            "p.yaml:4:3"
        );
        assert!(
            err("version: 1\nenv: Hopper-v5\nnoise:\n  schedule: [0.0, 0.2]\ntrex:\n  min_margin: 0.3\n")
                .starts_with("p.yaml:6:3: min_margin 0.3 is larger than the noise schedule's span 0.2")
        );
        assert!(err("version: 2\nenv: Hopper-v5\n").contains("write `version: 1`"));
        assert!(err("version: 1\nenv: Hopper-v5\nmethods: [drex, gail]\n").contains("unknown variant `gail`"));
        assert!(
            err("version: 1\nenv: Hopper-v5\ndemos:\n  from: nowhere.npz\n")
                .contains("p.yaml:4:3: demonstration file nowhere.npz does not exist")
        );
        assert!(
            err("version: 1\nenv: Hopper-v5\noverrides:\n  drex:\n    ppo:\n      lr: fast\n").contains("p.yaml:5:5: overrides.drex.ppo")
        );
        assert_eq!(err("version: 1\nenv: Hopper-v5\nbc:\n  lr: .nan\n"), "p.yaml:4:3: bc.lr is not a finite number; write a finite value");
        assert!(
            err("version: 1\nenv: Hopper-v5\nnoise:\n  schedule: [0.0, .inf]\n").starts_with("p.yaml:4:3: noise.schedule is not a finite")
        );
        let noise = err("version: 1\nenv: Hopper-v5\nidrex:\n  action_noise: pink\n");
        assert!(noise.contains("unknown variant `pink`, expected one of `gaussian`, `ou`, `time-correlated`"), "{noise}");
    }
}
