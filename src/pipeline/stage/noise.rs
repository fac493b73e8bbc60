//! `noise-rollouts`: D-REX's automatically ranked data, epsilon-greedy rollouts of the BC
//! policy at each level of the noise schedule (lower epsilon ranks higher).
use std::path::PathBuf;

use super::{DegradationLevel, RolloutSummary, StageCtx, degradation, load_policy_for};
use crate::algo::noise;
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
    ctx.progress.set_message("epsilon-greedy rollouts");
    let meta = TrajMeta { source: "bc".into(), ..Default::default() };
    let trajs = noise::epsilon_greedy(&mut env, &policy, &p.schedule, p.rollouts_per_level, ctx.seed, &meta);
    ctx.write_rollouts(p.env, &trajs, None)?;
    Ok(NoiseMetrics { degradation: degradation(&trajs), returns: RolloutSummary::of(&trajs) })
}
