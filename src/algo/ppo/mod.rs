//! PPO for continuous actions, read top to bottom like CleanRL's `ppo_continuous_action.py`:
//! collect a rollout (`collect`), turn its rewards into scaled rewards, let the
//! [`RolloutBuffer`] compute GAE (bootstrapping truncations where asked), run the
//! [`update`], log. The
//! implementation details that matter on MuJoCo: clipped surrogate and clipped value loss,
//! per-minibatch advantage normalisation, running observation normalisation (clipped to
//! +-10), return-based reward scaling (clipped to +-10), linear learning-rate annealing,
//! gradient-norm clipping, orthogonal initialisation and a state-independent log-std.
//!
//! A truncated episode is treated as terminal by default, as CleanRL and the original code's
//! PPO2 do; `bootstrap_truncation` bootstraps it instead (r += gamma * V(s_final), as SB3
//! does), which did worse on learned rewards.
//! The reward is pluggable: the environment's, or a learned [`RewardEnsemble`] (evaluated in
//! one batch per rollout on the next observations, minus its control cost).
mod buffer;
mod files;
pub mod fused;
mod scaling;
pub mod update;

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub use buffer::RolloutBuffer;
pub use files::{checkpoint_dir, checkpoints, write_curve};
use scaling::{Normalisers, scaled_rewards};

use crate::data::{RunningMeanStd, TrajMeta, Trajectory};
use crate::env::{Env, EnvId, Horizon, VecEnv};
use crate::error::{Error, Result};
use crate::nn::policy::CpuPolicy;
use crate::nn::reward::Composition;
use crate::nn::{ActorCritic, PolicyConfig, RewardEnsemble};
use crate::rollout::{self, PolicyActor};
use crate::seed::{self, Purpose};
use crate::stats::ReturnStats;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Total environment steps.
    pub total_steps: usize,
    /// Environments stepped in parallel (one vector of them).
    pub num_envs: usize,
    /// Steps per environment per rollout.
    pub num_steps: usize,
    /// Minibatches per update epoch (the rollout is split into this many).
    pub num_minibatches: usize,
    /// Passes over each rollout per update.
    pub update_epochs: usize,
    /// Adam learning rate.
    pub lr: f64,
    /// Anneal the learning rate linearly to 0 over the run.
    pub anneal_lr: bool,
    /// Discount factor.
    pub gamma: f64,
    /// Lambda of generalised advantage estimation.
    pub gae_lambda: f64,
    /// Clip range of the surrogate objective (and of the value loss with `clip_vloss`).
    pub clip_coef: f64,
    /// Clip the value loss around the old values, as CleanRL.
    pub clip_vloss: bool,
    /// Weight of the entropy bonus.
    pub ent_coef: f64,
    /// Weight of the value loss.
    pub vf_coef: f64,
    /// Gradient-norm clip of each minibatch update.
    pub max_grad_norm: f64,
    /// Normalise advantages per minibatch.
    pub norm_adv: bool,
    /// Clip of normalised observations and of scaled rewards.
    pub obs_clip: f64,
    /// Clip of the return-scaled reward.
    pub reward_clip: f64,
    /// Hidden layer sizes of the policy and value networks (tanh).
    pub hidden: Vec<usize>,
    /// Threads for stepping the environments (libtorch runs single-threaded in stages).
    pub threads: usize,
    /// Evaluate (stochastic policy, ground-truth reward) every this many steps; 0: never.
    pub eval_every: usize,
    /// Episodes per evaluation (`eval_every`).
    pub eval_episodes: usize,
    /// Evaluate the mean action instead of sampling (a demonstrator's stopping target can
    /// then measure what a deterministic demonstrator shows).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub eval_mean: bool,
    /// Where the minibatch updates run: `fused` (plain Rust, `algo/ppo/fused.rs`); `tch`
    /// (libtorch's autograd) is the tests' reference, refused in pipeline files.
    pub backend: Backend,
    /// Keep a checkpoint of the policy after the first update and every this many updates
    /// (0: none), as the original D-REX code (baselines' ppo2) did before evaluating each.
    pub checkpoint_every: usize,
    /// Bootstrap episodes cut by the time limit with gamma V(s_final) (SB3); false (the
    /// default) treats the limit as termination (CleanRL, and the original code's baselines
    /// PPO2). On learned rewards the bootstrap did worse (analysis/results/ablation/README.md).
    pub bootstrap_truncation: bool,
    /// Where the training episodes end: `task` (the task's termination) or `fixed` (only at
    /// the time limit; [`crate::env::Horizon`]). Evaluations always use the task's.
    #[serde(skip_serializing_if = "Horizon::is_task")]
    pub horizon: Horizon,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    Fused,
    Tch,
}

