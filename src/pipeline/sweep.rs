//! Sweeps: one pipeline file run as several variants, each the file with some fields set
//! (its `sweep:` block, the command line's `-S field=value` or `-S field=a,b,c`), as Hydra's
//! multirun and DVC's experiment queue run them. Each variant is a pipeline of its own, named
//! by what it sets (`halfcheetah[reward.ceiling=0.5]`) and recording its place in the sweep
//! in its evaluations ([`VariantTag`]); their graphs are joined, and a stage whose key is the
//! same in several variants is one node, computed once.
use std::collections::BTreeMap;
use std::path::Path;

use super::config::settings::{Setting, Source, parse_arg};
use super::graph::{Graph, expand};
use super::load::{ConfigError, Pipeline};
use super::stage::eval::VariantTag;

/// One variant: its label (the prefix of its own nodes' names) and its pipeline.
#[derive(Debug, Clone)]
pub struct Variant {
    pub label: String,
    pub pipeline: Pipeline,
}

/// A pipeline file as it runs: one variant, or a sweep's.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// The file with the command line's single-valued settings: its name, store, role.
    pub file: Pipeline,
    /// In order: named variants, then the grid's combinations.
    pub variants: Vec<Variant>,
    /// The study every variant is compared against.
    pub baseline: String,
}

/// A mistake in a `-S` argument, named as the file's would be.
fn arg_error(path: &Path, setting: String, message: String) -> ConfigError {
    ConfigError { file: path.into(), line: 0, column: 0, message, also: vec![], setting: Some(setting) }
}

impl Sweep {
    /// The file at `path` with the command line's `-S` arguments.
    pub fn load(path: &Path, args: &[String]) -> Result<Sweep, ConfigError> {
        Self::parse(path, &super::config::error::read(path)?, args)
    }

    pub fn parse(path: &Path, text: &str, args: &[String]) -> Result<Sweep, ConfigError> {
        let plain = Pipeline::parse(path, text)?;
        let (fixed, cli_axes) = command_line(path, args)?;
        let at = |keys: &[&str]| {
            let (line, column) = super::load::locate(text, keys);
            Source::Sweep { line, column }
        };
        let block = plain.spec.sweep.clone().unwrap_or_default();
        let mut named: Vec<(Option<String>, Vec<Setting>)> = block
            .variants
            .iter()
            .map(|(name, fields)| {
                let settings = fields
                    .iter()
                    .map(|(f, v)| Setting { path: f.clone(), value: v.clone(), source: at(&["sweep", "variants", name]) })
                    .collect();
                (Some(name.clone()), settings)
            })
            .collect();
        if named.is_empty() {
            named.push((None, Vec::new()));
        }
        let file_axes = block.grid.iter().map(|(f, vs)| (f.clone(), vs.iter().map(|v| (v.clone(), at(&["sweep", "grid", f]))).collect()));
        let axes: Vec<Axis> = file_axes.chain(cli_axes).collect();
        if let Some((f, _)) = axes.iter().find(|(_, vs)| vs.is_empty()) {
            return Err(error_at(path, text, &["sweep", "grid", f], format!("sweep.grid.{f} lists no value; give at least one")));
        }
        let combos = combinations(named, &axes);
        let name = plain.name.clone();
        let prefix: Vec<String> = fixed.iter().map(Setting::label).collect();
        let study = |own: &str| {
            let parts: Vec<&str> = prefix.iter().map(String::as_str).chain((!own.is_empty()).then_some(own)).collect();
            if parts.is_empty() { name.clone() } else { format!("{name}[{}]", parts.join(",").replace('/', "_")) }
        };
        let labels: Vec<String> = combos.iter().map(|(l, _)| l.join(",")).collect();
        // A combination that sets nothing is the file itself, under its own name.
        let names: Vec<String> = combos.iter().zip(&labels).map(|((_, own), l)| study(if own.is_empty() { "" } else { l })).collect();
        let baseline = match &block.baseline {
            Some(b) => {
                let i = labels.iter().position(|l| l == b || l.split(',').next() == Some(b.as_str())).ok_or_else(|| {
                    let message = format!("sweep.baseline `{b}` is no variant; name one of: {}", labels.join(", "));
                    error_at(path, text, &["sweep", "baseline"], message)
                })?;
                names[i].clone()
            }
            // `-S` alone: compared with the file as written.
            None if combos.len() == 1 && !fixed.is_empty() => name.clone(),
            None => names[(0..combos.len()).find(|&i| combos[i].1.is_empty()).unwrap_or(0)].clone(),
        };
        let mut variants = Vec::new();
        let mut problems: Vec<ConfigError> = Vec::new();
        for (((_, own), label), study) in combos.iter().zip(&labels).zip(&names) {
            let settings: Vec<Setting> = fixed.iter().chain(own).cloned().collect();
            let mut p = match Pipeline::parse_with(path, text, &settings) {
                Ok(p) => p,
                Err(e) => {
                    problems.push(e);
                    continue;
                }
            };
            p.name = study.clone();
            if !settings.is_empty() {
                p.variant = Some(VariantTag {
                    sweep: name.clone(),
                    label: if label.is_empty() { prefix.join(",") } else { label.clone() },
                    settings: settings.iter().map(Setting::label).collect(),
                    baseline: baseline.clone(),
                });
            }
            p.spec.sweep = None;
            let label = if label.is_empty() { "file".to_string() } else { label.replace('/', "_") };
            variants.push(Variant { label, pipeline: p });
        }
        if !problems.is_empty() {
            let mut first = problems.remove(0);
            first.also.extend(problems);
            return Err(first);
        }
        let mut seen = BTreeMap::new();
        if let Some(v) = variants.iter().find(|v| seen.insert(v.pipeline.name.clone(), ()).is_some()) {
            let set: Vec<String> = args.iter().map(|a| format!("-S {a}")).collect();
            let setting = if set.is_empty() { "sweep".to_string() } else { set.join(" ") };
            return Err(arg_error(path, setting, format!("two variants are both `{}`; list each value once", v.pipeline.name)));
        }
        let file = if fixed.is_empty() { plain } else { variants[0].pipeline.clone() };
        Ok(Sweep { file, variants, baseline })
    }

