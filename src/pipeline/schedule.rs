//! Which ready stage runs first: the one with the longest estimated chain of work still
//! behind it (critical path first), so that BC and the T-REX rewards, which everything
//! downstream waits on, start as early as they can and the PPO runs and evaluations fill
//! the cores around them.
//!
//! A stage's time is estimated from the store: per stage kind, the median of the stored
//! artifacts' seconds per unit of work (PPO and demonstrator steps, BC iterations, T-REX
//! iterations x models x the mean window's steps, rollouts, evaluation episodes), times this
//! node's work. Kinds the store has not seen use figures measured on the 2-core reference
//! machine at the paper's settings. Stored nodes cost nothing.
use std::collections::BTreeMap;

use super::graph::{Graph, Node};
use super::stage::{Params, StageKind};
use crate::store::Manifest;

/// How much work a node is, in its kind's unit.
fn work(params: &Params) -> f64 {
    let n = match params {
        Params::Ppo(p) => p.ppo.total_steps,
        Params::Demonstrator(p) => p.ppo.total_steps,
        Params::Bc(p) => p.bc.iterations,
        Params::MultiBcRollouts(p) => p.clone.bc.iterations * 3 + p.schedule.len() * p.rollouts_per_level,
        // A pair's cost is its windows' steps: SSRR's 50-500-step snippets (`window_max`) took
        // 1665 s where 50 steps took 265 s (HalfCheetah, one thread, AMD Zen 4).
        Params::Trex(p) => p.trex.iterations * p.trex.models * (p.trex.window + p.trex.window_max.unwrap_or(p.trex.window)) / 2,
        Params::NoiseRollouts(p) => p.schedule.len() * p.rollouts_per_level,
        Params::InterpolationRollouts(p) => p.alphas.len() * p.rollouts_per_level,
        Params::ActionNoiseRollouts(p) => p.sigmas.len() * p.rollouts_per_level,
        Params::Eval(p) => p.episodes,
        Params::Demos(p) => p.episodes,
        Params::DemosImport(_) => 1,
        Params::BankPolicy(p) => p.ppo.total_steps,
        Params::Bank(p) => {
            let per_checkpoint = p.episodes + (p.epsilon.len() + p.smooth.len()) * p.disturbed;
            per_checkpoint * 12 + p.still + p.random
        }
        Params::BankScore(_) => 1,
        Params::Probe(p) => p.run.ppo.total_steps,
    };
    n.max(1) as f64
}

/// Seconds per unit of work on the reference machine (2 cores, HalfCheetah at the paper's
/// settings, `--jobs 2`), for kinds the store has no artifact of.
fn reference_rate(kind: StageKind) -> f64 {
    match kind {
        StageKind::Ppo | StageKind::Demonstrator | StageKind::BankPolicy | StageKind::Probe => 65.0 / 1e6,
        StageKind::Bc => 80.0 / 50_000.0,
        StageKind::MultiBcRollouts => 220.0 / 150_100.0,
        StageKind::Trex => 160.0 / (9_000.0 * 50.0),
        StageKind::NoiseRollouts | StageKind::InterpolationRollouts | StageKind::ActionNoiseRollouts => 20.0 / 100.0,
        // 26 checkpoints of 20 episodes each.
        StageKind::Eval => 12.0 / 20.0,
        StageKind::Demos => 0.5,
        StageKind::DemosImport => 0.01,
        // Rollouts of 1000 steps with no reward model.
        StageKind::Bank => 0.15,
        StageKind::BankScore => 3.0,
    }
}

/// Seconds-per-unit rates per stage kind.
#[derive(Debug, Clone, Default)]
pub struct Estimates {
    measured: BTreeMap<StageKind, f64>,
    /// This processor against the reference machine, for the kinds the store has not measured.
    speed: super::calibrate::Speed,
}

