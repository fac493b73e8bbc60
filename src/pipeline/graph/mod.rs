//! A pipeline file expanded into a DAG of stage instances, in topological order. Expansion
//! is pure: it reads the pipeline and builds typed parameters; nothing runs.
//!
//! ```text
//! demonstrator ─> demos ─> bc ─┬─> bc/eval
//!                              └─> drex/noise ─> drex/trex ─> drex/ppo/<r> ─> drex/eval/<r>
//!                                                   │              │
//!        iD-REX iteration k: rollouts from the iteration's policies ─> <variant>/k<k>/trex
//!                             ─> <variant>/k<k>/ppo/<r> ─> <variant>/k<k>/eval/<r>
//! ```
pub mod bank;
pub mod idrex;

use std::collections::BTreeMap;

use super::Pipeline;
use super::config::Method;
use super::stage::{BcInputs, DemosInputs, EvalInputs, Inputs, NoInputs, NoiseInputs, Params, PpoInputs, StageKind, TrexInputs};
use super::stage::{bc, demos, eval, noise, ppo, trex};
use crate::store;
use idrex::{DrexNodes, Variant};

#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Unique within the pipeline, e.g. `drex/ppo/1`.
    pub name: String,
    pub params: Params,
    pub seed: u64,
    /// The nodes it reads, by their names, typed by its kind.
    pub inputs: Inputs<String>,
}

impl Node {
    pub fn kind(&self) -> StageKind {
        self.params.kind()
    }
}

#[derive(Debug, Clone, Default)]
pub struct Graph {
    pub nodes: Vec<Node>,
}

impl Graph {
    pub fn get(&self, name: &str) -> Option<&Node> {
        self.nodes.iter().find(|n| n.name == name)
    }

    pub fn push(&mut self, name: impl Into<String>, params: Params, seed: u64, inputs: Inputs<String>) -> String {
        let name = name.into();
        debug_assert!(inputs.iter().all(|(_, i)| self.get(i).is_some()), "inputs come first");
        debug_assert_eq!(params.kind(), inputs.kind(), "{name}: parameters and inputs of one kind");
        self.nodes.push(Node { name: name.clone(), params, seed, inputs });
        name
    }

    /// Every node's key, computed in topological order from kind, version, parameters, seed
    /// and the keys of its inputs.
    pub fn keys(&self) -> BTreeMap<String, String> {
        let mut keys: BTreeMap<String, String> = BTreeMap::new();
        for n in &self.nodes {
            let inputs: BTreeMap<String, String> = n.inputs.iter().map(|(role, src)| (role.name(), keys[src].clone())).collect();
            let k = store::key(n.kind().name(), n.kind().version(), &n.params.key_json(), n.seed, &inputs);
            keys.insert(n.name.clone(), k);
        }
        keys
    }

    /// The nodes whose names start with `prefix` (a study's environment, `Hopper-v5/`), under
    /// their names without it: that environment's graph as [`expand_one`] builds it.
    pub fn subgraph(&self, prefix: &str) -> Graph {
        let strip = |n: &str| n.strip_prefix(prefix).map(str::to_string);
        let nodes = self
            .nodes
            .iter()
            .filter_map(|n| {
                let inputs =
                    n.inputs.iter().all(|(_, src)| strip(src).is_some()).then(|| n.inputs.map(|src| strip(src).unwrap_or_default()))?;
                Some(Node { name: strip(&n.name)?, params: n.params.clone(), seed: n.seed, inputs })
            })
            .collect();
        Graph { nodes }
    }

    /// The nodes named by `targets` and every node they (transitively) read, in the graph's
    /// order: what `pipeline run --target` computes. A target names a node, or every node
    /// whose name ends with `/target` (`drex/trex` is each replicate's); one that names none
    /// is refused.
    pub fn up_to(&self, targets: &[String]) -> Result<Graph, String> {
        let mut keep: std::collections::BTreeSet<&str> = Default::default();
        for t in targets {
            let hit: Vec<&str> =
                self.nodes.iter().filter(|n| n.name == *t || n.name.ends_with(&format!("/{t}"))).map(|n| n.name.as_str()).collect();
            if hit.is_empty() {
                return Err(format!("--target {t}: no node of the pipeline is named so (`idrex pipeline plan` lists them)"));
            }
            keep.extend(hit);
        }
        for n in self.nodes.iter().rev() {
            if keep.contains(n.name.as_str()) {
                keep.extend(n.inputs.iter().map(|(_, i)| i.as_str()));
            }
        }
        Ok(Graph { nodes: self.nodes.iter().filter(|n| keep.contains(n.name.as_str())).cloned().collect() })
    }

