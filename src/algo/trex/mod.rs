//! T-REX reward learning from ranked trajectories.
//!
//! Each trajectory carries a score (higher is better; D-REX uses minus the noise level).
//! A training pair takes two trajectories whose scores differ by at least `min_margin`
//! (from the same group, when `same_group`), an independent random window of the same length
//! from each, and labels the better-scored window as preferred. The loss is Bradley-Terry:
//! softmax cross-entropy over the two windows' summed predicted rewards, plus
//! `l2 * sum of squared weights`. Each model of the ensemble trains on its own pairs.
use rand::seq::IndexedRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::nn;

use crate::data::Trajectory;
use crate::error::{Error, Result};
use crate::kernels::Buf;
use crate::kernels::bf16::Precision;
use crate::nn::dense::{Dense, Scratch};
use crate::nn::trainer::{LANES, Trainer};
use crate::nn::{Device, RewardConfig, RewardEnsemble, RewardNet};
use crate::seed::{self, Purpose};

mod config;
pub mod regression;
pub use config::{RewardObservation, TrexConfig, TrexLoss};
mod torch;
pub(crate) use torch::train_torch;

/// A training pair: windows `(trajectory, start)` of length `len`; `label` is 0 when the
/// first window is preferred, 1 when the second is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    pub a: (usize, usize),
    pub b: (usize, usize),
    pub len: usize,
    pub label: i64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModelReport {
    pub train_pairs: usize,
    pub val_pairs: usize,
    #[serde(with = "crate::stats::nan_as_null")]
    pub final_loss: f64,
    #[serde(with = "crate::stats::nan_as_null")]
    pub train_accuracy: f64,
    #[serde(with = "crate::stats::nan_as_null")]
    pub val_accuracy: f64,
    /// Every 50 iterations, for the learning-curve plot.
    pub curve: Vec<TrexCurvePoint>,
}

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrexCurvePoint {
    pub iteration: usize,
    #[serde(with = "crate::stats::nan_as_null")]
    pub loss: f64,
    pub batch_accuracy: f64,
}

/// Which trajectory is preferred to which.
///
/// `i` is preferred to `j` when both are in the same group (or groups are ignored) and
/// `scores[i] - scores[j] >= min_margin`; with `cross_level`, also whenever
/// `levels[i] > levels[j]` (iD-REX's equation 8: later iterations rank higher).
#[derive(Debug, Clone, Default)]
pub struct Ranking {
    pub scores: Vec<f64>,
    pub groups: Vec<usize>,
    pub levels: Vec<usize>,
    pub same_group: bool,
    pub cross_level: bool,
}

impl Ranking {
    /// Scores alone, one group, one level (D-REX, or T-REX with ranked returns).
    pub fn by_score(scores: Vec<f64>) -> Self {
        let n = scores.len();
        Ranking { scores, groups: vec![0; n], levels: vec![0; n], same_group: false, cross_level: false }
    }

    pub(crate) fn prefers(&self, i: usize, j: usize, margin: f64) -> bool {
        let group_ok = !self.same_group || self.groups[i] == self.groups[j];
        let by_score = group_ok && self.levels[i] == self.levels[j] && self.scores[i] - self.scores[j] >= margin - 1e-12;
        by_score || (self.cross_level && self.levels[i] > self.levels[j])
    }
}

/// Samples `n` pairs. Fails when no two trajectories can be compared.
pub fn sample_pairs(trajs: &[Trajectory], ranking: &Ranking, cfg: &TrexConfig, n: usize, rng: &mut ChaCha8Rng) -> Result<Vec<Pair>> {
    let mut candidates = Vec::new();
    for i in 0..trajs.len() {
        for j in 0..trajs.len() {
            if i != j && ranking.prefers(i, j, cfg.min_margin) && !trajs[i].is_empty() && !trajs[j].is_empty() {
                candidates.push((i, j)); // i is better than j
            }
        }
    }
    if candidates.is_empty() {
        return Err(Error::Invalid(format!(
            "no two trajectories have scores at least {} apart{}; lower min_margin or widen the noise schedule",
            cfg.min_margin,
            if ranking.same_group { " within one group" } else { "" }
        )));
    }
    Ok((0..n)
        .map(|_| {
            let &(better, worse) = candidates.choose(rng).expect("non-empty");
            // The options draw only when set, so the default's stream is D-REX's as before.
            let want = match cfg.window_max {
                Some(most) if most > cfg.window => rng.random_range(cfg.window..=most),
                _ => cfg.window,
            };
            let len = want.min(trajs[better].len()).min(trajs[worse].len());
            let start = |t: &Trajectory, rng: &mut ChaCha8Rng| rng.random_range(0..=t.len() - len);
            let (wb, ww) = if cfg.aligned {
                let w = start(&trajs[worse], rng);
                let last = trajs[better].len() - len;
                ((better, rng.random_range(w.min(last)..=last)), (worse, w))
            } else {
                let wb = (better, start(&trajs[better], rng));
                (wb, (worse, start(&trajs[worse], rng)))
            };
            if rng.random_bool(0.5) { Pair { a: wb, b: ww, len, label: 0 } } else { Pair { a: ww, b: wb, len, label: 1 } }
        })
        .collect())
}

