//! A pipeline file expanded into a DAG of stage instances, in topological order.
//!
//! ```text
//! demonstrator ─> demos ─> bc ─┬─> bc/eval
//!                              └─> drex/noise ─> drex/trex ─> drex/ppo/<r> ─> drex/eval/<r>
//!                                                   │              │
//!        iD-REX iteration k: rollouts from the iteration's policies ─> <variant>/k<k>/trex
//!                             ─> <variant>/k<k>/ppo/<r> ─> <variant>/k<k>/eval/<r>
//! ```
use std::collections::BTreeMap;

use serde_json::{Value, json};

use super::config::{Method, Pipeline};
use super::stages::StageKind;
use crate::store;

#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Unique within the pipeline, e.g. `drex/ppo/1`.
    pub name: String,
    pub kind: StageKind,
    pub params: Value,
    pub seed: u64,
    /// (role, node name); roles are unique within a node.
    pub inputs: Vec<(String, String)>,
}

#[derive(Debug, Clone, Default)]
pub struct Graph {
    pub nodes: Vec<Node>,
}

impl Graph {
    pub fn get(&self, name: &str) -> Option<&Node> {
        self.nodes.iter().find(|n| n.name == name)
    }

    fn push(&mut self, name: impl Into<String>, kind: StageKind, params: Value, seed: u64, inputs: Vec<(String, String)>) -> String {
        let name = name.into();
        debug_assert!(inputs.iter().all(|(_, i)| self.get(i).is_some()), "inputs come first");
        self.nodes.push(Node { name: name.clone(), kind, params, seed, inputs });
        name
    }

