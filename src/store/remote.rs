//! An S3 store ([`Remote`]) as a [`Backend`]: lookups, listings, verification and gc go to
//! the bucket; a stage's inputs are downloaded into the local cache (each file checked against
//! its digest) and its outputs, published in the cache first, are pushed, manifest last.
use std::collections::BTreeSet;
use std::path::PathBuf;

use super::backend::Backend;
use super::s3::{Created, Remote};
use super::{LocalDir, Manifest, now_unix};
use crate::error::{Error, Result};

impl Backend for Remote {
    fn location(&self, _: &LocalDir) -> String {
        self.url.clone()
    }

    fn url(&self) -> Option<&str> {
        Some(&self.url)
    }

    fn index(&self) -> Result<()> {
        self.index_blobs()
    }

    fn retried(&self) -> u64 {
        self.retries.count()
    }

    fn lookup(&self, _: &LocalDir, key: &str) -> Result<Option<Manifest>> {
        Ok(match Remote::check(self, key)? {
            Some(Ok(m)) => Some(m),
            Some(Err(problem)) => {
                tracing::warn!("artifact {key} in {} is incomplete ({problem}); recomputing it", self.url);
                None
            }
            None => None,
        })
    }

    /// Its manifest, and that every blob exists with its size; the digests are checked when
    /// a blob is downloaded, and by `verify`.
    fn check(&self, _: &LocalDir, key: &str) -> std::result::Result<Manifest, String> {
        Remote::check(self, key).map_err(|e| e.to_string())?.unwrap_or_else(|| Err("not stored".into()))
    }

    fn published(&self, local: &LocalDir, key: &str, replace: bool) -> Result<()> {
        // Publish what the cache holds under the key (a copy left by an earlier push that
        // failed has the same bytes: outputs depend on the key alone).
        let dir = local.dir(key);
        let ours = local.check(key).map_err(|p| Error::Invalid(format!("cached artifact {key}: {p}")))?;
        if self.push(&dir, &ours, replace)? == Created::AlreadyThere {
            match Remote::check(self, key)? {
                Some(Ok(theirs)) if theirs.outputs == ours.outputs => {
                    tracing::info!("{key} was published to {} by another run first; keeping theirs", self.url)
                }
                Some(Ok(_)) => {
                    // Same key, other bytes: a stage whose outputs are not a function of its
                    // key. The store's copy stands; ours must not feed this machine.
                    tracing::warn!(
                        "{key} was published to {} by another run with different bytes (outputs that do not depend on the key alone); keeping theirs",
                        self.url
                    );
                    local.quarantine(key)?;
                }
                // A manifest whose blobs are gone: ours replaces it.
                _ => {
                    self.push(&dir, &ours, true)?;
                }
            }
        }
        Ok(())
    }

    /// The artifact is downloaded into the cache first unless the cache holds it intact.
    fn input_dir(&self, local: &LocalDir, key: &str) -> Result<PathBuf> {
        let dir = local.dir(key);
        if local.check(key).is_ok() {
            return Ok(dir);
        }
        let _lock = local.lock(key)?;
        if local.check(key).is_ok() {
            return Ok(dir);
        }
        if dir.exists() {
            local.quarantine(key)?;
        }
        let m = match Remote::check(self, key)? {
            Some(Ok(m)) => m,
            Some(Err(problem)) => return Err(Error::Invalid(format!("artifact {key} in {} is incomplete: {problem}", self.url))),
            None => return Err(Error::Invalid(format!("artifact {key} is not in {}", self.url))),
        };
        // The staging directory starts empty and `download` writes exactly the manifest's
        // files, each checked against its digest, before anything is published.
        let staging = local.stage(key)?;
        self.download(&m, &staging.dir)?;
        local.publish(staging, m, false)?;
        Ok(dir)
    }

    fn keys(&self, _: &LocalDir) -> Result<Vec<String>> {
        Remote::keys(self)
    }

