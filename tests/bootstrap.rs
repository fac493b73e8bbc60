//! The set-up script: idempotent and fast once done; a failed pip install names the package
//! and leaves no environment behind that a later run would trust.
use std::process::Command;

use crate::util::{TempDir, repo, stderr};

#[test]
fn a_second_run_returns_in_under_a_second() {
    let script = repo("scripts/bootstrap.sh");
    assert!(Command::new(&script).output().unwrap().status.success());
    let start = std::time::Instant::now();
    let out = Command::new(&script).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(start.elapsed().as_secs_f64() < 1.0, "took {:?}", start.elapsed());
}

#[test]
fn a_failed_install_names_the_package_and_keeps_nothing() {
    let dir = TempDir::new("bootstrap-fail");
    std::fs::create_dir_all(dir.join("scripts")).unwrap();
    std::fs::copy(repo("scripts/bootstrap.sh"), dir.join("scripts/bootstrap.sh")).unwrap();
    std::fs::write(dir.join("scripts/requirements.txt"), "no-such-package-for-idrex-tests==9.9.9\n").unwrap();
    let cache = dir.join("cache");
    // Through bash, not exec: a test running in parallel may fork while the copy is still
    // open for writing, and exec'ing a file open for writing fails (ETXTBSY).
    let out = Command::new("bash").arg(dir.join("scripts/bootstrap.sh")).env("IDREX_CACHE", &cache).output().unwrap();
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("pip could not install 'no-such-package-for-idrex-tests==9.9.9'"), "{err}");
    let left: Vec<String> = std::fs::read_dir(&cache).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    assert!(left.iter().all(|n| !n.starts_with("env-") || n.ends_with(".install.log")), "{left:?}");
    assert!(!dir.join(".cargo/config.toml").exists(), "the clone is not pointed at a failed environment");
}
