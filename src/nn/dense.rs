//! Every MLP computed on the CPU: training of the BC policy, the T-REX reward nets and PPO's
//! actor and critic with explicit forward and backward passes over idrex's own matrix product
//! ([`crate::kernels::gemm`]), inference of those networks in batches (the learned reward in
//! PPO, evaluation and multi-BC), and a policy's actions one row at a time in rollouts.
//!
//! Why not autograd: at these shapes (256 units, batches of 128 rows for BC and 6,400 for
//! T-REX; 64 units and minibatches of 64 for PPO) libtorch spends a third to a half of each
//! step (for PPO, most of it) outside its matrix products, in per-operator dispatch,
//! allocation and passes over activations too large for the cache. Here every product goes
//! straight to the kernel, activations live in reused 64-byte-aligned buffers, and callers
//! feed batches in chunks of a few hundred rows, which stay in L2.
//!
//! Results are the same bits on every processor and thread count: the products and the
//! elementwise passes sum in an order fixed by the shapes; training ([`super::trainer`])
//! splits each batch into a fixed partition whose gradients it sums in a fixed order.
//! `tests::matches_libtorch_autograd` checks outputs and gradients against libtorch.

use tch::Tensor;

use super::{Activation, Mlp};
use crate::kernels::bf16::{Precision, gemm_bf16};
use crate::kernels::gemm::{Factor, Product, gemm};
use crate::kernels::{Buf, transpose_rows, vectorised};

/// One linear layer of an MLP held as a flat vector of parameters, libtorch's layout: the
/// `out x in` row-major weight at `w`, then the bias.
#[derive(Debug, Clone, Copy)]
pub struct Layer {
    pub w: usize,
    pub inp: usize,
    pub out: usize,
}

impl Layer {
    /// The offset of the bias.
    pub fn b(&self) -> usize {
        self.w + self.inp * self.out
    }

    /// The weight's range in the parameters.
    pub fn weight(&self) -> std::ops::Range<usize> {
        self.w..self.b()
    }

    /// The bias's range in the parameters.
    pub fn bias(&self) -> std::ops::Range<usize> {
        self.b()..self.b() + self.out
    }
}

/// Where a layer's bias enters the sum of its products. The two orders round differently,
/// and each trainer's stored bytes come from one: BC's and T-REX's from [`BiasOrder::Last`]
/// (and the learned reward's batches), PPO's from [`BiasOrder::First`] (and every policy's
/// actions one row at a time, [`Dense::forward_row`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BiasOrder {
    /// Each output starts from the bias and adds the products to it.
    First,
    /// The products are summed, then the bias is added.
    Last,
}

/// An MLP (the activation after every layer but the last) as one flat vector of parameters,
/// laid out as libtorch's Linear layers: per layer the `out x in` weight, then the bias. What
/// computes every network on the CPU: the training of BC, T-REX and PPO's actor and critic
/// ([`Dense::forward`], [`Dense::backward`]), the learned reward's batches
/// ([`Dense::predict`]), and a policy's actions one observation at a time in rollouts
/// ([`Dense::forward_row`]).
#[derive(Clone)]
pub struct Dense {
    pub(super) layers: Vec<Layer>,
    activation: Activation,
    /// The batched passes' order ([`Dense::forward`]); [`Dense::forward_row`] starts from the bias.
    bias: BiasOrder,
    pub params: Buf,
    /// Each layer's weight transposed (`in x out`, at the weight's offset), which the forward
    /// pass reads in place; [`Dense::refresh`] rewrites it after the parameters change.
    pub(super) wt: Buf,
    /// The factors of the training products (inference, [`Dense::predict`] included, takes
    /// whatever this says; networks are made in f32).
    precision: Precision,
}

/// One thread's activations and gradient buffers, grown to the largest chunk it has seen.
#[derive(Clone, Default)]
pub struct Scratch {
    /// Every layer's output, the last one's included.
    acts: Vec<Buf>,
    d: Buf,
    dprev: Buf,
}

