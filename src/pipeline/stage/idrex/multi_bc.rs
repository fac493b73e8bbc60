//! `multi-bc-rollouts`, iD-REX variant 3 (the report's equations 10-11): for each of the
//! previous iteration's policies, episodes of it, a BC clone of them, and epsilon-greedy
//! rollouts of the clone (group = the clone, ranked only within it).
//!
//! Every clone's fidelity is measured and recorded: its source episodes' lengths and true
//! returns, its own noise-free episodes', and BC's losses. The true returns are for the
//! reader only; no decision reads them.
//!
//! The report removed, by hand, clones whose trajectories were worse than the previous
//! iteration's. Here a filter ([`CloneFilter`]) can do it without the ground truth, by the
//! learned reward per step ([`crate::algo::scoring::per_step_score`]), or keep every clone (the original code).
use std::path::Path;

use super::clone::{self, CloneRecord};
use crate::algo::noise;
use crate::algo::scoring::{Fidelity, demo_scale, per_step_score, select};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId, Horizon};
use crate::error::{Error, Result};
use crate::nn::{Device, RewardEnsemble};
use crate::pipeline::config::{CloneConfig, CloneFilter, CloneSource};
use crate::pipeline::stage::{DegradationLevel, Metrics as AnyMetrics, REWARD, StageCtx, Typed, degradation, read_rollouts};
use crate::seed::{self, Purpose};

/// The file that keeps what the ranked set leaves out: every clone's source episodes, its
/// noise-free fidelity episodes, and the rejected clones' rollouts.
pub const CLONES: &str = "clones.mcap";

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub env: EnvId,
    pub clone: CloneConfig,
    pub filter: CloneFilter,
    pub schedule: Vec<f64>,
    pub rollouts_per_level: usize,
    /// Where the rollouts end ([`crate::env::Horizon`]; absent from the key when `task`).
    #[serde(default, skip_serializing_if = "Horizon::is_task")]
    pub horizon: Horizon,
    /// Where the clones train; absent (the CPU) from a CPU stage's parameters and key.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    /// The true return of the uniform-random policy (mean over the fidelity episodes' seeds),
    /// the zero of [`Fidelity::normalised`].
    pub random_return: f64,
    /// The earlier ranked set the filter compared with (0 = D-REX's), when it ran.
    pub baseline_set: Option<usize>,
    pub clones: Vec<CloneRecord>,
    pub degradation: Vec<DegradationLevel>,
}

impl Metrics {
    pub fn kept(&self) -> usize {
        self.clones.iter().filter(|c| c.kept).count()
    }
}

/// The least noisy rollouts of a set.
fn least_noisy(ts: &[Trajectory]) -> Vec<Trajectory> {
    let least = ts.iter().map(|t| t.meta.noise).fold(f64::INFINITY, f64::min);
    ts.iter().filter(|t| t.meta.noise == least).cloned().collect()
}

/// The checkpoint step the ground-truth-free protocol chooses from the source runs'
/// evaluations (the report's rule: the highest pessimistic learned return, pooled over runs).
pub fn chosen_step(evals: &[impl AsRef<Path>]) -> Result<usize> {
    let mut runs = Vec::new();
    for dir in evals {
        let path = dir.as_ref().join(crate::store::MANIFEST);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        match Typed::parse(&path, &text)?.1.metrics {
            AnyMetrics::Eval(e) => runs.push(e.checkpoints),
            _ => return Err(Error::file(&path, "the clone's source input is not an evaluation")),
        }
    }
    let slices: Vec<&[_]> = runs.iter().map(Vec::as_slice).collect();
    select(&slices)
        .without_ground_truth
        .ok_or_else(|| Error::Invalid("multi-BC's source is `checkpoint`, but the source runs have no learned checkpoint scores".into()))
}

