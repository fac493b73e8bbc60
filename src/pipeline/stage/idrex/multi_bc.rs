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
//! learned reward per step ([`per_step_score`]), or keep every clone (the original code).
use std::path::Path;

use super::clone::{self, CloneRecord, Fidelity};
use crate::algo::noise;
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
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

/// How much better, per step and in units of the demonstrations, `trajs` score than
/// `baseline` under `reward`: for each member m, the difference of the mean over episodes of
/// each episode's mean per-step reward, over the member's per-step standard deviation on the
/// demonstrations; averaged over members. Neither the episodes' lengths nor the members'
/// offsets (which T-REX leaves unidentified) change it, nor the members' scales.
/// Each member's per-step standard deviation over the demonstrations: the score's units.
pub fn demo_scale(reward: &RewardEnsemble, demos: &[Trajectory]) -> Vec<f64> {
    crate::pipeline::stage::eval::member_stats(reward, demos).into_iter().map(|(_, sd)| sd).collect()
}

/// (`scale`: [`demo_scale`].)
pub fn per_step_score(reward: &RewardEnsemble, scale: &[f64], trajs: &[Trajectory], baseline: &[Trajectory]) -> f64 {
    let members = reward.nets.len();
    // Each member's per-step mean of each episode, averaged over episodes.
    let level = |ts: &[Trajectory]| {
        let mut sums = vec![0.0f64; members];
        for t in ts.iter().filter(|t| !t.is_empty()) {
            for (s, r) in sums.iter_mut().zip(reward.raw(t.next_obs(), &t.actions)) {
                *s += r.iter().map(|&x| x as f64).sum::<f64>() / r.len() as f64;
            }
        }
        let n = ts.iter().filter(|t| !t.is_empty()).count().max(1) as f64;
        sums.into_iter().map(|s| s / n).collect::<Vec<_>>()
    };
    let (a, b) = (level(trajs), level(baseline));
    (0..members).map(|m| (a[m] - b[m]) / scale[m]).sum::<f64>() / members as f64
}

/// The least noisy rollouts of a set.
fn least_noisy(ts: &[Trajectory]) -> Vec<Trajectory> {
    let least = ts.iter().map(|t| t.meta.noise).fold(f64::INFINITY, f64::min);
    ts.iter().filter(|t| t.meta.noise == least).cloned().collect()
}

/// The checkpoint step the ground-truth-free protocol chooses from the source runs'
/// evaluations (the report's rule: the highest pessimistic learned return, pooled over runs).
pub fn chosen_step(evals: &[&Path]) -> Result<usize> {
    let mut runs = Vec::new();
    for dir in evals {
        let path = dir.join(crate::store::MANIFEST);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let m: crate::store::Manifest = serde_json::from_str(&text).map_err(|e| Error::file(&path, e.to_string()))?;
        match Typed::of(&m)?.metrics {
            AnyMetrics::Eval(e) => runs.push(e.checkpoints),
            _ => return Err(Error::file(&path, "the clone's source input is not an evaluation")),
        }
    }
    let slices: Vec<&[_]> = runs.iter().map(Vec::as_slice).collect();
    crate::pipeline::stage::eval::select(&slices)
        .without_ground_truth
        .ok_or_else(|| Error::Invalid("multi-BC's source is `checkpoint`, but the source runs have no learned checkpoint scores".into()))
}