    fn unverified_manifests(&self, _: &LocalDir) -> Result<Vec<Manifest>> {
        Ok(Remote::keys(self)?.iter().filter_map(|k| self.manifest(k).ok().flatten()).collect())
    }

    fn manifests(&self, _: &LocalDir) -> Result<Vec<Manifest>> {
        // A store that cannot be asked is an error, not an empty table.
        self.index_blobs()?;
        let mut out = Vec::new();
        for k in crate::log::progress::counted(Remote::keys(self)?, "manifests read") {
            if let Some(Ok(m)) = Remote::check(self, &k)? {
                out.push(m);
            }
        }
        Ok(out)
    }

    /// Every blob downloaded and hashed: what a reader would get.
    fn verify(&self, _: &LocalDir) -> Result<Vec<(String, String)>> {
        let mut bad = Vec::new();
        for k in crate::log::progress::counted(Remote::keys(self)?, "artifacts downloaded and re-hashed") {
            match Remote::check(self, &k)? {
                Some(Ok(m)) => {
                    for o in &m.outputs {
                        if let Some(problem) = self.blob_problem(&o.sha256, o.size)? {
                            bad.push((k.clone(), format!("{}: {problem}", o.path)));
                            break;
                        }
                    }
                }
                Some(Err(problem)) => bad.push((k, problem)),
                None => {}
            }
        }
        Ok(bad)
    }

    /// Manifests first, then the blobs no remaining manifest names. A blob younger than an
    /// hour stays: it may belong to an upload whose manifest is not committed yet (there is
    /// no lock across machines, so gc cannot see a run elsewhere).
    fn gc(&self, local: &LocalDir, keep: &BTreeSet<String>, dry_run: bool) -> Result<Vec<String>> {
        let keys = Remote::keys(self)?;
        let removed: Vec<String> = keys.iter().filter(|k| !keep.contains(*k)).cloned().collect();
        if dry_run {
            return Ok(removed);
        }
        // Runs on this machine, at least, are seen (through the cache's use lock).
        let _alone = local.exclusive()?;
        for k in &removed {
            self.delete_artifact(k)?;
        }
        // Definitions and claims of nodes never computed (failed jobs), unless still named.
        for k in self.submitted()? {
            if !keep.contains(&k) && !keys.contains(&k) {
                self.delete_submission(&k)?;
            }
        }
        let mut referenced = BTreeSet::new();
        for k in keys.iter().filter(|k| keep.contains(*k)) {
            if let Some(m) = self.manifest(k)? {
                referenced.extend(m.outputs.into_iter().map(|o| o.sha256));
            }
        }
        let young = now_unix() as i64 - 3600;
        for (sha, _, modified) in self.list("blobs")? {
            if !referenced.contains(&sha) && modified < young {
                self.delete(&Remote::blob_path(&sha))?;
            }
        }
        Ok(removed)
    }

    fn put_def(&self, _: &LocalDir, key: &str, text: String) -> Result<()> {
        self.create(&format!("defs/{key}.json"), text.into_bytes())?;
        Ok(())
    }

    fn get_def(&self, _: &LocalDir, key: &str) -> Result<Option<Vec<u8>>> {
        self.get(&format!("defs/{key}.json"))
    }

    fn claim(&self, _: &LocalDir, key: &str, n: u32, who: &str) -> Result<Created> {
        self.create(&format!("claims/{key}/{n}"), who.as_bytes().to_vec())
    }

    fn claims(&self, _: &LocalDir, key: &str) -> Result<Vec<String>> {
        Ok(self.list(&format!("claims/{key}"))?.into_iter().map(|(n, _, _)| n).collect())
    }

    fn claim_holder(&self, _: &LocalDir, key: &str, n: u32) -> Result<Vec<u8>> {
        Ok(self.get(&format!("claims/{key}/{n}"))?.unwrap_or_default())
    }
}
