//! idrex's study statistics against rliable 1.2.0's own functions (`metrics.aggregate_iqm`,
//! `metrics.probability_of_improvement`, `library.get_interval_estimates`), run by
//! `analysis/rliable/check.py` in the small environment `analysis/rliable/env.sh` makes. The
//! point values must agree exactly; the intervals, drawn from different random streams, to
//! within the bootstrap's own noise.
use std::io::Write;
use std::process::{Command, Stdio};

use idrex::stats::{hierarchical_ci, iqm, probability_of_improvement, probability_of_improvement_independent_ci};

use crate::util::{repo, stderr, stdout};

fn rliable(x: &[f64], y: &[f64], reps: usize) -> serde_json::Value {
    let env = Command::new(repo("analysis/rliable/env.sh")).output().expect("run analysis/rliable/env.sh");
    assert!(env.status.success(), "the rliable environment: {}", stderr(&env));
    let python = stdout(&env).trim().to_string();
    let mut child = Command::new(python)
        .arg(repo("analysis/rliable/check.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let input = serde_json::json!({ "x": x, "y": y, "reps": reps });
    child.stdin.take().unwrap().write_all(input.to_string().as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "check.py: {}", stderr(&out));
    serde_json::from_str(&stdout(&out)).unwrap()
}

fn pair(v: &serde_json::Value) -> (f64, f64) {
    (v[0].as_f64().unwrap(), v[1].as_f64().unwrap())
}

#[test]
fn study_statistics_match_rliable() {
    const REPS: usize = 50_000;
    // Ten replicates' scores of two methods (D-REX and BC on HalfCheetah, say), with a tie
    // across them; then five replicates where every X beats every Y.
    let x = [439.5, 505.5, 272.2, 610.0, 388.1, 140.9, 455.0, 520.3, 301.7, 192.1];
    let y = [192.1, 220.6, 132.2, 250.4, 171.2, 160.0, 199.9, 230.5, 180.3, 150.8];
    let sweep = ([5.0, 6.0, 7.0, 8.0, 9.0], [0.0, 1.0, 2.0, 3.0, 4.0]);
    for (x, y) in [(&x[..], &y[..]), (&sweep.0[..], &sweep.1[..])] {
        let want = rliable(x, y, REPS);
        assert!((iqm(x) - want["iqm"].as_f64().unwrap()).abs() < 1e-9, "IQM {} against {want}", iqm(x));
        assert!((probability_of_improvement(x, y) - want["poi"].as_f64().unwrap()).abs() < 1e-12, "P {want}");
        // One run per replicate: the hierarchical bootstrap is rliable's stratified one.
        let groups: Vec<Vec<f64>> = x.iter().map(|&v| vec![v]).collect();
        let (lo, hi) = hierarchical_ci(&groups, iqm, REPS, 0);
        let (wlo, whi) = pair(&want["iqm_ci"]);
        let span = (whi - wlo).max(1.0);
        assert!((lo - wlo).abs() < 0.05 * span && (hi - whi).abs() < 0.05 * span, "IQM interval [{lo}, {hi}] against [{wlo}, {whi}]");
        let (lo, hi) = probability_of_improvement_independent_ci(x, y, REPS, 0);
        let (wlo, whi) = pair(&want["poi_ci"]);
        assert!((lo - wlo).abs() <= 0.03 && (hi - whi).abs() <= 0.03, "P interval [{lo}, {hi}] against rliable's [{wlo}, {whi}]");
    }
}
