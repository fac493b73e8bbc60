//! The artifact store: one directory per stage result, named by its key.
//!
//! A key is the sha256 of a canonical JSON encoding (sorted keys) of the stage kind, the
//! stage's implementation version, its resolved parameters, its seed and the keys of its
//! inputs ([`key`]). An artifact directory holds the stage's outputs and `manifest.json`
//! (every output's sha256 and size, metrics, times, idrex version).
//!
//! Publishing is atomic: a stage writes into `.tmp/<key>.<pid>.<n>` on the same filesystem,
//! every file and the directory are fsynced, then the directory is renamed to `<key>` (or,
//! when a stored artifact is recomputed on purpose, atomically exchanged with it). A crash at
//! any moment leaves at most a stray `.tmp` entry, never a partial `<key>`. A staging
//! directory is owned through an OS file lock on `<dir>.lock`, held while the stage runs and
//! released by the kernel when the process dies: cleanup removes only staging nobody holds,
//! whatever PID namespace or process the owner lives in. A per-key lock
//! (`.locks/<key>.lock`) lets two runs share a store: the second waits, then finds the
//! artifact published. A pipeline run holds the store's use lock (`.locks/store.lock`)
//! shared; `gc` takes it exclusively, so it never deletes what a running pipeline uses. An
//! artifact whose files no longer match its manifest is corrupt: it is moved to `.corrupt/`
//! and recomputed, never used.
//!
//! The same interface also fronts an S3-compatible bucket ([`s3`], `s3://bucket/prefix`):
//! lookups, listings, verification and gc go to the bucket; a stage runs in a local cache
//! directory laid out like a local store (inputs downloaded into it and checked, outputs
//! published there first) and is then pushed, manifest last. The two differ only behind
//! `backend::Backend`: the local directory and the bucket are its two implementations.
pub mod archive;
mod backend;
mod remote;
pub mod retry;
pub mod s3;

use std::fs::File;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};
use backend::{Backend, Local};

mod claims;
mod location;
mod locks;
mod manifest;

pub use claims::NodeDef;
pub use location::Location;
pub use locks::{KeyLock, UseLock};
pub use manifest::{MANIFEST, Manifest, OutputFile, TestSetMark, hash_outputs, key, key_of_text, now_unix, sha256_file};
#[derive(Debug, Clone)]
pub struct Store {
    /// The store's directory; for an S3 store, the local cache it stages and reads through.
    local: LocalDir,
    /// Where published artifacts live: this directory, or a bucket.
    backend: Arc<dyn Backend>,
}

/// The directory a store stages, publishes and locks in, laid out as a local store: the
/// store itself, or an S3 store's cache. What both backends build on; they never call back
/// into [`Store`].
#[derive(Debug, Clone)]
pub(crate) struct LocalDir {
    root: PathBuf,
}

/// A stage's output directory before publication, owned through a lock on `<dir>.lock`.
pub struct Staging {
    pub dir: PathBuf,
    key: String,
    _owner: File,
}

impl Drop for Staging {
    fn drop(&mut self) {
        // Published (renamed away) or abandoned: either way the directory and its lock go.
        let _ = std::fs::remove_dir_all(&self.dir);
        let _ = std::fs::remove_file(lock_path(&self.dir));
    }
}

fn lock_path(dir: &Path) -> PathBuf {
    let mut name = dir.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

/// Who holds a lock, written into the lock file by its holder: shown to whoever waits.
fn holder() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    format!("pid {} on {}", std::process::id(), host.trim())
}

#[allow(unsafe_code)] // renameat2, which std does not offer
unsafe extern "C" {
    fn renameat2(olddirfd: i32, oldpath: *const std::ffi::c_char, newdirfd: i32, newpath: *const std::ffi::c_char, flags: u32) -> i32;
}

/// Atomically exchanges two directories (Linux `renameat2(RENAME_EXCHANGE)`).
#[allow(unsafe_code)]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    const AT_FDCWD: i32 = -100;
    const RENAME_EXCHANGE: u32 = 2;
    let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_bytes()).map_err(std::io::Error::other);
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: two valid NUL-terminated paths; the call only renames.
    let rc = unsafe { renameat2(AT_FDCWD, a.as_ptr(), AT_FDCWD, b.as_ptr(), RENAME_EXCHANGE) };
    if rc == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

