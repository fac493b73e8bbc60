//! Training runs of [`Dense`] networks, shared by BC and T-REX: Adam, the lane threads and
//! the fused update step.
//!
//! Bytes do not depend on the number of threads: every batch is split into [`LANES`] fixed
//! parts whose gradients are summed in lane order, whatever the number of threads that
//! compute them.
//!
//! The lane count is a contract, not a tuning knob: it fixes the order of the gradient sums,
//! so changing it changes every BC and T-REX artifact without changing their keys. The keys
//! do not record it. `tests::the_lane_count_is_the_stages_contract` holds it at 2; whoever
//! changes it must bump the BC, T-REX and every learner stage's version in the same commit
//! (see `pipeline::stage::kind`).
use std::ops::Range;

use super::Mlp;
use super::adam::Adam;
use super::dense::{Dense, Layer};
use crate::kernels::bf16::Precision;
use crate::kernels::{FlushDenormals, transpose_rows};

/// Every batch is split into this many lanes, whose gradients are summed in lane order; a
/// lane is the unit of parallelism, so bytes do not depend on how many threads there are.
pub const LANES: usize = 2;

/// Adam's eps for BC and T-REX (libtorch's default).
const EPS: f32 = 1e-8;

/// What BC and T-REX share of a training run: the network, Adam, the lane threads and the
/// summed gradient, with denormals flushed on the calling thread while it lives.
pub struct Trainer {
    pub net: Dense,
    adam: Adam,
    lr: f32,
    pool: LanePool,
    l2: f32,
    _ftz: FlushDenormals,
}

impl Trainer {
    /// Trains `mlp`'s parameters with Adam at `lr` and `l2` x the sum of squared weights
    /// added to the loss, on up to `threads` threads, its products at `precision`.
    pub fn new(mlp: &Mlp, lr: f64, l2: f64, threads: usize, precision: Precision) -> Self {
        let _ftz = FlushDenormals::new();
        let net = Dense::from_mlp(mlp).with_precision(precision);
        let adam = Adam::new(net.len());
        Trainer { net, adam, lr: lr as f32, pool: LanePool::new(threads), l2: l2 as f32, _ftz }
    }

    /// Runs `f(lane, share, net)` for each of the [`LANES`] lanes, with the lane's share of
    /// `batch`: a fixed partition into consecutive parts (the last may be shorter or empty).
    pub fn run<L: Send, T: Sync>(&self, lanes: &mut [L], batch: &[T], f: impl Fn(&mut L, &[T], &Dense) + Sync) {
        assert_eq!(lanes.len(), LANES, "one state per lane");
        let per = batch.len().div_ceil(LANES);
        let net = &self.net;
        self.pool.run(lanes, |lane, k| f(lane, batch.get(k * per..((k + 1) * per).min(batch.len())).unwrap_or(&[]), net));
    }

    /// One Adam step on the lanes' gradients summed in lane order, plus the L2 term's, then
    /// the transposed weights rewritten: both on the lane threads, split by parameters (then
    /// by transposed rows), elementwise, so the split changes no bit. On the calling thread
    /// alone they left BC's second thread idle much of each iteration.
    pub fn step<'a>(&mut self, lane_grads: impl IntoIterator<Item = &'a [f32]>) {
        const _: () = assert!(LANES == 2, "Adam::lanes sums two lanes");
        let lanes: Vec<&[f32]> = lane_grads.into_iter().collect();
        let [g0, g1] = lanes[..] else { panic!("one gradient per lane") };
        let k = self.adam.advance(self.lr, EPS);
        let l2 = 2.0 * self.l2;
        let Dense { layers, params, wt, .. } = &mut self.net;
        let (m, v) = self.adam.moments();
        let mut shares = AdamShare::split(params, m, v);
        let layers = &layers[..];
        self.pool.run(&mut shares, |share, _| {
            // Each layer's weights, then its biases, in the parameters' order.
            for (r, weights) in layers.iter().flat_map(|l| [(l.w..l.b(), true), (l.b()..l.b() + l.out, false)]) {
                let (a, b) = (r.start.max(share.start), r.end.min(share.start + share.params.len()));
                if a < b {
                    let at = a - share.start..b - share.start;
                    let (p, m, v) = (&mut share.params[at.clone()], &mut share.m[at.clone()], &mut share.v[at]);
                    Adam::lanes(k, p, &g0[a..b], &g1[a..b], weights, l2, m, v);
                }
            }
        });
        let params = &params[..];
        let mut shares = TransposeShare::split(layers, wt);
        self.pool.run(&mut shares, |share, _| {
            for t in share.iter_mut() {
                transpose_rows(&params[t.layer.w..t.layer.b()], t.layer.inp, t.layer.out, t.rows.clone(), t.dst);
            }
        });
    }

    /// Writes the parameters back into `mlp`; false (writing nothing) if any is not finite.
    pub fn write_to(&self, mlp: &Mlp) -> bool {
        let finite = self.net.params.iter().all(|p| p.is_finite());
        if finite {
            self.net.write_to(mlp);
        }
        finite
    }
}

