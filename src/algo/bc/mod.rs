//! Behavioural cloning as in D-REX: an MLP regresses the demonstrator's actions,
//! loss = squared error summed over action dimensions (mean over the batch)
//! + l2 * sum of squared weights; Adam; an 80/20 train/validation split of the steps.
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor};

use crate::data::{RunningMeanStd, Trajectory};
use crate::error::{Error, Result};
use crate::kernels::Buf;
use crate::nn::dense::Scratch;
use crate::nn::trainer::{LANES, Trainer};
use crate::nn::{ActorCritic, Device, PolicyConfig, WeightInit};

mod torch;
use torch::train_torch;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct BcConfig {
    /// Hidden layer sizes (D-REX: 4 x 256, ReLU).
    pub hidden: Vec<usize>,
    /// Adam learning rate.
    pub lr: f64,
    /// Steps per minibatch.
    pub batch_size: usize,
    /// Minibatch updates (at most, with early stopping).
    pub iterations: usize,
    /// Weight of the sum of squared weights.
    pub l2: f64,
    /// Fraction of the steps held out for validation.
    pub val_fraction: f64,
    /// Initialisation of the network.
    pub init: WeightInit,
    /// Stop when the validation loss stops improving, keeping the best weights; absent (the
    /// default, and from the key): train for `iterations`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub early_stopping: Option<EarlyStopping>,
    /// Which steps validate (and so drive early stopping): `steps` (the default, absent from
    /// the key), or `tail`.
    #[serde(skip_serializing_if = "Validation::is_steps")]
    pub validation: Validation,
    /// Standardise the observations with the training steps' mean and variance (clipped to
    /// +-10, stored with the policy as PPO's statistics are); false (the default) is absent
    /// from the key.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub normalize: bool,
}

/// The validation steps of [`BcConfig`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Validation {
    /// A random `val_fraction` of the steps: neighbours of training steps, so it says little
    /// about over-fitting (the original's split).
    #[default]
    Steps,
    /// The last `val_fraction` of each episode: a contiguous stretch training never sees,
    /// the nearest to a held-out episode when there is a single demonstration.
    Tail,
}

impl Validation {
    pub fn is_steps(&self) -> bool {
        *self == Validation::Steps
    }
}

/// Early stopping on the validation loss: measured every `every` iterations, training
/// stops after `patience` measurements without a new best, and the best weights are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EarlyStopping {
    /// Iterations between validation measurements.
    pub every: usize,
    /// Measurements without a new best validation loss before training stops.
    pub patience: usize,
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
            early_stopping: None,
            validation: Validation::Steps,
            normalize: false,
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
    /// With early stopping: the iteration whose weights were kept and how many ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best_iteration: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations_run: Option<usize>,
}

/// The clip of normalised observations (PPO's too).
const OBS_CLIP: f64 = 10.0;

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

/// The demonstration steps, split into training and validation rows, and the generator
/// that then draws the batches: what both training paths start from.
pub(crate) struct Data {
    x: Vec<f32>,
    y: Vec<f32>,
    od: usize,
    ad: usize,
    train: Vec<usize>,
    val: Vec<usize>,
    rng: ChaCha8Rng,
    /// With `normalize`: the training steps' statistics, already applied to `x`.
    obs_norm: Option<RunningMeanStd>,
}

