//! What `idrex env rollout` replays: a CSV of actions and an optional starting state, read
//! so that a replay starts bit-identical to the Python side (the equivalence tests).
use std::path::Path;

use crate::error::{Error, Result};

/// Reads a CSV of actions: one action per line, `width` comma-separated numbers each.
pub fn read_actions(path: &Path, width: usize) -> Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Invalid(format!("cannot read {}: {e}", path.display())))?;
    let mut actions = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let row =
            line.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<Vec<_>, _>>().map_err(|_| {
                Error::Invalid(format!("{} line {}: not a comma-separated list of numbers: '{line}'", path.display(), i + 1))
            })?;
        if row.len() != width {
            return Err(Error::Invalid(format!("{} line {}: expected {width} action values, got {}", path.display(), i + 1, row.len())));
        }
        actions.push(row);
    }
    Ok(actions)
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StateFile {
    qpos: Vec<f64>,
    qvel: Vec<f64>,
}

/// A state file `{"qpos": [...], "qvel": [...]}`, its numbers parsed exactly.
pub fn read_state(path: &Path) -> Result<(Vec<f64>, Vec<f64>)> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Invalid(format!("cannot read {}: {e}", path.display())))?;
    let state: StateFile =
        serde_json::from_str(&text).map_err(|e| Error::file(path, format!("expected {{\"qpos\": [...], \"qvel\": [...]}}: {e}")))?;
    // serde_json's float parsing may be off by an ulp; re-read the numbers exactly so that a
    // replay starts from bit-identical state.
    let qpos = exact_array(&text, "qpos").filter(|v| v.len() == state.qpos.len()).unwrap_or(state.qpos);
    let qvel = exact_array(&text, "qvel").filter(|v| v.len() == state.qvel.len()).unwrap_or(state.qvel);
    Ok((qpos, qvel))
}

/// The numbers of the JSON array under `key`, parsed with Rust's correctly rounded parser.
fn exact_array(text: &str, key: &str) -> Option<Vec<f64>> {
    let at = text.find(&format!("\"{key}\""))?;
    let rest = &text[at..];
    let open = rest.find('[')?;
    let close = rest[open..].find(']')? + open;
    let body = rest[open + 1..close].trim();
    if body.is_empty() {
        return Some(vec![]);
    }
    body.split(',').map(|x| x.trim().parse::<f64>().ok()).collect()
}
