//! Removing what no pipeline references, locally or in a bucket.

use super::*;
use crate::error::{Error, Result};

impl Store {
    /// Removes every artifact not in `keep` (and stale staging entries); returns what was
    /// (or, with `dry_run`, would be) removed.
    pub fn gc(&self, keep: &std::collections::BTreeSet<String>, dry_run: bool) -> Result<Vec<String>> {
        if let Some(r) = &self.remote {
            return self.remote_gc(r, keep, dry_run);
        }
        let _alone = if dry_run { None } else { Some(self.exclusive()?) };
        let mut removed = Vec::new();
        for k in self.keys()? {
            if !keep.contains(&k) {
                if !dry_run {
                    let _lock = self.lock(&k)?;
                    let path = self.dir(&k);
                    let gone = if path.is_dir() { std::fs::remove_dir_all(&path) } else { std::fs::remove_file(&path) };
                    gone.map_err(|e| Error::io(&path, e))?;
                }
                removed.push(k);
            }
        }
        Ok(removed)
    }
}

impl Store {
    /// Manifests first, then the blobs no remaining manifest names. A blob younger than an
    /// hour stays: it may belong to an upload whose manifest is not committed yet (there is
    /// no lock across machines, so gc cannot see a run elsewhere).
    fn remote_gc(&self, r: &s3::Remote, keep: &std::collections::BTreeSet<String>, dry_run: bool) -> Result<Vec<String>> {
        let keys = r.keys()?;
        let removed: Vec<String> = keys.iter().filter(|k| !keep.contains(*k)).cloned().collect();
        if dry_run {
            return Ok(removed);
        }
        // Runs on this machine, at least, are seen (through the cache's use lock).
        let _alone = self.exclusive()?;
        for k in &removed {
            r.delete_artifact(k)?;
        }
        // Definitions and claims of nodes never computed (failed jobs), unless still named.
        for k in r.submitted()? {
            if !keep.contains(&k) && !keys.contains(&k) {
                r.delete_submission(&k)?;
            }
        }
        let mut referenced = std::collections::BTreeSet::new();
        for k in keys.iter().filter(|k| keep.contains(*k)) {
            if let Some(m) = r.manifest(k)? {
                referenced.extend(m.outputs.into_iter().map(|o| o.sha256));
            }
        }
        let young = now_unix() as i64 - 3600;
        for (sha, _, modified) in r.list("blobs")? {
            if !referenced.contains(&sha) && modified < young {
                r.delete(&s3::Remote::blob_path(&sha))?;
            }
        }
        Ok(removed)
    }
}