impl Default for PpoConfig {
    /// CleanRL's defaults (and D-REX's PPO settings).
    fn default() -> Self {
        PpoConfig {
            total_steps: 1_000_000,
            num_envs: 1,
            num_steps: 2048,
            num_minibatches: 32,
            update_epochs: 10,
            lr: 3e-4,
            anneal_lr: true,
            gamma: 0.99,
            gae_lambda: 0.95,
            clip_coef: 0.2,
            clip_vloss: true,
            ent_coef: 0.0,
            vf_coef: 0.5,
            max_grad_norm: 0.5,
            norm_adv: true,
            obs_clip: 10.0,
            reward_clip: 10.0,
            hidden: vec![64, 64],
            threads: 1,
            eval_every: 0,
            eval_episodes: 5,
            eval_mean: false,
            backend: Backend::Fused,
            checkpoint_every: 20,
            bootstrap_truncation: false,
            horizon: Horizon::Task,
        }
    }
}

/// What PPO maximises.
#[allow(clippy::large_enum_variant)] // one per run, never moved in a loop.
pub enum RewardSource {
    GroundTruth,
    /// The task's reward with its forward term negated: the same costs and healthy reward,
    /// progress paid backwards (the reward bench's backward gaits).
    Backward,
    Learned {
        model: RewardEnsemble,
        composition: Composition,
    },
}

/// Reported after every update.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct PpoProgress {
    pub global_step: usize,
    pub update: usize,
    pub updates: usize,
    /// Mean ground-truth return of the training episodes that ended during this rollout.
    pub episodic_return: Option<f64>,
    /// Mean learned return of those episodes, when the reward is learned.
    pub learned_return: Option<f64>,
    pub policy_loss: f64,
    pub value_loss: f64,
    pub entropy: f64,
    pub approx_kl: f64,
    pub clipfrac: f64,
    pub explained_variance: f64,
    /// Wall-clock rate of this update; shown, never written into an artifact.
    pub sps: f64,
    pub eval: Option<ReturnStats>,
}

pub struct PpoResult {
    pub policy: ActorCritic,
    pub curve: Vec<PpoProgress>,
    pub wall_s: f64,
    /// Where the wall time went (for `idrex bench ppo`; never stored).
    pub phases: Phases,
    /// The learned reward's [`RewardEnsemble::capped_fraction`].
    pub reward_capped: Option<f64>,
}

/// Seconds of a PPO run by phase.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Phases {
    /// `VecEnv::step`: the physics and the environments' own bookkeeping.
    pub env_s: f64,
    /// The rest of the rollout: normalising observations, the policy's and critic's
    /// forward passes, sampling and clipping actions, filling the buffer.
    pub policy_s: f64,
    /// The reward PPO trains on (the learned ensemble's inference and composition, or the
    /// environment's), its scaling, bootstrap values and GAE.
    pub reward_s: f64,
    /// The minibatch updates.
    pub update_s: f64,
    /// Everything else: evaluations, checkpoints, statistics.
    pub other_s: f64,
}

/// Receives the policy and the global step every `checkpoint_every` updates.
pub type SaveCheckpoint<'a> = &'a mut dyn FnMut(&ActorCritic, usize) -> Result<()>;

