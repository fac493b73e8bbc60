//! Where a store's published artifacts, node definitions and claims live: the store's own
//! directory ([`Local`]) or an S3 bucket ([`super::s3::Remote`], implemented in
//! [`super::remote`]). Either way stages run in a local directory laid out like a local store
//! (the store itself, or an S3 store's cache, a [`LocalDir`]): its staging, publishing, locks and
//! checks of that directory are shared, and the backend decides the rest.
use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::atomic::Ordering;

use super::s3::Created;
use super::{LocalDir, Manifest};
use crate::error::{Error, Result};
use crate::log::progress::counted;

pub(crate) trait Backend: std::fmt::Debug + Send + Sync {
    /// The store's directory or URL, for messages.
    fn location(&self, local: &LocalDir) -> String;
    /// The URL a job on another machine opens (None: the store is a local directory).
    fn url(&self) -> Option<&str>;
    /// Before checking many artifacts: one listing instead of a request each.
    fn index(&self) -> Result<()>;
    /// Requests retried so far (each is logged as it happens).
    fn retried(&self) -> u64 {
        0
    }
    /// The manifest of `key` if it is published and intact.
    fn lookup(&self, local: &LocalDir, key: &str) -> Result<Option<Manifest>>;
    /// Checks an artifact against its manifest; the error says what is wrong.
    fn check(&self, local: &LocalDir, key: &str) -> std::result::Result<Manifest, String>;
    /// After `key` was published in the local directory: make it the store's (`replace`: a
    /// stored artifact is replaced).
    fn published(&self, local: &LocalDir, key: &str, replace: bool) -> Result<()>;
    /// The local directory holding `key`'s outputs, fetched there first where needed.
    fn input_dir(&self, local: &LocalDir, key: &str) -> Result<PathBuf>;
    /// Every published artifact's key.
    fn keys(&self, local: &LocalDir) -> Result<Vec<String>>;
    /// Every manifest as written, unchecked (for statistics, never for trust).
    fn unverified_manifests(&self, local: &LocalDir) -> Result<Vec<Manifest>>;
    /// Every intact artifact's manifest.
    fn manifests(&self, local: &LocalDir) -> Result<Vec<Manifest>>;
    /// (key, problem) for every corrupt artifact, every byte re-hashed.
    fn verify(&self, local: &LocalDir) -> Result<Vec<(String, String)>>;
    /// Removes every artifact not in `keep`; what was (or would be) removed.
    fn gc(&self, local: &LocalDir, keep: &BTreeSet<String>, dry_run: bool) -> Result<Vec<String>>;
    /// Records a node's definition (JSON text) for `idrex stage run KEY`.
    fn put_def(&self, local: &LocalDir, key: &str, text: String) -> Result<()>;
    /// A node's recorded definition.
    fn get_def(&self, local: &LocalDir, key: &str) -> Result<Option<Vec<u8>>>;
    /// Creates claim `n` on `key` for `who` unless it exists.
    fn claim(&self, local: &LocalDir, key: &str, n: u32, who: &str) -> Result<Created>;
    /// The names of `key`'s claims (attempt numbers, as written).
    fn claims(&self, local: &LocalDir, key: &str) -> Result<Vec<String>>;
    /// Who holds claim `n` on `key`.
    fn claim_holder(&self, local: &LocalDir, key: &str, n: u32) -> Result<Vec<u8>>;
}

/// A store that is a local directory: published artifacts are its `<key>` directories.
#[derive(Debug)]
pub(crate) struct Local;

impl Backend for Local {
    fn location(&self, local: &LocalDir) -> String {
        local.root.display().to_string()
    }

    fn url(&self) -> Option<&str> {
        None
    }

    fn index(&self) -> Result<()> {
        Ok(())
    }

    /// A corrupt artifact is moved to `.corrupt/` (so that it is recomputed) and reported as
    /// absent.
    fn lookup(&self, local: &LocalDir, key: &str) -> Result<Option<Manifest>> {
        if !local.dir(key).exists() {
            return Ok(None);
        }
        match local.check(key) {
            Ok(m) => Ok(Some(m)),
            Err(problem) => {
                tracing::warn!("artifact {key} is corrupt ({problem}); recomputing it");
                local.quarantine(key)?;
                Ok(None)
            }
        }
    }