impl Estimates {
    /// From the stored manifests (their parameters and wall times).
    pub fn from_manifests(manifests: &[Manifest]) -> Self {
        let mut rates: BTreeMap<StageKind, Vec<f64>> = BTreeMap::new();
        for m in manifests {
            let Some(kind) = StageKind::parse(&m.kind) else { continue };
            // An older version of a stage may have run at another speed.
            if m.version != kind.version() {
                continue;
            }
            let Ok(params) = Params::from_json(kind, &m.params) else { continue };
            if m.wall_s.is_finite() && m.wall_s > 0.0 {
                rates.entry(kind).or_default().push(m.wall_s / work(&params));
            }
        }
        let measured = rates
            .into_iter()
            .map(|(k, mut v)| {
                v.sort_by(f64::total_cmp);
                (k, v[v.len() / 2])
            })
            .collect();
        Estimates { measured, speed: Default::default() }
    }

    /// These estimates with the reference machine's rates scaled to `speed`.
    pub fn on(self, speed: super::calibrate::Speed) -> Self {
        Estimates { speed, ..self }
    }

    /// Whether some kind of `g`'s nodes has no rate from the store (a probe of this machine
    /// then makes the estimate).
    pub fn guesses(&self, g: &Graph) -> bool {
        g.nodes.iter().any(|n| !self.measured(n.kind()))
    }

    /// The estimated seconds `node` takes to compute.
    pub fn seconds(&self, node: &Node) -> f64 {
        let kind = node.kind();
        self.measured.get(&kind).copied().unwrap_or_else(|| reference_rate(kind) * self.speed.factor(kind)) * work(&node.params)
    }

    /// Whether the store gave the rate of `kind` (else the reference machine's is used).
    pub fn measured(&self, kind: StageKind) -> bool {
        self.measured.contains_key(&kind)
    }
}

/// Per node, its own cost plus the costliest chain of descendants after it.
pub fn remaining(g: &Graph, cost: &dyn Fn(&Node) -> f64) -> BTreeMap<String, f64> {
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    // Nodes are in topological order: walk it backwards.
    for n in g.nodes.iter().rev() {
        let after = g.nodes.iter().filter(|c| c.inputs.iter().any(|(_, i)| *i == n.name)).map(|c| out[&c.name]).fold(0.0, f64::max);
        out.insert(n.name.clone(), cost(n) + after);
    }
    out
}

/// The critical path (node names, first to last) and its estimated seconds.
pub fn critical_path(g: &Graph, cost: &dyn Fn(&Node) -> f64) -> (Vec<String>, f64) {
    let rem = remaining(g, cost);
    let roots = g.nodes.iter().filter(|n| n.inputs.is_empty());
    let Some(mut at) = roots.max_by(|a, b| rem[&a.name].total_cmp(&rem[&b.name])) else { return (vec![], 0.0) };
    let total = rem[&at.name];
    let mut path = vec![at.name.clone()];
    while let Some(next) =
        g.nodes.iter().filter(|c| c.inputs.iter().any(|(_, i)| *i == at.name)).max_by(|a, b| rem[&a.name].total_cmp(&rem[&b.name]))
    {
        path.push(next.name.clone());
        at = next;
    }
    (path, total)
}

