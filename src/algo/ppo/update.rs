//! PPO's update: `update_epochs` passes over the batch in shuffled minibatches, each one
//! gradient step on the clipped surrogate, the (clipped) value loss and the entropy bonus,
//! with gradient-norm clipping and Adam. Two backends compute the same step:
//! [`FusedUpdate`] in plain Rust ([`super::fused`]) and [`TchUpdate`] through libtorch
//! autograd.
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor, nn::OptimizerConfig};

use super::fused::{Fused, LossConfig};
use super::{Backend, PpoConfig};
use crate::error::Result;
use crate::nn::ActorCritic;

/// The batch an update reads, rows as in the rollout buffer.
pub struct Batch<'a> {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub obs: &'a [f32],
    pub actions: &'a [f32],
    pub logp: &'a [f32],
    pub advantages: &'a [f32],
    pub returns: &'a [f32],
    pub values: &'a [f32],
}

impl<'a> Batch<'a> {
    /// The rollout in `buf` with its advantages and returns.
    pub fn of(buf: &'a super::buffer::RolloutBuffer, advantages: &'a [f32], returns: &'a [f32]) -> Batch<'a> {
        Batch {
            obs_dim: buf.obs_dim,
            act_dim: buf.act_dim,
            obs: &buf.nobs,
            actions: &buf.actions,
            logp: &buf.logp,
            advantages,
            returns,
            values: &buf.values,
        }
    }

    fn len(&self) -> usize {
        self.logp.len()
    }
}

/// The last minibatch's losses (as CleanRL logs them) and the mean clip fraction.
#[derive(Debug, Clone, Copy, Default)]
pub struct UpdateStats {
    pub policy_loss: f64,
    pub value_loss: f64,
    pub entropy: f64,
    pub approx_kl: f64,
    pub clipfrac: f64,
}

/// One PPO update of `agent` on a batch.
pub trait Update {
    fn update(&mut self, agent: &mut ActorCritic, batch: &Batch, lr: f64, rng: &mut ChaCha8Rng) -> Result<UpdateStats>;
}

/// The backend `cfg` names, starting from `agent`'s weights.
pub fn new(cfg: &PpoConfig, agent: &ActorCritic) -> Result<Box<dyn Update>> {
    Ok(match cfg.backend {
        Backend::Fused => Box::new(FusedUpdate { fused: Fused::from_agent(agent), cfg: cfg.clone(), mb: Default::default() }),
        Backend::Tch => {
            Box::new(TchUpdate { opt: tch::nn::Adam { eps: 1e-5, ..Default::default() }.build(&agent.vs, cfg.lr)?, cfg: cfg.clone() })
        }
    })
}

/// Shuffled minibatches of row indices, one epoch.
fn minibatches<'a>(idx: &'a mut [i64], rng: &mut ChaCha8Rng, num_minibatches: usize) -> std::slice::Chunks<'a, i64> {
    idx.shuffle(rng);
    let size = (idx.len() / num_minibatches).max(1);
    idx.chunks(size)
}

pub struct FusedUpdate {
    fused: Fused,
    cfg: PpoConfig,
    /// Minibatch buffers reused across the update's gradient steps.
    mb: [Vec<f32>; 6],
}

impl Update for FusedUpdate {
    fn update(&mut self, agent: &mut ActorCritic, b: &Batch, lr: f64, rng: &mut ChaCha8Rng) -> Result<UpdateStats> {
        let cfg = &self.cfg;
        let loss = LossConfig {
            clip_coef: cfg.clip_coef as f32,
            clip_vloss: cfg.clip_vloss,
            ent_coef: cfg.ent_coef as f32,
            vf_coef: cfg.vf_coef as f32,
            norm_adv: cfg.norm_adv,
        };
        let gather = |dst: &mut Vec<f32>, src: &[f32], d: usize, mb: &[i64]| {
            dst.clear();
            for &k in mb {
                dst.extend_from_slice(&src[k as usize * d..(k as usize + 1) * d]);
            }
        };
        let mut idx: Vec<i64> = (0..b.len() as i64).collect();
        let mut stats = UpdateStats::default();
        let mut clipfracs = Vec::new();
        for _epoch in 0..cfg.update_epochs {
            for mb in minibatches(&mut idx, rng, cfg.num_minibatches) {
                let [o, a, lp, adv, ret, v] = &mut self.mb;
                gather(o, b.obs, b.obs_dim, mb);
                gather(a, b.actions, b.act_dim, mb);
                gather(lp, b.logp, 1, mb);
                gather(adv, b.advantages, 1, mb);
                gather(ret, b.returns, 1, mb);
                gather(v, b.values, 1, mb);
                let st = self.fused.loss_and_grad(o, a, lp, adv, ret, v, loss);
                self.fused.clip_and_step(cfg.max_grad_norm as f32, lr as f32, 1e-5);
                (stats.policy_loss, stats.value_loss, stats.entropy, stats.approx_kl) =
                    (st.policy_loss, st.value_loss, st.entropy, st.approx_kl);
                clipfracs.push(st.clipfrac);
            }
        }
        self.fused.write_to(agent);
        stats.clipfrac = crate::stats::mean(&clipfracs).unwrap_or(0.0);
        Ok(stats)
    }
}

pub struct TchUpdate {
    opt: tch::nn::Optimizer,
    cfg: PpoConfig,
}

impl Update for TchUpdate {
    fn update(&mut self, agent: &mut ActorCritic, b: &Batch, lr: f64, rng: &mut ChaCha8Rng) -> Result<UpdateStats> {
        let cfg = &self.cfg;
        self.opt.set_lr(lr);
        let n = b.len() as i64;
        let b_obs = Tensor::from_slice(b.obs).view([n, b.obs_dim as i64]);
        let b_act = Tensor::from_slice(b.actions).view([n, b.act_dim as i64]);
        let (b_logp, b_adv, b_ret, b_val) =
            (Tensor::from_slice(b.logp), Tensor::from_slice(b.advantages), Tensor::from_slice(b.returns), Tensor::from_slice(b.values));
        let mut idx: Vec<i64> = (0..n).collect();
        let mut stats = UpdateStats::default();
        let mut clipfracs = Vec::new();
        for _epoch in 0..cfg.update_epochs {
            for mb in minibatches(&mut idx, rng, cfg.num_minibatches) {
                let mbi = Tensor::from_slice(mb);
                let (new_logp, entropy) = agent.log_prob_entropy(&b_obs.index_select(0, &mbi), &b_act.index_select(0, &mbi));
                let new_v = agent.value(&b_obs.index_select(0, &mbi));
                let logratio = &new_logp - b_logp.index_select(0, &mbi);
                let ratio = logratio.exp();
                tch::no_grad(|| {
                    stats.approx_kl = ((&ratio - 1.0) - &logratio).mean(Kind::Float).double_value(&[]);
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
                self.opt.zero_grad();
                loss.backward();
                self.opt.clip_grad_norm(cfg.max_grad_norm);
                self.opt.step();
                stats.policy_loss = pg_loss.double_value(&[]);
                stats.value_loss = v_loss.double_value(&[]);
                stats.entropy = ent.double_value(&[]);
            }
        }
        stats.clipfrac = crate::stats::mean(&clipfracs).unwrap_or(0.0);
        Ok(stats)
    }
}
