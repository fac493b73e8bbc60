//! Scale-out against real services, started here on loopback and stopped afterwards
//! (scripts/services.sh): Slurm from Debian packages and SeaweedFS's S3 server. One test in
//! a binary of its own, because the services are machine-wide (one slurmctld, fixed ports).
//!
//! Where a service cannot start, the test says so on the terminal and passes, unless
//! IDREX_REQUIRE_SERVICES is set (CI sets it: there, a skip is a failure). The binary has no
//! test harness (`harness = false`), so that the skip is printed, not captured by cargo.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use idrex::store::{Location, Store};

#[path = "util.rs"]
mod util;

const KEY: &str = "idrex-test-key";
const SECRET: &str = "idrex-test-secret-not-for-logs";
const BUCKET: &str = "idrex";

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// Stops the services when dropped (also when the test fails), then removes the test's
/// directory if the test passed.
struct Services {
    dir: PathBuf,
    base: PathBuf,
}

impl Drop for Services {
    fn drop(&mut self) {
        let _ = Command::new(repo("scripts/services.sh")).arg("stop").arg(&self.dir).status();
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.base);
        }
    }
}

/// idrex with the test cluster's environment (sbatch passes it on to the jobs).
fn idrex(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_idrex")).args(args).current_dir(dir).output().expect("run idrex")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn ok(o: Output) -> String {
    assert!(o.status.success(), "{}", text(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// (node, output path) -> sha256 of every artifact in a store, by key.
fn digests(store: &Store) -> BTreeMap<String, Vec<(String, String)>> {
    store.manifests().unwrap().into_iter().map(|m| (m.key, m.outputs.into_iter().map(|o| (o.path, o.sha256)).collect())).collect()
}

fn s3(prefix: &str) -> String {
    format!("s3://{BUCKET}/{prefix}")
}

fn s3_store(prefix: &str) -> Store {
    Store::connect(&Location::S3 { bucket: BUCKET.into(), prefix: prefix.into() }, false).unwrap()
}

/// Polls `pipeline status` until no node is queued or running; returns its last output.
fn wait_settled(dir: &Path, file: &str, store: &str, limit: Duration) -> String {
    let start = Instant::now();
    loop {
        let out = ok(idrex(dir, &["pipeline", "status", file, "--store", store]));
        let last = out.lines().last().unwrap_or_default().to_string();
        if !last.contains("queued") && !last.contains("running") {
            return out;
        }
        assert!(start.elapsed() < limit, "jobs still queued or running after {limit:?}:\n{out}");
        std::thread::sleep(Duration::from_millis(500));
    }
}

fn submitted(out: &str) -> Vec<String> {
    out.lines().filter(|l| l.starts_with("submitted ")).map(|l| l.split_whitespace().nth(1).unwrap().to_string()).collect()
}

const NAME: &str = "pipelines_run_as_slurm_jobs_against_an_s3_store";

/// A test binary's command line as cargo test and nextest pass it: `--list` lists the test,
/// a name filter that does not match it runs nothing, other flags are accepted and ignored.
fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--list") {
        println!("{NAME}: test");
        return;
    }
    let ignored = args.iter().any(|a| a == "--ignored");
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with('-')).collect();
    let exact = args.iter().any(|a| a == "--exact");
    let selected = filters.is_empty() || filters.iter().any(|f| if exact { f.as_str() == NAME } else { NAME.contains(f.as_str()) });
    if ignored || !selected {
        println!("running 0 tests (cluster: {NAME} not selected)");
        return;
    }
    println!("running 1 test (cluster: {NAME})");
    if pipelines_run_as_slurm_jobs_against_an_s3_store() {
        println!("test {NAME} ... ok");
    }
}

