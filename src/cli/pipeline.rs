//! `idrex pipeline run|plan|status`.
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use crate::log::table::{Cell, Table};
use crate::nn::DeviceChoice;
use crate::pipeline::graph::{self, PlanFormat};
use crate::pipeline::runner::{self, Status};
use crate::pipeline::slurm::{self, NodeState, Submission};
use crate::pipeline::{Pipeline, Sweep, plots, stage};
use crate::store::{Location, Store};

#[derive(Debug, Subcommand)]
pub enum PipelineCommand {
    /// Compute every missing node of the pipeline.
    #[command(after_help = "Example: an ablation of the ceiling and the ensemble size, every combination one variant:\n  \
                            idrex pipeline run pipelines/hopper.yaml -S reward.ceiling=0.75,none -S trex.models=3,5")]
    Run(RunArgs),
    /// Print the DAG with each node's key and whether it is stored.
    Plan(PlanArgs),
    /// Each node's state: stored, queued, running (from Slurm's queue), failed or missing.
    Status(StatusArgs),
    /// Print the pipeline file's schema: JSON Schema (for editors that check YAML) or the
    /// reference table of docs/schema.md.
    Schema(SchemaArgs),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SchemaFormat {
    Json,
    Markdown,
}

#[derive(Debug, Args)]
pub struct SchemaArgs {
    #[arg(long, value_enum, default_value_t = SchemaFormat::Json)]
    pub format: SchemaFormat,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Executor {
    /// Run the stages here, `--jobs` at a time.
    Local,
    /// Submit each missing stage as a Slurm job (with dependencies) and return.
    Slurm,
}

#[derive(Debug, Args)]
pub struct RunArgs {
    pub file: PathBuf,
    /// Store directory or `s3://bucket/prefix` (overrides the pipeline file's `store`).
    #[arg(long)]
    pub store: Option<String>,
    #[arg(long, value_enum, default_value_t = Executor::Local)]
    pub executor: Executor,
    /// Slurm partition for every job (--executor slurm).
    #[arg(long)]
    pub partition: Option<String>,
    /// An extra sbatch argument for every job, e.g. `--sbatch-arg=--account=rl` (repeatable).
    #[arg(long = "sbatch-arg", allow_hyphen_values = true)]
    pub sbatch_args: Vec<String>,
    /// Where Slurm jobs write their output; must be visible to the compute nodes.
    #[arg(long, default_value = "slurm-logs")]
    pub log_dir: PathBuf,
    /// Stages run in parallel (default: the number of cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Recompute these nodes even if stored (repeatable).
    #[arg(long)]
    pub force: Vec<String>,
    /// Compute only these nodes and what they read (repeatable): a node's name, or a name's
    /// end for every replicate's (`--target drex/trex/bank-score` scores D-REX's rewards on
    /// the bank without running PPO).
    #[arg(long, value_name = "NODE")]
    pub target: Vec<String>,
    /// Run only this replicate of the file's (its stages' keys are those of the whole file's
    /// run), so that a long study lands one replicate at a time.
    #[arg(long, value_name = "R")]
    pub only_replicate: Option<usize>,
    /// Evaluate on a locked test set's seeds anyway (see `role: test`); the report marks
    /// these results as exploratory.
    #[arg(long)]
    pub reuse_test_set: bool,
    /// An archive of manifests (`idrex export`) whose evaluations count, beside the store's,
    /// as looks at their seeds (repeatable): a test set committed as archives stays locked on
    /// a machine whose store never held it.
    #[arg(long, value_name = "FILE")]
    pub archive: Vec<PathBuf>,
    /// Where the Rerun recording goes (default: recordings/<pipeline>-<env>.rrd).
    #[arg(long)]
    pub recording: Option<PathBuf>,
    /// Where BC, T-REX and PPO's learned reward compute (overrides the file's `device`;
    /// `auto` takes the GPU where libtorch sees one). The device is part of those stages' keys.
    #[arg(long, value_enum)]
    pub device: Option<DeviceChoice>,
    #[command(flatten)]
    pub set: super::SetArgs,
}

#[derive(Debug, Args)]
pub struct PlanArgs {
    pub file: PathBuf,
    /// Store directory or `s3://bucket/prefix` (overrides the pipeline file's `store`).
    #[arg(long)]
    pub store: Option<String>,
    #[arg(long, value_enum, default_value_t = PlanFormat::Text)]
    pub format: PlanFormat,
    /// The device to plan for (overrides the file's `device`), as `pipeline run --device`.
    #[arg(long, value_enum)]
    pub device: Option<DeviceChoice>,
    #[command(flatten)]
    pub set: super::SetArgs,
    /// The nodes as a table (node, kind, key, stored, inputs) in place of --format.
    #[command(flatten)]
    pub table: super::TableArgs,
}

#[derive(Debug, Args)]
pub struct StatusArgs {
    pub file: PathBuf,
    /// Store directory or `s3://bucket/prefix` (overrides the pipeline file's `store`).
    #[arg(long)]
    pub store: Option<String>,
    /// The device whose nodes to show (overrides the file's `device`).
    #[arg(long, value_enum)]
    pub device: Option<DeviceChoice>,
    #[command(flatten)]
    pub set: super::SetArgs,
    #[command(flatten)]
    pub table: super::TableArgs,
}

pub fn run(cmd: &PipelineCommand) -> anyhow::Result<()> {
    match cmd {
        PipelineCommand::Run(args) => pipeline_run(args),
        PipelineCommand::Plan(args) => plan(args),
        PipelineCommand::Status(args) => status(args),
        PipelineCommand::Schema(args) => {
            use crate::pipeline::config::schema;
            match args.format {
                SchemaFormat::Json => println!("{}", serde_json::to_string_pretty(&schema::json())?),
                SchemaFormat::Markdown => print!("{}", schema::markdown()),
            }
            Ok(())
        }
    }
}

/// Whether a command writes to the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreAccess {
    Read,
    Write,
}

/// The pipeline file (on `device`, where given) and the store it names (or `store` overrides).
pub fn load(file: &Path, store: Option<&str>, device: Option<DeviceChoice>, access: StoreAccess) -> anyhow::Result<(Pipeline, Store)> {
    let (s, store) = load_sweep(file, store, device, access, &[])?;
    Ok((s.file, store))
}

/// The pipeline file with the command line's `-S` settings: its variants (one without a
/// sweep), on `device` where given, and the store it names (or `store` overrides).
pub fn load_sweep(
    file: &Path,
    store: Option<&str>,
    device: Option<DeviceChoice>,
    access: StoreAccess,
    set: &[String],
) -> anyhow::Result<(Sweep, Store)> {
    let s = Sweep::load(file, set).map_err(|e| anyhow::anyhow!("{e}"))?;
    let s = match device {
        Some(choice) => s.map(|p| Ok(p.on(choice))).map_err(anyhow::Error::msg)?,
        None => s,
    };
    let location = match store {
        Some(s) => Location::parse(s)?,
        None => s.file.store.clone(),
    };
    let store = Store::connect(&location, access == StoreAccess::Write).with_context(|| format!("cannot open the store {location}"))?;
    Ok((s, store))
}

/// The nodes of a study, grouped by environment (one group, unnamed, for a single one).
fn env_groups<'a, T>(p: &Pipeline, items: &'a [T], name: impl Fn(&T) -> &str) -> Vec<(Option<&'static str>, Vec<&'a T>)> {
    if !p.is_study() {
        return vec![(None, items.iter().collect())];
    }
    // A sweep's own nodes carry their variant's label first.
    let of = |n: &str, e: &str| n.starts_with(&format!("{e}/")) || n.contains(&format!("/{e}/"));
    p.envs.iter().map(|e| (Some(e.name()), items.iter().filter(|t| of(name(t), e.name())).collect())).collect()
}

