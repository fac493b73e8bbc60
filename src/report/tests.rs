//! The report's tables on a fixed small store: manifests written out here, as the stages
//! would have, for one study of two replicates on Hopper (BC, D-REX with checkpoints and a
//! learned reward's accuracy, the demonstrations), every number checkable by hand.
use std::collections::BTreeMap;

use super::*;
use crate::algo::scoring::{CheckpointEval, LearnedScore};
use crate::env::EnvId;
use crate::pipeline::config::Method;
use crate::pipeline::stage::demos::DemosParams;
use crate::pipeline::stage::eval::{EvalMetrics, EvalParams, RewardAccuracy};
use crate::pipeline::stage::{Metrics, Params, RolloutSummary};
use crate::stats::ReturnStats;
use crate::stats::{pearson, spearman};

fn manifest(key: &str, params: &Params, metrics: &Metrics, inputs: &[(&str, &str)]) -> Manifest {
    Manifest {
        key: key.into(),
        kind: params.kind().name().into(),
        version: params.kind().version(),
        node: key.into(),
        params: params.to_json(),
        inputs: inputs.iter().map(|(r, k)| (r.to_string(), k.to_string())).collect(),
        metrics: metrics.to_json(),
        ended_unix: 1.0,
        wall_s: 1.0,
        idrex_version: "test".into(),
        ..Default::default()
    }
}

fn summary(returns: &[f64]) -> RolloutSummary {
    RolloutSummary { stats: ReturnStats::of(returns), returns: returns.to_vec(), lengths: vec![1000; returns.len()], terms: None }
}

/// A checkpoint whose pessimistic learned score is `learned`.
fn checkpoint(step: usize, returns: &[f64], learned: f64) -> CheckpointEval {
    CheckpointEval { step, returns: returns.to_vec(), learned: Some(LearnedScore { mean: learned, pessimistic: learned, spread: 0.0 }) }
}

/// Replicate r: demonstrations averaging 1000 + 100 r; BC one run at 900 + 100 r; D-REX two
/// runs, each with checkpoints at steps 0 and 100 (the final policy is step 100's), the
/// learned reward preferring step 0 on replicate 1 only.
fn store() -> Artifacts {
    let mut by_key = BTreeMap::new();
    let mut add = |m: Manifest| {
        by_key.insert(m.key.clone(), m);
    };
    for r in [1usize, 2] {
        let base = 100.0 * r as f64;
        let demos = format!("demos{r}");
        let dp = Params::Demos(DemosParams { env: EnvId::Hopper, episodes: 2, acting: Default::default(), noise_scale: 1.0 });
        add(manifest(&demos, &dp, &Metrics::Demos(summary(&[950.0 + base, 1050.0 + base])), &[]));
        let eval = |method, run| EvalParams {
            env: EnvId::Hopper,
            episodes: 2,
            pipeline: "fixture".into(),
            method,
            iteration: if method == Method::Bc { 0 } else { 1 },
            run,
            replicate: r,
            variant: None,
        };
        let bc = EvalMetrics { summary: summary(&[890.0 + base, 910.0 + base]), reward: None, checkpoints: vec![] };
        add(manifest(&format!("bc{r}"), &Params::Eval(eval(Method::Bc, 0)), &Metrics::Eval(bc), &[("demos", &demos)]));
        for run in 0..2 {
            let late = 2000.0 + base + 200.0 * run as f64;
            let early = 1500.0 + base;
            let prefers_early = if r == 1 { 1.0 } else { -1.0 };
            let x = EvalMetrics {
                summary: summary(&[late - 10.0, late + 10.0]),
                reward: Some(RewardAccuracy { predicted_returns: vec![1.0, 2.0], spearman: 1.0, pearson: 0.5, pairwise_accuracy: 1.0 }),
                checkpoints: vec![checkpoint(0, &[early, early], prefers_early), checkpoint(100, &[late - 10.0, late + 10.0], 0.0)],
            };
            add(manifest(&format!("drex{r}-{run}"), &Params::Eval(eval(Method::Drex, run)), &Metrics::Eval(x), &[("demos", &demos)]));
        }
    }
    Artifacts::of(by_key.into_values())
}

