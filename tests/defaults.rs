//! The shipped defaults and the files that reproduce the original code: a file that names no
//! reward option gets the recommended reward; `pipelines/*-original.yaml`, and any file that
//! spells the old values out, keep the keys the code gave them when the original's choices
//! were the defaults (commit 1e0361d), whatever the defaults become. The goldens are sha256s
//! of what 1e0361d's `idrex pipeline plan` printed (`name key[..12]` lines) for the same text.
use std::path::Path;

use idrex::pipeline::{Pipeline, expand};
use sha2::{Digest, Sha256};

use crate::util::{TempDir, idrex, repo, stderr, stdout};

/// The original's reward, spelled out.
const OLD_REWARD: &str = "reward:\n  level: running\n  ceiling: none\n";

/// Every node's name and key prefix, a line each, and the sha256 of those lines: what
/// `idrex pipeline plan` printed for the file at 1e0361d.
fn listing(file: &str, text: &str) -> (String, String) {
    let g = expand(&Pipeline::parse(Path::new(file), text).unwrap_or_else(|e| panic!("{file}: {e}"))).unwrap();
    let keys = g.keys();
    let lines: String = g.nodes.iter().map(|n| format!("{} {}\n", n.name, &keys[&n.name][..12])).collect();
    let digest = Sha256::digest(lines.as_bytes()).iter().map(|b| format!("{b:02x}")).collect();
    (lines, digest)
}

/// An original file with generated demonstrations in place of the outside data file (whose
/// bytes are not the repository's), so that the test runs anywhere; every stage after the
/// demonstrations keeps its original settings.
fn original(name: &str) -> String {
    let text = std::fs::read_to_string(repo("pipelines").join(name)).unwrap();
    let lines: Vec<&str> = text.lines().map(|l| if l.starts_with("  from: ") { "  episodes: 1" } else { l }).collect();
    assert!(lines.contains(&"  episodes: 1"), "{name} imports its demonstrations");
    lines.join("\n") + "\n"
}

#[test]
fn original_files_keep_the_original_keys() {
    // sha256 of `name key[..12]` lines from 1e0361d's `idrex pipeline plan` of the same text.
    for (name, want) in [("halfcheetah-original.yaml", HALFCHEETAH_ORIGINAL), ("hopper-original.yaml", HOPPER_ORIGINAL)] {
        let text = original(name);
        assert!(text.contains(OLD_REWARD.trim_start_matches("reward:\n")), "{name} spells out the original reward");
        let (lines, got) = listing(name, &text);
        assert_eq!(got, want, "{name}: a stage key changed:\n{lines}");
    }
}

#[test]
fn a_file_without_reward_options_gets_the_recommended_reward() {
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    assert!(!smoke.contains("reward:"), "the smoke pipeline names no reward option");
    let (_, old) = listing("smoke.yaml", &format!("{smoke}{OLD_REWARD}"));
    assert_eq!(old, SMOKE_OLD, "the old spelling gives 1e0361d's keys");
    let (_, default) = listing("smoke.yaml", &smoke);
    let (_, spelled) = listing("smoke.yaml", &format!("{smoke}reward:\n  level: ranked-floor\n  ceiling: 0.75\n"));
    assert_eq!(default, spelled, "the defaults are the recommended reward");
    assert_ne!(default, old);
}

/// A run stored under the old spelling is found again by the same file: nothing recomputes.
#[test]
fn a_run_under_the_old_spelling_is_reused_from_the_store() {
    let dir = TempDir::new("old-spelling");
    // Named as the smoke pipeline, so its evaluations' keys (which name their table) are too.
    let file = dir.join("smoke.yaml");
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    std::fs::write(&file, format!("{smoke}{OLD_REWARD}")).unwrap();
    let store = dir.join("store");
    let run = || {
        let out = idrex(&[
            "pipeline",
            "run",
            file.to_str().unwrap(),
            "--store",
            store.to_str().unwrap(),
            "--recording",
            dir.join("r.rrd").to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}\n{}", stdout(&out), stderr(&out));
        stdout(&out)
    };
    let first = run();
    assert!(first.contains(" computed") && !first.contains(" 0 computed"), "{first}");
    let again = run();
    assert!(again.contains(" 0 computed"), "{again}");
    // The store's keys are the 1e0361d keys of the same text.
    let plan = idrex(&["pipeline", "plan", file.to_str().unwrap(), "--store", store.to_str().unwrap()]);
    let plan = stdout(&plan);
    let lines: String = plan
        .lines()
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.len() >= 3 && (f[0] == "stored" || f[0] == "missing")).then(|| {
                assert_eq!(f[0], "stored", "{l}");
                format!("{} {}\n", f[2], f[1])
            })
        })
        .collect();
    let digest: String = Sha256::digest(lines.as_bytes()).iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(digest, SMOKE_OLD, "{plan}");
}

const HALFCHEETAH_ORIGINAL: &str = "c3ab36d70a0fd853b8870839da42e0537d5c61f194e3092135672a24fa9a7bd0";
const HOPPER_ORIGINAL: &str = "1e51c26d4a162d82d072bd4222ba7b1f8f11d4762a5e8835b4b61a038e18527a";
const SMOKE_OLD: &str = "7b1bf60e2ff6e7c78110c49a18358734cf32607de098d35b0133aafa9fa8b68c";
