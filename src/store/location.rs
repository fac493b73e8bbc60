//! Where a store is: a directory or an S3 bucket and prefix.
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Where a store lives: a directory, or a prefix in an S3-compatible bucket.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    Local(PathBuf),
    S3 { bucket: String, prefix: String },
}

impl Location {
    /// `s3://bucket/prefix` or a directory path.
    pub fn parse(text: &str) -> Result<Location> {
        let Some(rest) = text.strip_prefix("s3://") else { return Ok(Location::Local(PathBuf::from(text))) };
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        if bucket.is_empty() {
            return Err(Error::Invalid(format!("store URL {text}: no bucket; write s3://BUCKET/PREFIX")));
        }
        Ok(Location::S3 { bucket: bucket.to_string(), prefix: prefix.trim_matches('/').to_string() })
    }

    /// A relative directory is taken relative to `base` (the pipeline file's directory).
    pub fn relative_to(self, base: &Path) -> Location {
        match self {
            Location::Local(p) => Location::Local(base.join(p)),
            s3 => s3,
        }
    }

    /// The directory where an S3 store's artifacts are staged and cached on this machine:
    /// `$IDREX_S3_CACHE` or `~/.cache/idrex/s3`, then bucket and prefix.
    pub(super) fn cache_dir(bucket: &str, prefix: &str) -> PathBuf {
        let base = std::env::var_os("IDREX_S3_CACHE").map(PathBuf::from).unwrap_or_else(|| {
            let home = std::env::var_os("XDG_CACHE_HOME")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from(std::env::var_os("HOME").unwrap_or_else(|| "/tmp".into())).join(".cache"));
            home.join("idrex").join("s3")
        });
        let dir = base.join(bucket);
        if prefix.is_empty() { dir.join("_") } else { dir.join(prefix) }
    }
}

impl std::fmt::Display for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Location::Local(p) => write!(f, "{}", p.display()),
            Location::S3 { bucket, prefix } if prefix.is_empty() => write!(f, "s3://{bucket}"),
            Location::S3 { bucket, prefix } => write!(f, "s3://{bucket}/{prefix}"),
        }
    }
}
