//! PPO's minibatch update (losses, backward pass, gradient-norm clipping, Adam) written out
//! in plain Rust for the small actor-critic MLPs PPO uses on MuJoCo: the loss here, the
//! networks' passes in [`crate::nn::Dense`], the step in [`crate::nn::adam`].
//!
//! Why: a 64-64 network on a minibatch of 64 is a few hundred thousand multiply-adds, far
//! less than libtorch's per-operator overhead; with autograd each of the 320 gradient steps
//! per update cost about 1 ms, most of a 1M-step run. The networks still live in the tch
//! VarStore (initialisation, saving, the `tch` backend): [`Fused::from_agent`] reads them
//! and [`Fused::write_to`] writes them back. `tests::matches_libtorch_autograd` checks the
//! loss and every gradient against libtorch's autograd of the same loss.
use crate::nn::adam::Adam;
use crate::nn::dense::{BiasOrder, Scratch};
use crate::nn::{ActorCritic, Dense};

/// Per-minibatch statistics, as CleanRL logs them.
#[derive(Debug, Clone, Copy, Default)]
pub struct MinibatchStats {
    pub policy_loss: f64,
    pub value_loss: f64,
    pub entropy: f64,
    pub approx_kl: f64,
    pub clipfrac: f64,
}

/// The loss settings of [`super::PpoConfig`] that the update needs.
#[derive(Debug, Clone, Copy)]
pub struct LossConfig {
    pub clip_coef: f32,
    pub clip_vloss: bool,
    pub ent_coef: f32,
    pub vf_coef: f32,
    pub norm_adv: bool,
}

pub struct Fused {
    actor: Dense,
    critic: Dense,
    log_std: Vec<f32>,
    /// The gradient of the actor's, the critic's and the log-std's parameters, in that order
    /// (the order of the gradient's norm and of Adam's moments).
    grads: Vec<f32>,
    adam: Adam,
    actor_acts: Scratch,
    critic_acts: Scratch,
}

impl Fused {
    pub fn from_agent(agent: &ActorCritic) -> Self {
        let critic = agent.critic.as_ref().expect("PPO's agent has a critic");
        // PPO's stored bytes come from this order.
        let net = |mlp| Dense::from_mlp(mlp).with_bias_order(BiasOrder::First);
        let (actor, critic) = (net(&agent.actor), net(critic));
        let log_std = Vec::<f32>::try_from(agent.log_std.detach().to_kind(tch::Kind::Float).flatten(0, -1)).expect("f32 log-std");
        let n = actor.len() + critic.len() + log_std.len();
        Fused {
            actor,
            critic,
            log_std,
            grads: vec![0.0; n],
            adam: Adam::new(n),
            actor_acts: Scratch::default(),
            critic_acts: Scratch::default(),
        }
    }

    /// Copies the parameters back into the agent's VarStore.
    pub fn write_to(&self, agent: &mut ActorCritic) {
        self.actor.write_to(&agent.actor);
        self.critic.write_to(agent.critic.as_ref().expect("PPO's agent has a critic"));
        tch::no_grad(|| {
            let mut t = agent.log_std.shallow_clone();
            t.copy_(&tch::Tensor::from_slice(&self.log_std).view(t.size().as_slice()));
        });
    }