    /// The nodes that (transitively) depend on `name`, including itself.
    pub fn descendants(&self, name: &str) -> Vec<String> {
        let mut out = vec![name.to_string()];
        for n in &self.nodes {
            if n.inputs.iter().any(|(_, i)| out.contains(i)) && !out.contains(&n.name) {
                out.push(n.name.clone());
            }
        }
        out
    }
}

/// A T-REX node's parameters for `m` on the given ranked sets.
pub(super) fn trex_params(p: &Pipeline, m: Method, sets: Vec<trex::RankedSet>, cross_level: bool) -> Params {
    let mut cfg = p.trex_for(m);
    // On a task without contact forces in its observation, leaving them out changes nothing:
    // the key stays the one without the option.
    if p.env.spec().observed_contact().is_none() && cfg.observation == crate::algo::trex::RewardObservation::WithoutContactForces {
        cfg.observation = crate::algo::trex::RewardObservation::All;
    }
    Params::Trex(trex::TrexParams { env: p.env, trex: cfg, sets, cross_level, device: p.device })
}

fn eval_params(p: &Pipeline, method: Method, iteration: usize, run: usize) -> Params {
    Params::Eval(eval::EvalParams {
        env: p.env,
        episodes: p.spec.eval.episodes,
        pipeline: p.name.clone(),
        method,
        iteration,
        run,
        replicate: p.replicate,
        variant: p.variant.clone(),
    })
}

/// One RL run per seed of `m` on `reward`, each with its evaluation; returns the PPO nodes.
pub(super) fn rl_runs(g: &mut Graph, p: &Pipeline, m: Method, prefix: &str, iteration: usize, reward: &str, demos: &str) -> Vec<String> {
    p.spec
        .seeds
        .iter()
        .enumerate()
        .map(|(r, &seed)| {
            // D-REX's ranked set, the reward's first: where the ranked floor and the ceiling
            // are measured, for a composition that needs them.
            let floor = p.composition.needs_ranked_set().then(|| match g.get(reward).map(|n| &n.inputs) {
                Some(Inputs::Trex(t)) => t.sets[0].clone(),
                _ => unreachable!("a PPO run's reward is a T-REX node"),
            });
            let run = g.push(
                format!("{prefix}/ppo/{r}"),
                Params::Ppo(ppo::PpoParams { env: p.env, ppo: p.ppo_for(m), reward: p.composition, device: p.device }),
                seed,
                Inputs::Ppo(PpoInputs { reward: reward.to_string(), floor }),
            );
            g.push(
                format!("{prefix}/eval/{r}"),
                eval_params(p, m, iteration, r),
                seed,
                Inputs::Eval(EvalInputs { policy: run.clone(), demos: demos.to_string(), reward: Some(reward.to_string()) }),
            );
            run
        })
        .collect()
}

/// Expands a validated pipeline into its DAG. A study (several environments) is the union
/// of each environment's graph, its node names prefixed with the environment's name
/// (`Hopper-v5/drex/ppo/0`); a replicated file, the union of its replicates' graphs, named
/// `r<i>/` within each environment (`Hopper-v5/r3/drex/ppo/0`).
pub fn expand(p: &Pipeline) -> crate::Result<Graph> {
    expand_all(p).map_err(|e| match e {
        crate::Error::File { ref path, .. } if path == &p.file => e,
        // What the file asked for failed (a demonstrations file that cannot be read): the
        // refusal names the pipeline file too.
        other => crate::Error::file(&p.file, other.to_string()),
    })
}

fn expand_all(p: &Pipeline) -> crate::Result<Graph> {
    if !p.is_study() && !p.is_replicated() {
        return expand_one(p);
    }
    let mut g = Graph::default();
    for &env in &p.envs {
        for r in p.replicates.clone() {
            let sub = expand_one(&p.for_env(env).replicate(r))?;
            let mut prefix = String::new();
            if p.is_study() {
                prefix.push_str(&format!("{}/", env.name()));
            }
            if p.is_replicated() {
                prefix.push_str(&format!("r{r}/"));
            }
            // The bank is the task's, not a replicate's: one per environment.
            let env_prefix = if p.is_study() { format!("{}/", env.name()) } else { String::new() };
            let named = |n: &str| if bank::is_bank(n) { format!("{env_prefix}{n}") } else { format!("{prefix}{n}") };
            for n in sub.nodes {
                let inputs = n.inputs.map(|src| named(src));
                if bank::is_bank(&n.name) && g.get(&named(&n.name)).is_some() {
                    continue;
                }
                g.push(named(&n.name), n.params, n.seed, inputs);
            }
        }
    }
    Ok(g)
}

