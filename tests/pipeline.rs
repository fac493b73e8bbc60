//! The pipeline engine end to end on pipelines/smoke.yaml (every method, real MuJoCo, tiny
//! budgets): outputs checked with the tools users use (Python's mcap reader, `rerun rrd
//! verify`, Python's csv module), caching, crash safety, concurrency and corruption.
use std::path::Path;
use std::process::{Command, Stdio};

use crate::util::{TempDir, idrex, python, repo, stderr, stdout};

fn run_smoke(store: &Path, rec: &Path) -> std::process::Output {
    let smoke = repo("pipelines/smoke.yaml");
    idrex(&["pipeline", "run", smoke.to_str().unwrap(), "--store", store.to_str().unwrap(), "--recording", rec.to_str().unwrap()])
}

fn computed(out: &std::process::Output) -> usize {
    let s = stdout(out);
    let line = s.lines().find(|l| l.contains(" computed")).unwrap_or_else(|| panic!("no summary in: {s}"));
    line.split(", ").find_map(|p| p.strip_suffix(" computed")).unwrap().trim().parse().unwrap()
}

fn artifact_dirs(store: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(store)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir() && !p.file_name().unwrap().to_string_lossy().starts_with('.'))
        .collect()
}

fn py(code: &str, args: &[&str]) -> String {
    let out = Command::new(python()).arg("-c").arg(code).args(args).output().unwrap();
    assert!(out.status.success(), "python failed: {}", stderr(&out));
    stdout(&out)
}

