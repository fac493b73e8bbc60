//! The S3-compatible backend of the store (`--store s3://bucket/prefix`).
//!
//! Layout under the prefix:
//!
//! ```text
//! blobs/<sha256>                 every output file, named by its content
//! artifacts/<key>/manifest.json  the commit point: written last, create-if-absent
//! defs/<key>.json                a node as submitted (for `idrex stage run KEY`)
//! claims/<key>/<n>.json          who was sent to compute a node (Slurm job ids)
//! ```
//!
//! Blobs go up first (overwriting one is harmless: same name, same bytes), each checked
//! afterwards by its size; then the manifest is put with `If-None-Match: *`. A racer that
//! loses finds the winner's manifest and discards its own copy, so two machines computing a
//! node at once is wasted work, never a conflict, and no lock is needed. A reader trusts a
//! manifest only when every blob it names exists with its recorded size, and checks each
//! blob's sha256 when it downloads it (S3 stores have accepted truncated uploads).
//!
//! Endpoint, region and credentials come from the standard AWS environment variables
//! (`AWS_ENDPOINT_URL`, `AWS_REGION`, `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, ...);
//! they never enter a manifest, a log line or an error message.
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use futures::TryStreamExt;
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, ObjectStoreExt, PutMode, PutPayload};
use sha2::{Digest, Sha256};

use super::manifest::hex;
use super::retry::clean;
use super::{MANIFEST, Manifest};
use crate::error::{Error, Result};

/// A bucket and a prefix in it, with a connection.
pub struct Remote {
    store: Arc<dyn ObjectStore>,
    /// `s3://bucket/prefix`, for messages.
    pub url: String,
    endpoint: String,
    prefix: String,
    rt: tokio::runtime::Runtime,
    /// Blob sizes from one listing, when a command checks many artifacts
    /// ([`Remote::index_blobs`]); a blob it lacks is still asked about directly.
    blob_index: std::sync::Mutex<Option<std::collections::HashMap<String, u64>>>,
    /// Whether the server has answered yet, and how many requests were retried.
    pub(super) retries: super::retry::Retries,
}

impl std::fmt::Debug for Remote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Remote({})", self.url)
    }
}

/// Whether a put created the object or found it there already.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Created {
    Yes,
    AlreadyThere,
}

impl Remote {
    pub fn connect(bucket: &str, prefix: &str) -> Result<Remote> {
        let url = if prefix.is_empty() { format!("s3://{bucket}") } else { format!("s3://{bucket}/{prefix}") };
        let mut builder = AmazonS3Builder::from_env().with_bucket_name(bucket);
        let endpoint = std::env::var("AWS_ENDPOINT_URL_S3")
            .or_else(|_| std::env::var("AWS_ENDPOINT_URL"))
            .or_else(|_| std::env::var("AWS_ENDPOINT"))
            .unwrap_or_else(|_| "the AWS default endpoint".into());
        // A plain-HTTP endpoint is a deliberate choice (a test server, a cluster-internal
        // gateway); object_store refuses it unless told.
        let allow_http = endpoint.starts_with("http://") || std::env::var("AWS_ALLOW_HTTP").is_ok_and(|v| v == "true");
        if std::env::var_os("AWS_REGION").is_none() && std::env::var_os("AWS_DEFAULT_REGION").is_none() {
            builder = builder.with_region("us-east-1");
        }
        // Retries are idrex's own ([`super::retry`]): every one is logged, and a store that
        // has never answered is given up on within a second.
        let retry =
            object_store::RetryConfig { max_retries: 0, retry_timeout: Duration::ZERO, backoff: object_store::BackoffConfig::default() };
        let options = object_store::ClientOptions::new()
            .with_allow_http(allow_http)
            .with_connect_timeout(Duration::from_secs(5))
            .with_timeout(super::retry::request_timeout()?);
        let store =
            builder.with_retry(retry).with_client_options(options).build().map_err(|e| Error::Invalid(format!("{url}: {}", clean(&e))))?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("idrex-s3")
            .enable_all()
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start the S3 client's runtime: {e}")))?;
        Ok(Remote {
            store: Arc::new(store),
            url,
            endpoint,
            prefix: prefix.trim_matches('/').to_string(),
            rt,
            blob_index: std::sync::Mutex::new(None),
            retries: super::retry::Retries::default(),
        })
    }

