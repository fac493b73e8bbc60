//! `idrex pipeline run|plan`.
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use crate::pipeline::graph::{self, PlanFormat};
use crate::pipeline::runner::{self, Status};
use crate::pipeline::{Pipeline, expand, plots, stage};
use crate::store::Store;

#[derive(Debug, Subcommand)]
pub enum PipelineCommand {
    /// Compute every missing node of the pipeline.
    Run(RunArgs),
    /// Print the DAG with each node's key and whether it is stored.
    Plan(PlanArgs),
}

#[derive(Debug, Args)]
pub struct RunArgs {
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
pub struct PlanArgs {
    pub file: PathBuf,
    #[arg(long)]
    pub store: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = PlanFormat::Text)]
    pub format: PlanFormat,
}

pub fn run(cmd: &PipelineCommand) -> anyhow::Result<()> {
    match cmd {
        PipelineCommand::Run(args) => pipeline_run(args),
        PipelineCommand::Plan(args) => plan(args),
    }
}

/// Whether a command writes to the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreAccess {
    Read,
    Write,
}

/// The pipeline file and the store it names (or `store` overrides).
pub fn load(file: &Path, store: Option<&Path>, access: StoreAccess) -> anyhow::Result<(Pipeline, Store)> {
    let p = Pipeline::load(file).map_err(|e| anyhow::anyhow!("{e}"))?;
    let root = store.map_or_else(|| p.store.clone(), Path::to_path_buf);
    let store = match access {
        StoreAccess::Read => Store::at(&root),
        StoreAccess::Write => Store::open(&root).with_context(|| format!("cannot open the store {}", root.display()))?,
    };
    Ok((p, store))
}

fn plan(args: &PlanArgs) -> anyhow::Result<()> {
    let (p, store) = load(&args.file, args.store.as_deref(), StoreAccess::Read)?;
    let g = expand(&p)?;
    let stored = |k: &str| store.check(k).is_ok();
    let keys = g.keys();
    print!("{}", graph::render(&g, &keys, &stored, args.format));
    if args.format == PlanFormat::Text {
        // What is left, estimated from the store's own stage times (see pipeline::schedule).
        let est = crate::pipeline::schedule::Estimates::from_manifests(&store.unverified_manifests().unwrap_or_default());
        let cost = |n: &crate::pipeline::Node| if stored(&keys[&n.name]) { 0.0 } else { est.seconds(n) };
        let (path, cp) = crate::pipeline::schedule::critical_path(&g, &cost);
        let total: f64 = g.nodes.iter().map(cost).sum();
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let path: Vec<&str> = path.iter().filter(|n| !stored(&keys[n.as_str()])).map(String::as_str).collect();
        let guessed: Vec<&str> = crate::pipeline::stage::StageKind::ALL.iter().filter(|k| !est.measured(**k)).map(|k| k.name()).collect();
        println!(
            "\nestimated: {:.1} min of stage time left, critical path {:.1} min; with {cores} jobs at least {:.1} min",
            total / 60.0,
            cp / 60.0,
            cp.max(total / cores as f64) / 60.0
        );
        if !path.is_empty() {
            println!("critical path: {}", path.join(" -> "));
        }
        if !guessed.is_empty() {
            println!("(no stored artifact of {}: their times are the reference machine's)", guessed.join(", "));
        }
    }
    Ok(())
}

fn pipeline_run(args: &RunArgs) -> anyhow::Result<()> {
    let (p, store) = load(&args.file, args.store.as_deref(), StoreAccess::Write)?;
    let g = expand(&p)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let opts = runner::RunOptions { jobs: args.jobs.unwrap_or(cores), force: args.force.clone(), progress: true };
    let started = std::time::Instant::now();
    let body = |n: &crate::pipeline::Node, ctx: &stage::StageCtx| stage::run(&n.params, ctx).map(|m| m.to_json());
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
    plots::record(&g, &outcomes, &store, &rec, &p.name)?;
    println!("recording: {}", rec.display());
    if failed.is_empty() {
        println!(
            "next: `idrex report --store {}` (tables and figures in report/), `rerun {}` (the plots)",
            store.root().display(),
            rec.display()
        );
    }
    if !failed.is_empty() {
        // One line per failed stage: its cause, its log, and how much it held up.
        for o in &outcomes {
            if let Status::Failed { error, log } = &o.status {
                let held_up = g
                    .descendants(&o.node)
                    .iter()
                    .filter(|d| outcomes.iter().any(|x| &x.node == *d && matches!(x.status, Status::Skipped { .. })))
                    .count();
                eprintln!("failed: {} ({}): {error}; log: {}; {held_up} stages after it skipped", o.node, &o.key[..12], log.display());
            }
        }
        bail!("{} of {} stages did not complete", failed.len(), outcomes.len());
    }
    Ok(())
}