fn row<'a>(t: &'a Tables, pipeline: &str, method: &str, protocol: Protocol) -> &'a ProtocolRow {
    t.protocols
        .iter()
        .find(|r| r.pipeline == pipeline && r.method == method && r.protocol == protocol)
        .unwrap_or_else(|| panic!("no row {pipeline} {method} {protocol:?}"))
}

#[test]
fn each_table_has_its_rows_and_numbers() {
    let t = build(&store()).unwrap();
    // One row per table and method, per table for the demonstrations.
    assert_eq!(t.returns.len(), 4, "{:?}", t.returns);
    let drex1 = t.returns.iter().find(|r| r.pipeline == "fixture/r1" && r.method == "drex").unwrap();
    // Runs at 2100 ± 10 and 2300 ± 10: four episodes, the best run 2300.
    assert_eq!((drex1.mean, drex1.episodes, drex1.runs, drex1.best_run_avg), (2200.0, 4, 2, 2300.0));
    assert!((drex1.std - 10_100.0f64.sqrt()).abs() < 1e-9, "population std over runs x episodes: {}", drex1.std);
    assert_eq!(t.demos.iter().map(|d| d.demos_avg).collect::<Vec<_>>(), vec![1100.0, 1200.0]);
    assert_eq!(t.accuracy.len(), 2, "one row per table's D-REX: {:?}", t.accuracy);
    assert_eq!((t.accuracy[0].pearson, t.accuracy[0].runs, t.accuracy[0].reward_capped), (0.5, 2, None), "no PPO run behind the fixture");
    // Every file from the same rows: a header the readers know, one line per row.
    let files = t.files();
    let stems: Vec<&str> = files.iter().map(|f| f.0).collect();
    assert_eq!(stems, ["returns", "demos", "reward_accuracy", "protocols", "aggregate", "improvement"]);
    let returns = files[0].1.csv();
    assert!(returns.starts_with("env,pipeline,method,mean,std,episodes,best_run_avg,runs\n"), "{returns}");
    assert!(returns.contains("Hopper-v5,fixture/r1,drex,2200.0,"), "{returns}");
    let json: serde_json::Value = serde_json::from_str(&files[3].1.json()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), t.protocols.len());
    // Per table (replicate 1 is `fixture/r1`), per method, per protocol.
    let final1 = row(&t, "fixture/r1", "drex", Protocol::Final);
    assert_eq!(final1.run_means, vec![2100.0, 2300.0]);
    assert_eq!(final1.stats.mean, 2200.0);
    assert_eq!(final1.step, None);
    let truth = row(&t, "fixture/r1", "drex", Protocol::BestByGroundTruth);
    assert_eq!((truth.step, truth.stats.mean), (Some(100), 2200.0));
    let free1 = row(&t, "fixture/r1", "drex", Protocol::GroundTruthFree);
    assert_eq!((free1.step, free1.stats.mean, free1.gap_to_best), (Some(0), 1600.0, Some(600.0)));
    let free2 = row(&t, "fixture/r2", "drex", Protocol::GroundTruthFree);
    assert_eq!((free2.step, free2.gap_to_best), (Some(100), Some(0.0)));
    assert_eq!(row(&t, "fixture/r2", "bc", Protocol::Final).stats.mean, 1100.0);
    assert_eq!(t.demo_returns[&("Hopper-v5".to_string(), "fixture/r2".to_string())], vec![1150.0, 1250.0]);
}

