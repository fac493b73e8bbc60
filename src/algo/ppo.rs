//! PPO for continuous actions, in CleanRL's order (`ppo_continuous_action.py`), with the
//! implementation details that matter on MuJoCo: GAE, clipped surrogate and clipped value
//! loss, per-minibatch advantage normalisation, running observation normalisation (clipped
//! to +-10), return-based reward scaling (clipped to +-10), linear learning-rate annealing,
//! gradient-norm clipping, orthogonal initialisation and a state-independent log-std.
//!
//! Departure from CleanRL, on purpose: a truncated episode is bootstrapped
//! (r += gamma * V(s_final), as SB3 does) instead of being treated as terminal.
//! The reward is pluggable: the environment's, or a learned [`RewardEnsemble`] (evaluated in
//! one batch per rollout on the next observations, minus its control cost).
use std::path::PathBuf;
use std::time::Instant;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor, nn::OptimizerConfig};

use crate::algo::noise::PolicyActor;
use crate::algo::ppo_fused::{Fused, LossConfig};
use crate::data::{RunningMeanStd, TrajMeta};
use crate::env::{Env, EnvId, VecEnv};
use crate::error::Result;
use crate::nn::{ActorCritic, PolicyConfig, RewardEnsemble};
use crate::rollout::{self, ReturnStats};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Total environment steps.
    pub total_steps: usize,
    pub num_envs: usize,
    /// Steps per environment per rollout.
    pub num_steps: usize,
    pub num_minibatches: usize,
    pub update_epochs: usize,
    pub lr: f64,
    pub anneal_lr: bool,
    pub gamma: f64,
    pub gae_lambda: f64,
    pub clip_coef: f64,
    pub clip_vloss: bool,
    pub ent_coef: f64,
    pub vf_coef: f64,
    pub max_grad_norm: f64,
    pub norm_adv: bool,
    /// Clip of normalised observations and of scaled rewards.
    pub obs_clip: f64,
    pub reward_clip: f64,
    pub hidden: Vec<usize>,
    /// Threads for libtorch and for stepping the environments.
    pub threads: usize,
    /// Evaluate (stochastic policy, ground-truth reward) every this many steps; 0: never.
    pub eval_every: usize,
    pub eval_episodes: usize,
    /// Where the minibatch updates run: `fused` (plain Rust, see ppo_fused.rs) or `tch`
    /// (libtorch autograd). Both compute the same loss; fused is several times faster.
    pub backend: Backend,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
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
            backend: Backend::Fused,
        }
    }
}

/// What PPO maximises.
pub enum RewardSource {
    GroundTruth,
    Learned(RewardEnsemble),
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
    pub sps: f64,
    pub eval: Option<ReturnStats>,
}

pub struct PpoResult {
    pub policy: ActorCritic,
    pub curve: Vec<PpoProgress>,
    pub wall_s: f64,
}

struct Buffers {
    nobs: Vec<f32>,
    actions: Vec<f32>,
    logp: Vec<f32>,
    values: Vec<f32>,
    env_rewards: Vec<f64>,
    raw_next: Vec<f32>,
    clipped_actions: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    /// (t, env, normalised final observation) of every truncated step.
    truncations: Vec<(usize, usize, Vec<f32>)>,
}

