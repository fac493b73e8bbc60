//! A skipped test is seen: its line gets past cargo's output capture, and the ledger that
//! `./dev test` counts records it.
use std::process::Command;

use crate::util::{TempDir, skip};

/// Skips when run as the probe below; passes (doing nothing) otherwise.
#[test]
fn probe_that_skips() {
    if std::env::var_os("IDREX_SKIP_PROBE").is_some() {
        skip("skips::probe_that_skips", "asked to by the probe");
    }
}

#[test]
fn a_skip_is_printed_through_the_capture_and_recorded() {
    let dir = TempDir::new("skips");
    let ledger = dir.join("ledger.txt");
    // This test binary, run on the probe alone, with cargo's default capture.
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["skips::probe_that_skips", "--exact", "--test-threads", "1"])
        .env("IDREX_SKIP_PROBE", "1")
        .env("IDREX_SKIP_LEDGER", &ledger)
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("1 passed"), "the probe ran: {stdout}");
    let line = "test skips::probe_that_skips ... SKIPPED: asked to by the probe";
    assert!(stderr.contains(line), "the skip line got past the capture: {stderr}");
    assert_eq!(std::fs::read_to_string(&ledger).unwrap().trim(), line);
}

/// The cluster test, which has no libtest harness, reads libtest's command line as libtest
/// does: `-- --test-threads 1` runs it (a flag's value is no filter), `--skip` and other
/// names do not.
#[test]
fn the_cluster_test_reads_libtests_flags() {
    use crate::util::libtest_selects;
    let name = "pipelines_run_as_slurm_jobs_against_an_s3_store";
    let sel = |args: &[&str]| libtest_selects(name, &args.iter().map(|a| a.to_string()).collect::<Vec<_>>());
    assert!(sel(&[]) && sel(&["--test-threads", "1"]) && sel(&["--test-threads=1", "--nocapture"]) && sel(&["--color", "never"]));
    assert!(sel(&["slurm"]) && sel(&["--exact", name]) && sel(&["other", "s3_store"]) && sel(&["--include-ignored"]));
    assert!(!sel(&["--exact", "slurm"]) && !sel(&["nothing_here"]) && !sel(&["--ignored"]));
    assert!(!sel(&["--skip", "slurm"]) && !sel(&["--skip=s3"]) && sel(&["--skip", "other"]) && !sel(&["--exact", "--skip", name]));
}
