//! Sweeps end to end: `-S field=a,b` and a file's `sweep:` block run the same variants (the
//! same keys), stages the variants share run once, and the report and `exp show` group by
//! variant (read back with Python's csv); the sweeps that replaced hand-copied pipeline files
//! give those files' keys.
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use idrex::pipeline::{Sweep, expand};

use crate::util::{TempDir, idrex, python, repo, stderr, stdout};

/// The smoke pipeline cut to BC and D-REX over two replicates, named `name`.
fn small(name: &str) -> String {
    std::fs::read_to_string(repo("pipelines/smoke.yaml"))
        .unwrap()
        .replace("seeds: [0, 1]", &format!("name: {name}\nreplicates: 2\nseeds: [0, 1]"))
        .replace("methods: [bc, drex, idrex-interpolation, idrex-action-noise, idrex-multi-bc]", "methods: [bc, drex]")
}

fn count(out: &str, what: &str) -> usize {
    let line = out.lines().find(|l| l.contains(" computed, ")).unwrap_or_else(|| panic!("no summary in {out}"));
    let at = line.find(what).unwrap_or_else(|| panic!("{what} not in {line}"));
    line[..at].rsplit(' ').find(|w| !w.is_empty()).unwrap().parse().unwrap()
}

#[test]
fn a_sweep_computes_shared_stages_once_and_the_report_compares_its_variants() {
    let dir = TempDir::new("sweep");
    let store = dir.join("store");
    let s = store.to_str().unwrap();
    let file = dir.join("s.yaml");
    std::fs::write(&file, small("s")).unwrap();
    let f = file.to_str().unwrap();
    let rec = dir.join("rec.rrd");
    let rec = rec.to_str().unwrap();
    let run = |extra: &[&str], f: &str| {
        let mut args = vec!["pipeline", "run", f, "--store", s, "--recording", rec];
        args.extend_from_slice(extra);
        let out = idrex(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        stdout(&out)
    };
    let out = run(&["-S", "reward.ceiling=0.75,none"], f);
    assert!(out.lines().next().unwrap().contains("2 variants (against `s[reward.ceiling=0.75]`)"), "{out}");
    // Per replicate: demonstrator, demos, BC, noise and T-REX once; PPO and evaluations twice.
    assert_eq!(count(&out, "computed"), 2 * (5 + 2 * 5), "{out}");
    assert!(dir.join("rec-s[reward.ceiling=none]-Hopper-v5.rrd").is_file(), "one recording per variant: {out}");
    // The same sweep written in the file is the same variants: nothing left to compute.
    let swept = dir.join("swept.yaml");
    std::fs::write(&swept, small("s") + "sweep:\n  grid:\n    reward.ceiling: [0.75, none]\n").unwrap();
    let again = run(&[], swept.to_str().unwrap());
    assert_eq!(count(&again, "computed"), 0, "{again}");
    // `pipeline plan` says what the variants share.
    let plan = stdout(&idrex(&["pipeline", "plan", swept.to_str().unwrap(), "--store", s]));
    assert!(
        plan.contains("2 variants x their stages, 30 distinct stages") && plan.contains("s[reward.ceiling=none]: 20 stages, 10 shared"),
        "{plan}"
    );

    let report = dir.join("report");
    let out = idrex(&["report", "--store", s, "--out", report.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("### Sweep `s`, Hopper-v5: final policy (baseline `s[reward.ceiling=0.75]`)"), "{md}");
    let check = r#"
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if r["protocol"] == "final"]
assert {(r["study"], r["method"]) for r in rows} == {(f"s[reward.ceiling={c}]", m) for c in ("0.75", "none") for m in ("bc", "drex")}, rows
for r in rows:
    assert r["sweep"] == "s" and r["baseline"] == "s[reward.ceiling=0.75]" and r["replicates"] == "2", r
    assert float(r["mean_ci_low"]) <= float(r["mean"]) <= float(r["mean_ci_high"]), r
    against = r["study"] != r["baseline"]
    assert (r["paired_replicates"] == "2") == against, r
    if against:
        assert 0 <= float(r["rliable_probability"]) <= 1, r
bc = [r for r in rows if r["method"] == "bc" and r["study"].endswith("none]")][0]
assert bc["paired_ties"] == "2", "the variants share BC: every replicate ties"
print("ok")
"#;
    let py = Command::new(python()).args(["-c", check, report.join("sweeps.csv").to_str().unwrap()]).output().unwrap();
    assert!(py.status.success() && stdout(&py).trim() == "ok", "{}{}", stdout(&py), stderr(&py));
    // The decision: D-REX's variant against the baseline's, Holm over a family of one; BC is
    // shared and left out, and two replicates cannot decide (the sign test's floor is 0.25).
    assert!(md.contains("### Sweeps' variants against their baseline, corrected (final policy)"), "{md}");
    let check = r#"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert {r["method"] for r in rows} == {"drex"} and "return" in {r["measure"] for r in rows}, rows
for r in rows:
    assert r["study"] == "s[reward.ceiling=none]" and r["baseline"] == "s[reward.ceiling=0.75]", r
    assert r["paired_replicates"] == "2" and r["family"] == "1" and r["decided"] == "no", r
    assert float(r["sign_test_p"]) >= 0.25 and float(r["holm_p"]) == float(r["sign_test_p"]), r
print("ok")
"#;
    let py = Command::new(python()).args(["-c", check, report.join("sweep_decisions.csv").to_str().unwrap()]).output().unwrap();
    assert!(py.status.success() && stdout(&py).trim() == "ok", "{}{}", stdout(&py), stderr(&py));
    let show = idrex(&["exp", "show", "--store", s, "--csv"]);
    let show = stdout(&show);
    assert!(
        show.starts_with("study,settings,baseline,") && show.contains("s[reward.ceiling=none],reward.ceiling=none,s[reward.ceiling=0.75],"),
        "{show}"
    );
}

#[test]
fn a_mistake_in_a_setting_names_it() {
    let dir = TempDir::new("sweep-errors");
    let file = dir.join("s.yaml");
    std::fs::write(&file, small("s")).unwrap();
    let f = file.to_str().unwrap();
    let err = |set: &str| stderr(&idrex(&["pipeline", "plan", f, "--store", dir.join("store").to_str().unwrap(), "-S", set]));
    let e = err("reward.ceilng=0.5");
    assert!(e.contains("s.yaml: -S reward.ceilng=0.5: unknown field `ceilng`"), "{e}");
    let e = err("reward.ceiling=2");
    assert!(e.contains("s.yaml: -S reward.ceiling=2: reward.ceiling is 2; give a quantile"), "{e}");
    assert!(err("reward.ceiling").contains("write FIELD=VALUE"));
    assert!(err("trex.models=2,2").contains("two variants are both `s[trex.models=2]`"));
}

/// Rows of `report/hand-copied-keys.csv` (what `pipeline plan --csv` said of each hand-copied
/// file before the sweep replaced it): file -> node -> (key, inputs).
fn hand_copied(study: &str) -> BTreeMap<String, BTreeMap<String, (String, String)>> {
    let text = std::fs::read_to_string(repo(&format!("analysis/results/{study}/report/hand-copied-keys.csv"))).unwrap();
    let mut out: BTreeMap<String, BTreeMap<String, (String, String)>> = BTreeMap::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        out.entry(f[0].into()).or_default().insert(f[1].into(), (f[3].into(), f.get(4).copied().unwrap_or_default().into()));
    }
    out
}

