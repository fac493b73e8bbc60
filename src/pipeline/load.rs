//! Reading a pipeline file: YAML into the schema ([`crate::pipeline::config`]), then every
//! check, each mistake reported with the file, line and column and what to write instead,
//! before anything runs.
use std::path::{Path, PathBuf};

use crate::algo::{ppo::PpoConfig, trex::TrexConfig};
use crate::env::EnvId;
use crate::nn::reward::Composition;
use crate::nn::{Device, DeviceChoice};
use crate::pipeline::check::{self, Problems};
pub use crate::pipeline::config::error::{ConfigError, locate};
use crate::pipeline::config::settings::{self, Setting};
use crate::pipeline::config::*;

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
        let mut problems = Problems::new(path, text, settings);
        let spec = read(path, text, settings, &problems)?;
        let envs = check::envs(&spec, &mut problems);
        let env: Option<EnvId> = (envs.len() == spec.env.names().len()).then(|| envs.first().copied()).flatten();
        let replicates = check::replicates(&spec, &mut problems);
        check::sizes(&spec, &mut problems);
        check::noise(&spec, &mut problems);
        check::learners(&spec, settings, &mut problems);
        check::fields(&spec, &mut problems);
        let base = path.parent().unwrap_or(Path::new("."));
        let store = check::store(&spec, base, &mut problems);
        check::demo_files(&spec, &envs, base, &mut problems);
        if let Some(e) = problems.into_error() {
            return Err(e);
        }
        let env = env.expect("every environment parsed: no problem was found");
        let name = spec.name.clone().unwrap_or_else(|| path.file_stem().map_or("pipeline".into(), |s| s.to_string_lossy().into_owned()));
        let composition = Composition {
            ctrl_coeff: spec.reward.ctrl_coeff.unwrap_or(default_ctrl_coeff(env)),
            combine: spec.reward.combine,
            ctrl_action: spec.reward.ctrl_action,
            level: spec.reward.level,
            disagreement: spec.reward.disagreement,
            ceiling: spec.reward.ceiling.quantile(),
        };
        let device = spec.device.resolve();
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
            Some(v) => check::overridden(base, v).expect("validated at load"),
        }
    }
}

/// The file's YAML read into the schema (a non-finite number refused first, serde's message
/// given a hint), then `settings` applied.
fn read(path: &Path, text: &str, settings: &[Setting], problems: &Problems) -> Result<PipelineFile, ConfigError> {
    if let Ok(doc) = serde_yaml::from_str::<serde_yaml::Value>(text)
        && let Some(keys) = non_finite(&doc, &mut Vec::new())
    {
        let keys: Vec<&str> = keys.iter().map(String::as_str).collect();
        return Err(problems.at(&keys, format!("{} is not a finite number; write a finite value", keys.join("."))));
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
    match settings {
        [] => Ok(spec),
        _ => settings::apply(text, settings).map_err(|(i, message)| problems.of_setting(&settings[i], message)),
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
        EnvId::Ant | EnvId::AntNoCfrc => 0.5,
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
            "p.yaml:2:1: unknown environment 'Hopper-v9'; known environments: HalfCheetah-v5, Hopper-v5, Walker2d-v5, Ant-v5, Ant-v5-no-cfrc; write e.g. `env: Hopper-v5`"
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
