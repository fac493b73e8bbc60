//! Initial weights, drawn from idrex's own seeded generator in plain scalar arithmetic, so
//! that they are the same bits on every processor. libtorch's initialisers are not: its
//! samplers are compiled per instruction set (ATen picks a default, AVX2 or AVX-512 kernel
//! at run time) and its orthogonal initialisation takes a QR through LAPACK.
//!
//! The distributions are libtorch's (what `nn::Linear` and `nn::init` draw from); the
//! values are not, since the generator is another.
use std::cell::RefCell;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::Init;

thread_local! {
    /// The generator networks built on this thread draw from; [`seeded`] resets it.
    static RNG: RefCell<ChaCha8Rng> = RefCell::new(ChaCha8Rng::seed_from_u64(0));
}

/// Runs `f` (which builds networks) with this thread's initialisation generator seeded to
/// `seed`: the networks `f` builds, in the order it builds them, get weights that depend on
/// `seed` alone. Per thread, so stages built side by side never share a stream.
pub fn seeded<T>(seed: u64, f: impl FnOnce() -> T) -> T {
    RNG.with(|r| *r.borrow_mut() = ChaCha8Rng::seed_from_u64(seed));
    f()
}

/// Runs `f`, which builds networks whose weights are then overwritten (loading a saved
/// model), without moving the generator: loading inside [`seeded`] leaves the weights of
/// the networks built after it unchanged.
pub fn building<T>(f: impl FnOnce() -> T) -> T {
    let saved = RNG.with(|r| r.borrow().clone());
    let out = f();
    RNG.with(|r| *r.borrow_mut() = saved);
    out
}

/// A layer's weight (`out x in`, row-major) and bias under `init`; `last` marks the output
/// layer (its orthogonal gain is the init's `out_gain`).
pub fn layer(init: Init, out: usize, inp: usize, last: bool) -> (Vec<f32>, Vec<f32>) {
    RNG.with(|r| {
        let rng = &mut *r.borrow_mut();
        match init {
            // Kaiming-uniform with a = sqrt(5), which is U(-1/sqrt(in), 1/sqrt(in)), and the
            // bias from the same range: libtorch's Linear.
            Init::Default => {
                let bound = 1.0 / (inp.max(1) as f64).sqrt();
                let mut uniform = |n: usize| (0..n).map(|_| ((2.0 * rng.random::<f64>() - 1.0) * bound) as f32).collect::<Vec<f32>>();
                let w = uniform(out * inp);
                (w, uniform(out))
            }
            Init::Normal { std } => {
                let w = (0..out * inp).map(|_| (rng.sample::<f64, _>(StandardNormal) * std) as f32).collect();
                (w, vec![0.0; out])
            }
            Init::Orthogonal { out_gain } => {
                let gain = if last { out_gain } else { 2f64.sqrt() };
                let w = orthogonal(out, inp, rng).into_iter().map(|x| (x * gain) as f32).collect();
                (w, vec![0.0; out])
            }
        }
    })
}

/// A `rows x cols` matrix with orthonormal rows or columns (whichever are fewer), as
/// libtorch's `orthogonal_`: the Q of a Gaussian matrix's QR with R's diagonal positive.
/// Gram-Schmidt run twice per vector, in f64.
fn orthogonal(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let (long, short) = (rows.max(cols), rows.min(cols));
    let mut q: Vec<Vec<f64>> = (0..short).map(|_| (0..long).map(|_| rng.sample(StandardNormal)).collect()).collect();
    for j in 0..short {
        let (done, rest) = q.split_at_mut(j);
        let v = &mut rest[0];
        for _ in 0..2 {
            for u in done.iter() {
                let d: f64 = u.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(u).for_each(|(x, u)| *x -= d * u);
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.iter_mut().for_each(|x| *x /= norm);
    }
    // q[j] is the j-th orthonormal vector: a column when rows >= cols, else a row.
    (0..rows * cols).map(|ij| if rows >= cols { q[ij % cols][ij / cols] } else { q[ij / cols][ij % cols] }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orthogonal_rows_or_columns() {
        for (rows, cols) in [(64, 17), (6, 64), (64, 64), (1, 64)] {
            let w = seeded(3, || RNG.with(|r| orthogonal(rows, cols, &mut r.borrow_mut())));
            let (n, len) = (rows.min(cols), rows.max(cols));
            let vec = |i: usize, t: usize| if rows >= cols { w[t * cols + i] } else { w[i * cols + t] };
            for i in 0..n {
                for j in 0..n {
                    let d: f64 = (0..len).map(|t| vec(i, t) * vec(j, t)).sum();
                    assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12, "{rows}x{cols} ({i}, {j}): {d}");
                }
            }
        }
    }

    #[test]
    fn seeded_draws_repeat_and_loading_does_not_move_them() {
        let draw = || layer(Init::Default, 8, 5, false);
        let a = seeded(7, draw);
        let b = seeded(7, || {
            building(|| layer(Init::Normal { std: 0.02 }, 30, 30, false));
            draw()
        });
        assert_eq!(a, b);
        let (w, bias) = &a;
        assert!(w.iter().chain(bias).all(|x| x.abs() <= 1.0 / 5f32.sqrt()));
        assert_ne!(seeded(8, draw), a);
        let (w, bias) = seeded(1, || layer(Init::Normal { std: 0.02 }, 256, 256, false));
        let std = (w.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / w.len() as f64).sqrt();
        assert!((std - 0.02).abs() < 0.001 && bias.iter().all(|b| *b == 0.0), "{std}");
    }
}
