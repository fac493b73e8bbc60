//! Neural networks. Their definitions and storage are libtorch modules (tch): MLP blocks
//! ([`mlp`]), the Gaussian actor-critic ([`policy`]), the T-REX reward nets and ensembles
//! ([`reward`]), saved as safetensors with a JSON sidecar ([`sidecar`]). What computes on the
//! CPU is idrex's own code, the same bits on every processor: initial weights ([`init`]),
//! the matrix products ([`crate::kernels::gemm`], [`crate::kernels::bf16`]), and one MLP,
//! [`Dense`] ([`dense`]; a libtorch [`Mlp`]'s parameters, [`Mlp::to_cpu`]), for every pass:
//! BC's, T-REX's and PPO's training (with [`trainer`]'s lanes for BC and T-REX, Adam in
//! [`adam`]), batch inference of the learned reward and per-step inference in rollouts.
//! [`device`] picks libtorch's GPU where asked.

use crate::kernels::vectorised;

pub mod adam;
pub mod dense;
pub mod device;
pub mod init;
pub mod mlp;
pub mod policy;
pub mod reward;
pub mod sidecar;
pub mod trainer;

pub use dense::{Dense, Layer};
pub use device::{Device, DeviceChoice};
pub use init::{building, seeded};
pub use mlp::{Activation, Init, Mlp, WeightInit};
pub use policy::{ActorCritic, PolicyConfig};
pub use reward::{RewardConfig, RewardEnsemble, RewardNet};

/// Whether every variable of `vs` is finite: nothing non-finite is ever published.
pub fn all_finite(vs: &tch::nn::VarStore) -> bool {
    tch::no_grad(|| vs.trainable_variables().iter().all(|t| bool::try_from(&t.isfinite().all()).unwrap_or(false)))
}

/// Makes libtorch's operators single-threaded (a process-wide setting): on the CPU they
/// compute nothing that is stored (idrex's own kernels do), and idle libtorch threads would
/// spin against the stages' own; stages parallelise over stages, ensemble members and
/// environments instead.
pub fn single_threaded() {
    tch::set_num_threads(1);
}

vectorised! {
    /// The hidden layers' activation, in place (PPO's update and the policy's inference).
    fn activate(y: &mut [f32], activation: Activation) {
        match activation {
            Activation::Tanh => y.iter_mut().for_each(|v| *v = fast_tanh(*v)),
            Activation::Relu => y.iter_mut().for_each(|v| *v = v.max(0.0)),
        }
    }
}

/// tanh in f32 as a rational minimax approximation (Eigen's `ptanh_float` coefficients):
/// within a few ulp of `f32::tanh`, branch-free and vectorisable. libm's tanhf (through
/// expm1f) took a third of a PPO run's time.
#[inline]
#[allow(clippy::excessive_precision)] // Eigen's coefficients as published; each rounds to the f32 it always did.
pub fn fast_tanh(x: f32) -> f32 {
    let x = x.clamp(-9.0, 9.0);
    let x2 = x * x;
    let p = x2 * -2.760_768_5e-16 + 2.000_187_9e-13;
    let p = x2 * p + -8.604_671_5e-11;
    let p = x2 * p + 5.122_297e-8;
    let p = x2 * p + 1.485_722_4e-5;
    let p = x2 * p + 6.372_619_3e-4;
    let p = x2 * p + 4.893_524_6e-3;
    let q = x2 * 1.198_258_4e-6 + 1.185_347_1e-4;
    let q = x2 * q + 2.268_434_6e-3;
    let q = x2 * q + 4.893_525e-3;
    let t = x * p / q;
    if x.abs() < 4e-4 { x } else { t.clamp(-1.0, 1.0) }
}

#[cfg(test)]
mod tanh_tests {
    #[test]
    fn fast_tanh_is_accurate() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * 1e-4;
            worst = worst.max((super::fast_tanh(x) as f64 - (x as f64).tanh()).abs());
        }
        assert!(worst < 1e-6, "max abs error {worst}");
        assert_eq!(super::fast_tanh(100.0), 1.0);
        assert_eq!(super::fast_tanh(-100.0), -1.0);
    }
}
