//! `probe`: the reward bench's look at what PPO makes of a learned reward, before the RL runs
//! pay for it. One short PPO run (`bank.probe` steps) on the reward exactly as the method's
//! runs compose it; its score is the true return of the training episodes that ended in the
//! last quarter of its steps. The bank asks whether a reward orders gaits PPO found on the
//! *true* reward; the probe asks what gait PPO finds on the *learned* one
//! (`analysis/results/reward-bench/README.md`: on HalfCheetah the first fifth of the locked
//! sets' own runs predicted their end where the bank did not).
use std::path::PathBuf;

use super::StageCtx;
use super::ppo::{self, CurvePoint, PpoInputs, PpoMetrics, PpoParams};
use crate::error::{Error, Result};

/// The share of the probe's steps, at its end, whose finished episodes make its score.
pub const TAIL: f64 = 0.25;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeParams {
    /// The method's first RL run's parameters with the probe's steps and no checkpoints.
    pub run: PpoParams,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProbeMetrics {
    /// The mean true return of the training episodes that ended in the last [`TAIL`] of the
    /// run's steps.
    pub true_return: f64,
    /// The same episodes' learned return.
    pub learned_return: Option<f64>,
    pub run: PpoMetrics,
}

/// The mean of `get` over the curve's points in the last `tail` of `total` steps.
pub fn tail_mean(curve: &[CurvePoint], total: usize, tail: f64, get: impl Fn(&CurvePoint) -> Option<f64>) -> Option<f64> {
    let from = (1.0 - tail) * total as f64;
    let v: Vec<f64> = curve.iter().filter(|c| c.step as f64 > from).filter_map(get).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

pub fn run(p: &ProbeParams, inputs: &PpoInputs<PathBuf>, ctx: &StageCtx) -> Result<ProbeMetrics> {
    let run = ppo::run(&p.run, inputs, ctx)?;
    let total = p.run.ppo.total_steps;
    let true_return = tail_mean(&run.curve, total, TAIL, |c| c.true_return).ok_or_else(|| {
        Error::Invalid(format!(
            "the probe's {total} PPO steps ended no episode in their last {:.0} %: give `bank.probe` more steps",
            TAIL * 100.0
        ))
    })?;
    let learned_return = tail_mean(&run.curve, total, TAIL, |c| c.learned_return);
    Ok(ProbeMetrics { true_return, learned_return, run })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_score_is_the_last_quarters_episodes() {
        let point = |step, r| CurvePoint { step, true_return: r, learned_return: None };
        let curve = [point(100, Some(1.0)), point(700, Some(2.0)), point(800, None), point(900, Some(4.0)), point(1000, Some(6.0))];
        assert_eq!(tail_mean(&curve, 1000, TAIL, |c| c.true_return), Some(5.0), "steps 750-1000 only, no episode skipped");
        assert_eq!(tail_mean(&curve[..3], 1000, TAIL, |c| c.true_return), None);
    }
}
