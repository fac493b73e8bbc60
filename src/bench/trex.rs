//! `idrex bench trex`: T-REX on epsilon-greedy rollouts of a trained policy: rank correlation of
//! predicted and true returns on held-out rollouts, and the training time.
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;

use crate::env::{Env, EnvId};
use crate::nn::DeviceChoice;

#[derive(Debug, clap::Args)]
pub struct TrexBenchArgs {
    /// A trained policy directory (policy.safetensors + policy.json).
    #[arg(long)]
    pub policy: PathBuf,
    /// Training rollouts per epsilon level (D-REX: 5).
    #[arg(long, default_value_t = 5)]
    pub per_level: usize,
    /// Held-out rollouts per epsilon level.
    #[arg(long, default_value_t = 2)]
    pub held_out_per_level: usize,
    /// T-REX iterations per model (D-REX: 3000).
    #[arg(long, default_value_t = 3000)]
    pub iterations: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where T-REX trains (`auto`: the GPU where libtorch sees one).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Auto)]
    pub device: DeviceChoice,
}

/// Epsilon-greedy rollouts of `policy` at D-REX's 20 levels, `per_level` each: the
/// pipeline's own noise-rollout helper, so bench and pipeline figures are comparable.
fn eps_rollouts(env: &mut Env, policy: &crate::nn::ActorCritic, per_level: usize, seed: u64) -> Vec<crate::data::Trajectory> {
    let schedule: Vec<f64> = (0..20).map(|level| level as f64 * 0.05).collect();
    let meta = crate::data::TrajMeta { source: "bench".into(), ..Default::default() };
    crate::algo::noise::epsilon_greedy(env, policy, &schedule, per_level, seed, &meta)
}

pub fn trex_bench(args: &TrexBenchArgs) -> anyhow::Result<()> {
    use crate::{algo::trex, stats};
    let policy = crate::nn::ActorCritic::load(&args.policy)?;
    let id: EnvId = policy.env.clone().context("the policy does not name its environment")?.parse()?;
    let mut env = Env::new(id)?;
    let train = eps_rollouts(&mut env, &policy, args.per_level, args.seed);
    let held = eps_rollouts(&mut env, &policy, args.held_out_per_level, args.seed + 1);
    let cfg = trex::TrexConfig { iterations: args.iterations, ..Default::default() };
    let ranking = trex::Ranking::by_score(train.iter().map(|t| -t.meta.noise).collect());
    let device = args.device.resolve();
    let start = Instant::now();
    let (model, reports) =
        trex::train(&train, &ranking, &cfg, args.seed, std::thread::available_parallelism().map_or(1, |n| n.get()), device)?;
    let secs = start.elapsed().as_secs_f64();
    let pred: Vec<f64> = held.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
    let truth: Vec<f64> = held.iter().map(|t| t.ret()).collect();
    let out = serde_json::json!({
        "env": id.name(), "device": device.name(), "train_trajectories": train.len(), "held_out_trajectories": held.len(),
        "models": cfg.models, "iterations": cfg.iterations, "train_s": secs,
        "iterations_per_s": (cfg.models * cfg.iterations) as f64 / secs,
        "val_accuracy": reports.iter().map(|r| r.val_accuracy).collect::<Vec<_>>(),
        "held_out_spearman": stats::spearman(&pred, &truth), "held_out_pearson": stats::pearson(&pred, &truth),
        "held_out_pairwise_accuracy": stats::pairwise_accuracy(&pred, &truth),
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
