//! T-REX's settings (`trex:` in a pipeline file).
use crate::kernels::bf16::Precision;
use crate::nn::WeightInit;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrexConfig {
    /// Hidden layer sizes of each reward network (ReLU).
    pub hidden: Vec<usize>,
    /// Members of the ensemble, each trained on its own pairs and seed.
    pub models: usize,
    /// Training pairs sampled per member (the validation pairs among them).
    pub pairs_per_model: usize,
    /// Window length in steps (shortened to the shorter trajectory where needed).
    pub window: usize,
    /// With a value, each pair's window length is drawn uniformly from `window` to this
    /// (SSRR's snippets: 50-500 steps); absent (the key's default), every window is `window`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub window_max: Option<usize>,
    /// Windows aligned in time as T-REX's code drew them: the preferred trajectory's window
    /// starts no earlier than the other's, so a pair never prefers an early stretch to a late
    /// one. Absent from the key when false (independent starts, D-REX's).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub aligned: bool,
    /// Smallest score difference for a pair.
    pub min_margin: f64,
    /// Pair only trajectories of the same group (multi-BC ranks within one clone).
    pub same_group: bool,
    /// Adam learning rate.
    pub lr: f64,
    /// Pairs per minibatch.
    pub batch_size: usize,
    /// Minibatch updates per member.
    pub iterations: usize,
    /// Weight of the sum of squared weights.
    pub l2: f64,
    /// Fraction of the pairs held out for validation accuracy.
    pub val_fraction: f64,
    /// Feed the action to the reward net too.
    pub action_input: bool,
    /// Initialisation of the reward networks.
    pub init: WeightInit,
    /// The factors of the training products: f32 (the default) or bf16 with f32
    /// accumulation (`kernels::bf16`; native where the processor has AVX512-BF16, the same bits
    /// emulated elsewhere). Inference is f32 either way.
    #[serde(skip_serializing_if = "Precision::is_f32")]
    pub precision: Precision,
    /// What of each observation the networks read: `all`, `without-contact-forces` (Ant's 78
    /// contact-force entries left out; the other tasks observe none, and keep `all` in their
    /// keys), or `velocities` (qvel only, the root's and the joints': no posture or height to
    /// pay for).
    #[serde(skip_serializing_if = "RewardObservation::is_all")]
    pub observation: RewardObservation,
    /// `ranking` (T-REX's Bradley-Terry loss over pairs) or `regression` (SSRR's recipe
    /// without AIRL, [`super::regression`]: a sigmoid of the ranking ensemble's reward per step
    /// against noise, then a fresh ensemble regressed on it; D-REX's reward only).
    #[serde(skip_serializing_if = "TrexLoss::is_ranking")]
    pub loss: TrexLoss,
}

/// How the reward learns from the ranked set ([`TrexConfig::loss`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum TrexLoss {
    #[default]
    Ranking,
    Regression,
}

impl TrexLoss {
    pub fn is_ranking(&self) -> bool {
        *self == TrexLoss::Ranking
    }
}

/// What of each observation a learned reward reads ([`TrexConfig::observation`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum RewardObservation {
    /// The whole observation (the original code's).
    #[default]
    All,
    /// The positions and velocities only: without the contact forces a task observes (Ant's
    /// 78), on which a reward can key standing still.
    WithoutContactForces,
    /// The velocities only (qvel, as the task observes it): a reward that cannot see posture,
    /// height or contacts can pay for motion, not for holding a pose.
    Velocities,
}

impl RewardObservation {
    pub fn is_all(&self) -> bool {
        *self == RewardObservation::All
    }

    /// The observation entries the reward reads on `env` (`None`: all of them). Every task
    /// observes its positions, then its velocities, then (Ant) its contact forces.
    pub fn seen(self, env: &crate::env::Env) -> Option<std::ops::Range<usize>> {
        let positions = env.nq() - env.spec().obs_skip_qpos;
        let state = positions + env.nv();
        match self {
            RewardObservation::All => None,
            RewardObservation::WithoutContactForces => (state < env.obs_dim()).then_some(0..state),
            RewardObservation::Velocities => Some(positions..state),
        }
    }
}

impl Default for TrexConfig {
    fn default() -> Self {
        TrexConfig {
            hidden: vec![256, 256],
            models: 3,
            pairs_per_model: 5000,
            window: 50,
            window_max: None,
            aligned: false,
            min_margin: 0.3,
            same_group: false,
            lr: 1e-4,
            batch_size: 64,
            iterations: 3000,
            l2: 0.01,
            val_fraction: 0.2,
            action_input: false,
            // The original code's N(0, 0.02^2): with libtorch's default init, no setting of
            // PPO's reward composition kept the learned reward's gains on HalfCheetah
            // (analysis/results/ablation/README.md).
            init: WeightInit::Normal002,
            precision: Precision::F32,
            observation: RewardObservation::All,
            loss: TrexLoss::Ranking,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::RewardObservation::*;
    use crate::env::{Env, EnvId};

    /// The parts Gymnasium's observations hold: positions without the root's x (and Ant's
    /// y), then qvel, then Ant's contact forces.
    #[test]
    fn each_option_reads_its_part_of_every_task() {
        for (id, velocities, without_contacts) in [
            (EnvId::HalfCheetah, 8..17, None),
            (EnvId::Hopper, 5..11, None),
            (EnvId::Walker2d, 8..17, None),
            (EnvId::Ant, 13..27, Some(0..27)),
            (EnvId::AntNoCfrc, 13..27, None),
        ] {
            let env = Env::new(id).unwrap();
            assert_eq!(All.seen(&env), None, "{id:?}");
            assert_eq!(Velocities.seen(&env), Some(velocities), "{id:?}");
            assert_eq!(WithoutContactForces.seen(&env), without_contacts, "{id:?}");
        }
    }
}
