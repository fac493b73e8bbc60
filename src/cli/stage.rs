//! `idrex stage run KEY`: one node, as a Slurm job (or anything else) runs it.
use anyhow::bail;
use clap::{Args, Subcommand};

use crate::pipeline::graph::Node;
use crate::pipeline::runner::{self, Status};
use crate::pipeline::stage::{self, Inputs, Params, StageKind};
use crate::store::{Location, Store, key};

#[derive(Debug, Subcommand)]
pub enum StageCommand {
    /// Compute one node from the definition its submission stored, and publish it.
    Run(StageRunArgs),
}

#[derive(Debug, Args)]
pub struct StageRunArgs {
    pub key: String,
    /// Store directory or `s3://bucket/prefix`.
    #[arg(long)]
    pub store: String,
    /// Threads for work whose result does not depend on them (default: Slurm's
    /// SLURM_CPUS_PER_TASK, else the cores available).
    #[arg(long)]
    pub threads: Option<usize>,
}

pub fn run(cmd: &StageCommand) -> anyhow::Result<()> {
    let StageCommand::Run(args) = cmd;
    let store = Store::connect(&Location::parse(&args.store)?, true)?;
    let Some(def) = store.get_def(&args.key)? else {
        bail!(
            "{} holds no definition of {}; submit its pipeline with `idrex pipeline run FILE --executor slurm`",
            store.location(),
            args.key
        )
    };
    let Some(kind) = StageKind::parse(&def.kind) else {
        bail!("node {} has stage kind '{}', which this idrex does not know", def.node, def.kind)
    };
    let params = Params::from_json(kind, &def.params)?;
    // The definition must name the computation its key says: same kind version, parameters,
    // seed and inputs (a definition written by another idrex version is refused).
    let recomputed = key(kind.name(), kind.version(), &params.key_json(), def.seed, &def.inputs);
    if recomputed != args.key || def.version != kind.version() {
        bail!("the definition of {} does not match its key under this idrex version; resubmit the pipeline with this binary", args.key);
    }
    let threads = args
        .threads
        .or_else(|| std::env::var("SLURM_CPUS_PER_TASK").ok().and_then(|c| c.parse().ok()))
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let inputs = Inputs::from_recorded(kind, &def.node, def.inputs.iter().map(|(role, key)| (role, key.clone())))?;
    let node = Node { name: def.node.clone(), params, seed: def.seed, inputs };
    let body = |n: &Node, ctx: &stage::StageCtx| stage::run(&n.params, ctx).map(|m| m.to_json());
    let progress = std::io::IsTerminal::is_terminal(&std::io::stderr());
    match runner::run_one(&node, &args.key, node.inputs.clone(), &store, (threads, def.test_set.as_ref()), progress, &body) {
        Status::Cached => println!("{} ({}): already stored in {}", def.node, &args.key[..12], store.location()),
        Status::Computed { wall_s } => {
            println!("{} ({}): computed in {wall_s:.1} s, published to {}", def.node, &args.key[..12], store.location())
        }
        Status::Failed { error, log } => bail!("{} ({}) failed: {error}; log: {}", def.node, &args.key[..12], log.display()),
        Status::Skipped { because } => bail!("{} skipped because of {because}", def.node),
    }
    if store.retried() > 0 {
        println!("{}: {} requests retried", store.location(), store.retried());
    }
    Ok(())
}
