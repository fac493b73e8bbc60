//! The command line: clap definitions and a thin function per command, one file per command
//! group; the work is done by library functions. `anyhow` lives at the binary's edge: here,
//! `main.rs` and the benchmarks (`bench`, commands too); the library returns [`crate::Error`].
mod bank;
mod env;
mod exp;
mod logs;
mod pipeline;
mod report;
mod stage;
mod store;
mod train;

use clap::{Args, Parser, Subcommand};

use crate::log::table::{Format, Table};

/// Fields of the pipeline file set from the command line.
#[derive(Debug, Clone, Default, Args)]
pub struct SetArgs {
    /// Set a field of the file, `-S reward.ceiling=0.5`, or sweep it, `-S reward.ceiling=0.5,none`
    /// (one variant per value, each its own study: `NAME[reward.ceiling=0.5]`); repeatable, and
    /// several sweeps run every combination. Checked as the file's own value would be.
    #[arg(short = 'S', long = "set", value_name = "FIELD=VALUE")]
    pub set: Vec<String>,
}

/// How a command with tabular output prints it: aligned text by default.
#[derive(Debug, Clone, Args)]
pub struct TableArgs {
    /// CSV on stdout (an interval as `_ci_low` and `_ci_high` columns).
    #[arg(long, conflicts_with_all = ["json", "markdown"])]
    pub csv: bool,
    /// JSON on stdout: an array of objects, keys in column order.
    #[arg(long, conflicts_with = "markdown")]
    pub json: bool,
    /// A markdown table.
    #[arg(long)]
    pub markdown: bool,
}

impl TableArgs {
    pub fn format(&self) -> Format {
        match (self.csv, self.json, self.markdown) {
            (true, ..) => Format::Csv,
            (_, true, _) => Format::Json,
            (.., true) => Format::Markdown,
            _ => Format::Text,
        }
    }

    /// Whether a machine format was asked for (the command's own text is then left out).
    pub fn machine(&self) -> bool {
        self.format() != Format::Text
    }

    pub fn print(&self, t: &Table) {
        print!("{}", t.write(self.format()));
    }
}

#[derive(Debug, Parser)]
#[command(name = "idrex", version = crate::VERSION, about = "Reward learning from automatically ranked demonstrations (D-REX, iD-REX)")]
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
    Env(env::EnvCommand),
    /// Benchmarks, reported as ratios against a baseline measured in the same run.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Train a policy on the ground-truth reward.
    #[command(subcommand)]
    Train(train::TrainCommand),
    /// Evaluate a saved policy: ground-truth return of its stochastic policy (or, --mean, its mean action).
    Eval(train::EvalArgs),
    /// Run or inspect a pipeline file.
    #[command(subcommand)]
    Pipeline(pipeline::PipelineCommand),
    /// Run one stored node definition (what a Slurm job runs).
    #[command(subcommand)]
    Stage(stage::StageCommand),
    /// Re-hash every artifact in the store and list the corrupt ones.
    Verify(store::StoreArgs),
    /// Remove artifacts that no given pipeline file references (a dry run unless --yes).
    Gc(store::GcArgs),
    /// Write the manifests of a pipeline's stored stages (parameters, metrics, output digests;
    /// no outputs) to one file to commit: `idrex report --archive` rebuilds the report from it
    /// on any machine.
    Export(store::ExportArgs),
    /// Reopen MCAP rollout files.
    #[command(subcommand)]
    Logs(logs::LogsCommand),
    /// Comparison tables (CSV and markdown) from the store's evaluation results.
    Report(report::ReportArgs),
    /// The store's studies at a glance (`show`), and two of them side by side (`diff`).
    #[command(subcommand)]
    Exp(exp::ExpCommand),
    /// The reward bench: score learned rewards on their task's bank of gaits.
    #[command(subcommand)]
    Bank(bank::BankCommand),
}

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Environment steps/s next to the raw mj_step rate and Gymnasium's Python environment.
    Env(crate::bench::EnvBenchArgs),
    /// T-REX on epsilon-greedy rollouts of a trained policy: rank correlation of predicted and
    /// true returns on held-out rollouts, and the training time.
    Trex(crate::bench::TrexBenchArgs),
    /// T-REX and BC training speed at the report's shapes next to the same loops in PyTorch
    /// (run by this command), and the fraction of the machine's fp32 matrix-product rate.
    Learners(crate::bench::LearnersBenchArgs),
    /// A PPO run at CleanRL's settings broken down by phase (environment, policy inference,
    /// reward, update, the rest), next to the environment's mj_step bound measured in the
    /// same run.
    Ppo(crate::bench::PpoBenchArgs),
    /// Multi-BC's clone settings on a pipeline's stored D-REX runs: each clone's noise-free
    /// true return against its source's (0 = uniform-random, 1 = the source).
    Clones(crate::bench::clones::ClonesBenchArgs),
    /// `exp show` on a generated store of many studies, next to reading its manifests alone.
    Exp(crate::bench::exp::ExpBenchArgs),
}

#[allow(unsafe_code)] // MuJoCo's logging hook
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

/// Runs a benchmark that answers once, at the end, under a spinner on stderr (a terminal
/// only), cleared before its JSON is printed.
fn quiet_until_done(what: &str, work: impl FnOnce() -> anyhow::Result<serde_json::Value>) -> anyhow::Result<()> {
    let activity = crate::log::progress::Activity::start(what);
    let out = work();
    drop(activity);
    println!("{}", serde_json::to_string_pretty(&out?)?);
    Ok(())
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Env(cmd) => env::run(&cmd),
        Command::Bench(BenchCommand::Env(args)) => crate::bench::env_bench(&args),
        // These print once, at the end: a spinner shows they are at work until then.
        Command::Bench(BenchCommand::Trex(args)) => {
            quiet_until_done("bench trex: training and ranking", || crate::bench::trex_bench(&args))
        }
        Command::Bench(BenchCommand::Learners(args)) => {
            quiet_until_done("bench learners: idrex, then PyTorch", || crate::bench::learners_bench(&args))
        }
        Command::Bench(BenchCommand::Ppo(args)) => {
            quiet_until_done("bench ppo: idrex, then Stable-Baselines3", || crate::bench::ppo_bench(&args))
        }
        Command::Bench(BenchCommand::Clones(args)) => {
            let (p, store) = pipeline::load(&args.file, args.store.as_deref(), None, pipeline::StoreAccess::Read)?;
            crate::bench::clones::clones_bench(&args, &p, &store)
        }
        Command::Bench(BenchCommand::Exp(args)) => Ok(crate::bench::exp::exp_bench(&args)?),
        Command::Train(cmd) => train::run(&cmd),
        Command::Eval(args) => train::eval(&args),
        Command::Pipeline(cmd) => pipeline::run(&cmd),
        Command::Stage(cmd) => stage::run(&cmd),
        Command::Verify(args) => store::verify(&args),
        Command::Gc(args) => store::gc(&args),
        Command::Export(args) => store::export(&args),
        Command::Logs(cmd) => logs::run(&cmd),
        Command::Report(args) => report::run(&args),
        Command::Exp(cmd) => exp::run(&cmd),
        Command::Bank(cmd) => bank::run(&cmd),
    }
}