/// The estimated wall time of `g` run `jobs` stages at a time, each stage taking `cost`
/// seconds, started critical path first as the runner starts them: a list schedule.
pub fn makespan(g: &Graph, cost: &dyn Fn(&Node) -> f64, jobs: usize) -> f64 {
    let rem = remaining(g, cost);
    let mut done: BTreeMap<&str, f64> = BTreeMap::new();
    let mut started = std::collections::BTreeSet::new();
    // (finish time, node) of the running stages.
    let mut running: Vec<(f64, &str)> = Vec::new();
    let mut now = 0.0;
    loop {
        let mut ready: Vec<&Node> = g
            .nodes
            .iter()
            .filter(|n| !started.contains(n.name.as_str()))
            .filter(|n| n.inputs.iter().all(|(_, i)| done.get(i.as_str()).is_some_and(|&t| t <= now)))
            .collect();
        ready.sort_by(|a, b| rem[&b.name].total_cmp(&rem[&a.name]));
        for n in ready.into_iter().take(jobs.max(1).saturating_sub(running.len())) {
            started.insert(n.name.as_str());
            running.push((now + cost(n).max(0.0), n.name.as_str()));
        }
        let Some(first) = (0..running.len()).min_by(|&a, &b| running[a].0.total_cmp(&running[b].0)) else { break };
        let (t, name) = running.swap_remove(first);
        now = t;
        done.insert(name, t);
    }
    now
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::Pipeline;

    fn graph() -> Graph {
        let text = "version: 1\nenv: Hopper-v5\nseeds: [0, 1]\n";
        crate::pipeline::expand(&Pipeline::parse(std::path::Path::new("p.yaml"), text).unwrap()).unwrap()
    }

    #[test]
    fn remaining_work_is_a_node_plus_its_longest_chain() {
        let g = graph();
        let cost = |n: &Node| if n.kind() == StageKind::Trex { 10.0 } else { 1.0 };
        let rem = remaining(&g, &cost);
        for n in &g.nodes {
            let children: Vec<f64> = g.nodes.iter().filter(|c| c.inputs.iter().any(|(_, i)| *i == n.name)).map(|c| rem[&c.name]).collect();
            let want = cost(n) + children.iter().copied().fold(0.0, f64::max);
            assert_eq!(rem[&n.name], want, "{}", n.name);
        }
        // The path starts at a root, follows inputs, and adds up to the root's figure.
        let (path, total) = critical_path(&g, &cost);
        assert!(g.get(&path[0]).unwrap().inputs.is_empty());
        for w in path.windows(2) {
            assert!(g.get(&w[1]).unwrap().inputs.iter().any(|(_, i)| *i == w[0]), "{w:?}");
        }
        assert_eq!(path.iter().map(|p| cost(g.get(p).unwrap())).sum::<f64>(), total);
        // Two T-REX trainings lie on it (D-REX's, then iD-REX's), as in the paper's DAG.
        assert!(path.iter().filter(|p| g.get(p).unwrap().kind() == StageKind::Trex).count() >= 2, "{path:?}");
    }

    /// T-REX's work grows with its windows: a store that measured 50-step windows estimates
    /// 50-500-step ones at 5.5 times the seconds, and more members at their number.
    #[test]
    fn a_trex_stage_costs_its_windows_steps() {
        let g = graph();
        let trex = g.nodes.iter().find(|n| n.kind() == StageKind::Trex).unwrap();
        let with = |f: &dyn Fn(&mut crate::algo::trex::TrexConfig)| {
            let mut n = trex.clone();
            let Params::Trex(p) = &mut n.params else { unreachable!() };
            f(&mut p.trex);
            n
        };
        let measured = Manifest {
            kind: trex.kind().name().into(),
            version: trex.kind().version(),
            params: trex.params.to_json(),
            wall_s: 265.0,
            ..Default::default()
        };
        let e = Estimates::from_manifests(&[measured]);
        assert!((e.seconds(trex) - 265.0).abs() < 1e-9);
        let long = with(&|t| t.window_max = Some(500));
        assert!((e.seconds(&long) - 265.0 * 5.5).abs() < 1e-6, "{}", e.seconds(&long));
        let eight = with(&|t| t.models = 8);
        assert!((e.seconds(&eight) - 265.0 * 8.0 / 3.0).abs() < 1e-6);
        // The reference machine's figure is the paper's settings' 160 s.
        assert!((Estimates::default().seconds(trex) - 160.0).abs() < 1e-9);
    }

    #[test]
    fn the_makespan_lies_between_the_critical_path_and_the_serial_time() {
        let g = graph();
        let cost = |n: &Node| if n.kind() == StageKind::Trex { 10.0 } else { 1.0 };
        let serial: f64 = g.nodes.iter().map(cost).sum();
        let (_, path) = critical_path(&g, &cost);
        assert_eq!(makespan(&g, &cost, 1), serial);
        let two = makespan(&g, &cost, 2);
        assert!(two >= path && two >= serial / 2.0 && two < serial, "{two} against {path} and {serial}");
        // With a job per node, only the critical path is left.
        assert_eq!(makespan(&g, &cost, g.nodes.len()), path);
        // Stored nodes cost nothing.
        assert_eq!(makespan(&g, &|_| 0.0, 2), 0.0);
    }
}