    /// Whether the file runs as more than itself (a sweep, or `-S` settings).
    pub fn is_sweep(&self) -> bool {
        self.variants.len() > 1 || self.variants[0].pipeline.variant.is_some()
    }

    /// Every variant's pipeline moved by `f` (a device, a replicate cut).
    pub fn map(self, mut f: impl FnMut(Pipeline) -> Result<Pipeline, String>) -> Result<Sweep, String> {
        let variants =
            self.variants.into_iter().map(|v| Ok(Variant { label: v.label, pipeline: f(v.pipeline)? })).collect::<Result<_, String>>()?;
        Ok(Sweep { file: f(self.file)?, variants, baseline: self.baseline })
    }

    /// The variants' graphs joined: a node whose key several variants share is one node. The
    /// baseline's nodes keep the names its file gives them; another variant's own nodes are
    /// named after it (`label/r0/drex/trex`).
    pub fn graph(&self) -> crate::Result<Graph> {
        if let [only] = self.variants.as_slice() {
            return expand(&only.pipeline);
        }
        let mut order: Vec<&Variant> = self.variants.iter().collect();
        order.sort_by_key(|v| v.pipeline.name != self.baseline);
        let mut out = Graph::default();
        let mut named: BTreeMap<String, String> = BTreeMap::new();
        for v in order {
            let g = expand(&v.pipeline)?;
            let keys = g.keys();
            let mut alias: BTreeMap<&str, String> = BTreeMap::new();
            for n in &g.nodes {
                let key = &keys[&n.name];
                let name = match named.get(key) {
                    Some(existing) => existing.clone(),
                    None => {
                        let name = if v.pipeline.name == self.baseline { n.name.clone() } else { format!("{}/{}", v.label, n.name) };
                        out.push(name.clone(), n.params.clone(), n.seed, n.inputs.map(|src| alias[src.as_str()].clone()));
                        named.insert(key.clone(), name.clone());
                        name
                    }
                };
                alias.insert(&n.name, name);
            }
        }
        Ok(out)
    }

    /// Per variant: its study's name, how many nodes it has and how many of them it shares
    /// with another variant (`pipeline plan`'s summary).
    pub fn shares(&self) -> crate::Result<Vec<(String, usize, usize)>> {
        let keyed: Vec<BTreeMap<String, String>> =
            self.variants.iter().map(|v| Ok(expand(&v.pipeline)?.keys())).collect::<crate::Result<_>>()?;
        Ok(self
            .variants
            .iter()
            .zip(&keyed)
            .enumerate()
            .map(|(i, (v, keys))| {
                let shared = keys.values().filter(|k| keyed.iter().enumerate().any(|(j, o)| j != i && o.values().any(|x| x == *k))).count();
                (v.pipeline.name.clone(), keys.len(), shared)
            })
            .collect())
    }
}

