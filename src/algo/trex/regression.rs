//! SSRR's reward regression without AIRL (`trex.loss: regression`).
//!
//! SSRR (Chen et al. 2020) fits a sigmoid of performance against noise level to its noise-
//! injected rollouts, scored by AIRL's reward, then regresses a new reward on it: a snippet of
//! L steps from a rollout at noise eps has the target L x curve(eps). Here the ranking
//! ensemble T-REX learns from the same set stands in for AIRL's reward (idrex has no AIRL):
//! each ranked trajectory's predicted reward per step is the curve's data. Snippets are
//! `window / 5` to `window` steps long; the loss is the mean squared error of the snippet
//! sums plus `l2 * sum of squared weights`, with T-REX's optimiser, batches and iterations.
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{TrexConfig, push_inputs};
use crate::data::Trajectory;
use crate::error::{Error, Result};
use crate::kernels::Buf;
use crate::nn::dense::{Dense, Scratch};
use crate::nn::trainer::{LANES, Trainer};
use crate::nn::{RewardConfig, RewardEnsemble, RewardNet};
use crate::seed::{self, Purpose};

/// The regression ensemble's seeds are the ranking ensemble's with this mixed in.
const SEED_MIX: u64 = 0x55_52_52;

/// A decreasing sigmoid of the noise level:
/// `low + (high - low) / (1 + exp(slope * (noise - mid)))`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Curve {
    pub low: f64,
    pub high: f64,
    pub mid: f64,
    pub slope: f64,
}

impl Curve {
    pub fn at(&self, noise: f64) -> f64 {
        self.low + (self.high - self.low) * shape(self.slope, self.mid, noise)
    }
}

fn shape(slope: f64, mid: f64, noise: f64) -> f64 {
    1.0 / (1.0 + (slope * (noise - mid)).exp())
}

/// The least-squares sigmoid through `(noise, value)` points: a grid over the midpoint (41
/// points across the noise range) and the slope (30 from 0.5 to 200, geometric), the levels in
/// closed form at each. Deterministic; None with fewer than two distinct noise levels.
pub fn fit(noise: &[f64], value: &[f64]) -> Option<Curve> {
    let (lo, hi) = noise.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    if noise.len() != value.len() || hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let n = noise.len() as f64;
    let mut best: Option<(f64, Curve)> = None;
    for i in 0..=40 {
        let mid = lo + (hi - lo) * i as f64 / 40.0;
        for j in 0..30 {
            let slope = 0.5 * 400f64.powf(j as f64 / 29.0);
            let s: Vec<f64> = noise.iter().map(|&x| shape(slope, mid, x)).collect();
            // value = low + span * s, by least squares.
            let (ms, mv) = (s.iter().sum::<f64>() / n, value.iter().sum::<f64>() / n);
            let sxx: f64 = s.iter().map(|x| (x - ms).powi(2)).sum();
            let sxy: f64 = s.iter().zip(value).map(|(x, y)| (x - ms) * (y - mv)).sum();
            let span = if sxx > 1e-12 { sxy / sxx } else { 0.0 };
            let low = mv - span * ms;
            let sse: f64 = s.iter().zip(value).map(|(x, y)| (low + span * x - y).powi(2)).sum();
            if best.as_ref().is_none_or(|(b, _)| sse < *b) {
                best = Some((sse, Curve { low, high: low + span, mid, slope }));
            }
        }
    }
    best.map(|(_, c)| c)
}

/// A window of `len` steps of trajectory `t` from `start`, and its target sum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snippet {
    pub t: usize,
    pub start: usize,
    pub len: usize,
    pub target: f64,
}

/// `n` snippets, each from a random non-empty trajectory.
pub fn sample_snippets(trajs: &[Trajectory], curve: &Curve, window: usize, n: usize, rng: &mut ChaCha8Rng) -> Vec<Snippet> {
    let usable: Vec<usize> = (0..trajs.len()).filter(|&i| !trajs[i].is_empty()).collect();
    (0..n)
        .map(|_| {
            let t = usable[rng.random_range(0..usable.len())];
            let max = window.min(trajs[t].len()).max(1);
            let len = rng.random_range((max / 5).max(1)..=max);
            let start = rng.random_range(0..=trajs[t].len() - len);
            Snippet { t, start, len, target: len as f64 * curve.at(trajs[t].meta.noise) }
        })
        .collect()
}