static STAGING_COUNTER: AtomicU64 = AtomicU64::new(0);

impl Store {
    /// A handle for reading only (plan, report, verify): creates nothing, so that looking at a
    /// store never leaves `.tmp` and `.locks` behind, or a store where there was none.
    pub fn at(root: impl Into<PathBuf>) -> Self {
        Store { local: LocalDir { root: root.into() }, backend: Arc::new(Local) }
    }

    /// The store at `location`; `write` creates a local store's directory if needed. An S3
    /// store connects (nothing is sent yet) and opens its local cache.
    pub fn connect(location: &Location, write: bool) -> Result<Self> {
        match location {
            Location::Local(dir) if write => Store::open(dir),
            Location::Local(dir) => Ok(Store::at(dir)),
            Location::S3 { bucket, prefix } => {
                let remote = s3::Remote::connect(bucket, prefix)?;
                // One request now, so that wrong credentials or an unreachable endpoint fail
                // here with one line instead of in the middle of a command.
                remote.size("artifacts")?;
                let cache = Store::open(Location::cache_dir(bucket, prefix))?;
                Ok(Store { local: cache.local, backend: Arc::new(remote) })
            }
        }
    }

    /// The store's directory or URL, for messages.
    pub fn location(&self) -> String {
        self.backend.location(&self.local)
    }

    /// Requests to the store retried by this process so far (an S3 store's; each is
    /// logged when it happens).
    pub fn retried(&self) -> u64 {
        self.backend.retried()
    }

    /// Before checking many artifacts of an S3 store: one listing of its blobs instead of a
    /// request per file. (A local store needs nothing.)
    pub fn index(&self) -> Result<()> {
        self.backend.index()
    }

    /// The URL a job on another machine opens; None for a local directory.
    pub fn url(&self) -> Option<&str> {
        self.backend.url()
    }

    /// Opens a store for writing, creating it if needed.
    pub fn open(root: impl Into<PathBuf>) -> Result<Self> {
        let root = root.into();
        for sub in [".tmp", ".locks"] {
            let d = root.join(sub);
            std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
        }
        Ok(Store { local: LocalDir { root }, backend: Arc::new(Local) })
    }

    pub fn root(&self) -> &Path {
        &self.local.root
    }

    pub fn dir(&self, key: &str) -> PathBuf {
        self.local.dir(key)
    }

    /// The manifest of `key` if it is published and intact. A corrupt local artifact is moved
    /// to `.corrupt/` (so that it is recomputed) and reported as absent.
    pub fn lookup(&self, key: &str) -> Result<Option<Manifest>> {
        self.backend.lookup(&self.local, key)
    }

    /// Checks an artifact against its manifest; the error says what is wrong. (In an S3
    /// store: its manifest and that every blob exists with its size; the digests are checked
    /// when a blob is downloaded, and by [`Store::verify`].)
    pub fn check(&self, key: &str) -> std::result::Result<Manifest, String> {
        self.backend.check(&self.local, key)
    }

