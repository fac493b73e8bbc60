//! A frozen copy of an [`super::Mlp`] evaluated in plain Rust, one input row at a time.
//! Rollouts call a policy once per environment step; at these sizes (64 to 256 units) a
//! direct loop is several times faster than a libtorch call and allocates nothing.
use super::Activation;
use crate::kernels::vectorised;

#[derive(Debug, Clone)]
pub struct MlpCpu {
    /// (weights transposed, `in x out` row-major, bias, in, out) per layer.
    layers: Vec<(Vec<f32>, Vec<f32>, usize, usize)>,
    activation: Activation,
    width: usize,
}

impl MlpCpu {
    pub fn new(layers: Vec<(Vec<f32>, Vec<f32>, usize, usize)>, activation: Activation) -> Self {
        let width = layers.iter().map(|l| l.3.max(l.2)).max().unwrap_or(0);
        // Stored transposed (in x out) so that the forward pass is contiguous axpys, which
        // the compiler vectorises (a dot-product reduction it would not).
        let layers = layers
            .into_iter()
            .map(|(w, b, inp, out)| {
                let mut wt = vec![0.0; w.len()];
                for o in 0..out {
                    for i in 0..inp {
                        wt[i * out + o] = w[o * inp + i];
                    }
                }
                (wt, b, inp, out)
            })
            .collect();
        MlpCpu { layers, activation, width }
    }

    pub fn input_dim(&self) -> usize {
        self.layers[0].2
    }
    pub fn output_dim(&self) -> usize {
        self.layers.last().unwrap().3
    }

    /// Writes f(x) into `out`. `scratch` holds two buffers and is grown as needed.
    pub fn forward(&self, x: &[f32], out: &mut [f32], scratch: &mut Vec<f32>) {
        scratch.resize(2 * self.width, 0.0);
        let (a, b) = scratch.split_at_mut(self.width);
        a[..x.len()].copy_from_slice(x);
        let (mut cur, mut next) = (a, b);
        let n = self.layers.len();
        for (li, (wt, bias, inp, outd)) in self.layers.iter().enumerate() {
            let y = &mut next[..*outd];
            layer(y, &cur[..*inp], wt, bias);
            if li + 1 < n {
                super::activate(y, self.activation);
            }
            std::mem::swap(&mut cur, &mut next);
        }
        out.copy_from_slice(&cur[..self.output_dim()]);
    }
}

vectorised! {
    /// `y = bias + x W` (`wt` is `W^T`, `x.len() x y.len()` row-major).
    fn layer(y: &mut [f32], x: &[f32], wt: &[f32], bias: &[f32]) {
        let out = y.len();
        y.copy_from_slice(bias);
        for (i, &xi) in x.iter().enumerate() {
            for (yo, w) in y.iter_mut().zip(&wt[i * out..(i + 1) * out]) {
                *yo += xi * w;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Activation, Init, Mlp};
    use tch::{Device, Kind, Tensor, nn, nn::Module};

    #[test]
    fn matches_the_libtorch_forward() {
        tch::manual_seed(0);
        let vs = nn::VarStore::new(Device::Cpu);
        for act in [Activation::Tanh, Activation::Relu] {
            let m = Mlp::new(&(vs.root() / format!("{act:?}")), &[5, 16, 16, 3], act, Init::Default);
            let x = Tensor::randn([4, 5], (Kind::Float, Device::Cpu));
            let y: Vec<f32> = Vec::try_from(m.forward(&x).flatten(0, -1)).unwrap();
            let xs: Vec<f32> = Vec::try_from(x.flatten(0, -1)).unwrap();
            let cpu = m.to_cpu();
            let mut scratch = Vec::new();
            for r in 0..4 {
                let mut out = [0.0f32; 3];
                cpu.forward(&xs[r * 5..(r + 1) * 5], &mut out, &mut scratch);
                for c in 0..3 {
                    assert!((out[c] - y[r * 3 + c]).abs() < 1e-5);
                }
            }
        }
    }
}
