//! Scoring and selection: what a learned reward says of trajectories, which checkpoint a
//! protocol picks, and how true a clone is to its source. Pure functions of their inputs;
//! the `eval` and `multi-bc-rollouts` stages call them, the report and `bench clones` too.
use crate::data::Trajectory;
use crate::nn::RewardEnsemble;
use crate::stats::nan_as_null;

/// What the learned ensemble says of one checkpoint's episodes (means over the episodes).
/// Each member's return is measured in its own units relative to the demonstrations:
/// `z_m = sum_t (r_m(s_t) - mu_m) / sigma_m`, with mu_m and sigma_m the member's per-step
/// mean and std over the demonstrations' steps, so that members (whose scale and offset
/// T-REX leaves free) can be compared.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LearnedScore {
    /// The ensemble mean of each member's summed raw reward.
    pub mean: f64,
    /// min over members of z_m: the most pessimistic member's view.
    pub pessimistic: f64,
    /// std over members of z_m: the members' disagreement.
    pub spread: f64,
}

/// One checkpoint's evaluation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CheckpointEval {
    /// PPO's global step when the checkpoint was taken.
    pub step: usize,
    /// Ground-truth return of each episode.
    pub returns: Vec<f64>,
    pub learned: Option<LearnedScore>,
}

/// Each member's per-step mean and std over a set of trajectories.
pub fn member_stats(model: &RewardEnsemble, trajs: &[Trajectory]) -> Vec<(f64, f64)> {
    let mut sums = vec![(0.0f64, 0.0f64, 0usize); model.nets.len()];
    for t in trajs {
        for (s, r) in sums.iter_mut().zip(model.raw(t.next_obs(), &t.actions)) {
            for x in r {
                s.0 += x as f64;
                s.1 += (x as f64).powi(2);
                s.2 += 1;
            }
        }
    }
    sums.into_iter()
        .map(|(sum, sq, n)| {
            let n = n.max(1) as f64;
            let mean = sum / n;
            (mean, (sq / n - mean * mean).max(0.0).sqrt().max(1e-8))
        })
        .collect()
}

/// What `model` says of `trajs`, members measured against `reference` ([`member_stats`]
/// of the demonstrations).
pub fn learned_score(model: &RewardEnsemble, reference: &[(f64, f64)], trajs: &[Trajectory]) -> LearnedScore {
    let (mut mean, mut pessimistic, mut spread) = (0.0, 0.0, 0.0);
    for t in trajs {
        let raw = model.raw(t.next_obs(), &t.actions);
        let sums: Vec<f64> = raw.iter().map(|r| r.iter().map(|&x| x as f64).sum()).collect();
        let z: Vec<f64> = sums.iter().zip(reference).map(|(s, (mu, sigma))| (s - mu * t.len() as f64) / sigma).collect();
        let zm = z.iter().sum::<f64>() / z.len() as f64;
        mean += sums.iter().sum::<f64>() / sums.len() as f64;
        pessimistic += z.iter().copied().fold(f64::INFINITY, f64::min);
        spread += (z.iter().map(|x| (x - zm).powi(2)).sum::<f64>() / z.len() as f64).sqrt();
    }
    let n = trajs.len().max(1) as f64;
    LearnedScore { mean: mean / n, pessimistic: pessimistic / n, spread: spread / n }
}

/// Each member's per-step standard deviation over the demonstrations: [`per_step_score`]'s
/// units.
pub fn demo_scale(reward: &RewardEnsemble, demos: &[Trajectory]) -> Vec<f64> {
    member_stats(reward, demos).into_iter().map(|(_, sd)| sd).collect()
}

/// How much better, per step and in units of the demonstrations, `trajs` score than
/// `baseline` under `reward`: for each member m, the difference of the mean over episodes of
/// each episode's mean per-step reward, over the member's per-step standard deviation on the
/// demonstrations (`scale`, from [`demo_scale`]); averaged over members. Neither the
/// episodes' lengths nor the members' offsets (which T-REX leaves unidentified) change it,
/// nor the members' scales. Multi-BC's clone filter decides on it.
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