#[test]
fn smoke_pipeline_end_to_end() {
    let dir = TempDir::new("smoke");
    let (store, rec) = (dir.join("store"), dir.join("smoke.rrd"));
    let first = run_smoke(&store, &rec);
    assert!(first.status.success(), "{}\n{}", stdout(&first), stderr(&first));
    let total = computed(&first);
    assert!(total >= 20, "every method's stages ran: {}", stdout(&first));

    // Re-running recomputes nothing.
    let again = run_smoke(&store, &rec);
    assert!(again.status.success());
    assert_eq!(computed(&again), 0, "{}", stdout(&again));

    // The smoke's BC (300 iterations) ends at 49 % of its demonstrations (its bytes are pinned,
    // so these returns are the same everywhere): the first run says so when the BC lands, the
    // re-run in its second line, before anything else.
    let gap = "warning: bc: BC ends far below its demonstrations: 11.7 against their 24.1 (49 % of it; the warning is below 70 %";
    assert!(stdout(&first).contains(gap), "{}", stdout(&first));
    assert!(stdout(&again).lines().nth(1).is_some_and(|l| l.starts_with(gap)), "{}", stdout(&again));
    // `eval.bc_warning` is the threshold, and no part of a key: at 0.4 the same store says nothing.
    let lenient = dir.join("lenient");
    std::fs::create_dir_all(&lenient).unwrap();
    let text = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    assert!(text.contains("eval:\n  episodes: 3\n"));
    std::fs::write(lenient.join("smoke.yaml"), text.replace("eval:\n  episodes: 3\n", "eval:\n  episodes: 3\n  bc_warning: 0.4\n"))
        .unwrap();
    let plan = |file: &Path| idrex(&["pipeline", "plan", file.to_str().unwrap(), "--store", store.to_str().unwrap()]);
    assert!(stdout(&plan(&repo("pipelines/smoke.yaml"))).contains(gap));
    let quiet = plan(&lenient.join("smoke.yaml"));
    assert!(quiet.status.success() && !stdout(&quiet).contains("far below"), "{}", stdout(&quiet));
    assert!(stdout(&quiet).contains("estimated: 0.0 min of stage time left"), "the same keys, all stored: {}", stdout(&quiet));

    // The recording passes rerun's own verifier.
    let rerun = Path::new(&python()).with_file_name("rerun");
    let v = Command::new(&rerun).args(["rrd", "verify", rec.to_str().unwrap()]).output().unwrap();
    assert!(v.status.success(), "rerun rrd verify: {}{}", stdout(&v), stderr(&v));
    // It carries its layout (a blueprint: a viewport with automatic views off and one view
    // per figure, each on its own x axis over the whole timeline, legends giving way where a
    // view has many series), and every plotted row has the one plot timeline, `x`.
    let p = Command::new(&rerun).args(["rrd", "print", "-vv", rec.to_str().unwrap()]).output().unwrap();
    assert!(stdout(&p).contains("ViewportBlueprint:auto_views"), "the recording has no blueprint");
    let views = crate::recording::check_layout(&rec, |t| !t.contains(" series, legend"));
    assert_eq!(views.len(), 7, "one plot view per figure (multi-BC's clones among them): {views:?}");
    assert!(views.iter().any(|v| v.contains("Multi-BC clones")), "{views:?}");

    // Every rollout file opens in Python's mcap reader with monotonic log times.
    let mcaps: Vec<_> = walk(&store).into_iter().filter(|p| p.extension().is_some_and(|e| e == "mcap")).collect();
    assert!(mcaps.len() >= 10);
    let check = r#"
import json, sys
from mcap.reader import make_reader
for path in sys.argv[1:]:
    with open(path, "rb") as f:
        r = make_reader(f)
        last, n, schemas = 0, 0, set()
        for schema, channel, msg in r.iter_messages():
            assert msg.log_time > last, (path, msg.log_time, last)
            last = msg.log_time
            schemas.add(schema.encoding)
            json.loads(msg.data)
            n += 1
        meta = {m.name: m.metadata for m in r.iter_metadata()}
        assert schemas <= {"jsonschema"}, schemas
        assert meta["idrex.rollout"]["format"] == "idrex-rollout/1"
        # Empty only where every episode was filtered out (multi-BC's clone filter).
        assert n > 0 or meta["idrex.rollout"]["episodes"] == "0", path
print("ok", len(sys.argv) - 1)
"#;
    let args: Vec<&str> = mcaps.iter().map(|p| p.to_str().unwrap()).collect();
    assert!(py(check, &args).starts_with("ok"));
    // And in the TypeScript reader Foxglove is built on, every channel decoding under
    // Foxglove's JSON-schema rules (one type per field): the /step channel included.
    let ts = Command::new("node").arg(repo("analysis/foxglove/check.mjs")).args(&args).output().unwrap();
    assert!(ts.status.success(), "foxglove check: {}{}", stdout(&ts), stderr(&ts));
    let steps = stdout(&ts).lines().filter(|l| l.contains("\"/step\":") && !l.contains("\"/step\":0")).count();
    assert!(steps >= 10, "files whose /step messages decode: {}", stdout(&ts));

    // The report: CSV that Python's csv module reads, markdown with every method.
    let out_dir = dir.join("report");
    let rep = idrex(&["report", "--store", store.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    assert!(rep.status.success(), "{}", stderr(&rep));
    let md = std::fs::read_to_string(out_dir.join("report.md")).unwrap();
    assert!(md.contains("| Hopper-v5 | smoke |"), "{md}");
    assert!(!md.contains("missing"), "every method has results: {md}");
    assert!(md.contains("**BC ends far below its demonstrations: 11.7 against their 24.1 (49 % of it"), "the answer says it first: {md}");
    // What the tables do not show: episode counts, the rewards' validation accuracy, what
    // multi-BC's clone filter kept.
    assert!(md.contains(" episodes) |"), "{md}");
    assert!(md.contains("## Notes") && md.contains("held-out training pairs") && md.contains("the clone filter kept"), "{md}");
    // The smoke file turns the clone filter off, so no clone's fidelity is measured: the notes
    // say so, and no table or sentence prints NaN.
    assert!(md.contains("their fidelity was not measured (no clone filter scores them"), "{md}");
    assert!(!md.contains("NaN"), "{md}");
    // Multi-BC's clones joined its ranked set (the smoke file keeps every clone), so its reward
    // saw rankings of its own and its results are not D-REX's; every clone is in clones.csv
    // with its fidelity.
    let clones = py(
        "import csv,sys; rows = list(csv.DictReader(open(sys.argv[1]))); print(len(rows), sum(r['kept'] == 'true' for r in rows), all(r['source_return'] and r['clone_return'] for r in rows))",
        &[out_dir.join("clones.csv").to_str().unwrap()],
    );
    let counts: Vec<&str> = clones.split_whitespace().collect();
    assert_eq!(counts[0], "2", "one clone per D-REX run: {clones}");
    assert!(counts[1] == "2" && counts[2] == "True", "both clones kept: {clones}");
    let means = py(
        "import csv,sys; rows = {r['method']: r['mean'] for r in csv.DictReader(open(sys.argv[1]))}; print(rows['drex'], rows['idrex-multi-bc'])",
        &[out_dir.join("returns.csv").to_str().unwrap()],
    );
    let means: Vec<&str> = means.split_whitespace().collect();
    assert_ne!(means[0], means[1], "multi-BC's results are its own");
    // The figures: SVG and PNG of each kind, linked from report.md; every PNG decodes at its
    // size and is not blank (many colours, a good share of non-white pixels).
    let figures = out_dir.join("figures");
    for kind in ["degradation", "reward-drex", "reward-idrex-multi-bc", "ppo", "final", "clones"] {
        let stem = format!("hopper-v5-smoke-{kind}");
        assert!(md.contains(&format!("figures/{stem}.png")), "{stem} linked: {md}");
        let svg = std::fs::read_to_string(figures.join(format!("{stem}.svg"))).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("true return"), "{stem}.svg has labelled axes");
        // The major grid only: plotters' minor grid (faint lines, 10 per division) was most of
        // every SVG's bytes.
        let grid = svg.matches("<line opacity=").count();
        assert!((4..60).contains(&grid), "{stem}.svg draws {grid} grid lines");
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(figures.join(format!("{stem}.png"))).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut pixels).unwrap();
        assert_eq!((info.width, info.height), (960, 640), "{stem}");
        let rgb: Vec<[u8; 3]> = pixels[..info.buffer_size()].chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let colours: std::collections::HashSet<[u8; 3]> = rgb.iter().copied().collect();
        let inked = rgb.iter().filter(|p| **p != [255, 255, 255]).count() as f64 / rgb.len() as f64;
        assert!(colours.len() > 20 && inked > 0.02, "{stem}.png looks blank: {} colours, {:.1} % inked", colours.len(), inked * 100.0);
    }
    let csv_check = r#"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
methods = {r["method"] for r in rows}
assert methods == {"bc", "drex", "idrex-interpolation", "idrex-action-noise", "idrex-multi-bc"}, methods
for r in rows:
    float(r["mean"]); float(r["best_run_avg"])
print("ok")
"#;
    assert_eq!(py(csv_check, &[out_dir.join("returns.csv").to_str().unwrap()]).trim(), "ok");

    // Every PPO run kept its checkpoints (smoke: 4 updates, one checkpoint each) and its
    // evaluation evaluated every one of them, the final policy last.
    let checkpoints_check = r#"
import json, os, sys
store = sys.argv[1]
manifests = [json.load(open(os.path.join(store, d, "manifest.json"))) for d in os.listdir(store) if not d.startswith(".")]
ppo = {m["key"]: m for m in manifests if m["kind"] == "ppo"}
evals = [m for m in manifests if m["kind"] == "eval" and m["inputs"]["policy"] in ppo]
assert len(ppo) == 8 and len(evals) == 8, (len(ppo), len(evals))
for e in evals:
    key = e["inputs"]["policy"]
    stored = sorted(int(d.split("-")[1]) for d in os.listdir(os.path.join(store, key, "checkpoints")))
    assert stored == [1024, 2048, 3072, 4096], stored
    cps = e["metrics"]["checkpoints"]
    assert [c["step"] for c in cps] == stored, cps
    assert all(len(c["returns"]) == e["params"]["episodes"] and c["learned"] is not None for c in cps)
    assert cps[-1]["returns"] == e["metrics"]["returns"], "the last checkpoint is the final policy"
print("ok")
"#;
    assert_eq!(py(checkpoints_check, &[store.to_str().unwrap()]).trim(), "ok");

    // The three protocols: the report's figures are what a hand computation over the eval
    // manifests gives.
    let protocols_check = r#"
import csv, json, os, sys
from collections import defaultdict
store, table = sys.argv[1], sys.argv[2]
groups = defaultdict(list)
for d in os.listdir(store):
    if d.startswith("."):
        continue
    m = json.load(open(os.path.join(store, d, "manifest.json")))
    if m["kind"] == "eval":
        p = m["params"]
        groups[(p["env"], p["pipeline"], p["method"])].append(m["metrics"])
mean = lambda v: sum(v) / len(v)
rows = {(r["env"], r["pipeline"], r["method"], r["protocol"]): r for r in csv.DictReader(open(table))}
checked = 0
for (env, pipe, method), runs in groups.items():
    want = {"final": (None, mean([x for r in runs for x in r["returns"]]))}
    if runs[0]["checkpoints"]:
        steps = [c["step"] for c in runs[0]["checkpoints"]]
        at = lambda r, s: next(c for c in r["checkpoints"] if c["step"] == s)
        pooled = {s: mean([x for r in runs for x in at(r, s)["returns"]]) for s in steps}
        best = max(steps, key=lambda s: (pooled[s], -s))
        free = max(steps, key=lambda s: (mean([at(r, s)["learned"]["pessimistic"] for r in runs]), -s))
        want["best-by-ground-truth"] = (best, pooled[best])
        want["ground-truth-free"] = (free, pooled[free])
        gap = pooled[best] - pooled[free]
        assert abs(float(rows[(env, pipe, method, "ground-truth-free")]["gap_to_best"]) - gap) < 1e-9
    for protocol, (step, value) in want.items():
        row = rows[(env, pipe, method, protocol)]
        assert abs(float(row["mean"]) - value) < 1e-9, (method, protocol, row["mean"], value)
        assert (row["step"] or None) == (None if step is None else str(step)), (method, protocol, row["step"], step)
        assert float(row["ci_low"]) <= float(row["ci_high"])
        checked += 1
assert checked == 13, checked
print("ok")
"#;
    let table = out_dir.join("protocols.csv");
    let args = [store.to_str().unwrap(), table.to_str().unwrap()];
    assert_eq!(py(protocols_check, &args).trim(), "ok");
    // How each method earns its return: terms.csv's return is returns.csv's mean and the sum of
    // its terms; the SSRR-way correlation is Pearson over the reward's ranked set, the
    // demonstrations and the final policies' episodes, recomputed here from the manifests.
    let terms_check = r#"
import csv, json, os, sys
store, out = sys.argv[1], sys.argv[2]
read = lambda name: list(csv.DictReader(open(os.path.join(out, name))))
means = {(r["env"], r["pipeline"], r["method"]): float(r["mean"]) for r in read("returns.csv")}
for r in read("demos.csv"):
    means[(r["env"], r["pipeline"], "demonstrations")] = float(r["demos_avg"])
terms = read("terms.csv")
assert len(terms) == len(means) == 6, (len(terms), len(means))
for r in terms:
    total = sum(float(r[c]) for c in ("forward", "ctrl", "survive", "contact"))
    assert abs(total - float(r["return"])) < 1e-6 * max(1.0, abs(total)), r
    assert abs(float(r["return"]) - means[(r["env"], r["pipeline"], r["method"])]) < 1e-6, r
    assert r["earned_by"] in ("moving", "living") and float(r["survive"]) > 0, r
    learned = r["method"] not in ("bc", "demonstrations")
    assert (r["learned_per_step"] != "") == learned == (r["ranked_best_per_step"] != ""), r
ms = {}
for d in os.listdir(store):
    if not d.startswith("."):
        m = json.load(open(os.path.join(store, d, "manifest.json")))
        ms[m["key"]] = m
def pearson(x, y):
    n = len(x); mx, my = sum(x) / n, sum(y) / n
    cov = sum((a - mx) * (b - my) for a, b in zip(x, y))
    return cov / (sum((a - mx) ** 2 for a in x) * sum((b - my) ** 2 for b in y)) ** 0.5
evals = [m for m in ms.values() if m["kind"] == "eval" and "reward" in m["inputs"]]
pool = {}
for m in evals:
    p, t = pool.setdefault((m["inputs"]["reward"], m["params"]["pipeline"]), ([], []))
    p += m["metrics"]["predicted_returns"]
    t += m["metrics"]["returns"]
want = {}
for m in evals:
    k = m["inputs"]["reward"]
    x = ms[k]["metrics"]
    seen = pool[(k, m["params"]["pipeline"])]
    pred = x["train_set"]["predicted"] + x["demos"]["predicted"] + seen[0]
    true = x["train_set"]["true"] + x["demos"]["true"] + seen[1]
    want.setdefault((m["params"]["env"], m["params"]["pipeline"], m["params"]["method"]), []).append(pearson(pred, true))
rows = read("reward_accuracy.csv")
assert len(rows) == len(want) == 4, rows
for r in rows:
    v = want[(r["env"], r["pipeline"], r["method"])]
    assert abs(float(r["pearson_ssrr"]) - sum(v) / len(v)) < 1e-9, (r, v)
print("ok")
"#;
    assert_eq!(py(terms_check, &[store.to_str().unwrap(), out_dir.to_str().unwrap()]).trim(), "ok");
    assert!(md.contains("SELECTED WITH THE GROUND-TRUTH REWARD"), "{md}");

    // An archive of the stages' manifests rebuilds the same report, figures and all, with no
    // store at all (from the compressed archive), and with the store beside it; an edited
    // definition is refused.
    // What `idrex export` said, with `extra` arguments before `--out archive`.
    let export_with = |extra: &[&str], archive: &std::path::Path| {
        let smoke = repo("pipelines/smoke.yaml");
        let mut args = vec!["export", smoke.to_str().unwrap(), "--store", store.to_str().unwrap()];
        args.extend(extra);
        args.extend(["--out", archive.to_str().unwrap()]);
        let ex = idrex(&args);
        assert!(ex.status.success(), "{}{}", stdout(&ex), stderr(&ex));
        stdout(&ex)
    };
    let export = |archive: &std::path::Path| {
        let said = export_with(&[], archive);
        assert!(said.contains(": 28 of 28 stages' manifests"), "{said}");
    };
    let (archive, compressed) = (dir.join("smoke.ndjson"), dir.join("smoke.ndjson.zst"));
    export(&archive);
    export(&compressed);
    let (plain_len, zst) = (std::fs::metadata(&archive).unwrap().len(), std::fs::read(&compressed).unwrap());
    assert!(zst.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]) && (zst.len() as u64) * 3 < plain_len, "{} of {plain_len} bytes", zst.len());
    // A later phase's archive leaves out what an earlier one holds (`--except`); the two read
    // together are the whole.
    let (first_phase, second_phase) = (dir.join("phase1.ndjson"), dir.join("phase2.ndjson.zst"));
    let plain = std::fs::read_to_string(&archive).unwrap();
    std::fs::write(&first_phase, plain.lines().take(10).map(|l| format!("{l}\n")).collect::<String>()).unwrap();
    let said = export_with(&["--except", first_phase.to_str().unwrap()], &second_phase);
    assert!(said.contains(": 18 of 28 stages' manifests") && said.contains("; 10 already in"), "{said}");
    for (name, with_store, from) in [
        ("report-archive", false, vec![&compressed]),
        ("report-both", true, vec![&archive]),
        ("report-phases", false, vec![&first_phase, &second_phase]),
    ] {
        let again = dir.join(name);
        let store_arg = if with_store { store.clone() } else { dir.join("no-store-here") };
        let mut args = vec!["report".to_string(), "--store".into(), store_arg.to_str().unwrap().into()];
        for a in from {
            args.extend(["--archive".to_string(), a.to_str().unwrap().to_string()]);
        }
        args.extend(["--out".to_string(), again.to_str().unwrap().to_string()]);
        let rep = idrex(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(rep.status.success(), "{name}: {}", stderr(&rep));
        let files = walk(&out_dir);
        assert!(files.len() > 10, "{files:?}");
        for f in files {
            let rel = f.strip_prefix(&out_dir).unwrap();
            assert!(std::fs::read(&f).unwrap() == std::fs::read(again.join(rel)).unwrap(), "{name}: {} differs", rel.display());
        }
    }
    let text = std::fs::read_to_string(&archive).unwrap();
    let mut first: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    first["seed"] = serde_json::json!(first["seed"].as_u64().unwrap() + 1);
    let edited = dir.join("edited.ndjson");
    std::fs::write(&edited, text.replacen(text.lines().next().unwrap(), &first.to_string(), 1)).unwrap();
    let rep = idrex(&[
        "report",
        "--store",
        store.to_str().unwrap(),
        "--archive",
        edited.to_str().unwrap(),
        "--out",
        dir.join("x").to_str().unwrap(),
    ]);
    assert!(!rep.status.success() && stderr(&rep).contains("edited.ndjson: line 1: key"), "{}", stderr(&rep));

    // A flipped byte: verify reports it, a run recomputes exactly that artifact.
    let victim = mcaps[0].clone();
    let mut bytes = std::fs::read(&victim).unwrap();
    bytes[100] ^= 0xff;
    std::fs::write(&victim, bytes).unwrap();
    let v = idrex(&["verify", "--store", store.to_str().unwrap()]);
    assert!(!v.status.success());
    assert!(stdout(&v).contains("1 corrupt"), "{}", stdout(&v));
    let healed = run_smoke(&store, &rec);
    assert!(healed.status.success(), "{}", stderr(&healed));
    assert_eq!(computed(&healed), 1, "{}", stdout(&healed));
    assert!(idrex(&["verify", "--store", store.to_str().unwrap()]).status.success());

    // A missing run is named in the report.
    let drex_eval_1 = artifact_dirs(&store)
        .into_iter()
        .find(|d| std::fs::read_to_string(d.join("manifest.json")).unwrap().contains("\"node\": \"drex/eval/1\""))
        .unwrap();
    std::fs::remove_dir_all(drex_eval_1).unwrap();
    let rep = idrex(&["report", "--store", store.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    assert!(stdout(&rep).contains("run 1 missing"), "{}", stdout(&rep));

    // logs: list and export reopen our files (one that holds episodes: the store's order
    // follows the keys, multi-BC's filter may leave a file empty, and drex/eval/1's is gone).
    let listed = mcaps[1..].iter().filter(|m| m.exists()).map(|m| (m, idrex(&["logs", "list", m.to_str().unwrap()])));
    let (file, l) = listed.into_iter().find(|(_, l)| !stdout(l).contains(": 0 episodes")).unwrap();
    assert!(l.status.success() && stdout(&l).contains("episodes of Hopper-v5"), "{}", stderr(&l));
    let csv_out = dir.join("steps.csv");
    let e = idrex(&["logs", "export", file.to_str().unwrap(), "--format", "csv", "--out", csv_out.to_str().unwrap()]);
    assert!(e.status.success(), "{}", stderr(&e));
    let n = py(
        "import csv,sys; rows = list(csv.DictReader(open(sys.argv[1]))); assert 'next_obs_0' in rows[0]; print(len(rows))",
        &[csv_out.to_str().unwrap()],
    );
    assert!(n.trim().parse::<usize>().unwrap() > 0);
    // Another kind of file is called that, not corrupt, and nobody is told to delete it.
    let manifest = file.with_file_name("manifest.json");
    let l = idrex(&["logs", "list", manifest.to_str().unwrap()]);
    assert!(!l.status.success() && stderr(&l).contains("is not an MCAP file") && !stderr(&l).contains("delete"), "{}", stderr(&l));
    // Read-only commands create nothing: no store where there was none.
    let nowhere = dir.join("no-store");
    for args in [vec!["report", "--store", nowhere.to_str().unwrap()], vec!["verify", "--store", nowhere.to_str().unwrap()]] {
        let o = idrex(&args);
        assert!(!o.status.success() && stderr(&o).contains("no store at"), "{args:?}: {}", stderr(&o));
    }
    let plan = idrex(&["pipeline", "plan", repo("pipelines/smoke.yaml").to_str().unwrap(), "--store", nowhere.to_str().unwrap()]);
    assert!(plan.status.success() && stdout(&plan).contains("missing"), "{}", stderr(&plan));
    assert!(!nowhere.exists(), "a read-only command created {}", nowhere.display());
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.file_name().unwrap().to_string_lossy().starts_with('.') {
            continue;
        }
        if p.is_dir() { out.extend(walk(&p)) } else { out.push(p) }
    }
    out
}

#[test]
fn kill_minus_nine_leaves_nothing_partial_and_the_rerun_reuses_finished_work() {
    let dir = TempDir::new("kill");
    let store = dir.join("store");
    let smoke = repo("pipelines/smoke.yaml");
    let mut child = Command::new(env!("CARGO_BIN_EXE_idrex"))
        .args([
            "pipeline",
            "run",
            smoke.to_str().unwrap(),
            "--store",
            store.to_str().unwrap(),
            "--recording",
            dir.join("r.rrd").to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait until a few artifacts are published and more are being computed, then kill.
    let start = std::time::Instant::now();
    while (!store.exists() || artifact_dirs(&store).len() < 4) && start.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    unsafe { libc_kill(child.id() as i32, 9) };
    child.wait().unwrap();
    let published = artifact_dirs(&store);
    assert!(!published.is_empty());
    // Every published artifact is complete; staging leftovers are never trusted.
    let v = idrex(&["verify", "--store", store.to_str().unwrap()]);
    assert!(v.status.success(), "{}", stdout(&v));
    let rerun = run_smoke(&store, &dir.join("r.rrd"));
    assert!(rerun.status.success(), "{}", stderr(&rerun));
    let fresh = TempDir::new("kill-fresh");
    let full = computed(&run_smoke(&fresh.join("store"), &fresh.join("r.rrd")));
    assert_eq!(computed(&rerun) + published.len(), full, "finished nodes were reused, the rest computed once");
}

unsafe extern "C" {
    #[link_name = "kill"]
    fn libc_kill(pid: i32, sig: i32) -> i32;
}

#[test]
fn two_concurrent_runs_share_one_store() {
    let dir = TempDir::new("concurrent");
    let store = dir.join("store");
    let smoke = repo("pipelines/smoke.yaml");
    let spawn = |rec: &str| {
        Command::new(env!("CARGO_BIN_EXE_idrex"))
            .args([
                "pipeline",
                "run",
                smoke.to_str().unwrap(),
                "--store",
                store.to_str().unwrap(),
                "--jobs",
                "1",
                "--recording",
                dir.join(rec).to_str().unwrap(),
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn("a.rrd"), spawn("b.rrd"));
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    assert!(a.status.success() && b.status.success(), "{}{}", stderr(&a), stderr(&b));
    // Each node was computed by exactly one of them; the other reused it.
    assert_eq!(computed(&a) + computed(&b), artifact_dirs(&store).len(), "{}\n{}", stdout(&a), stdout(&b));
    assert!(idrex(&["verify", "--store", store.to_str().unwrap()]).status.success());
}

#[test]
fn a_bad_pipeline_file_runs_nothing() {
    let dir = TempDir::new("badyaml");
    std::fs::write(dir.join("p.yaml"), "version: 1\nenv: Hopper-v5\nppo:\n  total_stepz: 10\n").unwrap();
    let out = idrex(&["pipeline", "run", dir.join("p.yaml").to_str().unwrap(), "--store", dir.join("store").to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("p.yaml:4:3: ppo: unknown field `total_stepz`"), "{}", stderr(&out));
    assert!(!dir.join("store").exists(), "nothing ran, not even the store was created");
}

#[test]
fn changing_one_parameter_invalidates_exactly_its_descendants() {
    use idrex::pipeline::{Pipeline, expand};
    let text = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let base = Pipeline::parse(&repo("pipelines/smoke.yaml"), &text).unwrap();
    let changed = Pipeline::parse(&repo("pipelines/smoke.yaml"), &text.replace("  iterations: 100\n", "  iterations: 101\n")).unwrap();
    let (g, k1, k2) = (expand(&base).unwrap(), expand(&base).unwrap().keys(), expand(&changed).unwrap().keys());
    let differ: Vec<&String> = k1.keys().filter(|n| k1[*n] != k2[*n]).collect();
    // T-REX's stages: the rewards, and multi-BC's judge (trained like the reward before it).
    let mut expected: Vec<String> =
        g.nodes.iter().filter(|n| n.name.ends_with("/trex") || n.name.ends_with("/judge")).flat_map(|n| g.descendants(&n.name)).collect();
    expected.sort();
    expected.dedup();
    let mut differ: Vec<String> = differ.into_iter().cloned().collect();
    differ.sort();
    assert_eq!(differ, expected);
    assert!(!differ.contains(&"bc".to_string()) && !differ.contains(&"drex/noise".to_string()));
}

/// (key, outputs with digests) of every artifact in a store.
fn digests(store: &Path) -> std::collections::BTreeMap<String, serde_json::Value> {
    artifact_dirs(store)
        .into_iter()
        .map(|d| {
            let m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("manifest.json")).unwrap()).unwrap();
            (m["key"].as_str().unwrap().to_string(), m["outputs"].clone())
        })
        .collect()
}

#[test]
fn bytes_depend_on_the_key_alone() {
    let dir = TempDir::new("determinism");
    let smoke = repo("pipelines/smoke.yaml");
    let run = |store: &str, jobs: &str| {
        let out = idrex(&[
            "pipeline",
            "run",
            smoke.to_str().unwrap(),
            "--store",
            dir.join(store).to_str().unwrap(),
            "--jobs",
            jobs,
            "--recording",
            dir.join(format!("{store}.rrd").as_str()).to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
    };
    run("one", "1");
    run("two", "2");
    let (one, two) = (digests(&dir.join("one")), digests(&dir.join("two")));
    assert_eq!(one.len(), 28);
    assert_eq!(one, two, "every artifact's bytes are the same with --jobs 1 and --jobs 2");

    // Recomputing stored artifacts from their manifests gives the same bytes...
    let store = dir.join("one");
    let v = idrex(&["verify", "--store", store.to_str().unwrap(), "--recompute", "5"]);
    assert!(v.status.success(), "{}{}", stdout(&v), stderr(&v));
    assert!(stdout(&v).contains("5 recomputed, 0 differ"), "{}", stdout(&v));
    // ...and an artifact whose bytes were replaced (its manifest updated to match, so that
    // plain verification passes) is caught.
    let ppo = artifact_dirs(&store)
        .into_iter()
        .find(|d| std::fs::read_to_string(d.join("manifest.json")).unwrap().contains("\"kind\": \"ppo\""))
        .unwrap();
    let curve = ppo.join("curve.csv");
    let mut text = std::fs::read_to_string(&curve).unwrap();
    text.push('\n');
    std::fs::write(&curve, &text).unwrap();
    let mpath = ppo.join("manifest.json");
    let mut m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&mpath).unwrap()).unwrap();
    let (sha, size) = idrex::store::sha256_file(&curve).unwrap();
    for o in m["outputs"].as_array_mut().unwrap() {
        if o["path"] == "curve.csv" {
            o["sha256"] = sha.clone().into();
            o["size"] = size.into();
        }
    }
    std::fs::write(&mpath, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    assert!(idrex(&["verify", "--store", store.to_str().unwrap()]).status.success());
    let v = idrex(&["verify", "--store", store.to_str().unwrap(), "--recompute"]);
    assert!(!v.status.success());
    assert!(stdout(&v).contains("curve.csv") && stdout(&v).contains("28 recomputed, 1 differ"), "{}", stdout(&v));
    assert!(stderr(&v).contains("do not depend on their key alone"), "{}", stderr(&v));
}

/// The products and the initial weights are idrex's own, summed in an order the shapes
/// alone fix: the smoke pipeline's bytes are the same on every kernel variant this
/// processor has, and whatever MKL's and ATen's dispatch settings say (none of their
/// kernels computes a stored byte).
#[test]
fn bytes_are_the_same_on_every_kernel_variant() {
    let dir = TempDir::new("kernels");
    let smoke = repo("pipelines/smoke.yaml");
    let run = |name: &str, env: &[(&str, &str)]| {
        let store = dir.join(name);
        let out = Command::new(env!("CARGO_BIN_EXE_idrex"))
            .args(["pipeline", "run", smoke.to_str().unwrap(), "--store", store.to_str().unwrap()])
            .args(["--recording", dir.join(format!("{name}.rrd").as_str()).to_str().unwrap()])
            .envs(env.iter().copied())
            .output()
            .unwrap();
        (out, store)
    };
    let (out, scalar_store) = run("scalar", &[("IDREX_KERNEL", "scalar")]);
    assert!(out.status.success(), "{}", stderr(&out));
    let reference = digests(&scalar_store);
    assert_eq!(reference.len(), 28);
    let manifests: Vec<String> =
        artifact_dirs(&scalar_store).iter().map(|d| std::fs::read_to_string(d.join("manifest.json")).unwrap()).collect();
    assert!(manifests.iter().all(|m| m.contains("\"kernel\": \"scalar\"")), "{}", manifests[0]);
    let has = |v: &str| match v {
        "avx2" => std::arch::is_x86_feature_detected!("avx2"),
        _ => std::arch::is_x86_feature_detected!("avx512f"),
    };
    let mut compared = vec!["scalar"];
    for variant in ["avx2", "avx512"] {
        let (out, store) = run(variant, &[("IDREX_KERNEL", variant)]);
        if !has(variant) {
            assert!(!out.status.success() && stderr(&out).contains("IDREX_KERNEL"), "{}", stderr(&out));
            crate::util::skip(&format!("pipeline::kernel variant {variant}"), "this processor lacks it");
            continue;
        }
        assert!(out.status.success(), "{}", stderr(&out));
        assert_eq!(digests(&store), reference, "the {variant} kernels give the scalar kernels' bytes");
        compared.push(variant);
    }
    for (name, var, value) in [
        ("mkl-cbwr", "MKL_CBWR", "COMPATIBLE"),
        ("mkl-sse", "MKL_ENABLE_INSTRUCTIONS", "SSE4_2"),
        ("aten", "ATEN_CPU_CAPABILITY", "default"),
    ] {
        let (out, store) = run(name, &[(var, value)]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert_eq!(digests(&store), reference, "{var}={value} changes no byte");
    }
    eprintln!("smoke digests identical on kernel variants {compared:?} and under MKL and ATen dispatch settings");
    // And identical to every earlier build's: the sha256 of `key outputs` lines, pinned at
    // 8e58d64 (refactors must not move a byte; a change that means to bumps a stage version).
    let lines: String = reference.iter().map(|(k, o)| format!("{k} {o}\n")).collect();
    use sha2::Digest;
    let pinned: String = sha2::Sha256::digest(lines.as_bytes()).iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(pinned, SMOKE_BYTES, "the smoke pipeline's stored bytes changed:\n{lines}");
    // Recomputed on another variant, the scalar store's artifacts are the same bytes.
    let v = idrex(&["verify", "--store", scalar_store.to_str().unwrap(), "--recompute", "6"]);
    assert!(v.status.success(), "{}{}", stdout(&v), stderr(&v));
    let bad = Command::new(env!("CARGO_BIN_EXE_idrex"))
        .args(["verify", "--store", scalar_store.to_str().unwrap()])
        .env("IDREX_KERNEL", "avx9")
        .output()
        .unwrap();
    assert!(!bad.status.success() && stderr(&bad).contains("IDREX_KERNEL=avx9 is not a kernel variant"), "{}", stderr(&bad));
}

/// The smoke pipeline's artifacts, pinned: see the kernel-variants test.
const SMOKE_BYTES: &str = "b88156a3bdbc14b75406be2df09e68b5a93b64157ac9362c75f51740b7b187e2";

#[test]
fn runs_in_two_pid_namespaces_share_a_store() {
    // Where unshare works (root, or user namespaces allowed): one run sees other pids than
    // the other, so staging ownership must not be judged by pid.
    let probe = Command::new("unshare").args(["--pid", "--fork", "--mount-proc", "true"]).output();
    if !probe.is_ok_and(|o| o.status.success()) {
        crate::util::skip("pipeline::runs_in_two_pid_namespaces_share_a_store", "unshare --pid is not available here");
        return;
    }
    let dir = TempDir::new("namespaces");
    let store = dir.join("store");
    let smoke = repo("pipelines/smoke.yaml");
    let args = |rec: &str| {
        vec![
            "pipeline".to_string(),
            "run".into(),
            smoke.to_str().unwrap().into(),
            "--store".into(),
            store.to_str().unwrap().into(),
            "--jobs".into(),
            "1".into(),
            "--recording".into(),
            dir.join(rec).to_str().unwrap().into(),
        ]
    };
    let inner = Command::new("unshare")
        .args(["--pid", "--fork", "--mount-proc", env!("CARGO_BIN_EXE_idrex")])
        .args(args("a.rrd"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let outer =
        Command::new(env!("CARGO_BIN_EXE_idrex")).args(args("b.rrd")).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let (a, b) = (inner.wait_with_output().unwrap(), outer.wait_with_output().unwrap());
    assert!(a.status.success() && b.status.success(), "{}{}", stderr(&a), stderr(&b));
    assert_eq!(computed(&a) + computed(&b), artifact_dirs(&store).len(), "{}\n{}", stdout(&a), stdout(&b));
    assert!(idrex(&["verify", "--store", store.to_str().unwrap()]).status.success());
}

/// Two files of one study (the same `name`, disjoint replicates) report as one: the
/// aggregate table over three replicates, read back with Python's csv module; a file of the
/// same study that imports other demonstrations, or that gives a stored replicate other
/// seeds, is refused with one line naming the study and the fix.
#[test]
fn a_study_split_over_two_files_reports_its_replicates() {
    let dir = TempDir::new("study");
    let store = dir.join("store");
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let file = |name: &str, extra: &str, seeds: &str| {
        let path = dir.join(name);
        let text = smoke.replace("seeds: [0, 1]", &format!("name: study\nseeds: {seeds}\n{extra}"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let run = |path: &Path| {
        let rec = path.with_extension("rrd");
        idrex(&["pipeline", "run", path.to_str().unwrap(), "--store", store.to_str().unwrap(), "--recording", rec.to_str().unwrap()])
    };
    for f in [file("a.yaml", "replicates: 2", "[0, 1]"), file("b.yaml", "first_replicate: 2", "[0, 1]")] {
        let out = run(&f);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    // The recording of a file with two replicates has a view of each replicate's final
    // returns, one series (a point per replicate) per method; its layout holds like any
    // recording's. The second file holds one replicate: no such view.
    let views = crate::recording::check_layout(&dir.join("a.rrd"), |t| !t.contains(" series, legend"));
    assert!(views.iter().any(|v| v.contains("Each replicate's final policy")), "{views:?}");
    let single = crate::recording::check_layout(&dir.join("b.rrd"), |t| !t.contains(" series, legend"));
    assert!(!single.iter().any(|v| v.contains("Each replicate's")), "{single:?}");
    let printed = crate::recording::printed(&dir.join("a.rrd"));
    let methods: Vec<&String> = printed.keys().filter(|e| e.starts_with("/replicates/")).collect();
    assert_eq!(methods.len(), 5, "{methods:?}");
    let report = dir.join("report");
    let rep = idrex(&["report", "--store", store.to_str().unwrap(), "--out", report.to_str().unwrap()]);
    assert!(rep.status.success(), "{}", stderr(&rep));
    assert!(stdout(&rep).contains("### Hopper-v5, study `study`: final policy"), "{}", stdout(&rep));
    let check = r#"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
drex = [r for r in rows if r["method"] == "drex" and r["protocol"] == "final"]
assert len(drex) == 1 and drex[0]["replicates"] == "3" and drex[0]["runs"] == "6", drex
r = drex[0]
assert float(r["mean_ci_low"]) <= float(r["mean"]) <= float(r["mean_ci_high"]), r
assert 0 <= float(r["above_demos_avg"]) <= 1
imp = list(csv.DictReader(open(sys.argv[2])))
assert {(i["method"], i["baseline"]) for i in imp if i["protocol"] == "final"} >= {("drex", "bc"), ("idrex-multi-bc", "drex")}, imp
assert all(0 <= float(i["rliable_probability"]) <= 1 and i["replicates"] == "3" for i in imp), imp
# The paired form: wins of 3, an exact interval around the rate, the sign test, and the
# warning that 3 replicates are few.
for i in imp:
    n = 3 - int(i["paired_ties"])
    assert 0 <= int(i["paired_wins"]) <= n, i
    assert float(i["paired_ci_low"]) <= float(i["paired_rate"]) <= float(i["paired_ci_high"]), i
    assert 0 < float(i["sign_test_p"]) <= 1 and "only 3 replicates" in i["warning"], i
print("ok")
"#;
    let (agg, imp) = (report.join("aggregate.csv"), report.join("improvement.csv"));
    assert_eq!(py(check, &[agg.to_str().unwrap(), imp.to_str().unwrap()]).trim(), "ok");
    // The questions: Holm's correction recomputed here from the uncorrected p, the return's
    // D-REX-against-BC row equal to improvement.csv's.
    let holm = r#"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
imp = [i for i in csv.DictReader(open(sys.argv[2])) if i["protocol"] == "final" and i["method"] == "drex" and i["baseline"] == "bc"]
asked = {(r["method"], r["baseline"], r["measure"]) for r in rows}
assert {("drex", "bc", "return"), ("drex", "bc", "forward"), ("drex", "demonstrations", "return"), ("drex", "demonstrations", "forward")} <= asked, asked
ps = sorted((float(r["sign_test_p"]), i) for i, r in enumerate(rows) if r["sign_test_p"])
m, floor = len(ps), 0.0
for k, (p, i) in enumerate(ps):
    floor = max(floor, min(1.0, (m - k) * p))
    assert abs(float(rows[i]["holm_p"]) - floor) < 1e-3 and int(rows[i]["family"]) == m, (rows[i], floor, m)
r = [r for r in rows if (r["method"], r["baseline"], r["measure"]) == ("drex", "bc", "return")][0]
for c in ["rliable_probability", "rliable_ci_low", "paired_wins", "sign_test_p"]:
    assert r[c] == imp[0][c], (c, r, imp)
print("ok")
"#;
    let questions = report.join("questions.csv");
    assert_eq!(py(holm, &[questions.to_str().unwrap(), imp.to_str().unwrap()]).trim(), "ok");
    assert!(report.join("figures/hopper-v5-study-study-intervals.png").exists());
    assert!(report.join("figures/hopper-v5-study-study-profile.png").exists());
    // Replicate 0's figures and the study's only: no file and no link for replicates 1 and 2.
    let first = dir.join("first");
    let rep = idrex(&[
        "report",
        "--store",
        store.to_str().unwrap(),
        "--out",
        first.to_str().unwrap(),
        "--figures",
        "svg",
        "--replicate-figures",
        "first",
    ]);
    assert!(rep.status.success(), "{}", stderr(&rep));
    let figures = |d: &Path| -> Vec<String> {
        let mut f: Vec<String> =
            std::fs::read_dir(d.join("figures")).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into()).collect();
        f.sort();
        f
    };
    let (all, kept) = (figures(&report), figures(&first));
    assert!(all.iter().any(|f| f.contains("study_r1-")) && all.iter().any(|f| f.contains("study_r2-")), "{all:?}");
    assert!(kept.iter().all(|f| !f.contains("_r1-") && !f.contains("_r2-")), "{kept:?}");
    assert!(kept.iter().any(|f| f == "hopper-v5-study-final.svg") && kept.iter().any(|f| f.ends_with("study-intervals.svg")), "{kept:?}");
    let md = std::fs::read_to_string(first.join("report.md")).unwrap();
    assert!(!md.contains("_r1-") && md.contains("figures/hopper-v5-study-final.svg"), "{md}");

    // Replicate 1 again, with other seeds: two artifacts claim its runs.
    let out = run(&file("c.yaml", "first_replicate: 1", "[5, 6]"));
    assert!(out.status.success(), "{}", stderr(&out));
    let rep = idrex(&["report", "--store", store.to_str().unwrap(), "--out", report.to_str().unwrap()]);
    assert!(
        !rep.status.success() && stderr(&rep).contains("is evaluated twice") && stderr(&rep).contains("first_replicate"),
        "{}",
        stderr(&rep)
    );
    let fresh = dir.join("store2");
    std::fs::create_dir_all(&fresh).unwrap();
    // Replicate 3 of the study from imported demonstrations (an MCAP file another
    // demonstrator of this test recorded), beside generated ones.
    let store_ = idrex::store::Store::open(&store).unwrap();
    let demos = store_.manifests().unwrap().into_iter().find(|m| m.kind == "demos").expect("a demos artifact");
    let imported_demos = dir.join("imported-demos.mcap");
    std::fs::copy(store_.dir(&demos.key).join("rollouts.mcap"), &imported_demos).unwrap();
    let imported = file("e.yaml", "first_replicate: 3", "[0, 1]");
    let text = std::fs::read_to_string(&imported).unwrap();
    assert!(text.contains("demos:\n  episodes: 2\n"));
    std::fs::write(&imported, text.replace("demos:\n  episodes: 2\n", &format!("demos:\n  from: {}\n", imported_demos.display()))).unwrap();
    for f in [file("d.yaml", "replicates: 2", "[0, 1]"), imported] {
        let rec = dir.join("r.rrd");
        let out =
            idrex(&["pipeline", "run", f.to_str().unwrap(), "--store", fresh.to_str().unwrap(), "--recording", rec.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let rep = idrex(&["report", "--store", fresh.to_str().unwrap(), "--out", report.to_str().unwrap()]);
    assert!(!rep.status.success() && stderr(&rep).contains("disagree on the demonstrations"), "{}", stderr(&rep));
}

/// Ant-v5 through every method at the smoke file's budgets: its own demonstrator, BC, D-REX
/// and the three iD-REX variants all report; its rollout files carry the contact term and
/// open in Python's mcap reader with their schema's fields.
#[test]
fn ant_runs_through_every_method() {
    let dir = TempDir::new("ant");
    let store = dir.join("store");
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let file = dir.join("ant.yaml");
    std::fs::write(&file, smoke.replace("env: Hopper-v5", "name: ant-smoke\nenv: Ant-v5")).unwrap();
    let rec = dir.join("ant.rrd");
    let out = idrex(&["pipeline", "run", file.to_str().unwrap(), "--store", store.to_str().unwrap(), "--recording", rec.to_str().unwrap()]);
    assert!(out.status.success(), "{}\n{}", stdout(&out), stderr(&out));
    let report = dir.join("report");
    let rep = idrex(&["report", "--store", store.to_str().unwrap(), "--out", report.to_str().unwrap()]);
    assert!(rep.status.success(), "{}", stderr(&rep));
    let check = r#"
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if r["env"] == "Ant-v5"]
assert {r["method"] for r in rows} == {"bc", "drex", "idrex-interpolation", "idrex-action-noise", "idrex-multi-bc"}, rows
assert all(float(r["mean"]) == float(r["mean"]) for r in rows)
print("ok")
"#;
    assert_eq!(py(check, &[report.join("returns.csv").to_str().unwrap()]).trim(), "ok");
    let mcaps: Vec<String> =
        walk(&store).into_iter().filter(|p| p.extension().is_some_and(|e| e == "mcap")).map(|p| p.display().to_string()).collect();
    let fields = r#"
import json, sys
from mcap.reader import make_reader
steps = 0
for path in sys.argv[1:]:
    r = make_reader(open(path, "rb"))
    for schema, channel, msg in r.iter_messages(topics=["/step"]):
        m = json.loads(msg.data)
        assert set(json.loads(schema.data)["properties"]) >= set(m), (path, set(m))
        assert len(m["obs"]) == 105 and len(m["action"]) == 8 and m["reward_contact"] <= 0, m
        total = m["reward_forward"] + m["reward_ctrl"] + m["reward_survive"] + m["reward_contact"]
        assert abs(total - m["reward"]) < 1e-9, m
        steps += 1
print(steps)
"#;
    let args: Vec<&str> = mcaps.iter().map(String::as_str).collect();
    assert!(py(fields, &args).trim().parse::<usize>().unwrap() > 100);
}

/// `noise.toward: both` gives D-REX's ranked set two sets per level: random-action rollouts
/// (group 0) and zero-action ones (group 1, from their own resets), read back with Python's
/// mcap reader; at epsilon 1 the zero-action Ant never moves a joint and stands the whole
/// episode, the random-action one does not. The T-REX stage learns from both.
#[test]
fn noise_toward_both_ranks_still_rollouts_beside_random_ones() {
    let dir = TempDir::new("toward");
    let store = dir.join("store");
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let file = dir.join("toward.yaml");
    let yaml = smoke
        .replace("env: Hopper-v5", "name: toward-smoke\nenv: Ant-v5")
        .replace("methods: [bc, drex, idrex-interpolation, idrex-action-noise, idrex-multi-bc]", "methods: [bc, drex]")
        .replace(
            "  schedule: [0.0, 0.25, 0.5, 0.75, 1.0]\n  rollouts_per_level: 2",
            "  schedule: [0.0, 1.0]\n  rollouts_per_level: 1\n  toward: both",
        );
    assert!(yaml.contains("toward: both"), "the smoke file's noise block moved: {yaml}");
    std::fs::write(&file, yaml).unwrap();
    let rec = dir.join("toward.rrd");
    let out = idrex(&["pipeline", "run", file.to_str().unwrap(), "--store", store.to_str().unwrap(), "--recording", rec.to_str().unwrap()]);
    assert!(out.status.success(), "{}\n{}", stdout(&out), stderr(&out));
    let mcaps: Vec<String> =
        walk(&store).into_iter().filter(|p| p.extension().is_some_and(|e| e == "mcap")).map(|p| p.display().to_string()).collect();
    let check = r#"
import json, sys
from mcap.reader import make_reader
for path in sys.argv[1:]:
    r = make_reader(open(path, "rb"))
    meta = {m.name: m.metadata for m in r.iter_metadata()}
    episodes = [json.loads(v) for _, v in sorted(meta["idrex.episodes"].items())]
    if not any(e["noise"] == 1.0 for e in episodes):
        continue
    by = {(e["noise"], e["group"]): i for i, e in enumerate(episodes)}
    assert sorted(by) == [(0.0, 0), (0.0, 1), (1.0, 0), (1.0, 1)], by
    assert episodes[by[(1.0, 0)]]["seed"] != episodes[by[(1.0, 1)]]["seed"]
    acts = {}
    for schema, channel, msg in r.iter_messages(topics=["/step"]):
        m = json.loads(msg.data)
        acts.setdefault(m["episode"], []).append(m["action"])
    still, rand = acts[by[(1.0, 1)]], acts[by[(1.0, 0)]]
    assert all(a == [0.0] * 8 for a in still), still[:3]
    assert len(still) == 1000 and episodes[by[(1.0, 1)]]["truncated"], len(still)
    assert sum(abs(x) for a in rand for x in a) > 0.1 * 8 * len(rand)
    print("ok")
"#;
    let args: Vec<&str> = mcaps.iter().map(String::as_str).collect();
    assert_eq!(py(check, &args).trim(), "ok", "exactly one ranked set with both kinds of rollout");
}

/// The locked test set's committed archives (`report/r<R>/manifests.ndjson.zst`, replicate R's
/// stages) rebuild, with no store, every report committed as the replicates landed: each
/// `report/r<R>/` (and `report/final/`) from exactly the archives of the replicates it
/// covered, every row of its tables, to every digit (returns, protocols, aggregate,
/// improvement, demonstrations); the tables whose columns grew since (reward accuracy,
/// clones) column by column. Those reports' words and figures are not committed twice: this
/// is what rebuilds them.
#[test]
fn the_committed_archives_rebuild_the_locked_reports() {
    let dir = TempDir::new("archives");
    let reports = repo("analysis/results/locked/report");
    let mut dirs: Vec<std::path::PathBuf> = std::fs::read_dir(&reports).unwrap().flatten().map(|e| e.path()).collect();
    dirs.sort();
    let archive = |r: usize| reports.join(format!("r{r}/manifests.ndjson.zst"));
    assert!((0..10).all(|r| archive(r).is_file()), "an archive per replicate");
    // A row's table is its second column: `locked-test` for replicate 0, `locked-test/rR` after.
    let replicate = |line: &str| -> Option<usize> {
        match line.split(',').nth(1)?.strip_prefix("locked-test")? {
            "" => Some(0),
            r => r.strip_prefix("/r")?.parse().ok(),
        }
    };
    let mut rebuilt = 0;
    for d in &dirs {
        let committed = |t: &str| std::fs::read_to_string(d.join(t)).ok();
        let covered: std::collections::BTreeSet<usize> = committed("returns.csv").unwrap().lines().skip(1).filter_map(replicate).collect();
        let out = dir.join(d.file_name().unwrap().to_str().unwrap());
        let mut args = vec!["report".to_string(), "--store".into(), dir.join("none").display().to_string()];
        for r in &covered {
            args.extend(["--archive".to_string(), archive(*r).display().to_string()]);
        }
        args.extend(["--out".to_string(), out.display().to_string(), "--format".into(), "csv".into()]);
        let res = idrex(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(res.status.success(), "{}", stderr(&res));
        for table in ["returns.csv", "protocols.csv", "aggregate.csv", "improvement.csv", "demos.csv"] {
            let Some(theirs) = committed(table) else { continue };
            let ours = std::fs::read_to_string(out.join(table)).unwrap();
            let ours: std::collections::BTreeSet<&str> = ours.lines().collect();
            for line in theirs.lines() {
                assert!(ours.contains(line), "{}/{table}: the archives of {covered:?} do not give the row\n{line}", d.display());
            }
        }
        for table in ["reward_accuracy.csv", "clones.csv"] {
            let Some(theirs) = committed(table) else { continue };
            let ours = std::fs::read_to_string(out.join(table)).unwrap();
            let (ours_head, theirs_head) = (ours.lines().next().unwrap(), theirs.lines().next().unwrap());
            let columns: Vec<Option<usize>> = theirs_head.split(',').map(|c| ours_head.split(',').position(|o| o == c)).collect();
            assert!(columns.iter().all(Option::is_some), "{}/{table}: a column is gone: {theirs_head}", d.display());
            for (theirs_row, ours_row) in theirs.lines().zip(ours.lines()).skip(1) {
                let ours_row: Vec<&str> = ours_row.split(',').collect();
                for (cell, at) in theirs_row.split(',').zip(&columns) {
                    let mine = ours_row[at.unwrap()];
                    // bc_val_loss went through f32 in the reports of replicates 0-5 and 7.
                    let close = match (cell.parse::<f64>(), mine.parse::<f64>()) {
                        (Ok(a), Ok(b)) => (a - b).abs() <= 1e-6 * a.abs().max(b.abs()),
                        _ => cell == mine,
                    };
                    assert!(close, "{}/{table}: {cell} against {mine} in\n{theirs_row}", d.display());
                }
            }
            assert_eq!(theirs.lines().count(), ours.lines().count(), "{}/{table}", d.display());
        }
        rebuilt += 1;
    }
    assert_eq!(rebuilt, 11, "r0-r9 and final");
}

/// Ant-v5's held-out set: the report built from its committed archive alone holds every row
/// of the committed report's tables, cell for cell under each committed column (a column a
/// later report adds, such as the reward bench's, is not the archive's to give).
#[test]
fn the_committed_ant_archive_rebuilds_its_report() {
    let dir = TempDir::new("ant-archive");
    let report = repo("analysis/results/ant/report/test");
    let archive = report.join("manifests.ndjson.zst");
    let (store, out) = (dir.join("none").display().to_string(), dir.join("out").display().to_string());
    let res = idrex(&["report", "--store", &store, "--archive", archive.to_str().unwrap(), "--out", &out, "--format", "csv"]);
    assert!(res.status.success(), "{}", stderr(&res));
    for table in ["returns.csv", "protocols.csv", "reward_accuracy.csv", "aggregate.csv"] {
        let ours = std::fs::read_to_string(dir.join("out").join(table)).unwrap();
        let committed = std::fs::read_to_string(report.join(table)).unwrap();
        assert!(committed.lines().count() > 1, "{table}: no rows");
        let (theirs_head, ours_head) = (committed.lines().next().unwrap(), ours.lines().next().unwrap());
        let at: Vec<usize> = theirs_head
            .split(',')
            .map(|c| ours_head.split(',').position(|o| o == c).unwrap_or_else(|| panic!("{table}: the column {c} is gone")))
            .collect();
        let pick = |l: &str| -> Vec<String> {
            let cells: Vec<&str> = l.split(',').collect();
            at.iter().map(|&i| cells.get(i).copied().unwrap_or_default().to_string()).collect()
        };
        for line in committed.lines().skip(1) {
            let want: Vec<String> = line.split(',').map(String::from).collect();
            assert!(ours.lines().skip(1).any(|l| pick(l) == want), "{table}: the archive does not give the committed row\n{line}");
        }
    }
}

/// The second locked set's final report is what its 40 committed archives (ten replicates of
/// four tasks) give: every row of its tables, the 20 declared questions with their Holm p among
/// them, so a later report binary that answers differently fails here.
#[test]
fn the_committed_archives_rebuild_the_second_locked_report() {
    let dir = TempDir::new("locked2-archives");
    let reports = repo("analysis/results/locked2/report");
    let mut args = vec!["report".to_string(), "--store".into(), dir.join("none").display().to_string()];
    for r in 0..10 {
        for task in ["halfcheetah", "hopper", "walker2d", "ant"] {
            let archive = reports.join(format!("r{r}/{task}.ndjson.zst"));
            assert!(archive.is_file(), "{}", archive.display());
            args.extend(["--archive".to_string(), archive.display().to_string()]);
        }
    }
    let out = dir.join("out");
    args.extend(["--out".to_string(), out.display().to_string(), "--format".into(), "csv".into()]);
    let res = idrex(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(res.status.success(), "{}", stderr(&res));
    let final_report = reports.join("final");
    for table in ["returns.csv", "protocols.csv", "aggregate.csv", "improvement.csv", "questions.csv", "correlations.csv", "terms.csv"] {
        let ours = std::fs::read_to_string(out.join(table)).unwrap();
        let committed = std::fs::read_to_string(final_report.join(table)).unwrap();
        assert!(committed.lines().count() > 1, "{table}: no rows");
        assert_eq!(ours.lines().count(), committed.lines().count(), "{table}: rows");
        for line in committed.lines() {
            assert!(ours.lines().any(|l| l == line), "{table}: the archives do not give the committed row\n{line}");
        }
    }
    let questions = std::fs::read_to_string(final_report.join("questions.csv")).unwrap();
    assert_eq!(questions.lines().count(), 21, "the 20 declared questions");
    // The last two columns: the family's size, then the verdict.
    assert!(questions.lines().skip(1).all(|l| l.rsplit(',').nth(1) == Some("20")), "each corrected over the family of 20: {questions}");
}

/// On a machine whose store never held the locked test set, its committed archives still lock
/// its seeds: another configuration on them is refused before any stage runs.
#[test]
fn a_committed_archive_locks_the_test_seeds_on_an_empty_store() {
    let dir = TempDir::new("archive-lock");
    let locked = repo("analysis/results/locked");
    // The locked file with another ceiling: the same seeds, another learned reward. Its
    // demonstrations come from idrex's own demonstrator instead of the outside NPZ files, so
    // the check holds on a machine (or a clone) without them: the lock is on the seeds.
    let locked_text = std::fs::read_to_string(locked.join("test.yaml")).unwrap();
    let (head, tail) = locked_text.split_once("demos:\n").unwrap();
    let tail = &tail[tail.find("\nreward:").unwrap() + 1..];
    let text = format!("{head}{tail}")
        .replace("name: locked-test", "name: another-look")
        .replace("role: test", "role: study")
        .replace("ceiling: 0.75", "ceiling: 0.5");
    assert!(!text.contains("drex-demos") && text.contains("seeds: [500, 501, 502]"), "{text}");
    let file = dir.join("another.yaml");
    std::fs::write(&file, text).unwrap();
    let archive = locked.join("report/r6/manifests.ndjson.zst");
    let store = dir.join("store");
    let args = ["pipeline", "run", file.to_str().unwrap(), "--only-replicate", "6", "--store", store.to_str().unwrap()];
    let out = idrex(&[&args[..], &["--archive", archive.to_str().unwrap()]].concat());
    assert!(!out.status.success(), "{}", stdout(&out));
    let err = stderr(&out);
    assert!(err.contains("another.yaml") && err.contains("locked test set `locked-test`") && err.contains("--reuse-test-set"), "{err}");
    fn manifests(d: &Path) -> usize {
        std::fs::read_dir(d)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path())
            .map(|p| if p.is_dir() { manifests(&p) } else { (p.file_name().unwrap() == "manifest.json") as usize })
            .sum()
    }
    assert_eq!(manifests(&store), 0, "nothing ran");
}