/// Pairs fed to the network at a time: a chunk's activations (2 x 50 rows per pair x 256
/// units per layer) then stay in L2.
const CHUNK_PAIRS: usize = 2;

/// Appends the reward network's input rows of `t`'s steps `steps` to `x`.
fn push_inputs(t: &Trajectory, steps: std::ops::Range<usize>, action_input: bool, x: &mut Vec<f32>) {
    for s in steps {
        // The reward of step s is paid on s_{s+1}.
        x.extend_from_slice(t.obs_row(s + 1));
        if action_input {
            x.extend_from_slice(t.action_row(s));
        }
    }
}

/// Writes the input rows of `pairs` (each pair's first window, then its second) into `x`;
/// returns the number of rows.
fn fill_rows(trajs: &[Trajectory], pairs: &[&Pair], action_input: bool, x: &mut Vec<f32>) -> usize {
    x.clear();
    let mut rows = 0;
    for p in pairs {
        for (ti, start) in [p.a, p.b] {
            push_inputs(&trajs[ti], start..start + p.len, action_input, x);
            rows += p.len;
        }
    }
    rows
}

/// One lane's share of a batch: its pairs' summed cross-entropy, how many it ranks right,
/// and (when training) the gradient of `scale` x that sum.
struct Lane {
    scratch: Scratch,
    grads: Buf,
    x: Vec<f32>,
    dout: Vec<f32>,
    ce: f64,
    correct: usize,
}

impl Lane {
    fn new(params: usize) -> Self {
        Lane { scratch: Scratch::default(), grads: Buf::zeros(params), x: Vec::new(), dout: Vec::new(), ce: 0.0, correct: 0 }
    }

    fn run(&mut self, net: &Dense, trajs: &[Trajectory], pairs: &[&Pair], action_input: bool, scale: Option<f32>) {
        self.grads.fill(0.0);
        (self.ce, self.correct) = (0.0, 0);
        for chunk in pairs.chunks(CHUNK_PAIRS) {
            let rows = fill_rows(trajs, chunk, action_input, &mut self.x);
            let r = net.forward(&self.x, rows, &mut self.scratch);
            self.dout.clear();
            let mut at = 0;
            for p in chunk {
                let a: f64 = r[at..at + p.len].iter().map(|&v| v as f64).sum();
                let b: f64 = r[at + p.len..at + 2 * p.len].iter().map(|&v| v as f64).sum();
                at += 2 * p.len;
                // Bradley-Terry: softmax cross-entropy over the two windows' returns.
                let hi = a.max(b);
                let lse = hi + ((a - hi).exp() + (b - hi).exp()).ln();
                self.ce += lse - if p.label == 0 { a } else { b };
                // As argmax: the first of equal logits wins.
                self.correct += usize::from((b > a) == (p.label == 1));
                if let Some(scale) = scale {
                    let pa = (a - lse).exp();
                    let da = (pa - if p.label == 0 { 1.0 } else { 0.0 }) as f32 * scale;
                    self.dout.extend(std::iter::repeat_n(da, p.len));
                    self.dout.extend(std::iter::repeat_n(-da, p.len));
                }
            }
            if scale.is_some() {
                net.backward(&self.x, rows, &self.dout, &mut self.scratch, &mut self.grads);
            }
        }
    }
}

/// The fraction of `pairs` that `net` ranks right.
fn accuracy(net: &Dense, trajs: &[Trajectory], pairs: &[Pair], action_input: bool, lane: &mut Lane) -> f64 {
    if pairs.is_empty() {
        return f64::NAN;
    }
    let refs: Vec<&Pair> = pairs.iter().collect();
    lane.run(net, trajs, &refs, action_input, None);
    lane.correct as f64 / pairs.len() as f64
}