pub fn run(p: &Params, ctx: &StageCtx) -> Result<Metrics> {
    let mut env = Env::new(p.env)?;
    // Each reward with its units, measured once on the demonstrations.
    let demos = read_rollouts(ctx.input("demos")?)?;
    let scaled = |r: RewardEnsemble| {
        let scale = demo_scale(&r, &demos);
        (r, scale)
    };
    let previous = scaled(RewardEnsemble::load(&ctx.input("reward")?.join(REWARD))?);
    let judge = match p.filter {
        CloneFilter::None | CloneFilter::PreviousReward => None,
        CloneFilter::HeldOutReward => Some(scaled(RewardEnsemble::load(&ctx.input("judge")?.join(REWARD))?)),
    };
    // The newest earlier set with rollouts (an earlier multi-BC set may have kept none).
    let mut baseline = None;
    for (i, dir) in ctx.numbered("baseline").into_iter().enumerate() {
        let set = read_rollouts(dir)?;
        if !set.is_empty() {
            baseline = Some((i, least_noisy(&set)));
        }
    }
    let source_step = match p.clone.source {
        CloneSource::Final => None,
        CloneSource::Checkpoint => Some(chosen_step(&ctx.numbered("eval"))?),
    };
    let random_return = clone::random_return(&mut env, p.clone.fidelity_episodes, ctx.seed);
    let (mut kept, mut extra, mut clones) = (Vec::new(), Vec::new(), Vec::new());
    for (r, dir) in ctx.numbered("policy").into_iter().enumerate() {
        ctx.progress.set_message(format!("clone {}", r + 1));
        let made = clone::make(&mut env, dir, source_step, &p.clone, p.env, ctx.seed, r, ctx.threads, p.device)?;
        let meta = TrajMeta { source: format!("multi-bc/{r}"), group: r, ..Default::default() };
        let seed = seed::derive(ctx.seed, Purpose::CloneRollouts, r as u64);
        let trajs = noise::epsilon_greedy(&mut env, &made.policy, &p.schedule, p.rollouts_per_level, seed, &meta);
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
    crate::log::mcap::write(&ctx.out.join(CLONES), p.env.name(), env.dt(), &extra, None)?;
    let baseline_set = baseline.filter(|_| p.filter != CloneFilter::None).map(|(i, _)| i);
    Ok(Metrics { random_return, baseline_set, clones, degradation: degradation(&kept) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::RewardConfig;

    /// A trajectory of `len` steps whose observations are all `x`.
    fn constant(len: usize, x: f32) -> Trajectory {
        let (od, ad) = (2, 1);
        Trajectory {
            obs_dim: od,
            act_dim: ad,
            obs: vec![x; (len + 1) * od],
            actions: vec![0.0; len * ad],
            rewards: vec![0.0; len],
            terms: vec![Default::default(); len],
            ..Default::default()
        }
    }

    /// The score compares rewards per step: an episode twice as long at the same per-step
    /// reward scores the same, and shifting every member's output by a constant changes
    /// nothing (while the summed return, the old filter's score, depends on both).
    #[test]
    fn per_step_score_ignores_length_and_offset() {
        let cfg = RewardConfig { obs_dim: 2, act_dim: None, hidden: vec![8], models: 3, clip: 10.0, init: Default::default() };
        let reward = crate::nn::seeded(3, || RewardEnsemble::new(cfg.clone()));
        let demos = vec![constant(50, 0.3), constant(30, -0.2)];
        let good = |x: f32| reward.raw(constant(1, x).next_obs(), &[0.0]).iter().map(|m| m[0] as f64).sum::<f64>();
        // Two observation levels; `hi` is the one the ensemble prefers.
        let (hi, lo) = if good(1.0) > good(-1.0) { (1.0, -1.0) } else { (-1.0, 1.0) };
        let short_high = vec![constant(20, hi)];
        let long_high = vec![constant(400, hi)];
        let base = vec![constant(100, lo)];
        let a = per_step_score(&reward, &demo_scale(&reward, &demos), &short_high, &base);
        let b = per_step_score(&reward, &demo_scale(&reward, &demos), &long_high, &base);
        assert!(a > 0.0, "{a}");
        assert!((a - b).abs() < 1e-9 * a.abs(), "{a} vs {b}");
        // The same ensemble with every output shifted by +5 (the last layer's bias).
        let shifted = crate::nn::seeded(3, || RewardEnsemble::new(cfg.clone()));
        tch::no_grad(|| {
            for net in &shifted.nets {
                let (_, b) = net.parameters().last().expect("a layer");
                let _ = b.shallow_clone().g_add_scalar_(5.0);
            }
        });
        let c = per_step_score(&shifted, &demo_scale(&shifted, &demos), &short_high, &base);
        assert!((a - c).abs() < 1e-4 * a.abs(), "{a} vs {c}");
        // Teeth: the summed predicted return of the short episode falls below the long
        // baseline's once the offset is added, though its per-step reward is higher.
        let summed = |m: &RewardEnsemble, t: &Trajectory| m.predicted_return(t.next_obs(), &t.actions);
        assert!(summed(&shifted, &short_high[0]) < summed(&shifted, &base[0]));
        // And it is symmetric: the baseline against the clone scores minus as much.
        let d = per_step_score(&reward, &demo_scale(&reward, &demos), &base, &short_high);
        assert!((a + d).abs() < 1e-9 * a.abs());
    }
}
