//! `idrex env rollout`: user mistakes give one clear line and a non-zero exit.
use crate::util::{TempDir, idrex, stderr, stdout};

#[test]
fn seeded_rollout_prints_one_line_per_step() {
    let dir = TempDir::new("cli-seeded");
    std::fs::write(dir.join("a.csv"), "0,0,0\n0.5,-0.5,1\n\n1,1,1\n").unwrap();
    let a = dir.join("a.csv");
    let out = idrex(&["env", "rollout", "--env", "Hopper-v5", "--seed", "3", "--actions", a.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert_eq!(text.lines().count(), 3);
    let first: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    assert_eq!(first["obs"].as_array().unwrap().len(), 11);
    assert_eq!(first["reward_survive"], 1.0);
    // Same seed, same output.
    let again = idrex(&["env", "rollout", "--env", "Hopper-v5", "--seed", "3", "--actions", a.to_str().unwrap()]);
    assert_eq!(stdout(&again), text);
}

fn fails_with(args: &[&str], expect: &str) {
    let out = idrex(args);
    assert!(!out.status.success(), "{args:?} should fail");
    let err = stderr(&out);
    assert!(err.contains(expect), "{args:?}: expected '{expect}' in: {err}");
    assert_eq!(err.trim().lines().count(), 1, "one line, got: {err}");
}

#[test]
fn mistakes_give_one_clear_line() {
    let dir = TempDir::new("cli-errors");
    std::fs::write(dir.join("a.csv"), "0,0,0\n0,0\n").unwrap();
    std::fs::write(dir.join("ok.csv"), "0,0,0\n").unwrap();
    std::fs::write(dir.join("s.json"), r#"{"qpos": [0, 1.25, 0], "qvel": [0,0,0,0,0,0]}"#).unwrap();
    let (a, ok, s) = (dir.join("a.csv"), dir.join("ok.csv"), dir.join("s.json"));
    let (a, ok, s) = (a.to_str().unwrap(), ok.to_str().unwrap(), s.to_str().unwrap());
    fails_with(&["env", "rollout", "--env", "Hopper-v4", "--actions", ok], "unknown environment 'Hopper-v4'");
    fails_with(&["env", "rollout", "--env", "Hopper-v5", "--actions", a], "line 2: expected 3 action values, got 2");
    fails_with(&["env", "rollout", "--env", "Hopper-v5", "--actions", ok, "--state", s], "qpos: expected 6 values, got 3");
    fails_with(&["env", "rollout", "--env", "Hopper-v5", "--actions", "/nonexistent.csv"], "cannot read /nonexistent.csv");
}

#[test]
fn eval_says_how_long_episodes_last_and_what_each_term_pays() {
    // A barely trained Hopper policy falls early: every step before the fall pays the healthy
    // reward of 1 (v5 pays nothing on the step it falls), and the terms add up to the return.
    let dir = TempDir::new("cli-eval");
    let policy = dir.join("ppo");
    let out = idrex(&["train", "ppo", "--env", "Hopper-v5", "--steps", "2048", "--eval-every", "0", "--out", policy.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = idrex(&["eval", "--policy", policy.to_str().unwrap(), "--episodes", "3", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"));
    assert!(f("length") > 1.0 && f("length") < 1000.0, "{v}");
    assert!((f("survive") - (f("length") - 1.0)).abs() < 1e-9, "{v}");
    let sum = f("forward") + f("ctrl") + f("survive") + f("contact");
    assert!((sum - f("mean")).abs() < 1e-6 * f("mean").abs().max(1.0), "{v}");
    assert!(f("ctrl") < 0.0 && f("contact") == 0.0, "{v}");
    assert_eq!(v["earned_by"], "moving", "a policy that falls early is not living: {v}");
}
