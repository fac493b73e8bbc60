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
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_of_one_stage_do_not_collide() {
        let mut seen = std::collections::BTreeSet::new();
        for purpose in [
            Purpose::Episode,
            Purpose::EvalEpisode,
            Purpose::CloneDemo,
            Purpose::CloneRollouts,
            Purpose::CloneFidelity,
            Purpose::RandomBaseline,
            Purpose::TrexModel,
        ] {
            for k in 0..200 {
                assert!(seen.insert(derive(7, purpose, k)), "{purpose:?} {k}");
            }
        }
    }
}