/// The checkpoints a method's runs chose, pooled over the runs (the steps every run has).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Selection {
    /// The highest pooled true return: the paper's protocol.
    pub by_ground_truth: Option<usize>,
    /// The highest pooled pessimistic learned return, where every run has learned scores.
    pub without_ground_truth: Option<usize>,
}

/// Chooses checkpoints from the runs' checkpoint evaluations (one slice per run): the
/// report's protocols and multi-BC's `source: checkpoint` choose with this.
pub fn select(runs: &[&[CheckpointEval]]) -> Selection {
    let mut steps: Vec<usize> = runs.first().map(|r| r.iter().map(|c| c.step).collect()).unwrap_or_default();
    steps.retain(|s| runs.iter().all(|r| r.iter().any(|c| c.step == *s)));
    let at = |r: &[CheckpointEval], s: usize| r.iter().find(|c| c.step == s).cloned().expect("a common step");
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    Selection {
        by_ground_truth: argmax(&steps, |s| Some(mean(&runs.iter().flat_map(|r| at(r, s).returns).collect::<Vec<_>>()))),
        without_ground_truth: argmax(&steps, |s| {
            runs.iter().map(|r| at(r, s).learned.map(|l| l.pessimistic)).collect::<Option<Vec<_>>>().map(|v| mean(&v))
        }),
    }
}

/// The step maximising `score` (the earliest on ties), if any.
fn argmax(steps: &[usize], score: impl Fn(usize) -> Option<f64>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for &s in steps {
        let v = score(s)?;
        if best.is_none_or(|(_, b)| v > b) {
            best = Some((s, v));
        }
    }
    best.map(|(s, _)| s)
}

/// How true a clone is to its source, on the ground truth (recorded for the reader only).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fidelity {
    pub source_lengths: Vec<usize>,
    pub source_returns: Vec<f64>,
    /// The clone's noise-free episodes.
    pub clone_lengths: Vec<usize>,
    pub clone_returns: Vec<f64>,
    /// (clone - random) / (source - random) of the mean returns: 1 is as good as the source,
    /// 0 as the uniform-random policy. Null where the source is within 100 of random.
    #[serde(with = "nan_as_null")]
    pub normalised: f64,
    /// The clone's mean episode length over the source's.
    pub length_ratio: f64,
}

impl Fidelity {
    /// A source at least this far above random has a normalised fidelity.
    pub const MIN_SOURCE_ABOVE_RANDOM: f64 = 100.0;

    pub fn of(source: &[Trajectory], clone: &[Trajectory], random_return: f64) -> Fidelity {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let (source_returns, clone_returns): (Vec<f64>, Vec<f64>) =
            (source.iter().map(Trajectory::ret).collect(), clone.iter().map(Trajectory::ret).collect());
        let (source_lengths, clone_lengths): (Vec<usize>, Vec<usize>) =
            (source.iter().map(Trajectory::len).collect(), clone.iter().map(Trajectory::len).collect());
        let gap = mean(&source_returns) - random_return;
        let normalised = if gap >= Self::MIN_SOURCE_ABOVE_RANDOM { (mean(&clone_returns) - random_return) / gap } else { f64::NAN };
        let lengths = |v: &[usize]| mean(&v.iter().map(|&l| l as f64).collect::<Vec<_>>());
        let length_ratio = lengths(&clone_lengths) / lengths(&source_lengths).max(1.0);
        Fidelity { source_lengths, source_returns, clone_lengths, clone_returns, normalised, length_ratio }
    }
}

/// BC's return far below its demonstrations' (`eval.bc_warning`): D-REX ranks rollouts of BC
/// degraded by noise, so its ranking then holds nothing near the demonstration to extrapolate
/// from. Below means under `fraction` x the demonstrations' average, or under the average
/// itself where that is negative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CloneGap {
    pub bc: f64,
    pub demos: f64,
    pub fraction: f64,
}

/// The threshold `eval.bc_warning` and `idrex report --bc-warning` default to.
pub const BC_WARNING: f64 = 0.7;

impl CloneGap {
    /// The gap, where BC ends below the threshold.
    pub fn check(bc: f64, demos: f64, fraction: f64) -> Option<CloneGap> {
        let floor = if demos >= 0.0 { fraction * demos } else { demos };
        (bc.is_finite() && demos.is_finite() && bc < floor).then_some(CloneGap { bc, demos, fraction })
    }