impl Dense {
    pub fn from_mlp(mlp: &Mlp) -> Self {
        let mut layers = Vec::new();
        let mut params = Vec::new();
        for (w, b) in mlp.parameters() {
            let (out, inp) = (w.size()[0] as usize, w.size()[1] as usize);
            layers.push(Layer { w: params.len(), inp, out });
            let f32s = |t: &Tensor| t.detach().to_kind(tch::Kind::Float).flatten(0, -1);
            params.extend(Vec::<f32>::try_from(f32s(w)).expect("f32 weights"));
            params.extend(Vec::<f32>::try_from(f32s(b)).expect("f32 bias"));
        }
        let mut buf = Buf::zeros(params.len());
        buf.copy_from_slice(&params);
        let (activation, wt) = (mlp.activation(), Buf::zeros(params.len()));
        let mut dense = Dense { layers, activation, bias: BiasOrder::Last, params: buf, wt, precision: Precision::F32 };
        dense.refresh();
        dense
    }

    /// The same network computing its products at `precision`.
    pub fn with_precision(self, precision: Precision) -> Self {
        Dense { precision, ..self }
    }

    /// The same network with its batched passes summing in `bias` order.
    pub fn with_bias_order(self, bias: BiasOrder) -> Self {
        Dense { bias, ..self }
    }

    /// One product of the passes, at the network's precision.
    fn gemm(&self, p: Product<'_>, c: &mut [f32], ldc: usize) {
        match self.precision {
            Precision::F32 => gemm(p, c, ldc),
            Precision::Bf16 => gemm_bf16(p, c, ldc),
        }
    }

    /// Adds Gaussian noise to every weight (not the biases), each layer's at `scale` times the
    /// root mean square of its own weights, so one scale disturbs every layer alike
    /// (parameter-space noise); the transposed weights follow.
    pub fn perturb_weights(&mut self, scale: f64, rng: &mut impl rand::Rng) {
        for l in self.layers.clone() {
            let w = &mut self.params[l.w..l.b()];
            let rms = (w.iter().map(|&x| (x as f64).powi(2)).sum::<f64>() / w.len().max(1) as f64).sqrt();
            for x in w.iter_mut() {
                *x += (scale * rms * rng.sample::<f64, _>(rand_distr::StandardNormal)) as f32;
            }
        }
        self.refresh();
    }

    /// Rewrites the transposed weights from the parameters: call after changing them.
    pub fn refresh(&mut self) {
        for l in &self.layers {
            transpose_rows(&self.params[l.w..l.b()], l.inp, l.out, 0..l.inp, &mut self.wt[l.w..l.b()]);
        }
    }

    /// Writes the parameters back into `mlp` (the network this was made from).
    pub fn write_to(&self, mlp: &Mlp) {
        tch::no_grad(|| {
            for (l, (w, b)) in self.layers.iter().zip(mlp.parameters()) {
                let mut w = w.shallow_clone();
                let mut b = b.shallow_clone();
                w.copy_(&Tensor::from_slice(&self.params[l.w..l.b()]).view([l.out as i64, l.inp as i64]));
                b.copy_(&Tensor::from_slice(&self.params[l.b()..l.b() + l.out]));
            }
        });
    }

    pub fn len(&self) -> usize {
        self.params.len()
    }

    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    pub fn output_dim(&self) -> usize {
        self.layers.last().expect("an MLP has layers").out
    }

    pub fn input_dim(&self) -> usize {
        self.layers[0].inp
    }

    /// Writes f(x) for one input row into `out`, layer by layer as contiguous axpys over the
    /// transposed weights (which the compiler vectorises, a dot product it would not);
    /// allocates nothing once `scratch` has grown. Rollouts call it once per environment
    /// step, where a libtorch call would cost several times more.
    pub fn forward_row(&self, x: &[f32], out: &mut [f32], scratch: &mut Vec<f32>) {
        let width = self.layers.iter().map(|l| l.inp.max(l.out)).max().unwrap_or(0);
        scratch.resize(2 * width, 0.0);
        let (a, b) = scratch.split_at_mut(width);
        a[..x.len()].copy_from_slice(x);
        let (mut cur, mut next) = (a, b);
        let last = self.layers.len() - 1;
        for (i, l) in self.layers.iter().enumerate() {
            let y = &mut next[..l.out];
            row_layer(y, &cur[..l.inp], &self.wt[l.weight()], &self.params[l.bias()]);
            if i < last {
                super::activate(y, self.activation);
            }
            std::mem::swap(&mut cur, &mut next);
        }
        out.copy_from_slice(&cur[..self.output_dim()]);
    }