impl Data {
    /// The steps of `trajs`, a `val_fraction` of them held out; or, given `held_out`, all of
    /// `trajs` for training and `held_out`'s steps for validation.
    fn new(trajs: &[Trajectory], held_out: Option<&[Trajectory]>, cfg: &BcConfig, seed: u64) -> Result<Data> {
        if trajs.iter().all(|t| t.is_empty()) {
            return Err(Error::Invalid("behavioural cloning needs at least one demonstration step".into()));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (x, y, od, ad, train, val) = if let Some(held_out) = held_out {
            let all: Vec<Trajectory> = trajs.iter().chain(held_out).cloned().collect();
            let (x, y, od, ad) = pairs(&all);
            let n_train: usize = trajs.iter().map(Trajectory::len).sum();
            let (train, val) = ((0..n_train).collect(), (n_train..x.len() / od).collect());
            (x, y, od, ad, train, val)
        } else {
            let (x, y, od, ad) = pairs(trajs);
            let held = |n: usize| (((n as f64) * cfg.val_fraction).round() as usize).min(n.saturating_sub(1));
            let (train, val) = match cfg.validation {
                Validation::Steps => {
                    let mut idx: Vec<usize> = (0..x.len() / od).collect();
                    idx.shuffle(&mut rng);
                    let n_val = held(idx.len());
                    let train = idx.split_off(n_val);
                    (train, idx)
                }
                Validation::Tail => {
                    let (mut train, mut val, mut first) = (Vec::new(), Vec::new(), 0);
                    for t in trajs {
                        let cut = first + t.len() - held(t.len());
                        train.extend(first..cut);
                        val.extend(cut..first + t.len());
                        first += t.len();
                    }
                    (train, val)
                }
            };
            (x, y, od, ad, train, val)
        };
        let mut data = Data { x, y, od, ad, train, val, rng, obs_norm: None };
        if cfg.normalize {
            let mut stats = RunningMeanStd::new(od);
            let rows: Vec<f32> = data.train.iter().flat_map(|&r| data.x[r * od..(r + 1) * od].iter().copied()).collect();
            stats.update(&rows);
            stats.normalize(&mut data.x, OBS_CLIP);
            data.obs_norm = Some(stats);
        }
        Ok(data)
    }

    /// The validation loss of the network being trained (mean summed squared error).
    fn val_loss(&self, net: &crate::nn::dense::Dense, out: &mut Vec<f32>) -> f64 {
        let mut x = Vec::with_capacity(self.val.len() * self.od);
        for &r in &self.val {
            x.extend_from_slice(&self.x[r * self.od..(r + 1) * self.od]);
        }
        out.clear();
        net.predict(&x, self.val.len(), out);
        let sse: f64 = self
            .val
            .iter()
            .enumerate()
            .map(|(i, &r)| {
                let (p, t) = (&out[i * self.ad..(i + 1) * self.ad], &self.y[r * self.ad..(r + 1) * self.ad]);
                p.iter().zip(t).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>()
            })
            .sum();
        sse / self.val.len().max(1) as f64
    }

    /// The next batch's rows.
    fn picks(&mut self, batch: usize) -> Vec<usize> {
        let nt = self.train.len();
        (0..batch).map(|_| self.train[self.rng.random_range(0..nt)]).collect()
    }

    fn gather(&self, rows: &[usize], targets: bool) -> Tensor {
        let (src, d) = if targets { (&self.y, self.ad) } else { (&self.x, self.od) };
        let mut v = Vec::with_capacity(rows.len() * d);
        for &r in rows {
            v.extend_from_slice(&src[r * d..(r + 1) * d]);
        }
        Tensor::from_slice(&v).view([rows.len() as i64, d as i64])
    }

    fn policy(&self, cfg: &BcConfig, seed: u64) -> ActorCritic {
        let mut config = PolicyConfig::bc(self.od, self.ad);
        config.hidden = cfg.hidden.clone();
        config.init = cfg.init;
        crate::nn::seeded(seed, || ActorCritic::new(config))
    }

    /// The losses of a trained policy (on the CPU).
    fn report(&self, policy: &ActorCritic) -> BcReport {
        let loss = |rows: &[usize]| mse(policy, &self.gather(rows, false), &self.gather(rows, true)).double_value(&[]);
        tch::no_grad(|| BcReport {
            train_steps: self.train.len(),
            val_steps: self.val.len(),
            train_loss: loss(&self.train),
            val_loss: if self.val.is_empty() { f64::NAN } else { loss(&self.val) },
            best_iteration: None,
            iterations_run: None,
        })
    }
}

fn diverged(it: usize, loss: f64, cfg: &BcConfig) -> Error {
    Error::Diverged(format!("BC diverged at iteration {it}: the loss is {loss}; lower bc.lr (now {})", cfg.lr))
}

fn non_finite(cfg: &BcConfig) -> Error {
    Error::Diverged(format!("BC ended with non-finite weights; lower bc.lr (now {})", cfg.lr))
}

/// Trains a deterministic policy on the (s_t, a_t) pairs of `trajs`: on the CPU on up to
/// `workers` threads (the result does not depend on how many: see [`crate::nn::dense`]), or
/// on the GPU (`train_torch`).
pub fn train(trajs: &[Trajectory], cfg: &BcConfig, seed: u64, workers: usize, device: Device) -> Result<(ActorCritic, BcReport)> {
    train_validated(trajs, None, cfg, seed, workers, device)
}

/// [`train`], validated on `held_out`'s steps (for example whole episodes the training set
/// lacks) instead of a fraction of the training steps.
pub fn train_validated(
    trajs: &[Trajectory],
    held_out: Option<&[Trajectory]>,
    cfg: &BcConfig,
    seed: u64,
    workers: usize,
    device: Device,
) -> Result<(ActorCritic, BcReport)> {
    let data = Data::new(trajs, held_out, cfg, seed)?;
    let obs_norm = data.obs_norm.clone();
    let (mut policy, report) = match device {
        Device::Cpu => train_dense(data, cfg, seed, workers),
        Device::Cuda => {
            device.ensure_available()?;
            train_torch(data, cfg, seed, device.tch())
        }
    }?;
    if obs_norm.is_some() {
        policy.obs_norm = obs_norm;
        policy.obs_clip = OBS_CLIP;
    }
    Ok((policy, report))
}

/// Early stopping's bookkeeping, the same on both paths: the best validation loss measured,
/// its iteration and a copy of its weights (`W`), and the measurements since.
struct Stopper<W> {
    es: Option<EarlyStopping>,
    best: Option<(f64, usize, W)>,
    since_best: usize,
}

impl<W> Stopper<W> {
    /// Inactive without `bc.early_stopping` or without validation steps.
    fn new(cfg: &BcConfig, data: &Data) -> Self {
        Stopper { es: cfg.early_stopping.filter(|_| !data.val.is_empty()), best: None, since_best: 0 }
    }

