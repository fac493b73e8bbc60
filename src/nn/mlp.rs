//! A multi-layer perceptron: `(b, in)` -> `(b, out)`, an activation after every layer but the
//! last.
use tch::{Tensor, nn, nn::Module};

use super::dense::Dense;

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    Tanh,
    Relu,
}

impl Activation {
    pub fn apply(self, x: &Tensor) -> Tensor {
        match self {
            Activation::Tanh => x.tanh(),
            Activation::Relu => x.relu(),
        }
    }
}

/// Weight initialisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Init {
    /// libtorch's default distribution (Kaiming-uniform weights, uniform bias), as in the
    /// D-REX code.
    Default,
    /// Orthogonal weights with gain sqrt(2) on hidden layers and `out_gain` on the output
    /// layer, zero biases (the PPO implementation details of CleanRL and SB3).
    Orthogonal { out_gain: f64 },
    /// N(0, std^2) weights, zero biases (the original D-REX code's reward and BC networks).
    Normal { std: f64 },
}

/// The initialisation a pipeline file can choose for the BC and reward networks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub enum WeightInit {
    /// libtorch's default (Kaiming-uniform weights, uniform biases); also read as
    /// `default`, its name in stage keys.
    #[default]
    #[serde(rename(serialize = "default", deserialize = "libtorch"), alias = "default")]
    TorchDefault,
    /// N(0, 0.02^2) weights and zero biases, as the original D-REX code.
    #[serde(rename = "normal-0.02")]
    Normal002,
}

impl WeightInit {
    pub fn init(self) -> Init {
        match self {
            WeightInit::TorchDefault => Init::Default,
            WeightInit::Normal002 => Init::Normal { std: 0.02 },
        }
    }
}

#[derive(Debug)]
pub struct Mlp {
    layers: Vec<nn::Linear>,
    activation: Activation,
}

impl Mlp {
    /// Layers `sizes[0] -> sizes[1] -> ... -> sizes[n]`, named `l0, l1, ...` under `p`, with
    /// weights from this thread's initialisation generator ([`super::init`]; build inside
    /// [`super::seeded`] for reproducible weights).
    pub fn new(p: &nn::Path, sizes: &[i64], activation: Activation, init: Init) -> Self {
        let n = sizes.len() - 1;
        let zeros = nn::LinearConfig { ws_init: nn::Init::Const(0.0), bs_init: Some(nn::Init::Const(0.0)), bias: true };
        let layers: Vec<nn::Linear> = (0..n).map(|i| nn::linear(p / format!("l{i}"), sizes[i], sizes[i + 1], zeros)).collect();
        tch::no_grad(|| {
            for (i, l) in layers.iter().enumerate() {
                let (out, inp) = (sizes[i + 1], sizes[i]);
                let (w, b) = super::init::layer(init, out as usize, inp as usize, i + 1 == n);
                l.ws.shallow_clone().copy_(&Tensor::from_slice(&w).view([out, inp]));
                l.bs.as_ref().expect("idrex's linear layers have biases").shallow_clone().copy_(&Tensor::from_slice(&b));
            }
        });
        Mlp { layers, activation }
    }

    pub fn activation(&self) -> Activation {
        self.activation
    }

    /// Every layer's weight (`out x in`) and bias, in order.
    pub fn parameters(&self) -> impl Iterator<Item = (&Tensor, &Tensor)> {
        self.layers.iter().map(|l| (&l.ws, l.bs.as_ref().expect("idrex's linear layers have biases")))
    }

    /// Sum of squared weights (not biases): the L2 term of the BC and T-REX losses.
    pub fn weight_l2(&self) -> Tensor {
        self.layers.iter().map(|l| l.ws.square().sum(tch::Kind::Float)).reduce(|a, b| a + b).expect("an MLP has layers")
    }

    /// A frozen copy computed by idrex's own code ([`Dense`]).
    pub fn to_cpu(&self) -> Dense {
        Dense::from_mlp(self)
    }
}

impl Module for Mlp {
    fn forward(&self, x: &Tensor) -> Tensor {
        let mut h = x.shallow_clone();
        for (i, l) in self.layers.iter().enumerate() {
            h = l.forward(&h);
            if i + 1 < self.layers.len() {
                h = self.activation.apply(&h);
            }
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::WeightInit;

    /// `libtorch` is the name a file uses; keys keep spelling it `default`, as they always did.
    #[test]
    fn libtorch_init_reads_both_names_and_keys_keep_the_old_one() {
        for name in ["libtorch", "default"] {
            assert_eq!(serde_yaml::from_str::<WeightInit>(name).unwrap(), WeightInit::TorchDefault, "{name}");
        }
        assert_eq!(serde_json::to_string(&WeightInit::TorchDefault).unwrap(), "\"default\"");
        assert!(serde_yaml::from_str::<WeightInit>("torch").is_err());
    }
}
