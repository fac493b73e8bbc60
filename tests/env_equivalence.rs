//! Our environments against Gymnasium's own, step by step, from the same state with the same
//! actions: observations, rewards, each reward term, termination and truncation agree to 1e-6,
//! and each case prints its largest absolute difference (`-- --nocapture`; 0 where idrex
//! computes every number as Gymnasium does).
use idrex::env::{Env, EnvId};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

use crate::util::{TempDir, idrex, python, repo, stderr, stdout};

#[derive(Clone, Copy, Debug)]
enum Pattern {
    /// Uniform in the action box.
    Random,
    /// Every component at -1 or +1.
    Bounds,
    /// Uniform in [-2, 2]: MuJoCo clamps ctrl, the control cost sees the raw action.
    OutOfBounds,
}

fn actions(pattern: Pattern, n: usize, width: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            (0..width)
                .map(|_| match pattern {
                    Pattern::Random => rng.random_range(-1.0..1.0),
                    Pattern::Bounds => {
                        if rng.random_bool(0.5) {
                            1.0
                        } else {
                            -1.0
                        }
                    }
                    Pattern::OutOfBounds => rng.random_range(-2.0..2.0),
                })
                .collect()
        })
        .collect()
}

fn lines(text: &str) -> Vec<Value> {
    text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect()
}

/// Asserts `a` and `b` agree to 1e-6 everywhere; raises `max` to their largest difference.
fn close(a: &Value, b: &Value, path: &str, max: &mut f64) {
    match (a, b) {
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}: lengths differ");
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                close(p, q, &format!("{path}[{i}]"), max);
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(x.keys().collect::<Vec<_>>(), y.keys().collect::<Vec<_>>(), "{path}: fields differ");
            for (k, v) in x {
                close(v, &y[k], &format!("{path}.{k}"), max);
            }
        }
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!((x - y).abs() <= 1e-6, "{path}: ours {x} vs Gymnasium {y}");
            *max = max.max((x - y).abs());
        }
        _ => assert_eq!(a, b, "{path}"),
    }
}

/// Runs both sides and returns how the episode ended: (steps, terminated, truncated).
fn compare(id: EnvId, pattern: Pattern, steps: usize, seed: u64) -> (usize, bool, bool) {
    let dir = TempDir::new(&format!("equiv-{id}-{pattern:?}"));
    let mut env = Env::new(id).unwrap();
    let mut obs = vec![0.0; env.obs_dim()];
    env.reset(Some(seed), &mut obs);
    let state = serde_json::json!({"qpos": env.qpos(), "qvel": env.qvel()});
    std::fs::write(dir.join("state.json"), state.to_string()).unwrap();
    let csv: String = actions(pattern, steps, env.act_dim(), seed)
        .iter()
        .map(|a| a.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(",") + "\n")
        .collect();
    std::fs::write(dir.join("actions.csv"), csv).unwrap();
    let (state_path, actions_path) = (dir.join("state.json"), dir.join("actions.csv"));
    let (state_arg, actions_arg) = (state_path.to_str().unwrap(), actions_path.to_str().unwrap());

    let ours = idrex(&["env", "rollout", "--env", id.name(), "--state", state_arg, "--actions", actions_arg]);
    assert!(ours.status.success(), "idrex env rollout failed: {}", stderr(&ours));
    let theirs = std::process::Command::new(python())
        .arg(repo("analysis/gym_replay.py"))
        .args(["--env", id.name(), "--state", state_arg, "--actions", actions_arg])
        .output()
        .unwrap();
    assert!(theirs.status.success(), "gym_replay.py failed: {}", stderr(&theirs));

    let (ours, theirs) = (lines(&stdout(&ours)), lines(&stdout(&theirs)));
    assert_eq!(ours.len(), theirs.len(), "{id} {pattern:?}: episode lengths differ");
    let mut max = 0.0f64;
    for (t, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        close(a, b, &format!("{id} {pattern:?} step {t}"), &mut max);
    }
    eprintln!("{id} {pattern:?}: {} steps, largest |idrex - Gymnasium| = {max:e}", ours.len());
    let last = ours.last().unwrap();
    (ours.len(), last["terminated"].as_bool().unwrap(), last["truncated"].as_bool().unwrap())
}

#[test]
fn half_cheetah_matches_gymnasium_for_a_whole_episode() {
    for (i, p) in [Pattern::Random, Pattern::Bounds, Pattern::OutOfBounds].into_iter().enumerate() {
        let steps = if i == 0 { 1000 } else { 200 };
        let (len, term, trunc) = compare(EnvId::HalfCheetah, p, steps, 11 + i as u64);
        assert_eq!(len, steps);
        assert!(!term);
        assert_eq!(trunc, steps == 1000, "truncated exactly at the 1000-step limit");
    }
}

#[test]
fn hopper_matches_gymnasium_until_it_falls() {
    for (i, p) in [Pattern::Random, Pattern::Bounds, Pattern::OutOfBounds].into_iter().enumerate() {
        let (len, term, _) = compare(EnvId::Hopper, p, 1000, 21 + i as u64);
        assert!(term && len < 1000, "{p:?}: the hopper should fall under random actions ({len} steps)");
    }
}

#[test]
fn walker2d_matches_gymnasium_until_it_falls() {
    for (i, p) in [Pattern::Random, Pattern::Bounds, Pattern::OutOfBounds].into_iter().enumerate() {
        let (len, term, _) = compare(EnvId::Walker2d, p, 1000, 31 + i as u64);
        assert!(term && len < 1000, "{p:?}: the walker should fall under random actions ({len} steps)");
    }
}

#[test]
fn ant_matches_gymnasium_contact_forces_included() {
    for (i, p) in [Pattern::Random, Pattern::Bounds, Pattern::OutOfBounds].into_iter().enumerate() {
        let steps = if i == 0 { 1000 } else { 300 };
        let (len, term, trunc) = compare(EnvId::Ant, p, steps, 41 + i as u64);
        assert!(len == steps || term, "{p:?}: {len} steps, neither the whole run nor a termination");
        assert_eq!(trunc, len == 1000, "{p:?}: truncated exactly at the 1000-step limit");
    }
}

#[test]
fn ant_matches_gymnasium_contact_forces_left_out_of_the_observation() {
    // gym.make("Ant-v5", include_cfrc_ext_in_observation=False): 27 observations, the contact
    // cost still in the reward.
    assert_eq!(Env::new(EnvId::AntNoCfrc).unwrap().obs_dim(), 27);
    for (i, p) in [Pattern::Random, Pattern::OutOfBounds].into_iter().enumerate() {
        let steps = if i == 0 { 1000 } else { 300 };
        let (len, term, trunc) = compare(EnvId::AntNoCfrc, p, steps, 51 + i as u64);
        assert!(len == steps || term, "{p:?}: {len} steps, neither the whole run nor a termination");
        assert_eq!(trunc, len == 1000, "{p:?}: truncated exactly at the 1000-step limit");
    }
}