/// Trains a policy with PPO. `on_update` sees every update's statistics and returns false to
/// stop early (the demonstrator stops at a target return); `checkpoint`, when given,
/// receives the policy after the first update and every `cfg.checkpoint_every` updates.
pub fn train(
    id: EnvId,
    cfg: &PpoConfig,
    mut reward: RewardSource,
    seed: u64,
    on_update: &mut dyn FnMut(&PpoProgress) -> bool,
    mut checkpoint: Option<SaveCheckpoint>,
) -> Result<PpoResult> {
    let started = Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut envs = VecEnv::new(id, cfg.num_envs, seed, cfg.threads)?;
    envs.set_horizon(cfg.horizon);
    let (n, od, ad) = (cfg.num_envs, envs.obs_dim(), envs.act_dim());
    let mut agent = new_agent(id, cfg, seed, od, ad);
    let mut updater = update::new(cfg, &agent)?;
    let mut norm =
        Normalisers { obs: RunningMeanStd::new(od), ret: RunningMeanStd::new(1), disc_ret: vec![0.0; n], obs_clip: cfg.obs_clip };
    let mut buf = RolloutBuffer::new(n, cfg.num_steps, od, ad);
    let batch = buf.len();
    let updates = cfg.total_steps / batch;
    let mut obs = envs.obs().to_vec();
    norm.obs.update(&obs);
    let mut curve = Vec::new();
    let mut global_step = 0;
    let mut episode_learned = vec![0.0f64; n];
    let mut scratch = Vec::new();
    let mut phases = Phases::default();

    for update in 1..=updates {
        let upd_start = Instant::now();
        let lr = if cfg.anneal_lr { cfg.lr * (1.0 - (update - 1) as f64 / updates as f64) } else { cfg.lr };
        agent.obs_norm = Some(norm.obs.clone());
        let policy = agent.to_cpu();

        let t = Instant::now();
        let ended_true = collect(&mut envs, &policy, &mut norm, &mut buf, &mut obs, &mut rng, &mut phases.env_s)?;
        phases.policy_s += t.elapsed().as_secs_f64();
        global_step += batch;
        let t = Instant::now();

        let (mut rewards, ended_learned) = scaled_rewards(&mut reward, &buf, &mut norm, &mut episode_learned, cfg);
        if cfg.bootstrap_truncation {
            buf.bootstrap_truncations(&mut rewards, cfg.gamma, |f| policy.value(f, &mut scratch));
        }
        let next_values: Vec<f32> = (0..n).map(|i| policy.value(&norm.obs(&obs[i * od..(i + 1) * od]), &mut scratch)).collect();
        let (advantages, returns) = buf.advantages(&rewards, &next_values, cfg.gamma, cfg.gae_lambda);
        phases.reward_s += t.elapsed().as_secs_f64();
        let t = Instant::now();

        let stats = updater.update(&mut agent, &update::Batch::of(&buf, &advantages, &returns), lr, &mut rng)?;
        phases.update_s += t.elapsed().as_secs_f64();

        if !(stats.policy_loss.is_finite() && stats.value_loss.is_finite()) || rewards.iter().any(|r| !r.is_finite()) {
            return Err(diverged(&stats, &rewards, update, global_step, cfg));
        }
        agent.obs_norm = Some(norm.obs.clone());
        let eval = (cfg.eval_every > 0 && (global_step % cfg.eval_every < batch || update == updates))
            .then(|| evaluate(&agent, id, cfg.eval_episodes, seed::derive(seed, Purpose::PpoEval, update as u64), cfg.eval_mean))
            .transpose()?;
        let progress = PpoProgress {
            global_step,
            update,
            updates,
            episodic_return: crate::stats::mean(&ended_true),
            learned_return: matches!(reward, RewardSource::Learned { .. }).then(|| crate::stats::mean(&ended_learned)).flatten(),
            policy_loss: stats.policy_loss,
            value_loss: stats.value_loss,
            entropy: stats.entropy,
            approx_kl: stats.approx_kl,
            clipfrac: stats.clipfrac,
            explained_variance: explained_variance(&returns, &buf.values),
            sps: batch as f64 / upd_start.elapsed().as_secs_f64(),
            eval,
        };
        let go_on = on_update(&progress);
        curve.push(progress);
        if let Some(save) = &mut checkpoint
            && cfg.checkpoint_every > 0
            && (update == 1 || update % cfg.checkpoint_every == 0)
        {
            save(&agent, global_step)?;
        }
        if !go_on {
            break;
        }
    }
    agent.obs_norm = Some(norm.obs);
    let wall_s = started.elapsed().as_secs_f64();
    // The rollout's time includes the environment's; each phase is counted once.
    phases.policy_s -= phases.env_s;
    phases.other_s = wall_s - phases.env_s - phases.policy_s - phases.reward_s - phases.update_s;
    let reward_capped = match &reward {
        RewardSource::Learned { model, .. } => model.capped_fraction(),
        RewardSource::GroundTruth | RewardSource::Backward => None,
    };
    Ok(PpoResult { policy: agent, curve, wall_s, phases, reward_capped })
}

