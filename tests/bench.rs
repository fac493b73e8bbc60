//! The benchmarks' Python baselines run from the binary the suite built, whichever clone
//! built it last (issue 43: the clones test builds in temporary clones that share the target
//! directory, then deletes them). The clones test runs before this binary's tests and leaves
//! the shared build as this clone's; the scripts are compiled in, so no path into a clone is
//! needed either way.
use crate::util::{idrex, python, stderr, stdout};

/// A positive number at `path` of the JSON that `args` print.
fn figure(args: &[&str], path: &[&str]) -> f64 {
    let out = idrex(args);
    assert!(out.status.success(), "idrex {}: {}\n{}", args.join(" "), stdout(&out), stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap_or_else(|e| panic!("{e}: {}", stdout(&out)));
    let x = path.iter().fold(&v, |v, k| &v[*k]).as_f64().unwrap_or_else(|| panic!("no {path:?} in {v}"));
    assert!(x > 0.0, "{path:?} = {x}");
    x
}

#[test]
fn benchmarks_run_their_python_baselines() {
    let py = python();
    figure(&["bench", "env", "--env", "HalfCheetah-v5", "--steps", "3000", "--json"], &["gymnasium_steps_per_s"]);
    figure(&["bench", "ppo", "--ground-truth", "--steps", "4096", "--python", &py], &["sb3_steps_per_s"]);
    let args = ["bench", "learners", "--trex-iterations", "10", "--bc-iterations", "20", "--device", "cpu", "--python", &py];
    figure(&args, &["trex", "pytorch_model_iterations_per_s"]);
}

/// `bench env --envpool` runs EnvPool from its own environment (analysis/envpool/env.sh)
/// beside idrex, one row per configuration, each with its runs and a ratio.
#[test]
fn bench_env_measures_envpool_beside_idrex() {
    let env = std::process::Command::new(crate::util::repo("analysis/envpool/env.sh")).output().unwrap();
    assert!(env.status.success(), "analysis/envpool/env.sh: {}", stderr(&env));
    let envpool = stdout(&env).trim().to_string();
    let args = ["bench", "env", "--env", "Ant-v5", "--steps", "1000", "--runs", "1", "--python", "none", "--envpool", &envpool, "--json"];
    let out = idrex(&args);
    assert!(out.status.success(), "{}\n{}", stdout(&out), stderr(&out));
    let lines: Vec<serde_json::Value> = stdout(&out).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let rows = lines.iter().find_map(|v| v["envpool"].as_array()).unwrap_or_else(|| panic!("no EnvPool rows: {lines:?}"));
    let configs: Vec<(u64, u64)> = rows.iter().map(|r| (r["num_envs"].as_u64().unwrap(), r["threads"].as_u64().unwrap())).collect();
    assert_eq!(configs, [(1, 1), (8, 1), (8, 2), (64, 1), (64, 2)]);
    for r in rows {
        let (ours, theirs) = (r["idrex_steps_per_s"].as_f64().unwrap(), r["envpool_steps_per_s"].as_f64().unwrap());
        assert!(ours > 0.0 && theirs > 0.0 && (r["ratio"].as_f64().unwrap() - ours / theirs).abs() < 1e-9 && r["runs"] == 1, "{r}");
    }
}