#[test]
fn ported_sweeps_give_the_keys_of_the_files_they_replaced() {
    let files = hand_copied("task-reward");
    for (sweep, file_of) in [
        ("tuning-ant.yaml", &(|l: &str| format!("tuning-ant-{l}")) as &dyn Fn(&str) -> String),
        ("tuning-hopper.yaml", &|l: &str| {
            if l == "shipped" { "own-demos/tuning-hopper-sampled-drex".into() } else { format!("tuning-hopper-{l}") }
        }),
    ] {
        let s = Sweep::load(Path::new(&repo(&format!("analysis/results/task-reward/{sweep}"))), &[]).unwrap();
        assert!(s.variants.len() >= 4, "{sweep}");
        for v in &s.variants {
            let name = file_of(&v.label);
            let want = files.get(&name).unwrap_or_else(|| panic!("{sweep}: no hand-copied file {name}"));
            let g = expand(&v.pipeline).unwrap();
            let keys = g.keys();
            assert_eq!(keys.keys().collect::<Vec<_>>(), want.keys().collect::<Vec<_>>(), "{sweep} {}: the same nodes", v.label);
            for n in &g.nodes {
                let (key, inputs) = &want[&n.name];
                if n.kind().name() != "eval" {
                    assert_eq!(&keys[&n.name], key, "{sweep} {}: {}", v.label, n.name);
                    continue;
                }
                // An evaluation's key names its study; what it evaluates is the file's.
                let theirs: BTreeMap<&str, &str> =
                    inputs.split(' ').filter_map(|i| i.split_once('=')).map(|(r, src)| (r, want[src].0.as_str())).collect();
                let ours: BTreeMap<String, &str> = n.inputs.iter().map(|(r, src)| (r.name(), keys[src].as_str())).collect();
                assert_eq!(
                    ours.iter().map(|(r, k)| (r.as_str(), *k)).collect::<BTreeMap<_, _>>(),
                    theirs,
                    "{sweep} {}: {}",
                    v.label,
                    n.name
                );
            }
        }
    }
}
