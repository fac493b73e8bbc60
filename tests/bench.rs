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
