//! `ppo`: one RL run on a learned reward ([`crate::algo::ppo`]); the final policy, its
//! learning curve and a checkpoint every `ppo.checkpoint_every` updates
//! (`checkpoints/step-<global step>/`, the final policy always among them), which the
//! evaluation stage evaluates one by one. With `reward.level: ranked-floor`, the reward's
//! levels are fixed from the `floor` input (D-REX's ranked set) before training; with
//! `reward.ceiling`, each member's cap is measured there too.
use std::path::PathBuf;

use super::{POLICY, REWARD, StageCtx, ppo_progress};
use crate::algo::ppo::{self, PpoConfig};
use crate::env::EnvId;
use crate::error::Result;
use crate::nn::reward::{Composition, RewardLevel};
use crate::nn::{Device, RewardEnsemble};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PpoParams {
    pub env: EnvId,
    pub ppo: PpoConfig,
    /// How the learned reward is composed.
    pub reward: Composition,
    /// Where the learned reward is computed; absent (the CPU) from a CPU stage's parameters
    /// and key.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

/// One point of the learning curve: the mean true and learned returns of the training
/// episodes that ended in an update.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CurvePoint {
    pub step: usize,
    pub true_return: Option<f64>,
    pub learned_return: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PpoMetrics {
    pub wall_s: f64,
    pub steps_per_s: f64,
    pub curve: Vec<CurvePoint>,
    /// With `reward.ceiling`: the fraction of the members' per-step values RL trained on
    /// that the ceiling capped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reward_capped: Option<f64>,
}

pub const CURVE: &str = "curve.csv";

crate::stage_inputs! {
    /// PPO trains on the learned reward; where the reward's composition measures a level or
    /// a ceiling ([`Composition::needs_ranked_set`]), on D-REX's ranked set too.
    PpoInputs { reward: One Reward, floor: Maybe Floor }
}

pub fn run(p: &PpoParams, inputs: &PpoInputs<PathBuf>, ctx: &StageCtx) -> Result<PpoMetrics> {
    let cfg = p.ppo.clone();
    let mut reward = RewardEnsemble::load(&inputs.reward.join(REWARD))?;
    if let Some(floor) = &inputs.floor {
        let set = super::read_rollouts(floor)?;
        if p.reward.level == RewardLevel::RankedFloor {
            reward.fix_levels_from(&set)?;
        }
        if let Some(q) = p.reward.ceiling {
            reward.fix_ceilings_from(&set, q)?;
        }
    }
    reward.to_device(p.device)?;
    let mut show = ppo_progress(ctx, cfg.total_steps);
    let mut on_update = |u: &ppo::PpoProgress| {
        show(u);
        true
    };
    let hyper = serde_json::to_value(&cfg).unwrap_or_default();
    let mut save = |policy: &crate::nn::ActorCritic, step: usize| policy.save(&ppo::checkpoint_dir(ctx.out, step), hyper.clone());
    let source = ppo::RewardSource::Learned { model: reward, composition: p.reward };
    let res = ppo::train(p.env, &cfg, source, ctx.seed, &mut on_update, Some(&mut save))?;
    res.policy.save(&ctx.out.join(POLICY), hyper.clone())?;
    let steps = res.curve.last().map_or(0, |u| u.global_step);
    let last = ppo::checkpoint_dir(ctx.out, steps);
    if cfg.checkpoint_every > 0 && !last.exists() {
        res.policy.save(&last, hyper)?;
    }
    ppo::write_curve(&ctx.out.join(CURVE), &res.curve)?;
    Ok(PpoMetrics {
        wall_s: res.wall_s,
        steps_per_s: steps as f64 / res.wall_s,
        curve: res
            .curve
            .iter()
            .map(|u| CurvePoint { step: u.global_step, true_return: u.episodic_return, learned_return: u.learned_return })
            .collect(),
        reward_capped: res.reward_capped,
    })
}