/// The graph of one environment's pipeline: its methods' stages, and with `bank`, the reward
/// bench's and a score of every learned reward on it.
pub fn expand_one(p: &Pipeline) -> crate::Result<Graph> {
    let mut g = expand_methods(p)?;
    if let Some(cfg) = &p.spec.bank {
        bank::expand(&mut g, p.env, cfg);
    }
    Ok(g)
}

fn expand_methods(p: &Pipeline) -> crate::Result<Graph> {
    let s = &p.spec;
    let env = p.env;
    let mut g = Graph::default();
    let seed0 = s.seeds[0];
    let wants = |m: Method| s.methods.contains(&m);
    let demos = match s.demos.from.as_ref().and_then(|f| f.for_env(env)) {
        Some(from) => {
            let path = p.base_dir().join(from);
            let (sha256, _) = store::sha256_file(&path)?;
            g.push("demos", Params::DemosImport(demos::ImportParams { env, path, sha256 }), seed0, Inputs::DemosImport(NoInputs::default()))
        }
        None => {
            let mut ppo = s.ppo.clone();
            ppo.total_steps = s.demonstrator.steps;
            ppo.eval_every = s.demonstrator.eval_every;
            ppo.eval_mean = s.demonstrator.eval_mean;
            // The demonstrator learns the task as it is.
            ppo.horizon = crate::env::Horizon::Task;
            let d = g.push(
                "demonstrator",
                Params::Demonstrator(demos::DemonstratorParams { env, ppo, target_return: s.demonstrator.target_return }),
                seed0,
                Inputs::Demonstrator(NoInputs::default()),
            );
            g.push(
                "demos",
                Params::Demos(demos::DemosParams {
                    env,
                    episodes: s.demos.episodes,
                    acting: s.demos.acting,
                    noise_scale: s.demos.noise_scale,
                }),
                seed0,
                Inputs::Demos(DemosInputs { policy: d }),
            )
        }
    };
    let bc_of = |demos: &str| Inputs::Bc(BcInputs { demos: demos.to_string() });
    let bc = g.push("bc", Params::Bc(bc::BcParams { env, bc: s.bc.clone(), device: p.device }), seed0, bc_of(&demos));
    if wants(Method::Bc) {
        let inputs = Inputs::Eval(EvalInputs { policy: bc.clone(), demos: demos.clone(), reward: None });
        g.push("bc/eval", eval_params(p, Method::Bc, 0, 0), seed0, inputs);
    }
    let variants: Vec<Variant> = Variant::ALL.into_iter().filter(|v| wants(v.method())).collect();
    if !wants(Method::Drex) && variants.is_empty() {
        return Ok(g);
    }
    // D-REX's own BC where the file gives one that differs from the baseline's.
    let source = match &s.noise.bc {
        Some(cfg) if *cfg != s.bc => {
            g.push("drex/bc", Params::Bc(bc::BcParams { env, bc: cfg.clone(), device: p.device }), seed0, bc_of(&demos))
        }
        _ => bc.clone(),
    };
    let noise = g.push(
        "drex/noise",
        Params::NoiseRollouts(noise::NoiseParams {
            env,
            schedule: s.noise.schedule.clone(),
            rollouts_per_level: s.noise.rollouts_per_level,
            horizon: s.noise.horizon.on(env),
            toward: s.noise.toward,
            still: s.noise.still,
            disturbance: s.noise.disturbance,
        }),
        seed0,
        Inputs::NoiseRollouts(NoiseInputs { policy: source.clone() }),
    );
    let drex_trex = g.push(
        "drex/trex",
        trex_params(p, Method::Drex, vec![trex::RankedSet { level: 0, same_group: false }], false),
        seed0,
        Inputs::Trex(TrexInputs { demos: demos.clone(), sets: vec![noise.clone()] }),
    );
    let drex_ppo = rl_runs(&mut g, p, Method::Drex, "drex", 1, &drex_trex, &demos);
    let drex = DrexNodes { demos: &demos, bc: &source, noise: &noise, trex: &drex_trex, ppo: &drex_ppo };
    for v in variants {
        idrex::expand(&mut g, p, v, &drex);
    }
    Ok(g)
}

