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

use idrex::store::{Location, Store, TestSetMark};

#[path = "s3_proxy.rs"]
mod s3_proxy;
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

/// idrex with extra environment variables (a proxy's endpoint, a cache of its own).
fn idrex_with(dir: &Path, args: &[&str], vars: &[(&str, String)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_idrex"));
    c.args(args).current_dir(dir);
    for (k, v) in vars {
        c.env(k, v);
    }
    c.output().expect("run idrex")
}

/// The number of retries an idrex run logged.
fn retries_logged(o: &Output) -> usize {
    String::from_utf8_lossy(&o.stderr).lines().filter(|l| l.contains("; retry ")).count()
}

fn services(svc: &Path, what: &str) {
    let o = Command::new(repo("scripts/services.sh"))
        .arg(what)
        .arg(svc)
        .env("IDREX_S3_KEY", KEY)
        .env("IDREX_S3_SECRET", SECRET)
        .output()
        .unwrap();
    assert!(o.status.success(), "services.sh {what}: {}", text(&o));
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

/// What a Slurm job's stage process is called on its command line.
const STAGE_PROCESS: &str = concat!(env!("CARGO_BIN_EXE_idrex"), " stage run ");

/// Waits until a job's stage process is running (seen by `pgrep`), so that a kill lands
/// mid-way through a stage.
fn wait_for_stage_process(limit: Duration) {
    let start = Instant::now();
    while !Command::new("pgrep").args(["-f", STAGE_PROCESS]).output().unwrap().status.success() {
        assert!(start.elapsed() < limit, "no stage process appeared");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn submitted(out: &str) -> Vec<String> {
    out.lines().filter(|l| l.starts_with("submitted ")).map(|l| l.split_whitespace().nth(1).unwrap().to_string()).collect()
}

const NAME: &str = "pipelines_run_as_slurm_jobs_against_an_s3_store";

/// A test binary's command line as cargo test and nextest pass it: `--list` lists the test,
/// a name filter that does not match it, or a `--skip` that does, runs nothing; libtest's
/// other flags are accepted ([`util::libtest_selects`]).
fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--list") {
        println!("{NAME}: test");
        return;
    }
    if !util::libtest_selects(NAME, &args) {
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
    // Mid-way: once the job's stage process is seen running, not after a clock.
    wait_for_stage_process(limit);
    assert!(Command::new("scancel").arg(&first).status().unwrap().success());
    let status = wait_settled(&base, slow, &s3("c"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 failed"), "{status}");
    let out = ok(idrex(&base, &["pipeline", "run", slow, "--store", &s3("c"), "--executor", "slurm", "--log-dir", "logs-c"]));
    assert_eq!(submitted(&out).len(), 28, "{out}");
    let status = wait_settled(&base, slow, &s3("c"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 stored"), "{status}");

    // 4b. A job that fails (its process killed, as the kernel's OOM killer would): it and
    // what depends on it show as failed, and a resubmission completes the pipeline.
    let out = ok(idrex(&base, &["pipeline", "run", slow, "--store", &s3("e"), "--executor", "slurm", "--log-dir", "logs-e"]));
    assert_eq!(submitted(&out).len(), 28, "{out}");
    let start = Instant::now();
    while !ok(idrex(&base, &["pipeline", "status", slow, "--store", &s3("e")]))
        .lines()
        .any(|l| l.contains("demonstrator") && l.contains("running"))
    {
        assert!(start.elapsed() < limit, "the demonstrator job never ran");
        std::thread::sleep(Duration::from_millis(200));
    }
    wait_for_stage_process(limit);
    assert!(Command::new("pkill").args(["-KILL", "-f", STAGE_PROCESS]).status().unwrap().success(), "no stage process to kill");
    let status = wait_settled(&base, slow, &s3("e"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 failed"), "{status}");
    let out = ok(idrex(&base, &["pipeline", "run", slow, "--store", &s3("e"), "--executor", "slurm", "--log-dir", "logs-e"]));
    assert_eq!(submitted(&out).len(), 28, "{out}");
    let status = wait_settled(&base, slow, &s3("e"), limit);
    assert!(status.lines().last().unwrap().ends_with("28 stored"), "{status}");
    assert!(ok(idrex(&base, &["verify", "--store", &s3("e")])).contains("28 artifacts, 0 corrupt"));
    println!("slurm faults: a cancelled job (c) and a killed job (e) each failed their dependents, and a resubmission completed 28 of 28");

    // 4d. A locked test set (`role: test`) as Slurm jobs: each evaluation's job writes the test
    // set's mark into its manifest, as a local run does, and its seeds are then locked.
    let smoke_bc = std::fs::read_to_string(repo("pipelines/smoke.yaml"))
        .unwrap()
        .replace("methods: [bc, drex, idrex-interpolation, idrex-action-noise, idrex-multi-bc]\n", "methods: [bc]\n");
    assert!(smoke_bc.contains("methods: [bc]\n"), "the smoke pipeline's methods changed");
    let (locked, other) = (base.join("locked.yaml"), base.join("other.yaml"));
    std::fs::write(&locked, format!("{smoke_bc}name: locked\nrole: test\n")).unwrap();
    // Another configuration: a BC trained for fewer iterations.
    let other_bc = smoke_bc.replacen("bc:\n  hidden: [64, 64]\n  iterations: 300\n", "bc:\n  hidden: [64, 64]\n  iterations: 200\n", 1);
    assert_ne!(other_bc, smoke_bc, "the smoke pipeline's BC changed");
    std::fs::write(&other, format!("{other_bc}name: other\n")).unwrap();
    let (locked, other) = (locked.to_str().unwrap(), other.to_str().unwrap());
    let out = ok(idrex(&base, &["pipeline", "run", locked, "--store", &s3("t"), "--executor", "slurm", "--log-dir", "logs-t"]));
    assert_eq!(submitted(&out).len(), 4, "{out}");
    let status = wait_settled(&base, locked, &s3("t"), limit);
    assert!(status.lines().last().unwrap().ends_with("4 stored"), "{status}");
    let marks: Vec<_> = s3_store("t").manifests().unwrap().into_iter().filter(|m| m.kind == "eval").map(|m| m.test_set).collect();
    assert_eq!(marks, [Some(TestSetMark::Test { study: "locked".into() })]);
    let refused = idrex(&base, &["pipeline", "run", other, "--store", &s3("t"), "--executor", "slurm", "--log-dir", "logs-t"]);
    assert!(!refused.status.success() && text(&refused).contains("belongs to the locked test set `locked`"), "{}", text(&refused));
    println!("slurm test set: a role: test file's evaluation job wrote the mark; another configuration on its seeds was refused");

    // 4c. A replicated study (replicates: 3) as Slurm jobs into the bucket, with each new
    // replicate's first node submitted twice more by hand while its pipeline job waits or
    // runs: the duplicates are harmless, and every digest equals a local run's.
    let replicated = base.join("replicated.yaml");
    std::fs::write(&replicated, std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap() + "replicates: 3\n").unwrap();
    let replicated = replicated.to_str().unwrap();
    ok(idrex(&base, &["pipeline", "run", replicated, "--store", "local3", "--jobs", "2"]));
    let local3 = digests(&Store::at(base.join("local3")));
    // Replicate 0 keeps the file's seeds: its nodes but the evaluations (which record their
    // replicate) are the smoke run's, stored already.
    let shared = local3.keys().filter(|k| reference.contains_key(*k)).count();
    let n3 = local3.len();
    assert!(n3 >= 84 && shared > 0, "{n3} nodes, {shared} shared with the smoke run");
    let out = ok(idrex(&base, &["pipeline", "run", replicated, "--store", &s3("a"), "--executor", "slurm", "--log-dir", "logs-r"]));
    assert_eq!(submitted(&out).len(), n3 - shared, "what the bucket lacks is submitted:\n{out}");
    let roots: Vec<String> = out
        .lines()
        .filter(|l| l.starts_with("submitted ") && l.split_whitespace().nth(1).is_some_and(|n| n.ends_with("demonstrator")))
        .map(|l| l.split_whitespace().nth(2).unwrap().to_string())
        .collect();
    assert!(!roots.is_empty(), "{out}");
    let remote = idrex::store::s3::Remote::connect(BUCKET, "a").unwrap();
    let defs = remote.submitted().unwrap();
    let store_url = s3("a");
    let mut duplicates = Vec::new();
    for short in &roots {
        let key = defs.iter().find(|k| k.starts_with(short.as_str())).expect("the root's definition");
        for n in 0..2 {
            let wrap = format!("--wrap=exec {} stage run {key} --store {store_url}", env!("CARGO_BIN_EXE_idrex"));
            let log = base.join(format!("logs-r/duplicate-{short}-{n}-%j.out"));
            let o = Command::new("sbatch")
                .args(["--parsable", "--cpus-per-task=1", &format!("--output={}", log.display()), &wrap])
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", text(&o));
            duplicates.push(String::from_utf8_lossy(&o.stdout).trim().to_string());
        }
    }
    // And once more at once from "another machine" (a cache of its own), outside Slurm:
    // it races the node's own job, which starts a scheduler cycle later.
    let racers: Vec<_> = roots
        .iter()
        .map(|short| {
            let key = defs.iter().find(|k| k.starts_with(short.as_str())).unwrap();
            Command::new(env!("CARGO_BIN_EXE_idrex"))
                .args(["stage", "run", key, "--store", &store_url])
                .env("IDREX_S3_CACHE", base.join("cache-racer"))
                .current_dir(&base)
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    let raced: Vec<String> = racers.into_iter().map(|c| ok(c.wait_with_output().unwrap())).collect();
    let status = wait_settled(&base, replicated, &s3("a"), Duration::from_secs(600));
    assert!(status.lines().last().unwrap().ends_with(&format!("{n3} stored")), "{status}");
    let start = Instant::now();
    while Command::new("squeue")
        .args(["--noheader", "--jobs", &duplicates.join(",")])
        .output()
        .map(|o| !o.stdout.is_empty())
        .unwrap_or(false)
    {
        assert!(start.elapsed() < limit, "duplicate jobs still queued");
        std::thread::sleep(Duration::from_millis(500));
    }
    let dup_logs: Vec<String> = std::fs::read_dir(base.join("logs-r"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("duplicate-"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
        .collect();
    assert_eq!(dup_logs.len(), 2 * roots.len());
    let dup_logs: Vec<String> = dup_logs.into_iter().chain(raced).collect();
    for l in &dup_logs {
        assert!(l.contains("already stored") || l.contains("computed in"), "a duplicate job did not finish cleanly:\n{l}");
    }
    let in_bucket = digests(&s3_store("a"));
    for (key, files) in &local3 {
        assert_eq!(in_bucket.get(key), Some(files), "a replicated study through Slurm into S3 made other bytes than a local run for {key}");
    }
    let total = in_bucket.len();
    assert_eq!(total, 28 + n3 - shared);
    assert!(ok(idrex(&base, &["verify", "--store", &s3("a")])).contains(&format!("{total} artifacts, 0 corrupt")));
    let computed = dup_logs.iter().filter(|l| l.contains("computed in")).count();
    println!(
        "slurm: replicates: 3 as {} jobs plus {} duplicates of their roots (2 each as Slurm jobs, 1 each at once outside Slurm; {computed} of them computed the node too) = a local run's {n3} digests",
        n3 - shared,
        dup_logs.len()
    );

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
        let started = Instant::now();
        let o = status(&vars);
        assert!(started.elapsed() < Duration::from_secs(10), "took {:?} to give up", started.elapsed());
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(err.contains(want), "{err}");
        assert!(!err.contains(SECRET) && !err.contains("wrong-secret"), "a secret in the message: {err}");
    }

    // A run with a wrong secret: one line, and nothing written to its prefix.
    let o = idrex_with(&base, &["pipeline", "run", smoke, "--store", &s3("w")], &[("AWS_SECRET_ACCESS_KEY", "wrong-secret".into())]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success() && err.trim().lines().count() == 1 && err.contains("refused the credentials"), "{err}");
    assert!(idrex::store::s3::Remote::connect(BUCKET, "w").unwrap().list("").unwrap().is_empty(), "a refused run wrote to its prefix");

    s3_load(&base, smoke, &reference);
    s3_faults(&base, smoke, &reference);
    s3_refusals(&base);
    s3_server_killed(&base, &svc, smoke, &reference);
    s3_outage_outlasts_the_retries(&base, &svc, smoke, &reference);

    // gc on the bucket keeps what a pipeline names and removes the rest; what stays is intact.
    let gc = ok(idrex(&base, &["gc", smoke, replicated, "--store", &s3("a"), "--yes"]));
    assert!(gc.contains("0 artifacts removed"), "{gc}");
    let one_seed = base.join("one-seed.yaml");
    std::fs::write(&one_seed, std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap().replace("seeds: [0, 1]", "seeds: [0]"))
        .unwrap();
    let gc = ok(idrex(&base, &["gc", one_seed.to_str().unwrap(), "--store", &s3("a"), "--yes"]));
    let removed: usize = gc.lines().last().unwrap().split_whitespace().next().unwrap().parse().unwrap();
    assert!(removed > 0 && removed < total, "{gc}");
    let verified = ok(idrex(&base, &["verify", "--store", &s3("a")]));
    assert!(verified.contains(&format!("{} artifacts, 0 corrupt", total - removed)), "{verified}");
    true
}

type Digests = BTreeMap<String, Vec<(String, String)>>;

/// Requests dropped, answered 503, stalled past the timeout, and cut off in either direction
/// (a proxy in front of the server): the run rides them out with logged retries and stores
/// a local run's bytes; verify and a report, reading every blob back through the same
/// faults from an empty cache, find them intact.
fn s3_faults(base: &Path, smoke: &str, reference: &Digests) {
    let proxy = s3_proxy::Proxy::start(8333, 0.2, 4, Duration::from_secs(8), 7);
    let via = |cache: &str| {
        vec![
            ("AWS_ENDPOINT_URL", format!("http://127.0.0.1:{}", proxy.port)),
            ("IDREX_S3_TIMEOUT", "3".to_string()),
            ("IDREX_S3_CACHE", base.join(cache).display().to_string()),
        ]
    };
    let started = Instant::now();
    let run = idrex_with(base, &["pipeline", "run", smoke, "--store", &s3("f"), "--jobs", "2"], &via("cache-f"));
    let run_retries = retries_logged(&run);
    let out = ok(run);
    assert!(out.contains(" 28 computed") && out.contains("requests retried"), "{out}");
    assert_eq!(&digests(&s3_store("f")), reference, "a run through faults stored other bytes");
    let verify = idrex_with(base, &["verify", "--store", &s3("f")], &via("cache-f-verify"));
    let verify_retries = retries_logged(&verify);
    assert!(ok(verify).contains("28 artifacts, 0 corrupt"));
    let report = idrex_with(base, &["report", "--store", &s3("f"), "--out", "report-f"], &via("cache-f-report"));
    let report_retries = retries_logged(&report);
    assert!(ok(report).contains("| Hopper-v5 | smoke |"));
    let injected = proxy.injected();
    for (fault, n) in &injected {
        assert!(*n > 0, "no {fault:?} fault was injected: {injected:?}");
    }
    println!(
        "s3 faults: {} requests, {} faults injected {injected:?}; retries logged: run {run_retries}, verify {verify_retries}, report {report_retries}; {:.0} s; digests equal to a local run's",
        proxy.requests(),
        proxy.total_injected(),
        started.elapsed().as_secs_f64()
    );
    assert!(run_retries + verify_retries + report_retries > 0);
}

/// S3's refusals, reached on purpose: an upload of a key another run published first with
/// other bytes leaves theirs standing and sets ours aside (quarantined in the cache, never
/// read), and a manifest whose output path climbs out of the cache is refused, writing
/// nothing outside it.
fn s3_refusals(base: &Path) {
    let remote = idrex::store::s3::Remote::connect(BUCKET, "q").unwrap();
    let key_of = |seed: u64| idrex::store::key("refusal", 1, &serde_json::json!({}), seed, &BTreeMap::new());
    let key = key_of(0);
    let manifest = |key: &str| idrex::store::Manifest {
        key: key.to_string(),
        kind: "refusal".into(),
        version: 1,
        node: "refusal".into(),
        params: serde_json::json!({}),
        metrics: serde_json::json!({}),
        idrex_version: "test".into(),
        ..Default::default()
    };
    let publish = |store: &Store, bytes: &str| {
        let _lock = store.lock(&key).unwrap();
        let staging = store.stage(&key).unwrap();
        std::fs::write(staging.dir.join("out.txt"), bytes).unwrap();
        store.publish(staging, manifest(&key), false).unwrap()
    };
    // Theirs: published by another machine first.
    let elsewhere = Store::open(base.join("elsewhere")).unwrap();
    let theirs = publish(&elsewhere, "theirs");
    assert_eq!(remote.push(&elsewhere.dir(&key), &theirs, false).unwrap(), idrex::store::s3::Created::Yes);
    // Ours: the same key with other bytes, through the S3 store.
    let ours = s3_store("q");
    publish(&ours, "ours");
    assert!(!ours.dir(&key).exists(), "our copy is set aside");
    let aside = std::fs::read_dir(ours.root().join(".corrupt"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&key))
        .count();
    assert_eq!(aside, 1, "our copy is quarantined");
    assert_eq!(remote.manifest(&key).unwrap().unwrap().outputs, theirs.outputs, "theirs stands");
    assert_eq!(std::fs::read_to_string(ours.input_dir(&key).unwrap().join("out.txt")).unwrap(), "theirs");

    // A manifest whose output path climbs out of the cache, naming a blob that exists.
    let escape = key_of(1);
    let mut m = manifest(&escape);
    m.outputs = theirs.outputs.clone();
    m.outputs[0].path = "../../escaped.txt".into();
    remote.put(&format!("artifacts/{escape}/manifest.json"), serde_json::to_vec(&m).unwrap()).unwrap();
    let err = ours.input_dir(&escape).unwrap_err().to_string();
    assert!(err.contains("'../../escaped.txt' is not a plain relative path"), "{err}");
    let outside = ours.dir(&escape).join("../../escaped.txt");
    assert!(!outside.exists() && !ours.root().join("escaped.txt").exists(), "nothing written outside the cache");
    assert!(ours.lookup(&escape).unwrap().is_none(), "a run recomputes it");
    println!("s3 refusals: same key with other bytes kept theirs and quarantined ours; a manifest's path escape was refused");
}

/// The S3 server killed (kill -9) while a run publishes, and restarted 3 s later. The run
/// either rides it out on its retries or ends with one clear error; either way nothing
/// half-written is published (verify is clean), and a re-run completes with a local run's
/// bytes.
fn s3_server_killed(base: &Path, svc: &Path, smoke: &str, reference: &Digests) {
    let started = Instant::now();
    let (mut child, remote) = run_until_published(base, smoke, "k", 8);
    let published_before = remote.keys().unwrap().len();
    services(svc, "s3-stop");
    std::thread::sleep(Duration::from_secs(3));
    services(svc, "s3-start");
    let status = child.wait().unwrap();
    let err = std::fs::read_to_string(base.join("run-k.err")).unwrap();
    let retries = err.lines().filter(|l| l.contains("; retry ")).count();
    let outcome = if status.success() {
        assert_eq!(&digests(&s3_store("k")), reference, "a run through a server restart stored other bytes");
        "rode it out"
    } else {
        unreachable_stages(&err);
        "failed clearly"
    };
    verify_then_rerun(base, smoke, "k", reference);
    println!(
        "s3 killed: the server was killed after {published_before} of 28 artifacts and back 3 s later; the run {outcome} with {retries} retries logged; verify clean; {:.0} s",
        started.elapsed().as_secs_f64()
    );
}

/// Load on a bucket: eight runs at once from two machines' caches (four runs each: the
/// smoke file and its one-seed subset in turn), with verify and gc called beside them. Every
/// run ends, nothing is corrupt, gc removes nothing a pipeline names, and the bucket holds a
/// local run's bytes.
fn s3_load(base: &Path, smoke: &str, reference: &Digests) {
    let one_seed = base.join("load-one-seed.yaml");
    std::fs::write(&one_seed, std::fs::read_to_string(smoke).unwrap().replace("seeds: [0, 1]", "seeds: [0]")).unwrap();
    let one_seed_s = one_seed.to_str().unwrap().to_string();
    let dir = base.join("load");
    std::fs::create_dir_all(&dir).unwrap();
    let mut beside = 0;
    let mut last = Instant::now();
    let started = Instant::now();
    let outs = util::runs_at_once(
        &dir,
        &s3("l"),
        &[PathBuf::from(smoke), one_seed],
        8,
        &|i| vec![("IDREX_S3_CACHE".into(), base.join(format!("cache-l{}", i % 2)).display().to_string())],
        Duration::from_secs(900),
        &mut || {
            if last.elapsed() < Duration::from_secs(2) {
                return;
            }
            let v = ok(idrex(base, &["verify", "--store", &s3("l")]));
            assert!(v.contains(" 0 corrupt"), "{v}");
            let g = ok(idrex(base, &["gc", smoke, &one_seed_s, "--store", &s3("l"), "--yes"]));
            assert!(g.contains("0 artifacts removed"), "{g}");
            beside += 1;
            last = Instant::now();
        },
    );
    let computed: usize = outs.iter().map(|o| util::computed(o)).sum();
    let stored = digests(&s3_store("l"));
    let nodes = stored.len();
    // The two files share every node but the iD-REX ones, which rank all the seeds' runs.
    assert!(
        nodes > 28 && (nodes..=2 * nodes).contains(&computed),
        "two machines compute each of {nodes} nodes at most once each: {computed}"
    );
    for (key, files) in reference {
        assert_eq!(stored.get(key), Some(files), "eight runs at once stored other bytes than a local run for {key}");
    }
    assert!(ok(idrex(base, &["verify", "--store", &s3("l")])).contains(&format!("{nodes} artifacts, 0 corrupt")));
    println!(
        "load (s3): 8 runs from 2 caches, {computed} computations of {nodes} nodes, verify and gc beside them {} times (clean, nothing named removed); {:.0} s",
        beside,
        started.elapsed().as_secs_f64()
    );
}

/// The S3 server down for longer than the retries last: the run ends with one line per
/// stage it could not finish, each saying the server cannot be reached; what was published is
/// intact (verify is clean), and once the server is back a re-run completes with a local run's
/// bytes.
fn s3_outage_outlasts_the_retries(base: &Path, svc: &Path, smoke: &str, reference: &Digests) {
    let started = Instant::now();
    let (mut child, _) = run_until_published(base, smoke, "o", 4);
    services(svc, "s3-stop");
    let down = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(down.elapsed() < Duration::from_secs(600), "the run still waits 600 s into an outage");
        std::thread::sleep(Duration::from_millis(200));
    };
    let gave_up = down.elapsed();
    services(svc, "s3-start");
    let err = std::fs::read_to_string(base.join("run-o.err")).unwrap();
    assert!(!status.success(), "the run passed with the server down:\n{err}");
    let failed = unreachable_stages(&err);
    let retries = err.lines().filter(|l| l.contains("; retry ")).count();
    verify_then_rerun(base, smoke, "o", reference);
    println!(
        "s3 outage: the server stopped after 4 artifacts; the run gave up {:.0} s later with {} stages failed, one line each ({retries} retries logged); verify clean; the re-run completed; {:.0} s",
        gave_up.as_secs_f64(),
        failed.len(),
        started.elapsed().as_secs_f64()
    );
}

/// Starts the smoke pipeline into prefix `p` (a cache of its own; output in `run-<p>.out` and
/// `.err`) and returns once `n` artifacts are published, with the bucket's handle.
fn run_until_published(base: &Path, smoke: &str, p: &str, n: usize) -> (std::process::Child, idrex::store::s3::Remote) {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_idrex"))
        .args(["pipeline", "run", smoke, "--store", &s3(p), "--jobs", "2"])
        .env("IDREX_S3_CACHE", base.join(format!("cache-{p}")))
        .current_dir(base)
        .stdout(std::fs::File::create(base.join(format!("run-{p}.out"))).unwrap())
        .stderr(std::fs::File::create(base.join(format!("run-{p}.err"))).unwrap())
        .spawn()
        .unwrap();
    let remote = idrex::store::s3::Remote::connect(BUCKET, p).unwrap();
    while remote.keys().unwrap().len() < n {
        assert!(child.try_wait().unwrap().is_none(), "the run ended before {n} artifacts were published");
        assert!(started.elapsed() < Duration::from_secs(240), "no {n} artifacts published within 240 s");
        std::thread::sleep(Duration::from_millis(100));
    }
    (child, remote)
}

/// The `failed:` lines of a run's stderr: at least one, each saying the server cannot be reached.
fn unreachable_stages(err: &str) -> Vec<&str> {
    let failed: Vec<&str> = err.lines().filter(|l| l.starts_with("failed: ")).collect();
    assert!(!failed.is_empty() && failed.iter().all(|l| l.contains("cannot reach")), "not one clear line per failed stage:\n{err}");
    failed
}

/// After a fault on prefix `p`: verify is clean, and a re-run (same cache) completes with a
/// local run's bytes.
fn verify_then_rerun(base: &Path, smoke: &str, p: &str, reference: &Digests) {
    let verified = ok(idrex(base, &["verify", "--store", &s3(p)]));
    assert!(verified.contains(" 0 corrupt"), "{verified}");
    let cache = base.join(format!("cache-{p}")).display().to_string();
    let rerun = ok(idrex_with(base, &["pipeline", "run", smoke, "--store", &s3(p), "--jobs", "2"], &[("IDREX_S3_CACHE", cache)]));
    assert!(rerun.contains("0 failed"), "{rerun}");
    assert_eq!(&digests(&s3_store(p)), reference, "after the fault on {p} and a re-run, other bytes than a local run's");
}
