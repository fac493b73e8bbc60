//! The reward bench's nodes ([`crate::pipeline::stage::bank`]): two PPO runs and the bank,
//! named `bank/...` once per environment whatever the replicates, and one `bank-score` beside
//! every T-REX node of the graph (`drex/trex` -> `drex/trex/bank-score`).
use super::{Graph, Inputs, NoInputs, Params, StageKind};
use crate::algo::ppo::PpoConfig;
use crate::env::{EnvId, Horizon};
use crate::pipeline::config::BankConfig;
use crate::pipeline::stage::bank::{BankParams, BankPolicyParams, Objective, ScoreParams};
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
    let forward = g.push("bank/forward", run(cfg.steps, Objective::Forward, cfg.checkpoints), cfg.seed, Inputs::BankPolicy(NoInputs::default()));
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
    }
}