fn status(args: &StatusArgs) -> anyhow::Result<()> {
    let (sweep, store) = load_sweep(&args.file, args.store.as_deref(), args.device, StoreAccess::Read, &args.set.set)?;
    let p = &sweep.file;
    store.index()?;
    let g = sweep.graph()?;
    let keys = g.keys();
    // Without Slurm, the store alone answers (a claimed node then shows its last job).
    let queue = match slurm::Queue::read() {
        Ok(q) => Some(q),
        Err(e) => {
            eprintln!("note: {e}; showing the store's view only");
            None
        }
    };
    let mut counts: std::collections::BTreeMap<&str, usize> = Default::default();
    let mut rows = Vec::new();
    let text = !args.table.machine();
    for (env, nodes) in env_groups(p, &g.nodes, |n| n.name.as_str()) {
        if let Some(env) = env
            && text
        {
            println!("{env}:");
        }
        for n in nodes {
            let key = &keys[&n.name];
            let state = slurm::node_state(&store, key, queue.as_ref())?;
            *counts.entry(state.label()).or_default() += 1;
            let detail = match &state {
                NodeState::Queued { job, reason } => format!("job {job} ({reason})"),
                NodeState::Running { job } => format!("job {job}"),
                NodeState::Failed { job, log } => format!("job {job}; log {}", log.display()),
                NodeState::Stored | NodeState::Missing => String::new(),
            };
            if text {
                println!("  {:<34} {} {:<8} {detail}", n.name, &key[..12], state.label());
            }
            rows.push(vec![Cell::text(&n.name), Cell::text(key), Cell::text(state.label()), Cell::text(detail)]);
        }
    }
    if !text {
        args.table.print(&Table { columns: ["node", "key", "state", "detail"].map(String::from).to_vec(), rows });
        return Ok(());
    }
    let summary: Vec<String> = counts.iter().map(|(k, v)| format!("{v} {k}")).collect();
    println!("{} nodes in {}: {}", g.nodes.len(), store.location(), summary.join(", "));
    Ok(())
}

