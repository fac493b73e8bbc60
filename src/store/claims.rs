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
}

impl Store {
    /// Records a node's definition next to the artifacts, for `idrex stage run KEY`.
    pub fn put_def(&self, def: &NodeDef) -> Result<()> {
        let text = serde_json::to_string_pretty(def).expect("a definition serialises") + "\n";
        match &self.remote {
            Some(r) => {
                r.create(&format!("defs/{}.json", def.key), text.into_bytes())?;
                Ok(())
            }
            None => {
                let dir = self.root.join(".defs");
                std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
                let path = dir.join(format!("{}.json", def.key));
                let tmp = dir.join(format!(".{}.{}", def.key, std::process::id()));
                std::fs::write(&tmp, text).and_then(|_| std::fs::rename(&tmp, &path)).map_err(|e| Error::io(&path, e))
            }
        }
    }

    /// Claims attempt `n` at computing `key` for `who` (a Slurm job id): create-if-absent,
    /// so of two submitters racing for one attempt exactly one wins.
    pub fn claim(&self, key: &str, n: u32, who: &str) -> Result<s3::Created> {
        match &self.remote {
            Some(r) => r.create(&format!("claims/{key}/{n}"), who.as_bytes().to_vec()),
            None => {
                let dir = self.root.join(".claims").join(key);
                std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
                let path = dir.join(n.to_string());
                // Written whole to the side, then linked into place: link fails if the name
                // exists, and a reader never sees a claim half-written.
                let tmp = dir.join(format!(".{n}.{}.{}", std::process::id(), STAGING_COUNTER.fetch_add(1, Ordering::Relaxed)));
                std::fs::write(&tmp, who).map_err(|e| Error::io(&tmp, e))?;
                let linked = std::fs::hard_link(&tmp, &path);
                let _ = std::fs::remove_file(&tmp);
                match linked {
                    Ok(()) => Ok(s3::Created::Yes),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(s3::Created::AlreadyThere),
                    Err(e) => Err(Error::io(&path, e)),
                }
            }
        }
    }

    /// The latest claim on `key`: (attempt, who).
    pub fn last_claim(&self, key: &str) -> Result<Option<(u32, String)>> {
        let names: Vec<String> = match &self.remote {
            Some(r) => r.list(&format!("claims/{key}"))?.into_iter().map(|(n, _, _)| n).collect(),
            None => std::fs::read_dir(self.root.join(".claims").join(key))
                .map(|d| d.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect())
                .unwrap_or_default(),
        };
        let Some(n) = names.iter().filter_map(|n| n.parse::<u32>().ok()).max() else { return Ok(None) };
        let who = match &self.remote {
            Some(r) => r.get(&format!("claims/{key}/{n}"))?.unwrap_or_default(),
            None => std::fs::read(self.root.join(".claims").join(key).join(n.to_string())).unwrap_or_default(),
        };
        Ok(Some((n, String::from_utf8_lossy(&who).into_owned())))
    }

    pub fn get_def(&self, key: &str) -> Result<Option<NodeDef>> {
        let bytes = match &self.remote {
            Some(r) => r.get(&format!("defs/{key}.json"))?,
            None => std::fs::read(self.root.join(".defs").join(format!("{key}.json"))).ok(),
        };
        bytes
            .map(|b| serde_json::from_slice(&b).map_err(|e| Error::Invalid(format!("{}: definition of {key}: {e}", self.location()))))
            .transpose()
    }
}
