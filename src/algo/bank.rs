//! The reward bench: a bank of gaits no ranked set contains, each with its true return, and
//! the scores of a learned reward on it. A reward that keys on what epsilon-greedy noise
//! looks like (jitter, posture) instead of progress shows it here, before PPO climbs it: it
//! orders the forward gaits by how calm they are rather than how fast, and pays a backward,
//! standing or flailing trajectory more than a forward gait the true reward ranks above it.
use crate::stats::{pearson, spearman};

/// How a bank trajectory's policy was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GaitClass {
    /// A checkpoint of PPO on the task's reward: slow to fast.
    Forward,
    /// A checkpoint of PPO on the task's reward with its forward term negated.
    Backward,
    /// The zero action: standing, or on a task that ends, slumping until it falls.
    Still,
    /// Uniform random actions: flailing, and falling where the task can end.
    Random,
}

impl GaitClass {
    pub const ALL: [GaitClass; 4] = [GaitClass::Forward, GaitClass::Backward, GaitClass::Still, GaitClass::Random];

    pub fn name(self) -> &'static str {
        match self {
            GaitClass::Forward => "forward",
            GaitClass::Backward => "backward",
            GaitClass::Still => "still",
            GaitClass::Random => "random",
        }
    }

    pub fn parse(name: &str) -> Option<GaitClass> {
        GaitClass::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// What was done to a checkpoint's actions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Disturbance {
    /// The policy's own sampled actions.
    None,
    /// Epsilon-greedy uniform random actions, D-REX's noise: jerky.
    Epsilon,
    /// Ornstein-Uhlenbeck noise on the mean action: smooth, temporally correlated.
    Smooth,
    /// No noise at all: the checkpoint's mean action, its calmest version.
    MeanAction,
}

impl Disturbance {
    pub fn name(self) -> &'static str {
        match self {
            Disturbance::None => "none",
            Disturbance::Epsilon => "epsilon",
            Disturbance::Smooth => "smooth",
            Disturbance::MeanAction => "mean-action",
        }
    }
}

/// One trajectory of the bank, in the order of its rollout file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BankEntry {
    pub class: GaitClass,
    pub disturbance: Disturbance,
    /// Epsilon, or the noise's sigma; 0 undisturbed.
    pub level: f64,
    /// The PPO step of the checkpoint (0 for the still and random classes).
    pub checkpoint: usize,
    /// True return, its forward term, and the episode's length.
    pub ret: f64,
    pub forward: f64,
    pub length: usize,
    /// Ended by the task (fell) before the time limit.
    pub terminated: bool,
}

/// What a learned reward pays one class, on average.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClassPay {
    pub class: GaitClass,
    pub trajectories: usize,
    /// Learned and true reward per step.
    pub learned_per_step: f64,
    pub true_per_step: f64,
}

/// A learned reward's scores on a bank ([`score`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BankScore {
    pub trajectories: usize,
    /// Learned against true return over the whole bank.
    pub pearson: f64,
    pub spearman: f64,
    /// The same within the forward gaits (every checkpoint, disturbed or not): does it order
    /// speed?
    pub forward_pearson: f64,
    pub forward_spearman: f64,
    /// Backward, still and random trajectories the reward pays more than an undisturbed
    /// forward gait the true reward ranks above them (where every forward gait is truly better,
    /// the slowest), per class in [`GaitClass::ALL`]'s order (forward's count is always 0).
    pub overpaid: Vec<usize>,
    /// Of the (non-forward, undisturbed forward) pairs the true return orders, the fraction
    /// the learned return orders the other way.
    pub misordered: f64,
    pub per_class: Vec<ClassPay>,
}

impl BankScore {
    /// Whether it pays any backward, still or random trajectory more than a truly better
    /// forward gait.
    pub fn pays_a_wrong_gait(&self) -> bool {
        self.overpaid.iter().any(|&n| n > 0)
    }

    /// Overpaid trajectories of `class`.
    pub fn overpaid_of(&self, class: GaitClass) -> usize {
        GaitClass::ALL.iter().position(|&c| c == class).and_then(|i| self.overpaid.get(i).copied()).unwrap_or(0)
    }
}