/// A swept field and its values, each with where it was written.
type Axis = (String, Vec<(serde_json::Value, Source)>);

/// The command line's `-S` arguments: single values (applied to every variant) and lists
/// (axes of the sweep).
fn command_line(path: &Path, args: &[String]) -> Result<(Vec<Setting>, Vec<Axis>), ConfigError> {
    let (mut fixed, mut axes) = (Vec::new(), Vec::new());
    for a in args {
        let (field, values) = parse_arg(a).map_err(|e| {
            let prefix = format!("-S {a}: ");
            arg_error(path, format!("-S {a}"), e.strip_prefix(&prefix).unwrap_or(&e).to_string())
        })?;
        match values.as_slice() {
            [one] => fixed.push(Setting { path: field, value: one.clone(), source: Source::CommandLine }),
            _ => axes.push((field, values.into_iter().map(|v| (v, Source::CommandLine)).collect())),
        }
    }
    Ok((fixed, axes))
}

/// Every named variant with every combination of the axes, the first axis slowest; a
/// combination's label is its variant's name and its axes' settings.
fn combinations(named: Vec<(Option<String>, Vec<Setting>)>, axes: &[Axis]) -> Vec<(Vec<String>, Vec<Setting>)> {
    let mut combos: Vec<(Vec<String>, Vec<Setting>)> = named.into_iter().map(|(n, s)| (n.into_iter().collect(), s)).collect();
    for (field, values) in axes {
        combos = combos
            .into_iter()
            .flat_map(|(label, s)| {
                values.iter().map(move |(v, src)| {
                    let setting = Setting { path: field.clone(), value: v.clone(), source: src.clone() };
                    let (mut label, mut s) = (label.clone(), s.clone());
                    label.push(setting.label());
                    s.push(setting);
                    (label, s)
                })
            })
            .collect();
    }
    combos
}