    /// Computes the PPO loss of one minibatch and leaves its gradient in `self.grads`.
    #[allow(clippy::too_many_arguments)]
    pub fn loss_and_grad(
        &mut self,
        obs: &[f32],
        actions: &[f32],
        old_logp: &[f32],
        adv: &[f32],
        returns: &[f32],
        old_values: &[f32],
        cfg: LossConfig,
    ) -> MinibatchStats {
        let b = old_logp.len();
        let ad = self.log_std.len();
        let bf = b as f32;
        self.grads.iter_mut().for_each(|g| *g = 0.0);
        let mu = self.actor.forward(obs, b, &mut self.actor_acts);
        let values = self.critic.forward(obs, b, &mut self.critic_acts);
        let ls = &self.log_std;
        let half_log_2pi = 0.5 * (2.0 * std::f32::consts::PI).ln();
        // Minibatch advantage normalisation (unbiased std, as torch's .std()).
        let (amean, astd) = if cfg.norm_adv {
            let m = adv.iter().sum::<f32>() / bf;
            let var = adv.iter().map(|a| (a - m) * (a - m)).sum::<f32>() / (bf - 1.0).max(1.0);
            (m, var.sqrt() + 1e-8)
        } else {
            (0.0, 1.0)
        };
        let mut d_mu = vec![0.0f32; b * ad];
        let mut d_ls = vec![0.0f32; ad];
        let mut d_v = vec![0.0f32; b];
        let mut stats = MinibatchStats::default();
        let (lo, hi) = (1.0 - cfg.clip_coef, 1.0 + cfg.clip_coef);
        // The standard deviations, once per minibatch (the same values as per sample).
        let mut std = [0.0f32; 32];
        for j in 0..ad {
            std[j] = ls[j].exp();
        }
        for r in 0..b {
            let mut logp = 0.0f32;
            let mut z = [0.0f32; 32];
            for j in 0..ad {
                z[j] = (actions[r * ad + j] - mu[r * ad + j]) / std[j];
                logp += -0.5 * z[j] * z[j] - ls[j] - half_log_2pi;
            }
            let logratio = logp - old_logp[r];
            let ratio = logratio.exp();
            stats.approx_kl += ((ratio - 1.0) - logratio) as f64;
            stats.clipfrac += f64::from((ratio - 1.0).abs() > cfg.clip_coef);
            let a = (adv[r] - amean) / astd;
            let (pg1, pg2) = (-a * ratio, -a * ratio.clamp(lo, hi));
            stats.policy_loss += pg1.max(pg2) as f64;
            // Inside the clip range both branches are equal and carry the gradient; outside
            // it only the unclipped branch does, when it is the larger.
            let d_ratio = if (lo..=hi).contains(&ratio) || pg1 > pg2 { -a / bf } else { 0.0 };
            let d_logp = d_ratio * ratio;
            for j in 0..ad {
                d_mu[r * ad + j] = d_logp * z[j] / std[j];
                d_ls[j] += d_logp * (z[j] * z[j] - 1.0);
            }
            let (v, ret) = (values[r], returns[r]);
            let unclipped = (v - ret) * (v - ret);
            let (vl, dv) = if cfg.clip_vloss {
                let delta = v - old_values[r];
                let vc = old_values[r] + delta.clamp(-cfg.clip_coef, cfg.clip_coef);
                let clipped = (vc - ret) * (vc - ret);
                let inside = delta.abs() <= cfg.clip_coef;
                let dv = if inside || unclipped > clipped { v - ret } else { 0.0 };
                (unclipped.max(clipped), dv)
            } else {
                (unclipped, v - ret)
            };
            stats.value_loss += 0.5 * vl as f64;
            d_v[r] = cfg.vf_coef * dv / bf;
        }
        let entropy: f32 = ls.iter().map(|l| l + 0.5 + half_log_2pi).sum();
        for g in &mut d_ls {
            *g -= cfg.ent_coef;
        }
        let (ga, rest) = self.grads.split_at_mut(self.actor.len());
        let (gc, gls) = rest.split_at_mut(self.critic.len());
        for (g, d) in gls.iter_mut().zip(&d_ls) {
            *g += d;
        }
        self.actor.backward(obs, b, &d_mu, &mut self.actor_acts, ga);
        self.critic.backward(obs, b, &d_v, &mut self.critic_acts, gc);
        stats.policy_loss /= b as f64;
        stats.value_loss /= b as f64;
        stats.approx_kl /= b as f64;
        stats.clipfrac /= b as f64;
        stats.entropy = entropy as f64;
        stats
    }

    /// Clips the gradient's global norm to `max_norm` (as torch's clip_grad_norm_) and takes
    /// one Adam step (betas 0.9, 0.999).
    pub fn clip_and_step(&mut self, max_norm: f32, lr: f32, eps: f32) {
        let norm = self.grads.iter().map(|g| g * g).sum::<f32>().sqrt();
        let scale = (max_norm / (norm + 1e-6)).min(1.0);
        let params = [&mut self.actor.params[..], &mut self.critic.params[..], &mut self.log_std[..]];
        self.adam.step_scaled(params, &self.grads, scale, lr, eps);
        self.actor.refresh();
        self.critic.refresh();
    }

