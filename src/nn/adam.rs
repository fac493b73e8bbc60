//! Adam as libtorch's (betas 0.9 and 0.999, no weight decay): the one optimiser of BC, T-REX
//! ([`super::trainer`]) and PPO ([`crate::algo::ppo`]). The bias-corrected step is
//! `lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)`.
//!
//! Two passes take the gradient where each caller has it, and update with the same formula:
//! PPO's whole gradient times its clipping scale ([`Adam::step_scaled`]), and the trainer's
//! two lanes' gradients plus the L2 term, over a share of the parameters per thread
//! ([`Adam::lanes`]). Each is one pass over memory, not several.
use crate::kernels::{Buf, vectorised};

const B1: f32 = 0.9;
const B2: f32 = 0.999;

/// The moments and step count of one training run.
pub struct Adam {
    pub(super) m: Buf,
    pub(super) v: Buf,
    t: i32,
}

/// One step's constants: the learning rate over the first moment's bias correction, the
/// square root of the second's, and eps.
#[derive(Debug, Clone, Copy)]
pub struct AdamStep {
    step: f32,
    bc2s: f32,
    eps: f32,
}

vectorised! {
    /// One update from `grads` times `scale`.
    fn update_scaled(params: &mut [f32], grads: &[f32], scale: f32, m: &mut [f32], v: &mut [f32], k: AdamStep) {
        for (((p, &g), m), v) in params.iter_mut().zip(grads).zip(m.iter_mut()).zip(v.iter_mut()) {
            let g = g * scale;
            *m = B1 * *m + (1.0 - B1) * g;
            *v = B2 * *v + (1.0 - B2) * g * g;
            *p -= k.step * *m / (v.sqrt() / k.bc2s + k.eps);
        }
    }
}

vectorised! {
    /// One update from the gradient `g0 + g1` (two lanes' sums), plus `l2 * params` where
    /// `weights`.
    #[allow(clippy::too_many_arguments)]
    fn update_lanes(params: &mut [f32], g0: &[f32], g1: &[f32], weights: bool, l2: f32, m: &mut [f32], v: &mut [f32], k: AdamStep) {
        for ((((p, &g0), &g1), m), v) in params.iter_mut().zip(g0).zip(g1).zip(m.iter_mut()).zip(v.iter_mut()) {
            let sum = g0 + g1;
            let g = if weights { sum + l2 * *p } else { sum };
            *m = B1 * *m + (1.0 - B1) * g;
            *v = B2 * *v + (1.0 - B2) * g * g;
            *p -= k.step * *m / (v.sqrt() / k.bc2s + k.eps);
        }
    }
}

impl Adam {
    pub fn new(len: usize) -> Self {
        Adam { m: Buf::zeros(len), v: Buf::zeros(len), t: 0 }
    }

    /// Counts a step at learning rate `lr`; its constants.
    pub fn advance(&mut self, lr: f32, eps: f32) -> AdamStep {
        self.t += 1;
        AdamStep { step: lr / (1.0 - B1.powi(self.t)), bc2s: (1.0 - B2.powi(self.t)).sqrt(), eps }
    }

    /// One step on every parameter from `grads` times `scale` (PPO's clipped gradient);
    /// `parts` hold the parameters in the gradient's order (PPO's actor, critic, log-std).
    pub fn step_scaled<const N: usize>(&mut self, parts: [&mut [f32]; N], grads: &[f32], scale: f32, lr: f32, eps: f32) {
        assert_eq!(parts.iter().map(|p| p.len()).sum::<usize>(), grads.len(), "a gradient for every parameter");
        let k = self.advance(lr, eps);
        let (mut m, mut v, mut g) = (&mut self.m[..], &mut self.v[..], grads);
        for p in parts {
            let n = p.len();
            let (mh, mt) = std::mem::take(&mut m).split_at_mut(n);
            let (vh, vt) = std::mem::take(&mut v).split_at_mut(n);
            update_scaled(p, &g[..n], scale, mh, vh, k);
            (m, v, g) = (mt, vt, &g[n..]);
        }
    }

    /// The moments, to split with the parameters into the lanes' shares of a step.
    pub fn moments(&mut self) -> (&mut [f32], &mut [f32]) {
        (&mut self.m, &mut self.v)
    }

    /// The update of one share of the parameters, `params` with its moments `m` and `v`,
    /// from two lanes' gradients `g0 + g1`, plus `l2 * params` where `weights`.
    #[allow(clippy::too_many_arguments)]
    pub fn lanes(k: AdamStep, params: &mut [f32], g0: &[f32], g1: &[f32], weights: bool, l2: f32, m: &mut [f32], v: &mut [f32]) {
        update_lanes(params, g0, g1, weights, l2, m, v, k);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(x: &[f32]) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// The AVX-512 builds of both passes give the bits of the same operations one element
    /// at a time, and the two passes agree where their gradients are the same.
    #[test]
    fn vectorised_adam_gives_the_scalar_bits() {
        if crate::kernels::gemm::Kernel::active() != crate::kernels::gemm::Kernel::Avx512 {
            crate::kernels::narrowed(
                "nn::adam::tests::vectorised_adam_gives_the_scalar_bits",
                "AVX-512 (the scalar build is compared with itself)",
            );
        }
        let n = 16 * 37 + 5;
        let vals = |k: f32| (0..n).map(|i| ((i as f32 * k).sin() * 3.0).powi(3)).collect::<Vec<f32>>();
        let (g, h, p0) = (vals(0.37), vals(0.91), vals(0.13));
        let k = AdamStep { step: 1e-3 / 0.1, bc2s: 0.0447, eps: 1e-8 };
        let (mut p, mut m, mut v) = (p0.clone(), h.clone(), g.iter().map(|x| x * x).collect::<Vec<f32>>());
        let (mut wp, mut wm, mut wv) = (p.clone(), m.clone(), v.clone());
        let (mut lp, mut lm, mut lv) = (p.clone(), m.clone(), v.clone());
        update_scaled(&mut p, &g, 0.75, &mut m, &mut v, k);
        for i in 0..n {
            let gi = g[i] * 0.75;
            wm[i] = 0.9 * wm[i] + (1.0 - 0.9) * gi;
            wv[i] = 0.999 * wv[i] + (1.0 - 0.999) * gi * gi;
            wp[i] -= 1e-3 / 0.1 * wm[i] / (wv[i].sqrt() / 0.0447 + 1e-8);
        }
        assert_eq!((bits(&p), bits(&m), bits(&v)), (bits(&wp), bits(&wm), bits(&wv)));
        // g0 + g1 = 0.75 g exactly (0.5 g + 0.25 g): the lanes' pass gives the same bits.
        let (g0, g1): (Vec<f32>, Vec<f32>) = g.iter().map(|x| (0.5 * x, 0.25 * x)).unzip();
        update_lanes(&mut lp, &g0, &g1, false, 0.0, &mut lm, &mut lv, k);
        assert_eq!((bits(&lp), bits(&lm), bits(&lv)), (bits(&wp), bits(&wm), bits(&wv)));
    }

    #[test]
    fn the_step_constants_are_libtorchs_bias_corrections() {
        let mut adam = Adam::new(1);
        let k = adam.advance(1e-3, 1e-8);
        assert_eq!((k.step, k.bc2s), (1e-3 / (1.0 - 0.9f32), (1.0 - 0.999f32).sqrt()));
        let k = adam.advance(1e-3, 1e-5);
        assert_eq!((k.step, k.bc2s, k.eps), (1e-3 / (1.0 - 0.9f32.powi(2)), (1.0 - 0.999f32.powi(2)).sqrt(), 1e-5));
    }
}
