//! `probe`: the reward bench's look at what PPO makes of a learned reward, before the RL runs
//! pay for it. One short PPO run (`bank.probe` steps) on the reward exactly as the method's
//! runs compose it; its score is the true return of the training episodes that ended in the
//! last quarter of its steps (the mean over those updates of their episodes' mean). Its final
//! policy then acts for `episodes` episodes, as the evaluation stage's do, so that on a task
//! that ends the probe says whether the gait moves or only lives (the forward term; the
//! training curve has no terms). The bank asks whether a reward orders gaits PPO found on the
//! *true* reward; the probe asks what gait PPO finds on the *learned* one
//! (`analysis/results/reward-bench/README.md`: on HalfCheetah the first fifth of the locked
//! sets' own runs predicted their end where the bank did not).
use std::path::PathBuf;

use super::ppo::{self, CurvePoint, PpoInputs, PpoMetrics, PpoParams};
use super::{POLICY, StageCtx};
use crate::data::TrajMeta;
use crate::env::Env;
use crate::error::{Error, Result};
use crate::nn::ActorCritic;
use crate::rollout::{self, PolicyActor};
use crate::seed::Purpose;

/// The share of the probe's steps, at its end, whose finished episodes make its score.
pub const TAIL: f64 = 0.25;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeParams {
    /// The method's first RL run's parameters with the probe's steps and no checkpoints.
    pub run: PpoParams,
    /// Episodes of the final policy acting (its sampled actions).
    pub episodes: usize,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProbeMetrics {
    /// The mean true return of the training episodes that ended in the last [`TAIL`] of the
    /// run's steps (the mean over those updates of each update's finished episodes' mean).
    pub true_return: f64,
    /// The same episodes' learned return.
    pub learned_return: Option<f64>,
    /// The final policy's `episodes` episodes: the mean true return, forward term and length.
    pub final_return: f64,
    pub final_forward: f64,
    pub final_length: f64,
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
    // The steps PPO took: whole updates, at most `total_steps`.
    let total = run.curve.last().map_or(0, |c| c.step);
    let true_return = tail_mean(&run.curve, total, TAIL, |c| c.true_return).ok_or_else(|| {
        Error::Invalid(format!(
            "the probe's {total} PPO steps ended no episode in their last {:.0} %: give `bank.probe` more steps",
            TAIL * 100.0
        ))
    })?;
    let learned_return = tail_mean(&run.curve, total, TAIL, |c| c.learned_return);
    let policy = ActorCritic::load(&ctx.out.join(POLICY))?;
    let mut env = Env::new(p.run.env)?;
    let meta = TrajMeta { source: "probe".into(), ..Default::default() };
    let trajs = rollout::episodes(&mut env, &mut PolicyActor::acting(&policy), p.episodes.max(1), ctx.seed, Purpose::ProbeEpisode, &meta);
    let mean = |f: &dyn Fn(&crate::data::Trajectory) -> f64| trajs.iter().map(f).sum::<f64>() / trajs.len() as f64;
    Ok(ProbeMetrics {
        true_return,
        learned_return,
        final_return: mean(&|t| t.ret()),
        final_forward: mean(&|t| t.terms.iter().map(|x| x.reward_forward).sum()),
        final_length: mean(&|t| t.len() as f64),
        run,
    })
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
