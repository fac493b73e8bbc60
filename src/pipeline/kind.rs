//! The closed set of stage kinds: each one's name in manifests and Slurm job names, its
//! version (part of every key) and whether it runs on several threads. The kinds' parameters,
//! metrics and bodies are in [`crate::pipeline::stage`].
use serde::{Deserialize, Serialize};

macro_rules! kinds {
    ($($kind:ident = $name:literal,)*) => {
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, schemars::JsonSchema)]
        pub enum StageKind {
            $(#[serde(rename = $name)] $kind,)*
        }

        impl StageKind {
            pub const ALL: &[StageKind] = &[$(StageKind::$kind,)*];

            pub fn name(self) -> &'static str {
                match self { $(StageKind::$kind => $name,)* }
            }
        }
    };
}

kinds! {
    Demonstrator = "demonstrator",
    Demos = "demos",
    DemosImport = "demos-import",
    Bc = "bc",
    NoiseRollouts = "noise-rollouts",
    Trex = "trex",
    Ppo = "ppo",
    Eval = "eval",
    InterpolationRollouts = "interpolation-rollouts",
    ActionNoiseRollouts = "action-noise-rollouts",
    MultiBcRollouts = "multi-bc-rollouts",
    BankPolicy = "bank-policy",
    Bank = "bank",
    BankScore = "bank-score",
    Probe = "probe",
}

impl StageKind {
    /// Bump when a change to the stage would change its results.
    pub fn version(self) -> u32 {
        match self {
            // 2: trained on nn::dense (explicit gradients over MKL's sgemm) instead of
            // libtorch's autograd, which sums in another order. 3: idrex's own products
            // (kernels::gemm) and initial weights (nn::init), the same bits on every processor.
            StageKind::Bc | StageKind::Trex => 3,
            // 4: clones from deterministic, mean-labelled source episodes with early
            // stopping, fidelity measured, and a per-step filter.
            StageKind::MultiBcRollouts => 4,
            // 2: the networks' initial weights (PPO) and the learned reward's inference
            // (PPO, evaluation) from idrex's own code instead of libtorch's. 3 (PPO and the
            // demonstrator, which PPO trains): the minibatch update's products through
            // kernels::gemm (fused multiply-adds) instead of plain loops.
            // The probe is a PPO run: its version follows PPO's.
            StageKind::Demonstrator | StageKind::Ppo | StageKind::Probe => 3,
            StageKind::Eval => 2,
            _ => 1,
        }
    }

    /// Whether the stage uses more than one thread when granted them (`ctx.threads`).
    pub fn parallel(self) -> bool {
        matches!(self, StageKind::Bc | StageKind::Trex | StageKind::MultiBcRollouts)
    }

    pub fn parse(name: &str) -> Option<StageKind> {
        StageKind::ALL.iter().copied().find(|k| k.name() == name)
    }
}
