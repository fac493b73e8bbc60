//! This processor's speed against the reference machine's, measured in about a second before
//! a run whose store has no stage times of its own: the estimate on a run's first line then
//! scales the reference machine's stage times by it. Two probes, because processors differ
//! unequally: matrix products (what BC's and T-REX's training spend their time on; AVX-512
//! against AVX2 shows here) and MuJoCo stepping (PPO, rollouts and evaluations).
use std::time::Instant;

use super::stage::StageKind;
use crate::env::{Env, EnvId};
use crate::kernels::gemm::{Factor, Product, gemm};

/// The probes' seconds on the reference machine, each the fastest of its repeats: a 2-core
/// Intel Xeon (family 6, model 167), whose main-job stage times are within a third of
/// `schedule`'s reference table (T-REX 192 s against 160, PPO 45 s against 65, BC 58 s
/// against 80).
const REFERENCE_PRODUCTS_S: f64 = 0.100;
const REFERENCE_STEPPING_S: f64 = 0.104;

/// Seconds here per second on the reference machine (above 1: slower), per kind of work.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Speed {
    pub products: f64,
    pub stepping: f64,
}

impl Default for Speed {
    fn default() -> Self {
        Speed { products: 1.0, stepping: 1.0 }
    }
}

impl Speed {
    /// Runs both probes (each the fastest of three repeats, one thread).
    pub fn measure() -> Speed {
        let fastest = |probe: &dyn Fn()| {
            (0..3)
                .map(|_| {
                    let t = Instant::now();
                    probe();
                    t.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min)
        };
        Speed { products: fastest(&products) / REFERENCE_PRODUCTS_S, stepping: fastest(&stepping) / REFERENCE_STEPPING_S }
    }

    /// The factor for a stage kind's reference time.
    pub fn factor(&self, kind: StageKind) -> f64 {
        match kind {
            StageKind::Bc | StageKind::Trex | StageKind::MultiBcRollouts => self.products,
            _ => self.stepping,
        }
    }
}

/// 256 x 256 x 256 products, as T-REX's and BC's layers compute them.
fn products() {
    const N: usize = 256;
    let a: Vec<f32> = (0..N * N).map(|i| ((i * 7919) % 1000) as f32 * 1e-3 - 0.5).collect();
    let b: Vec<f32> = (0..N * N).map(|i| ((i * 104_729) % 1000) as f32 * 1e-3 - 0.5).collect();
    let mut c = vec![0.0f32; N * N];
    for _ in 0..400 {
        let p = Product { m: N, n: N, k: N, a: Factor::new(&a, N), b: Factor::t(&b, N), accumulate: false };
        gemm(p, &mut c, N);
        std::hint::black_box(&c);
    }
}

/// HalfCheetah stepped 4,000 times under a fixed periodic action.
fn stepping() {
    let Ok(mut env) = Env::new(EnvId::HalfCheetah) else { return };
    let (mut obs, dim) = (vec![0.0; env.obs_dim()], env.act_dim());
    env.reset(Some(0), &mut obs);
    for t in 0..4000 {
        let action: Vec<f64> = (0..dim).map(|j| ((t + 13 * j) as f64 * 0.1).sin()).collect();
        if env.step(&action, &mut obs).is_ok_and(|s| s.terminated || s.truncated) {
            env.reset(Some(t as u64), &mut obs);
        }
    }
    std::hint::black_box(&obs);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The probes run and give factors a processor could have (not a timing claim: idrex's
    /// processors are within 4x of the reference).
    #[test]
    fn the_probes_measure_this_processor() {
        let s = Speed::measure();
        for f in [s.products, s.stepping] {
            assert!(f.is_finite() && f > 0.05 && f < 50.0, "{s:?}");
        }
        assert_eq!(s.factor(StageKind::Trex), s.products);
        assert_eq!(s.factor(StageKind::Ppo), s.stepping);
        assert_eq!(Speed::default().factor(StageKind::Eval), 1.0);
    }
}
