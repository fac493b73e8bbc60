//! `idrex verify --recompute`: recomputes stored artifacts in scratch directories from their
//! manifests alone (kind, parameters, seed, inputs) and compares the bytes. A stage's outputs
//! must depend only on its key; a difference means they do not (or the artifact was made by
//! other code under the same key).
use std::collections::BTreeMap;

use super::stage::{self, Params, StageCtx, StageKind};
use crate::error::{Error, Result};
use crate::store::{OutputFile, Store, hash_outputs};

/// What recomputing one artifact found.
#[derive(Debug, Clone, PartialEq)]
pub struct Recomputed {
    pub key: String,
    pub node: String,
    /// Output paths whose bytes differ, or that exist on one side only.
    pub differing: Vec<String>,
}

fn diff(stored: &[OutputFile], fresh: &[OutputFile]) -> Vec<String> {
    let a: BTreeMap<&str, (&str, u64)> = stored.iter().map(|o| (o.path.as_str(), (o.sha256.as_str(), o.size))).collect();
    let b: BTreeMap<&str, (&str, u64)> = fresh.iter().map(|o| (o.path.as_str(), (o.sha256.as_str(), o.size))).collect();
    let mut out: Vec<String> = a.keys().chain(b.keys()).filter(|p| a.get(*p) != b.get(*p)).map(|p| p.to_string()).collect();
    out.sort();
    out.dedup();
    out
}

/// Recomputes the artifact `key` of `store` in a scratch directory and compares its outputs.
pub fn recompute(store: &Store, key: &str, threads: usize) -> Result<Recomputed> {
    let m = store.check(key).map_err(|problem| Error::Invalid(format!("artifact {key} is corrupt: {problem}")))?;
    let kind = StageKind::parse(&m.kind).ok_or_else(|| Error::Invalid(format!("artifact {key}: unknown stage kind '{}'", m.kind)))?;
    let params = Params::from_json(kind, &m.params)?;
    for (role, k) in &m.inputs {
        store.check(k).map_err(|problem| Error::Invalid(format!("input {role} ({k}) of {key} is corrupt: {problem}")))?;
    }
    let inputs = stage::Inputs::from_recorded(kind, &format!("artifact {key}"), m.inputs.iter())?.try_map(|k| store.input_dir(k))?;
    let scratch = store.stage(&format!("recompute-{key}"))?;
    let bar = indicatif::ProgressBar::hidden();
    let ctx = StageCtx { seed: m.seed, inputs, out: &scratch.dir, threads, progress: &bar };
    let result = stage::run(&params, &ctx).and_then(|_| hash_outputs(&scratch.dir));
    let _ = std::fs::remove_dir_all(&scratch.dir);
    Ok(Recomputed { key: key.to_string(), node: m.node, differing: diff(&m.outputs, &result?) })
}
