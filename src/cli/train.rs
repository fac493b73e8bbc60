//! `idrex train ppo` and `idrex eval`: PPO on the true reward outside a pipeline, and the
//! evaluation of a saved policy.
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use crate::algo::ppo;
use crate::env::EnvId;
use crate::pipeline::stage::RolloutSummary;
use crate::report::terms::EarnedBy;

#[derive(Debug, Subcommand)]
pub enum TrainCommand {
    /// PPO with CleanRL's hyper-parameters.
    Ppo(TrainPpoArgs),
}

#[derive(Debug, Args)]
pub struct TrainPpoArgs {
    #[arg(long)]
    pub env: String,
    /// Environment steps.
    #[arg(long, default_value_t = 1_000_000)]
    pub steps: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Directory for the final policy, checkpoints and the learning curve.
    #[arg(long)]
    pub out: PathBuf,
    /// Parallel environments (CleanRL: 1).
    #[arg(long, default_value_t = 1)]
    pub num_envs: usize,
    /// Threads for libtorch and the environments.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Evaluate every this many steps (stochastic policy, 5 episodes).
    #[arg(long, default_value_t = 100_000)]
    pub eval_every: usize,
    /// Save a checkpoint every this many updates (0: only the final policy).
    #[arg(long, default_value_t = 50)]
    pub checkpoint_every: usize,
}

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A directory holding policy.safetensors and policy.json.
    #[arg(long)]
    pub policy: PathBuf,
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Environment, when the policy does not name one.
    #[arg(long)]
    pub env: Option<String>,
    #[arg(long)]
    pub json: bool,
    /// Act with the policy's mean action instead of sampling.
    #[arg(long)]
    pub mean: bool,
}

pub fn run(cmd: &TrainCommand) -> anyhow::Result<()> {
    let TrainCommand::Ppo(args) = cmd;
    let id: EnvId = args.env.parse()?;
    let cfg = ppo::PpoConfig {
        total_steps: args.steps,
        num_envs: args.num_envs,
        threads: args.threads,
        eval_every: args.eval_every,
        checkpoint_every: args.checkpoint_every,
        ..Default::default()
    };
    let batch = cfg.num_envs * cfg.num_steps;
    if args.steps < batch {
        bail!(
            "--steps {} is less than one rollout ({} envs x {} steps = {batch}); ask for at least {batch}",
            args.steps,
            cfg.num_envs,
            cfg.num_steps
        );
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let bar = indicatif::ProgressBar::new(args.steps as u64).with_style(
        indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} steps ({per_sec}) {msg}")
            .expect("a valid template"),
    );
    let mut on_update = |p: &ppo::PpoProgress| {
        bar.set_position(p.global_step as u64);
        if let Some(r) = p.episodic_return {
            bar.set_message(format!("true return {r:.1}"));
        }
        if let Some(e) = &p.eval {
            let line = format!(
                "step {:>8}: eval return {:.1} +- {:.1} over {} episodes ({:.0} steps/s)",
                p.global_step, e.mean, e.std, e.episodes, p.sps
            );
            // A hidden bar (no terminal) drops println; the evaluation lines must still show.
            if bar.is_hidden() { println!("{line}") } else { bar.println(line) }
        }
        true
    };
    let hyper = serde_json::to_value(&cfg)?;
    let mut save = |p: &crate::nn::ActorCritic, step: usize| p.save(&ppo::checkpoint_dir(&args.out, step), hyper.clone());
    let res = ppo::train(id, &cfg, ppo::RewardSource::GroundTruth, args.seed, &mut on_update, Some(&mut save))?;
    bar.finish_and_clear();
    res.policy.save(&args.out, serde_json::to_value(&cfg)?)?;
    ppo::write_curve(&args.out.join("curve.csv"), &res.curve)?;
    let last = res.curve.last();
    println!(
        "trained {} for {} steps in {:.1} s ({:.0} steps/s); final training return {}; policy in {}",
        id,
        last.map_or(0, |p| p.global_step),
        res.wall_s,
        last.map_or(0, |p| p.global_step) as f64 / res.wall_s,
        last.and_then(|p| p.episodic_return).map_or("-".into(), |r| format!("{r:.1}")),
        args.out.display()
    );
    Ok(())
}

pub fn eval(args: &EvalArgs) -> anyhow::Result<()> {
    let policy = crate::nn::ActorCritic::load(&args.policy)?;
    let name = args
        .env
        .clone()
        .or_else(|| policy.env.clone())
        .with_context(|| format!("{} does not name its environment; pass --env", args.policy.display()))?;
    let id: EnvId = name.parse()?;
    let evaluating = crate::log::progress::Activity::start(format!("eval: {} episodes of {id}", args.episodes));
    let episodes = ppo::evaluation_episodes(&policy, id, args.episodes, args.seed, args.mean)?;
    drop(evaluating);
    let summary = RolloutSummary::of(&episodes).with_terms(&episodes);
    let (stats, terms) = (&summary.stats, summary.terms.as_ref().expect("with_terms"));
    let per_episode = |v: &[f64]| crate::stats::mean(v).unwrap_or(f64::NAN);
    let lengths: Vec<f64> = summary.lengths.iter().map(|&n| n as f64).collect();
    let (length, forward, ctrl, survive, contact) = (
        per_episode(&lengths),
        per_episode(&terms.forward),
        per_episode(&terms.ctrl),
        per_episode(&terms.survive),
        per_episode(&terms.contact),
    );
    let earned_by = EarnedBy::of(id, length, forward, survive).name();
    if args.json {
        println!(
            "{}",
            serde_json::json!({"env": id.name(), "policy": args.policy, "acting": if args.mean { "mean" } else { "sampled" },
                "mean": stats.mean, "std": stats.std, "min": stats.min, "max": stats.max, "episodes": stats.episodes,
                "length": length, "forward": forward, "ctrl": ctrl, "survive": survive, "contact": contact, "earned_by": earned_by})
        );
    } else {
        println!(
            "{id}: return {:.1} +- {:.1} (min {:.1}, max {:.1}) over {} episodes of {length:.0} steps on average; \
             per episode forward {forward:.1}, control {ctrl:.1}, healthy {survive:.1}, contact {contact:.1}: {earned_by}",
            stats.mean, stats.std, stats.min, stats.max, stats.episodes
        );
    }
    Ok(())
}