    /// An intact artifact's `manifest.json` as written (what [`archive`] keeps), checked; from
    /// an S3 store, through its cache.
    pub fn manifest_text(&self, key: &str) -> Result<String> {
        let dir = self.input_dir(key)?;
        self.local.check(key).map_err(|p| Error::Invalid(format!("artifact {key} in {}: {p}", self.location())))?;
        let path = dir.join(MANIFEST);
        std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))
    }

    /// A fresh, empty staging directory for `key`, owned until the [`Staging`] is dropped.
    pub fn stage(&self, key: &str) -> Result<Staging> {
        self.local.stage(key)
    }

    /// Removes staging directories nobody owns any more (their process died mid-stage).
    pub fn clean_stale_staging(&self) {
        self.local.clean_stale_staging()
    }

    /// Hashes the staged outputs, writes the manifest, fsyncs and renames into place; with
    /// `replace`, a stored artifact is exchanged for the new one atomically (readers see the
    /// old or the new, never neither). The caller holds the key's lock.
    pub fn publish(&self, staging: Staging, manifest: Manifest, replace: bool) -> Result<Manifest> {
        let key = staging.key.clone();
        let m = self.local.publish(staging, manifest, replace)?;
        self.backend.published(&self.local, &key, replace)?;
        Ok(m)
    }

    /// The local directory holding `key`'s outputs, for reading them: for an S3 store, the
    /// artifact is downloaded into the cache first (each file checked against its digest)
    /// unless the cache holds it intact.
    pub fn input_dir(&self, key: &str) -> Result<PathBuf> {
        self.backend.input_dir(&self.local, key)
    }

    /// Every published artifact's key (and anything else that sits where one would).
    pub fn keys(&self) -> Result<Vec<String>> {
        self.backend.keys(&self.local)
    }

    /// Every artifact's manifest as written, without re-hashing its outputs: for statistics
    /// (stage-time estimates), never for trusting an artifact.
    pub fn unverified_manifests(&self) -> Result<Vec<Manifest>> {
        self.backend.unverified_manifests(&self.local)
    }

    /// Every intact artifact's manifest (corrupt ones are skipped, not moved).
    pub fn manifests(&self) -> Result<Vec<Manifest>> {
        self.backend.manifests(&self.local)
    }

    /// Re-hashes every artifact; returns (key, problem) for each corrupt one.
    pub fn verify(&self) -> Result<Vec<(String, String)>> {
        self.backend.verify(&self.local)
    }

    /// Removes every artifact not in `keep`; returns what was (or, with `dry_run`, would be)
    /// removed.
    pub fn gc(&self, keep: &std::collections::BTreeSet<String>, dry_run: bool) -> Result<Vec<String>> {
        self.backend.gc(&self.local, keep, dry_run)
    }
}

impl LocalDir {
    pub(super) fn dir(&self, key: &str) -> PathBuf {
        self.root.join(key)
    }

    /// Checks the local directory's copy of `key` against its manifest.
    pub(super) fn check(&self, key: &str) -> std::result::Result<Manifest, String> {
        let dir = self.dir(key);
        let text = std::fs::read_to_string(dir.join(MANIFEST)).map_err(|e| format!("{MANIFEST}: {e}"))?;
        let m: Manifest = serde_json::from_str(&text).map_err(|e| format!("{MANIFEST}: {e}"))?;
        if m.key != key {
            return Err(format!("{MANIFEST} names key {}", m.key));
        }
        for o in &m.outputs {
            let (sha, size) = sha256_file(&dir.join(&o.path)).map_err(|e| e.to_string())?;
            if size != o.size || sha != o.sha256 {
                return Err(format!("{} does not match its recorded sha256 and size", o.path));
            }
        }
        Ok(m)
    }

    pub(super) fn quarantine(&self, key: &str) -> Result<()> {
        let bad = self.root.join(".corrupt");
        std::fs::create_dir_all(&bad).map_err(|e| Error::io(&bad, e))?;
        let to = bad.join(format!("{key}.{}", now_unix() as u64));
        std::fs::rename(self.dir(key), &to).map_err(|e| Error::io(self.dir(key), e))
    }

    /// A fresh, empty staging directory for `key`, owned until the [`Staging`] is dropped.
    pub(super) fn stage(&self, key: &str) -> Result<Staging> {
        let n = STAGING_COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = self.root.join(".tmp");
        std::fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let dir = tmp.join(format!("{key}.{}.{n}", std::process::id()));
        let lock = lock_path(&dir);
        let owner = File::options().create(true).truncate(false).write(true).open(&lock).map_err(|e| Error::io(&lock, e))?;
        owner.lock().map_err(|e| Error::io(&lock, e))?;
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        Ok(Staging { dir, key: key.to_string(), _owner: owner })
    }

    /// Removes staging directories nobody owns any more (their process died mid-stage). A
    /// live run's staging is locked and stays, whatever process or namespace owns it.
    pub(super) fn clean_stale_staging(&self) {
        let tmp = self.root.join(".tmp");
        let Ok(entries) = std::fs::read_dir(&tmp) else { return };
        for e in entries.flatten() {
            let path = e.path();
            if path.extension().is_some_and(|x| x == "lock") {
                continue;
            }
            let lock = lock_path(&path);
            let Ok(f) = File::options().create(true).truncate(false).write(true).open(&lock) else { continue };
            if f.try_lock().is_ok() {
                let _ = std::fs::remove_dir_all(&path);
                let _ = std::fs::remove_file(&lock);
            }
        }
    }