    /// The outputs (`rows x out`) of `x` (`rows x in`), kept in `s` for [`Dense::backward`].
    pub fn forward<'s>(&self, x: &[f32], rows: usize, s: &'s mut Scratch) -> &'s [f32] {
        s.acts.resize_with(self.layers.len(), Buf::default);
        let last = self.layers.len() - 1;
        for (i, l) in self.layers.iter().enumerate() {
            let (done, rest) = s.acts.split_at_mut(i);
            let input: &[f32] = if i == 0 { x } else { &done[i - 1] };
            let y = &mut rest[0];
            y.resize(rows * l.out);
            let bias = &self.params[l.bias()];
            if self.bias == BiasOrder::First {
                y.chunks_exact_mut(l.out).for_each(|row| row.copy_from_slice(bias));
            }
            let p = Product {
                m: rows,
                n: l.out,
                k: l.inp,
                a: Factor::new(input, l.inp),
                b: Factor::new(&self.wt[l.weight()], l.out),
                accumulate: self.bias == BiasOrder::First,
            };
            self.gemm(p, y, l.out);
            let activate = i < last;
            match (self.bias, self.activation) {
                // The sum and the ReLU in one pass.
                (BiasOrder::Last, Activation::Relu) => add_bias(y, bias, activate),
                (BiasOrder::Last, Activation::Tanh) => add_bias(y, bias, false),
                (BiasOrder::First, _) => {}
            }
            if activate && (self.bias, self.activation) != (BiasOrder::Last, Activation::Relu) {
                super::activate(y, self.activation);
            }
        }
        &s.acts[last][..rows * self.output_dim()]
    }

    /// The outputs (`rows x out`) of `x` (`rows x in`), appended to `out`. Computed in chunks
    /// of rows that stay in cache: a row's output depends on that row alone, so the chunks
    /// change no bit.
    pub fn predict(&self, x: &[f32], rows: usize, out: &mut Vec<f32>) {
        const CHUNK: usize = 256;
        let inp = self.layers[0].inp;
        let mut s = Scratch::default();
        for start in (0..rows).step_by(CHUNK) {
            let n = CHUNK.min(rows - start);
            out.extend_from_slice(self.forward(&x[start * inp..(start + n) * inp], n, &mut s));
        }
    }

    /// Adds the gradient of a loss to `grads` (laid out as the parameters), given the input
    /// of the last [`Dense::forward`] and the loss's gradient `dout` with respect to its
    /// outputs (`rows x out`).
    pub fn backward(&self, x: &[f32], rows: usize, dout: &[f32], s: &mut Scratch, grads: &mut [f32]) {
        let Scratch { acts, d, dprev } = s;
        let last = self.layers.len() - 1;
        let top = self.layers[last];
        col_sums(&dout[..rows * top.out], &mut grads[top.b()..top.b() + top.out]);
        for (i, l) in self.layers.iter().enumerate().rev() {
            // The gradient with respect to this layer's outputs (its bias's is already added).
            let cur: &[f32] = if i == last { &dout[..rows * l.out] } else { d };
            let input: &[f32] = if i == 0 { x } else { &acts[i - 1] };
            let p = Product { m: l.out, n: l.inp, k: rows, a: Factor::t(cur, l.out), b: Factor::new(input, l.inp), accumulate: true };
            self.gemm(p, &mut grads[l.w..l.b()], l.inp);
            if i > 0 {
                dprev.resize(rows * l.inp);
                let p = Product {
                    m: rows,
                    n: l.inp,
                    k: l.out,
                    a: Factor::new(cur, l.out),
                    b: Factor::new(&self.params[l.w..l.b()], l.inp),
                    accumulate: false,
                };
                self.gemm(p, dprev, l.inp);
                let below = self.layers[i - 1];
                let db = &mut grads[below.bias()];
                match self.activation {
                    Activation::Relu => relu_backward(dprev, input, db),
                    Activation::Tanh => tanh_backward(dprev, input, db),
                }
                std::mem::swap(d, dprev);
            }
        }
    }

    /// Adds the gradient of `coef * sum of squared weights` (not biases) to `grads`: the
    /// separate pass [`super::trainer::Trainer::step`] fuses, kept as the tests' reference.
    #[cfg(test)]
    pub fn add_weight_l2(&self, coef: f32, grads: &mut [f32]) {
        for l in &self.layers {
            axpy(2.0 * coef, &self.params[l.w..l.b()], &mut grads[l.w..l.b()]);
        }
    }

    /// The sum of squared weights (not biases).
    pub fn weight_l2(&self) -> f64 {
        self.layers.iter().flat_map(|l| &self.params[l.w..l.b()]).map(|&w| (w as f64) * (w as f64)).sum()
    }
}

