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

/// Load: `runs` pipeline runs on one store at once (`files` in turn; run `i` gets the
/// environment `vars(i)`), in `dir`, while `beside` is called in a loop until they have all
/// ended. Panics when a run fails or outlasts `limit`; returns each run's stdout.
pub fn runs_at_once(
    dir: &Path,
    store: &str,
    files: &[PathBuf],
    runs: usize,
    vars: &dyn Fn(usize) -> Vec<(String, String)>,
    limit: std::time::Duration,
    beside: &mut dyn FnMut(),
) -> Vec<String> {
    let start = std::time::Instant::now();
    let mut children: Vec<_> = (0..runs)
        .map(|i| {
            let file = files[i % files.len()].to_str().unwrap().to_string();
            let rec = dir.join(format!("load-{i}.rrd"));
            let mut c = Command::new(env!("CARGO_BIN_EXE_idrex"));
            c.args(["pipeline", "run", &file, "--store", store, "--jobs", "1", "--recording", rec.to_str().unwrap()]).current_dir(dir);
            for (k, v) in vars(i) {
                c.env(k, v);
            }
            let out = std::fs::File::create(dir.join(format!("load-{i}.out"))).unwrap();
            let err = std::fs::File::create(dir.join(format!("load-{i}.err"))).unwrap();
            Some(c.stdout(out).stderr(err).spawn().unwrap())
        })
        .collect();
    loop {
        let mut alive = 0;
        for (i, slot) in children.iter_mut().enumerate() {
            let Some(child) = slot else { continue };
            match child.try_wait().unwrap() {
                None => alive += 1,
                Some(status) => {
                    let err = std::fs::read_to_string(dir.join(format!("load-{i}.err"))).unwrap_or_default();
                    assert!(status.success(), "run {i} failed:\n{err}");
                    *slot = None;
                }
            }
        }
        if alive == 0 {
            break;
        }
        if start.elapsed() > limit {
            for c in children.iter_mut().flatten() {
                let _ = c.kill();
            }
            panic!("{alive} of {runs} runs still going after {limit:?}: a run waits forever");
        }
        beside();
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    (0..runs).map(|i| std::fs::read_to_string(dir.join(format!("load-{i}.out"))).unwrap()).collect()
}

/// The stages a run computed, from its summary line (`NAME: N stages, C computed, ...`).
pub fn computed(stdout: &str) -> usize {
    stdout
        .lines()
        .find_map(|l| {
            let rest = l.split(" stages, ").nth(1)?;
            rest.split(" computed").next()?.trim().parse().ok()
        })
        .unwrap_or_else(|| panic!("no summary line in:\n{stdout}"))
}

/// Whether libtest's command line (as `cargo test` and nextest pass it) selects the test
/// `name` of a binary without libtest's harness: name filters (substrings, whole names with
/// `--exact`), `--skip` (repeatable), `--ignored` (runs only ignored tests: not this one) and
/// `--list` (handled by the caller); the other flags are accepted, those with a value
/// (`--test-threads 1`, `--color=never`) with it.
pub fn libtest_selects(name: &str, args: &[String]) -> bool {
    const WITH_VALUE: &[&str] = &["--test-threads", "--skip", "--color", "--format", "--logfile", "--shuffle-seed", "-Z"];
    let (mut filters, mut skips) = (Vec::new(), Vec::new());
    let (mut exact, mut ignored) = (false, false);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let (flag, inline) = match a.split_once('=') {
            Some((f, v)) if f.starts_with('-') => (f, Some(v.to_string())),
            _ => (a.as_str(), None),
        };
        if WITH_VALUE.contains(&flag) {
            let value = inline.or_else(|| it.next().cloned()).unwrap_or_default();
            if flag == "--skip" {
                skips.push(value);
            }
        } else if flag == "--exact" {
            exact = true;
        } else if flag == "--ignored" {
            ignored = true;
        } else if !flag.starts_with('-') {
            filters.push(a.clone());
        }
    }
    let matches = |f: &String| if exact { f == name } else { name.contains(f.as_str()) };
    !ignored && (filters.is_empty() || filters.iter().any(matches)) && !skips.iter().any(matches)
}

/// The bootstrap's Python run with these arguments and `input` on its standard input.
pub fn python_with_input<S: AsRef<std::ffi::OsStr>>(args: &[S], input: impl AsRef<[u8]>) -> Output {
    use std::io::Write;
    let mut child = Command::new(python())
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(input.as_ref()).unwrap();
    child.wait_with_output().unwrap()
}
