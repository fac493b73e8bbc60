//! `interpolation-rollouts`, iD-REX variant 1 (the report's equations 6-8): for each RL run
//! r, rollouts of pi_k(.|alpha), which acts with the run's newer policy with probability
//! alpha and with its older one (pi_{k-1}; BC at k = 1) otherwise. Higher alpha ranks higher
//! within one source policy; stored as noise = 1 - alpha so that lower noise ranks higher.
use crate::algo::noise::Interpolation;
use crate::data::TrajMeta;
use crate::env::{Env, EnvId, Horizon};
use crate::error::Result;
use crate::pipeline::stage::{DegradationMetrics, StageCtx, degradation, load_policy_for};
use crate::rollout::{self, PolicyActor};
use crate::seed::{self, Purpose};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub env: EnvId,
    pub alphas: Vec<f64>,
    pub rollouts_per_level: usize,
    /// Where the rollouts end ([`crate::env::Horizon`]; absent from the key when `task`).
    #[serde(default, skip_serializing_if = "Horizon::is_task")]
    pub horizon: Horizon,
}

crate::stage_inputs! {
    /// The iteration's policies, each paired with the one before it (`older[r]`, BC's for
    /// the first iteration).
    InterpolationInputs { policies: Many Policy, older: Many Older }
}

pub fn run(p: &Params, inputs: &InterpolationInputs<std::path::PathBuf>, ctx: &StageCtx) -> Result<DegradationMetrics> {
    let mut env = Env::new(p.env)?.with_horizon(p.horizon);
    let noise: Vec<f64> = p.alphas.iter().map(|a| 1.0 - a).collect();
    let mut trajs = Vec::new();
    for (r, (n, o)) in inputs.policies.iter().zip(&inputs.older).enumerate() {
        let (newer, older) = (load_policy_for(n, &env, p.env)?, load_policy_for(o, &env, p.env)?);
        let meta = TrajMeta { source: format!("interpolation/{r}"), group: r, ..Default::default() };
        let seed = seed::derive(ctx.seed, Purpose::Source, r as u64);
        trajs.extend(rollout::at_levels(&mut env, seed, &noise, p.rollouts_per_level, &meta, |noise| Interpolation {
            newer: PolicyActor::acting(&newer),
            older: PolicyActor::acting(&older),
            alpha: 1.0 - noise,
        }));
    }
    ctx.write_rollouts(p.env, &trajs, None)?;
    Ok(DegradationMetrics { degradation: degradation(&trajs) })
}
