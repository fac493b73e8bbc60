//! The reward bench's nodes ([`crate::pipeline::stage::bank`]): two PPO runs and the bank,
//! named `bank/...` once per environment whatever the replicates, one `bank-score` beside
//! every T-REX node of the graph (`drex/trex` -> `drex/trex/bank-score`) and, with
//! `bank.probe`, a short PPO run beside every reward PPO trains on (`drex/trex/probe`).
use super::{Graph, Inputs, NoInputs, Params, StageKind};
use crate::algo::ppo::PpoConfig;
use crate::env::{EnvId, Horizon};
use crate::pipeline::config::BankConfig;
use crate::pipeline::stage::bank::{BankParams, BankPolicyParams, Objective, ScoreParams};
use crate::pipeline::stage::probe::ProbeParams;
use crate::pipeline::stage::{BankPolicyInputs, ScoreInputs};

const PREFIX: &str = "bank/";

/// Whether a node is one of the bank's own (shared by every replicate of its environment).
pub fn is_bank(name: &str) -> bool {
    name.starts_with(PREFIX)
}

/// Where the bank's PPO runs train: the task itself, except Ant-v5, where idrex's PPO falls
/// at every budget tried; its gaits come from Ant-v5-no-cfrc, which walks, and act in Ant-v5
/// on the observation less the contact forces (the same body and reward).
pub fn gait_env(env: EnvId) -> EnvId {
    match env {
        EnvId::Ant => EnvId::AntNoCfrc,
        other => other,
    }
}

/// Adds the bank of `env` and a score of every T-REX node already in `g`.
pub fn expand(g: &mut Graph, env: EnvId, cfg: &BankConfig) {
    let rewards: Vec<String> = g.nodes.iter().filter(|n| n.kind() == StageKind::Trex).map(|n| n.name.clone()).collect();
    if rewards.is_empty() {
        return;
    }
    let run = |steps: usize, objective: Objective, checkpoints: usize| {
        let ppo = PpoConfig { total_steps: steps, horizon: Horizon::Task, ..PpoConfig::default() };
        Params::BankPolicy(BankPolicyParams { env: gait_env(env), ppo, objective, checkpoints, first: cfg.first })
    };
    let forward =
        g.push("bank/forward", run(cfg.steps, Objective::Forward, cfg.checkpoints), cfg.seed, Inputs::BankPolicy(NoInputs::default()));
    let backward = g.push(
        "bank/backward",
        run(cfg.backward_steps, Objective::Backward, cfg.backward_checkpoints),
        cfg.seed + 1,
        Inputs::BankPolicy(NoInputs::default()),
    );
    let params = BankParams {
        env,
        episodes: cfg.episodes,
        epsilon: cfg.epsilon.clone(),
        smooth: cfg.smooth.clone(),
        disturbed: cfg.disturbed,
        still: cfg.still,
        random: cfg.random,
        mean: cfg.mean,
    };
    let bank = g.push("bank/gaits", Params::Bank(params), cfg.seed, Inputs::Bank(BankPolicyInputs { forward, backward }));
    for reward in rewards {
        let inputs = Inputs::BankScore(ScoreInputs { reward: reward.clone(), bank: bank.clone() });
        g.push(format!("{reward}/bank-score"), Params::BankScore(ScoreParams { env }), cfg.seed, inputs);
        if let Some(steps) = cfg.probe {
            push_probe(g, &reward, steps);
        }
    }
}

/// Episodes of a probe's final policy.
const PROBE_EPISODES: usize = 5;