/// Trains an ensemble on ranked trajectories; returns it with one report per model.
///
/// Each model trains with its own generator, its batches split into [`LANES`] lanes whose
/// gradients are summed in order, so the result does not depend on `workers`. With at least
/// as many workers as models, the models train concurrently (each on `workers / models`
/// threads, one per lane at most); with fewer, one after another, each on all the workers
/// (3 models on 2 cores would otherwise leave one core idle a third of the time).
pub fn train(
    trajs: &[Trajectory],
    ranking: &Ranking,
    cfg: &TrexConfig,
    seed: u64,
    workers: usize,
    device: Device,
) -> Result<(RewardEnsemble, Vec<ModelReport>)> {
    if trajs.is_empty() || trajs.len() != ranking.scores.len() {
        return Err(Error::Invalid("T-REX needs one score per trajectory and at least two trajectories".into()));
    }
    let obs_dim = trajs[0].obs_dim;
    let config = RewardConfig {
        obs_dim,
        obs_stride: None,
        obs_offset: None,
        act_dim: cfg.action_input.then_some(trajs[0].act_dim),
        hidden: cfg.hidden.clone(),
        models: cfg.models,
        clip: 100.0,
        init: cfg.init,
    };
    let mut model = crate::nn::seeded(seed, || RewardEnsemble::new(config));
    if device == Device::Cuda {
        device.ensure_available()?;
        if cfg.precision != Precision::F32 {
            return Err(Error::Invalid("trex.precision: bf16 is a CPU path; on a GPU set precision: f32 (or device: cpu)".into()));
        }
        let reports = train_torch(&mut model, trajs, ranking, cfg, seed, device.tch())?;
        return Ok((model, reports));
    }
    let workers = workers.max(1);
    let groups = if workers >= cfg.models { cfg.models } else { 1 };
    let lane_threads = (workers / groups).clamp(1, LANES);
    // Tensors cannot be shared between threads, only moved: each group owns its models.
    let mut owned: Vec<Vec<(usize, nn::VarStore, RewardNet)>> = (0..groups).map(|_| Vec::new()).collect();
    for (m, (store, net)) in model.stores.drain(..).zip(model.nets.drain(..)).enumerate() {
        owned[m % groups].push((m, store, net));
    }
    let mut done: Vec<(usize, nn::VarStore, RewardNet, Result<ModelReport>)> = std::thread::scope(|scope| {
        let handles: Vec<_> = owned
            .into_iter()
            .map(|mine| {
                scope.spawn(move || {
                    // OpenMP's thread count is per thread: set it in this one too.
                    crate::nn::single_threaded();
                    mine.into_iter()
                        .map(|(m, store, net)| {
                            let report = train_model(&net, m, trajs, ranking, cfg, seed, lane_threads);
                            (m, store, net, report)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("a T-REX worker panicked")).collect()
    });
    done.sort_by_key(|d| d.0);
    let mut reports = Vec::with_capacity(done.len());
    for (_, store, net, report) in done {
        model.stores.push(store);
        model.nets.push(net);
        reports.push(report?);
    }
    Ok((model, reports))
}

/// Model `m`'s pairs, of which the first `n_val` are for validation, and the generator that
/// then draws its batches.
fn model_pairs(m: usize, trajs: &[Trajectory], ranking: &Ranking, cfg: &TrexConfig, seed: u64) -> Result<(Vec<Pair>, usize, ChaCha8Rng)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed::derive(seed, Purpose::TrexModel, m as u64));
    let pairs = sample_pairs(trajs, ranking, cfg, cfg.pairs_per_model, &mut rng)?;
    let n_val = ((pairs.len() as f64) * cfg.val_fraction).round() as usize;
    let n_val = n_val.min(pairs.len().saturating_sub(1));
    Ok((pairs, n_val, rng))
}

fn diverged(m: usize, it: usize, loss: f64, cfg: &TrexConfig) -> Error {
    Error::Diverged(format!("T-REX model {m} diverged at iteration {it}: the pair loss is {loss:.3e}; lower trex.lr (now {})", cfg.lr))
}

fn non_finite(m: usize, cfg: &TrexConfig) -> Error {
    Error::Diverged(format!("T-REX model {m} has non-finite weights; lower trex.lr (now {})", cfg.lr))
}

/// Trains model `m` of the ensemble on its own pairs, on `threads` threads.
fn train_model(
    net: &RewardNet,
    m: usize,
    trajs: &[Trajectory],
    ranking: &Ranking,
    cfg: &TrexConfig,
    seed: u64,
    threads: usize,
) -> Result<ModelReport> {
    let (pairs, n_val, mut rng) = model_pairs(m, trajs, ranking, cfg, seed)?;
    let (val, train) = pairs.split_at(n_val);
    let mut trainer = Trainer::new(net, cfg.lr, cfg.l2, threads, cfg.precision);
    let mut lanes: Vec<Lane> = (0..LANES).map(|_| Lane::new(trainer.net.len())).collect();
    let mut final_loss = f64::NAN;
    let mut curve = Vec::new();
    for it in 0..cfg.iterations {
        let picks: Vec<&Pair> = (0..cfg.batch_size).map(|_| &train[rng.random_range(0..train.len())]).collect();
        // The loss is the mean over the batch's pairs.
        let scale = 1.0 / picks.len() as f32;
        trainer.run(&mut lanes, &picks, |lane, mine, net| lane.run(net, trajs, mine, cfg.action_input, Some(scale)));
        trainer.step(lanes.iter().map(|l| &l.grads[..]));
        final_loss = lanes.iter().map(|l| l.ce).sum::<f64>() / picks.len() as f64;
        // A pair's cross-entropy starts near ln 2; far above it the model is not learning.
        if !final_loss.is_finite() || final_loss > 1e3 {
            return Err(diverged(m, it, final_loss, cfg));
        }
        if it % 50 == 0 || it + 1 == cfg.iterations {
            // As the loss, of the weights before this iteration's step.
            let acc = lanes.iter().map(|l| l.correct).sum::<usize>() as f64 / picks.len() as f64;
            curve.push(TrexCurvePoint { iteration: it, loss: final_loss, batch_accuracy: acc });
        }
    }
    if !trainer.write_to(net) {
        return Err(non_finite(m, cfg));
    }
    let lane = &mut lanes[0];
    Ok(ModelReport {
        train_pairs: train.len(),
        val_pairs: val.len(),
        final_loss,
        train_accuracy: accuracy(&trainer.net, trajs, train, cfg.action_input, lane),
        val_accuracy: accuracy(&trainer.net, trajs, val, cfg.action_input, lane),
        curve,
    })
}

#[cfg(test)]
mod tests {
    use super::torch::DevicePairs;
    use super::*;
    use crate::data::TrajMeta;
    use crate::nn::WeightInit;
    use crate::stats::{pairwise_accuracy, spearman};
    use tch::Tensor;

    /// Toy trajectories in a 3-d observation space whose true reward is obs[0] - obs[1];
    /// the score handed to T-REX is the true return, as T-REX's ranked checkpoints are.
    fn toy(n: usize, rng: &mut ChaCha8Rng) -> Vec<Trajectory> {
        (0..n)
            .map(|k| {
                let drift = rng.random_range(-1.0..1.0f32);
                let mut obs = Vec::new();
                for _ in 0..=40 {
                    obs.extend([
                        drift + rng.random_range(-0.5..0.5f32),
                        -drift + rng.random_range(-0.5..0.5f32),
                        rng.random_range(-1.0..1.0f32),
                    ]);
                }
                let rewards = (1..=40).map(|t| (obs[3 * t] - obs[3 * t + 1]) as f64).collect();
                Trajectory {
                    obs_dim: 3,
                    act_dim: 1,
                    obs,
                    actions: vec![0.0; 40],
                    rewards,
                    terms: vec![Default::default(); 40],
                    meta: TrajMeta { group: k % 2, ..Default::default() },
                    ..Default::default()
                }
            })
            .collect()
    }

    /// A small ensemble that learns the toy reward in seconds.
    fn known_reward_cfg() -> TrexConfig {
        TrexConfig {
            hidden: vec![32, 32],
            models: 2,
            pairs_per_model: 1000,
            window: 20,
            min_margin: 1.0,
            lr: 1e-3,
            iterations: 300,
            l2: 0.0,
            ..Default::default()
        }
    }

    #[test]
    fn learns_to_rank_trajectories_of_a_known_reward() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let train_set = toy(30, &mut rng);
        let test_set = toy(30, &mut rng);
        let scores: Vec<f64> = train_set.iter().map(|t| t.ret()).collect();
        let cfg = known_reward_cfg();
        let (model, reports) = train(&train_set, &Ranking::by_score(scores), &cfg, 1, 2, Device::Cpu).unwrap();
        assert!(reports.iter().all(|r| r.val_accuracy > 0.85), "{reports:?}");
        let pred: Vec<f64> = test_set.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
        let truth: Vec<f64> = test_set.iter().map(|t| t.ret()).collect();
        assert!(spearman(&pred, &truth) > 0.9, "spearman {}", spearman(&pred, &truth));
        assert!(pairwise_accuracy(&pred, &truth) > 0.85);
    }

    /// In bf16 the reward learns the ranking as in f32, its weights differ from the f32 run's
    /// (the products round differently), and they do not depend on the number of workers.
    #[test]
    fn learns_in_bf16_and_does_not_depend_on_the_workers() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let train_set = toy(30, &mut rng);
        let test_set = toy(30, &mut rng);
        let ranking = Ranking::by_score(train_set.iter().map(|t| t.ret()).collect());
        let cfg = TrexConfig { precision: Precision::Bf16, ..known_reward_cfg() };
        let (model, reports) = train(&train_set, &ranking, &cfg, 1, 2, Device::Cpu).unwrap();
        assert!(reports.iter().all(|r| r.val_accuracy > 0.85), "{reports:?}");
        let pred: Vec<f64> = test_set.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
        let truth: Vec<f64> = test_set.iter().map(|t| t.ret()).collect();
        assert!(spearman(&pred, &truth) > 0.9, "spearman {}", spearman(&pred, &truth));
        let (f32_model, _) =
            train(&train_set, &ranking, &TrexConfig { precision: Precision::F32, ..cfg.clone() }, 1, 2, Device::Cpu).unwrap();
        assert_ne!(weights(&model), weights(&f32_model));
        for workers in [1, 3] {
            let (again, again_reports) = train(&train_set, &ranking, &cfg, 1, workers, Device::Cpu).unwrap();
            assert_eq!(weights(&again), weights(&model), "{workers} workers");
            assert_eq!(again_reports, reports);
        }
    }

    /// Every parameter of every model, flat.
    fn weights(model: &RewardEnsemble) -> Vec<f32> {
        model.nets.iter().flat_map(|n| Dense::from_mlp(n).params.to_vec()).collect()
    }

    #[test]
    fn does_not_depend_on_the_number_of_workers() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let trajs = toy(12, &mut rng);
        let ranking = Ranking::by_score(trajs.iter().map(|t| t.ret()).collect());
        // An odd batch, so that the lanes are unequal too.
        let cfg = TrexConfig {
            hidden: vec![16, 16],
            models: 3,
            pairs_per_model: 200,
            window: 10,
            min_margin: 1.0,
            batch_size: 7,
            iterations: 40,
            ..Default::default()
        };
        let runs: Vec<_> = [1, 2, 3, 6].into_iter().map(|w| train(&trajs, &ranking, &cfg, 9, w, Device::Cpu).unwrap()).collect();
        for (model, reports) in &runs[1..] {
            assert_eq!(weights(model), weights(&runs[0].0));
            assert_eq!(reports, &runs[0].1);
        }
    }

    /// Trajectories of two lengths (15 and 40 steps), so that a window of 25 is cut short
    /// in some pairs and the GPU path's padding mask is exercised.
    fn two_lengths(rng: &mut ChaCha8Rng) -> Vec<Trajectory> {
        let mut trajs = toy(16, rng);
        for t in trajs.iter_mut().skip(8) {
            t.obs.truncate(16 * 3);
            t.actions.truncate(15);
            t.rewards.truncate(15);
            t.terms.truncate(15);
        }
        trajs
    }

    /// The GPU path (libtorch's autograd), run here on the CPU, computes the same loss and
    /// gradient as the CPU path on the same batch. (Weights are not compared after
    /// training: where the two windows' sums nearly cancel, a gradient is mostly rounding,
    /// and Adam's first steps turn that into steps of the full learning rate on either path.)
    #[test]
    fn torch_path_computes_the_cpu_paths_gradient() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let trajs = two_lengths(&mut rng);
        let ranking = Ranking::by_score(trajs.iter().map(|t| t.ret()).collect());
        let cfg = TrexConfig { hidden: vec![32, 32], pairs_per_model: 300, window: 25, min_margin: 0.5, ..Default::default() };
        let (pairs, n_val, _) = model_pairs(0, &trajs, &ranking, &cfg, 3).unwrap();
        assert!(pairs.iter().any(|p| p.len == 15) && pairs.iter().any(|p| p.len == 25));
        // Torch's default initialisation: larger weights than N(0, 0.02^2), so that the
        // gradients are well above rounding.
        let config = RewardConfig {
            obs_dim: 3,
            obs_stride: None,
            obs_offset: None,
            act_dim: None,
            hidden: cfg.hidden.clone(),
            models: 1,
            clip: 100.0,
            init: WeightInit::TorchDefault,
        };
        let model = crate::nn::seeded(1, || RewardEnsemble::new(config));
        let net = &model.nets[0];
        let picks: Vec<usize> = (n_val..pairs.len()).step_by(7).collect();
        // The CPU path: one lane, the whole batch.
        let dense = Dense::from_mlp(net);
        let mut lane = Lane::new(dense.len());
        let refs: Vec<&Pair> = picks.iter().map(|&i| &pairs[i]).collect();
        lane.run(&dense, &trajs, &refs, false, Some(1.0 / picks.len() as f32));
        // The GPU path's loss and autograd.
        let on = DevicePairs::new(&trajs, &pairs, false, tch::Device::Cpu);
        let idx = Tensor::from_slice(&picks.iter().map(|&i| i as i64).collect::<Vec<_>>());
        let (logits, labels) = on.logits(net, &idx);
        let ce = logits.cross_entropy_for_logits(&labels);
        assert!((ce.double_value(&[]) - lane.ce / picks.len() as f64).abs() < 1e-5);
        assert_eq!(DevicePairs::correct(&logits, &labels) as usize, lane.correct);
        ce.backward();
        let grad: Vec<f32> = net
            .parameters()
            .flat_map(|(w, b)| {
                let mut g = Vec::<f32>::try_from(w.grad().flatten(0, -1)).unwrap();
                g.extend(Vec::<f32>::try_from(b.grad()).unwrap());
                g
            })
            .collect();
        let norm = |v: &mut dyn Iterator<Item = f32>| v.map(|x| (x as f64).powi(2)).sum::<f64>().sqrt();
        let diff = norm(&mut grad.iter().zip(lane.grads.iter()).map(|(a, b)| a - b));
        let size = norm(&mut lane.grads.iter().copied());
        assert!(size > 1e-3 && diff < 1e-5 * size, "gradients differ: |a - b| = {diff:e}, |a| = {size:e}");
    }

    /// Trained on the GPU path (here on the CPU), the reward predicts the CPU path's returns
    /// (up to a shift) and ranks as well, and the path is deterministic.
    #[test]
    fn torch_path_learns_as_the_cpu_path_does() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let trajs = two_lengths(&mut rng);
        let test_set = toy(30, &mut rng);
        let ranking = Ranking::by_score(trajs.iter().map(|t| t.ret()).collect());
        let cfg = TrexConfig {
            hidden: vec![32, 32],
            models: 2,
            pairs_per_model: 600,
            window: 25,
            min_margin: 1.0,
            lr: 1e-3,
            iterations: 300,
            l2: 0.0,
            ..Default::default()
        };
        let (dense, dr) = train(&trajs, &ranking, &cfg, 3, 2, Device::Cpu).unwrap();
        let torch_run = || {
            let config = RewardConfig {
                obs_dim: 3,
                obs_stride: None,
                obs_offset: None,
                act_dim: None,
                hidden: cfg.hidden.clone(),
                models: 2,
                clip: 100.0,
                init: cfg.init,
            };
            let mut model = crate::nn::seeded(3, || RewardEnsemble::new(config));
            let reports = train_torch(&mut model, &trajs, &ranking, &cfg, 3, tch::Device::Cpu).unwrap();
            (model, reports)
        };
        let (torch, tr) = torch_run();
        // Predicted returns less their mean: the output bias, whose gradient is mostly
        // rounding (windows of equal length), drifts differently on the two paths and
        // shifts every 40-step return alike, which no ranking sees.
        let centred = |m: &RewardEnsemble| {
            let v: Vec<f64> = test_set.iter().map(|t| m.predicted_return(t.next_obs(), &t.actions)).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            v.into_iter().map(|x| x - mean).collect::<Vec<_>>()
        };
        let (pd, pt) = (centred(&dense), centred(&torch));
        let rms = |v: Vec<f64>| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let (gap, spread) = (rms(pd.iter().zip(&pt).map(|(a, b)| a - b).collect()), rms(pd.clone()));
        assert!(gap < 1e-2 * spread, "predicted returns differ by {gap} (spread {spread})");
        let truth: Vec<f64> = test_set.iter().map(|t| t.ret()).collect();
        assert!(spearman(&pd, &truth) > 0.9 && spearman(&pt, &truth) > 0.9);
        for (d, t) in dr.iter().zip(&tr) {
            assert_eq!((d.train_pairs, d.val_pairs), (t.train_pairs, t.val_pairs));
            // The same initial weights and first batch: the same first loss.
            assert!((d.curve[0].loss - t.curve[0].loss).abs() < 1e-5, "{:?} vs {:?}", d.curve[0], t.curve[0]);
            let its = |r: &ModelReport| r.curve.iter().map(|c| c.iteration).collect::<Vec<_>>();
            assert_eq!(its(d), its(t));
            assert!(t.val_accuracy > 0.85 && (d.val_accuracy - t.val_accuracy).abs() < 0.05, "{d:?} vs {t:?}");
        }
        let (again, ar) = torch_run();
        assert_eq!(weights(&again), weights(&torch));
        assert_eq!(ar, tr);
    }

    #[test]
    fn aligned_and_longer_windows_follow_their_options() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let trajs = toy(10, &mut rng);
        let ranking = Ranking::by_score((0..10).map(|i| i as f64).collect());
        let base = TrexConfig { min_margin: 0.5, window: 10, ..Default::default() };
        // Left unset, the options draw nothing: the same pairs as before they existed.
        let spelled = TrexConfig { window_max: Some(10), aligned: false, ..base.clone() };
        let draw = |cfg: &TrexConfig| sample_pairs(&trajs, &ranking, cfg, 200, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        assert_eq!(draw(&base), draw(&spelled));
        let key = serde_json::to_string(&base).unwrap();
        assert!(!key.contains("aligned") && !key.contains("window_max"), "{key}");
        let aligned = draw(&TrexConfig { aligned: true, ..base.clone() });
        for p in &aligned {
            let (better, worse) = if p.label == 0 { (p.a, p.b) } else { (p.b, p.a) };
            assert!(better.1 >= worse.1, "the preferred window starts no earlier: {p:?}");
            assert_eq!(p.len, 10);
        }
        let longer = draw(&TrexConfig { window_max: Some(35), ..base });
        assert!(longer.iter().all(|p| (10..=35).contains(&p.len)));
        assert!(longer.iter().any(|p| p.len > 25) && longer.iter().any(|p| p.len < 15), "lengths spread over the range");
    }

    #[test]
    fn pairs_respect_margin_and_groups() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let trajs = toy(10, &mut rng);
        let scores: Vec<f64> = (0..10).map(|i| i as f64 * 0.1).collect();
        let cfg = TrexConfig { min_margin: 0.3, window: 50, ..Default::default() };
        let groups = trajs.iter().map(|t| t.meta.group).collect();
        let ranking = Ranking { scores: scores.clone(), groups, levels: vec![0; 10], same_group: true, cross_level: false };
        let pairs = sample_pairs(&trajs, &ranking, &cfg, 500, &mut rng).unwrap();
        for p in &pairs {
            let (better, worse) = if p.label == 0 { (p.a.0, p.b.0) } else { (p.b.0, p.a.0) };
            assert!(scores[better] - scores[worse] >= 0.3 - 1e-9);
            assert_eq!(trajs[better].meta.group, trajs[worse].meta.group);
            assert_eq!(p.len, 40, "windows shrink to the trajectory length");
        }
        let too_far = TrexConfig { min_margin: 5.0, ..cfg.clone() };
        assert!(sample_pairs(&trajs, &ranking, &too_far, 1, &mut rng).unwrap_err().to_string().contains("lower min_margin"));
        // Across levels the later iteration wins whatever the scores.
        let levels = Ranking { levels: (0..10).map(|i| usize::from(i < 2)).collect(), cross_level: true, ..ranking };
        let pairs = sample_pairs(&trajs, &levels, &TrexConfig { min_margin: 5.0, ..cfg }, 200, &mut rng).unwrap();
        for p in &pairs {
            let (better, worse) = if p.label == 0 { (p.a.0, p.b.0) } else { (p.b.0, p.a.0) };
            assert!(better < 2 && worse >= 2);
        }
    }
}
