//! Every random stream idrex draws is derived here, from a stage's seed, what the stream is
//! for and an index. One place, so that two streams can never collide by accident and a
//! reader can see at a glance which randomness a result depends on.
//!
//! The formulas are those the stages used before they were gathered here, so stored results
//! keep their random streams.

/// What a derived seed is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Purpose {
    /// The k-th episode of a rollout set: its reset and, through [`Purpose::ActorNoise`],
    /// its actor's randomness.
    Episode,
    /// The k-th evaluation episode of a policy (disjoint from its training-set episodes).
    EvalEpisode,
    /// The rollout set of the r-th source policy within one stage (iD-REX's per-policy sets).
    Source,
    /// Multi-BC: the trajectory the r-th clone is cloned from.
    CloneDemo,
    /// Multi-BC: training the r-th clone.
    CloneTraining,
    /// Multi-BC: the r-th clone's epsilon-greedy rollouts.
    CloneRollouts,
    /// Multi-BC: the r-th clone's noise-free fidelity episodes.
    CloneFidelity,
    /// The k-th episode of the uniform-random policy a stage measures as its zero.
    RandomBaseline,

    /// T-REX: model m's pairs and minibatches.
    TrexModel,
    /// PPO: the evaluation after update u (its episodes are `seed + k`).
    PpoEval,
    /// The actor's generator within an episode, from the episode's seed (index unused).
    ActorNoise,
    /// `noise.toward: both`: the seed of the zero-action set beside the random-action one.
    ZeroActionSet,
    /// `noise.still`: the k-th episode of the zero action ranked below every noise level.
    StillSet,
    /// `noise.disturbance: weights`: the k-th level's perturbation of BC's weights.
    WeightNoise,
    /// The reward bench's probe: the k-th episode of its final policy (apart from the
    /// evaluation's, which score the method's own runs on the same seed).
    ProbeEpisode,
}

/// The seed of stream `index` for `purpose`, from the stage seed `seed`.
pub fn derive(seed: u64, purpose: Purpose, index: u64) -> u64 {
    let episode = |s: u64, k: u64| s.wrapping_mul(1_000_003).wrapping_add(k);
    match purpose {
        Purpose::Episode | Purpose::Source => episode(seed, index),
        Purpose::EvalEpisode => episode(seed ^ 0xe7a1, index),
        Purpose::CloneDemo => episode(seed, 10_000 + index),
        Purpose::CloneTraining => episode(seed, index),
        Purpose::CloneRollouts => episode(seed, 20_000 + index),
        Purpose::CloneFidelity => episode(seed, 30_000 + index),
        Purpose::RandomBaseline => episode(seed, 40_000 + index),
        Purpose::TrexModel => seed.wrapping_mul(1000).wrapping_add(index),
        Purpose::PpoEval => seed.wrapping_add(1_000_000 + index),
        Purpose::ActorNoise => seed ^ 0x9e37_79b9_7f4a_7c15,
        Purpose::ZeroActionSet => episode(seed ^ 0x2e70, index),
        Purpose::StillSet => episode(seed ^ 0x5711, index),
        Purpose::WeightNoise => episode(seed ^ 0x3e16, index),
        Purpose::ProbeEpisode => episode(seed ^ 0x960b, index),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::{BTreeMap, BTreeSet};

    /// Every purpose, in declaration order. `position` below is an exhaustive match, so a new
    /// variant does not compile until it has a position there; list it here too (nothing
    /// fails where it is missing: the tests then leave it out).
    const ALL: [Purpose; 15] = [
        Purpose::Episode,
        Purpose::EvalEpisode,
        Purpose::Source,
        Purpose::CloneDemo,
        Purpose::CloneTraining,
        Purpose::CloneRollouts,
        Purpose::CloneFidelity,
        Purpose::RandomBaseline,
        Purpose::TrexModel,
        Purpose::PpoEval,
        Purpose::ActorNoise,
        Purpose::ZeroActionSet,
        Purpose::StillSet,
        Purpose::WeightNoise,
        Purpose::ProbeEpisode,
    ];

    fn position(p: Purpose) -> usize {
        match p {
            Purpose::Episode => 0,
            Purpose::EvalEpisode => 1,
            Purpose::Source => 2,
            Purpose::CloneDemo => 3,
            Purpose::CloneTraining => 4,
            Purpose::CloneRollouts => 5,
            Purpose::CloneFidelity => 6,
            Purpose::RandomBaseline => 7,
            Purpose::TrexModel => 8,
            Purpose::PpoEval => 9,
            Purpose::ActorNoise => 10,
            Purpose::ZeroActionSet => 11,
            Purpose::StillSet => 12,
            Purpose::WeightNoise => 13,
            Purpose::ProbeEpisode => 14,
        }
    }

    /// Purposes whose streams meet, kept because stored results depend on their formulas,
    /// and why no stage draws both from one seed:
    /// - `Source` and `Episode` (the same formula): the stages that derive per-source seeds
    ///   (interpolation, action noise) draw episodes only from those derived seeds.
    /// - `CloneTraining` and `Episode`, `Source` (the same formula): a clone's seed feeds its
    ///   BC training; its episodes come from `CloneDemo`, `CloneFidelity` and `RandomBaseline`.
    /// - `TrexModel` and `Episode`, `Source`, `CloneTraining` (at stage seed 0 only, where
    ///   both are the index): the T-REX stage draws nothing else.
    const MEET: [(Purpose, Purpose); 6] = [
        (Purpose::Episode, Purpose::Source),
        (Purpose::Episode, Purpose::CloneTraining),
        (Purpose::Source, Purpose::CloneTraining),
        (Purpose::Episode, Purpose::TrexModel),
        (Purpose::Source, Purpose::TrexModel),
        (Purpose::CloneTraining, Purpose::TrexModel),
    ];

    #[test]
    fn the_list_holds_every_purpose() {
        for (i, p) in ALL.iter().enumerate() {
            assert_eq!(position(*p), i, "{p:?}");
        }
    }

    /// Over 200 indices (one for `ActorNoise`, which ignores its index) and several stage
    /// seeds, two purposes' streams meet exactly where `MEET` says, and no purpose repeats a
    /// seed of its own.
    #[test]
    fn streams_of_one_stage_meet_only_where_declared() {
        let mut met: BTreeSet<(usize, usize)> = BTreeSet::new();
        for seed in [0, 7, 123_456_789, u64::MAX - 3] {
            let mut seen: BTreeMap<u64, Vec<Purpose>> = BTreeMap::new();
            for purpose in ALL {
                let n = if purpose == Purpose::ActorNoise { 1 } else { 200 };
                let mut own = BTreeSet::new();
                for k in 0..n {
                    let s = derive(seed, purpose, k);
                    assert!(own.insert(s), "{purpose:?} repeats seed {s} at index {k} (stage seed {seed})");
                    let before = seen.entry(s).or_default();
                    for other in before.iter() {
                        let (a, b) = (position(*other), position(purpose));
                        met.insert((a.min(b), a.max(b)));
                    }
                    before.push(purpose);
                }
            }
        }
        let declared: BTreeSet<(usize, usize)> = MEET.iter().map(|&(a, b)| (position(a), position(b))).collect();
        let name = |set: &BTreeSet<(usize, usize)>| set.iter().map(|&(a, b)| format!("{:?}/{:?}", ALL[a], ALL[b])).collect::<Vec<_>>();
        assert_eq!(name(&met), name(&declared), "purposes whose streams meet");
    }
}