    /// Every node's key, computed in topological order from kind, version, parameters, seed
    /// and the keys of its inputs.
    pub fn keys(&self) -> BTreeMap<String, String> {
        let mut keys: BTreeMap<String, String> = BTreeMap::new();
        for n in &self.nodes {
            let inputs: BTreeMap<String, String> = n.inputs.iter().map(|(role, src)| (role.clone(), keys[src].clone())).collect();
            let k = store::key(n.kind.name(), n.kind.version(), &n.params, n.seed, &inputs);
            keys.insert(n.name.clone(), k);
        }
        keys
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

fn io(role: &str, src: &str) -> (String, String) {
    (role.to_string(), src.to_string())
}

/// Expands a validated pipeline into its DAG.
pub fn expand(p: &Pipeline) -> crate::Result<Graph> {
    let s = &p.spec;
    let env = p.env.name();
    let mut g = Graph::default();
    let seed0 = s.seeds[0];
    let wants = |m: Method| s.methods.contains(&m);
    let demos = match &s.demos.from {
        Some(from) => {
            let path = p.base_dir().join(from);
            // The file's content, not its path, goes into the key.
            let (sha256, _) = store::sha256_file(&path)?;
            g.push("demos", StageKind::DemosImport, json!({"env": env, "path": path, "sha256": sha256}), seed0, vec![])
        }
        None => {
            let mut ppo = s.ppo.clone();
            ppo.total_steps = s.demonstrator.steps;
            ppo.eval_every = s.demonstrator.eval_every;
            let d = g.push(
                "demonstrator",
                StageKind::Demonstrator,
                json!({"env": env, "ppo": ppo, "target_return": s.demonstrator.target_return}),
                seed0,
                vec![],
            );
            g.push("demos", StageKind::Demos, json!({"env": env, "episodes": s.demos.episodes}), seed0, vec![io("policy", &d)])
        }
    };
    let bc = g.push("bc", StageKind::Bc, json!({"env": env, "bc": s.bc}), seed0, vec![io("demos", &demos)]);
    let eval_params = |method: Method, k: usize, run: usize| json!({"env": env, "episodes": s.eval.episodes, "pipeline": p.name, "method": method.name(), "iteration": k, "run": run});
    if wants(Method::Bc) {
        g.push("bc/eval", StageKind::Eval, eval_params(Method::Bc, 0, 0), seed0, vec![io("policy", &bc), io("demos", &demos)]);
    }
    let idrex = [Method::IdrexInterpolation, Method::IdrexActionNoise, Method::IdrexMultiBc];
    if !(wants(Method::Drex) || idrex.iter().any(|&m| wants(m))) {
        return Ok(g);
    }
    let noise = g.push(
        "drex/noise",
        StageKind::NoiseRollouts,
        json!({"env": env, "schedule": s.noise.schedule, "rollouts_per_level": s.noise.rollouts_per_level}),
        seed0,
        vec![io("policy", &bc)],
    );
    let trex_params = |m: Method, sets: Value| json!({"env": env, "trex": p.trex_for(m), "ctrl_coeff": p.ctrl_coeff, "sets": sets});
    let drex_trex = g.push(
        "drex/trex",
        StageKind::Trex,
        trex_params(Method::Drex, json!([{"level": 0, "same_group": false}])),
        seed0,
        vec![io("set0", &noise), io("demos", &demos)],
    );
    // Each method's RL runs and evaluations on a reward; returns the PPO node names.
    let rl = |g: &mut Graph, m: Method, prefix: &str, k: usize, reward: &str| -> Vec<String> {
        s.seeds
            .iter()
            .enumerate()
            .map(|(r, &seed)| {
                let ppo = g.push(
                    format!("{prefix}/ppo/{r}"),
                    StageKind::Ppo,
                    json!({"env": env, "ppo": p.ppo_for(m)}),
                    seed,
                    vec![io("reward", reward)],
                );
                g.push(
                    format!("{prefix}/eval/{r}"),
                    StageKind::Eval,
                    eval_params(m, k, r),
                    seed,
                    vec![io("policy", &ppo), io("reward", reward), io("demos", &demos)],
                );
                ppo
            })
            .collect()
    };
    let drex_ppo = rl(&mut g, Method::Drex, "drex", 1, &drex_trex);
    for m in idrex.into_iter().filter(|&m| wants(m)) {
        // The ranked sets so far, (set node, level, same_group), and the policies of the
        // current iteration; iteration 1 starts from D-REX.
        let mut sets: Vec<(String, usize, bool)> = vec![(noise.clone(), 0, false)];
        let mut current = drex_ppo.clone();
        let mut previous: Vec<String> = vec![bc.clone(); s.seeds.len()];
        let mut prev_reward = drex_trex.clone();
        for k in 1..s.iterations {
            let prefix = format!("{}/k{k}", m.name());
            let mut inputs: Vec<(String, String)> = current.iter().enumerate().map(|(r, n)| io(&format!("policy{r}"), n)).collect();
            let (kind, params) = match m {
                Method::IdrexInterpolation => {
                    inputs.extend(previous.iter().enumerate().map(|(r, n)| io(&format!("older{r}"), n)));
                    (
                        StageKind::InterpolationRollouts,
                        json!({"env": env, "alphas": s.idrex.alphas, "rollouts_per_level": s.idrex.rollouts_per_level}),
                    )
                }
                Method::IdrexActionNoise => (
                    StageKind::ActionNoiseRollouts,
                    json!({"env": env, "sigmas": s.idrex.sigmas, "noise": s.idrex.action_noise, "rollouts_per_level": s.idrex.rollouts_per_level}),
                ),
                _ => {
                    inputs.push(io("reward", &prev_reward));
                    inputs.push(io("baseline", &sets.last().expect("the D-REX set").0));
                    (
                        StageKind::MultiBcRollouts,
                        json!({"env": env, "bc": s.bc, "schedule": s.idrex.multi_bc_schedule, "rollouts_per_level": s.idrex.multi_bc_rollouts_per_level}),
                    )
                }
            };
            let rollouts = g.push(format!("{prefix}/rollouts"), kind, params, seed0, inputs);
            sets.push((rollouts, k, m == Method::IdrexMultiBc));
            let set_params: Vec<Value> = sets.iter().map(|(_, level, same)| json!({"level": level, "same_group": same})).collect();
            let mut trex_inputs: Vec<(String, String)> = sets.iter().enumerate().map(|(i, (n, _, _))| io(&format!("set{i}"), n)).collect();
            trex_inputs.push(io("demos", &demos));
            let mut params = trex_params(m, Value::Array(set_params));
            params["cross_level"] = json!(m == Method::IdrexInterpolation);
            let trex = g.push(format!("{prefix}/trex"), StageKind::Trex, params, seed0, trex_inputs);
            previous = current;
            current = rl(&mut g, m, &prefix, k + 1, &trex);
            prev_reward = trex;
        }
    }
    Ok(g)
}

/// The graph as text, Graphviz dot or Mermaid; `status` says whether a node is stored.
pub fn render(g: &Graph, keys: &BTreeMap<String, String>, stored: &dyn Fn(&str) -> bool, format: &str) -> String {
    let mut out = String::new();
    let id = |name: &str| name.replace(['/', '-'], "_");
    match format {
        "dot" => {
            out.push_str("digraph pipeline {\n  rankdir=LR;\n  node [shape=box, fontname=monospace];\n");
            for n in &g.nodes {
                let k = &keys[&n.name];
                let style = if stored(k) { ", style=filled, fillcolor=palegreen" } else { "" };
                out.push_str(&format!("  {} [label=\"{}\\n{}\\n{}\"{style}];\n", id(&n.name), n.name, n.kind.name(), &k[..12]));
                for (_, src) in &n.inputs {
                    out.push_str(&format!("  {} -> {};\n", id(src), id(&n.name)));
                }
            }
            out.push_str("}\n");
        }
        "mermaid" => {
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
                for (_, src) in &n.inputs {
                    out.push_str(&format!("  {} --> {}\n", id(src), id(&n.name)));
                }
                if stored(k) {
                    out.push_str(&format!("  style {} fill:#bfb\n", id(&n.name)));
                }
            }
        }
        _ => {
            for n in &g.nodes {
                let k = &keys[&n.name];
                let inputs: Vec<&str> = n.inputs.iter().map(|(_, s)| s.as_str()).collect();
                out.push_str(&format!(
                    "{:<8} {}  {:<38} {:<24} <- {}\n",
                    if stored(k) { "stored" } else { "missing" },
                    &k[..12],
                    n.name,
                    n.kind.name(),
                    if inputs.is_empty() { "-".to_string() } else { inputs.join(", ") }
                ));
            }
        }
    }
    out
}