/// Trains a policy with PPO. `on_update` sees every update's statistics and returns false to
/// stop early (the demonstrator stops at a target return); `checkpoint`,
/// when given, receives the policy every `checkpoint_every` updates.
pub fn train(
    id: EnvId,
    cfg: &PpoConfig,
    mut reward: RewardSource,
    seed: u64,
    on_update: &mut dyn FnMut(&PpoProgress) -> bool,
    mut checkpoint: Option<(&mut dyn FnMut(&ActorCritic, usize) -> Result<()>, usize)>,
) -> Result<PpoResult> {
    let started = Instant::now();
    tch::set_num_threads(cfg.threads.max(1) as i32);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut envs = VecEnv::new(id, cfg.num_envs, seed, cfg.threads)?;
    let (n, od, ad, t_len) = (cfg.num_envs, envs.obs_dim(), envs.act_dim(), cfg.num_steps);
    let (low, high) = {
        let (l, h) = envs.env(0).action_bounds();
        (l.to_vec(), h.to_vec())
    };
    let mut pconfig = PolicyConfig::ppo(od, ad);
    pconfig.hidden = cfg.hidden.clone();
    let mut agent = crate::nn::seeded(seed, || ActorCritic::new(pconfig));
    agent.env = Some(id.name().to_string());
    agent.obs_clip = cfg.obs_clip;
    let mut obs_rms = RunningMeanStd::new(od);
    let mut ret_rms = RunningMeanStd::new(1);
    let mut disc_ret = vec![0.0f64; n];
    let mut opt = tch::nn::Adam { eps: 1e-5, ..Default::default() }.build(&agent.vs, cfg.lr)?;
    let mut fused = (cfg.backend == Backend::Fused).then(|| Fused::from_agent(&agent));
    let loss_cfg = LossConfig {
        clip_coef: cfg.clip_coef as f32,
        clip_vloss: cfg.clip_vloss,
        ent_coef: cfg.ent_coef as f32,
        vf_coef: cfg.vf_coef as f32,
        norm_adv: cfg.norm_adv,
    };

    let batch = n * t_len;
    let minibatch = (batch / cfg.num_minibatches).max(1);
    let updates = cfg.total_steps / batch;
    let mut buf = Buffers {
        nobs: vec![0.0; batch * od],
        actions: vec![0.0; batch * ad],
        logp: vec![0.0; batch],
        values: vec![0.0; batch],
        env_rewards: vec![0.0; batch],
        raw_next: vec![0.0; batch * od],
        clipped_actions: vec![0.0; batch * ad],
        terminated: vec![false; batch],
        truncated: vec![false; batch],
        truncations: Vec::new(),
    };
    let mut obs = envs.obs().to_vec();
    obs_rms.update(&obs);
    let mut curve = Vec::new();
    let mut global_step = 0;
    let mut scratch = Vec::new();
    let mut mean = vec![0.0f32; ad];
    let mut act = vec![0.0f32; n * ad];
    let mut episode_learned = vec![0.0f64; n];

    for update in 1..=updates {
        let upd_start = Instant::now();
        let lr = if cfg.anneal_lr { cfg.lr * (1.0 - (update - 1) as f64 / updates as f64) } else { cfg.lr };
        opt.set_lr(lr);
        agent.obs_norm = Some(obs_rms.clone());
        let cpu = agent.to_cpu();
        buf.truncations.clear();
        let mut ended_true = Vec::new();
        // ---- rollout ----
        for t in 0..t_len {
            for i in 0..n {
                let row = (t * n + i) * od;
                let nrow = &mut buf.nobs[row..row + od];
                nrow.copy_from_slice(&obs[i * od..(i + 1) * od]);
                obs_rms.normalize(nrow, cfg.obs_clip);
                cpu.mean(nrow, &mut mean, &mut scratch);
                buf.values[t * n + i] = cpu.value(nrow, &mut scratch);
                let a = &mut buf.actions[(t * n + i) * ad..(t * n + i + 1) * ad];
                buf.logp[t * n + i] = cpu.sample(&mean, &mut rng, a);
                for k in 0..ad {
                    act[i * ad + k] = (a[k] as f64).clamp(low[k], high[k]) as f32;
                }
            }
            buf.clipped_actions[t * n * ad..(t + 1) * n * ad].copy_from_slice(&act);
            let step = envs.step(&act)?;
            global_step += n;
            for i in 0..n {
                let k = t * n + i;
                buf.env_rewards[k] = step.rewards[i];
                buf.terminated[k] = step.terminated[i];
                buf.truncated[k] = step.truncated[i];
                let next = step.final_obs[i].as_deref().unwrap_or(&step.obs[i * od..(i + 1) * od]);
                buf.raw_next[k * od..(k + 1) * od].copy_from_slice(next);
                if step.truncated[i] && !step.terminated[i] {
                    let mut f = next.to_vec();
                    obs_rms.normalize(&mut f, cfg.obs_clip);
                    buf.truncations.push((t, i, f));
                }
            }
            ended_true.extend(step.episodes.iter().map(|e| e.ret));
            obs.copy_from_slice(&step.obs);
            obs_rms.update(&obs);
        }
        // ---- rewards: environment or learned, then return-based scaling ----
        let mut rewards: Vec<f64> = match &mut reward {
            RewardSource::GroundTruth => buf.env_rewards.clone(),
            RewardSource::Learned(model) => model.rl_reward(&buf.raw_next, &buf.clipped_actions, ad, true),
        };
        let mut ended_learned = Vec::new();
        for t in 0..t_len {
            for i in 0..n {
                let k = t * n + i;
                episode_learned[i] += rewards[k];
                disc_ret[i] = disc_ret[i] * cfg.gamma + rewards[k];
                ret_rms.update_scalar(disc_ret[i]);
                rewards[k] = (rewards[k] / (ret_rms.var[0] + 1e-8).sqrt()).clamp(-cfg.reward_clip, cfg.reward_clip);
                if buf.terminated[k] || buf.truncated[k] {
                    disc_ret[i] = 0.0;
                    ended_learned.push(episode_learned[i]);
                    episode_learned[i] = 0.0;
                }
            }
        }
        for (t, i, f) in &buf.truncations {
            rewards[t * n + i] += cfg.gamma * cpu.value(f, &mut scratch) as f64;
        }
        // ---- GAE ----
        let mut next_values = vec![0.0f32; n];
        for i in 0..n {
            let mut f = obs[i * od..(i + 1) * od].to_vec();
            obs_rms.normalize(&mut f, cfg.obs_clip);
            next_values[i] = cpu.value(&f, &mut scratch);
        }
        let mut adv = vec![0.0f32; batch];
        let mut last = vec![0.0f64; n];
        for t in (0..t_len).rev() {
            for i in 0..n {
                let k = t * n + i;
                let done = buf.terminated[k] || buf.truncated[k];
                let next_v = if t + 1 == t_len { next_values[i] } else { buf.values[k + n] } as f64;
                let nonterminal = if done { 0.0 } else { 1.0 };
                let delta = rewards[k] + cfg.gamma * next_v * nonterminal - buf.values[k] as f64;
                last[i] = delta + cfg.gamma * cfg.gae_lambda * nonterminal * last[i];
                adv[k] = last[i] as f32;
            }
        }
        let returns: Vec<f32> = adv.iter().zip(&buf.values).map(|(a, v)| a + v).collect();
        // ---- update ----
        let (mut pg_l, mut v_l, mut ent_l, mut kl, mut clipfracs) = (0.0, 0.0, 0.0, 0.0, Vec::new());
        let mut idx: Vec<i64> = (0..batch as i64).collect();
        if let Some(f) = &mut fused {
            // Minibatch buffers reused across the update's 320 steps.
            let gather = |dst: &mut Vec<f32>, src: &[f32], d: usize, mb: &[i64]| {
                dst.clear();
                for &k in mb {
                    dst.extend_from_slice(&src[k as usize * d..(k as usize + 1) * d]);
                }
            };
            let mut mbuf: [Vec<f32>; 6] = Default::default();
            for _epoch in 0..cfg.update_epochs {
                idx.shuffle(&mut rng);
                for mb in idx.chunks(minibatch) {
                    let [o, a, lp, ad_, r, v] = &mut mbuf;
                    gather(o, &buf.nobs, od, mb);
                    gather(a, &buf.actions, ad, mb);
                    gather(lp, &buf.logp, 1, mb);
                    gather(ad_, &adv, 1, mb);
                    gather(r, &returns, 1, mb);
                    gather(v, &buf.values, 1, mb);
                    let st = f.loss_and_grad(o, a, lp, ad_, r, v, loss_cfg);
                    f.clip_and_step(cfg.max_grad_norm as f32, lr as f32, 1e-5);
                    (pg_l, v_l, ent_l, kl) = (st.policy_loss, st.value_loss, st.entropy, st.approx_kl);
                    clipfracs.push(st.clipfrac);
                }
            }
            f.write_to(&mut agent);
        } else {
            let b_obs = Tensor::from_slice(&buf.nobs).view([batch as i64, od as i64]);
            let b_act = Tensor::from_slice(&buf.actions).view([batch as i64, ad as i64]);
            let b_logp = Tensor::from_slice(&buf.logp);
            let b_adv = Tensor::from_slice(&adv);
            let b_ret = Tensor::from_slice(&returns);
            let b_val = Tensor::from_slice(&buf.values);
            for _epoch in 0..cfg.update_epochs {
                idx.shuffle(&mut rng);
                for mb in idx.chunks(minibatch) {
                    let mbi = Tensor::from_slice(mb);
                    let (new_logp, entropy) = agent.log_prob_entropy(&b_obs.index_select(0, &mbi), &b_act.index_select(0, &mbi));
                    let new_v = agent.value(&b_obs.index_select(0, &mbi));
                    let logratio = &new_logp - b_logp.index_select(0, &mbi);
                    let ratio = logratio.exp();
                    tch::no_grad(|| {
                        kl = ((&ratio - 1.0) - &logratio).mean(Kind::Float).double_value(&[]);
                        clipfracs.push((&ratio - 1.0).abs().gt(cfg.clip_coef).to_kind(Kind::Float).mean(Kind::Float).double_value(&[]));
                    });
                    let mut mb_adv = b_adv.index_select(0, &mbi);
                    if cfg.norm_adv {
                        mb_adv = (&mb_adv - mb_adv.mean(Kind::Float)) / (mb_adv.std(true) + 1e-8);
                    }
                    let pg1 = -&mb_adv * &ratio;
                    let pg2 = -&mb_adv * ratio.clamp(1.0 - cfg.clip_coef, 1.0 + cfg.clip_coef);
                    let pg_loss = pg1.maximum(&pg2).mean(Kind::Float);
                    let mb_ret = b_ret.index_select(0, &mbi);
                    let v_loss: Tensor = if cfg.clip_vloss {
                        let mb_val = b_val.index_select(0, &mbi);
                        let unclipped = (&new_v - &mb_ret).square();
                        let clipped = (&mb_val + (&new_v - &mb_val).clamp(-cfg.clip_coef, cfg.clip_coef) - &mb_ret).square();
                        unclipped.maximum(&clipped).mean(Kind::Float) * 0.5
                    } else {
                        (&new_v - &mb_ret).square().mean(Kind::Float) * 0.5
                    };
                    let ent = entropy.mean(Kind::Float);
                    let loss: Tensor = &pg_loss - &ent * cfg.ent_coef + &v_loss * cfg.vf_coef;
                    opt.zero_grad();
                    loss.backward();
                    opt.clip_grad_norm(cfg.max_grad_norm);
                    opt.step();
                    pg_l = pg_loss.double_value(&[]);
                    v_l = v_loss.double_value(&[]);
                    ent_l = ent.double_value(&[]);
                }
            }
        }
        let var_y = variance(&returns);
        let resid: Vec<f32> = returns.iter().zip(&buf.values).map(|(r, v)| r - v).collect();
        agent.obs_norm = Some(obs_rms.clone());
        let eval = (cfg.eval_every > 0 && (global_step % cfg.eval_every < batch || update == updates))
            .then(|| evaluate(&agent, id, cfg.eval_episodes, seed.wrapping_add(1_000_000 + update as u64)))
            .transpose()?;
        let progress = PpoProgress {
            global_step,
            update,
            updates,
            episodic_return: mean_of(&ended_true),
            learned_return: matches!(reward, RewardSource::Learned(_)).then(|| mean_of(&ended_learned)).flatten(),
            policy_loss: pg_l,
            value_loss: v_l,
            entropy: ent_l,
            approx_kl: kl,
            clipfrac: clipfracs.iter().sum::<f64>() / clipfracs.len().max(1) as f64,
            explained_variance: if var_y == 0.0 { f64::NAN } else { 1.0 - variance(&resid) / var_y },
            sps: batch as f64 / upd_start.elapsed().as_secs_f64(),
            eval,
        };
        let go_on = on_update(&progress);
        curve.push(progress);
        if let Some((save, every)) = &mut checkpoint
            && *every > 0
            && update % *every == 0
        {
            save(&agent, global_step)?;
        }
        if !go_on {
            break;
        }
    }
    agent.obs_norm = Some(obs_rms);
    Ok(PpoResult { policy: agent, curve, wall_s: started.elapsed().as_secs_f64() })
}

