//! T-REX through libtorch's autograd and Adam: the GPU path, which learns what the CPU path
//! in the parent module learns.
use tch::nn::{Module, OptimizerConfig};
use tch::{Kind, Tensor};

use super::*;

/// Every pair's window rows as indices into a table of all trajectories' input rows, both
/// on the device: a batch is then its pair indices alone.
pub(super) struct DevicePairs {
    /// Every step's input row: `[rows, input]`.
    table: Tensor,
    /// Per pair, the table rows of its first window then its second, each padded to the
    /// longest window with the window's first row: `[pairs, 2 * len]`.
    rows: Tensor,
    /// 1 for a window's own steps, 0 for padding; None when no window is short.
    mask: Option<Tensor>,
    labels: Tensor,
    len: usize,
}

impl DevicePairs {
    pub(super) fn new(trajs: &[Trajectory], pairs: &[Pair], action_input: bool, dev: tch::Device) -> DevicePairs {
        let width = trajs[0].obs_dim + if action_input { trajs[0].act_dim } else { 0 };
        let mut table = Vec::new();
        let mut offsets = Vec::with_capacity(trajs.len());
        for t in trajs {
            offsets.push((table.len() / width) as i64);
            push_inputs(t, 0..t.len(), action_input, &mut table);
        }
        let len = pairs.iter().map(|p| p.len).max().unwrap_or(1).max(1);
        let (mut rows, mut mask) = (Vec::with_capacity(pairs.len() * 2 * len), Vec::with_capacity(pairs.len() * 2 * len));
        for p in pairs {
            for (t, start) in [p.a, p.b] {
                let first = offsets[t] + start as i64;
                rows.extend((0..len as i64).map(|s| if (s as usize) < p.len { first + s } else { first }));
                mask.extend((0..len).map(|s| if s < p.len { 1.0f32 } else { 0.0 }));
            }
        }
        let n = pairs.len() as i64;
        let short = pairs.iter().any(|p| p.len < len);
        DevicePairs {
            table: Tensor::from_slice(&table).view([(table.len() / width) as i64, width as i64]).to_device(dev),
            rows: Tensor::from_slice(&rows).view([n, 2 * len as i64]).to_device(dev),
            mask: short.then(|| Tensor::from_slice(&mask).view([n, 2, len as i64]).to_device(dev)),
            labels: Tensor::from_slice(&pairs.iter().map(|p| p.label).collect::<Vec<_>>()).to_device(dev),
            len,
        }
    }

    /// The two windows' predicted returns of the pairs `picks` (indices on the device),
    /// `[picks, 2]`, and their labels.
    pub(super) fn logits(&self, net: &RewardNet, picks: &Tensor) -> (Tensor, Tensor) {
        let n = picks.size()[0];
        let x = self.table.index_select(0, &self.rows.index_select(0, picks).view([-1]));
        let r = net.forward(&x).view([n, 2, self.len as i64]);
        let r = match &self.mask {
            Some(mask) => r * mask.index_select(0, picks),
            None => r,
        };
        (r.sum_dim_intlist(-1, false, Kind::Float), self.labels.index_select(0, picks))
    }

    /// How many of the pairs `picks` the logits rank right (as argmax: the first of equal
    /// logits wins, as on the CPU).
    pub(super) fn correct(logits: &Tensor, labels: &Tensor) -> i64 {
        logits.argmax(-1, false).eq_tensor(labels).sum(Kind::Int64).int64_value(&[])
    }

    /// The fraction of the pairs `from..to` ranked right.
    fn accuracy(&self, net: &RewardNet, from: usize, to: usize) -> f64 {
        if from == to {
            return f64::NAN;
        }
        let dev = self.rows.device();
        let correct: i64 = tch::no_grad(|| {
            (from..to)
                .step_by(1024)
                .map(|c| {
                    let picks = Tensor::arange_start(c as i64, to.min(c + 1024) as i64, (Kind::Int64, dev));
                    let (logits, labels) = self.logits(net, &picks);
                    Self::correct(&logits, &labels)
                })
                .sum()
        });
        correct as f64 / (to - from) as f64
    }
}

/// The same training through libtorch's autograd and Adam on `dev`, the models one after
/// another: the GPU path. Each model draws the same pairs and batches from the same
/// generator as on the CPU, and so learns the same reward up to the order of floating-point
/// sums (`tests::torch_path_learns_as_the_cpu_path_does`). Pairs and rows live on the device; the
/// host reads the loss back only at the learning curve's points, every 50 iterations.
pub(crate) fn train_torch(
    model: &mut RewardEnsemble,
    trajs: &[Trajectory],
    ranking: &Ranking,
    cfg: &TrexConfig,
    seed: u64,
    dev: tch::Device,
) -> Result<Vec<ModelReport>> {
    let _ftz = crate::kernels::FlushDenormals::new();
    let mut reports = Vec::with_capacity(model.nets.len());
    for m in 0..model.nets.len() {
        let (pairs, n_val, mut rng) = model_pairs(m, trajs, ranking, cfg, seed)?;
        let n_train = pairs.len() - n_val;
        let on = DevicePairs::new(trajs, &pairs, cfg.action_input, dev);
        let (store, net) = (&mut model.stores[m], &model.nets[m]);
        store.set_device(dev);
        let mut opt = tch::nn::Adam::default().build(store, cfg.lr)?;
        let mut curve = Vec::new();
        let mut final_loss = f64::NAN;
        for it in 0..cfg.iterations {
            let picks: Vec<i64> = (0..cfg.batch_size).map(|_| (n_val + rng.random_range(0..n_train)) as i64).collect();
            let (logits, labels) = on.logits(net, &Tensor::from_slice(&picks).to_device(dev));
            let ce = logits.cross_entropy_for_logits(&labels);
            let loss = &ce + cfg.l2 * net.weight_l2();
            if it % 50 == 0 || it + 1 == cfg.iterations {
                final_loss = ce.double_value(&[]);
                // A pair's cross-entropy starts near ln 2; far above it the model is not learning.
                if !final_loss.is_finite() || final_loss > 1e3 {
                    return Err(diverged(m, it, final_loss, cfg));
                }
                let acc = tch::no_grad(|| DevicePairs::correct(&logits, &labels)) as f64 / picks.len() as f64;
                curve.push(TrexCurvePoint { iteration: it, loss: final_loss, batch_accuracy: acc });
            }
            opt.backward_step(&loss);
        }
        reports.push(ModelReport {
            train_pairs: n_train,
            val_pairs: n_val,
            final_loss,
            train_accuracy: on.accuracy(net, n_val, pairs.len()),
            val_accuracy: on.accuracy(net, 0, n_val),
            curve,
        });
        model.stores[m].set_device(tch::Device::Cpu);
        if !crate::nn::all_finite(&model.stores[m]) {
            return Err(non_finite(m, cfg));
        }
    }
    Ok(reports)
}
