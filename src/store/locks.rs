//! The store's locks: one per key (two runs share a store), and the use lock (shared by
//! pipeline runs, exclusive for gc).
use std::fs::File;
use std::io::Write;

use super::*;
use crate::error::{Error, Result};

/// Holds a key's lock until dropped.
pub struct KeyLock {
    _file: File,
}

/// Holds the store's use lock (shared by pipeline runs, exclusive for gc) until dropped.
pub struct UseLock {
    _file: File,
}

impl LocalDir {
    /// Blocks until this process holds `key`'s lock; `waiting` is told who holds it first
    /// when someone does.
    pub fn lock(&self, key: &str) -> Result<KeyLock> {
        self.lock_or_wait(key, &mut |_| {})
    }

    pub fn lock_or_wait(&self, key: &str, waiting: &mut dyn FnMut(&str)) -> Result<KeyLock> {
        let locks = self.root.join(".locks");
        std::fs::create_dir_all(&locks).map_err(|e| Error::io(&locks, e))?; // a cache may be deleted under a run
        let path = locks.join(format!("{key}.lock"));
        let file = File::options().create(true).truncate(false).read(true).write(true).open(&path).map_err(|e| Error::io(&path, e))?;
        if file.try_lock().is_err() {
            let who = std::fs::read_to_string(&path).unwrap_or_default();
            waiting(if who.trim().is_empty() { "another run" } else { who.trim() });
            file.lock().map_err(|e| Error::io(&path, e))?;
        }
        let _ = file.set_len(0).and_then(|_| (&file).write_all(holder().as_bytes()));
        Ok(KeyLock { _file: file })
    }

    fn use_lock_file(&self) -> Result<File> {
        let path = self.root.join(".locks").join("store.lock");
        File::options().create(true).truncate(false).write(true).open(&path).map_err(|e| Error::io(&path, e))
    }

    /// Marks the store as in use by a pipeline run (shared with other runs) until dropped.
    pub fn in_use(&self) -> Result<UseLock> {
        let file = self.use_lock_file()?;
        file.lock_shared().map_err(|e| Error::io(self.root.join(".locks/store.lock"), e))?;
        Ok(UseLock { _file: file })
    }

    /// The store to itself, for deleting: fails while a pipeline run uses it.
    pub fn exclusive(&self) -> Result<UseLock> {
        let file = self.use_lock_file()?;
        file.try_lock().map_err(|_| {
            Error::Invalid(format!("a pipeline run is using the store {}; run gc again when it has finished", self.root.display()))
        })?;
        Ok(UseLock { _file: file })
    }
}

impl Store {
    /// Blocks until this process holds `key`'s lock.
    pub fn lock(&self, key: &str) -> Result<KeyLock> {
        self.local.lock(key)
    }

    /// Blocks until this process holds `key`'s lock; `waiting` is told who holds it first
    /// when someone does.
    pub fn lock_or_wait(&self, key: &str, waiting: &mut dyn FnMut(&str)) -> Result<KeyLock> {
        self.local.lock_or_wait(key, waiting)
    }

    /// Marks the store as in use by a pipeline run (shared with other runs) until dropped.
    pub fn in_use(&self) -> Result<UseLock> {
        self.local.in_use()
    }

    /// The store to itself, for deleting: fails while a pipeline run uses it.
    pub fn exclusive(&self) -> Result<UseLock> {
        self.local.exclusive()
    }
}