/// Scores `learned` (each bank trajectory's learned return, in `entries`' order).
pub fn score(entries: &[BankEntry], learned: &[f64]) -> BankScore {
    assert_eq!(entries.len(), learned.len(), "one learned return per bank trajectory");
    let truth: Vec<f64> = entries.iter().map(|e| e.ret).collect();
    let forward: Vec<usize> = (0..entries.len()).filter(|&i| entries[i].class == GaitClass::Forward).collect();
    let pick = |idx: &[usize], v: &[f64]| idx.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let (fl, ft) = (pick(&forward, learned), pick(&forward, &truth));
    let clean: Vec<usize> = forward.iter().copied().filter(|&i| entries[i].disturbance == Disturbance::None).collect();
    let mut overpaid = vec![0; GaitClass::ALL.len()];
    let (mut pairs, mut wrong) = (0usize, 0usize);
    for (b, e) in entries.iter().enumerate().filter(|(_, e)| e.class != GaitClass::Forward) {
        let better: Vec<usize> = clean.iter().copied().filter(|&f| truth[f] > truth[b]).collect();
        let under = better.iter().filter(|&&f| learned[f] < learned[b]).count();
        pairs += better.len();
        wrong += under;
        if under > 0 {
            overpaid[GaitClass::ALL.iter().position(|&c| c == e.class).expect("a class")] += 1;
        }
    }
    let per_class = GaitClass::ALL
        .into_iter()
        .filter_map(|class| {
            let idx: Vec<usize> = (0..entries.len()).filter(|&i| entries[i].class == class).collect();
            let steps = idx.iter().map(|&i| entries[i].length).sum::<usize>().max(1) as f64;
            (!idx.is_empty()).then(|| ClassPay {
                class,
                trajectories: idx.len(),
                learned_per_step: idx.iter().map(|&i| learned[i]).sum::<f64>() / steps,
                true_per_step: idx.iter().map(|&i| truth[i]).sum::<f64>() / steps,
            })
        })
        .collect();
    BankScore {
        trajectories: entries.len(),
        pearson: pearson(learned, &truth),
        spearman: spearman(learned, &truth),
        forward_pearson: pearson(&fl, &ft),
        forward_spearman: spearman(&fl, &ft),
        overpaid,
        misordered: if pairs == 0 { f64::NAN } else { wrong as f64 / pairs as f64 },
        per_class,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(class: GaitClass, disturbance: Disturbance, ret: f64) -> BankEntry {
        BankEntry { class, disturbance, level: 0.0, checkpoint: 0, ret, forward: ret, length: 1000, terminated: false }
    }

    /// Forward gaits at 100..500, a backward one at -200, standing at 0, a jerky fast one.
    fn bank() -> Vec<BankEntry> {
        use Disturbance::*;
        use GaitClass::*;
        let mut out: Vec<BankEntry> = (1..=5).map(|k| entry(Forward, None, 100.0 * k as f64)).collect();
        out.push(entry(Forward, Epsilon, 350.0));
        out.extend([entry(Backward, None, -200.0), entry(Still, None, 0.0), entry(Random, None, -300.0)]);
        out
    }

    #[test]
    fn the_truth_scores_perfectly_and_its_opposite_is_caught() {
        let b = bank();
        let truth: Vec<f64> = b.iter().map(|e| e.ret).collect();
        let s = score(&b, &truth);
        assert!((s.pearson - 1.0).abs() < 1e-12 && (s.forward_spearman - 1.0).abs() < 1e-12);
        assert!(!s.pays_a_wrong_gait() && s.misordered == 0.0, "{s:?}");
        // A reward that pays calm: the backward and still gaits above the slow forward ones,
        // and the jerky fast gait lowest.
        let calm: Vec<f64> = b.iter().map(|e| if e.disturbance == Disturbance::Epsilon { -1.0 } else { 300.0 - e.ret.abs() }).collect();
        let s = score(&b, &calm);
        assert!(s.forward_spearman < 0.0, "{s:?}");
        assert!(s.pays_a_wrong_gait() && s.overpaid_of(GaitClass::Still) == 1 && s.overpaid_of(GaitClass::Backward) == 1);
        assert!(s.misordered > 0.5, "{s:?}");
        assert_eq!(s.per_class.iter().map(|c| c.trajectories).sum::<usize>(), b.len());
    }

    /// A trajectory the truth ranks above every forward gait (a long-lived still Hopper above
    /// one that falls at once) is no fault of the reward's for being paid more.
    #[test]
    fn only_truly_better_forward_gaits_count() {
        let mut b = vec![entry(GaitClass::Forward, Disturbance::None, 50.0), entry(GaitClass::Still, Disturbance::None, 1000.0)];
        b[0].terminated = true;
        let s = score(&b, &[1.0, 10.0]);
        assert!(!s.pays_a_wrong_gait() && s.misordered.is_nan(), "{s:?}");
    }
}
