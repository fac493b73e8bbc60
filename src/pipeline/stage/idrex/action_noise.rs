//! `action-noise-rollouts`, iD-REX variant 2 (the report's equation 9): for each RL run's
//! policy, its mean action plus noise of scale sigma (Gaussian, Ornstein-Uhlenbeck or
//! time-correlated); lower sigma ranks higher, within one source policy.
use crate::algo::noise::NoiseProcess;
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
    pub sigmas: Vec<f64>,
    pub noise: NoiseProcess,
    pub rollouts_per_level: usize,
    /// Where the rollouts end ([`crate::env::Horizon`]; absent from the key when `task`).
    #[serde(default, skip_serializing_if = "Horizon::is_task")]
    pub horizon: Horizon,
}

crate::stage_inputs! {
    /// The iteration's policies, one per RL run.
    ActionNoiseInputs { policies: Many Policy }
}

pub fn run(p: &Params, inputs: &ActionNoiseInputs<std::path::PathBuf>, ctx: &StageCtx) -> Result<DegradationMetrics> {
    let mut env = Env::new(p.env)?.with_horizon(p.horizon);
    let ad = env.act_dim();
    let mut trajs = Vec::new();
    for (r, dir) in inputs.policies.iter().enumerate() {
        let policy = load_policy_for(dir, &env, p.env)?;
        let meta = TrajMeta { source: format!("action-noise/{r}"), group: r, ..Default::default() };
        let seed = seed::derive(ctx.seed, Purpose::Source, r as u64);
        trajs.extend(rollout::at_levels(&mut env, seed, &p.sigmas, p.rollouts_per_level, &meta, |sigma| {
            p.noise.around(PolicyActor::mean_of(&policy), sigma, ad)
        }));
    }
    ctx.write_rollouts(p.env, &trajs, None)?;
    Ok(DegradationMetrics { degradation: degradation(&trajs) })
}
