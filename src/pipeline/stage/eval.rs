//! `eval`: the ground-truth return of a policy over `episodes` episodes (PPO policies sample,
//! BC acts with its mean); with a reward model as input, also what the learned reward says
//! of the same episodes and how well it ranks them.
use super::{RolloutSummary, StageCtx, load_policy_for};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::Result;
use crate::nn::RewardEnsemble;
use crate::pipeline::config::Method;
use crate::rollout::{self, PolicyActor};
use crate::seed::Purpose;
use crate::stats::{nan_as_null, pairwise_accuracy, pearson, spearman};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvalParams {
    pub env: EnvId,
    pub episodes: usize,
    /// Which table cell the result belongs to.
    pub pipeline: String,
    pub method: Method,
    pub iteration: usize,
    pub run: usize,
}

/// How the learned reward scores the evaluation episodes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RewardAccuracy {
    pub predicted_returns: Vec<f64>,
    #[serde(with = "nan_as_null")]
    pub spearman: f64,
    #[serde(with = "nan_as_null")]
    pub pearson: f64,
    #[serde(with = "nan_as_null")]
    pub pairwise_accuracy: f64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalMetrics {
    #[serde(flatten)]
    pub summary: RolloutSummary,
    #[serde(flatten)]
    pub reward: Option<RewardAccuracy>,
}

pub fn run(p: &EvalParams, ctx: &StageCtx) -> Result<EvalMetrics> {
    let mut env = Env::new(p.env)?;
    let policy = load_policy_for(ctx.input("policy")?, &env, p.env)?;
    let meta = TrajMeta { source: "eval".into(), ..Default::default() };
    let trajs = rollout::episodes(&mut env, &mut PolicyActor::acting(&policy), p.episodes, ctx.seed, Purpose::EvalEpisode, &meta);
    let (reward, learned) = match ctx.inputs.get("reward") {
        None => (None, None),
        Some(dir) => {
            let model = RewardEnsemble::load(&dir.join(super::REWARD))?;
            let per_step: Vec<Vec<f64>> = trajs
                .iter()
                .map(|t| {
                    let raw = model.raw(t.next_obs(), &t.actions);
                    (0..t.len()).map(|s| raw.iter().map(|m| m[s] as f64).sum::<f64>() / raw.len() as f64).collect()
                })
                .collect();
            let pred: Vec<f64> = per_step.iter().map(|r| r.iter().sum()).collect();
            let truth: Vec<f64> = trajs.iter().map(Trajectory::ret).collect();
            let acc = RewardAccuracy {
                spearman: spearman(&pred, &truth),
                pearson: pearson(&pred, &truth),
                pairwise_accuracy: pairwise_accuracy(&pred, &truth),
                predicted_returns: pred,
            };
            (Some(acc), Some(per_step))
        }
    };
    ctx.write_rollouts(p.env, &trajs, learned.as_deref())?;
    Ok(EvalMetrics { summary: RolloutSummary::of(&trajs), reward })
}