/// False where it was skipped.
fn pipelines_run_as_slurm_jobs_against_an_s3_store() -> bool {
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("cluster-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    std::fs::create_dir_all(&base).unwrap();
    let svc = base.join("services");
    let started = Command::new(repo("scripts/services.sh"))
        .arg("start")
        .arg(&svc)
        .env("IDREX_S3_KEY", KEY)
        .env("IDREX_S3_SECRET", SECRET)
        .output()
        .expect("run scripts/services.sh");
    let _services = Services { dir: svc.clone(), base: base.clone() };
    if !started.status.success() {
        let why = text(&started);
        assert!(std::env::var_os("IDREX_REQUIRE_SERVICES").is_none(), "the services did not start (IDREX_REQUIRE_SERVICES is set): {why}");
        util::skip(
            NAME,
            &format!(
                "the Slurm and S3 services did not start (`scripts/services.sh install` installs them): {}",
                why.trim().lines().last().unwrap_or("")
            ),
        );
        return false;
    }
    // SAFETY: the only test of this binary; set before any thread reads the environment.
    unsafe {
        std::env::set_var("SLURM_CONF", svc.join("slurm.conf"));
        std::env::set_var("AWS_ACCESS_KEY_ID", KEY);
        std::env::set_var("AWS_SECRET_ACCESS_KEY", SECRET);
        std::env::set_var("AWS_ENDPOINT_URL", "http://127.0.0.1:8333");
        std::env::set_var("IDREX_S3_CACHE", base.join("s3-cache"));
    }
    let smoke = repo("pipelines/smoke.yaml");
    let smoke = smoke.to_str().unwrap();
    let limit = Duration::from_secs(240);

    // The reference: the smoke pipeline run here into a local store.
    ok(idrex(&base, &["pipeline", "run", smoke, "--store", "local", "--jobs", "2"]));
    let reference = digests(&Store::at(base.join("local")));
    assert_eq!(reference.len(), 28);

    // 1. Submitted through Slurm into S3: same keys, same bytes.
    let out = ok(idrex(&base, &["pipeline", "run", smoke, "--store", &s3("a"), "--executor", "slurm", "--log-dir", "logs-a"]));
    assert_eq!(submitted(&out).len(), 28, "{out}");
    let status = wait_settled(&base, smoke, &s3("a"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 stored"), "{status}");
    assert_eq!(digests(&s3_store("a")), reference, "Slurm + S3 made other bytes than a local run");
    let again = ok(idrex(&base, &["pipeline", "run", smoke, "--store", &s3("a"), "--executor", "slurm", "--log-dir", "logs-a"]));
    assert!(submitted(&again).is_empty() && again.contains("28 stored"), "{again}");
    let verified = ok(idrex(&base, &["verify", "--store", &s3("a")]));
    assert!(verified.contains("28 artifacts, 0 corrupt"), "{verified}");
    // The report reads the bucket like a directory.
    let report = ok(idrex(&base, &["report", "--store", &s3("a"), "--out", "report-a"]));
    assert!(report.contains("| Hopper-v5 | smoke |"), "{report}");

    // 2. A truncated blob is found by verify, makes its artifact absent, and a local run
    // against the bucket recomputes and repairs it.
    let store = s3_store("a");
    let victim = store.manifests().unwrap().into_iter().find(|m| m.node == "drex/trex").unwrap();
    let blob = &victim.outputs[0];
    // Blobs are content-addressed: the rewards' sidecars are the same bytes, so four
    // artifacts (D-REX's reward and the three iD-REX rewards; the smoke file trains no judge)
    // lose the file. The run recomputes D-REX's reward; the iD-REX rewards, downstream of it,
    // find the blob repaired.
    let sharing = store.manifests().unwrap().iter().filter(|m| m.outputs.iter().any(|o| o.sha256 == blob.sha256)).count();
    assert_eq!(sharing, 4);
    let bucket = idrex::store::s3::Remote::connect(BUCKET, "a").unwrap();
    bucket.put(&format!("blobs/{}", blob.sha256), b"truncated".to_vec()).unwrap();
    let o = idrex(&base, &["verify", "--store", &s3("a")]);
    assert!(!o.status.success() && text(&o).contains(&victim.key), "{}", text(&o));
    let plan = ok(idrex(&base, &["pipeline", "status", smoke, "--store", &s3("a")]));
    assert!(plan.lines().any(|l| l.contains("drex/trex") && !l.contains("stored")), "{plan}");
    let rerun = ok(idrex(&base, &["pipeline", "run", smoke, "--store", &s3("a")]));
    assert!(rerun.contains(" 1 computed"), "{rerun}");
    assert!(ok(idrex(&base, &["verify", "--store", &s3("a")])).contains("0 corrupt"));

    // 3. Two submissions of one file at once compute each node once.
    let spawn = |logs: &str| {
        Command::new(env!("CARGO_BIN_EXE_idrex"))
            .args(["pipeline", "run", smoke, "--store", &s3("b"), "--executor", "slurm", "--log-dir", logs])
            .current_dir(&base)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (x, y) = (spawn("logs-b"), spawn("logs-b"));
    let (x, y) = (ok(x.wait_with_output().unwrap()), ok(y.wait_with_output().unwrap()));
    let mut both = submitted(&x);
    both.extend(submitted(&y));
    both.sort();
    let before = both.len();
    both.dedup();
    assert_eq!((before, both.len()), (28, 28), "each node submitted once in all:\n{x}\n{y}");
    wait_settled(&base, smoke, &s3("b"), limit);
    let computed = std::fs::read_dir(base.join("logs-b"))
        .unwrap()
        .flatten()
        .filter(|e| std::fs::read_to_string(e.path()).unwrap_or_default().contains("computed in"))
        .count();
    assert_eq!(computed, 28, "every node computed exactly once");
    assert_eq!(digests(&s3_store("b")).len(), 28);
    assert!(ok(idrex(&base, &["verify", "--store", &s3("b")])).contains("28 artifacts, 0 corrupt"));

    // 4. A job killed mid-way: it and what depends on it show as failed (nothing pends
    // forever), and a resubmission completes the pipeline.
    let slow = base.join("slow.yaml");
    let yaml = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap().replace("  steps: 4096\n", "  steps: 300000\n");
    assert!(yaml.contains("steps: 300000"), "the smoke pipeline's demonstrator changed");
    std::fs::write(&slow, yaml).unwrap();
    let slow = slow.to_str().unwrap();
    let out = ok(idrex(&base, &["pipeline", "run", slow, "--store", &s3("c"), "--executor", "slurm", "--log-dir", "logs-c"]));
    let first = out.lines().find(|l| l.contains(" demonstrator ")).unwrap().split_whitespace().last().unwrap().to_string();
    let start = Instant::now();
    while !ok(idrex(&base, &["pipeline", "status", slow, "--store", &s3("c")]))
        .lines()
        .any(|l| l.contains("demonstrator") && l.contains("running"))
    {
        assert!(start.elapsed() < limit, "the demonstrator job never ran");
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(Duration::from_secs(1));
    assert!(Command::new("scancel").arg(&first).status().unwrap().success());
    let status = wait_settled(&base, slow, &s3("c"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 failed"), "{status}");
    let out = ok(idrex(&base, &["pipeline", "run", slow, "--store", &s3("c"), "--executor", "slurm", "--log-dir", "logs-c"]));
    assert_eq!(submitted(&out).len(), 28, "{out}");
    let status = wait_settled(&base, slow, &s3("c"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 stored"), "{status}");

    // 5. Mistakes in the connection: one line that names the problem, never the secret.
    let status = |vars: &[(&str, &str)]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_idrex"));
        c.args(["pipeline", "status", smoke, "--store", &s3("a")]).current_dir(&base);
        for (k, v) in vars {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    for (vars, want) in [
        (vec![("AWS_SECRET_ACCESS_KEY", "wrong-secret")], "refused the credentials"),
        (vec![("AWS_ENDPOINT_URL", "http://127.0.0.1:9")], "cannot reach http://127.0.0.1:9"),
    ] {
        let o = status(&vars);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(err.contains(want), "{err}");
        assert!(!err.contains(SECRET) && !err.contains("wrong-secret"), "a secret in the message: {err}");
    }

    // gc on the bucket keeps what a pipeline names and removes the rest; what stays is intact.
    let gc = ok(idrex(&base, &["gc", smoke, "--store", &s3("a"), "--yes"]));
    assert!(gc.contains("0 artifacts removed"), "{gc}");
    let one_seed = base.join("one-seed.yaml");
    std::fs::write(&one_seed, std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap().replace("seeds: [0, 1]", "seeds: [0]"))
        .unwrap();
    let gc = ok(idrex(&base, &["gc", one_seed.to_str().unwrap(), "--store", &s3("a"), "--yes"]));
    let removed: usize = gc.lines().last().unwrap().split_whitespace().next().unwrap().parse().unwrap();
    assert!(removed > 0 && removed < 28, "{gc}");
    let verified = ok(idrex(&base, &["verify", "--store", &s3("a")]));
    assert!(verified.contains(&format!("{} artifacts, 0 corrupt", 28 - removed)), "{verified}");
    true
}