/// How `idrex pipeline plan` prints the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum PlanFormat {
    #[default]
    Text,
    /// Graphviz.
    Dot,
    Mermaid,
}

/// A node's inputs, each source node once (in first-role order) with how many roles read it.
fn distinct_inputs(n: &Node) -> Vec<(&str, usize)> {
    let mut out: Vec<(&str, usize)> = Vec::new();
    for (_, src) in n.inputs.iter() {
        match out.iter_mut().find(|(s, _)| *s == src.as_str()) {
            Some((_, c)) => *c += 1,
            None => out.push((src.as_str(), 1)),
        }
    }
    out
}

/// The graph in `format`; `stored` says whether a key is in the store.
pub fn render(g: &Graph, keys: &BTreeMap<String, String>, stored: &dyn Fn(&str) -> bool, format: PlanFormat) -> String {
    let mut out = String::new();
    let id = |name: &str| name.replace(['/', '-'], "_");
    match format {
        PlanFormat::Dot => {
            out.push_str("digraph pipeline {\n  rankdir=LR;\n  node [shape=box, fontname=monospace];\n");
            for n in &g.nodes {
                let k = &keys[&n.name];
                let style = if stored(k) { ", style=filled, fillcolor=palegreen" } else { "" };
                out.push_str(&format!("  {} [label=\"{}\\n{}\\n{}\"{style}];\n", id(&n.name), n.name, n.kind().name(), &k[..12]));
                for (_, src) in n.inputs.iter() {
                    out.push_str(&format!("  {} -> {};\n", id(src), id(&n.name)));
                }
            }
            out.push_str("}\n");
        }
        PlanFormat::Mermaid => {
            out.push_str("flowchart LR\n");
            for n in &g.nodes {
                let k = &keys[&n.name];
                out.push_str(&format!(
                    "  {}[\"{}<br/>{} {}\"]\n",
                    id(&n.name),
                    n.name,
                    &k[..12],
                    if stored(k) { "stored" } else { "missing" }
                ));
                for (src, _) in distinct_inputs(n) {
                    out.push_str(&format!("  {} --> {}\n", id(src), id(&n.name)));
                }
                if stored(k) {
                    out.push_str(&format!("  style {} fill:#bfb\n", id(&n.name)));
                }
            }
        }
        PlanFormat::Text => {
            for n in &g.nodes {
                let k = &keys[&n.name];
                // A node read under several roles (interpolation's older policies) once, counted.
                let inputs: Vec<String> =
                    distinct_inputs(n).into_iter().map(|(s, c)| if c > 1 { format!("{s} x{c}") } else { s.to_string() }).collect();
                out.push_str(&format!(
                    "{:<8} {}  {:<38} {:<24} <- {}\n",
                    if stored(k) { "stored" } else { "missing" },
                    &k[..12],
                    n.name,
                    n.kind().name(),
                    if inputs.is_empty() { "-".to_string() } else { inputs.join(", ") }
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = "version: 1\nenv: Hopper-v5\nseeds: [0, 1]\nnoise:\n  schedule: [0.0, 0.5, 1.0]\n";

    /// The nodes whose keys differ when `extra` is added to the base file.
    fn changed(extra: &str) -> Vec<String> {
        let p = |text: &str| Pipeline::parse(std::path::Path::new("p.yaml"), text).unwrap();
        let (a, b) = (expand(&p(BASE)).unwrap().keys(), expand(&p(&format!("{BASE}{extra}"))).unwrap().keys());
        a.keys().filter(|n| a[*n] != b[*n]).cloned().collect()
    }

    /// The reward's level and the two brakes touch PPO only: exactly the PPO stages
    /// and what depends on them change (the stored rewards are reused); their defaults (the
    /// recommended reward) change nothing when spelled out.
    #[test]
    fn reward_options_change_exactly_the_rl_stages_and_what_follows() {
        let g = expand(&Pipeline::parse(std::path::Path::new("p.yaml"), BASE).unwrap()).unwrap();
        let mut expected: Vec<String> =
            g.nodes.iter().filter(|n| n.kind() == StageKind::Ppo).flat_map(|n| g.descendants(&n.name)).collect();
        expected.sort();
        expected.dedup();
        assert!(!expected.is_empty());
        for extra in
            ["reward:\n  level: running\n", "reward:\n  disagreement: 0.5\n", "reward:\n  ceiling: 0.99\n", "reward:\n  ceiling: none\n"]
        {
            let mut got = changed(extra);
            got.sort();
            assert_eq!(got, expected, "{extra}");
            // D-REX's reward and multi-BC's judge (trained on D-REX's sets) are reused.
            assert!(!got.iter().any(|n| n == "drex/trex" || n == "bc" || n.ends_with("/judge")), "{got:?}");
        }
        assert!(changed("reward:\n  level: ranked-floor\n  ceiling: 0.75\n  disagreement: 0\n").is_empty());
        // The ranked floor and the ceiling are measured on D-REX's set; the original's reward
        // (running, no cap) reads no set.
        let ppo_inputs = |extra: &str| {
            let p = Pipeline::parse(std::path::Path::new("p.yaml"), &format!("{BASE}{extra}")).unwrap();
            expand(&p).unwrap().get("drex/ppo/0").unwrap().inputs.clone()
        };
        let floor = |i: Inputs<String>| match i {
            Inputs::Ppo(p) => p.floor,
            other => panic!("{other:?}"),
        };
        for extra in ["", "reward:\n  ceiling: none\n", "reward:\n  level: running\n"] {
            assert_eq!(floor(ppo_inputs(extra)).as_deref(), Some("drex/noise"), "{extra}");
        }
        assert_eq!(floor(ppo_inputs("reward:\n  level: running\n  ceiling: none\n")), None);
    }

    /// Training the rewards in bf16, or on the velocities only, changes every T-REX stage and
    /// what follows it (BC and the rollouts it feeds are reused); `precision: f32` is the
    /// default and changes nothing.
    #[test]
    fn reward_precision_and_inputs_change_exactly_the_trex_stages_and_what_follows() {
        let g = expand(&Pipeline::parse(std::path::Path::new("p.yaml"), BASE).unwrap()).unwrap();
        let mut expected: Vec<String> =
            g.nodes.iter().filter(|n| n.kind() == StageKind::Trex).flat_map(|n| g.descendants(&n.name)).collect();
        expected.sort();
        expected.dedup();
        assert!(expected.iter().any(|n| n == "drex/trex") && expected.iter().any(|n| n.starts_with("drex/ppo/")));
        // What the reward reads changes the same stages; on Hopper, which observes no contact
        // forces, leaving them out changes nothing.
        for extra in ["trex:\n  precision: bf16\n", "trex:\n  observation: velocities\n"] {
            let mut got = changed(extra);
            got.sort();
            assert_eq!(got, expected, "{extra}");
            assert!(!got.iter().any(|n| n == "bc" || n == "drex/noise"), "{got:?}");
        }
        assert!(changed("trex:\n  precision: f32\n").is_empty());
        assert!(changed("trex:\n  observation: without-contact-forces\n").is_empty());
        // The manifest's CPU path names the bf16 path of a bf16 reward only.
        let p = Pipeline::parse(std::path::Path::new("p.yaml"), &format!("{BASE}trex:\n  precision: bf16\n")).unwrap();
        let g = expand(&p).unwrap();
        let kernel = crate::kernels::gemm::Kernel::active().name();
        let bf16 = crate::kernels::bf16::Bf16Path::active().name();
        assert_eq!(g.get("drex/trex").unwrap().params.cpu_path(), format!("{kernel}; bf16 {bf16}"));
        assert_eq!(g.get("bc").unwrap().params.cpu_path(), kernel);
    }

    /// Replicate r has the same keys whatever the count, replicate 0 those of the file
    /// without replicates; every replicate has its own seeds for every stage; a study takes
    /// replicates per environment; two files of one study split its replicates.
    #[test]
    fn replicates_keep_their_keys_as_the_count_grows() {
        let parse = |text: &str| Pipeline::parse(std::path::Path::new("p.yaml"), text).unwrap();
        let single = expand(&parse(BASE)).unwrap().keys();
        let two = expand(&parse(&format!("{BASE}replicates: 2\n"))).unwrap();
        let three = expand(&parse(&format!("{BASE}replicates: 3\n"))).unwrap().keys();
        assert_eq!(two.nodes.len(), 2 * single.len());
        for (name, key) in two.keys() {
            assert_eq!(three[&name], key, "{name}");
        }
        for (name, key) in &single {
            assert_eq!(&three[&format!("r0/{name}")], key, "{name}");
            assert_ne!(&three[&format!("r1/{name}")], key, "replicate 1 recomputes {name}");
        }
        for n in two.nodes.iter().filter(|n| n.name.starts_with("r1/")) {
            let twin = two.get(&n.name.replacen("r1/", "r0/", 1)).unwrap();
            assert_eq!(n.seed, crate::pipeline::config::replicate_seed(twin.seed, 1), "{}", n.name);
            if let (Params::Eval(a), Params::Eval(b)) = (&n.params, &twin.params) {
                assert_eq!((a.replicate, b.replicate), (1, 0));
            }
        }
        // The second half of a study in another file with the same name: the same nodes.
        let split = expand(&parse(&format!("{BASE}replicates: 2\nfirst_replicate: 1\n"))).unwrap().keys();
        assert_eq!(split.len(), 2 * single.len());
        for (name, key) in &split {
            assert_eq!(&three[name], key, "{name}");
        }
        let study = expand(&parse(&format!("{}replicates: 2\n", BASE.replace("env: Hopper-v5", "env: [Hopper-v5, Walker2d-v5]")))).unwrap();
        assert_eq!(study.keys()["Hopper-v5/r1/drex/trex"], three["r1/drex/trex"]);
        assert!(study.get("Walker2d-v5/r1/drex/ppo/1").is_some());
    }

    #[test]
    fn a_study_is_each_environments_graph_under_its_name() {
        let parse = |text: &str| Pipeline::parse(std::path::Path::new("p.yaml"), text);
        let one = expand(&parse(BASE).unwrap()).unwrap();
        let walker = expand(&parse(&BASE.replace("Hopper-v5", "Walker2d-v5")).unwrap()).unwrap();
        let study = parse(&BASE.replace("env: Hopper-v5", "env: [Hopper-v5, Walker2d-v5]")).unwrap();
        assert!(study.is_study());
        let g = expand(&study).unwrap();
        assert_eq!(g.nodes.len(), one.nodes.len() + walker.nodes.len());
        // The same computations, so the same keys: a study shares artifacts with the
        // single-environment files (and a store with their runs).
        let keys = g.keys();
        for (single, env) in [(&one, "Hopper-v5"), (&walker, "Walker2d-v5")] {
            for (name, key) in single.keys() {
                assert_eq!(keys[&format!("{env}/{name}")], key, "{env}/{name}");
            }
        }
        assert_eq!(g.subgraph("Walker2d-v5/").nodes, walker.nodes);
        let ppo = g.get("Walker2d-v5/drex/ppo/0").unwrap();
        let drex = |node: &str| format!("Walker2d-v5/drex/{node}");
        assert_eq!(ppo.inputs, Inputs::Ppo(PpoInputs { reward: drex("trex"), floor: Some(drex("noise")) }));
        // Each environment keeps its own defaults (the control-cost weight differs).
        assert_ne!(study.for_env(crate::env::EnvId::HalfCheetah).composition, study.composition);

        let err = |text: &str| parse(text).unwrap_err().to_string();
        assert!(err(&BASE.replace("env: Hopper-v5", "env: [Hopper-v5, Hopper-v5]")).contains("lists Hopper-v5 twice"));
        assert!(err(&BASE.replace("env: Hopper-v5", "env: []")).contains("empty list"));
        let dir = std::env::temp_dir().join(format!("idrex-study-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let missing = format!("{}demos:\n  from:\n    Hopper-v5: h.npz\n", BASE.replace("env: Hopper-v5", "env: [Hopper-v5, Walker2d-v5]"));
        let e = Pipeline::parse(&dir.join("p.yaml"), &missing).unwrap_err().to_string();
        assert!(e.contains("demos.from has no file for Walker2d-v5"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn slurm_resources_per_stage_kind_fall_back_to_the_default() {
        let text = format!("{BASE}slurm:\n  default: {{cpus: 1, mem: 2G}}\n  stages:\n    trex: {{cpus: 2, time: \"1:00:00\"}}\n");
        let p = Pipeline::parse(std::path::Path::new("p.yaml"), &text).unwrap();
        let trex = p.spec.slurm.for_kind(StageKind::Trex);
        assert_eq!((trex.cpus, trex.mem.as_deref(), trex.time.as_deref()), (Some(2), Some("2G"), Some("1:00:00")));
        assert_eq!(p.spec.slurm.for_kind(StageKind::Ppo).cpus, Some(1));
        // Resources are not part of any key.
        assert_eq!(expand(&p).unwrap().keys(), expand(&Pipeline::parse(std::path::Path::new("p.yaml"), BASE).unwrap()).unwrap().keys());
        let bad = Pipeline::parse(std::path::Path::new("p.yaml"), &format!("{BASE}slurm:\n  stages:\n    gail: {{cpus: 2}}\n"));
        assert!(bad.unwrap_err().to_string().contains("unknown variant `gail`"));
    }

    /// The device is part of the definition of the stages it changes, and of nothing else;
    /// a CPU stage's parameters have no device field, so keys from before the GPU path stay.
    #[test]
    fn the_device_is_in_the_keys_of_the_stages_it_changes() {
        use crate::nn::DeviceChoice;
        let text = format!("{BASE}slurm:\n  default: {{cpus: 1}}\nbank: {{probe: 8192}}\n");
        let p = Pipeline::parse(std::path::Path::new("p.yaml"), &text).unwrap();
        let (cpu, cuda) = (expand(&p.clone().on(DeviceChoice::Cpu)).unwrap(), expand(&p.clone().on(DeviceChoice::Cuda)).unwrap());
        let on_device = [StageKind::Bc, StageKind::Trex, StageKind::Ppo, StageKind::MultiBcRollouts, StageKind::Probe];
        for (a, b) in cpu.nodes.iter().zip(&cuda.nodes) {
            let json = a.params.key_json().to_string();
            assert!(!json.contains("device"), "{}: {json}", a.name);
            let mine = on_device.contains(&a.kind());
            assert_eq!(b.params.key_json().to_string().contains("\"device\":\"cuda\""), mine, "{}", a.name);
            assert_eq!(a.params.key_json() == b.params.key_json(), !mine, "{}", a.name);
            // A job planned for CUDA asks Slurm for a GPU; the rest ask for none.
            let gpus = |n: &Node| crate::pipeline::slurm::job_resources(n, &p.spec.slurm).gpus;
            assert_eq!((gpus(a), gpus(b)), (None, mine.then_some(1)), "{}", a.name);
        }
        // What depends on a GPU stage has other keys too; the demonstrations do not.
        let (ka, kb) = (cpu.keys(), cuda.keys());
        assert_eq!(ka["demos"], kb["demos"]);
        assert_ne!(ka["drex/eval/0"], kb["drex/eval/0"]);
        // The file's field, and a clear message for a wrong one.
        let file = |d: &str| Pipeline::parse(std::path::Path::new("p.yaml"), &format!("{BASE}device: {d}\n"));
        assert_eq!(file("cpu").unwrap().device, crate::nn::Device::Cpu);
        assert_eq!(file("cuda").unwrap().device, crate::nn::Device::Cuda);
        let e = file("gpu").unwrap_err().to_string();
        assert!(e.contains("unknown variant `gpu`") && e.contains("`auto`, `cpu`, `cuda`"), "{e}");
    }

    /// `noise.bc` gives D-REX its own BC: the baseline's BC and its evaluation follow `bc`,
    /// D-REX and the variants follow `noise.bc`, with the keys a file whose `bc` it is would
    /// give them (so stored results are reused); equal to `bc`, it adds nothing.
    #[test]
    fn noise_bc_separates_drex_source_from_the_baseline() {
        let parse = |bc: &str, noise_bc: Option<&str>| {
            let noise_bc = noise_bc.map_or(String::new(), |b| format!("  bc:\n    {b}\n"));
            let text = format!("version: 1\nenv: Hopper-v5\nseeds: [0, 1]\nbc:\n  {bc}\nnoise:\n  schedule: [0.0, 0.5, 1.0]\n{noise_bc}");
            expand(&Pipeline::parse(std::path::Path::new("p.yaml"), &text).unwrap()).unwrap()
        };
        let (tuned, plain) = ("init: normal-0.02", "init: libtorch");
        let split = parse(tuned, Some(plain));
        let (ks, kt, kp) = (split.keys(), parse(tuned, None).keys(), parse(plain, None).keys());
        assert_eq!(ks["bc"], kt["bc"]);
        assert_eq!(ks["bc/eval"], kt["bc/eval"]);
        assert_eq!(ks["drex/bc"], kp["bc"]);
        for (name, key) in &kp {
            if name.starts_with("drex/") || name.starts_with("idrex-") {
                assert_eq!(&ks[name], key, "{name}");
                assert_ne!(&kt[name], key, "{name}: teeth, the baseline's BC would change it");
            }
        }
        assert_eq!(split.get("drex/noise").unwrap().inputs, Inputs::NoiseRollouts(NoiseInputs { policy: "drex/bc".to_string() }));
        // The same settings twice: one BC stage.
        let same = parse(plain, Some(plain));
        assert!(same.get("drex/bc").is_none());
        assert_eq!(same.keys(), kp);
    }

    #[test]
    fn each_original_choice_changes_exactly_its_stages() {
        let g = expand(&Pipeline::parse(std::path::Path::new("p.yaml"), BASE).unwrap()).unwrap();
        let descendants = |of: &[StageKind]| -> Vec<String> {
            let mut out: Vec<String> = g.nodes.iter().filter(|n| of.contains(&n.kind())).flat_map(|n| g.descendants(&n.name)).collect();
            out.sort();
            out.dedup();
            out
        };
        // The reward's composition: the PPO runs (on learned rewards) and what follows them,
        // never the reward models themselves or anything before.
        for extra in ["reward:\n  combine: last-over-count\n", "reward:\n  ctrl_action: clipped\n", "reward:\n  ctrl_coeff: 0.5\n"] {
            assert_eq!(changed(extra), descendants(&[StageKind::Ppo]), "{extra}");
        }
        // The truncation bootstrap and the checkpoint interval: every PPO run, the
        // demonstrator's included.
        for extra in ["ppo:\n  bootstrap_truncation: true\n", "ppo:\n  checkpoint_every: 5\n"] {
            assert_eq!(changed(extra), descendants(&[StageKind::Demonstrator, StageKind::Ppo]), "{extra}");
        }
        // Initialisation: the reward networks (T-REX and everything after), and BC (with
        // multi-BC's clones) and everything after.
        assert_eq!(changed("trex:\n  init: default\n"), descendants(&[StageKind::Trex]));
        assert_eq!(changed("bc:\n  init: normal-0.02\n"), descendants(&[StageKind::Bc, StageKind::MultiBcRollouts]));
    }

    /// The still episodes change D-REX's ranked set and everything after it (every iD-REX
    /// variant ranks with it), never BC; `still: 0` is the default and changes nothing.
    #[test]
    fn still_episodes_change_exactly_drex_ranked_set_and_what_follows() {
        let g = expand(&Pipeline::parse(std::path::Path::new("p.yaml"), BASE).unwrap()).unwrap();
        let mut expected = g.descendants("drex/noise");
        expected.sort();
        expected.dedup();
        let mut got = changed("  still: 5\n");
        got.sort();
        assert_eq!(got, expected);
        assert!(got.iter().any(|n| n == "drex/noise") && !got.iter().any(|n| n == "bc" || n == "demos"), "{got:?}");
        assert!(changed("  still: 0\n").is_empty());
    }

    /// An imported demonstration file is identified by its content, not where it lies: a
    /// copy elsewhere keeps every key, a changed file changes them all.
    #[test]
    fn imported_demonstrations_are_keyed_by_content_not_path() {
        use crate::data::{TrajMeta, Trajectory};
        use crate::env::RewardTerms;
        let dir = std::env::temp_dir().join(format!("idrex-import-key-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("moved")).unwrap();
        // A short valid Hopper episode (11-dim observations, 3-dim actions).
        let write = |path: &std::path::Path, seed: u64| {
            let len = 3;
            let t = Trajectory {
                obs_dim: 11,
                act_dim: 3,
                obs: (0..(len + 1) * 11).map(|i| i as f32 * 0.01).collect(),
                actions: vec![0.1; len * 3],
                rewards: vec![1.0; len],
                terms: vec![RewardTerms { reward_forward: 0.5, reward_ctrl: -0.1, reward_survive: 0.6, reward_contact: 0.0 }; len],
                terminated: false,
                truncated: true,
                meta: TrajMeta { source: "demo".into(), noise: 0.0, seed, group: 0 },
            };
            crate::rollout::mcap::write(path, "Hopper-v5", 0.008, &[t], None).unwrap();
        };
        let npz = dir.join("demos.mcap");
        write(&npz, 0);
        let keys = |file: &std::path::Path| {
            let text = format!("{BASE}demos:\n  from: {}\n", file.display());
            expand(&Pipeline::parse(&dir.join("p.yaml"), &text).unwrap()).unwrap().keys()
        };
        let here = keys(&npz);
        let moved = dir.join("moved/other-name.mcap");
        std::fs::copy(&npz, &moved).unwrap();
        assert_eq!(keys(&moved), here);
        write(&moved, 1);
        let changed = keys(&moved);
        assert!(here.keys().all(|n| changed[n] != here[n]), "every node descends from the demonstrations");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