    /// One sentence for where a user looks first.
    pub fn sentence(&self) -> String {
        let share = if self.demos > 0.0 {
            format!("{:.0} % of it; the warning is below {:.0} %", 100.0 * self.bc / self.demos, 100.0 * self.fraction)
        } else {
            "below it".into()
        };
        format!(
            "BC ends far below its demonstrations: {:.1} against their {:.1} ({share}, `eval.bc_warning`). \
             D-REX's ranking degrades this BC, so it holds nothing near the demonstrations to extrapolate from: expect the \
             learned-reward methods to start from BC's level, not the demonstrator's.",
            self.bc, self.demos
        )
    }
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
        let cfg = RewardConfig {
            obs_dim: 2,
            obs_stride: None,
            obs_offset: None,
            act_dim: None,
            hidden: vec![8],
            models: 3,
            clip: 10.0,
            init: Default::default(),
        };
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

    fn checkpoint(step: usize, ret: f64, pessimistic: Option<f64>) -> CheckpointEval {
        CheckpointEval { step, returns: vec![ret], learned: pessimistic.map(|p| LearnedScore { mean: 0.0, pessimistic: p, spread: 0.0 }) }
    }

    /// The pooled best over the steps every run has, the earliest on ties; no learned choice
    /// when a run lacks learned scores.
    #[test]
    fn select_pools_runs_over_their_common_steps() {
        let a = [checkpoint(0, 1.0, Some(5.0)), checkpoint(10, 3.0, Some(1.0)), checkpoint(20, 9.0, Some(0.0))];
        let b = [checkpoint(0, 1.0, Some(5.0)), checkpoint(10, 3.0, Some(5.0))];
        let s = select(&[&a, &b]);
        // Step 20 is not common; the learned score picks 0 (pooled 5 against 3), the truth 10.
        assert_eq!(s, Selection { by_ground_truth: Some(10), without_ground_truth: Some(0) });
        let tie = [checkpoint(0, 2.0, None), checkpoint(10, 2.0, None)];
        assert_eq!(select(&[&tie]), Selection { by_ground_truth: Some(0), without_ground_truth: None });
        assert_eq!(select(&[]), Selection::default());
    }

    #[test]
    fn fidelity_is_normalised_between_random_and_the_source() {
        let ep = |len: usize, ret: f64| Trajectory {
            obs_dim: 1,
            act_dim: 1,
            obs: vec![0.0; len + 1],
            actions: vec![0.0; len],
            rewards: std::iter::once(ret).chain(std::iter::repeat_n(0.0, len - 1)).collect(),
            terms: vec![Default::default(); len],
            ..Default::default()
        };
        let f = Fidelity::of(&[ep(100, 300.0), ep(100, 500.0)], &[ep(50, 200.0)], 0.0);
        assert_eq!((f.normalised, f.length_ratio), (0.5, 0.5));
        assert!(Fidelity::of(&[ep(10, 50.0)], &[ep(10, 40.0)], 0.0).normalised.is_nan(), "a source near random has none");
    }

    #[test]
    fn a_clone_gap_is_below_the_fraction_or_below_a_negative_average() {
        assert!(CloneGap::check(42.6, 214.1, 0.7).is_some());
        assert!(CloneGap::check(150.0, 214.1, 0.7).is_none(), "150 is 70 % of 214.1");
        assert!(CloneGap::check(-20.0, -10.0, 0.7).is_some(), "a negative average: below it");
        assert!(CloneGap::check(-5.0, -10.0, 0.7).is_none());
        assert!(CloneGap::check(f64::NAN, 100.0, 0.7).is_none(), "nothing measured, nothing said");
        let s = CloneGap::check(42.6, 214.1, 0.7).unwrap().sentence();
        assert!(s.contains("42.6 against their 214.1 (20 % of it; the warning is below 70 %, `eval.bc_warning`)"), "{s}");
        let s = CloneGap::check(-20.0, -10.0, 0.7).unwrap().sentence();
        assert!(s.contains("-20.0 against their -10.0 (below it, `eval.bc_warning`)"), "{s}");
    }
}
