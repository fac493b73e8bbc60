//! `idrex verify` and `idrex gc`: the store's integrity and its garbage.
use std::path::PathBuf;

use anyhow::bail;
use clap::Args;

use crate::store::Store;

#[derive(Debug, Args)]
pub struct StoreArgs {
    /// Artifact store directory.
    #[arg(long, default_value = "artifacts")]
    pub store: PathBuf,
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

pub fn verify(args: &StoreArgs) -> anyhow::Result<()> {
    let store = Store::open(&args.store)?;
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

pub fn gc(args: &GcArgs) -> anyhow::Result<()> {
    if args.files.is_empty() {
        bail!("name the pipeline files whose artifacts to keep, e.g. `idrex gc pipelines/*.yaml`");
    }
    let store = Store::open(&args.store)?;
    let mut keep = std::collections::BTreeSet::new();
    for f in &args.files {
        let (p, _) = super::pipeline::load(f, Some(&args.store))?;
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