/// One lane's share of a batch: its snippets' summed squared error and (when training) the
/// gradient of `scale` x that sum.
struct Lane {
    scratch: Scratch,
    grads: Buf,
    x: Vec<f32>,
    dout: Vec<f32>,
    sq: f64,
}

impl Lane {
    fn run(&mut self, net: &Dense, trajs: &[Trajectory], snippets: &[&Snippet], action_input: bool, scale: Option<f32>) {
        self.grads.fill(0.0);
        self.sq = 0.0;
        for s in snippets {
            self.x.clear();
            push_inputs(&trajs[s.t], s.start..s.start + s.len, action_input, &mut self.x);
            let r = net.forward(&self.x, s.len, &mut self.scratch);
            let err = r.iter().map(|&v| v as f64).sum::<f64>() - s.target;
            self.sq += err * err;
            if let Some(scale) = scale {
                self.dout.clear();
                self.dout.extend(std::iter::repeat_n((2.0 * err) as f32 * scale, s.len));
                net.backward(&self.x, s.len, &self.dout, &mut self.scratch, &mut self.grads);
            }
        }
    }
}

/// One regression member's fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RegressionReport {
    pub train_snippets: usize,
    pub val_snippets: usize,
    /// Mean squared error of the snippet sums.
    #[serde(with = "crate::stats::nan_as_null")]
    pub train_mse: f64,
    #[serde(with = "crate::stats::nan_as_null")]
    pub val_mse: f64,
    /// The targets' variance over the validation snippets (`val_mse` against it is 1 - R²).
    #[serde(with = "crate::stats::nan_as_null")]
    pub val_target_var: f64,
}

/// Trains a fresh ensemble of `config`'s shape by regression on `curve`; `trajs` are the ranked
/// set (each with its noise level).
pub fn train(
    trajs: &[Trajectory],
    curve: &Curve,
    config: RewardConfig,
    cfg: &TrexConfig,
    seed: u64,
    threads: usize,
) -> Result<(RewardEnsemble, Vec<RegressionReport>)> {
    if trajs.iter().all(Trajectory::is_empty) {
        return Err(Error::Invalid("the regression learner needs a non-empty ranked set".into()));
    }
    let seed = seed ^ SEED_MIX;
    let model = crate::nn::seeded(seed, || RewardEnsemble::new(config));
    let reports =
        model.nets.iter().enumerate().map(|(m, net)| train_member(net, m, trajs, curve, cfg, seed, threads)).collect::<Result<_>>()?;
    Ok((model, reports))
}

