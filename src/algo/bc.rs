//! Behavioural cloning as in D-REX: an MLP regresses the demonstrator's actions,
//! loss = squared error summed over action dimensions (mean over the batch)
//! + l2 * sum of squared weights; Adam; an 80/20 train/validation split of the steps.
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor, nn::OptimizerConfig};

use crate::data::Trajectory;
use crate::error::{Error, Result};
use crate::nn::{ActorCritic, PolicyConfig, WeightInit};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BcConfig {
    /// Hidden layer sizes (D-REX: 4 x 256, ReLU).
    pub hidden: Vec<usize>,
    pub lr: f64,
    pub batch_size: usize,
    pub iterations: usize,
    /// Weight of the sum of squared weights.
    pub l2: f64,
    /// Fraction of the steps held out for validation.
    pub val_fraction: f64,
    /// Initialisation of the network.
    pub init: WeightInit,
}

impl Default for BcConfig {
    fn default() -> Self {
        BcConfig {
            hidden: vec![256; 4],
            lr: 1e-4,
            batch_size: 128,
            iterations: 50_000,
            l2: 1e-3,
            val_fraction: 0.2,
            init: WeightInit::TorchDefault,
        }
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BcReport {
    pub train_steps: usize,
    pub val_steps: usize,
    /// Mean over samples of the summed squared error, without the L2 term.
    #[serde(with = "crate::stats::nan_as_null")]
    pub train_loss: f64,
    /// NaN (stored as null) without validation steps.
    #[serde(with = "crate::stats::nan_as_null")]
    pub val_loss: f64,
}

fn pairs(trajs: &[Trajectory]) -> (Vec<f32>, Vec<f32>, usize, usize) {
    let (od, ad) = (trajs[0].obs_dim, trajs[0].act_dim);
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for t in trajs {
        for s in 0..t.len() {
            x.extend_from_slice(t.obs_row(s));
            y.extend_from_slice(t.action_row(s));
        }
    }
    (x, y, od, ad)
}

fn mse(policy: &ActorCritic, x: &Tensor, y: &Tensor) -> Tensor {
    (policy.mean(x) - y).square().sum_dim_intlist(-1, false, Kind::Float).mean(Kind::Float)
}

/// Trains a deterministic policy on the (s_t, a_t) pairs of `trajs`.
pub fn train(trajs: &[Trajectory], cfg: &BcConfig, seed: u64) -> Result<(ActorCritic, BcReport)> {
    if trajs.iter().all(|t| t.is_empty()) {
        return Err(Error::Invalid("behavioural cloning needs at least one demonstration step".into()));
    }
    let (x, y, od, ad) = pairs(trajs);
    let n = x.len() / od;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut rng);
    let n_val = ((n as f64) * cfg.val_fraction).round() as usize;
    let n_val = n_val.min(n.saturating_sub(1));
    let (val, train) = idx.split_at(n_val);
    let gather = |rows: &[usize], src: &[f32], d: usize| -> Tensor {
        let mut v = Vec::with_capacity(rows.len() * d);
        for &r in rows {
            v.extend_from_slice(&src[r * d..(r + 1) * d]);
        }
        Tensor::from_slice(&v).view([rows.len() as i64, d as i64])
    };
    let (xt, yt) = (gather(train, &x, od), gather(train, &y, ad));
    let mut config = PolicyConfig::bc(od, ad);
    config.hidden = cfg.hidden.clone();
    config.init = cfg.init;
    let policy = crate::nn::seeded(seed, || ActorCritic::new(config));
    let mut opt = tch::nn::Adam::default().build(&policy.vs, cfg.lr)?;
    let _ftz = crate::nn::FlushDenormals::new();
    let nt = train.len();
    for it in 0..cfg.iterations {
        let picks: Vec<i64> = (0..cfg.batch_size.min(nt)).map(|_| rng.random_range(0..nt) as i64).collect();
        let b = Tensor::from_slice(&picks);
        let loss = mse(&policy, &xt.index_select(0, &b), &yt.index_select(0, &b)) + cfg.l2 * policy.actor.weight_l2();
        opt.backward_step(&loss);
        if it % 100 == 0 || it + 1 == cfg.iterations {
            let l = loss.double_value(&[]);
            if !l.is_finite() {
                return Err(Error::Diverged(format!("BC diverged at iteration {it}: the loss is {l}; lower bc.lr (now {})", cfg.lr)));
            }
        }
    }
    let report = tch::no_grad(|| BcReport {
        train_steps: train.len(),
        val_steps: val.len(),
        train_loss: mse(&policy, &xt, &yt).double_value(&[]),
        val_loss: if val.is_empty() { f64::NAN } else { mse(&policy, &gather(val, &x, od), &gather(val, &y, ad)).double_value(&[]) },
    });
    Ok((policy, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{Env, EnvId};
    use crate::rollout::PolicyActor;
    use crate::rollout::{self, Actor};

    /// A known linear policy on Hopper; BC on its rollouts must reproduce its actions.
    struct Linear;
    impl Actor for Linear {
        fn act(&mut self, obs: &[f32], _rng: &mut ChaCha8Rng, out: &mut [f32]) {
            for (i, o) in out.iter_mut().enumerate() {
                *o = (0.5 * obs[2 + i] - 0.3 * obs[5 + i]).tanh();
            }
        }
    }

    #[test]
    fn recovers_a_known_policy_from_its_rollouts() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let trajs: Vec<_> = (0..20).map(|s| rollout::episode(&mut env, &mut Linear, s, Default::default())).collect();
        let cfg = BcConfig { hidden: vec![64, 64], lr: 1e-3, iterations: 1500, l2: 0.0, ..Default::default() };
        let (policy, report) = train(&trajs, &cfg, 0).unwrap();
        // Actions are in [-1, 1]; predicting 0 would cost about sum of E[a^2], far above this.
        let baseline: f64 = trajs.iter().flat_map(|t| t.actions.iter()).map(|&a| (a as f64).powi(2)).sum::<f64>()
            / trajs.iter().map(|t| t.len()).sum::<usize>() as f64;
        assert!(report.val_loss < 0.05 * baseline, "{report:?}, baseline {baseline}");
        // And it acts like the policy on a fresh episode.
        let mut clone = PolicyActor::new(policy.to_cpu(), false);
        let fresh = rollout::episode(&mut env, &mut Linear, 99, Default::default());
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut err = 0.0;
        for t in 0..fresh.len() {
            let mut a = [0.0f32; 3];
            clone.act(fresh.obs_row(t), &mut rng, &mut a);
            err += a.iter().zip(fresh.action_row(t)).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>();
        }
        assert!(err / (fresh.len() as f64) < 0.05 * baseline);
    }

    #[test]
    fn is_deterministic_for_a_seed() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let trajs: Vec<_> = (0..2).map(|s| rollout::episode(&mut env, &mut Linear, s, Default::default())).collect();
        let cfg = BcConfig { hidden: vec![32], iterations: 50, ..Default::default() };
        let (_, a) = train(&trajs, &cfg, 7).unwrap();
        let (_, b) = train(&trajs, &cfg, 7).unwrap();
        assert_eq!(a, b);
    }
}