    /// Publishes staged outputs into this directory (see [`Store::publish`]).
    pub(super) fn publish(&self, staging: Staging, mut manifest: Manifest, replace: bool) -> Result<Manifest> {
        manifest.key = staging.key.clone();
        manifest.outputs = hash_outputs(&staging.dir)?;
        for o in &manifest.outputs {
            let f = staging.dir.join(&o.path);
            File::open(&f).and_then(|h| h.sync_all()).map_err(|e| Error::io(&f, e))?;
        }
        let mpath = staging.dir.join(MANIFEST);
        let text = serde_json::to_string_pretty(&manifest).expect("a manifest serialises");
        std::fs::write(&mpath, text + "\n").map_err(|e| Error::io(&mpath, e))?;
        File::open(&mpath).and_then(|h| h.sync_all()).map_err(|e| Error::io(&mpath, e))?;
        for d in walkdir::WalkDir::new(&staging.dir).into_iter().filter_map(|e| e.ok()).filter(|e| e.file_type().is_dir()) {
            File::open(d.path()).and_then(|h| h.sync_all()).map_err(|e| Error::io(d.path(), e))?;
        }
        let dest = self.dir(&staging.key);
        if dest.exists() && replace {
            // The old artifact ends up in the staging directory, removed when it drops.
            exchange(&staging.dir, &dest).map_err(|e| Error::io(&dest, e))?;
            File::open(&self.root).and_then(|h| h.sync_all()).map_err(|e| Error::io(&self.root, e))?;
        } else if !dest.exists() {
            std::fs::rename(&staging.dir, &dest).map_err(|e| Error::io(&dest, e))?;
            File::open(&self.root).and_then(|h| h.sync_all()).map_err(|e| Error::io(&self.root, e))?;
        }
        // Else published by someone else meanwhile (only possible without the lock): keep theirs.
        Ok(manifest)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    fn manifest(kind: &str) -> Manifest {
        Manifest {
            kind: kind.into(),
            version: 1,
            node: "n".into(),
            params: serde_json::json!({}),
            metrics: serde_json::json!({}),
            idrex_version: "test".into(),
            ..Default::default()
        }
    }

    #[test]
    fn keys_are_canonical_and_sensitive_to_every_part() {
        let p1: serde_json::Value = serde_json::from_str(r#"{"a": 1, "b": [1.5, 2]}"#).unwrap();
        let p2: serde_json::Value = serde_json::from_str(r#"{"b": [1.5, 2], "a": 1}"#).unwrap();
        let none = BTreeMap::new();
        let base = key("bc", 1, &p1, 0, &none);
        assert_eq!(base, key("bc", 1, &p2, 0, &none), "key order does not matter");
        assert_ne!(base, key("bc", 2, &p1, 0, &none));
        assert_ne!(base, key("ppo", 1, &p1, 0, &none));
        assert_ne!(base, key("bc", 1, &p1, 1, &none));
        let inputs: BTreeMap<String, String> = [("demos".to_string(), "abc".to_string())].into();
        assert_ne!(base, key("bc", 1, &p1, 0, &inputs));
    }

    #[test]
    fn locations_parse_from_paths_and_s3_urls() {
        assert_eq!(Location::parse("runs/x").unwrap(), Location::Local("runs/x".into()));
        let s3 = Location::parse("s3://bucket/a/b/").unwrap();
        assert_eq!(s3, Location::S3 { bucket: "bucket".into(), prefix: "a/b".into() });
        assert_eq!(s3.to_string(), "s3://bucket/a/b");
        assert_eq!(Location::parse("s3://bucket").unwrap().to_string(), "s3://bucket");
        assert!(Location::parse("s3:///x").unwrap_err().to_string().contains("no bucket"));
        assert_eq!(Location::parse("x").unwrap().relative_to(Path::new("/p")), Location::Local("/p/x".into()));
        assert_eq!(s3.clone().relative_to(Path::new("/p")), s3);
    }

    #[test]
    fn claims_are_won_once_and_definitions_round_trip() {
        let root = std::env::temp_dir().join(format!("idrex-claims-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let store = Store::open(&root).unwrap();
        assert_eq!(store.last_claim("k").unwrap(), None);
        assert_eq!(store.claim("k", 0, "job 1").unwrap(), s3::Created::Yes);
        assert_eq!(store.claim("k", 0, "job 2").unwrap(), s3::Created::AlreadyThere);
        assert_eq!(store.claim("k", 1, "job 3").unwrap(), s3::Created::Yes);
        assert_eq!(store.last_claim("k").unwrap(), Some((1, "job 3".to_string())));
        let def = NodeDef {
            key: "k".into(),
            node: "drex/trex".into(),
            kind: "trex".into(),
            version: 1,
            params: serde_json::json!({"a": 1}),
            seed: 3,
            inputs: [("demos".to_string(), "d".to_string())].into(),
            test_set: Some(TestSetMark::Test { study: "locked".into() }),
        };
        assert_eq!(store.get_def("k").unwrap(), None);
        store.put_def(&def).unwrap();
        assert_eq!(store.get_def("k").unwrap(), Some(def));
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn publish_verify_and_quarantine() {
        let root = std::env::temp_dir().join(format!("idrex-store-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let store = Store::open(&root).unwrap();
        let k = key("t", 1, &serde_json::json!({}), 0, &BTreeMap::new());
        let _lock = store.lock(&k).unwrap();
        let s = store.stage(&k).unwrap();
        std::fs::write(s.dir.join("out.txt"), "hello").unwrap();
        let m = store.publish(s, manifest("t"), false).unwrap();
        assert_eq!(m.outputs.len(), 1);
        assert_eq!(store.lookup(&k).unwrap().unwrap().outputs[0].size, 5);
        assert!(store.verify().unwrap().is_empty());
        // Flip a byte: verify reports it, lookup moves it aside.
        std::fs::write(store.dir(&k).join("out.txt"), "hellO").unwrap();
        let bad = store.verify().unwrap();
        assert_eq!(bad.len(), 1);
        assert!(bad[0].1.contains("out.txt"), "{bad:?}");
        assert!(store.lookup(&k).unwrap().is_none());
        assert!(!store.dir(&k).exists());
        // A plain file where an artifact would be is reported too.
        std::fs::write(store.dir(&k), "not an artifact").unwrap();
        assert_eq!(store.verify().unwrap().len(), 1);
        std::fs::remove_file(store.dir(&k)).unwrap();
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn staging_is_owned_through_its_lock_and_gc_waits_for_runs() {
        let root = std::env::temp_dir().join(format!("idrex-staging-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let store = Store::open(&root).unwrap();
        // A live stage's staging survives cleanup, whatever its name says about its pid.
        let live = store.stage("k1").unwrap();
        let dead_pid = root.join(".tmp").join("k2.999999999.0");
        std::fs::create_dir_all(&dead_pid).unwrap();
        let mut fake_live = dead_pid.clone().into_os_string();
        fake_live.push(".lock");
        let held = File::options().create(true).truncate(false).write(true).open(&fake_live).unwrap();
        held.lock().unwrap();
        let orphan = root.join(".tmp").join("k3.1.0");
        std::fs::create_dir_all(&orphan).unwrap();
        store.clean_stale_staging();
        assert!(live.dir.exists() && dead_pid.exists(), "owned staging stays");
        assert!(!orphan.exists(), "unowned staging goes");
        drop(held);
        store.clean_stale_staging();
        assert!(!dead_pid.exists());
        let dir = live.dir.clone();
        drop(live);
        assert!(!dir.exists());

        // gc refuses while a pipeline run uses the store, and deletes nothing.
        let k = key("t", 1, &serde_json::json!({}), 0, &BTreeMap::new());
        let s = store.stage(&k).unwrap();
        store.publish(s, manifest("t"), false).unwrap();
        let run = store.in_use().unwrap();
        let err = store.gc(&Default::default(), false).unwrap_err().to_string();
        assert!(err.contains("a pipeline run is using the store"), "{err}");
        assert!(store.dir(&k).exists());
        drop(run);
        assert_eq!(store.gc(&Default::default(), false).unwrap(), vec![k.clone()]);
        assert!(!store.dir(&k).exists());
        std::fs::remove_dir_all(&root).unwrap();
    }
}
