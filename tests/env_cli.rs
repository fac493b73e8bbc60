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
