//! Rollout files as flat text for tools that do not read MCAP: one row (CSV) or one JSON
//! object (NDJSON) per step.
use std::io::Write;

use super::mcap::Rollouts;
use crate::data::Trajectory;

/// The flat formats `idrex logs export` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    Csv,
    Ndjson,
}

/// Step `s` of episode `e` as one JSON object.
pub fn step_json(r: &Rollouts, e: usize, s: usize) -> serde_json::Value {
    let t = &r.trajectories[e];
    let last = s + 1 == t.len();
    serde_json::json!({"episode": e, "t": s, "obs": t.obs_row(s), "action": t.action_row(s), "next_obs": t.obs_row(s + 1),
        "reward": t.rewards[s], "reward_forward": t.terms[s].reward_forward, "reward_ctrl": t.terms[s].reward_ctrl,
        "reward_survive": t.terms[s].reward_survive, "learned_reward": learned(r, e, s), "terminated": last && t.terminated,
        "truncated": last && t.truncated})
}

fn learned(r: &Rollouts, e: usize, s: usize) -> Option<f64> {
    r.learned.as_ref().and_then(|l| l[e].get(s)).copied()
}

/// Every step of every episode in `format`.
pub fn export(r: &Rollouts, format: ExportFormat, w: &mut impl Write) -> std::io::Result<()> {
    match format {
        ExportFormat::Ndjson => {
            for (e, t) in r.trajectories.iter().enumerate() {
                for s in 0..t.len() {
                    writeln!(w, "{}", step_json(r, e, s))?;
                }
            }
        }
        ExportFormat::Csv => {
            let (od, ad) = r.trajectories.first().map_or((0, 0), |t| (t.obs_dim, t.act_dim));
            let mut header = vec!["episode".to_string(), "t".into(), "noise".into(), "group".into()];
            header.extend((0..od).map(|i| format!("obs_{i}")));
            header.extend((0..ad).map(|i| format!("action_{i}")));
            header.extend((0..od).map(|i| format!("next_obs_{i}")));
            header.extend(
                ["reward", "reward_forward", "reward_ctrl", "reward_survive", "learned_reward", "terminated", "truncated"]
                    .map(String::from),
            );
            writeln!(w, "{}", header.join(","))?;
            for (e, t) in r.trajectories.iter().enumerate() {
                for s in 0..t.len() {
                    writeln!(w, "{}", csv_row(r, e, t, s))?;
                }
            }
        }
    }
    Ok(())
}

fn csv_row(r: &Rollouts, e: usize, t: &Trajectory, s: usize) -> String {
    let mut row = vec![e.to_string(), s.to_string(), t.meta.noise.to_string(), t.meta.group.to_string()];
    row.extend(t.obs_row(s).iter().map(|x| x.to_string()));
    row.extend(t.action_row(s).iter().map(|x| x.to_string()));
    row.extend(t.obs_row(s + 1).iter().map(|x| x.to_string()));
    let last = s + 1 == t.len();
    row.extend([
        t.rewards[s].to_string(),
        t.terms[s].reward_forward.to_string(),
        t.terms[s].reward_ctrl.to_string(),
        t.terms[s].reward_survive.to_string(),
        learned(r, e, s).map_or(String::new(), |x| x.to_string()),
        (last && t.terminated).to_string(),
        (last && t.truncated).to_string(),
    ]);
    row.join(",")
}
