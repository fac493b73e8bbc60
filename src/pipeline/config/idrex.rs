//! `idrex:` in a pipeline file: how iD-REX makes its new ranked sets, per variant.
use crate::algo::bc::{BcConfig, EarlyStopping};
use crate::algo::noise::NoiseProcess;
use crate::nn::WeightInit;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct IdrexConfig {
    /// Variant 1: action-selection probabilities alpha of the newer policy.
    pub alphas: Vec<f64>,
    /// Variant 2: Gaussian action-noise levels.
    pub sigmas: Vec<f64>,
    /// Variant 2: the noise process.
    pub action_noise: NoiseProcess,
    /// Variants 1 and 2: rollouts per level and per source policy.
    pub rollouts_per_level: usize,
    /// Variant 3: epsilon schedule for the clones.
    pub multi_bc_schedule: Vec<f64>,
    /// Variant 3: epsilon-greedy rollouts of each clone per level (1 in the original).
    pub multi_bc_rollouts_per_level: usize,
    /// Variant 3: how the clones are made.
    pub multi_bc: CloneConfig,
    /// Variant 3: which clones join the ranked set: none (keep all: the original code),
    /// previous-reward, or held-out-reward.
    pub multi_bc_filter: CloneFilter,
}

impl Default for IdrexConfig {
    fn default() -> Self {
        IdrexConfig {
            alphas: (0..=10).map(|i| i as f64 * 0.1).collect(),
            sigmas: (0..=10).map(|i| i as f64 * 0.1).collect(),
            action_noise: NoiseProcess::Gaussian,
            rollouts_per_level: 5,
            multi_bc_schedule: (0..20).map(|i| i as f64 * 0.05).collect(),
            multi_bc_rollouts_per_level: 1,
            multi_bc: CloneConfig::default(),
            multi_bc_filter: CloneFilter::default(),
        }
    }
}

/// Which policy of each source run a clone imitates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CloneSource {
    /// The policy at the end of training.
    #[default]
    Final,
    /// The checkpoint the ground-truth-free protocol chooses (the highest pessimistic
    /// learned return, pooled over the runs). The original code cloned a checkpoint chosen
    /// by hand.
    Checkpoint,
}

/// How the source acts in the episodes a clone learns from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum SourceActing {
    /// Sampling from its Gaussian, as PPO policies are evaluated (and as the original did).
    Stochastic,
    /// With its mean action.
    #[default]
    Deterministic,
}

/// What the clone regresses at each of the source's states.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CloneLabels {
    /// The actions the source took (sampled, clipped to the box; the original code).
    Sampled,
    /// The source's mean action, clipped to the box: what the noise-free clone should do.
    #[default]
    Mean,
}

/// How multi-BC's clones are made (`idrex.multi_bc` in a pipeline file).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CloneConfig {
    pub source: CloneSource,
    pub acting: SourceActing,
    pub labels: CloneLabels,
    /// Episodes of the source a clone trains on (the report: one trajectory).
    pub episodes: usize,
    /// Further source episodes held out for BC's validation loss and early stopping; 0
    /// validates on `bc.val_fraction` of the training steps instead.
    pub held_out_episodes: usize,
    /// Feed the clone observations normalised with its source's statistics (and store them
    /// with it), as the source saw them.
    pub normalize: bool,
    /// The clones' BC settings (separate from the demonstrations' `bc`); given, it replaces
    /// the whole default.
    pub bc: BcConfig,
    /// Noise-free episodes of each clone, measured for fidelity and scored by the filter.
    pub fidelity_episodes: usize,
}

impl Default for CloneConfig {
    fn default() -> Self {
        CloneConfig {
            source: CloneSource::Final,
            acting: SourceActing::Deterministic,
            labels: CloneLabels::Mean,
            episodes: 4,
            held_out_episodes: 1,
            normalize: true,
            bc: BcConfig {
                iterations: 20_000,
                init: WeightInit::Normal002,
                early_stopping: Some(EarlyStopping { every: 250, patience: 8 }),
                ..BcConfig::default()
            },
            fidelity_episodes: 5,
        }
    }
}

impl CloneConfig {
    /// Source episodes per clone, training and held out: their seeds are 100 apart per clone.
    pub const MAX_EPISODES: usize = 100;

    pub fn check(&self) -> std::result::Result<(), String> {
        if self.episodes == 0 {
            return Err("idrex.multi_bc.episodes is 0; a clone needs at least 1 source episode".into());
        }
        if self.episodes + self.held_out_episodes > Self::MAX_EPISODES {
            return Err(format!("idrex.multi_bc.episodes + held_out_episodes is over {}; use fewer", Self::MAX_EPISODES));
        }
        if self.fidelity_episodes == 0 {
            return Err("idrex.multi_bc.fidelity_episodes is 0; measure each clone on at least 1 episode".into());
        }
        if self.bc.normalize {
            return Err("idrex.multi_bc.bc.normalize: clones see their source's statistics; set idrex.multi_bc.normalize instead".into());
        }
        Ok(())
    }
}

/// Which clones join the ranked set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CloneFilter {
    /// Every clone (the original code).
    None,
    /// Clones whose noise-free episodes score per step at least as high as the previous set's
    /// least noisy rollouts under the previous iteration's reward: the reward the sources
    /// were trained on, so on a task where PPO exploits it the filter is circular.
    PreviousReward,
    /// The same comparison under a judge: a reward trained on the previous iteration's ranked
    /// sets from independent seeds, which no policy was trained on.
    #[default]
    HeldOutReward,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clone_settings_that_cannot_work_are_refused_with_the_field() {
        assert!(CloneConfig::default().check().is_ok());
        let no_episodes = CloneConfig { episodes: 0, ..Default::default() };
        assert!(no_episodes.check().unwrap_err().contains("idrex.multi_bc.episodes"));
        // The clones take their source's statistics; their BC standardising again would
        // train on statistics of statistics.
        let twice = CloneConfig { bc: BcConfig { normalize: true, ..CloneConfig::default().bc }, ..Default::default() };
        assert!(twice.check().unwrap_err().contains("idrex.multi_bc.normalize"));
    }
}
