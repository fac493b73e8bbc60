//! What a PPO run leaves on disk besides its final policy: checkpoints by global step and
//! the learning curve.
use std::path::{Path, PathBuf};

use super::PpoProgress;
use crate::error::{Error, Result};

/// Where the checkpoint at global step `step` of a run writing into `out` goes.
pub fn checkpoint_dir(out: &Path, step: usize) -> PathBuf {
    out.join("checkpoints").join(format!("step-{step:08}"))
}

/// The checkpoints under `out`, as (global step, directory), in step order; none when the
/// run kept none.
pub fn checkpoints(out: &Path) -> Result<Vec<(usize, PathBuf)>> {
    let dir = out.join("checkpoints");
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut found = Vec::new();
    for e in std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))? {
        let e = e.map_err(|e| Error::io(&dir, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        let step = name.strip_prefix("step-").and_then(|s| s.parse::<usize>().ok());
        match step {
            Some(step) => found.push((step, e.path())),
            None => return Err(Error::file(e.path(), "not a checkpoint directory (step-<global step>)")),
        }
    }
    found.sort();
    Ok(found)
}

/// The learning curve as CSV, one row per update: the one writer for every PPO curve.
/// Only what the seed determines goes in (no timings), so the file's bytes depend only on
/// the run's definition.
pub fn write_curve(path: &Path, curve: &[PpoProgress]) -> Result<()> {
    let mut csv = String::from(
        "global_step,episodic_return,learned_return,policy_loss,value_loss,entropy,approx_kl,clipfrac,explained_variance,eval_mean,eval_std\n",
    );
    let f = |x: Option<f64>| x.map_or(String::new(), |v| v.to_string());
    for p in curve {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{}\n",
            p.global_step,
            f(p.episodic_return),
            f(p.learned_return),
            p.policy_loss,
            p.value_loss,
            p.entropy,
            p.approx_kl,
            p.clipfrac,
            p.explained_variance,
            f(p.eval.map(|e| e.mean)),
            f(p.eval.map(|e| e.std))
        ));
    }
    std::fs::write(path, csv).map_err(|e| Error::io(path, e))
}
