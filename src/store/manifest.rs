//! What an artifact's manifest records, and how keys and digests are computed.
use std::collections::BTreeMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::error::{Error, Result};

pub const MANIFEST: &str = "manifest.json";

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OutputFile {
    pub path: String,
    pub sha256: String,
    pub size: u64,
}

#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    pub key: String,
    pub kind: String,
    pub version: u32,
    /// The pipeline node this artifact was computed for (not part of the key).
    pub node: String,
    pub params: serde_json::Value,
    pub seed: u64,
    /// Input role -> key.
    pub inputs: BTreeMap<String, String>,
    pub outputs: Vec<OutputFile>,
    pub metrics: serde_json::Value,
    pub started_unix: f64,
    pub ended_unix: f64,
    pub wall_s: f64,
    pub idrex_version: String,
    /// The CPU code path (the [`crate::kernels::gemm::Kernel`] variant, and the bf16 path where a
    /// stage trains in bf16: `Params::cpu_path`), as information
    /// only: every variant gives the same bytes. Absent from manifests written before it was
    /// recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel: Option<String>,
    /// An evaluation's standing against a locked test set, for the report; not part of the
    /// key. Absent outside test sets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_set: Option<TestSetMark>,
}

/// How an evaluation relates to a locked test set (a pipeline file with `role: test`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TestSetMark {
    /// Evaluated by the test set's own file, on seeds no other configuration had used.
    Test { study: String },
    /// Evaluated with `--reuse-test-set` where a test set (named) or another configuration
    /// had already looked: the result is exploratory.
    Reuse { study: String },
}

/// The key of a stage instance.
pub fn key(kind: &str, version: u32, params: &serde_json::Value, seed: u64, inputs: &BTreeMap<String, String>) -> String {
    // serde_json's Map is a BTreeMap (no preserve_order feature): keys serialise sorted.
    // key_format 2: parameters became typed structs (some gained fields, the PPO curve
    // changed columns), so every key changed once. key_format 3: rollout MCAP files omit an
    // absent learned reward instead of writing null, so their bytes changed.
    key_of_text(kind, version, &params.to_string(), seed, inputs)
}

/// [`key`] with the parameters given as their compact JSON text: an archive's line keeps
/// that text as written, which parsing could move by an ulp.
pub fn key_of_text(kind: &str, version: u32, params: &str, seed: u64, inputs: &BTreeMap<String, String>) -> String {
    // The object `json!` would build, keys in sorted order.
    let canonical = format!(
        "{{\"inputs\":{},\"key_format\":3,\"kind\":{},\"params\":{params},\"seed\":{seed},\"version\":{version}}}",
        serde_json::to_string(inputs).expect("a map of strings encodes"),
        serde_json::Value::from(kind),
    );
    hex(&Sha256::digest(canonical.as_bytes()))
}

pub(crate) fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

pub fn sha256_file(path: &Path) -> Result<(String, u64)> {
    let mut f = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    let mut size = 0u64;
    loop {
        let n = f.read(&mut buf).map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        size += n as u64;
        h.update(&buf[..n]);
    }
    Ok((hex(&h.finalize()), size))
}

/// Every file under `dir` but the manifest, with its sha256 and size, in path order.
pub fn hash_outputs(dir: &Path) -> Result<Vec<OutputFile>> {
    let mut files: Vec<PathBuf> =
        walkdir::WalkDir::new(dir).into_iter().filter_map(|e| e.ok()).filter(|e| e.file_type().is_file()).map(|e| e.into_path()).collect();
    files.sort();
    let mut out = Vec::with_capacity(files.len());
    for f in &files {
        let rel = f.strip_prefix(dir).expect("under the directory").to_string_lossy().into_owned();
        if rel != MANIFEST {
            let (sha256, size) = sha256_file(f)?;
            out.push(OutputFile { path: rel, sha256, size });
        }
    }
    Ok(out)
}

pub fn now_unix() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}
