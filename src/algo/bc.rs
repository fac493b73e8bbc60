//! Behavioural cloning as in D-REX: an MLP regresses the demonstrator's actions,
//! loss = squared error summed over action dimensions (mean over the batch)
//! + l2 * sum of squared weights; Adam; an 80/20 train/validation split of the steps.
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor};

use crate::data::Trajectory;
use crate::error::{Error, Result};
use crate::nn::dense::{Buf, LANES, Scratch, Trainer};
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

/// One lane's share of a batch: the rows it gathers, and the gradient of its part of the
/// loss (summed squared errors x `scale`).
struct Lane {
    scratch: Scratch,
    grads: Buf,
    x: Buf,
    y: Vec<f32>,
    dout: Vec<f32>,
    sse: f64,
}

/// Trains a deterministic policy on the (s_t, a_t) pairs of `trajs`, on up to `workers`
/// threads (the result does not depend on how many: see [`crate::nn::dense`]).
pub fn train(trajs: &[Trajectory], cfg: &BcConfig, seed: u64, workers: usize) -> Result<(ActorCritic, BcReport)> {
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
    let mut config = PolicyConfig::bc(od, ad);
    config.hidden = cfg.hidden.clone();
    config.init = cfg.init;
    let policy = crate::nn::seeded(seed, || ActorCritic::new(config));
    let mut trainer = Trainer::new(&policy.actor, cfg.lr, cfg.l2, workers);
    let mut lanes: Vec<Lane> = (0..LANES)
        .map(|_| Lane {
            scratch: Scratch::default(),
            grads: Buf::zeros(trainer.net.len()),
            x: Buf::default(),
            y: Vec::new(),
            dout: Vec::new(),
            sse: 0.0,
        })
        .collect();
    let nt = train.len();
    let batch = cfg.batch_size.min(nt);
    let scale = 2.0 / batch as f32;
    for it in 0..cfg.iterations {
        let picks: Vec<usize> = (0..batch).map(|_| train[rng.random_range(0..nt)]).collect();
        trainer.run(&mut lanes, &picks, |lane, mine, net| {
            lane.grads.fill(0.0);
            lane.sse = 0.0;
            lane.x.resize(mine.len() * od);
            lane.y.clear();
            for (row, &r) in lane.x.chunks_exact_mut(od).zip(mine) {
                row.copy_from_slice(&x[r * od..(r + 1) * od]);
                lane.y.extend_from_slice(&y[r * ad..(r + 1) * ad]);
            }
            let pred = net.forward(&lane.x, mine.len(), &mut lane.scratch);
            lane.dout.clear();
            for (p, t) in pred.iter().zip(&lane.y) {
                lane.sse += ((p - t) as f64).powi(2);
                // d/dp of (p - t)^2 / batch.
                lane.dout.push(scale * (p - t));
            }
            net.backward(&lane.x, mine.len(), &lane.dout, &mut lane.scratch, &mut lane.grads);
        });
        if it % 100 == 0 || it + 1 == cfg.iterations {
            let l = lanes.iter().map(|l| l.sse).sum::<f64>() / batch as f64 + cfg.l2 * trainer.net.weight_l2();
            if !l.is_finite() {
                return Err(Error::Diverged(format!("BC diverged at iteration {it}: the loss is {l}; lower bc.lr (now {})", cfg.lr)));
            }
        }
        trainer.step(lanes.iter().map(|l| &l.grads[..]));
    }
    if !trainer.write_to(&policy.actor) {
        return Err(Error::Diverged(format!("BC ended with non-finite weights; lower bc.lr (now {})", cfg.lr)));
    }
    let report = tch::no_grad(|| BcReport {
        train_steps: train.len(),
        val_steps: val.len(),
        train_loss: mse(&policy, &gather(train, &x, od), &gather(train, &y, ad)).double_value(&[]),
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
        let (policy, report) = train(&trajs, &cfg, 0, 1).unwrap();
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
        let cfg = BcConfig { hidden: vec![32], iterations: 50, batch_size: 37, ..Default::default() };
        let (pa, a) = train(&trajs, &cfg, 7, 1).unwrap();
        // On two threads, with an odd batch whose lanes are unequal: the same bytes.
        let (pb, b) = train(&trajs, &cfg, 7, 2).unwrap();
        assert_eq!(a, b);
        let weights = |p: &ActorCritic| crate::nn::dense::Dense::from_mlp(&p.actor).params.to_vec();
        assert_eq!(weights(&pa), weights(&pb));
    }
}
