//! The command line: clap definitions and one function per command. `anyhow` lives here and
//! in `main.rs` only; the library returns [`crate::Error`].
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};

use crate::env::{Env, EnvId};

#[derive(Debug, Parser)]
#[command(name = "idrex", version, about = "Reward learning from automatically ranked demonstrations (D-REX, iD-REX)")]
pub struct Cli {
    /// More log output (-v info, -vv debug); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Drive one environment directly.
    #[command(subcommand)]
    Env(EnvCommand),
    /// Benchmarks, reported as ratios against a baseline measured in the same run.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Train a policy on the ground-truth reward.
    #[command(subcommand)]
    Train(TrainCommand),
    /// Evaluate a saved policy: ground-truth return of its stochastic policy.
    Eval(EvalArgs),
    /// Run or inspect a pipeline file.
    #[command(subcommand)]
    Pipeline(PipelineCommand),
    /// Re-hash every artifact in the store and list the corrupt ones.
    Verify(StoreArgs),
    /// Remove artifacts that no given pipeline file references (a dry run unless --yes).
    Gc(GcArgs),
    /// Reopen MCAP rollout files.
    #[command(subcommand)]
    Logs(LogsCommand),
    /// Comparison tables (CSV and markdown) from the store's evaluation results.
    Report(ReportArgs),
}

#[derive(Debug, Args)]
pub struct StoreArgs {
    /// Artifact store directory.
    #[arg(long, default_value = "artifacts")]
    pub store: PathBuf,
}

#[derive(Debug, Subcommand)]
pub enum PipelineCommand {
    /// Compute every missing node of the pipeline.
    Run(PipelineRunArgs),
    /// Print the DAG with each node's key and whether it is stored.
    Plan(PipelinePlanArgs),
}

#[derive(Debug, Args)]
pub struct PipelineRunArgs {
    pub file: PathBuf,
    /// Store directory (overrides the pipeline file's `store`).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// Stages run in parallel (default: the number of cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Recompute these nodes even if stored (repeatable).
    #[arg(long)]
    pub force: Vec<String>,
    /// Where the Rerun recording goes (default: recordings/<pipeline>-<env>.rrd).
    #[arg(long)]
    pub recording: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct PipelinePlanArgs {
    pub file: PathBuf,
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// text, dot or mermaid.
    #[arg(long, default_value = "text")]
    pub format: String,
}

#[derive(Debug, Args)]
pub struct GcArgs {
    /// Pipeline files whose artifacts are kept.
    pub files: Vec<PathBuf>,
    #[arg(long, default_value = "artifacts")]
    pub store: PathBuf,
    /// Really delete (default: only list what would go).
    #[arg(long)]
    pub yes: bool,
}

#[derive(Debug, Subcommand)]
pub enum LogsCommand {
    /// Episodes with length, return and noise level.
    List { file: PathBuf },
    /// The steps of one episode, one JSON line each.
    Show {
        file: PathBuf,
        #[arg(long, default_value_t = 0)]
        episode: usize,
    },
    /// Every step as CSV or NDJSON.
    Export {
        file: PathBuf,
        /// csv or ndjson.
        #[arg(long, default_value = "csv")]
        format: String,
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Debug, Args)]
pub struct ReportArgs {
    #[arg(long, default_value = "artifacts")]
    pub store: PathBuf,
    /// csv, md or both.
    #[arg(long, default_value = "both")]
    pub format: String,
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
}

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
}

#[derive(Debug, Subcommand)]
pub enum EnvCommand {
    /// Replay actions from a state and print one JSON line per step.
    Rollout(RolloutArgs),
}

#[derive(Debug, Args)]
pub struct RolloutArgs {
    /// Environment id: HalfCheetah-v5, Hopper-v5 or Walker2d-v5.
    #[arg(long)]
    pub env: String,
    /// JSON file {"qpos": [...], "qvel": [...]} to start from, instead of a seeded reset.
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// CSV file with one action per line (comma-separated numbers).
    #[arg(long)]
    pub actions: PathBuf,
    /// Seed of the reset when no --state is given.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Environment steps/s next to the raw mj_step rate and Gymnasium's Python environment.
    Env(crate::bench::EnvBenchArgs),
    /// T-REX on epsilon-greedy rollouts of a trained policy: rank correlation of predicted and
    /// true returns on held-out rollouts, and the training time.
    Trex(crate::bench::TrexBenchArgs),
}