#[test]
fn a_study_of_two_replicates_is_aggregated_over_them() {
    let t = build(&store()).unwrap();
    let agg = |method: &str, protocol: Protocol| {
        t.aggregate.iter().find(|a| a.study == "fixture" && a.method == method && a.protocol == protocol).unwrap()
    };
    let drex = agg("drex", Protocol::Final);
    assert_eq!((drex.replicates, drex.runs), (2, 4));
    // Replicate scores 2200 and 2300: the mean of each replicate's run means.
    assert_eq!(drex.scores, vec![(1, 2200.0), (2, 2300.0)]);
    assert_eq!(drex.mean, 2250.0);
    assert!(drex.mean_ci.0 >= 2100.0 && drex.mean_ci.1 <= 2400.0 && drex.mean_ci.0 < drex.mean_ci.1, "{:?}", drex.mean_ci);
    assert_eq!((drex.above_demos_avg.k, drex.above_demos_avg.n), (2, 2));
    let bc = agg("bc", Protocol::Final);
    assert_eq!(bc.scores, vec![(1, 1000.0), (2, 1100.0)]);
    // Demonstrations average 1100 and 1200: BC is above neither.
    assert_eq!(bc.above_demos_avg.k, 0);
    // D-REX against BC: above it on both replicates; every pair agrees.
    let imp = t
        .improvement
        .iter()
        .find(|i| i.study == "fixture" && i.method == "drex" && i.baseline == "bc" && i.protocol == Protocol::Final)
        .unwrap();
    assert_eq!((imp.improvement.unpaired, imp.improvement.wins, imp.improvement.pairs), (1.0, 2, 2));
    assert_eq!(imp.improvement.unpaired_ci, (1.0, 1.0));
    let md = markdown(&t);
    assert!(md.contains("## The answer") && md.contains("Hopper-v5, fixture (2 replicates)"), "{md}");
    assert!(md.contains("| Hopper-v5 | fixture/r1 | 1100.0 | 1150.0 | 1000.0 ± 10.0 (1000.0, 2 episodes) | 2200.0 ± 100.5 (2300.0, 2 runs, 4 episodes) | missing |"), "{md}");
    assert!(md.contains("2 of 2") && md.contains("only 2 replicates"), "{md}");
    // The answer's D-REX row: against BC in both forms; D-REX and K - 1 do not apply.
    let answer = &md[..md.find("## How often").unwrap_or(md.len())];
    assert!(answer.contains("| against BC | against D-REX | against K - 1 |"), "{answer}");
    assert!(answer.contains("| D-REX | 2250.0 [") && answer.contains("| P 1.00 [1.00, 1.00]; 2 of 2 [0.16, 1.00], p = 0.250 ⚠ only 2 replicates; every pair agrees, so the bootstrap interval is a point | - | - | 2 of 2 (p = 0.250"), "{answer}");
}

#[test]
fn a_study_whose_files_disagree_on_the_demonstrations_is_refused() {
    let imported = Params::DemosImport(crate::pipeline::stage::demos::ImportParams {
        env: EnvId::Hopper,
        path: "d.npz".into(),
        sha256: "ab".repeat(32),
    });
    let m = manifest("demos2", &imported, &Metrics::DemosImport(summary(&[1.0])), &[]);
    // Replicate 2's demonstrations replaced by an imported file's.
    let s = Artifacts::of(store().iter().filter(|x| x.key != "demos2").cloned().chain([m]));
    let err = build(&s).err().expect("refused").to_string();
    assert!(err.contains("disagree on the demonstrations"), "{err}");
}

#[test]
fn the_previous_iteration_is_named_from_a_label_past_k_2() {
    assert_eq!(previous_iteration(&method_label(Method::IdrexMultiBc, 3)).as_deref(), Some("idrex-multi-bc"));
    assert_eq!(previous_iteration(&method_label(Method::IdrexMultiBc, 4)).as_deref(), Some("idrex-multi-bc (k=3)"));
    for none in [method_label(Method::IdrexMultiBc, 2), method_label(Method::Drex, 1), "nope (k=3)".into(), "drex (k=x)".into()] {
        assert_eq!(previous_iteration(&none), None, "{none}");
    }
}

#[test]
fn the_reward_is_correlated_with_the_truth_over_a_runs_checkpoints() {
    let ckpt = |step, truth: f64, learned: Option<f64>| CheckpointEval {
        step,
        returns: vec![truth - 1.0, truth + 1.0],
        learned: learned.map(|mean| LearnedScore { mean, pessimistic: 0.0, spread: 0.0 }),
    };
    // The learned return rises with the truth, but not in proportion: ranks agree exactly,
    // the linear fit does not.
    let run: Vec<_> =
        [(0, 100.0, 1.0), (1, 200.0, 2.0), (2, 300.0, 3.0), (3, 400.0, 30.0)].into_iter().map(|(s, t, l)| ckpt(s, t, Some(l))).collect();
    assert_eq!(over_checkpoints(&run, spearman), 1.0);
    let r = over_checkpoints(&run, pearson);
    // Pearson of (1, 2, 3, 30) with (100, 200, 300, 400) (numpy.corrcoef): 0.8101.
    assert!((r - 0.8101).abs() < 1e-4, "{r}");
    let unscored = [ckpt(0, 100.0, Some(1.0)), ckpt(1, 200.0, None)];
    assert!(over_checkpoints(&unscored, pearson).is_nan());
}