    /// The last minibatch's gradient: the actor's, the critic's, then the log-std's.
    pub fn grads(&self) -> &[f32] {
        &self.grads
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::PolicyConfig;
    use rand::{Rng, SeedableRng};
    use tch::{Kind, Tensor};

    /// The same loss through libtorch's autograd (the `tch` backend's formula).
    #[allow(clippy::too_many_arguments)] // the reference loss takes every tensor of the update.
    fn tch_loss(
        agent: &ActorCritic,
        obs: &Tensor,
        act: &Tensor,
        old_logp: &Tensor,
        adv: &Tensor,
        ret: &Tensor,
        old_v: &Tensor,
        c: LossConfig,
    ) -> Tensor {
        let (logp, entropy) = agent.log_prob_entropy(obs, act);
        let v = agent.value(obs);
        let ratio = (&logp - old_logp).exp();
        let a = (adv - adv.mean(Kind::Float)) / (adv.std(true) + 1e-8);
        let pg = (-&a * &ratio).maximum(&(-&a * ratio.clamp(1.0 - c.clip_coef as f64, 1.0 + c.clip_coef as f64))).mean(Kind::Float);
        let unclipped = (&v - ret).square();
        let clipped = (old_v + (&v - old_v).clamp(-c.clip_coef as f64, c.clip_coef as f64) - ret).square();
        let vl = unclipped.maximum(&clipped).mean(Kind::Float) * 0.5;
        pg - entropy.mean(Kind::Float) * c.ent_coef as f64 + vl * c.vf_coef as f64
    }

    #[test]
    fn matches_libtorch_autograd() {
        let agent = crate::nn::seeded(3, || ActorCritic::new(PolicyConfig::ppo(5, 2)));
        let b = 64;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let mut r = |n: usize, s: f32| -> Vec<f32> { (0..n).map(|_| rng.random_range(-s..s)).collect() };
        let (obs, act, adv, ret, old_v) = (r(b * 5, 2.0), r(b * 2, 1.5), r(b, 1.0), r(b, 1.0), r(b, 0.5));
        // Old log-probabilities spread so that many ratios fall outside the clip range.
        let (lp, _) = agent.log_prob_entropy(&Tensor::from_slice(&obs).view([64, 5]), &Tensor::from_slice(&act).view([64, 2]));
        let jitter = r(b, 0.6);
        let old_logp: Vec<f32> = Vec::<f32>::try_from(lp.detach()).unwrap().iter().zip(&jitter).map(|(l, j)| l + j).collect();
        let cfg = LossConfig { clip_coef: 0.2, clip_vloss: true, ent_coef: 0.01, vf_coef: 0.5, norm_adv: true };

        let mut fused = Fused::from_agent(&agent);
        let stats = fused.loss_and_grad(&obs, &act, &old_logp, &adv, &ret, &old_v, cfg);
        let t = |v: &[f32], shape: &[i64]| Tensor::from_slice(v).view(shape);
        let loss = tch_loss(
            &agent,
            &t(&obs, &[64, 5]),
            &t(&act, &[64, 2]),
            &t(&old_logp, &[64]),
            &t(&adv, &[64]),
            &t(&ret, &[64]),
            &t(&old_v, &[64]),
            cfg,
        );
        loss.backward();
        let ours = stats.policy_loss - 0.01 * stats.entropy + 0.5 * stats.value_loss;
        assert!((ours - loss.double_value(&[])).abs() < 1e-5, "loss {ours} vs {}", loss.double_value(&[]));
        let mlps = [&agent.actor, agent.critic.as_ref().unwrap()];
        let params = mlps.iter().flat_map(|m| m.parameters()).flat_map(|(w, b)| [w, b]).chain([&agent.log_std]);
        let want: Vec<f32> = params.flat_map(|t| Vec::<f32>::try_from(t.grad().flatten(0, -1)).unwrap()).collect();
        assert_eq!(fused.grads().len(), want.len());
        for (i, (a, e)) in fused.grads().iter().zip(&want).enumerate() {
            assert!((a - e).abs() <= 1e-5 + 1e-4 * e.abs(), "parameter {i}: ours {a} vs autograd {e}");
        }
    }
}