crate::stage_inputs! {
    /// Clones of the iteration's policies (`evals[r]`: each run's evaluation, where clones
    /// start from its chosen checkpoint), filtered against the newest earlier ranked set that
    /// kept rollouts (`baselines`), the previous reward (always read: the stage records what
    /// its filter would decide) or the held-out `judge`, in units of the demonstrations.
    MultiBcInputs {
        policies: Many Policy,
        baselines: Many Baseline,
        reward: One Reward,
        demos: One Demos,
        judge: Maybe Judge,
        evals: Many Eval,
    }
}

pub fn run(p: &Params, inputs: &MultiBcInputs<std::path::PathBuf>, ctx: &StageCtx) -> Result<Metrics> {
    let mut env = Env::new(p.env)?;
    // Each reward with its units, measured once on the demonstrations.
    let demos = read_rollouts(&inputs.demos)?;
    let scaled = |r: RewardEnsemble| {
        let scale = demo_scale(&r, &demos);
        (r, scale)
    };
    let previous = scaled(RewardEnsemble::load(&inputs.reward.join(REWARD))?);
    let judge = match p.filter {
        CloneFilter::None | CloneFilter::PreviousReward => None,
        CloneFilter::HeldOutReward => {
            let judge = inputs.judge.as_ref().ok_or_else(|| Error::Invalid("the held-out filter needs the judge input".into()))?;
            Some(scaled(RewardEnsemble::load(&judge.join(REWARD))?))
        }
    };
    // The newest earlier set with rollouts (an earlier multi-BC set may have kept none).
    let mut baseline = None;
    for (i, dir) in inputs.baselines.iter().enumerate() {
        let set = read_rollouts(dir)?;
        if !set.is_empty() {
            baseline = Some((i, least_noisy(&set)));
        }
    }
    let source_step = match p.clone.source {
        CloneSource::Final => None,
        CloneSource::Checkpoint => Some(chosen_step(&inputs.evals)?),
    };
    let random_return = clone::random_return(&mut env, p.clone.fidelity_episodes, ctx.seed);
    let (mut kept, mut extra, mut clones) = (Vec::new(), Vec::new(), Vec::new());
    for (r, dir) in inputs.policies.iter().enumerate() {
        ctx.progress.set_message(format!("clone {}", r + 1));
        let made = clone::make(&mut env, dir, source_step, &p.clone, p.env, ctx.seed, r, ctx.threads, p.device)?;
        let meta = TrajMeta { source: format!("multi-bc/{r}"), group: r, ..Default::default() };
        let seed = seed::derive(ctx.seed, Purpose::CloneRollouts, r as u64);
        // The ranked rollouts end where `horizon` says; the clones' fidelity episodes where the task does.
        env.set_horizon(p.horizon);
        let trajs = noise::epsilon_greedy(&mut env, &made.policy, &p.schedule, p.rollouts_per_level, seed, &meta);
        env.set_horizon(Horizon::Task);
        let score_under = |(reward, scale): &(RewardEnsemble, Vec<f64>)| {
            baseline.as_ref().map(|(_, base)| per_step_score(reward, scale, &made.fidelity_episodes, base))
        };
        let previous_reward_score = score_under(&previous);
        let score = match p.filter {
            CloneFilter::None => None,
            CloneFilter::PreviousReward => previous_reward_score,
            CloneFilter::HeldOutReward => judge.as_ref().and_then(score_under),
        };
        let keep = score.is_none_or(|s| s >= 0.0);
        clones.push(CloneRecord {
            clone: r,
            fidelity: Fidelity::of(&made.source_episodes, &made.fidelity_episodes, random_return),
            source_step: made.source_step,
            bc: made.report,
            score,
            previous_reward_score,
            kept: keep,
        });
        extra.extend(made.source_episodes);
        extra.extend(made.fidelity_episodes);
        if keep { kept.extend(trajs) } else { extra.extend(trajs) }
    }
    ctx.write_rollouts(p.env, &kept, None)?;
    crate::rollout::mcap::write(&ctx.out.join(CLONES), p.env.name(), env.dt(), &extra, None)?;
    let baseline_set = baseline.filter(|_| p.filter != CloneFilter::None).map(|(i, _)| i);
    Ok(Metrics { random_return, baseline_set, clones, degradation: degradation(&kept) })
}