pub fn init_tracing(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    // MuJoCo's messages go through the log facade into tracing. Its model compiler warns
    // about a deprecated attribute in gymnasium's own XML files on every load; that is not
    // the user's to fix, so MuJoCo is shown from `error` up unless RUST_LOG says otherwise.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{default},mujoco=error")));
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).try_init();
    // SAFETY: called at start-up, before any thread uses MuJoCo.
    unsafe { mujoco_rs::prelude::install_logging_hook() };
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Env(EnvCommand::Rollout(args)) => env_rollout(&args),
        Command::Bench(BenchCommand::Env(args)) => crate::bench::env_bench(&args),
        Command::Bench(BenchCommand::Trex(args)) => crate::bench::trex_bench(&args),
        Command::Train(TrainCommand::Ppo(args)) => train_ppo(&args),
        Command::Eval(args) => eval(&args),
        Command::Pipeline(PipelineCommand::Run(args)) => pipeline_run(&args),
        Command::Pipeline(PipelineCommand::Plan(args)) => pipeline_plan(&args),
        Command::Verify(args) => verify(&args),
        Command::Gc(args) => gc(&args),
        Command::Logs(cmd) => logs(&cmd),
        Command::Report(args) => report(&args),
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StateFile {
    qpos: Vec<f64>,
    qvel: Vec<f64>,
}

/// Reads a CSV of actions: one action per line, `width` comma-separated numbers each.
pub fn read_actions(path: &Path, width: usize) -> anyhow::Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut actions = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let row = line
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<Vec<_>, _>>()
            .with_context(|| format!("{} line {}: not a comma-separated list of numbers: '{line}'", path.display(), i + 1))?;
        if row.len() != width {
            bail!("{} line {}: expected {width} action values, got {}", path.display(), i + 1, row.len());
        }
        actions.push(row);
    }
    Ok(actions)
}

/// The numbers of the JSON array under `key`, parsed with Rust's correctly rounded parser.
fn exact_array(text: &str, key: &str) -> Option<Vec<f64>> {
    let at = text.find(&format!("\"{key}\""))?;
    let rest = &text[at..];
    let open = rest.find('[')?;
    let close = rest[open..].find(']')? + open;
    let body = rest[open + 1..close].trim();
    if body.is_empty() {
        return Some(vec![]);
    }
    body.split(',').map(|x| x.trim().parse::<f64>().ok()).collect()
}

fn env_rollout(args: &RolloutArgs) -> anyhow::Result<()> {
    // Parsed here rather than by clap so that the error is one line like every other.
    let mut env = Env::new(args.env.parse::<EnvId>()?)?;
    let mut obs = vec![0.0; env.obs_dim()];
    let actions = read_actions(&args.actions, env.act_dim())?;
    match &args.state {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
            let state: StateFile = serde_json::from_str(&text)
                .with_context(|| format!("{}: expected {{\"qpos\": [...], \"qvel\": [...]}}", path.display()))?;
            // serde_json's float parsing may be off by an ulp; re-read the numbers exactly so
            // that a replay starts from bit-identical state.
            let qpos = exact_array(&text, "qpos").filter(|v| v.len() == state.qpos.len()).unwrap_or(state.qpos);
            let qvel = exact_array(&text, "qvel").filter(|v| v.len() == state.qvel.len()).unwrap_or(state.qvel);
            env.set_state(&qpos, &qvel, &mut obs).with_context(|| path.display().to_string())?;
        }
        None => env.reset(Some(args.seed), &mut obs),
    }
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for (t, action) in actions.iter().enumerate() {
        let info = env.step(action, &mut obs)?;
        let line = serde_json::json!({
            "step": t,
            "obs": obs,
            "reward": info.reward,
            "terminated": info.terminated,
            "truncated": info.truncated,
            "reward_forward": info.terms.reward_forward,
            "reward_ctrl": info.terms.reward_ctrl,
            "reward_survive": info.terms.reward_survive,
            "x_position": info.x_position,
            "x_velocity": info.x_velocity,
        });
        writeln!(out, "{line}")?;
        if info.terminated || info.truncated {
            break;
        }
    }
    out.flush()?;
    Ok(())
}

