//! `idrex exp show` and `exp diff` on a real store: two studies of the smoke pipeline (BC and
//! D-REX, two replicates on the same seeds) that differ in PPO's step budget only. The CSV
//! and JSON are read back with Python's csv and json modules.

use crate::util::{TempDir, idrex, python_with_input, repo, stderr, stdout};

fn py(code: &str, input: &str) -> String {
    let out = python_with_input(&["-c", code], input);
    assert!(out.status.success(), "python failed: {}\non:\n{input}", stderr(&out));
    stdout(&out)
}

#[test]
fn exp_show_and_diff_list_and_compare_the_stores_studies() {
    let dir = TempDir::new("exp");
    let store = dir.join("store");
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    for (name, steps) in [("base", 4096), ("longer", 6144)] {
        let text = smoke
            .replace("seeds: [0, 1]", &format!("name: {name}\nreplicates: 2\nseeds: [0, 1]"))
            .replace("methods: [bc, drex, idrex-interpolation, idrex-action-noise, idrex-multi-bc]", "methods: [bc, drex]")
            .replace("  total_steps: 4096", &format!("  total_steps: {steps}"));
        let file = dir.join(&format!("{name}.yaml"));
        std::fs::write(&file, text).unwrap();
        let rec = dir.join(&format!("{name}.rrd"));
        let out =
            idrex(&["pipeline", "run", file.to_str().unwrap(), "--store", store.to_str().unwrap(), "--recording", rec.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let s = store.to_str().unwrap();
    let exp = |args: &[&str]| {
        let mut all = vec!["exp"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--store", s]);
        idrex(&all)
    };

    let csv = exp(&["show", "--csv"]);
    assert!(csv.status.success(), "{}", stderr(&csv));
    let check = r#"
import csv, sys
rows = list(csv.DictReader(sys.stdin))
assert [r["study"] for r in rows] == ["base", "longer"], rows
assert [r["ppo.ppo.total_steps"] for r in rows] == ["4096", "6144"], rows
assert "ppo.ppo.lr" not in rows[0], "a parameter both share is not listed"
for r in rows:
    assert r["replicates"] == "2" and r["runs"] == "6" and r["methods"] == "bc drex", r
    lo, mid, hi = (float(r["Hopper-v5 drex" + k]) for k in ("_ci_low", "", "_ci_high"))
    assert lo <= mid <= hi, r
print("ok")
"#;
    assert_eq!(py(check, &stdout(&csv)).trim(), "ok");

    let json = exp(&["show", "--json", "--only-changed", "--all-params"]);
    assert!(json.status.success(), "{}", stderr(&json));
    let check = r#"
import json, sys
rows = json.load(sys.stdin)
assert len(rows) == 2 and list(rows[0])[0] == "study", rows
assert "replicates" not in rows[0] and "ppo.ppo.total_steps" in rows[0] and "ppo.ppo.lr" not in rows[0], list(rows[0])
print("ok")
"#;
    assert_eq!(py(check, &stdout(&json)).trim(), "ok");
    let all = exp(&["show", "--all-params", "--columns", "ppo.ppo.lr"]);
    assert_eq!(stdout(&all).lines().nth(1).map(|l| l.split_whitespace().collect::<Vec<_>>()), Some(vec!["base", "0.0003"]));

    let diff = exp(&["diff", "longer", "base"]);
    assert!(diff.status.success(), "{}", stderr(&diff));
    let text = stdout(&diff);
    assert!(text.contains("Parameters that differ (1)") && text.contains("ppo.ppo.total_steps  6144    4096"), "{text}");
    let csv = exp(&["diff", "longer", "base", "--csv", "--protocol", "final", "--protocol", "best-by-ground-truth"]);
    let check = r#"
import csv, sys
rows = list(csv.DictReader(sys.stdin))
assert {(r["method"], r["protocol"]) for r in rows} == {(m, p) for m in ("bc", "drex") for p in ("final", "best-by-ground-truth")}, rows
for r in rows:
    # Replicate r of both studies ran on the same seeds: every replicate pairs.
    # (a tie, as where both pick the same early checkpoint, leaves the paired count)
    wins, untied = map(int, r["paired_wins"].split(" of "))
    assert r["paired"] == "2" and wins <= untied <= 2, r
    assert float(r["rliable_p_ci_low"]) <= float(r["rliable_p"]) <= float(r["rliable_p_ci_high"]), r
    assert abs(float(r["a_mean"]) - float(r["b_mean"]) - float(r["a_minus_b"])) < 1e-9, r
bc = [r for r in rows if r["method"] == "bc"][0]
assert float(bc["a_minus_b"]) == 0.0, "BC does not depend on PPO's budget"
print("ok")
"#;
    assert_eq!(py(check, &stdout(&csv)).trim(), "ok");

    for (args, says) in [
        (vec!["diff", "base", "nope"], "no study `nope`"),
        (vec!["show", "--method", "nope"], "--method nope: no study"),
        (vec!["show", "--protocol", "best"], "`best` is no protocol"),
    ] {
        let out = exp(&args);
        assert!(!out.status.success() && stderr(&out).contains(says), "{args:?}: {}", stderr(&out));
    }
    let none = exp(&["show", "--env", "Walker2d-v5"]);
    assert_eq!(stdout(&none).lines().count(), 1, "a header and no rows: {}", stdout(&none));

    // Every other command with a table emits it as CSV and JSON too, on the same store.
    let base = dir.join("base.yaml");
    let b = base.to_str().unwrap();
    let check = r#"
import csv, json, sys
kind, text = sys.argv[1], sys.stdin.read()
rows = json.loads(text) if kind == "json" else list(csv.DictReader(text.splitlines()))
print(len(rows), sorted(set(r[sys.argv[2]] for r in rows)))
"#;
    let table = |args: &[&str], kind: &str, column: &str| {
        let out = idrex(args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        let read = python_with_input(&["-c", check, kind, column], &out.stdout);
        assert!(read.status.success(), "{}", stderr(&read));
        String::from_utf8(read.stdout).unwrap().trim().to_string()
    };
    let stored = std::fs::read_dir(&store).unwrap().flatten().filter(|e| !e.file_name().to_string_lossy().starts_with('.')).count();
    assert_eq!(table(&["verify", "--store", s, "--csv"], "csv", "state"), format!("{stored} ['intact']"));
    let nodes = table(&["pipeline", "status", b, "--store", s, "--json"], "json", "state");
    assert!(nodes.ends_with(" ['stored']"), "{nodes}");
    assert_eq!(
        table(&["pipeline", "plan", b, "--store", s, "--csv"], "csv", "stored"),
        format!("{} ['true']", nodes.split(' ').next().unwrap())
    );
    // The other study's PPO runs and evaluations (BC's too: an evaluation names its study)
    // are not the base file's; BC and the rewards are shared: 2 replicates x (2 PPO + 3 evals).
    assert_eq!(table(&["gc", b, "--store", s, "--json"], "json", "kind"), "10 ['eval', 'ppo']");
    let mcap = std::fs::read_dir(&store).unwrap().flatten().map(|e| e.path().join("rollouts.mcap")).find(|p| p.exists()).unwrap();
    let episodes = table(&["logs", "list", mcap.to_str().unwrap(), "--csv"], "csv", "end");
    assert!(episodes.starts_with(|c: char| c.is_ascii_digit()) && !episodes.starts_with("0 "), "{episodes}");
}