/// PPO's actor-critic for `id`, initialised from `seed`.
fn new_agent(id: EnvId, cfg: &PpoConfig, seed: u64, obs_dim: usize, act_dim: usize) -> ActorCritic {
    let mut pconfig = PolicyConfig::ppo(obs_dim, act_dim);
    pconfig.hidden = cfg.hidden.clone();
    let mut agent = crate::nn::seeded(seed, || ActorCritic::new(pconfig));
    agent.env = Some(id.name().to_string());
    agent.obs_clip = cfg.obs_clip;
    agent
}

/// The refusal of an update whose losses or rewards are not finite.
fn diverged(stats: &update::UpdateStats, rewards: &[f64], update: usize, global_step: usize, cfg: &PpoConfig) -> Error {
    Error::Diverged(format!(
        "PPO diverged at update {update} (step {global_step}): policy loss {}, value loss {}{}; lower ppo.lr (now {})",
        stats.policy_loss,
        stats.value_loss,
        if rewards.iter().any(|r| !r.is_finite()) { ", non-finite rewards" } else { "" },
        cfg.lr
    ))
}

/// 1 - Var(returns - values) / Var(returns): how much of the returns the critic explains.
fn explained_variance(returns: &[f32], values: &[f32]) -> f64 {
    let var_y = variance(returns);
    let resid: Vec<f32> = returns.iter().zip(values).map(|(r, v)| r - v).collect();
    if var_y == 0.0 { f64::NAN } else { 1.0 - variance(&resid) / var_y }
}

/// Steps every environment `num_steps` times with the current policy, filling `buf`;
/// returns the ground-truth returns of the episodes that ended. Adds the seconds spent in
/// the environments' steps to `env_s`.
fn collect(
    envs: &mut VecEnv,
    policy: &CpuPolicy,
    norm: &mut Normalisers,
    buf: &mut RolloutBuffer,
    obs: &mut [f32],
    rng: &mut ChaCha8Rng,
    env_s: &mut f64,
) -> Result<Vec<f64>> {
    let (n, od, ad) = (buf.num_envs, buf.obs_dim, buf.act_dim);
    let (low, high) = {
        let (l, h) = envs.env(0).action_bounds();
        (l.to_vec(), h.to_vec())
    };
    let (mut mean, mut act, mut scratch) = (vec![0.0f32; ad], vec![0.0f32; n * ad], Vec::new());
    let mut ended = Vec::new();
    buf.clear();
    for t in 0..buf.num_steps {
        for i in 0..n {
            let k = t * n + i;
            let nrow = &mut buf.nobs[k * od..(k + 1) * od];
            nrow.copy_from_slice(&obs[i * od..(i + 1) * od]);
            norm.obs.normalize(nrow, norm.obs_clip);
            policy.mean(nrow, &mut mean, &mut scratch);
            buf.values[k] = policy.value(nrow, &mut scratch);
            let a = &mut buf.actions[k * ad..(k + 1) * ad];
            buf.logp[k] = policy.sample(&mean, rng, a);
            for j in 0..ad {
                act[i * ad + j] = (a[j] as f64).clamp(low[j], high[j]) as f32;
            }
        }
        buf.clipped_actions[t * n * ad..(t + 1) * n * ad].copy_from_slice(&act);
        let stepping = Instant::now();
        let step = envs.step(&act)?;
        *env_s += stepping.elapsed().as_secs_f64();
        for i in 0..n {
            let k = t * n + i;
            buf.env_rewards[k] = step.rewards[i];
            buf.env_forward[k] = step.infos[i].terms.reward_forward;
            buf.terminated[k] = step.terminated[i];
            buf.truncated[k] = step.truncated[i];
            let next = step.final_obs[i].as_deref().unwrap_or(&step.obs[i * od..(i + 1) * od]);
            buf.raw_next[k * od..(k + 1) * od].copy_from_slice(next);
            if step.truncated[i] && !step.terminated[i] {
                let f = norm.obs(next);
                buf.push_truncation(k, f);
            }
        }
        ended.extend(step.episodes.iter().map(|e| e.ret));
        obs.copy_from_slice(&step.obs);
        norm.obs.update(obs);
    }
    Ok(ended)
}

