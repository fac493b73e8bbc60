//! Issue 77's screen reader (`analysis/screen.py`) on the real plan of the round-3 tuning file:
//! it finds every variant's probe by the plan's keys and applies the declared rule (at least 7
//! of 10 replicates above `shipped`; the best passing go to PPO).
use crate::util::{TempDir, idrex, python_with_input, repo, stderr, stdout};

#[test]
fn the_screen_reads_the_plan_and_applies_the_rule() {
    let dir = TempDir::new("screen");
    let store = dir.join("store");
    std::fs::create_dir_all(&store).unwrap();
    let file = repo("analysis/results/reward-search3/tuning-halfcheetah.yaml");
    let plan = idrex(&["pipeline", "plan", file.to_str().unwrap(), "--store", store.to_str().unwrap()]);
    assert!(plan.status.success(), "{}", stderr(&plan));
    let plan = stdout(&plan);
    // A probe per variant and replicate, stored under its planned key: `aligned` above the
    // baseline on 8 of 10 (passes), `ou` on 6 (fails), every other variant tied with it.
    // Replicates 5-9 go to an archive instead (what `idrex export` writes, one manifest per
    // line): the screen reads the two together as it would the committed replicates.
    let archive = dir.join("r5-9.ndjson");
    let mut archived = String::new();
    let mut probes = 0;
    for line in plan.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        let (Some(key), Some(node)) = (f.get(1), f.get(2)) else { continue };
        let Some(head) = node.strip_suffix("/drex/trex/probe") else { continue };
        let (variant, r) = head.rsplit_once('/').unwrap_or(("shipped", head));
        let r: u32 = r.trim_start_matches('r').parse().unwrap();
        let score = match (variant, r) {
            ("aligned", 0..8) => 110.0,
            ("aligned", _) => 90.0,
            ("ou", 0..6) => 120.0,
            ("ou", _) => 80.0,
            _ => 100.0,
        };
        let key = format!("{key}{}", "0".repeat(52));
        let manifest = format!(r#"{{"key":"{key}","kind":"probe","node":"{node}","metrics":{{"true_return":{score}}},"wall_s":15.0}}"#);
        if r >= 5 {
            archived.push_str(&(manifest + "\n"));
        } else {
            let at = store.join(&key);
            std::fs::create_dir_all(&at).unwrap();
            std::fs::write(at.join("manifest.json"), manifest).unwrap();
        }
        probes += 1;
    }
    std::fs::write(&archive, archived).unwrap();
    assert_eq!(probes, 90, "9 variants x 10 replicates:\n{plan}");
    let only_store = python_with_input(&[repo("analysis/screen.py"), store.clone()], &plan);
    assert!(stdout(&only_store).contains("aligned,5,5,5,"), "the store alone holds replicates 0-4: {}", stdout(&only_store));
    let out = python_with_input(&[repo("analysis/screen.py"), store.clone(), archive], &plan);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = stdout(&out);
    let row = |v: &str| csv.lines().find(|l| l.starts_with(&format!("{v},"))).unwrap_or_else(|| panic!("{v}:\n{csv}")).to_string();
    assert_eq!(csv.lines().count(), 10, "{csv}");
    assert!(row("aligned").starts_with("aligned,10,10,8,10.0,0.0547,110.0,True,True,"), "{csv}");
    assert!(row("ou").starts_with("ou,10,10,6,20.0,0.3770,120.0,False,,"), "{csv}");
    assert!(row("held").starts_with("held,10,10,0,0.0,,100.0,False,,"), "{csv}");
    // The median paired difference's interval, d(2) to d(9) of the ten sorted differences.
    assert!(row("aligned").ends_with(",-10.0,10.0,0.979") && row("ou").ends_with(",-20.0,20.0,0.979"), "{csv}");
    assert!(row("shipped").ends_with(",,,"), "{csv}");
}
