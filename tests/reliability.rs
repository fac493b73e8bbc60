//! What idrex refuses to publish or even start: diverging training fails its stage with one
//! clear message, and bad demonstration files are refused when the pipeline loads, before
//! any stage runs, with one line naming the file and the problem.
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::{TempDir, idrex, python, repo, stderr};

/// The smoke pipeline with one section replaced.
fn smoke_with(dir: &Path, section: &str, body: &str) -> PathBuf {
    let text = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let mut out = String::new();
    let mut skipping = false;
    for line in text.lines() {
        if line.starts_with(&format!("{section}:")) {
            skipping = true;
            out.push_str(&format!("{section}:\n{body}"));
            continue;
        }
        if skipping && line.starts_with("  ") {
            continue;
        }
        skipping = false;
        out.push_str(line);
        out.push('\n');
    }
    let path = dir.join(format!("{section}.yaml"));
    std::fs::write(&path, out).unwrap();
    path
}

fn kinds_in(store: &Path) -> Vec<String> {
    std::fs::read_dir(store)
        .unwrap()
        .flatten()
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| {
            let m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(e.path().join("manifest.json")).unwrap()).unwrap();
            m["kind"].as_str().unwrap().to_string()
        })
        .collect()
}

#[test]
fn diverging_training_fails_its_stage_and_publishes_nothing() {
    let dir = TempDir::new("diverge");
    let cases = [
        ("bc", "  hidden: [64, 64]\n  iterations: 300\n  lr: 1000000.0\n", "bc", "BC diverged at iteration"),
        (
            "trex",
            "  hidden: [32, 32]\n  models: 2\n  pairs_per_model: 200\n  iterations: 100\n  window: 20\n  lr: 1000.0\n",
            "trex",
            "T-REX model 0 diverged at iteration",
        ),
        (
            "ppo",
            "  total_steps: 4096\n  num_envs: 2\n  num_steps: 512\n  update_epochs: 2\n  lr: 100.0\n",
            "demonstrator",
            "PPO diverged at update",
        ),
    ];
    for (section, body, kind, message) in cases {
        let file = smoke_with(dir.path(), section, body);
        let store = dir.join(&format!("store-{section}"));
        // With the shipped clone filter, multi-BC's judge trains beside D-REX's reward.
        let out = idrex(&[
            "pipeline",
            "run",
            file.to_str().unwrap(),
            "--store",
            store.to_str().unwrap(),
            "--recording",
            dir.join("r.rrd").to_str().unwrap(),
            "-S",
            "idrex.multi_bc_filter=held-out-reward",
        ]);
        assert!(!out.status.success());
        let err = stderr(&out);
        assert!(err.contains(message) && err.contains(&format!("lower {section}.lr")), "{section}: {err}");
        assert!(err.contains("stages after it skipped"), "{err}");
        // One line per failure: T-REX's case fails two stages, D-REX's reward and multi-BC's
        // judge (a diverging judge is refused like any reward: it trains alike on the same
        // sets), each other case one.
        let mut failed: Vec<&str> =
            err.lines().filter_map(|l| l.strip_prefix("failed: ")).map(|l| l.split_whitespace().next().unwrap_or_default()).collect();
        failed.sort();
        match section {
            "trex" => assert_eq!(failed, ["drex/trex", "idrex-multi-bc/k1/judge"], "{err}"),
            _ => assert_eq!(failed.len(), 1, "one line per failure: {err}"),
        }
        assert!(!kinds_in(&store).iter().any(|k| k == kind), "nothing of the diverged {kind} stage is published");
        let v = idrex(&["verify", "--store", store.to_str().unwrap()]);
        assert!(v.status.success());
    }
}

