//! `idrex bench trex`: T-REX on epsilon-greedy rollouts of a trained policy: rank correlation of
//! predicted and true returns on held-out rollouts, and the training time; per seed, in f32
//! and, with `--bf16`, in bf16 on the same rollouts, with the mean and the seed-to-seed
//! spread of each.
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
    /// The first seed (rollouts and training); seeds `seed, seed + 1, ...`.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Seeds to run.
    #[arg(long, default_value_t = 1)]
    pub seeds: u64,
    /// Also train in bf16 (`trex.precision: bf16`) on each seed's rollouts.
    #[arg(long)]
    pub bf16: bool,
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

/// One T-REX run's held-out ranking quality and time.
#[derive(Debug, Clone, serde::Serialize)]
struct Quality {
    seed: u64,
    train_s: f64,
    val_accuracy: Vec<f64>,
    held_out_spearman: f64,
    held_out_pearson: f64,
    held_out_pairwise_accuracy: f64,
}

/// Mean and sample standard deviation over seeds of each figure of `runs`.
fn summary(runs: &[Quality]) -> serde_json::Value {
    let stat = |f: &dyn Fn(&Quality) -> f64| {
        let v: Vec<f64> = runs.iter().map(f).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let sd = if v.len() > 1 { (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt() } else { f64::NAN };
        serde_json::json!({ "mean": mean, "sd": sd })
    };
    serde_json::json!({
        "runs": runs.len(),
        "held_out_spearman": stat(&|q| q.held_out_spearman),
        "held_out_pearson": stat(&|q| q.held_out_pearson),
        "held_out_pairwise_accuracy": stat(&|q| q.held_out_pairwise_accuracy),
        "train_s": stat(&|q| q.train_s),
    })
}

pub fn trex_bench(args: &TrexBenchArgs) -> anyhow::Result<serde_json::Value> {
    use crate::kernels::bf16::{Bf16Path, Precision};
    use crate::{algo::trex, stats};
    let policy = crate::nn::ActorCritic::load(&args.policy)?;
    let id: EnvId = policy.env.clone().context("the policy does not name its environment")?.parse()?;
    let mut env = Env::new(id)?;
    let device = args.device.resolve();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let precisions: &[Precision] = if args.bf16 { &[Precision::F32, Precision::Bf16] } else { &[Precision::F32] };
    let mut runs: Vec<Vec<Quality>> = vec![Vec::new(); precisions.len()];
    for seed in args.seed..args.seed + args.seeds.max(1) {
        // Seeds of the rollouts two apart, so that one seed's held-out set is not the next's
        // training set.
        let train = eps_rollouts(&mut env, &policy, args.per_level, 2 * seed);
        let held = eps_rollouts(&mut env, &policy, args.held_out_per_level, 2 * seed + 1);
        let ranking = trex::Ranking::by_score(train.iter().map(|t| -t.meta.noise).collect());
        let truth: Vec<f64> = held.iter().map(|t| t.ret()).collect();
        for (&precision, out) in precisions.iter().zip(runs.iter_mut()) {
            let cfg = trex::TrexConfig { iterations: args.iterations, precision, ..Default::default() };
            let start = Instant::now();
            let (model, reports) = trex::train(&train, &ranking, &cfg, seed, threads, device)?;
            let train_s = start.elapsed().as_secs_f64();
            let pred: Vec<f64> = held.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
            let q = Quality {
                seed,
                train_s,
                val_accuracy: reports.iter().map(|r| r.val_accuracy).collect(),
                held_out_spearman: stats::spearman(&pred, &truth),
                held_out_pearson: stats::pearson(&pred, &truth),
                held_out_pairwise_accuracy: stats::pairwise_accuracy(&pred, &truth),
            };
            tracing::info!(seed, ?precision, train_s, spearman = q.held_out_spearman, "T-REX trained");
            out.push(q);
        }
    }
    let cfg = trex::TrexConfig { iterations: args.iterations, ..Default::default() };
    let mut out = serde_json::json!({
        "env": id.name(), "device": device.name(), "threads": threads,
        "train_trajectories": 20 * args.per_level, "held_out_trajectories": 20 * args.held_out_per_level,
        "models": cfg.models, "iterations": cfg.iterations,
        "f32": { "summary": summary(&runs[0]), "seeds": runs[0] },
    });
    if args.bf16 {
        let (f, b) = (&runs[0], &runs[1]);
        let secs = |r: &[Quality]| r.iter().map(|q| q.train_s).sum::<f64>();
        out["bf16"] = serde_json::json!({ "path": Bf16Path::active().name(), "summary": summary(b), "seeds": b });
        // Paired by seed: the same rollouts, the same pairs and initial weights.
        out["bf16_minus_f32_mean"] = serde_json::json!({
            "held_out_spearman": b.iter().zip(f).map(|(b, f)| b.held_out_spearman - f.held_out_spearman).sum::<f64>() / f.len() as f64,
            "held_out_pearson": b.iter().zip(f).map(|(b, f)| b.held_out_pearson - f.held_out_pearson).sum::<f64>() / f.len() as f64,
            "held_out_pairwise_accuracy":
                b.iter().zip(f).map(|(b, f)| b.held_out_pairwise_accuracy - f.held_out_pairwise_accuracy).sum::<f64>() / f.len() as f64,
        });
        out["bf16_speedup"] = serde_json::json!(secs(f) / secs(b));
    }
    Ok(out)
}
