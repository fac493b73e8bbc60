//! The reward bench on real MuJoCo models: a HalfCheetah bank built twice (`--jobs 1` and
//! `--jobs 2`, the same bytes), a hand-written reward that pays forward velocity scoring high
//! on it and one that pays still joints scoring low; and the smoke pipeline with a bank, whose
//! report and `idrex bank score` carry every learned reward's scores, and a probe runs beside
//! every reward PPO trains on.
use std::path::{Path, PathBuf};

use idrex::algo::bank::{BankScore, GaitClass, score};
use idrex::data::Trajectory;
use idrex::pipeline::stage::bank::read_bank;

use crate::util::{TempDir, idrex, repo, stderr, stdout};

/// A small HalfCheetah bank: PPO long enough to run forward and backward at a few speeds.
const BANK: &str = "version: 1\nenv: HalfCheetah-v5\nseeds: [0]\nmethods: [bc, drex]\nbank:\n  steps: 204800\n  backward_steps: 102400\n  \
                    checkpoints: 4\n  backward_checkpoints: 2\n  episodes: 1\n  epsilon: [0.5]\n  smooth: [0.5]\n  still: 2\n  random: 2\n";

fn manifests(store: &Path) -> Vec<(PathBuf, serde_json::Value)> {
    let mut out: Vec<(PathBuf, serde_json::Value)> = std::fs::read_dir(store)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|d| d.join("manifest.json").is_file())
        .map(|d| {
            let m = serde_json::from_str(&std::fs::read_to_string(d.join("manifest.json")).unwrap()).unwrap();
            (d, m)
        })
        .collect();
    out.sort_by(|a, b| a.1["key"].as_str().cmp(&b.1["key"].as_str()));
    out
}

/// HalfCheetah's observation: qpos less x (8), then qvel: x velocity at 8, the six joints'
/// velocities at 11..17.
fn summed(t: &Trajectory, per_step: impl Fn(&[f32]) -> f64) -> f64 {
    t.next_obs().chunks(t.obs_dim).map(per_step).sum()
}