fn train_ppo(args: &TrainPpoArgs) -> anyhow::Result<()> {
    use crate::algo::ppo;
    let id: EnvId = args.env.parse()?;
    let cfg = ppo::PpoConfig {
        total_steps: args.steps,
        num_envs: args.num_envs,
        threads: args.threads,
        eval_every: args.eval_every,
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
    let mut curve = String::from(
        "global_step,episodic_return,policy_loss,value_loss,entropy,approx_kl,clipfrac,explained_variance,sps,eval_mean,eval_std\n",
    );
    let mut on_update = |p: &ppo::PpoProgress| {
        bar.set_position(p.global_step as u64);
        if let Some(r) = p.episodic_return {
            bar.set_message(format!("return {r:.1}"));
        }
        if let Some(e) = &p.eval {
            let line = format!(
                "step {:>8}: eval return {:.1} +- {:.1} over {} episodes ({:.0} steps/s)",
                p.global_step, e.mean, e.std, e.episodes, p.sps
            );
            // A hidden bar (no terminal) drops println; the evaluation lines must still show.
            if bar.is_hidden() { println!("{line}") } else { bar.println(line) }
        }
        let f = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v}"));
        curve.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{}\n",
            p.global_step,
            f(p.episodic_return),
            p.policy_loss,
            p.value_loss,
            p.entropy,
            p.approx_kl,
            p.clipfrac,
            p.explained_variance,
            p.sps,
            f(p.eval.map(|e| e.mean)),
            f(p.eval.map(|e| e.std))
        ));
        true
    };
    let out = args.out.clone();
    let hyper = serde_json::to_value(&cfg)?;
    let hyper_ck = hyper.clone();
    let mut save_ck = |p: &crate::nn::ActorCritic, step: usize| p.save(&ppo::checkpoint_dir(&out, step), hyper_ck.clone());
    let res = ppo::train(id, &cfg, ppo::RewardSource::GroundTruth, args.seed, &mut on_update, Some((&mut save_ck, args.checkpoint_every)))?;
    bar.finish_and_clear();
    res.policy.save(&args.out, hyper)?;
    std::fs::write(args.out.join("curve.csv"), curve)?;
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

fn eval(args: &EvalArgs) -> anyhow::Result<()> {
    let policy = crate::nn::ActorCritic::load(&args.policy)?;
    let name = args
        .env
        .clone()
        .or_else(|| policy.env.clone())
        .with_context(|| format!("{} does not name its environment; pass --env", args.policy.display()))?;
    let id: EnvId = name.parse()?;
    let stats = crate::algo::ppo::evaluate(&policy, id, args.episodes, args.seed)?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({"env": id.name(), "policy": args.policy, "mean": stats.mean, "std": stats.std, "min": stats.min, "max": stats.max, "episodes": stats.episodes})
        );
    } else {
        println!(
            "{id}: return {:.1} +- {:.1} (min {:.1}, max {:.1}) over {} episodes",
            stats.mean, stats.std, stats.min, stats.max, stats.episodes
        );
    }
    Ok(())
}

fn load_pipeline(file: &Path, store: &Option<PathBuf>) -> anyhow::Result<(crate::pipeline::Pipeline, crate::store::Store)> {
    let p = crate::pipeline::Pipeline::load(file).map_err(|e| anyhow::anyhow!("{e}"))?;
    let root = store.clone().unwrap_or_else(|| p.store.clone());
    let store = crate::store::Store::open(&root).with_context(|| format!("cannot open the store {}", root.display()))?;
    Ok((p, store))
}

fn pipeline_plan(args: &PipelinePlanArgs) -> anyhow::Result<()> {
    let (p, store) = load_pipeline(&args.file, &args.store)?;
    if !["text", "dot", "mermaid"].contains(&args.format.as_str()) {
        bail!("--format {}: write text, dot or mermaid", args.format);
    }
    let g = crate::pipeline::expand(&p)?;
    let keys = g.keys();
    let stored = |k: &str| store.check(k).is_ok();
    print!("{}", crate::pipeline::graph::render(&g, &keys, &stored, &args.format));
    Ok(())
}