/// A mistake in the file's `sweep:` block, at `keys`.
fn error_at(path: &Path, text: &str, keys: &[&str], message: String) -> ConfigError {
    let (line, column) = super::load::locate(text, keys);
    ConfigError { file: path.into(), line, column, message, also: vec![], setting: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "version: 1\nname: s\nenv: Hopper-v5\nseeds: [0, 1]\nmethods: [bc, drex]\nnoise:\n  schedule: [0.0, 0.5, 1.0]\n";

    fn sweep(text: &str, args: &[&str]) -> Result<Sweep, ConfigError> {
        Sweep::parse(Path::new("p.yaml"), text, &args.iter().map(|a| a.to_string()).collect::<Vec<_>>())
    }

    fn names(s: &Sweep) -> Vec<&str> {
        s.variants.iter().map(|v| v.pipeline.name.as_str()).collect()
    }

    #[test]
    fn a_file_without_a_sweep_is_its_one_variant() {
        let s = sweep(FILE, &[]).unwrap();
        assert!(!s.is_sweep() && s.baseline == "s" && s.variants[0].pipeline.variant.is_none());
        let plain = Pipeline::parse(Path::new("p.yaml"), FILE).unwrap();
        assert_eq!(s.graph().unwrap().keys(), expand(&plain).unwrap().keys());
    }

    #[test]
    fn each_variant_is_the_file_with_its_settings_written_in() {
        let s = sweep(FILE, &["reward.ceiling=0.5,none"]).unwrap();
        assert_eq!(names(&s), ["s[reward.ceiling=0.5]", "s[reward.ceiling=none]"]);
        assert_eq!(s.baseline, "s[reward.ceiling=0.5]", "the first value, where no variant sets nothing");
        let by_hand = Pipeline::parse(Path::new("p.yaml"), &format!("{FILE}reward:\n  ceiling: none\n")).unwrap();
        let (ours, theirs) = (expand(&s.variants[1].pipeline).unwrap(), expand(&by_hand).unwrap());
        let (ok, tk) = (ours.keys(), theirs.keys());
        for n in &ours.nodes {
            match &n.params {
                crate::pipeline::stage::Params::Eval(e) => {
                    let tag = e.variant.as_ref().unwrap();
                    assert_eq!(
                        (tag.sweep.as_str(), tag.label.as_str(), tag.baseline.as_str()),
                        ("s", "reward.ceiling=none", "s[reward.ceiling=0.5]")
                    );
                    assert_eq!(e.pipeline, "s[reward.ceiling=none]");
                }
                _ => assert_eq!(ok[&n.name], tk[&n.name], "{}: the hand-written file's key", n.name),
            }
        }
        // Joined, the stages both variants share are one node each: BC's and T-REX's, not PPO's.
        let g = s.graph().unwrap();
        let keys = g.keys();
        assert_eq!(keys.values().collect::<std::collections::BTreeSet<_>>().len(), g.nodes.len(), "no key twice");
        assert!(g.get("drex/trex").is_some() && g.get("reward.ceiling=none/drex/trex").is_none());
        assert!(g.get("reward.ceiling=none/drex/ppo/1").is_some() && g.get("drex/ppo/1").is_some());
        assert_eq!(s.shares().unwrap()[1], ("s[reward.ceiling=none]".to_string(), 10, 5));
    }

    #[test]
    fn named_variants_and_a_grid_run_every_combination() {
        let text = format!(
            "{FILE}sweep:\n  variants:\n    shipped: {{}}\n    fixed: {{noise.horizon: fixed}}\n  grid:\n    trex.models: [2, 3]\n  baseline: shipped\n"
        );
        let s = sweep(&text, &["ppo.total_steps=2048"]).unwrap();
        assert_eq!(
            names(&s),
            [
                "s[ppo.total_steps=2048,fixed,trex.models=2]",
                "s[ppo.total_steps=2048,fixed,trex.models=3]",
                "s[ppo.total_steps=2048,shipped,trex.models=2]",
                "s[ppo.total_steps=2048,shipped,trex.models=3]"
            ]
        );
        assert_eq!(s.baseline, "s[ppo.total_steps=2048,shipped,trex.models=2]");
        let tag = s.variants[0].pipeline.variant.as_ref().unwrap();
        assert_eq!(tag.settings, ["ppo.total_steps=2048", "noise.horizon=fixed", "trex.models=2"]);
        assert!(s.variants.iter().all(|v| v.pipeline.spec.ppo.total_steps == 2048 && v.pipeline.spec.sweep.is_none()));
    }

    #[test]
    fn a_variant_that_sets_nothing_is_the_file_itself() {
        let text = format!("{FILE}sweep:\n  variants:\n    shipped: {{}}\n    running: {{reward.level: running}}\n");
        let s = sweep(&text, &[]).unwrap();
        assert_eq!(names(&s), ["s[running]", "s"]);
        assert_eq!(s.baseline, "s");
        assert!(s.variants[1].pipeline.variant.is_none());
        let plain = Pipeline::parse(Path::new("p.yaml"), FILE).unwrap();
        let file = expand(&plain).unwrap().keys();
        let g = s.graph().unwrap().keys();
        assert!(file.iter().all(|(n, k)| g.get(n) == Some(k)), "the file's nodes, under its names");
        // `-S` alone is compared with the file as written.
        assert_eq!(sweep(FILE, &["trex.models=2"]).unwrap().baseline, "s");
    }

    #[test]
    fn a_mistake_names_its_setting() {
        let e = |text: &str, args: &[&str]| sweep(text, args).unwrap_err().to_string();
        assert!(e(FILE, &["reward.ceiling=2"]).starts_with("p.yaml: -S reward.ceiling=2: reward.ceiling is 2"));
        assert!(e(FILE, &["trex.modls=2"]).contains("p.yaml: -S trex.modls=2: unknown field `modls`"));
        let grid = e(&format!("{FILE}sweep:\n  grid:\n    trex.modls: [2]\n"), &[]);
        assert!(grid.starts_with("p.yaml:10:5: sweep sets trex.modls=2: unknown field"), "{grid}");
        let base = e(&format!("{FILE}sweep:\n  grid:\n    trex.models: [2]\n  baseline: nope\n"), &[]);
        assert!(base.contains("sweep.baseline `nope` is no variant; name one of: trex.models=2"), "{base}");
        assert!(e(FILE, &["trex.models=2,2"]).contains("two variants are both `s[trex.models=2]`"));
        assert!(e(FILE, &["name=t"]).contains("name cannot be set by a sweep or -S"));
        assert!(e(&format!("{FILE}sweep:\n  grid:\n    trex.models: []\n"), &[]).contains("sweep.grid.trex.models lists no value"));
    }
}