vectorised! {
    /// `y = bias + x W` for one row (`wt` is `W^T`, `x.len() x y.len()` row-major).
    fn row_layer(y: &mut [f32], x: &[f32], wt: &[f32], bias: &[f32]) {
        let out = y.len();
        y.copy_from_slice(bias);
        for (i, &xi) in x.iter().enumerate() {
            for (yo, w) in y.iter_mut().zip(&wt[i * out..(i + 1) * out]) {
                *yo += xi * w;
            }
        }
    }
}

impl std::fmt::Debug for Dense {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sizes: Vec<usize> = std::iter::once(self.input_dim()).chain(self.layers.iter().map(|l| l.out)).collect();
        f.debug_struct("Dense").field("sizes", &sizes).field("activation", &self.activation).field("precision", &self.precision).finish()
    }
}

vectorised! {
    /// `y = y + bias` on every row, then the ReLU where `relu`.
    fn add_bias(y: &mut [f32], bias: &[f32], relu: bool) {
        for row in y.chunks_exact_mut(bias.len()) {
            for (v, b) in row.iter_mut().zip(bias) {
                let t = *v + b;
                *v = if relu { t.max(0.0) } else { t };
            }
        }
    }
}

vectorised! {
    /// `sums += ` the column sums of `m` (rows of `sums.len()`), row by row.
    fn col_sums(m: &[f32], sums: &mut [f32]) {
        for row in m.chunks_exact(sums.len()) {
            sums.iter_mut().zip(row).for_each(|(s, v)| *s += v);
        }
    }
}

vectorised! {
    /// Through a ReLU whose outputs were `h`: `g` is zeroed where the unit was off, and its
    /// column sums (the layer's bias gradient) are added to `db`.
    fn relu_backward(g: &mut [f32], h: &[f32], db: &mut [f32]) {
        for (grow, hrow) in g.chunks_exact_mut(db.len()).zip(h.chunks_exact(db.len())) {
            for ((gv, &hv), s) in grow.iter_mut().zip(hrow).zip(db.iter_mut()) {
                // A select, not a branch, so that it vectorises.
                let v = if hv > 0.0 { *gv } else { 0.0 };
                *gv = v;
                *s += v;
            }
        }
    }
}

vectorised! {
    /// Through a tanh whose outputs were `h`: `g` times `1 - h^2`, and its column sums (the
    /// layer's bias gradient) added to `db`.
    fn tanh_backward(g: &mut [f32], h: &[f32], db: &mut [f32]) {
        for (grow, hrow) in g.chunks_exact_mut(db.len()).zip(h.chunks_exact(db.len())) {
            for ((gv, &hv), s) in grow.iter_mut().zip(hrow).zip(db.iter_mut()) {
                *gv *= 1.0 - hv * hv;
                *s += *gv;
            }
        }
    }
}

#[cfg(test)]
vectorised! {
    /// `y += a x`.
    fn axpy(a: f32, x: &[f32], y: &mut [f32]) {
        y.iter_mut().zip(x).for_each(|(y, x)| *y += a * x);
    }
}

