//! One multi-BC clone: episodes of a source policy, behavioural cloning on them, and how
//! true the clone is to its source (its [`Fidelity`], measured on the ground truth for the
//! reader; nothing decides on it).
use std::path::Path;

use crate::algo::bc::{self, BcReport};
use crate::algo::ppo;
use crate::algo::scoring::Fidelity;
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::{Error, Result};
use crate::nn::{ActorCritic, Device};
use crate::pipeline::config::{CloneConfig, CloneLabels, SourceActing};
use crate::pipeline::stage::load_policy_for;
use crate::rollout::{self, Actor, PolicyActor, UniformActor};
use crate::seed::{self, Purpose};

/// One clone's record in the stage's metrics.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CloneRecord {
    pub clone: usize,
    /// The source checkpoint's PPO step; None for the final policy.
    pub source_step: Option<usize>,
    pub fidelity: Fidelity,
    pub bc: BcReport,
    /// The filter's per-step score against the baseline (None without a filter).
    pub score: Option<f64>,
    /// The same score under the previous iteration's reward, whichever filter ran: what the
    /// `previous-reward` filter would have decided on (for comparing the rules).
    #[serde(default)]
    pub previous_reward_score: Option<f64>,
    pub kept: bool,
}

/// A trained clone with the episodes it came from and was measured on.
pub struct Made {
    pub policy: ActorCritic,
    pub source_episodes: Vec<Trajectory>,
    pub fidelity_episodes: Vec<Trajectory>,
    pub report: BcReport,
    pub source_step: Option<usize>,
}

/// The mean true return of the uniform-random policy over `episodes` episodes.
pub fn random_return(env: &mut Env, episodes: usize, seed: u64) -> f64 {
    let mut actor = UniformActor::of(env);
    let ts = rollout::episodes(env, &mut actor, episodes, seed, Purpose::RandomBaseline, &TrajMeta::default());
    ts.iter().map(Trajectory::ret).sum::<f64>() / ts.len().max(1) as f64
}

/// The source policy in a PPO run's directory: its final policy, or the checkpoint at `step`.
fn source_policy(dir: &Path, step: Option<usize>, env: &Env, id: EnvId) -> Result<ActorCritic> {
    let Some(step) = step else { return load_policy_for(dir, env, id) };
    let found = ppo::checkpoints(dir)?.into_iter().find(|(s, _)| *s == step);
    let (_, at) = found.ok_or_else(|| Error::file(dir, format!("no checkpoint at step {step}")))?;
    let p = ActorCritic::load(&at)?;
    p.expect_dims(env.obs_dim(), env.act_dim(), id.name())?;
    Ok(p)
}

/// `t` with every action replaced by `policy`'s mean action at that state, clipped to the box.
fn mean_labelled(t: &Trajectory, policy: &ActorCritic, env: &Env) -> Trajectory {
    let mut actor = PolicyActor::mean_of(policy);
    let (low, high) = env.action_bounds();
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
    let mut out = t.clone();
    for s in 0..t.len() {
        let a = &mut out.actions[s * t.act_dim..(s + 1) * t.act_dim];
        actor.act(t.obs_row(s), &mut rng, a);
        for (i, x) in a.iter_mut().enumerate() {
            *x = (*x as f64).clamp(low[i], high[i]) as f32;
        }
    }
    out
}

/// `t`'s observations as `policy`'s networks see them.
fn normalised(t: &Trajectory, policy: &ActorCritic) -> Trajectory {
    let cpu = policy.to_cpu();
    let mut out = t.clone();
    for (row, raw) in out.obs.chunks_exact_mut(t.obs_dim).zip(t.obs.chunks_exact(t.obs_dim)) {
        cpu.normalize(raw, row);
    }
    out
}

/// Clone `r` of the run in `dir` (the stage seed `seed`).
#[allow(clippy::too_many_arguments)]
pub fn make(
    env: &mut Env,
    dir: &Path,
    step: Option<usize>,
    cfg: &CloneConfig,
    id: EnvId,
    seed: u64,
    r: usize,
    threads: usize,
    device: Device,
) -> Result<Made> {
    let source = source_policy(dir, step, env, id)?;
    let stochastic = cfg.acting == SourceActing::Stochastic;
    let mut actor = PolicyActor::new(source.to_cpu(), stochastic);
    let meta = TrajMeta { source: format!("multi-bc/{r}/source"), group: r, ..Default::default() };
    let first = (r * CloneConfig::MAX_EPISODES) as u64;
    let source_episodes: Vec<Trajectory> = (0..(cfg.episodes + cfg.held_out_episodes) as u64)
        .map(|k| rollout::episode(env, &mut actor, seed::derive(seed, Purpose::CloneDemo, first + k), meta.clone()))
        .collect();
    let labelled: Vec<Trajectory> = source_episodes
        .iter()
        .map(|t| {
            let t = if cfg.labels == CloneLabels::Mean { mean_labelled(t, &source, env) } else { t.clone() };
            if cfg.normalize { normalised(&t, &source) } else { t }
        })
        .collect();
    let (train, held_out) = labelled.split_at(cfg.episodes);
    let held_out = (!held_out.is_empty()).then_some(held_out);
    let (mut policy, report) =
        bc::train_validated(train, held_out, &cfg.bc, seed::derive(seed, Purpose::CloneTraining, r as u64), threads, device)?;
    if cfg.normalize {
        policy.obs_norm = source.obs_norm.clone();
        policy.obs_clip = source.obs_clip;
    }
    let meta = TrajMeta { source: format!("multi-bc/{r}/clone"), group: r, ..Default::default() };
    let mut clone_actor = PolicyActor::mean_of(&policy);
    let fidelity_seed = seed::derive(seed, Purpose::CloneFidelity, r as u64);
    let fidelity_episodes = rollout::episodes(env, &mut clone_actor, cfg.fidelity_episodes, fidelity_seed, Purpose::Episode, &meta);
    Ok(Made { policy, source_episodes, fidelity_episodes, report, source_step: step })
}