fn pipeline_run(args: &PipelineRunArgs) -> anyhow::Result<()> {
    use crate::pipeline::runner::{self, Status};
    let (p, store) = load_pipeline(&args.file, &args.store)?;
    let g = crate::pipeline::expand(&p)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let opts = runner::RunOptions { jobs: args.jobs.unwrap_or(cores), force: args.force.clone(), progress: true };
    let started = std::time::Instant::now();
    let body = |n: &crate::pipeline::Node, ctx: &crate::pipeline::stages::StageCtx| crate::pipeline::stages::run(n.kind, ctx);
    let outcomes = runner::run(&g, &store, &opts, &body)?;
    let count = |f: &dyn Fn(&Status) -> bool| outcomes.iter().filter(|o| f(&o.status)).count();
    let failed: Vec<_> = outcomes.iter().filter(|o| matches!(o.status, Status::Failed { .. } | Status::Skipped { .. })).collect();
    println!(
        "{}: {} stages, {} computed, {} reused from {}, {} failed, {} skipped ({:.1} s)",
        p.name,
        outcomes.len(),
        count(&|s| matches!(s, Status::Computed { .. })),
        count(&|s| matches!(s, Status::Cached)),
        store.root().display(),
        count(&|s| matches!(s, Status::Failed { .. })),
        count(&|s| matches!(s, Status::Skipped { .. })),
        started.elapsed().as_secs_f64()
    );
    let rec = args.recording.clone().unwrap_or_else(|| PathBuf::from("recordings").join(format!("{}-{}.rrd", p.name, p.env.name())));
    if let Some(dir) = rec.parent() {
        std::fs::create_dir_all(dir).ok();
    }
    crate::pipeline::plots::record(&g, &outcomes, &store, &rec, &p.name)?;
    println!("recording: {}", rec.display());
    if !failed.is_empty() {
        for o in &failed {
            match &o.status {
                Status::Failed { error, log } => eprintln!("failed: {} ({}): {error}; log: {}", o.node, &o.key[..12], log.display()),
                Status::Skipped { because } => eprintln!("skipped: {} (its input {because} failed)", o.node),
                _ => {}
            }
        }
        bail!("{} of {} stages did not complete", failed.len(), outcomes.len());
    }
    Ok(())
}

fn verify(args: &StoreArgs) -> anyhow::Result<()> {
    let store = crate::store::Store::open(&args.store)?;
    let keys = store.keys()?;
    let bad = store.verify()?;
    for (k, problem) in &bad {
        println!("corrupt {k}: {problem}");
    }
    println!("{} artifacts, {} corrupt", keys.len(), bad.len());
    if !bad.is_empty() {
        bail!("{} corrupt artifacts in {}; `idrex pipeline run` recomputes them", bad.len(), args.store.display());
    }
    Ok(())
}

fn gc(args: &GcArgs) -> anyhow::Result<()> {
    if args.files.is_empty() {
        bail!("name the pipeline files whose artifacts to keep, e.g. `idrex gc pipelines/*.yaml`");
    }
    let store = crate::store::Store::open(&args.store)?;
    let mut keep = std::collections::BTreeSet::new();
    for f in &args.files {
        let (p, _) = load_pipeline(f, &Some(args.store.clone()))?;
        keep.extend(crate::pipeline::expand(&p)?.keys().into_values());
    }
    let removed = store.gc(&keep, !args.yes)?;
    for k in &removed {
        println!("{} {k}", if args.yes { "removed" } else { "would remove" });
    }
    println!(
        "{} artifacts {}; {} kept",
        removed.len(),
        if args.yes { "removed" } else { "unreferenced (dry run; --yes deletes them)" },
        keep.len()
    );
    Ok(())
}

