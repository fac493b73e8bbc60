//! `eval`: the ground-truth return of a policy over `episodes` episodes (PPO policies sample,
//! as the original D-REX evaluation did; BC acts with its mean), and of every checkpoint the
//! PPO run kept, each on the same episode seeds. With a reward model as input, also what the
//! learned reward says of each checkpoint's episodes: the ensemble's mean predicted return,
//! its most pessimistic member and the members' disagreement (the ground-truth-free
//! checkpoint choice reads these), and for the final policy how well it ranks the episodes.
use std::path::PathBuf;

use super::{REWARD, RolloutSummary, StageCtx, load_policy_for, read_rollouts};
use crate::algo::ppo;
use crate::algo::scoring::{CheckpointEval, learned_score, member_stats};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::Result;
use crate::nn::{ActorCritic, RewardEnsemble};
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
    /// The study replicate (independent seeds for every stage) the run belongs to; absent
    /// for replicate 0, whose keys are those of a file without replicates.
    #[serde(default, skip_serializing_if = "super::is_zero")]
    pub replicate: usize,
    /// The sweep variant the run belongs to (absent outside sweeps, and for the variant that
    /// sets nothing: the file itself).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variant: Option<VariantTag>,
}

/// A sweep variant's place in its sweep, recorded in its evaluations: the report and `exp
/// show` group studies by it and compare each variant with the baseline.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantTag {
    /// The sweep's name: the pipeline file's.
    pub sweep: String,
    /// What tells the variant apart: its name, or its settings (`reward.ceiling=0.5`).
    pub label: String,
    /// Every field it sets, `path=value`, in the order applied.
    pub settings: Vec<String>,
    /// The study (`pipeline` name) it is compared against.
    pub baseline: String,
}

impl EvalParams {
    /// The table a run's figures go to: its pipeline's name, and its replicate past the
    /// first (`study/r3`).
    pub fn table(&self) -> String {
        if self.replicate == 0 { self.pipeline.clone() } else { format!("{}/r{}", self.pipeline, self.replicate) }
    }
}

/// How the learned reward scores the final policy's evaluation episodes.
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
    /// The final policy.
    #[serde(flatten)]
    pub summary: RolloutSummary,
    #[serde(flatten)]
    pub reward: Option<RewardAccuracy>,
    /// Every checkpoint in step order, the final policy last; empty for policies without
    /// checkpoints (BC).
    #[serde(default)]
    pub checkpoints: Vec<CheckpointEval>,
}

crate::stage_inputs! {
    /// An evaluation rolls out a PPO run's (or BC's) policy; with the reward it trained on,
    /// it also scores the episodes by it, in units measured on the demonstrations.
    EvalInputs { policy: One Policy, reward: Maybe Reward, demos: One Demos }
}

pub fn run(p: &EvalParams, inputs: &EvalInputs<PathBuf>, ctx: &StageCtx) -> Result<EvalMetrics> {
    let mut env = Env::new(p.env)?;
    let policy_dir = inputs.policy.as_path();
    let reward = match &inputs.reward {
        None => None,
        Some(dir) => {
            let model = RewardEnsemble::load(&dir.join(REWARD))?;
            let reference = member_stats(&model, &read_rollouts(&inputs.demos)?);
            Some((model, reference))
        }
    };
    let meta = TrajMeta { source: "eval".into(), ..Default::default() };
    let dims = (env.obs_dim(), env.act_dim());
    // The same episode seeds for every checkpoint: their returns differ by the policy only.
    let mut play = |policy: &ActorCritic| {
        rollout::episodes(&mut env, &mut PolicyActor::acting(policy), p.episodes, ctx.seed, Purpose::EvalEpisode, &meta)
    };
    // The PPO stage keeps the final policy as its last checkpoint; its episodes are the
    // final policy's.
    let stored = ppo::checkpoints(policy_dir)?;
    let mut checkpoints = Vec::with_capacity(stored.len());
    let mut last_trajs = None;
    for (i, (step, dir)) in stored.iter().enumerate() {
        ctx.progress.set_message(format!("checkpoint {}/{} (step {step})", i + 1, stored.len()));
        let policy = ActorCritic::load(dir)?;
        policy.expect_dims(dims.0, dims.1, p.env.name())?;
        let trajs = play(&policy);
        checkpoints.push(CheckpointEval {
            step: *step,
            returns: trajs.iter().map(Trajectory::ret).collect(),
            learned: reward.as_ref().map(|(m, r)| learned_score(m, r, &trajs)),
        });
        last_trajs = Some(trajs);
    }
    let trajs = match last_trajs {
        Some(t) => t,
        None => play(&load_policy_for(policy_dir, &Env::new(p.env)?, p.env)?),
    };
    let (accuracy, learned) = match &reward {
        None => (None, None),
        Some((model, _)) => {
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
    Ok(EvalMetrics { summary: RolloutSummary::of(&trajs).with_terms(&trajs), reward: accuracy, checkpoints })
}
