//! `noise-rollouts`: D-REX's automatically ranked data, epsilon-greedy rollouts of the BC
//! policy at each level of the noise schedule (lower epsilon ranks higher), each noisy step a
//! uniform random action or the zero action (`noise.toward`), and optionally episodes of the
//! zero action ranked below every level (`noise.still`).
use std::path::PathBuf;

use super::{DegradationLevel, RolloutSummary, StageCtx, degradation, load_policy_for};
use crate::algo::noise::{self, Disturbance, NoiseToward};
use crate::data::TrajMeta;
use crate::env::{Env, EnvId, Horizon};
use crate::error::Result;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseParams {
    pub env: EnvId,
    /// Epsilon levels.
    pub schedule: Vec<f64>,
    pub rollouts_per_level: usize,
    /// Where the rollouts end ([`crate::env::Horizon`]; absent from the key when `task`).
    #[serde(default, skip_serializing_if = "Horizon::is_task")]
    pub horizon: Horizon,
    /// What a noisy step takes instead of the policy's action (absent from the key when
    /// `random`, D-REX's).
    #[serde(default, skip_serializing_if = "NoiseToward::is_random")]
    pub toward: NoiseToward,
    /// Episodes of the zero action ranked below every level (absent from the key at 0, D-REX's
    /// MuJoCo code's).
    #[serde(default, skip_serializing_if = "super::is_zero")]
    pub still: usize,
    /// How the rollouts are disturbed (absent from the key when `epsilon`, D-REX's).
    #[serde(default, skip_serializing_if = "Disturbance::is_epsilon")]
    pub disturbance: Disturbance,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseMetrics {
    pub degradation: Vec<DegradationLevel>,
    pub returns: RolloutSummary,
}

crate::stage_inputs! {
    /// Noise is injected into the policy it rolls out (D-REX's: BC).
    NoiseInputs { policy: One Policy }
}

pub fn run(p: &NoiseParams, inputs: &NoiseInputs<PathBuf>, ctx: &StageCtx) -> Result<NoiseMetrics> {
    let mut env = Env::new(p.env)?.with_horizon(p.horizon);
    let policy = load_policy_for(&inputs.policy, &env, p.env)?;
    ctx.progress.set_message(match p.toward {
        NoiseToward::Random => "epsilon-greedy rollouts",
        NoiseToward::Zero => "epsilon-greedy rollouts toward the zero action",
        NoiseToward::Both => "epsilon-greedy rollouts toward random and zero actions",
    });
    let meta = TrajMeta { source: "bc".into(), ..Default::default() };
    let mut trajs = match p.disturbance {
        Disturbance::Epsilon => noise::degrade(&mut env, &policy, &p.schedule, p.rollouts_per_level, ctx.seed, &meta, p.toward),
        other => noise::disturb(&mut env, &policy, &p.schedule, p.rollouts_per_level, ctx.seed, &meta, other),
    };
    trajs.extend(noise::still(&mut env, p.still, ctx.seed, &meta));
    ctx.write_rollouts(p.env, &trajs, None)?;
    Ok(NoiseMetrics { degradation: degradation(&trajs), returns: RolloutSummary::of(&trajs) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// D-REX's own degradation stays out of the key, so every stored ranked set keeps its key;
    /// the zero action and a still set enter it.
    #[test]
    fn random_is_absent_from_the_key() {
        let p = NoiseParams {
            env: EnvId::Ant,
            schedule: vec![0.0, 1.0],
            rollouts_per_level: 1,
            horizon: Horizon::Task,
            toward: NoiseToward::Random,
            still: 0,
            disturbance: Disturbance::Epsilon,
        };
        let key = serde_json::to_string(&p).unwrap();
        assert!(!key.contains("toward") && !key.contains("still"), "{key}");
        let zero = serde_json::to_string(&NoiseParams { toward: NoiseToward::Zero, ..p.clone() }).unwrap();
        assert!(zero.contains(r#""toward":"zero""#), "{zero}");
        let still = serde_json::to_string(&NoiseParams { still: 5, ..p }).unwrap();
        assert!(still.contains(r#""still":5"#), "{still}");
    }
}