fn logs(cmd: &LogsCommand) -> anyhow::Result<()> {
    use crate::log::mcap;
    match cmd {
        LogsCommand::List { file } => {
            let r = mcap::read(file)?;
            println!("{}: {} episodes of {}", file.display(), r.trajectories.len(), r.env);
            println!("{:>7} {:>7} {:>12} {:>8} {:>6} {:<11} source", "episode", "length", "return", "noise", "group", "end");
            for (i, t) in r.trajectories.iter().enumerate() {
                let end = if t.terminated {
                    "terminated"
                } else if t.truncated {
                    "truncated"
                } else {
                    "-"
                };
                println!("{i:>7} {:>7} {:>12.2} {:>8.3} {:>6} {end:<11} {}", t.len(), t.ret(), t.meta.noise, t.meta.group, t.meta.source);
            }
        }
        LogsCommand::Show { file, episode } => {
            let r = mcap::read(file)?;
            let t = r
                .trajectories
                .get(*episode)
                .with_context(|| format!("{} has {} episodes; --episode {episode} does not exist", file.display(), r.trajectories.len()))?;
            for s in 0..t.len() {
                println!("{}", step_json(&r, *episode, t, s));
            }
        }
        LogsCommand::Export { file, format, out } => {
            let r = mcap::read(file)?;
            let mut w = std::io::BufWriter::new(std::fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?);
            match format.as_str() {
                "ndjson" => {
                    for (e, t) in r.trajectories.iter().enumerate() {
                        for s in 0..t.len() {
                            writeln!(w, "{}", step_json(&r, e, t, s))?;
                        }
                    }
                }
                "csv" => {
                    let (od, ad) = r.trajectories.first().map_or((0, 0), |t| (t.obs_dim, t.act_dim));
                    let mut header = vec!["episode".to_string(), "t".into(), "noise".into(), "group".into()];
                    header.extend((0..od).map(|i| format!("obs_{i}")));
                    header.extend((0..ad).map(|i| format!("action_{i}")));
                    header.extend(
                        ["reward", "reward_forward", "reward_ctrl", "reward_survive", "learned_reward", "terminated", "truncated"]
                            .map(String::from),
                    );
                    writeln!(w, "{}", header.join(","))?;
                    for (e, t) in r.trajectories.iter().enumerate() {
                        for s in 0..t.len() {
                            let mut row = vec![e.to_string(), s.to_string(), t.meta.noise.to_string(), t.meta.group.to_string()];
                            row.extend(t.obs_row(s).iter().map(|x| x.to_string()));
                            row.extend(t.action_row(s).iter().map(|x| x.to_string()));
                            let last = s + 1 == t.len();
                            let learned = r.learned.as_ref().and_then(|l| l[e].get(s)).map_or(String::new(), |x| x.to_string());
                            row.extend([
                                t.rewards[s].to_string(),
                                t.terms[s].reward_forward.to_string(),
                                t.terms[s].reward_ctrl.to_string(),
                                t.terms[s].reward_survive.to_string(),
                                learned,
                                (last && t.terminated).to_string(),
                                (last && t.truncated).to_string(),
                            ]);
                            writeln!(w, "{}", row.join(","))?;
                        }
                    }
                }
                other => bail!("--format {other}: write csv or ndjson"),
            }
            w.flush()?;
        }
    }
    Ok(())
}

fn step_json(r: &crate::log::mcap::Rollouts, e: usize, t: &crate::data::Trajectory, s: usize) -> serde_json::Value {
    let last = s + 1 == t.len();
    serde_json::json!({"episode": e, "t": s, "obs": t.obs_row(s), "action": t.action_row(s), "reward": t.rewards[s],
        "reward_forward": t.terms[s].reward_forward, "reward_ctrl": t.terms[s].reward_ctrl, "reward_survive": t.terms[s].reward_survive,
        "learned_reward": r.learned.as_ref().and_then(|l| l[e].get(s)), "terminated": last && t.terminated, "truncated": last && t.truncated})
}

fn report(args: &ReportArgs) -> anyhow::Result<()> {
    if !["csv", "md", "both"].contains(&args.format.as_str()) {
        bail!("--format {}: write csv, md or both", args.format);
    }
    let store = crate::store::Store::open(&args.store)?;
    let mut t = crate::report::build(&store)?;
    if t.returns.height() == 0 {
        bail!("{} holds no evaluation results yet; run a pipeline first (`idrex pipeline run pipelines/smoke.yaml`)", args.store.display());
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    if args.format != "md" {
        crate::report::write_csv(&mut t.returns, &args.out.join("returns.csv"))?;
        crate::report::write_csv(&mut t.demos, &args.out.join("demos.csv"))?;
        crate::report::write_csv(&mut t.accuracy, &args.out.join("reward_accuracy.csv"))?;
    }
    let md = crate::report::markdown(&t);
    if args.format != "csv" {
        std::fs::write(args.out.join("report.md"), &md)?;
    }
    print!("{md}");
    Ok(())
}