fn submit(
    args: &RunArgs,
    p: &Pipeline,
    store: &Store,
    g: &crate::pipeline::Graph,
    test_set: Option<&crate::store::TestSetMark>,
) -> anyhow::Result<()> {
    if !args.force.is_empty() {
        bail!("--force is not supported with --executor slurm; recompute locally, or remove the artifact with `idrex gc`");
    }
    let binary = std::env::current_exe().context("cannot find the idrex binary to submit")?;
    let opts = slurm::SlurmOptions {
        partition: args.partition.clone(),
        sbatch_args: args.sbatch_args.clone(),
        log_dir: args.log_dir.clone(),
        binary,
    };
    store.index()?;
    let out = slurm::submit(g, store, &p.spec.slurm, &opts, test_set)?;
    let mut jobs = Vec::new();
    for (node, key, s) in &out {
        match s {
            Submission::Submitted { job } => {
                println!("submitted {node:<34} {} job {job}", &key[..12]);
                jobs.push(job.as_str());
            }
            Submission::Queued { job } => println!("queued    {node:<34} {} job {job} (already)", &key[..12]),
            Submission::Stored => {}
        }
    }
    let stored = out.iter().filter(|(_, _, s)| *s == Submission::Stored).count();
    println!(
        "{}: {} stages, {} submitted, {} already queued, {stored} stored in {}",
        p.name,
        out.len(),
        jobs.len(),
        out.len() - jobs.len() - stored,
        store.location()
    );
    println!(
        "next: `idrex pipeline status {}{}`",
        args.file.display(),
        args.store.as_ref().map_or(String::new(), |s| format!(" --store {s}"))
    );
    Ok(())
}

fn plan(args: &PlanArgs) -> anyhow::Result<()> {
    let (sweep, store) = load_sweep(&args.file, args.store.as_deref(), args.device, StoreAccess::Read, &args.set.set)?;
    let p = &sweep.file;
    store.index()?;
    let g = sweep.graph()?;
    let stored = |k: &str| store.check(k).is_ok();
    let keys = g.keys();
    if args.table.machine() {
        let rows = g.nodes.iter().map(|n| {
            let inputs: Vec<String> = n.inputs.iter().map(|(role, src)| format!("{}={src}", role.name())).collect();
            vec![
                Cell::text(&n.name),
                Cell::text(n.params.kind().name()),
                Cell::text(&keys[&n.name]),
                Cell::Flag(stored(&keys[&n.name])),
                Cell::text(inputs.join(" ")),
            ]
        });
        let columns = ["node", "kind", "key", "stored", "inputs"].map(String::from).to_vec();
        args.table.print(&Table { columns, rows: rows.collect() });
        return Ok(());
    }
    print!("{}", graph::render(&g, &keys, &stored, args.format));
    if args.format == PlanFormat::Text && p.is_study() {
        println!();
        for (env, nodes) in env_groups(p, &g.nodes, |n| n.name.as_str()) {
            let done = nodes.iter().filter(|n| stored(&keys[&n.name])).count();
            println!("{}: {} nodes, {done} stored", env.unwrap_or_default(), nodes.len());
        }
    }
    if args.format == PlanFormat::Text && sweep.is_sweep() {
        println!(
            "\n{} variants x their stages, {} distinct stages (compared against `{}`):",
            sweep.variants.len(),
            g.nodes.len(),
            sweep.baseline
        );
        for (study, nodes, shared) in sweep.shares()? {
            println!("  {study}: {nodes} stages, {shared} shared with another variant");
        }
    }
    if args.format == PlanFormat::Text {
        // What is left, estimated from the store's own stage times (see pipeline::schedule).
        let manifests = store.unverified_manifests().unwrap_or_default();
        crate::pipeline::gaps::print(&g, &manifests, p.spec.eval.bc_warning);
        let est = crate::pipeline::schedule::Estimates::from_manifests(&manifests);
        let est = if est.guesses(&g) { est.on(crate::pipeline::calibrate::Speed::measure()) } else { est };
        let cost = |n: &crate::pipeline::Node| if stored(&keys[&n.name]) { 0.0 } else { est.seconds(n) };
        let (path, cp) = crate::pipeline::schedule::critical_path(&g, &cost);
        let total: f64 = g.nodes.iter().map(cost).sum();
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let path: Vec<&str> = path.iter().filter(|n| !stored(&keys[n.as_str()])).map(String::as_str).collect();
        let guessed: Vec<&str> = crate::pipeline::stage::StageKind::ALL.iter().filter(|k| !est.measured(**k)).map(|k| k.name()).collect();
        println!(
            "\nestimated: {:.1} min of stage time left, critical path {:.1} min; with {} at least {:.1} min",
            total / 60.0,
            cp / 60.0,
            crate::pipeline::runner::jobs_phrase(cores),
            cp.max(total / cores as f64) / 60.0
        );
        if !path.is_empty() {
            println!("critical path: {}", path.join(" -> "));
        }
        if !guessed.is_empty() {
            println!("(no stored artifact of {}: their times are the reference machine's, scaled to this processor)", guessed.join(", "));
        }
    }
    Ok(())
}

