//! The clone filter idrex ships (`idrex.multi_bc_filter: held-out-reward`) end to end, on
//! the smoke file's budget: multi-BC's judge is trained beside D-REX's reward on the same
//! ranked set from its own seed, the stage loads it, scores every clone under it and keeps
//! exactly the clones that score at least the previous set's least noisy rollouts. The seeds
//! are chosen so that it keeps one clone and rejects two (the bytes, and so the decisions, are
//! the same on every processor).
use std::collections::BTreeSet;
use std::path::Path;

use crate::util::{TempDir, idrex, repo, stderr};

fn manifests(store: &Path) -> Vec<serde_json::Value> {
    std::fs::read_dir(store)
        .unwrap()
        .flatten()
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| serde_json::from_str(&std::fs::read_to_string(e.path().join("manifest.json")).unwrap()).unwrap())
        .collect()
}

/// The clones' groups in a rollout file of an artifact.
fn groups(store: &Path, key: &str, file: &str) -> BTreeSet<usize> {
    let path = store.join(key).join(file);
    let r = idrex::rollout::mcap::parse(&path, &std::fs::read(&path).unwrap()).unwrap();
    r.trajectories.iter().filter(|t| t.meta.source.starts_with("multi-bc/")).map(|t| t.meta.group).collect()
}

#[test]
fn the_held_out_filter_keeps_the_clones_its_judge_scores_well_and_rejects_the_others() {
    let dir = TempDir::new("clone-filter");
    let store = dir.join("store");
    let out = idrex(&[
        "pipeline",
        "run",
        repo("pipelines/smoke.yaml").to_str().unwrap(),
        "--store",
        store.to_str().unwrap(),
        "--recording",
        dir.join("r.rrd").to_str().unwrap(),
        "-S",
        "methods=[drex,idrex-multi-bc]",
        "-S",
        "idrex.multi_bc_filter=held-out-reward",
        "-S",
        "seeds=[3,4,5]",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let all = manifests(&store);
    let node = |name: &str| all.iter().find(|m| m["node"] == name).unwrap_or_else(|| panic!("no {name} in the store"));
    let (reward, judge, rollouts) = (node("drex/trex"), node("idrex-multi-bc/k1/judge"), node("idrex-multi-bc/k1/rollouts"));

    // The judge: D-REX's reward trained again on the same sets from its own seed.
    assert_eq!(judge["kind"], "trex");
    assert_eq!(judge["params"], reward["params"]);
    assert_eq!(judge["inputs"], reward["inputs"]);
    assert_ne!(judge["seed"], reward["seed"]);
    assert_ne!(judge["outputs"], reward["outputs"], "the judge is another reward");

    // The stage read it, scored every clone under it, and kept exactly the ones scoring >= 0.
    assert_eq!(rollouts["inputs"]["judge"], judge["key"]);
    assert_eq!(rollouts["inputs"]["reward"], reward["key"]);
    let clones = rollouts["metrics"]["clones"].as_array().unwrap();
    assert_eq!(clones.len(), 3);
    let kept: Vec<bool> = clones.iter().map(|c| c["kept"].as_bool().unwrap()).collect();
    assert_eq!(kept, [false, false, true], "{clones:#?}");
    for c in clones {
        let score = c["score"].as_f64().expect("every clone scored");
        assert!(score.is_finite());
        assert_eq!(c["kept"].as_bool().unwrap(), score >= 0.0, "{c:#?}");
        assert_ne!(c["score"], c["previous_reward_score"], "scored under the judge, not the previous reward");
    }

    // The ranked set holds the kept clone's rollouts only; the rejected clones' are set aside.
    let key = rollouts["key"].as_str().unwrap();
    assert_eq!(groups(&store, key, "rollouts.mcap"), BTreeSet::from([2]));
    assert!(groups(&store, key, "clones.mcap").is_superset(&BTreeSet::from([0, 1])));
    // And the next reward learns from that set.
    let next = node("idrex-multi-bc/k1/trex");
    assert!(next["inputs"].as_object().unwrap().values().any(|v| v == &rollouts["key"]));

    // The report says what the filter decided.
    let report = dir.join("report");
    let out = idrex(&["report", "--store", store.to_str().unwrap(), "--out", report.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("The filter kept 1 of 3 clones."), "{md}");
}
