//! `idrex verify` and `idrex gc`: the store's integrity and its garbage.
use std::path::PathBuf;

use anyhow::bail;
use clap::Args;

use crate::log::table::{Cell, Table};
use crate::nn::DeviceChoice;
use crate::store::{Location, Store};

const GIVE_STORE: &str = "give its directory or s3://bucket/prefix with --store";

/// The store a command names; a local one must exist (else the error ends with `hint`).
pub fn existing(text: &str, write: bool, hint: &str) -> anyhow::Result<Store> {
    let location = Location::parse(text)?;
    if let Location::Local(dir) = &location
        && !dir.is_dir()
    {
        bail!("no store at {}; {hint}", dir.display());
    }
    Ok(Store::connect(&location, write)?)
}

#[derive(Debug, Args)]
pub struct StoreArgs {
    /// Artifact store directory or `s3://bucket/prefix`.
    #[arg(long, default_value = "artifacts")]
    pub store: String,
    /// Also recompute N artifacts (all without N) in scratch directories and report any
    /// whose bytes differ from the stored ones.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "all")]
    pub recompute: Option<String>,
    /// Every artifact as a table row (key, node, state, problem); with --recompute, every
    /// recomputed one (key, node, same, differing files).
    #[command(flatten)]
    pub table: super::TableArgs,
}

#[derive(Debug, Args)]
pub struct GcArgs {
    /// Pipeline files whose artifacts are kept.
    pub files: Vec<PathBuf>,
    /// Artifact store directory or `s3://bucket/prefix`.
    #[arg(long, default_value = "artifacts")]
    pub store: String,
    /// Really delete (default: only list what would go).
    #[arg(long)]
    pub yes: bool,
    /// What goes, as a table (key, node, kind, compute seconds, action).
    #[command(flatten)]
    pub table: super::TableArgs,
}

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The pipeline file whose stored artifacts are exported.
    pub file: PathBuf,
    /// Artifact store directory or `s3://bucket/prefix` (default: the file's `store`).
    #[arg(long)]
    pub store: Option<String>,
    /// Only replicate R's stages (a replicated study).
    #[arg(long, value_name = "R")]
    pub only_replicate: Option<usize>,
    /// The archive to write: NDJSON, one manifest per line (`idrex report --archive` reads it);
    /// compressed with zstd where the name ends in `.zst` (`FILE.ndjson.zst`).
    #[arg(long, value_name = "FILE.ndjson")]
    pub out: PathBuf,
    /// Leave out the stages this archive already holds (repeatable): a later phase of a study
    /// commits only its own manifests, and `idrex report --archive` reads the phases together.
    #[arg(long, value_name = "ARCHIVE")]
    pub except: Vec<PathBuf>,
    #[command(flatten)]
    pub set: super::SetArgs,
}

/// Writes the manifests of the file's stored stages to an archive; names those not stored.
pub fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let (sweep, store) =
        super::pipeline::load_sweep(&args.file, args.store.as_deref(), None, super::pipeline::StoreAccess::Read, &args.set.set)?;
    let sweep = match args.only_replicate {
        Some(r) => sweep.map(|p| p.only_replicate(r)).map_err(|e| anyhow::anyhow!("{}: --only-replicate {r}: {e}", args.file.display()))?,
        None => sweep,
    };
    store.index()?;
    let keys = sweep.graph()?.keys();
    let mut archived = std::collections::BTreeSet::new();
    for a in &args.except {
        archived.extend(crate::store::archive::keys(a)?);
    }
    let (left_out, wanted): (Vec<_>, Vec<_>) = keys.iter().partition(|(_, key)| archived.contains(*key));
    let left_out = left_out.len();
    let mut texts = std::collections::BTreeMap::new();
    let mut missing = Vec::new();
    for (node, key) in wanted {
        // Checked once, and (unlike `lookup`) without moving a corrupt artifact aside: this
        // command only reads.
        match store.manifest_text(key) {
            Ok(text) => {
                texts.insert(key.clone(), text);
            }
            Err(_) => missing.push(node.as_str()),
        }
    }
    if texts.is_empty() && left_out > 0 {
        bail!(
            "{}: every stored stage is already in the --except archives ({left_out} of {}); nothing to export",
            args.file.display(),
            keys.len()
        );
    }
    if texts.is_empty() {
        bail!("{}: none of its {} stages is in {}; run it first or give --store", args.file.display(), keys.len(), store.location());
    }
    crate::store::archive::write(&args.out, &texts)?;
    let bytes = std::fs::metadata(&args.out).map_or(0, |m| m.len());
    let except = if args.except.is_empty() { String::new() } else { format!("; {left_out} already in the --except archives") };
    println!("{}: {} of {} stages' manifests ({bytes} bytes){except}", args.out.display(), texts.len(), keys.len());
    if let Some(first) = missing.first() {
        println!("not stored intact, so not exported: {} stages (first: {first})", missing.len());
    }
    Ok(())
}