fn train_member(
    net: &RewardNet,
    m: usize,
    trajs: &[Trajectory],
    curve: &Curve,
    cfg: &TrexConfig,
    seed: u64,
    threads: usize,
) -> Result<RegressionReport> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed::derive(seed, Purpose::TrexModel, m as u64));
    let snippets = sample_snippets(trajs, curve, cfg.window, cfg.pairs_per_model, &mut rng);
    let n_val = (((snippets.len() as f64) * cfg.val_fraction).round() as usize).min(snippets.len().saturating_sub(1));
    let (val, train) = snippets.split_at(n_val);
    let mut trainer = Trainer::new(net, cfg.lr, cfg.l2, threads.clamp(1, LANES), cfg.precision);
    let new_lane = || Lane { scratch: Scratch::default(), grads: Buf::zeros(trainer.net.len()), x: Vec::new(), dout: Vec::new(), sq: 0.0 };
    let mut lanes: Vec<Lane> = (0..LANES).map(|_| new_lane()).collect();
    for it in 0..cfg.iterations {
        let picks: Vec<&Snippet> = (0..cfg.batch_size).map(|_| &train[rng.random_range(0..train.len())]).collect();
        let scale = 1.0 / picks.len() as f32;
        trainer.run(&mut lanes, &picks, |lane, mine, net| lane.run(net, trajs, mine, cfg.action_input, Some(scale)));
        trainer.step(lanes.iter().map(|l| &l.grads[..]));
        let mse = lanes.iter().map(|l| l.sq).sum::<f64>() / picks.len() as f64;
        if !mse.is_finite() {
            return Err(Error::Diverged(format!("regression member {m} diverged at iteration {it}; lower trex.lr (now {})", cfg.lr)));
        }
    }
    if !trainer.write_to(net) {
        return Err(Error::Diverged(format!("regression member {m} has non-finite weights; lower trex.lr (now {})", cfg.lr)));
    }
    let mse = |set: &[Snippet], lane: &mut Lane| {
        let refs: Vec<&Snippet> = set.iter().collect();
        lane.run(&trainer.net, trajs, &refs, cfg.action_input, None);
        if set.is_empty() { f64::NAN } else { lane.sq / set.len() as f64 }
    };
    let lane = &mut lanes[0];
    let targets: Vec<f64> = val.iter().map(|s| s.target).collect();
    let mean = targets.iter().sum::<f64>() / targets.len().max(1) as f64;
    Ok(RegressionReport {
        train_snippets: train.len(),
        val_snippets: val.len(),
        train_mse: mse(train, lane),
        val_mse: mse(val, lane),
        val_target_var: targets.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / targets.len().max(1) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::TrajMeta;
    use crate::nn::WeightInit;

    #[test]
    fn fits_a_sigmoid_it_was_given() {
        let truth = Curve { low: -1.0, high: 2.0, mid: 0.45, slope: 12.0 };
        let noise: Vec<f64> = (0..20).map(|i| i as f64 * 0.05).collect();
        let value: Vec<f64> = noise.iter().map(|&x| truth.at(x)).collect();
        let c = fit(&noise, &value).unwrap();
        for &x in &noise {
            assert!((c.at(x) - truth.at(x)).abs() < 0.05, "{c:?} at {x}");
        }
        assert!(fit(&[0.1, 0.1], &[1.0, 2.0]).is_none(), "one noise level");
    }

    /// Trajectories whose observation is their noise level: the regression learns a reward per
    /// step that falls with the noise as the curve does, and its snippets' sums scale with
    /// their length.
    #[test]
    fn regresses_onto_the_curve() {
        let noise: Vec<f64> = (0..10).map(|i| i as f64 * 0.1).collect();
        let trajs: Vec<Trajectory> = noise
            .iter()
            .map(|&eps| Trajectory {
                obs_dim: 1,
                act_dim: 1,
                obs: vec![eps as f32; 41],
                actions: vec![0.0; 40],
                rewards: vec![0.0; 40],
                terms: vec![Default::default(); 40],
                meta: TrajMeta { noise: eps, ..Default::default() },
                ..Default::default()
            })
            .collect();
        let curve = Curve { low: 0.0, high: 1.0, mid: 0.5, slope: 10.0 };
        let config = RewardConfig {
            obs_dim: 1,
            obs_stride: None,
            obs_offset: None,
            act_dim: None,
            hidden: vec![16],
            models: 2,
            clip: 100.0,
            init: WeightInit::TorchDefault,
        };
        let cfg = TrexConfig { window: 20, pairs_per_model: 500, iterations: 400, lr: 3e-3, l2: 0.0, ..Default::default() };
        let (model, reports) = train(&trajs, &curve, config, &cfg, 3, 2).unwrap();
        assert!(reports.iter().all(|r| r.val_mse < 0.1 * r.val_target_var), "{reports:?}");
        let per_step = |t: &Trajectory| model.predicted_return(t.next_obs(), &t.actions) / t.len() as f64;
        for (t, &eps) in trajs.iter().zip(&noise) {
            assert!((per_step(t) - curve.at(eps)).abs() < 0.15, "noise {eps}: {} against {}", per_step(t), curve.at(eps));
        }
        let (again, _) = train(&trajs, &curve, model.config.clone(), &cfg, 3, 1).unwrap();
        assert_eq!(
            again.predicted_return(trajs[0].next_obs(), &trajs[0].actions),
            model.predicted_return(trajs[0].next_obs(), &trajs[0].actions)
        );
    }
}