#[cfg(test)]
vectorised! {
    /// `a += b`, elementwise.
    fn add_into(a: &mut [f32], b: &[f32]) {
        a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::Init;
    use tch::{Device, Kind, nn, nn::Module};

    /// The passes run their AVX-512 build on a CPU that has it: the bits must be those of
    /// the same operations one element at a time.
    #[test]
    #[allow(clippy::needless_range_loop)] // the reference loop reads like the formula.
    fn vectorised_passes_give_the_scalar_bits() {
        let n = 16 * 37 + 5;
        let vals = |k: f32| (0..n).map(|i| ((i as f32 * k).sin() * 3.0).powi(3)).collect::<Vec<f32>>();
        let (g, h) = (vals(0.37), vals(0.91));
        let width = n / 7;
        let rows = n / width;
        // ReLU backward with the bias gradient.
        let (mut got, mut db) = (g.clone(), vec![0.5f32; width]);
        relu_backward(&mut got[..rows * width], &h[..rows * width], &mut db);
        let (mut want, mut want_db) = (g.clone(), vec![0.5f32; width]);
        for r in 0..rows {
            for c in 0..width {
                let i = r * width + c;
                want[i] = if h[i] > 0.0 { g[i] } else { 0.0 };
                want_db[c] += want[i];
            }
        }
        assert_eq!(bits(&got), bits(&want));
        assert_eq!(bits(&db), bits(&want_db));
        // Bias and ReLU.
        let mut y = g.clone();
        add_bias(&mut y[..rows * width], &h[..width], true);
        let want: Vec<f32> = (0..rows * width).map(|i| (g[i] + h[i % width]).max(0.0)).collect();
        assert_eq!(bits(&y[..rows * width]), bits(&want));
    }

    fn bits(x: &[f32]) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// One row at a time, tanh and ReLU networks: libtorch's forward.
    #[test]
    fn forward_row_matches_the_libtorch_forward() {
        tch::manual_seed(0);
        let vs = nn::VarStore::new(Device::Cpu);
        for act in [Activation::Tanh, Activation::Relu] {
            let m = Mlp::new(&(vs.root() / format!("{act:?}")), &[5, 16, 16, 3], act, Init::Default);
            let x = Tensor::randn([4, 5], (Kind::Float, Device::Cpu));
            let y: Vec<f32> = Vec::try_from(m.forward(&x).flatten(0, -1)).unwrap();
            let xs: Vec<f32> = Vec::try_from(x.flatten(0, -1)).unwrap();
            let cpu = Dense::from_mlp(&m);
            let mut scratch = Vec::new();
            for r in 0..4 {
                let mut out = [0.0f32; 3];
                cpu.forward_row(&xs[r * 5..(r + 1) * 5], &mut out, &mut scratch);
                for c in 0..3 {
                    assert!((out[c] - y[r * 3 + c]).abs() < 1e-5);
                }
            }
        }
    }

    #[test]
    fn matches_libtorch_autograd() {
        tch::manual_seed(3);
        let vs = nn::VarStore::new(Device::Cpu);
        let mlp = Mlp::new(&vs.root(), &[7, 32, 16, 2], Activation::Relu, Init::Default);
        let rows = 11;
        let x = Tensor::randn([rows as i64, 7], (Kind::Float, Device::Cpu));
        let target = Tensor::randn([rows as i64, 2], (Kind::Float, Device::Cpu));
        // loss = sum (f(x) - target)^2 + 0.1 * sum of squared weights
        let loss: Tensor = (mlp.forward(&x) - &target).square().sum(Kind::Float) + mlp.weight_l2() * 0.1;
        loss.backward();
        let dense = Dense::from_mlp(&mlp);
        let xs: Vec<f32> = Vec::try_from(x.flatten(0, -1)).unwrap();
        let ts: Vec<f32> = Vec::try_from(target.flatten(0, -1)).unwrap();
        let mut s = Scratch::default();
        let out = dense.forward(&xs, rows, &mut s).to_vec();
        let want: Vec<f32> = Vec::try_from(mlp.forward(&x).flatten(0, -1)).unwrap();
        for (o, w) in out.iter().zip(&want) {
            assert!((o - w).abs() < 1e-5);
        }
        let dout: Vec<f32> = out.iter().zip(&ts).map(|(o, t)| 2.0 * (o - t)).collect();
        let mut grads = vec![0.0; dense.len()];
        dense.backward(&xs, rows, &dout, &mut s, &mut grads);
        dense.add_weight_l2(0.1, &mut grads);
        let mut want = Vec::new();
        for (w, b) in mlp.parameters() {
            want.extend(Vec::<f32>::try_from(w.grad().flatten(0, -1)).unwrap());
            want.extend(Vec::<f32>::try_from(b.grad()).unwrap());
        }
        assert_eq!(grads.len(), want.len());
        for (i, (g, w)) in grads.iter().zip(&want).enumerate() {
            assert!((g - w).abs() < 1e-4 * (1.0 + w.abs()), "parameter {i}: {g} vs {w}");
        }
    }
}