fn variance(v: &[f32]) -> f64 {
    let n = v.len() as f64;
    let m = v.iter().map(|&x| x as f64).sum::<f64>() / n;
    v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / n
}

/// Ground-truth returns of `episodes` episodes of the stochastic policy (or its mean action,
/// `mean`; frozen normalisation), episode k from a reset seeded with `seed + k`.
pub fn evaluate(policy: &ActorCritic, id: EnvId, episodes: usize, seed: u64, mean: bool) -> Result<ReturnStats> {
    let returns: Vec<f64> = evaluation_episodes(policy, id, episodes, seed, mean)?.iter().map(Trajectory::ret).collect();
    Ok(ReturnStats::of(&returns))
}

/// The episodes [`evaluate`] scores, whole (lengths and reward terms for `idrex eval`).
pub fn evaluation_episodes(policy: &ActorCritic, id: EnvId, episodes: usize, seed: u64, mean: bool) -> Result<Vec<Trajectory>> {
    let mut env = Env::new(id)?;
    policy.expect_dims(env.obs_dim(), env.act_dim(), id.name())?;
    let mut actor = PolicyActor::new(policy.to_cpu(), !mean);
    Ok((0..episodes).map(|k| rollout::episode(&mut env, &mut actor, seed.wrapping_add(k as u64), TrajMeta::default())).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::{Kind, Tensor};

    #[test]
    fn a_small_budget_clearly_beats_a_random_policy() {
        // Hopper: a random policy falls within ~20 steps (return ~ 15-20).
        let random = {
            let mut env = Env::new(EnvId::Hopper).unwrap();
            let mut u = crate::rollout::UniformActor { low: vec![-1.0; 3], high: vec![1.0; 3] };
            let r: Vec<f64> = (0..20).map(|s| rollout::episode(&mut env, &mut u, s, TrajMeta::default()).ret()).collect();
            ReturnStats::of(&r).mean
        };
        let cfg = PpoConfig { total_steps: 40_960, num_envs: 2, num_steps: 1024, ..Default::default() };
        let res = train(EnvId::Hopper, &cfg, RewardSource::GroundTruth, 0, &mut |_| true, None).unwrap();
        let trained = evaluate(&res.policy, EnvId::Hopper, 20, 123, false).unwrap();
        assert!(trained.mean > 3.0 * random && trained.mean > 150.0, "trained {trained:?} vs random {random}");
    }

    #[test]
    fn the_tch_backend_takes_the_same_first_step() {
        // One update of one minibatch from the same initial weights: the two backends compute
        // the same loss, so the weights after the step agree to float precision.
        let cfg = PpoConfig { total_steps: 256, num_envs: 1, num_steps: 256, num_minibatches: 1, update_epochs: 1, ..Default::default() };
        let fused = train(EnvId::Hopper, &cfg, RewardSource::GroundTruth, 9, &mut |_| true, None).unwrap();
        let tch_cfg = PpoConfig { backend: Backend::Tch, ..cfg };
        let tch = train(EnvId::Hopper, &tch_cfg, RewardSource::GroundTruth, 9, &mut |_| true, None).unwrap();
        let x = Tensor::ones([1, 11], (Kind::Float, tch::Device::Cpu));
        assert!(fused.policy.mean(&x).allclose(&tch.policy.mean(&x), 1e-4, 1e-5, false));
        assert!(fused.policy.value(&x).allclose(&tch.policy.value(&x), 1e-4, 1e-5, false));
    }

    #[test]
    fn deterministic_for_a_seed() {
        let cfg = PpoConfig { total_steps: 1024, num_envs: 2, num_steps: 256, update_epochs: 2, ..Default::default() };
        let a = train(EnvId::HalfCheetah, &cfg, RewardSource::GroundTruth, 5, &mut |_| true, None).unwrap();
        let b = train(EnvId::HalfCheetah, &cfg, RewardSource::GroundTruth, 5, &mut |_| true, None).unwrap();
        let x = Tensor::ones([1, 17], (Kind::Float, tch::Device::Cpu));
        assert!(a.policy.mean(&x).equal(&b.policy.mean(&x)));
    }
}