    fn path(&self, rel: &str) -> ObjectPath {
        ObjectPath::from(if self.prefix.is_empty() { rel.to_string() } else { format!("{}/{rel}", self.prefix) })
    }

    /// One line for an object_store error: what went wrong and what to check.
    fn err(&self, what: &str, e: object_store::Error) -> Error {
        let text = clean(&e);
        let hint = if ["SignatureDoesNotMatch", "InvalidAccessKeyId", "AccessDenied", "Forbidden", "403"].iter().any(|s| text.contains(s)) {
            "the server refused the credentials: check AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY".to_string()
        } else if ["error sending request", "connect", "Connection refused", "timed out", "dns"].iter().any(|s| text.contains(s)) {
            format!("cannot reach {}: check AWS_ENDPOINT_URL and that the server is up", self.endpoint)
        } else if text.contains("NoSuchBucket") {
            "no such bucket: create it, or fix the bucket in the store URL".to_string()
        } else {
            text
        };
        Error::Invalid(format!("{} {what}: {hint}", self.url))
    }

    /// Runs one request, retried with backoff while it fails in a way that may pass
    /// ([`super::retry`]); every request is idempotent (a create that is retried after its
    /// answer was lost finds its own object, which is the same bytes).
    fn call<T, F, Fut>(&self, what: &str, op: F) -> std::result::Result<T, object_store::Error>
    where
        F: Fn() -> Fut,
        Fut: std::future::Future<Output = std::result::Result<T, object_store::Error>>,
    {
        self.retries.run(&self.url, what, || self.rt.block_on(op()))
    }

    pub fn get(&self, rel: &str) -> Result<Option<Vec<u8>>> {
        let p = self.path(rel);
        let what = format!("reading {rel}");
        self.call(&what, || async {
            match self.store.get(&p).await {
                Ok(r) => r.bytes().await.map(|b| Some(b.to_vec())),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(e),
            }
        })
        .map_err(|e| self.err(&what, e))
    }

    /// The size of an object, or None when it does not exist.
    pub fn size(&self, rel: &str) -> Result<Option<u64>> {
        let p = self.path(rel);
        let what = format!("checking {rel}");
        self.call(&what, || async {
            match self.store.head(&p).await {
                Ok(m) => Ok(Some(m.size)),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(e),
            }
        })
        .map_err(|e| self.err(&what, e))
    }

    pub fn put(&self, rel: &str, bytes: Vec<u8>) -> Result<()> {
        let p = self.path(rel);
        let what = format!("writing {rel}");
        let payload = PutPayload::from(bytes);
        self.call(&what, || self.store.put(&p, payload.clone())).map(|_| ()).map_err(|e| self.err(&what, e))
    }

    /// Puts `bytes` only if nothing is at `rel` (S3 `If-None-Match: *`).
    pub fn create(&self, rel: &str, bytes: Vec<u8>) -> Result<Created> {
        let p = self.path(rel);
        let what = format!("creating {rel}");
        let payload = PutPayload::from(bytes);
        self.call(&what, || async {
            match self.store.put_opts(&p, payload.clone(), PutMode::Create.into()).await {
                Ok(_) => Ok(Created::Yes),
                Err(object_store::Error::AlreadyExists { .. } | object_store::Error::Precondition { .. }) => Ok(Created::AlreadyThere),
                Err(e) => Err(e),
            }
        })
        .map_err(|e| self.err(&what, e))
    }

