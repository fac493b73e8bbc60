//! Every semantic check of a parsed pipeline file ([`crate::pipeline::load`] reads the YAML
//! and assembles the [`crate::pipeline::Pipeline`]): each mistake is collected with where it
//! was written, so that one run of a command lists them all.
use std::path::{Path, PathBuf};

use crate::algo::{ppo::Backend, ppo::PpoConfig, trex::TrexConfig, trex::TrexLoss};
use crate::env::EnvId;
use crate::pipeline::config::error::{ConfigError, locate};
use crate::pipeline::config::settings::{Setting, Source};
use crate::pipeline::config::*;

/// Stored bytes are idrex's own kernels' (the same on every processor); libtorch's PPO
/// update is a reference for the tests, not a stage.
const TCH_BACKEND: &str = "ppo.backend tch computes with libtorch's kernels, whose bytes depend on the processor, so no stage uses it; \
                           remove it (fused, the default, computes the same update)";

/// Where a mistake is reported: at the setting that gave the field (a sweep's line or the
/// command line's `-S`), else at the field's line and column in the file.
pub struct Problems<'a> {
    path: &'a Path,
    text: &'a str,
    settings: &'a [Setting],
    pub found: Vec<ConfigError>,
}

impl<'a> Problems<'a> {
    pub fn new(path: &'a Path, text: &'a str, settings: &'a [Setting]) -> Problems<'a> {
        Problems { path, text, settings, found: Vec::new() }
    }

    /// `message` about what setting `s` gave.
    pub fn of_setting(&self, s: &Setting, message: String) -> ConfigError {
        let file = self.path.into();
        match s.source {
            Source::CommandLine => ConfigError { file, line: 0, column: 0, message, also: vec![], setting: Some(s.describe()) },
            Source::Sweep { line, column } => {
                ConfigError { file, line, column, message: format!("{}: {message}", s.describe()), also: vec![], setting: None }
            }
        }
    }

    /// `message` about the field at `keys`.
    pub fn at(&self, keys: &[&str], message: String) -> ConfigError {
        match self.settings.iter().rev().find(|s| s.covers(keys)) {
            Some(s) => self.of_setting(s, message),
            None => {
                let (line, column) = locate(self.text, keys);
                ConfigError { file: self.path.into(), line, column, message, also: vec![], setting: None }
            }
        }
    }

    pub fn bad(&mut self, keys: &[&str], message: String) {
        let e = self.at(keys, message);
        self.found.push(e);
    }

    /// The first problem, carrying the others; None if there is none.
    pub fn into_error(mut self) -> Option<ConfigError> {
        if self.found.is_empty() {
            return None;
        }
        let mut first = self.found.remove(0);
        first.also = self.found;
        Some(first)
    }
}

/// The schema version, the environments (those that parse, in order), the seeds and methods.
pub fn envs(spec: &PipelineFile, p: &mut Problems) -> Vec<EnvId> {
    if spec.version != SCHEMA_VERSION {
        p.bad(&["version"], format!("schema version {} is not supported; write `version: {SCHEMA_VERSION}`", spec.version));
    }
    let mut envs: Vec<EnvId> = Vec::new();
    for name in spec.env.names() {
        match name.parse() {
            Ok(e) if envs.contains(&e) => p.bad(&["env"], format!("env lists {name} twice; list each environment once")),
            Ok(e) => envs.push(e),
            Err(e) => {
                let e: crate::Error = e;
                p.bad(&["env"], format!("{e}; write e.g. `env: Hopper-v5`"));
            }
        }
    }
    if spec.env.names().is_empty() {
        p.bad(&["env"], "env is an empty list; name at least one environment, e.g. `env: [Hopper-v5]`".into());
    }
    if spec.seeds.is_empty() {
        p.bad(&["seeds"], "seeds is empty; give at least one seed, e.g. `seeds: [0, 1, 2]`".into());
    }
    if spec.methods.is_empty() {
        p.bad(
            &["methods"],
            "methods is empty; list at least one of bc, drex, idrex-interpolation, idrex-action-noise, idrex-multi-bc".into(),
        );
    }
    envs
}

/// The replicates the file expands to (`first_replicate..first_replicate + replicates`).
pub fn replicates(spec: &PipelineFile, p: &mut Problems) -> std::ops::Range<usize> {
    let mut count = |v: Option<f64>, key: &str, least: f64| -> usize {
        match v {
            None => least as usize,
            Some(x) if x.fract() == 0.0 && x >= least && x <= MAX_REPLICATES as f64 => x as usize,
            Some(x) => {
                p.bad(&[key], format!("{key} is {x}; give a whole number from {least} to {MAX_REPLICATES}"));
                least as usize
            }
        }
    };
    let replicates = count(spec.replicates, "replicates", 1.0);
    let first = count(spec.first_replicate, "first_replicate", 0.0);
    first..first + replicates
}

/// Counts and sizes: iterations, episodes, batch sizes, the reward's ensemble and windows.
pub fn sizes(spec: &PipelineFile, p: &mut Problems) {
    if spec.iterations > MAX_ITERATIONS {
        // Found by the fuzz tests: K = 2075 expands to 39,416 stages.
        p.bad(&["iterations"], format!("iterations is {}; give at most {MAX_ITERATIONS} (the report runs 2 and 3)", spec.iterations));
    }
    let mut positive = |v: usize, keys: &[&str], what: &str| {
        if v == 0 {
            p.bad(keys, format!("{what} must be at least 1"));
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
    // The probe scores the last quarter of its updates: it needs 4 of them at least.
    if let Some(steps) = spec.bank.as_ref().and_then(|b| b.probe) {
        let batch = spec.ppo.num_envs * spec.ppo.num_steps;
        if steps < 4 * batch {
            p.bad(&["bank", "probe"], format!("bank.probe is {steps} steps, under 4 PPO updates of {batch}; give at least {}", 4 * batch));
        }
    }
}

/// The noise schedule, and T-REX's margin within its span.
pub fn noise(spec: &PipelineFile, p: &mut Problems) {
    let schedule = &spec.noise.schedule;
    if schedule.is_empty() {
        p.bad(
            &["noise", "schedule"],
            "the noise schedule is empty; give epsilon levels, e.g. `schedule: [0.0, 0.25, 0.5, 0.75, 1.0]`".into(),
        );
    } else if let Some(out) = schedule.iter().find(|e| !(0.0..=1.0).contains(*e)) {
        p.bad(&["noise", "schedule"], format!("epsilon {out} is outside [0, 1]"));
    } else {
        let span = schedule.iter().copied().fold(f64::NEG_INFINITY, f64::max) - schedule.iter().copied().fold(f64::INFINITY, f64::min);
        if spec.trex.min_margin > span + 1e-12 {
            p.bad(
                &["trex", "min_margin"],
                format!(
                    "min_margin {} is larger than the noise schedule's span {span}, so no pair can be formed; use at most {span}",
                    spec.trex.min_margin
                ),
            );
        }
    }
}

/// PPO's budget and backend, each method's overrides, and where the regression learner may
/// run; a test set's refusal of settings.
pub fn learners(spec: &PipelineFile, settings: &[Setting], p: &mut Problems) {
    let batch = spec.ppo.num_envs * spec.ppo.num_steps;
    if spec.ppo.total_steps < batch || batch == 0 {
        p.bad(
            &["ppo", "total_steps"],
            format!("ppo.total_steps {} is less than one rollout (num_envs x num_steps = {batch})", spec.ppo.total_steps),
        );
    }
    let trex_of = |v: &serde_json::Value| overridden::<TrexConfig>(&spec.trex, v);
    for (m, o) in &spec.overrides {
        if let Some(Err(e)) = o.trex.as_ref().map(trex_of) {
            p.bad(&["overrides", m.name(), "trex"], format!("overrides.{}.trex: {e}", m.name()));
        }
        match o.ppo.as_ref().map(|v| overridden::<PpoConfig>(&spec.ppo, v)) {
            Some(Err(e)) => p.bad(&["overrides", m.name(), "ppo"], format!("overrides.{}.ppo: {e}", m.name())),
            Some(Ok(c)) if c.backend == Backend::Tch => p.bad(&["overrides", m.name(), "ppo"], TCH_BACKEND.into()),
            _ => {}
        }
    }
    if spec.role == Purpose::Test && (!settings.is_empty() || spec.sweep.is_some()) {
        p.bad(
            &["role"],
            "role: test locks its seeds to one configuration; run a sweep or -S settings on tuning seeds, \
             and write the chosen settings into the test set's file"
                .into(),
        );
    }
    if spec.ppo.backend == Backend::Tch {
        p.bad(&["ppo", "backend"], TCH_BACKEND.into());
    }
    // The regression learner fits one noise curve: D-REX's one ranked set.
    let regressing = spec.methods.iter().filter(|m| !matches!(m, Method::Bc | Method::Drex)).find(|m| {
        let merged = spec.overrides.get(m).and_then(|o| o.trex.as_ref()).map_or(Ok(spec.trex.clone()), trex_of);
        merged.is_ok_and(|c| c.loss == TrexLoss::Regression)
    });
    if let Some(m) = regressing {
        let at: &[&str] = if spec.trex.loss == TrexLoss::Regression { &["trex", "loss"] } else { &["overrides", m.name(), "trex"] };
        p.bad(
            at,
            format!(
                "trex.loss: regression learns D-REX's reward from its one ranked set, and {} ranks several; set it for D-REX \
                 alone (`overrides: {{drex: {{trex: {{loss: regression}}}}}}`) or run D-REX without the iD-REX methods",
                m.name()
            ),
        );
    }
}

/// Fractions, scales and brakes: the BC warning, the demonstrator's noise, iD-REX's
/// rollouts, the reward's disagreement brake and ceiling, the clone filter.
pub fn fields(spec: &PipelineFile, p: &mut Problems) {
    if !(spec.eval.bc_warning.is_finite() && (0.0..=1.0).contains(&spec.eval.bc_warning)) {
        p.bad(&["eval", "bc_warning"], format!("eval.bc_warning {} is not a fraction; give one in [0, 1], e.g. 0.7", spec.eval.bc_warning));
    }
    if !(spec.demos.noise_scale.is_finite() && spec.demos.noise_scale >= 0.0) {
        p.bad(
            &["demos", "noise_scale"],
            format!("demos.noise_scale {} is not a scale; give a number of at least 0, e.g. 0.3", spec.demos.noise_scale),
        );
    }
    if spec.demos.from.is_some() && !spec.demos.acting.is_sampled() {
        p.bad(
            &["demos", "acting"],
            "demos.acting says how idrex's demonstrator acts, but demos.from imports the demonstrations; remove one".into(),
        );
    }
    if spec.idrex.rollouts_per_level == 0 || spec.idrex.multi_bc_rollouts_per_level == 0 {
        p.bad(&["idrex"], "idrex rollouts per level must be at least 1".into());
    }
    if !(spec.reward.disagreement.is_finite() && spec.reward.disagreement >= 0.0) {
        p.bad(&["reward", "disagreement"], format!("reward.disagreement is {}; give k >= 0 (0: no brake)", spec.reward.disagreement));
    }
    if let Some(q) = spec.reward.ceiling.quantile().filter(|q| !(*q > 0.0 && *q <= 1.0)) {
        p.bad(&["reward", "ceiling"], format!("reward.ceiling is {q}; give a quantile in (0, 1], e.g. 0.75, or `none` for no cap"));
    }
    if let Err(e) = spec.idrex.multi_bc.check() {
        p.bad(&["idrex", "multi_bc"], e);
    }
}

/// The store the file names, relative to its directory `base` (`artifacts` by default).
pub fn store(spec: &PipelineFile, base: &Path, p: &mut Problems) -> crate::store::Location {
    let default = || crate::store::Location::Local(PathBuf::from("artifacts"));
    match spec.store.as_deref().map(crate::store::Location::parse) {
        None => default(),
        Some(Ok(l)) => l.relative_to(base),
        Some(Err(e)) => {
            p.bad(&["store"], e.to_string());
            default()
        }
    }
}

/// Imported demonstrations: a file per environment, each one present and loadable (bad
/// data is refused now, before any stage runs).
pub fn demo_files(spec: &PipelineFile, envs: &[EnvId], base: &Path, p: &mut Problems) {
    let Some(from) = &spec.demos.from else { return };
    if let DemosFrom::PerEnv(m) = from {
        for e in m.keys().filter(|e| !envs.iter().any(|x| x.name() == e.as_str())) {
            p.bad(&["demos", "from"], format!("demos.from names {e}, which is not in env; remove it or add it to env"));
        }
    }
    for &e in envs {
        let Some(file) = from.for_env(e) else {
            p.bad(&["demos", "from"], format!("demos.from has no file for {}; add `{}: PATH` under it", e.name(), e.name()));
            continue;
        };
        let path = base.join(file);
        if !path.is_file() {
            p.bad(
                &["demos", "from"],
                format!("demonstration file {} does not exist (the path is relative to the pipeline file)", path.display()),
            );
        } else if let Err(err) = crate::pipeline::stage::demos::load(&path, e) {
            p.bad(&["demos", "from"], format!("demonstration file {err}"));
        }
    }
}

/// A method's override (`overrides.<method>.trex`, `.ppo`) applied to the file's shared
/// section: the merged value read back as the section's type.
pub fn overridden<T: serde::Serialize + serde::de::DeserializeOwned>(base: &T, over: &serde_json::Value) -> serde_json::Result<T> {
    serde_json::from_value(merge(serde_json::to_value(base).expect("serialises"), over))
}

/// `over` merged into `base`, objects recursively.
fn merge(mut base: serde_json::Value, over: &serde_json::Value) -> serde_json::Value {
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
