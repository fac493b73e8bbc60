//! `multi-bc-rollouts`, iD-REX variant 3 (the report's equations 10-11): for each of the
//! previous iteration's policies, one trajectory, a BC clone of it, and epsilon-greedy
//! rollouts of the clone (group = the clone, ranked only within it).
//!
//! The report removed, by hand, clones whose trajectories were worse than the previous
//! iteration's. Here a clone is kept only if its noise-free rollouts score at least as high
//! under the previous learned reward as the previous set's noise-free rollouts: the ground
//! truth is never consulted.
use crate::algo::bc::{self, BcConfig};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::Result;
use crate::nn::{Device, RewardEnsemble};
use crate::pipeline::stage::{DegradationLevel, REWARD, StageCtx, degradation, load_policy_for, read_rollouts};
use crate::rollout::{self, PolicyActor};
use crate::seed::{self, Purpose};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub env: EnvId,
    pub bc: BcConfig,
    pub schedule: Vec<f64>,
    pub rollouts_per_level: usize,
    /// Where the clones train; absent (the CPU) from a CPU stage's parameters and key.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

/// The filter's decision on one clone.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CloneDecision {
    pub clone: usize,
    pub predicted_clean_return: f64,
    pub kept: bool,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    pub threshold: f64,
    pub clones: Vec<CloneDecision>,
    pub degradation: Vec<DegradationLevel>,
}

pub fn run(p: &Params, ctx: &StageCtx) -> Result<Metrics> {
    let reward = RewardEnsemble::load(&ctx.input("reward")?.join(REWARD))?;
    // The mean predicted return of a set's least noisy rollouts.
    let clean_score = |ts: &[Trajectory]| {
        let least = ts.iter().map(|t| t.meta.noise).fold(f64::INFINITY, f64::min);
        let scores: Vec<f64> =
            ts.iter().filter(|t| t.meta.noise == least).map(|t| reward.predicted_return(t.next_obs(), &t.actions)).collect();
        scores.iter().sum::<f64>() / scores.len().max(1) as f64
    };
    let threshold = clean_score(&read_rollouts(ctx.input("baseline")?)?);
    let mut env = Env::new(p.env)?;
    let mut kept = Vec::new();
    let mut clones = Vec::new();
    for (r, dir) in ctx.numbered("policy").into_iter().enumerate() {
        let policy = load_policy_for(dir, &env, p.env)?;
        let r64 = r as u64;
        let demo = rollout::episode(
            &mut env,
            &mut PolicyActor::acting(&policy),
            seed::derive(ctx.seed, Purpose::CloneDemo, r64),
            TrajMeta { source: format!("multi-bc/{r}/demo"), ..Default::default() },
        );
        let (clone, _) =
            bc::train(std::slice::from_ref(&demo), &p.bc, seed::derive(ctx.seed, Purpose::CloneTraining, r64), ctx.threads, p.device)?;
        let meta = TrajMeta { source: format!("multi-bc/{r}"), group: r, ..Default::default() };
        let seed = seed::derive(ctx.seed, Purpose::CloneRollouts, r64);
        let trajs = rollout::epsilon_greedy(&mut env, &clone, &p.schedule, p.rollouts_per_level, seed, &meta);
        let score = clean_score(&trajs);
        let keep = score >= threshold;
        clones.push(CloneDecision { clone: r, predicted_clean_return: score, kept: keep });
        if keep {
            kept.extend(trajs);
        }
    }
    ctx.write_rollouts(p.env, &kept, None)?;
    Ok(Metrics { threshold, clones, degradation: degradation(&kept) })
}