    pub fn delete(&self, rel: &str) -> Result<()> {
        let p = self.path(rel);
        let what = format!("deleting {rel}");
        self.call(&what, || async {
            match self.store.delete(&p).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
                Err(e) => Err(e),
            }
        })
        .map_err(|e| self.err(&what, e))
    }

    /// Every object under `rel/`: (path relative to `rel/`, size, last modified as unix seconds).
    pub fn list(&self, rel: &str) -> Result<Vec<(String, u64, i64)>> {
        let p = self.path(rel);
        let what = format!("listing {rel}");
        let metas: Vec<object_store::ObjectMeta> =
            self.call(&what, || self.store.list(Some(&p)).try_collect()).map_err(|e| self.err(&what, e))?;
        let base = format!("{}/", p.as_ref());
        Ok(metas
            .into_iter()
            .filter_map(|m| {
                let name = m.location.as_ref().strip_prefix(&base)?.to_string();
                Some((name, m.size, m.last_modified.timestamp()))
            })
            .collect())
    }

    fn manifest_path(key: &str) -> String {
        format!("artifacts/{key}/{MANIFEST}")
    }

    pub fn blob_path(sha256: &str) -> String {
        format!("blobs/{sha256}")
    }

    /// The manifest of `key` as written, without looking at its blobs.
    pub fn manifest(&self, key: &str) -> Result<Option<Manifest>> {
        let Some(bytes) = self.get(&Self::manifest_path(key))? else { return Ok(None) };
        serde_json::from_slice(&bytes).map(Some).map_err(|e| Error::Invalid(format!("{} artifacts/{key}/{MANIFEST}: {e}", self.url)))
    }

    /// The manifest of `key` if every blob it names exists with its size; the error says what
    /// is missing or wrong (an unreadable manifest, a bad digest or path: the artifact is
    /// then recomputed like a missing one). `Ok(None)` when there is no manifest; `Err` only
    /// when the store cannot be asked.
    pub fn check(&self, key: &str) -> Result<Option<std::result::Result<Manifest, String>>> {
        let Some(bytes) = self.get(&Self::manifest_path(key))? else { return Ok(None) };
        let m: Manifest = match serde_json::from_slice(&bytes) {
            Ok(m) => m,
            Err(e) => return Ok(Some(Err(format!("{MANIFEST} is unreadable: {e}")))),
        };
        if m.key != key {
            return Ok(Some(Err(format!("{MANIFEST} names key {}", m.key))));
        }
        if let Some(problem) = m.outputs.iter().find_map(output_problem) {
            return Ok(Some(Err(problem)));
        }
        for o in &m.outputs {
            let listed = self.blob_index.lock().unwrap_or_else(|e| e.into_inner()).as_ref().and_then(|i| i.get(&o.sha256).copied());
            if listed == Some(o.size) {
                continue;
            }
            match self.size(&Self::blob_path(&o.sha256))? {
                Some(size) if size == o.size => {}
                Some(size) => return Ok(Some(Err(format!("{}: blob has {size} bytes, the manifest says {}", o.path, o.size)))),
                None => return Ok(Some(Err(format!("{}: blob {} is missing", o.path, &o.sha256[..12])))),
            }
        }
        Ok(Some(Ok(m)))
    }

    /// Lists every blob once, so that checking many artifacts (status, report, submission)
    /// costs a listing instead of a request per file: a PPO run alone has about 100 files.
    pub fn index_blobs(&self) -> Result<()> {
        let index = self.list("blobs")?.into_iter().map(|(sha, size, _)| (sha, size)).collect();
        *self.blob_index.lock().unwrap_or_else(|e| e.into_inner()) = Some(index);
        Ok(())
    }

    /// Downloads every output of `m` into `dir`, checking each blob's sha256 and size.
    pub fn download(&self, m: &Manifest, dir: &Path) -> Result<()> {
        if let Some(problem) = m.outputs.iter().find_map(output_problem) {
            return Err(Error::Invalid(format!("{}: artifact {}: {problem}", self.url, m.key)));
        }
        for o in &m.outputs {
            let bytes = self
                .fetch_blob(&o.sha256, o.size)?
                .map_err(|problem| Error::Invalid(format!("{}: artifact {}, {}: {problem}", self.url, m.key, o.path)))?;
            let to = dir.join(&o.path);
            if let Some(parent) = to.parent() {
                std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            std::fs::write(&to, &bytes).map_err(|e| Error::io(&to, e))?;
        }
        Ok(())
    }

    /// A blob's bytes once checked against its size and digest, or what is wrong with it.
    fn fetch_blob(&self, sha256: &str, size: u64) -> Result<std::result::Result<Vec<u8>, String>> {
        let short = &sha256[..sha256.len().min(12)];
        Ok(match self.get(&Self::blob_path(sha256))? {
            None => Err(format!("blob {short} is missing")),
            Some(b) if b.len() as u64 != size => Err(format!("blob {short} has {} bytes, not {size}", b.len())),
            Some(b) if hex(&Sha256::digest(&b)) != sha256 => Err(format!("blob {short} does not match its digest")),
            Some(b) => Ok(b),
        })
    }

    /// The problem with a blob's bytes, if any (verify downloads and hashes every blob).
    pub fn blob_problem(&self, sha256: &str, size: u64) -> Result<Option<String>> {
        Ok(self.fetch_blob(sha256, size)?.err())
    }

    /// Uploads a published local artifact: blobs first, each checked by size afterwards, then
    /// the manifest as the commit point. Returns whether this call committed it
    /// ([`Created::AlreadyThere`]: someone else did first, and theirs stands). With `replace`
    /// (a forced recomputation, or a stored manifest whose blobs are gone) the manifest is
    /// overwritten.
    pub fn push(&self, dir: &Path, m: &Manifest, replace: bool) -> Result<Created> {
        for o in &m.outputs {
            let rel = Self::blob_path(&o.sha256);
            if self.size(&rel)? == Some(o.size) {
                continue; // content-addressed: already there
            }
            let f = dir.join(&o.path);
            let bytes = std::fs::read(&f).map_err(|e| Error::io(&f, e))?;
            self.put(&rel, bytes)?;
            match self.size(&rel)? {
                Some(s) if s == o.size => {}
                got => {
                    return Err(Error::Invalid(format!(
                        "{}: uploading {} of {} left {:?} bytes, not {}; nothing was committed",
                        self.url, o.path, m.key, got, o.size
                    )));
                }
            }
        }
        let text = serde_json::to_string_pretty(m).expect("a manifest serialises") + "\n";
        let rel = Self::manifest_path(&m.key);
        let created = if replace {
            self.put(&rel, text.into_bytes())?;
            Created::Yes
        } else {
            self.create(&rel, text.into_bytes())?
        };
        if created == Created::Yes {
            // A blob found already there may have been old and unreferenced, and removed by a
            // concurrent gc since: put back whatever the committed manifest lacks.
            for o in &m.outputs {
                let rel = Self::blob_path(&o.sha256);
                if self.size(&rel)? != Some(o.size) {
                    let f = dir.join(&o.path);
                    self.put(&rel, std::fs::read(&f).map_err(|e| Error::io(&f, e))?)?;
                }
            }
        }
        Ok(created)
    }

    /// Every key with a manifest.
    pub fn keys(&self) -> Result<Vec<String>> {
        let mut keys: Vec<String> = self
            .list("artifacts")?
            .into_iter()
            .filter_map(|(name, _, _)| name.strip_suffix(&format!("/{MANIFEST}")).map(str::to_string))
            .collect();
        keys.sort();
        keys.dedup();
        Ok(keys)
    }

    pub fn delete_artifact(&self, key: &str) -> Result<()> {
        self.delete(&Self::manifest_path(key))?;
        self.delete_submission(key)
    }

    /// A node's definition and claims.
    pub fn delete_submission(&self, key: &str) -> Result<()> {
        self.delete(&format!("defs/{key}.json"))?;
        for (name, _, _) in self.list(&format!("claims/{key}"))? {
            self.delete(&format!("claims/{key}/{name}"))?;
        }
        Ok(())
    }

    /// Keys with a stored definition (submitted nodes, computed or not).
    pub fn submitted(&self) -> Result<Vec<String>> {
        Ok(self.list("defs")?.into_iter().filter_map(|(name, _, _)| name.strip_suffix(".json").map(str::to_string)).collect())
    }
}

/// What is wrong with a manifest's output entry, if anything: its digest must be 64 hex
/// digits and its path relative, without `..` (it is joined to a local directory).
fn output_problem(o: &super::OutputFile) -> Option<String> {
    let path = Path::new(&o.path);
    if o.sha256.len() != 64 || !o.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
        Some(format!("{}: '{}' is not a sha256", o.path, o.sha256))
    } else if o.path.is_empty() || path.is_absolute() || path.components().any(|c| !matches!(c, std::path::Component::Normal(_))) {
        Some(format!("output path '{}' is not a plain relative path", o.path))
    } else {
        None
    }
}