    fn active(&self) -> bool {
        self.es.is_some()
    }

    /// Whether iteration `it` (before its step) measures the validation loss.
    fn due(&self, it: usize) -> bool {
        self.es.is_some_and(|es| it.is_multiple_of(es.every.max(1)))
    }

    /// Records the loss measured at `it`; true when `patience` measurements in a row brought
    /// no new best.
    fn stop(&mut self, loss: f64, it: usize, weights: impl FnOnce() -> W) -> bool {
        let Some(es) = self.es else { return false };
        if self.best.as_ref().is_none_or(|(b, _, _)| loss < *b) {
            self.best = Some((loss, it, weights()));
            self.since_best = 0;
            false
        } else {
            self.since_best += 1;
            self.since_best >= es.patience.max(1)
        }
    }

    /// Given the loss at the end of the `ran` iterations: the weights to restore where an
    /// earlier measurement was at least as good, and the iteration whose weights are kept.
    fn finish(self, end: Option<f64>, ran: usize) -> (Option<W>, Option<usize>) {
        match (end, self.best) {
            (None, _) => (None, None),
            (Some(v), Some((b, it, w))) if b <= v => (Some(w), Some(it)),
            (Some(_), _) => (None, Some(ran)),
        }
    }
}

fn train_dense(mut data: Data, cfg: &BcConfig, seed: u64, workers: usize) -> Result<(ActorCritic, BcReport)> {
    let (od, ad) = (data.od, data.ad);
    let policy = data.policy(cfg, seed);
    let mut trainer = Trainer::new(&policy.actor, cfg.lr, cfg.l2, workers, crate::kernels::bf16::Precision::F32);
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
    let batch = cfg.batch_size.min(data.train.len());
    let scale = 2.0 / batch as f32;
    let mut stopper = Stopper::new(cfg, &data);
    let (mut out, mut ran) = (Vec::new(), cfg.iterations);
    for it in 0..cfg.iterations {
        if stopper.due(it) && stopper.stop(data.val_loss(&trainer.net, &mut out), it, || trainer.net.params.to_vec()) {
            ran = it;
            break;
        }
        let picks = data.picks(batch);
        let (x, y) = (&data.x, &data.y);
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
                return Err(diverged(it, l, cfg));
            }
        }
        trainer.step(lanes.iter().map(|l| &l.grads[..]));
    }
    // The end of training is a measurement too.
    let end = stopper.active().then(|| data.val_loss(&trainer.net, &mut out));
    let (restore, kept) = stopper.finish(end, ran);
    if let Some(w) = restore {
        trainer.net.params.copy_from_slice(&w);
        trainer.net.refresh();
    }
    if !trainer.write_to(&policy.actor) {
        return Err(non_finite(cfg));
    }
    let report = BcReport { best_iteration: kept, iterations_run: kept.map(|_| ran), ..data.report(&policy) };
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
        let trajs = episodes(&mut env, &mut Linear, 20);
        let cfg = BcConfig { hidden: vec![64, 64], lr: 1e-3, iterations: 1500, l2: 0.0, ..Default::default() };
        let (policy, report) = train(&trajs, &cfg, 0, 1, Device::Cpu).unwrap();
        // Actions are in [-1, 1]; predicting 0 would cost about sum of E[a^2], far above this.
        let baseline = action_energy(&trajs);
        assert!(report.val_loss < 0.05 * baseline, "{report:?}, baseline {baseline}");
        // And it acts like the policy on a fresh episode.
        assert!(error_on_a_fresh_episode(&policy) < 0.05 * baseline);
    }

    /// Episodes 0..n of `actor` on `env`, seeded by their index.
    fn episodes(env: &mut Env, actor: &mut impl Actor, n: u64) -> Vec<Trajectory> {
        (0..n).map(|s| rollout::episode(env, actor, s, Default::default())).collect()
    }

    /// Mean over steps of the summed squared actions: what predicting 0 would cost.
    fn action_energy(trajs: &[Trajectory]) -> f64 {
        trajs.iter().flat_map(|t| t.actions.iter()).map(|&a| (a as f64).powi(2)).sum::<f64>()
            / trajs.iter().map(|t| t.len()).sum::<usize>() as f64
    }

    /// Mean summed squared difference between `policy`'s actions and [`Linear`]'s on a
    /// fresh Hopper episode.
    fn error_on_a_fresh_episode(policy: &ActorCritic) -> f64 {
        let mut clone = PolicyActor::new(policy.to_cpu(), false);
        let fresh = rollout::episode(&mut Env::new(EnvId::Hopper).unwrap(), &mut Linear, 99, Default::default());
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut err = 0.0;
        for t in 0..fresh.len() {
            let mut a = [0.0f32; 3];
            clone.act(fresh.obs_row(t), &mut rng, &mut a);
            err += a.iter().zip(fresh.action_row(t)).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>();
        }
        err / fresh.len() as f64
    }

    /// With normalised observations the policy carries the statistics it trained with: it
    /// acts on raw observations like the policy it cloned. The tail split holds out the end
    /// of every episode.
    #[test]
    fn normalised_tail_validated_clone_acts_on_raw_observations() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let trajs = episodes(&mut env, &mut Linear, 20);
        let cfg = BcConfig {
            hidden: vec![64, 64],
            lr: 1e-3,
            iterations: 1500,
            l2: 0.0,
            normalize: true,
            validation: Validation::Tail,
            ..Default::default()
        };
        let data = Data::new(&trajs, None, &cfg, 0).unwrap();
        let held: usize = trajs.iter().map(|t| ((t.len() as f64) * 0.2).round() as usize).sum();
        assert_eq!(data.val.len(), held);
        let mut first = 0;
        for t in &trajs {
            // Each episode's last steps validate, the rest train.
            let cut = first + t.len() - ((t.len() as f64) * 0.2).round() as usize;
            assert!(data.train.contains(&(cut - 1)) && (cut..first + t.len()).all(|r| data.val.contains(&r)));
            first += t.len();
        }
        let (policy, _) = train(&trajs, &cfg, 0, 1, Device::Cpu).unwrap();
        let stats = policy.obs_norm.clone().expect("normalised BC stores its statistics");
        let z = |i: usize| (trajs[0].obs_row(0)[i] as f64 - stats.mean[i]) / stats.var[i].sqrt();
        assert!((0..trajs[0].obs_dim).all(|i| z(i).abs() < 10.0));
        let baseline = action_energy(&trajs);
        let mut policy = policy;
        let err = error_on_a_fresh_episode(&policy);
        assert!(err < 0.05 * baseline, "{err} against {baseline}");
        // Teeth: the same network fed raw observations is far off.
        policy.obs_norm = None;
        let raw = error_on_a_fresh_episode(&policy);
        assert!(raw > 0.2 * baseline, "{raw} against {baseline}");
    }

    /// Uniform random actions: labels no network can predict, so fitting them over-fits.
    struct Noise;
    impl Actor for Noise {
        fn act(&mut self, _obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
            out.iter_mut().for_each(|o| *o = rng.random_range(-1.0..1.0));
        }
    }

    /// On both paths early stopping stops once the validation loss stops improving and keeps
    /// the best weights: exactly those of a run that trains only up to that iteration (the
    /// measurements draw nothing from the batch generator).
    #[test]
    fn early_stopping_keeps_the_weights_of_the_best_iteration() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let trajs = episodes(&mut env, &mut Noise, 6);
        let cfg = BcConfig {
            hidden: vec![64, 64],
            lr: 1e-3,
            iterations: 3000,
            batch_size: 32,
            l2: 0.0,
            init: WeightInit::Normal002,
            validation: Validation::Tail,
            early_stopping: Some(EarlyStopping { every: 20, patience: 5 }),
            ..Default::default()
        };
        type Path = fn(&[Trajectory], &BcConfig) -> (ActorCritic, BcReport);
        let cpu: Path = |t, c| train(t, c, 5, 1, Device::Cpu).unwrap();
        let torch: Path = |t, c| train_torch(Data::new(t, None, c, 5).unwrap(), c, 5, tch::Device::Cpu).unwrap();
        for (name, path) in [("cpu", cpu), ("torch", torch)] {
            let (kept, report) = path(&trajs, &cfg);
            let (best, ran) = (report.best_iteration.unwrap(), report.iterations_run.unwrap());
            assert!(best > 0 && best < ran && ran < cfg.iterations, "{name}: {report:?}");
            let plain = BcConfig { iterations: best, early_stopping: None, ..cfg.clone() };
            let (short, short_report) = path(&trajs, &plain);
            assert_eq!(weights(&kept), weights(&short), "{name}");
            assert_eq!(report.val_loss, short_report.val_loss, "{name}");
            // Teeth: training on to where it stopped ends worse on the held-out tail.
            let (_, longer) = path(&trajs, &BcConfig { iterations: ran, ..plain });
            assert!(longer.val_loss > report.val_loss, "{name}: {longer:?} against {report:?}");
        }
    }

    /// Every parameter of a policy's actor, flat.
    fn weights(p: &ActorCritic) -> Vec<f32> {
        crate::nn::dense::Dense::from_mlp(&p.actor).params.to_vec()
    }

    #[test]
    fn is_deterministic_for_a_seed() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let trajs = episodes(&mut env, &mut Linear, 2);
        let cfg = BcConfig { hidden: vec![32], iterations: 50, batch_size: 37, ..Default::default() };
        let (pa, a) = train(&trajs, &cfg, 7, 1, Device::Cpu).unwrap();
        // On two threads, with an odd batch whose lanes are unequal: the same bytes.
        let (pb, b) = train(&trajs, &cfg, 7, 2, Device::Cpu).unwrap();
        assert_eq!(a, b);
        assert_eq!(weights(&pa), weights(&pb));
    }

    /// The GPU path is libtorch's autograd on the device; run here on the CPU, it must learn
    /// what the CPU path learns from the same batches, and be deterministic itself. (Their
    /// weights are compared through the actions: where a gradient is mostly rounding, Adam
    /// turns the two paths' different rounding into different full-size steps. The two round
    /// differently anyway: idrex's products are chains of fused multiply-adds, libtorch's
    /// MKL's; after 300 steps their actions differ by 0.24 % of the actions' size, against
    /// 20 % for the CPU path a tenth of the way through.)
    #[test]
    fn torch_path_follows_the_cpu_path() {
        let mut env = Env::new(EnvId::Hopper).unwrap();
        let trajs = episodes(&mut env, &mut Linear, 3);
        let cfg = BcConfig { hidden: vec![64, 64], lr: 1e-3, iterations: 300, batch_size: 50, ..Default::default() };
        let (dense, dr) = train(&trajs, &cfg, 3, 1, Device::Cpu).unwrap();
        let (torch, tr) = train_torch(Data::new(&trajs, None, &cfg, 3).unwrap(), &cfg, 3, tch::Device::Cpu).unwrap();
        // The root-mean-square difference of two policies' actions on a fresh episode.
        let fresh = rollout::episode(&mut env, &mut Linear, 50, Default::default());
        let obs = Tensor::from_slice(&fresh.obs[..fresh.len() * fresh.obs_dim]).view([fresh.len() as i64, fresh.obs_dim as i64]);
        let gap = |a: &ActorCritic, b: &ActorCritic| {
            tch::no_grad(|| (a.mean(&obs) - b.mean(&obs)).square().mean(Kind::Float).sqrt().double_value(&[]))
        };
        let spread = tch::no_grad(|| dense.mean(&obs).square().mean(Kind::Float).sqrt().double_value(&[]));
        let close = gap(&dense, &torch);
        assert!(close < 1e-2 * spread, "actions differ by {close} (rms action {spread})");
        assert_eq!((dr.train_steps, dr.val_steps), (tr.train_steps, tr.val_steps));
        assert!((dr.val_loss - tr.val_loss).abs() < 1e-2 * dr.val_loss, "{dr:?} vs {tr:?}");
        // Teeth: the CPU path a tenth of the way through is much further off.
        let (early, _) = train(&trajs, &BcConfig { iterations: 30, ..cfg.clone() }, 3, 1, Device::Cpu).unwrap();
        let far = gap(&dense, &early);
        assert!(far > 10.0 * close, "{far} vs {close}");
        let (again, ar) = train_torch(Data::new(&trajs, None, &cfg, 3).unwrap(), &cfg, 3, tch::Device::Cpu).unwrap();
        assert_eq!(weights(&again), weights(&torch));
        assert_eq!(ar, tr);
    }
}
