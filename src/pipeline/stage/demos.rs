//! Where the demonstrations come from: a demonstrator trained with PPO on the true reward
//! (`demonstrator`) and its rollouts (`demos`), or a file of someone else's
//! (`demos-import`: MCAP in our schema, or NPZ as the original D-REX code stored them).
use std::path::{Path, PathBuf};

use super::{RolloutSummary, StageCtx, load_policy_for, ppo_progress};
use crate::algo::ppo::{self, PpoConfig};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::{Error, Result};
use crate::pipeline::inputs::NoInputs;
use crate::rollout::mcap;
use crate::rollout::{self, Acting, PolicyActor};
use crate::seed::Purpose;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DemonstratorParams {
    pub env: EnvId,
    pub ppo: PpoConfig,
    /// Stop once an evaluation reaches this mean return.
    pub target_return: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DemonstratorMetrics {
    pub steps: usize,
    /// The step at which an evaluation reached the target, if one did.
    pub stopped_at_target: Option<usize>,
    pub wall_s: f64,
    pub final_eval: Option<f64>,
}

pub fn demonstrator(p: &DemonstratorParams, _: &NoInputs<PathBuf>, ctx: &StageCtx) -> Result<DemonstratorMetrics> {
    let cfg = p.ppo.clone();
    let mut show = ppo_progress(ctx, cfg.total_steps);
    let mut reached = None;
    let mut on_update = |u: &ppo::PpoProgress| {
        show(u);
        match (p.target_return, u.eval) {
            (Some(t), Some(e)) if e.mean >= t => {
                reached = Some(u.global_step);
                false
            }
            _ => true,
        }
    };
    let res = ppo::train(p.env, &cfg, ppo::RewardSource::GroundTruth, ctx.seed, &mut on_update, None)?;
    res.policy.save(&ctx.out.join(super::POLICY), serde_json::to_value(&cfg).unwrap_or_default())?;
    let last = res.curve.last();
    Ok(DemonstratorMetrics {
        steps: last.map_or(0, |u| u.global_step),
        stopped_at_target: reached,
        wall_s: res.wall_s,
        final_eval: last.and_then(|u| u.eval.map(|e| e.mean)),
    })
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DemosParams {
    pub env: EnvId,
    pub episodes: usize,
    /// How the demonstrator acts and what is recorded; absent (sampled) from the key.
    #[serde(default, skip_serializing_if = "Acting::is_sampled")]
    pub acting: Acting,
    /// Scales the sampled deviation from the mean action; absent (1) from the key.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub noise_scale: f64,
}

fn one() -> f64 {
    1.0
}
fn is_one(x: &f64) -> bool {
    *x == 1.0
}

crate::stage_inputs! {
    /// The demonstrations are rolled out from the demonstrator's policy.
    DemosInputs { policy: One Policy }
}

/// Rollouts of the demonstrator's policy, acting as `acting` says, episode k from
/// `derive(seed, Episode, k)`.
pub fn demos(p: &DemosParams, inputs: &DemosInputs<PathBuf>, ctx: &StageCtx) -> Result<RolloutSummary> {
    let mut env = Env::new(p.env)?;
    let policy = load_policy_for(&inputs.policy, &env, p.env)?;
    let meta = TrajMeta { source: "demonstrator".into(), ..Default::default() };
    let trajs = rollout::episodes(
        &mut env,
        &mut PolicyActor::with(&policy, p.acting, p.noise_scale),
        p.episodes,
        ctx.seed,
        Purpose::Episode,
        &meta,
    );
    ctx.write_rollouts(p.env, &trajs, None)?;
    Ok(RolloutSummary::of(&trajs).with_terms(&trajs))
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportParams {
    pub env: EnvId,
    pub path: PathBuf,
    /// The file's content: a changed file changes the key even at the same path.
    pub sha256: String,
}

pub fn import(p: &ImportParams, _: &NoInputs<PathBuf>, ctx: &StageCtx) -> Result<RolloutSummary> {
    let trajs = load(&p.path, p.env)?;
    ctx.write_rollouts(p.env, &trajs, None)?;
    Ok(RolloutSummary::of(&trajs))
}

/// Demonstrations from a file (MCAP in our rollout schema, or NPZ), checked for use in `env`:
/// at least one episode, the environment's dimensions, finite numbers, and for MCAP the
/// environment it was recorded in. Pipelines call this when they load, before any stage.
pub fn load(path: &Path, env: EnvId) -> Result<Vec<Trajectory>> {
    let trajs = if path.extension().is_some_and(|e| e == "mcap") {
        let r = mcap::read(path)?;
        if r.env != env.name() {
            return Err(Error::file(path, format!("was recorded in {}, but this pipeline's environment is {env}", r.env)));
        }
        r.trajectories
    } else {
        crate::data::npz::read(path, "imported")?
    };
    if trajs.is_empty() {
        return Err(Error::file(path, "holds no episodes"));
    }
    let e = Env::new(env)?;
    for (i, t) in trajs.iter().enumerate() {
        if (t.obs_dim, t.act_dim) != (e.obs_dim(), e.act_dim()) {
            return Err(Error::file(
                path,
                format!("has {}-dim observations and {}-dim actions; {env} has {} and {}", t.obs_dim, t.act_dim, e.obs_dim(), e.act_dim()),
            ));
        }
        if t.is_empty() {
            return Err(Error::file(path, format!("episode {i} has no steps")));
        }
        let finite = t.obs.iter().chain(&t.actions).all(|x| x.is_finite()) && t.rewards.iter().all(|x| x.is_finite());
        if !finite {
            return Err(Error::file(path, format!("episode {i} holds a non-finite observation, action or reward")));
        }
    }
    Ok(trajs)
}