fn mean_of(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn variance(v: &[f32]) -> f64 {
    let n = v.len() as f64;
    let m = v.iter().map(|&x| x as f64).sum::<f64>() / n;
    v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / n
}

/// Ground-truth returns of `episodes` episodes of the stochastic policy (frozen
/// normalisation), episode k from a reset seeded with `seed + k`.
pub fn evaluate(policy: &ActorCritic, id: EnvId, episodes: usize, seed: u64) -> Result<ReturnStats> {
    let mut env = Env::new(id)?;
    policy.expect_dims(env.obs_dim(), env.act_dim(), id.name())?;
    let mut actor = PolicyActor::new(policy.to_cpu(), true);
    let returns: Vec<f64> =
        (0..episodes).map(|k| rollout::episode(&mut env, &mut actor, seed.wrapping_add(k as u64), TrajMeta::default()).ret()).collect();
    Ok(ReturnStats::of(&returns))
}

/// Where `idrex train ppo` writes its checkpoints.
pub fn checkpoint_dir(out: &std::path::Path, step: usize) -> PathBuf {
    out.join("checkpoints").join(format!("step-{step:08}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_budget_clearly_beats_a_random_policy() {
        // Hopper: a random policy falls within ~20 steps (return ~ 15-20).
        let random = {
            let mut env = Env::new(EnvId::Hopper).unwrap();
            let mut u = crate::algo::noise::UniformActor { low: vec![-1.0; 3], high: vec![1.0; 3] };
            let r: Vec<f64> = (0..20).map(|s| rollout::episode(&mut env, &mut u, s, TrajMeta::default()).ret()).collect();
            ReturnStats::of(&r).mean
        };
        let cfg = PpoConfig { total_steps: 40_960, num_envs: 2, num_steps: 1024, ..Default::default() };
        let res = train(EnvId::Hopper, &cfg, RewardSource::GroundTruth, 0, &mut |_| true, None).unwrap();
        let trained = evaluate(&res.policy, EnvId::Hopper, 20, 123).unwrap();
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