/// Writes an NPZ with the given arrays through numpy (the Python the tests compare with).
fn npz(path: &Path, code: &str) {
    let script = format!("import numpy as np, sys\n{code}\n");
    let out = Command::new(python()).arg("-c").arg(script).arg(path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn bad_demonstrations_are_refused_before_anything_runs() {
    let dir = TempDir::new("baddata");
    let ok = "obs = np.zeros((10, 11)); act = np.zeros((10, 3), np.float32); rew = np.ones(10); lens = np.array([4, 6])";
    let save = "np.savez(sys.argv[1], obs=obs, actions=act, rewards=rew, episode_lengths=lens)";
    let cases: Vec<(&str, String, &str)> = vec![
        ("nan", format!("{ok}; obs[3, 2] = np.nan; {save}"), "obs holds a non-finite value"),
        ("inf", format!("{ok}; rew[1] = np.inf; {save}"), "rewards holds a non-finite value"),
        ("fractional", format!("{ok}; lens = np.array([4.5, 5.5]); {save}"), "episode_lengths[0] is 4.5"),
        ("zero", format!("{ok}; lens = np.array([0, 10]); {save}"), "episode_lengths[0] is 0"),
        ("negative", format!("{ok}; lens = np.array([-2, 12]); {save}"), "episode_lengths[0] is -2"),
        (
            "empty",
            format!("{ok}; obs = np.zeros((0, 11)); act = np.zeros((0, 3)); rew = np.zeros(0); lens = np.zeros(0, np.int64); {save}"),
            "holds no episodes",
        ),
        ("missing", format!("{ok}; np.savez(sys.argv[1], obs=obs, actions=act, rewards=rew)"), "has no 'episode_lengths' array"),
        (
            "header",
            format!(
                "{ok}; {save}\nimport zipfile\nzf = zipfile.ZipFile(sys.argv[1], 'a'); zf.writestr('bad.npy', b'x')\nzipfile.ZipFile(sys.argv[1] + '.2', 'w').writestr('obs.npy', b'\\x93NUMPY\\x01\\x00\\xff\\xff{{}}')\nimport shutil; shutil.move(sys.argv[1] + '.2', sys.argv[1])"
            ),
            "obs: malformed .npy header",
        ),
    ];
    for (name, code, expect) in cases {
        let data = dir.join(&format!("{name}.npz"));
        npz(&data, &code);
        let file = dir.join(&format!("{name}.yaml"));
        std::fs::write(&file, format!("version: 1\nenv: Hopper-v5\ndemos:\n  from: {name}.npz\n")).unwrap();
        let store = dir.join(&format!("store-{name}"));
        let out = idrex(&["pipeline", "run", file.to_str().unwrap(), "--store", store.to_str().unwrap()]);
        let err = stderr(&out);
        assert!(!out.status.success(), "{name}");
        assert!(err.contains(expect) && err.contains(&format!("{name}.npz")), "{name}: expected '{expect}' in: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{name}: one line: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!store.exists(), "{name}: nothing ran");
    }
}

#[test]
fn mcap_demonstrations_from_another_environment_or_corrupt_are_refused() {
    let dir = TempDir::new("badmcap");
    // A Walker2d rollout file: the same dimensions as HalfCheetah (17 and 6).
    let walker = dir.join("walker.yaml");
    std::fs::write(
        &walker,
        "version: 1\nenv: Walker2d-v5\nseeds: [0]\nmethods: [bc]\ndemonstrator:\n  steps: 2048\n  eval_every: 0\nbc:\n  iterations: 10\n  hidden: [8]\nppo:\n  total_steps: 2048\n  num_steps: 1024\neval:\n  episodes: 1\n",
    )
    .unwrap();
    let store = dir.join("walker-store");
    let out = idrex(&[
        "pipeline",
        "run",
        walker.to_str().unwrap(),
        "--store",
        store.to_str().unwrap(),
        "--recording",
        dir.join("w.rrd").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let demos = std::fs::read_dir(&store)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| std::fs::read_to_string(p.join("manifest.json")).is_ok_and(|m| m.contains("\"kind\": \"demos\"")))
        .unwrap()
        .join("rollouts.mcap");
    std::fs::copy(&demos, dir.join("walker.mcap")).unwrap();
    let cheetah = dir.join("cheetah.yaml");
    std::fs::write(&cheetah, "version: 1\nenv: HalfCheetah-v5\ndemos:\n  from: walker.mcap\n").unwrap();
    let out = idrex(&["pipeline", "run", cheetah.to_str().unwrap(), "--store", dir.join("s1").to_str().unwrap()]);
    let err = stderr(&out);
    assert!(
        !out.status.success()
            && err.contains("walker.mcap: was recorded in Walker2d-v5, but this pipeline's environment is HalfCheetah-v5"),
        "{err}"
    );
    assert!(!dir.join("s1").exists());

    // A flipped byte inside the compressed chunk.
    let mut bytes = std::fs::read(dir.join("walker.mcap")).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x55;
    std::fs::write(dir.join("flipped.mcap"), bytes).unwrap();
    std::fs::write(&walker, std::fs::read_to_string(&walker).unwrap() + "demos:\n  from: flipped.mcap\n").unwrap();
    let out = idrex(&["pipeline", "run", walker.to_str().unwrap(), "--store", dir.join("s2").to_str().unwrap()]);
    let err = stderr(&out);
    assert!(!out.status.success() && err.contains("flipped.mcap") && err.contains("corrupt"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!dir.join("s2").exists());
}

#[test]
fn a_full_disk_fails_stages_cleanly_and_keeps_the_previous_recording() {
    // A 1 MB tmpfs in a private mount namespace (root only; skipped elsewhere): the smoke
    // store needs about 3 MB, so stages fail for lack of space part-way.
    let probe = Command::new("unshare").args(["--mount", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"]).output();
    if !probe.is_ok_and(|o| o.status.success()) {
        crate::util::skip("reliability::a_full_disk_fails_stages_cleanly_and_keeps_the_previous_recording", "cannot mount a tmpfs here");
        return;
    }
    let dir = TempDir::new("diskfull");
    let disk = dir.join("disk");
    std::fs::create_dir_all(&disk).unwrap();
    let script = format!(
        r#"set -u
d='{disk}'
mount -t tmpfs -o size=1m tmpfs "$d"
printf OLD > "$d/r.rrd"
'{idrex}' pipeline run '{smoke}' --store "$d/store" --recording "$d/r.rrd" > "$d/../run.out" 2> "$d/../run.err"
echo "run exit $?"
echo "recording $(head -c 3 "$d/r.rrd")"
'{idrex}' verify --store "$d/store" > /dev/null 2>&1; echo "verify exit $?"
ls "$d/store/.tmp" | grep -v '\.lock$' | wc -l | sed 's/^/staging left /'
"#,
        disk = disk.display(),
        idrex = env!("CARGO_BIN_EXE_idrex"),
        smoke = repo("pipelines/smoke.yaml").display()
    );
    let out = Command::new("unshare").args(["--mount", "sh", "-c", &script]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let err = std::fs::read_to_string(dir.join("run.err")).unwrap_or_default();
    assert!(text.contains("run exit 1"), "the run fails: {text}\n{err}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(err.contains("No space left on device"), "and says why: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(text.contains("recording OLD"), "the previous recording is intact: {text}");
    assert!(text.contains("verify exit 0"), "nothing partial was published: {text}");
    assert!(text.contains("staging left 0"), "failed stages left no staging behind: {text}");
}

/// Load on a local store: eight pipeline runs at once (four of the smoke file, four of its
/// one-seed subset), with `verify` and `gc` called in a loop beside them. Every run ends
/// well within its limit, each node is computed once in all (the others wait on its lock
/// and reuse it), verify never finds a corrupt artifact, gc refuses while runs use the store
/// (and, when it gets to run, removes nothing a pipeline names), and the store ends intact.
#[test]
fn eight_runs_with_gc_and_verify_beside_them_share_a_local_store() {
    let dir = TempDir::new("load");
    let smoke = repo("pipelines/smoke.yaml");
    let one_seed = dir.join("one-seed.yaml");
    let text = std::fs::read_to_string(&smoke).unwrap();
    assert!(text.contains("seeds: [0, 1]"));
    std::fs::write(&one_seed, text.replace("seeds: [0, 1]", "seeds: [0]")).unwrap();
    let store = dir.join("store");
    let store_s = store.to_str().unwrap().to_string();
    let (mut verified, mut gc_refused, mut gc_ran) = (0, 0, 0);
    let started = std::time::Instant::now();
    let outs = crate::util::runs_at_once(
        dir.path(),
        &store_s,
        &[smoke.clone(), one_seed.clone()],
        8,
        &|_| vec![],
        std::time::Duration::from_secs(900),
        &mut || {
            if store.join(".locks").exists() {
                let v = idrex(&["verify", "--store", &store_s]);
                assert!(v.status.success() && crate::util::stdout(&v).contains(" 0 corrupt"), "{}{}", crate::util::stdout(&v), stderr(&v));
                verified += 1;
                let g = idrex(&["gc", smoke.to_str().unwrap(), one_seed.to_str().unwrap(), "--store", &store_s, "--yes"]);
                if g.status.success() {
                    assert!(crate::util::stdout(&g).contains("0 artifacts removed"), "{}", crate::util::stdout(&g));
                    gc_ran += 1;
                } else {
                    assert!(stderr(&g).contains("is using the store"), "{}", stderr(&g));
                    gc_refused += 1;
                }
            }
        },
    );
    let computed: usize = outs.iter().map(|o| crate::util::computed(o)).sum();
    // The two files share every node but the iD-REX ones, which rank all the seeds' runs.
    let nodes = std::fs::read_dir(&store).unwrap().flatten().filter(|e| !e.file_name().to_string_lossy().starts_with('.')).count();
    assert!(nodes > 28, "{nodes}");
    assert_eq!(computed, nodes, "each node computed once in all:\n{}", outs.join("\n"));
    let v = idrex(&["verify", "--store", &store_s]);
    assert!(crate::util::stdout(&v).contains(&format!("{nodes} artifacts, 0 corrupt")), "{}", crate::util::stdout(&v));
    assert!(verified > 0 && gc_refused > 0, "verify {verified}, gc refused {gc_refused}");
    println!(
        "load (local): 8 runs, {nodes} nodes computed once in all, verify beside them {verified} times (clean), gc refused {gc_refused} times and ran {gc_ran}; {:.0} s",
        started.elapsed().as_secs_f64()
    );
}
