//! Shared helpers: temporary directories, the idrex binary, the bootstrap's Python.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh directory under the target dir, removed when dropped.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(name: &str) -> Self {
        let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
        let dir = base.join(format!("{name}-{}-{:?}", std::process::id(), std::thread::current().id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
    pub fn path(&self) -> &Path {
        &self.0
    }
    pub fn join(&self, p: &str) -> PathBuf {
        self.0.join(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Where skipped tests are recorded, one line each, for `./dev test` to count (the test
/// harness can only call them passed).
pub fn skip_ledger() -> PathBuf {
    std::env::var_os("IDREX_SKIP_LEDGER")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("skipped-tests.txt"))
}

/// Skips the calling test: one line on the terminal, written past cargo's output capture
/// (which takes only `print!` and `eprint!`), and one in the skip ledger. The caller returns.
pub fn skip(test: &str, why: &str) {
    use std::io::Write;
    let line = format!("test {test} ... SKIPPED: {why}\n");
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
    let ledger = std::fs::OpenOptions::new().create(true).append(true).open(skip_ledger());
    // One write per line, appended: lines from tests running at once do not interleave.
    let _ = ledger.and_then(|mut f| f.write_all(line.as_bytes()));
}

pub fn idrex(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_idrex")).args(args).output().expect("run idrex")
}

pub fn python() -> String {
    let p = env!("IDREX_BUILD_PYTHON");
    assert!(!p.is_empty(), "built without scripts/bootstrap.sh: no Python to compare against");
    p.to_string()
}

pub fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