/// The probe of `reward`: its first RL run's stage, shortened to `steps`, on that run's seed
/// and inputs. None where no PPO trains on the reward (a judge).
fn push_probe(g: &mut Graph, reward: &str, steps: usize) {
    let first = g.nodes.iter().find_map(|n| match (&n.params, &n.inputs) {
        (Params::Ppo(p), Inputs::Ppo(i)) if i.reward == reward => Some((p.clone(), i.clone(), n.seed)),
        _ => None,
    });
    let Some((mut run, inputs, seed)) = first else { return };
    run.ppo.total_steps = steps;
    run.ppo.checkpoint_every = 0;
    g.push(format!("{reward}/probe"), Params::Probe(ProbeParams { run, episodes: PROBE_EPISODES }), seed, Inputs::Probe(inputs));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::Pipeline;
    use crate::pipeline::graph::expand;

    fn graph(text: &str) -> Graph {
        expand(&Pipeline::parse(std::path::Path::new("p.yaml"), text).unwrap()).unwrap()
    }

    const BASE: &str = "version: 1\nenv: Hopper-v5\nseeds: [0, 1]\nnoise:\n  schedule: [0.0, 0.5, 1.0]\nbank: {}\n";

    /// The bank is the task's: its keys ignore the seeds and every other stage's settings,
    /// follow its own, and a replicated file or a study holds one per environment, with a score
    /// beside every T-REX node.
    #[test]
    fn the_bank_is_the_tasks_and_scores_every_reward() {
        let bank_keys = |g: &Graph| -> Vec<String> {
            let keys = g.keys();
            g.nodes.iter().filter(|n| is_bank(&n.name)).map(|n| keys[&n.name].clone()).collect()
        };
        let base = graph(BASE);
        assert_eq!(bank_keys(&base).len(), 3);
        let other = graph(&format!("{}trex:\n  iterations: 77\n", BASE.replace("seeds: [0, 1]", "seeds: [5, 6, 7]")));
        assert_eq!(bank_keys(&other), bank_keys(&base), "seeds and T-REX settings leave the bank alone");
        assert_ne!(bank_keys(&graph(&BASE.replace("bank: {}", "bank: {steps: 4096}"))), bank_keys(&base));
        let trex = base.nodes.iter().filter(|n| n.kind() == StageKind::Trex).count();
        assert_eq!(base.nodes.iter().filter(|n| n.kind() == StageKind::BankScore).count(), trex);
        // Three replicates: one bank, a score per replicate's reward.
        let three = graph(&format!("{BASE}replicates: 3\n"));
        assert_eq!(bank_keys(&three), bank_keys(&base));
        assert_eq!(three.nodes.iter().filter(|n| n.kind() == StageKind::BankScore).count(), 3 * trex);
        // A study: each environment its own bank; no bank without a learned reward.
        let study = graph(&format!("{}replicates: 2\n", BASE.replace("env: Hopper-v5", "env: [Hopper-v5, Walker2d-v5]")));
        assert_eq!(study.nodes.iter().filter(|n| n.kind() == StageKind::Bank).count(), 2);
        assert!(study.get("Walker2d-v5/bank/gaits").is_some() && study.get("Walker2d-v5/r1/drex/trex/bank-score").is_some());
        assert!(graph(&format!("{BASE}methods: [bc]\n")).nodes.iter().all(|n| !is_bank(&n.name)));
        // Ant-v5's gaits are trained where idrex's PPO walks.
        let ant = graph(&BASE.replace("Hopper-v5", "Ant-v5"));
        assert!(matches!(&ant.get("bank/forward").unwrap().params, Params::BankPolicy(p) if p.env == EnvId::AntNoCfrc));
        assert!(matches!(&ant.get("bank/gaits").unwrap().params, Params::Bank(p) if p.env == EnvId::Ant));
    }

    /// A probe is the reward's first RL run, shortened, with that run's seed and inputs; the
    /// bank's keys and every other node's ignore it, and a judge (no PPO) has none.
    #[test]
    fn a_probe_is_the_first_run_shortened() {
        let text = format!("{}methods: [bc, drex, idrex-multi-bc]\n", BASE.replace("bank: {}", "bank: {probe: 20480}"));
        let g = graph(&text);
        let probe = g.get("drex/trex/probe").unwrap();
        let run = g.get("drex/ppo/0").unwrap();
        let (Params::Probe(p), Params::Ppo(r)) = (&probe.params, &run.params) else { panic!("a probe is a PPO run") };
        assert_eq!((p.run.ppo.total_steps, p.run.ppo.checkpoint_every, probe.seed), (20480, 0, run.seed));
        let same = PpoConfig { total_steps: r.ppo.total_steps, checkpoint_every: r.ppo.checkpoint_every, ..p.run.ppo.clone() };
        assert_eq!((same, p.run.reward, p.run.env), (r.ppo.clone(), r.reward, r.env), "otherwise the run's settings");
        assert!(matches!((&probe.inputs, &run.inputs), (Inputs::Probe(a), Inputs::Ppo(b)) if a == b), "the run's reward and floor");
        assert!(g.get("idrex-multi-bc/k1/trex/probe").is_some() && g.get("idrex-multi-bc/k1/judge/probe").is_none());
        let plain = graph(&text.replace("bank: {probe: 20480}", "bank: {}"));
        assert!(plain.nodes.iter().all(|n| n.kind() != StageKind::Probe));
        assert!(plain.keys().iter().all(|(n, k)| g.keys()[n] == *k), "nothing else changes");
    }

    /// `--target` keeps the named nodes and what they read, nothing else.
    #[test]
    fn a_target_runs_what_it_reads_and_no_more() {
        let g = graph(&format!("{BASE}replicates: 2\n"));
        let up = g.up_to(&["drex/trex/bank-score".to_string()]).unwrap();
        assert!(up.nodes.iter().all(|n| n.kind() != StageKind::Ppo && n.kind() != StageKind::Eval), "no PPO, no evaluation");
        assert!(up.get("r1/drex/trex/bank-score").is_some() && up.get("bank/forward").is_some() && up.get("r0/bc").is_some());
        assert!(up.keys().iter().all(|(n, k)| g.keys()[n] == *k), "the same keys as the whole file's");
        assert!(g.up_to(&["nope".to_string()]).unwrap_err().contains("no node of the pipeline is named so"));
    }
}
