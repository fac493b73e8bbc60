//! Submitted node definitions and the claims that make a Slurm job run a node once.
use std::collections::BTreeMap;

use super::*;
use crate::error::{Error, Result};

/// A node as submitted: what `idrex stage run KEY` executes on another machine. Its key is
/// recomputed from these fields before it runs, so a definition from another idrex version
/// (or a damaged one) is refused rather than run under the wrong key.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NodeDef {
    pub key: String,
    pub node: String,
    pub kind: String,
    pub version: u32,
    pub params: serde_json::Value,
    pub seed: u64,
    pub inputs: BTreeMap<String, String>,
    /// The locked test set's mark the job writes into its manifest (evaluations of a `role:
    /// test` file, or run with `--reuse-test-set`); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_set: Option<super::TestSetMark>,
}

impl Store {
    /// Records a node's definition next to the artifacts, for `idrex stage run KEY`.
    pub fn put_def(&self, def: &NodeDef) -> Result<()> {
        let text = serde_json::to_string_pretty(def).expect("a definition serialises") + "\n";
        self.backend.put_def(&self.local, &def.key, text)
    }

    /// Claims attempt `n` at computing `key` for `who` (a Slurm job id): create-if-absent,
    /// so of two submitters racing for one attempt exactly one wins.
    pub fn claim(&self, key: &str, n: u32, who: &str) -> Result<s3::Created> {
        self.backend.claim(&self.local, key, n, who)
    }

    /// The latest claim on `key`: (attempt, who).
    pub fn last_claim(&self, key: &str) -> Result<Option<(u32, String)>> {
        let names = self.backend.claims(&self.local, key)?;
        let Some(n) = names.iter().filter_map(|n| n.parse::<u32>().ok()).max() else { return Ok(None) };
        let who = self.backend.claim_holder(&self.local, key, n)?;
        Ok(Some((n, String::from_utf8_lossy(&who).into_owned())))
    }

    pub fn get_def(&self, key: &str) -> Result<Option<NodeDef>> {
        self.backend
            .get_def(&self.local, key)?
            .map(|b| serde_json::from_slice(&b).map_err(|e| Error::Invalid(format!("{}: definition of {key}: {e}", self.location()))))
            .transpose()
    }
}