fn pipeline_run(args: &RunArgs) -> anyhow::Result<()> {
    let (sweep, store) = load_sweep(&args.file, args.store.as_deref(), args.device, StoreAccess::Write, &args.set.set)?;
    let sweep = match args.only_replicate {
        Some(r) => sweep.map(|p| p.only_replicate(r)).map_err(|e| anyhow::anyhow!("{}: --only-replicate {r}: {e}", args.file.display()))?,
        None => sweep,
    };
    let p = &sweep.file;
    let g = sweep.graph()?;
    let g = if args.target.is_empty() { g } else { g.up_to(&args.target).map_err(|e| anyhow::anyhow!("{}: {e}", args.file.display()))? };
    let manifests = store.unverified_manifests()?;
    let present: std::collections::BTreeSet<&str> = manifests.iter().map(|m| m.key.as_str()).collect();
    let mut archived = Vec::new();
    for a in &args.archive {
        archived.extend(crate::store::archive::read(a, stage::recorded_key)?.into_iter().filter(|m| !present.contains(m.key.as_str())));
    }
    let looks = crate::report::Artifacts::of(manifests.iter().cloned().chain(archived)).looks();
    let test_set = crate::pipeline::test_set::check(p, &g, &looks, &|k| present.contains(k), args.reuse_test_set)?;
    if args.executor == Executor::Slurm {
        return submit(args, p, &store, &g, test_set.as_ref());
    }
    // Before any stage runs: a pipeline planned for CUDA on a machine without it.
    p.device.ensure_available().map_err(|e| anyhow::anyhow!("{}: {e}", args.file.display()))?;
    // In use until the recordings are written (they read the stored artifacts): gc waits.
    let _using = store.in_use()?;
    tracing::info!("BC, T-REX and the learned reward compute on {}", p.device.name());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let opts = runner::RunOptions { jobs: args.jobs.unwrap_or(cores), force: args.force.clone(), progress: true, test_set };
    println!("{}", runner::intent(&sweep, &manifests, &g, &opts));
    crate::pipeline::gaps::print(&g, &manifests, p.spec.eval.bc_warning);
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
        store.location(),
        count(&|s| matches!(s, Status::Failed { .. })),
        count(&|s| matches!(s, Status::Skipped { .. })),
        started.elapsed().as_secs_f64()
    );
    if store.retried() > 0 {
        println!("{}: {} requests retried (each is in the log above)", store.location(), store.retried());
    }
    // One line per failed stage first: the recordings read the store, which may be what failed.
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
    // BC far below its demonstrations, once it is known; after a failure, the failed lines
    // above are what matters (and the store may be what failed).
    if failed.is_empty()
        && outcomes.iter().any(|o| matches!(o.status, Status::Computed { .. }))
        && let Ok(m) = store.unverified_manifests()
    {
        crate::pipeline::gaps::print(&g, &m, p.spec.eval.bc_warning);
    }
    let recordings = plots::record_sweep(&sweep, args.recording.as_deref(), &outcomes, &store)?;
    if !failed.is_empty() {
        bail!("{} of {} stages did not complete", failed.len(), outcomes.len());
    }
    println!(
        "next: `idrex report --store {}` (tables and figures in report/), `rerun {}` (the plots)",
        store.location(),
        recordings.join(" ")
    );
    Ok(())
}