/// A lane's share of an Adam step: the parameters from `start` on, with their moments.
struct AdamShare<'a> {
    start: usize,
    params: &'a mut [f32],
    m: &'a mut [f32],
    v: &'a mut [f32],
}

impl<'a> AdamShare<'a> {
    /// [`LANES`] consecutive shares, all but the last a multiple of 16 floats long.
    fn split(mut params: &'a mut [f32], mut m: &'a mut [f32], mut v: &'a mut [f32]) -> Vec<Self> {
        let per = params.len().div_ceil(LANES).next_multiple_of(16);
        (0..LANES)
            .map(|k| {
                let take = per.min(params.len());
                let (p, p_rest) = std::mem::take(&mut params).split_at_mut(take);
                let (mk, m_rest) = std::mem::take(&mut m).split_at_mut(take);
                let (vk, v_rest) = std::mem::take(&mut v).split_at_mut(take);
                (params, m, v) = (p_rest, m_rest, v_rest);
                AdamShare { start: k * per, params: p, m: mk, v: vk }
            })
            .collect()
    }
}

/// Rows `rows` of `layer`'s transposed weight, to be written to `dst`.
struct TransposeShare<'a> {
    layer: Layer,
    rows: Range<usize>,
    dst: &'a mut [f32],
}

impl<'a> TransposeShare<'a> {
    /// Per lane, its consecutive part of every layer's rows of `wt` (laid out as the
    /// parameters).
    fn split(layers: &[Layer], mut wt: &'a mut [f32]) -> Vec<Vec<Self>> {
        let mut shares: Vec<Vec<Self>> = (0..LANES).map(|_| Vec::new()).collect();
        let mut at = 0;
        for &layer in layers {
            // Skip the previous layer's bias slots.
            wt = &mut std::mem::take(&mut wt)[layer.w - at..];
            at = layer.w;
            let per = layer.inp.div_ceil(LANES);
            for (k, share) in shares.iter_mut().enumerate() {
                let rows = (k * per).min(layer.inp)..((k + 1) * per).min(layer.inp);
                let (dst, rest) = std::mem::take(&mut wt).split_at_mut(rows.len() * layer.out);
                wt = rest;
                at += rows.len() * layer.out;
                share.push(TransposeShare { layer, rows, dst });
            }
        }
        shares
    }
}

/// The threads that compute lanes, kept for a whole training run rather than started per
/// step (with MKL, T-REX on two cores ran 113 model-iterations/s with a thread per step and
/// 117-128 with the pool).
pub struct LanePool(Option<rayon::ThreadPool>);

impl LanePool {
    /// Up to `threads` threads (none of them the caller's, which waits while they run).
    pub fn new(threads: usize) -> Self {
        if threads.min(LANES) <= 1 {
            return LanePool(None);
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.min(LANES))
            .thread_name(|i| format!("idrex-lane-{i}"))
            .start_handler(|_| {
                // For the thread's whole life, which is the pool's.
                std::mem::forget(FlushDenormals::new());
            })
            .build();
        // Without threads to spare, the lanes run on the caller's thread: same result.
        LanePool(pool.ok())
    }

