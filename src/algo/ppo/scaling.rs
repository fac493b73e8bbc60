//! Return-based reward scaling, as CleanRL's `NormalizeReward` wrapper does it: each reward
//! divided by the running standard deviation of the discounted return, then clipped; and the
//! running observation statistics the policy normalises with.
use super::{PpoConfig, RewardSource, RolloutBuffer};
use crate::data::RunningMeanStd;
use crate::nn::reward::CtrlAction;

/// The running normalisers of observations and of discounted returns (reward scaling).
pub(super) struct Normalisers {
    pub obs: RunningMeanStd,
    pub ret: RunningMeanStd,
    pub disc_ret: Vec<f64>,
    pub obs_clip: f64,
}

impl Normalisers {
    pub fn obs(&self, raw: &[f32]) -> Vec<f32> {
        let mut f = raw.to_vec();
        self.obs.normalize(&mut f, self.obs_clip);
        f
    }
}

/// The rewards PPO trains on for the batch in `buf` (the environment's, or the learned one
/// composed for RL), each divided by the running standard deviation of the discounted return
/// and clipped; and the learned returns of the episodes that ended.
#[allow(clippy::needless_range_loop)] // k indexes the rewards, the buffer and the env slot together.
pub(super) fn scaled_rewards(
    reward: &mut RewardSource,
    buf: &RolloutBuffer,
    norm: &mut Normalisers,
    episode_learned: &mut [f64],
    cfg: &PpoConfig,
) -> (Vec<f64>, Vec<f64>) {
    let n = episode_learned.len();
    let mut rewards: Vec<f64> = match reward {
        RewardSource::GroundTruth => buf.env_rewards.clone(),
        RewardSource::Backward => buf.env_rewards.iter().zip(&buf.env_forward).map(|(r, f)| r - 2.0 * f).collect(),
        RewardSource::Learned { model, composition } => {
            let cost_actions = match composition.ctrl_action {
                CtrlAction::Clipped => &buf.clipped_actions,
                CtrlAction::Raw => &buf.actions,
            };
            model.rl_reward(&buf.raw_next, &buf.clipped_actions, cost_actions, buf.act_dim, composition, true)
        }
    };
    let mut ended_learned = Vec::new();
    for k in 0..buf.len() {
        let i = k % n;
        episode_learned[i] += rewards[k];
        norm.disc_ret[i] = norm.disc_ret[i] * cfg.gamma + rewards[k];
        norm.ret.update_scalar(norm.disc_ret[i]);
        rewards[k] = (rewards[k] / (norm.ret.var[0] + 1e-8).sqrt()).clamp(-cfg.reward_clip, cfg.reward_clip);
        if buf.done(k) {
            norm.disc_ret[i] = 0.0;
            ended_learned.push(episode_learned[i]);
            episode_learned[i] = 0.0;
        }
    }
    (rewards, ended_learned)
}