    fn check(&self, local: &LocalDir, key: &str) -> std::result::Result<Manifest, String> {
        local.check(key)
    }

    fn published(&self, _: &LocalDir, _: &str, _: bool) -> Result<()> {
        Ok(())
    }

    fn input_dir(&self, local: &LocalDir, key: &str) -> Result<PathBuf> {
        Ok(local.dir(key))
    }

    fn keys(&self, local: &LocalDir) -> Result<Vec<String>> {
        let root = &local.root;
        let mut keys = Vec::new();
        for e in std::fs::read_dir(root).map_err(|e| Error::io(root, e))? {
            let e = e.map_err(|e| Error::io(root, e))?;
            let name = e.file_name().to_string_lossy().into_owned();
            if !name.starts_with('.') {
                keys.push(name);
            }
        }
        keys.sort();
        Ok(keys)
    }

    fn unverified_manifests(&self, local: &LocalDir) -> Result<Vec<Manifest>> {
        Ok(self
            .keys(local)?
            .iter()
            .filter_map(|k| std::fs::read_to_string(local.dir(k).join(super::MANIFEST)).ok())
            .filter_map(|text| serde_json::from_str(&text).ok())
            .collect())
    }

    /// Corrupt ones are skipped, not moved.
    fn manifests(&self, local: &LocalDir) -> Result<Vec<Manifest>> {
        Ok(counted(self.keys(local)?, "artifacts re-hashed").filter_map(|k| local.check(&k).ok()).collect())
    }

    fn verify(&self, local: &LocalDir) -> Result<Vec<(String, String)>> {
        Ok(counted(self.keys(local)?, "artifacts re-hashed").filter_map(|k| local.check(&k).err().map(|p| (k, p))).collect())
    }

    fn gc(&self, local: &LocalDir, keep: &BTreeSet<String>, dry_run: bool) -> Result<Vec<String>> {
        let _alone = if dry_run { None } else { Some(local.exclusive()?) };
        let mut removed = Vec::new();
        for k in self.keys(local)? {
            if !keep.contains(&k) {
                if !dry_run {
                    let _lock = local.lock(&k)?;
                    let path = local.dir(&k);
                    let gone = if path.is_dir() { std::fs::remove_dir_all(&path) } else { std::fs::remove_file(&path) };
                    gone.map_err(|e| Error::io(&path, e))?;
                }
                removed.push(k);
            }
        }
        Ok(removed)
    }

    fn put_def(&self, local: &LocalDir, key: &str, text: String) -> Result<()> {
        let dir = local.root.join(".defs");
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let path = dir.join(format!("{key}.json"));
        let tmp = dir.join(format!(".{key}.{}", std::process::id()));
        std::fs::write(&tmp, text).and_then(|_| std::fs::rename(&tmp, &path)).map_err(|e| Error::io(&path, e))
    }

    fn get_def(&self, local: &LocalDir, key: &str) -> Result<Option<Vec<u8>>> {
        Ok(std::fs::read(local.root.join(".defs").join(format!("{key}.json"))).ok())
    }

    fn claim(&self, local: &LocalDir, key: &str, n: u32, who: &str) -> Result<Created> {
        let dir = local.root.join(".claims").join(key);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let path = dir.join(n.to_string());
        // Written whole to the side, then linked into place: link fails if the name exists,
        // and a reader never sees a claim half-written.
        let tmp = dir.join(format!(".{n}.{}.{}", std::process::id(), super::STAGING_COUNTER.fetch_add(1, Ordering::Relaxed)));
        std::fs::write(&tmp, who).map_err(|e| Error::io(&tmp, e))?;
        let linked = std::fs::hard_link(&tmp, &path);
        let _ = std::fs::remove_file(&tmp);
        match linked {
            Ok(()) => Ok(Created::Yes),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(Created::AlreadyThere),
            Err(e) => Err(Error::io(&path, e)),
        }
    }

    fn claims(&self, local: &LocalDir, key: &str) -> Result<Vec<String>> {
        Ok(std::fs::read_dir(local.root.join(".claims").join(key))
            .map(|d| d.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect())
            .unwrap_or_default())
    }

    fn claim_holder(&self, local: &LocalDir, key: &str, n: u32) -> Result<Vec<u8>> {
        Ok(std::fs::read(local.root.join(".claims").join(key).join(n.to_string())).unwrap_or_default())
    }
}