    /// Runs `f(lane, k)` for every lane `k`.
    pub fn run<T: Send>(&self, lanes: &mut [T], f: impl Fn(&mut T, usize) + Sync) {
        use rayon::prelude::*;
        match &self.0 {
            None => lanes.iter_mut().enumerate().for_each(|(k, lane)| f(lane, k)),
            Some(pool) => pool.install(|| lanes.par_iter_mut().enumerate().for_each(|(k, lane)| f(lane, k))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::dense::{Scratch, add_into};
    use crate::nn::{Activation, Init};
    use tch::{Device, Kind, Tensor, nn, nn::Module};

    fn bits(x: &[f32]) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// The contract of the module doc: two lanes, whatever the machine.
    #[test]
    fn the_lane_count_is_the_stages_contract() {
        assert_eq!(LANES, 2, "the lane count changes every BC and T-REX artifact: bump their stage versions with it");
    }

    /// The trainer's step (fused, split over the lane threads) gives the bits of the passes
    /// it replaced, one after another on one thread: sum the lanes into a buffer, add the
    /// L2 term, Adam, transpose. Widths off the 8 x 8 blocks and an odd split included.
    #[test]
    fn step_gives_the_bits_of_the_separate_passes() {
        tch::manual_seed(11);
        let vs = nn::VarStore::new(Device::Cpu);
        let mlp = Mlp::new(&vs.root(), &[17, 40, 29, 6], Activation::Relu, Init::Default);
        for threads in [1, 2] {
            let mut trainer = Trainer::new(&mlp, 1e-2, 0.01, threads, Precision::F32);
            let mut want = Dense::from_mlp(&mlp);
            let mut adam = Adam::new(want.len());
            for t in 0..3 {
                let g0 = crate::kernels::gemm::test_values(want.len(), 0.37 + t as f32);
                let g1 = crate::kernels::gemm::test_values(want.len(), 0.53 + t as f32);
                let mut grads = g0.clone();
                add_into(&mut grads, &g1);
                want.add_weight_l2(0.01, &mut grads);
                adam.step_scaled([&mut want.params[..]], &grads, 1.0, 1e-2, EPS);
                want.refresh();
                trainer.step([&g0[..], &g1[..]]);
                assert_eq!(bits(&trainer.net.params), bits(&want.params), "threads {threads}, step {t}: parameters");
                assert_eq!(bits(&trainer.net.wt), bits(&want.wt), "threads {threads}, step {t}: transposed weights");
                assert_eq!((bits(&trainer.adam.m), bits(&trainer.adam.v)), (bits(&adam.m), bits(&adam.v)));
            }
        }
        // And the transposes are transposes, every element.
        let d = Dense::from_mlp(&mlp);
        for l in &d.layers {
            for (o, i) in (0..l.out).flat_map(|o| (0..l.inp).map(move |i| (o, i))) {
                assert_eq!(d.wt[l.w + i * l.out + o].to_bits(), d.params[l.w + o * l.inp + i].to_bits());
            }
        }
    }

    #[test]
    fn adam_matches_libtorch() {
        use tch::nn::OptimizerConfig;
        tch::manual_seed(5);
        let vs = nn::VarStore::new(Device::Cpu);
        let mlp = Mlp::new(&vs.root(), &[3, 4, 1], Activation::Relu, Init::Default);
        let mut dense = Dense::from_mlp(&mlp);
        let mut opt = nn::Adam::default().build(&vs, 1e-2).unwrap();
        let mut adam = Adam::new(dense.len());
        let x = Tensor::randn([6, 3], (Kind::Float, Device::Cpu));
        let xs: Vec<f32> = Vec::try_from(x.flatten(0, -1)).unwrap();
        let mut s = Scratch::default();
        for _ in 0..5 {
            // loss = sum f(x)
            opt.backward_step(&mlp.forward(&x).sum(Kind::Float));
            dense.forward(&xs, 6, &mut s);
            let mut grads = vec![0.0; dense.len()];
            dense.backward(&xs, 6, &[1.0; 6], &mut s, &mut grads);
            adam.step_scaled([&mut dense.params[..]], &grads, 1.0, 1e-2, EPS);
            dense.refresh();
        }
        let after = Dense::from_mlp(&mlp);
        for (a, b) in dense.params.iter().zip(after.params.iter()) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }
}