#[test]
fn a_forward_velocity_reward_scores_high_on_the_bank_and_a_still_joint_reward_low() {
    let dir = TempDir::new("bank");
    let file = dir.join("bank.yaml");
    std::fs::write(&file, BANK).unwrap();
    let run = |store: &str, jobs: &str| {
        let s = dir.join(store);
        let out =
            idrex(&["pipeline", "run", file.to_str().unwrap(), "--store", s.to_str().unwrap(), "--jobs", jobs, "--target", "bank/gaits"]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(stdout(&out).contains("3 stages, 3 computed"), "--target runs the bank alone: {}", stdout(&out));
        manifests(&s)
    };
    let (one, two) = (run("one", "1"), run("two", "2"));
    let outputs = |v: &[(PathBuf, serde_json::Value)]| v.iter().map(|(_, m)| (m["key"].clone(), m["outputs"].clone())).collect::<Vec<_>>();
    assert_eq!(outputs(&one).len(), 3);
    assert_eq!(outputs(&one), outputs(&two), "the bank's bytes are the same at --jobs 1 and 2");

    let bank = &one.iter().find(|(_, m)| m["kind"] == "bank").unwrap().0;
    let (entries, trajs) = read_bank(bank).unwrap();
    // 4 + 2 checkpoints x (1 + 1 + 1) episodes, 2 still, 2 random.
    assert_eq!(entries.len(), 6 * 3 + 4);
    let fastest = entries.iter().filter(|e| e.class == GaitClass::Forward).map(|e| e.forward).fold(f64::MIN, f64::max);
    let backward = entries.iter().filter(|e| e.class == GaitClass::Backward).map(|e| e.forward).fold(f64::MAX, f64::min);
    assert!(fastest > 200.0 && backward < -100.0, "the bank runs both ways: fastest forward {fastest}, backward {backward}");

    let forward_velocity: Vec<f64> = trajs.iter().map(|t| summed(t, |o| o[8] as f64)).collect();
    let still_joints: Vec<f64> = trajs.iter().map(|t| summed(t, |o| -o[11..17].iter().map(|&v| (v * v) as f64).sum::<f64>())).collect();
    let (good, bad): (BankScore, BankScore) = (score(&entries, &forward_velocity), score(&entries, &still_joints));
    eprintln!("forward velocity: {good:?}\nstill joints: {bad:?}");
    assert!(good.spearman > 0.8 && good.forward_spearman > 0.8, "{good:?}");
    assert!(!good.pays_a_wrong_gait(), "{good:?}");
    assert!(bad.spearman < good.spearman - 0.3 && bad.forward_spearman < 0.5, "{bad:?}");
    assert!(bad.overpaid_of(GaitClass::Still) > 0 && bad.misordered > 0.3, "{bad:?}");
}

/// The smoke pipeline with a bank: every learned reward is scored (a `bank-score` beside each
/// T-REX stage), the report carries the scores beside the SSRR-way correlation and splits each
/// method's gain over BC into its terms, and `idrex bank score` prints the same numbers.
#[test]
fn the_report_and_the_command_carry_the_bank_scores() {
    let dir = TempDir::new("bank-report");
    let smoke = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let tiny = "bank:\n  steps: 6144\n  backward_steps: 2048\n  checkpoints: 2\n  backward_checkpoints: 1\n  episodes: 1\n  \
                epsilon: [0.5]\n  smooth: [0.5]\n  still: 1\n  random: 1\n  probe: 4096\n";
    let file = dir.join("smoke.yaml");
    std::fs::write(&file, format!("{smoke}{tiny}")).unwrap();
    let store = dir.join("store");
    let (f, s) = (file.to_str().unwrap(), store.to_str().unwrap());
    let rec = dir.join("smoke.rrd");
    let out = idrex(&["pipeline", "run", f, "--store", s, "--recording", rec.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let scores: Vec<serde_json::Value> = manifests(&store).into_iter().filter(|(_, m)| m["kind"] == "bank-score").map(|(_, m)| m).collect();
    assert_eq!(scores.len(), 4, "one per T-REX stage: D-REX's and each iD-REX variant's");
    let probes: Vec<serde_json::Value> = manifests(&store).into_iter().filter(|(_, m)| m["kind"] == "probe").map(|(_, m)| m).collect();
    assert_eq!(probes.len(), 4, "a probe beside every reward PPO trains on");
    assert!(probes.iter().all(|m| m["metrics"]["true_return"].as_f64().is_some_and(f64::is_finite)), "{probes:?}");

    let report = dir.join("report");
    let r = report.to_str().unwrap();
    let out = idrex(&["report", "--store", s, "--out", r, "--print", "answer", "--recording", rec.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let printed = stdout(&out);
    assert!(printed.contains("## The answer") && printed.contains("Where everything is:"), "{printed}");
    assert!(!printed.contains("![") && !printed.contains("## Ground-truth return"), "the answer alone: {printed}");
    assert!(printed.contains("report.md") && printed.contains("smoke.rrd"), "{printed}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("## The reward bench") && md.contains("bank Spearman") && md.contains("gain over BC, by term"), "{md}");
    let bank_csv = std::fs::read_to_string(report.join("bank.csv")).unwrap();
    assert_eq!(bank_csv.lines().count(), 5, "a header and one row per learned-reward method: {bank_csv}");
    let probe_at = bank_csv.lines().next().unwrap().split(',').position(|h| h == "probe_return").unwrap();
    assert!(bank_csv.lines().skip(1).all(|l| l.split(',').nth(probe_at).unwrap().parse::<f64>().is_ok_and(f64::is_finite)), "{bank_csv}");
    let accuracy = std::fs::read_to_string(report.join("reward_accuracy.csv")).unwrap();
    let header: Vec<&str> = accuracy.lines().next().unwrap().split(',').collect();
    let at = |c: &str| header.iter().position(|h| *h == c).unwrap();
    assert_eq!(at("bank_spearman"), at("pearson_ssrr") + 1, "beside the SSRR-way correlation");
    let drex = accuracy.lines().find(|l| l.contains(",drex,")).unwrap().split(',').collect::<Vec<_>>();
    assert!(drex[at("bank_spearman")].parse::<f64>().is_ok(), "{accuracy}");
    let gains = std::fs::read_to_string(report.join("gains.csv")).unwrap();
    assert!(gains.starts_with("env,pipeline,method,return,forward,survive,control,mostly_from") && gains.lines().count() == 5, "{gains}");

    // The command: D-REX's reward by its key's prefix, the bank found by its task.
    let trex = manifests(&store).into_iter().find(|(_, m)| m["kind"] == "trex" && m["node"] == "drex/trex").unwrap().1;
    let key = trex["key"].as_str().unwrap();
    let out = idrex(&["bank", "score", &key[..12], "--store", s, "--csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = stdout(&out);
    let spearman = |line: &str| line.split(',').nth(3).unwrap().parse::<f64>().unwrap();
    let from_report = bank_csv.lines().find(|l| l.contains(",drex,")).unwrap().split(',').nth(6).unwrap().parse::<f64>().unwrap();
    assert!((spearman(csv.lines().nth(1).unwrap()) - from_report).abs() < 1e-3, "{csv}\n{bank_csv}");
    let probe_at = csv.lines().next().unwrap().split(',').position(|h| h == "probe_return").unwrap();
    assert!(
        csv.lines().nth(1).unwrap().split(',').nth(probe_at).unwrap().parse::<f64>().is_ok_and(f64::is_finite),
        "the reward's probe: {csv}"
    );
    // A mistake gets one short message that names the fix.
    let out = idrex(&["bank", "score", "abc", "--store", s]);
    assert!(!out.status.success() && stderr(&out).contains("at least 8 characters"), "{}", stderr(&out));
}