pub fn verify(args: &StoreArgs) -> anyhow::Result<()> {
    // Recomputing stages into the store's .tmp; only checking writes nothing.
    let store = existing(&args.store, args.recompute.is_some(), GIVE_STORE)?;
    let keys = store.keys()?;
    let bad = store.verify()?;
    let text = !args.table.machine();
    if text {
        for (k, problem) in &bad {
            println!("corrupt {k}: {problem}");
        }
        println!("{} artifacts, {} corrupt", keys.len(), bad.len());
    } else if args.recompute.is_none() {
        let problems: std::collections::BTreeMap<&String, &String> = bad.iter().map(|(k, p)| (k, p)).collect();
        let rows = keys.iter().map(|k| {
            let problem = problems.get(k).map_or(String::new(), |p| p.to_string());
            vec![Cell::text(k), Cell::text(if problem.is_empty() { "intact" } else { "corrupt" }), Cell::text(problem)]
        });
        args.table.print(&Table { columns: ["key", "state", "problem"].map(String::from).to_vec(), rows: rows.collect() });
    }
    if !bad.is_empty() {
        bail!("{} corrupt artifacts in {}; `idrex pipeline run` recomputes them", bad.len(), store.location());
    }
    if let Some(n) = &args.recompute {
        let n = match n.as_str() {
            "all" => keys.len(),
            n => n.parse::<usize>().map_err(|_| anyhow::anyhow!("--recompute {n}: give a number of artifacts, or nothing for all"))?,
        };
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let mut differ = 0;
        let mut rows = Vec::new();
        for k in crate::log::progress::counted(keys.iter().take(n).collect(), "artifacts recomputed") {
            let r = crate::pipeline::recompute::recompute(&store, k, threads)?;
            if !r.differing.is_empty() {
                differ += 1;
            }
            if text && r.differing.is_empty() {
                println!("same    {} {}", &k[..12], r.node);
            } else if text {
                println!("DIFFERS {} {}: {}", &k[..12], r.node, r.differing.join(", "));
            }
            rows.push(vec![Cell::text(k), Cell::text(&r.node), Cell::Flag(r.differing.is_empty()), Cell::text(r.differing.join(" "))]);
        }
        if text {
            println!("{} recomputed, {differ} differ", n.min(keys.len()));
        } else {
            args.table.print(&Table { columns: ["key", "node", "same", "differing"].map(String::from).to_vec(), rows });
        }
        if differ > 0 {
            // Bytes are the same on every processor and kernel variant, so nothing but a
            // defect (or other code under the same key) explains a difference.
            bail!("{differ} artifacts changed when recomputed: their bytes do not depend on their key alone");
        }
    }
    Ok(())
}

pub fn gc(args: &GcArgs) -> anyhow::Result<()> {
    if args.files.is_empty() {
        bail!("name the pipeline files whose artifacts to keep, e.g. `idrex gc pipelines/*.yaml`");
    }
    let store = existing(&args.store, true, GIVE_STORE)?;
    let mut keep = std::collections::BTreeSet::new();
    for f in &args.files {
        // Both devices' artifacts: which one computed them is not this machine's to decide;
        // every variant of a sweep the file declares.
        for device in [DeviceChoice::Cpu, DeviceChoice::Cuda] {
            let (sweep, _) = super::pipeline::load_sweep(f, Some(&args.store), Some(device), super::pipeline::StoreAccess::Read, &[])?;
            keep.extend(sweep.graph()?.keys().into_values());
        }
    }
    // What each doomed artifact is, read before it goes.
    let described: std::collections::BTreeMap<String, crate::store::Manifest> =
        store.manifests()?.into_iter().map(|m| (m.key.clone(), m)).collect();
    let stored = store.keys()?;
    let removed = store.gc(&keep, !args.yes)?;
    let action = if args.yes { "removed" } else { "would remove" };
    if args.table.machine() {
        let rows = removed.iter().map(|k| {
            let m = described.get(k);
            vec![
                Cell::text(k),
                Cell::text(m.map_or("", |m| m.node.as_str())),
                Cell::text(m.map_or("unreadable or partial", |m| m.kind.as_str())),
                Cell::opt(m.map(|m| m.wall_s), 0),
                Cell::text(action),
            ]
        });
        args.table
            .print(&Table { columns: ["key", "node", "kind", "compute_s", "action"].map(String::from).to_vec(), rows: rows.collect() });
        return Ok(());
    }
    for k in &removed {
        let what = described
            .get(k)
            .map_or("unreadable or partial artifact".to_string(), |m| format!("{} ({}, {:.0} s to compute)", m.node, m.kind, m.wall_s));
        println!("{action} {} {what}", &k[..k.len().min(12)]);
    }
    println!(
        "{} artifacts {}; {} kept (of {} the pipeline files name)",
        removed.len(),
        if args.yes { "removed" } else { "unreferenced (dry run; --yes deletes them)" },
        stored.iter().filter(|k| keep.contains(*k)).count(),
        keep.len()
    );
    Ok(())
}
