//! Behavioural cloning through libtorch's autograd and Adam: the GPU path, which learns what
//! the CPU path in the parent module learns.
use tch::Tensor;
use tch::nn::OptimizerConfig;

use super::*;

/// The same training through libtorch's autograd and Adam on `dev`: the GPU path. It draws
/// the same batches from the same generator as the CPU path, and so learns the same policy
/// up to the order of floating-point sums (`tests::torch_path_follows_the_cpu_path`). The
/// steps stay on the device and a batch is 128 row indices: the host reads the loss back
/// only every 100 iterations.
pub(crate) fn train_torch(mut data: Data, cfg: &BcConfig, seed: u64, dev: tch::Device) -> Result<(ActorCritic, BcReport)> {
    let mut policy = data.policy(cfg, seed);
    policy.vs.set_device(dev);
    let all: Vec<usize> = (0..data.x.len() / data.od).collect();
    let (xs, ys) = (data.gather(&all, false).to_device(dev), data.gather(&all, true).to_device(dev));
    let mut opt = tch::nn::Adam::default().build(&policy.vs, cfg.lr)?;
    let _ftz = crate::kernels::FlushDenormals::new();
    let batch = cfg.batch_size.min(data.train.len());
    let val = Tensor::from_slice(&data.val.iter().map(|&r| r as i64).collect::<Vec<_>>()).to_device(dev);
    let (val_x, val_y) = (xs.index_select(0, &val), ys.index_select(0, &val));
    let val_loss = |p: &ActorCritic| tch::no_grad(|| mse(p, &val_x, &val_y).double_value(&[]));
    let copy = |p: &ActorCritic| tch::no_grad(|| p.vs.trainable_variables().iter().map(Tensor::copy).collect::<Vec<_>>());
    let mut stopper = Stopper::new(cfg, &data);
    let mut ran = cfg.iterations;
    for it in 0..cfg.iterations {
        if stopper.due(it) && stopper.stop(val_loss(&policy), it, || copy(&policy)) {
            ran = it;
            break;
        }
        let picks: Vec<i64> = data.picks(batch).into_iter().map(|r| r as i64).collect();
        let b = Tensor::from_slice(&picks).to_device(dev);
        let loss = mse(&policy, &xs.index_select(0, &b), &ys.index_select(0, &b)) + cfg.l2 * policy.actor.weight_l2();
        if it % 100 == 0 || it + 1 == cfg.iterations {
            let l = loss.double_value(&[]);
            if !l.is_finite() {
                return Err(diverged(it, l, cfg));
            }
        }
        opt.backward_step(&loss);
    }
    let end = stopper.active().then(|| val_loss(&policy));
    let (restore, kept) = stopper.finish(end, ran);
    if let Some(w) = restore {
        tch::no_grad(|| {
            for (mut var, saved) in policy.vs.trainable_variables().into_iter().zip(&w) {
                var.copy_(saved);
            }
        });
    }
    policy.vs.set_device(tch::Device::Cpu);
    if !crate::nn::all_finite(&policy.vs) {
        return Err(non_finite(cfg));
    }
    let report = BcReport { best_iteration: kept, iterations_run: kept.map(|_| ran), ..data.report(&policy) };
    Ok((policy, report))
}
