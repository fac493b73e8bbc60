//! Statistics shared by stages, reports and benchmarks: summaries of returns and rank
//! statistics of predicted against true returns.

/// Mean, std (population), min and max of a set of returns.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReturnStats {
    #[serde(with = "nan_as_null")]
    pub mean: f64,
    #[serde(with = "nan_as_null")]
    pub std: f64,
    /// Infinite (stored as null) for an empty set.
    #[serde(with = "nan_as_null")]
    pub min: f64,
    #[serde(with = "nan_as_null")]
    pub max: f64,
    pub episodes: usize,
}

impl ReturnStats {
    pub fn of(returns: &[f64]) -> Self {
        let n = returns.len().max(1) as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        ReturnStats {
            mean,
            std,
            min: returns.iter().copied().fold(f64::INFINITY, f64::min),
            max: returns.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            episodes: returns.len(),
        }
    }
}

/// The mean of `v`, or None when it is empty.
pub fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// A 95 % percentile-bootstrap confidence interval of the mean of `values` (rliable's
/// practice for few runs: resample the runs, not the episodes), from `resamples` resamples
/// drawn with a fixed seed so that a report is reproducible.
pub fn bootstrap_ci(values: &[f64], resamples: usize, seed: u64) -> (f64, f64) {
    use rand::{Rng, SeedableRng};
    if values.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let means: Vec<f64> = (0..resamples.max(1))
        .map(|_| (0..values.len()).map(|_| values[rng.random_range(0..values.len())]).sum::<f64>() / values.len() as f64)
        .collect();
    percentile_interval(means)
}

/// The percentile interval (2.5 %, 97.5 %) of bootstrap statistics.
fn percentile_interval(mut stats: Vec<f64>) -> (f64, f64) {
    stats.sort_by(f64::total_cmp);
    let at = |q: f64| stats[((q * stats.len() as f64) as usize).min(stats.len() - 1)];
    (at(0.025), at(0.975))
}

/// The interquartile mean (rliable's IQM, scipy's `trim_mean(x, 0.25)`): the mean of what is
/// left after cutting floor(n / 4) values from each end.
pub fn iqm(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let cut = v.len() / 4;
    mean(&v[cut..v.len() - cut]).unwrap_or(f64::NAN)
}

pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// A 95 % percentile-bootstrap interval of `statistic` over replicates, for hierarchical
/// data: `groups[r]` are replicate r's run means. Each resample draws replicates with
/// replacement, then runs with replacement within each drawn replicate, and applies
/// `statistic` to the resampled replicates' means (a replicate's runs share its BC policy and
/// rewards, so the replicate is the unit, and the runs add their own spread).
pub fn hierarchical_ci(groups: &[Vec<f64>], statistic: fn(&[f64]) -> f64, resamples: usize, seed: u64) -> (f64, f64) {
    use rand::{Rng, SeedableRng};
    let groups: Vec<&Vec<f64>> = groups.iter().filter(|g| !g.is_empty()).collect();
    if groups.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let stats = (0..resamples.max(1))
        .map(|_| {
            let means: Vec<f64> = (0..groups.len())
                .map(|_| {
                    let g = groups[rng.random_range(0..groups.len())];
                    (0..g.len()).map(|_| g[rng.random_range(0..g.len())]).sum::<f64>() / g.len() as f64
                })
                .collect();
            statistic(&means)
        })
        .collect();
    percentile_interval(stats)
}

/// The probability of improvement of X over Y (rliable; the Mann-Whitney U statistic over
/// the number of pairs): the chance that a random replicate of X scores above a random one
/// of Y, ties counting half.
pub fn probability_of_improvement(x: &[f64], y: &[f64]) -> f64 {
    if x.is_empty() || y.is_empty() {
        return f64::NAN;
    }
    let wins: f64 = x
        .iter()
        .flat_map(|a| {
            y.iter().map(move |b| {
                if a > b {
                    1.0
                } else if a == b {
                    0.5
                } else {
                    0.0
                }
            })
        })
        .sum();
    wins / (x.len() * y.len()) as f64
}

/// P(X >= k) for X ~ Binomial(n, p).
fn binomial_upper_tail(k: usize, n: usize, p: f64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    // Terms by their logarithms: n up to thousands without overflow.
    let ln_choose = |i: usize| -> f64 { (1..=i).map(|j| ((n - i + j) as f64 / j as f64).ln()).sum() };
    (k..=n)
        .map(|i| {
            let ln = ln_choose(i) + i as f64 * p.ln() + (n - i) as f64 * (1.0 - p).ln();
            if p == 0.0 {
                f64::from(u8::from(i == 0))
            } else if p == 1.0 {
                f64::from(u8::from(i == n))
            } else {
                ln.exp()
            }
        })
        .sum::<f64>()
        .min(1.0)
}

/// The one-sided sign test of "X beats Y more often than not" from `wins` of `n` paired
/// replicates (ties dropped before): P(at least `wins` of `n` under a fair coin).
pub fn sign_test_p(wins: usize, n: usize) -> f64 {
    if n == 0 { f64::NAN } else { binomial_upper_tail(wins, n, 0.5) }
}

/// Holm's step-down correction of a family of p-values (Holm 1979), in the family's order:
/// the i-th smallest p is multiplied by m - i + 1 (i from 1), made no smaller than the one
/// before it, and capped at 1. A question of the family is decided where its corrected p is
/// below the level; NaN (a question not measured) stays NaN and leaves the family.
pub fn holm(ps: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..ps.len()).filter(|&i| ps[i].is_finite()).collect();
    order.sort_by(|&a, &b| ps[a].total_cmp(&ps[b]));
    let m = order.len();
    let mut out = vec![f64::NAN; ps.len()];
    let mut floor = 0.0_f64;
    for (i, &at) in order.iter().enumerate() {
        floor = floor.max(((m - i) as f64 * ps[at]).min(1.0));
        out[at] = floor;
    }
    out
}

/// The lower end of the two-sided 95 % Clopper-Pearson interval of a win rate seen as `wins`
/// of `n`: the p at which P(X >= wins) = 2.5 % (0 when `wins` is 0). 5 of 5 gives 0.478.
pub fn clopper_pearson_lower(wins: usize, n: usize) -> f64 {
    if n == 0 {
        return f64::NAN;
    }
    if wins == 0 {
        return 0.0;
    }
    // The tail grows with p: bisect.
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if binomial_upper_tail(wins, n, mid) < 0.025 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// "k of n replicates above Y", with what k of n can show: the one-sided sign test and the
/// 95 % Clopper-Pearson lower bound on the rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WinCount {
    pub k: usize,
    pub n: usize,
}

impl WinCount {
    pub fn fraction(self) -> f64 {
        self.k as f64 / self.n as f64
    }

    pub fn sign_p(self) -> f64 {
        sign_test_p(self.k, self.n)
    }

    pub fn lower(self) -> f64 {
        clopper_pearson_lower(self.k, self.n)
    }
}

impl std::fmt::Display for WinCount {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} of {} (p = {:.3}, rate ≥ {:.2})", self.k, self.n, self.sign_p(), self.lower())
    }
}

/// A 95 % interval of [`probability_of_improvement`] by rliable's independent bootstrap
/// (`StratifiedIndependentBootstrap` with one task): X's and Y's scores are resampled
/// separately, each with replacement, and the percentile interval taken.
pub fn probability_of_improvement_independent_ci(x: &[f64], y: &[f64], resamples: usize, seed: u64) -> (f64, f64) {
    use rand::{Rng, SeedableRng};
    if x.is_empty() || y.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut draw = |v: &[f64]| -> Vec<f64> { (0..v.len()).map(|_| v[rng.random_range(0..v.len())]).collect() };
    let stats = (0..resamples.max(1))
        .map(|_| {
            let (a, b) = (draw(x), draw(y));
            probability_of_improvement(&a, &b)
        })
        .collect();
    percentile_interval(stats)
}

/// X against Y over replicates, two ways. rliable's probability of improvement compares
/// every replicate of X with every one of Y, as if unpaired; its interval resamples each
/// side independently. Where replicate r of both shares its seeds (and so its BC and
/// rankings), the paired form counts the replicates where X beats Y: a win rate with its
/// exact (Clopper-Pearson) interval and a one-sided sign test, which do not claim more than
/// n coin flips can show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Improvement {
    /// rliable's statistic, and its independent-bootstrap 95 % interval.
    pub unpaired: f64,
    pub unpaired_ci: (f64, f64),
    /// Replicates where X scored above Y, and of the `pairs`, those that tied (dropped
    /// from the rate and the test).
    pub wins: usize,
    pub ties: usize,
    pub pairs: usize,
    /// The two-sided 95 % Clopper-Pearson interval of the win rate over untied pairs.
    pub paired_ci: (f64, f64),
    /// P(at least `wins` wins under a fair coin).
    pub sign_p: f64,
}

impl Improvement {
    /// From (X, Y) on each shared replicate.
    pub fn of(pairs: &[(f64, f64)], resamples: usize, seed: u64) -> Self {
        let (x, y): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
        let wins = pairs.iter().filter(|(a, b)| a > b).count();
        let ties = pairs.iter().filter(|(a, b)| a == b).count();
        let n = pairs.len() - ties;
        Improvement {
            unpaired: probability_of_improvement(&x, &y),
            unpaired_ci: probability_of_improvement_independent_ci(&x, &y, resamples, seed),
            wins,
            ties,
            pairs: pairs.len(),
            paired_ci: (clopper_pearson_lower(wins, n), 1.0 - clopper_pearson_lower(n - wins, n)),
            sign_p: sign_test_p(wins, n),
        }
    }

    /// The win rate over untied pairs.
    pub fn paired(&self) -> f64 {
        self.wins as f64 / (self.pairs - self.ties) as f64
    }

    /// Whether the comparison decides anything at the 5 % level: both forms must agree, the
    /// rliable interval clear of 0.5 and the paired sign test (of wins, or of losses) below 0.05.
    pub fn verdict(&self) -> Verdict {
        let untied = self.pairs - self.ties;
        if self.unpaired_ci.0 > 0.5 && self.sign_p < 0.05 {
            Verdict::Better
        } else if self.unpaired_ci.1 < 0.5 && sign_test_p(untied - self.wins, untied) < 0.05 {
            Verdict::Worse
        } else {
            Verdict::NoDifferenceShown
        }
    }

    /// What the reader must know before trusting the figures, or None.
    pub fn warning(&self) -> Option<String> {
        let mut w = Vec::new();
        if self.pairs < 10 {
            w.push(format!("only {} replicates", self.pairs));
        }
        if self.unpaired_ci.0 == self.unpaired_ci.1 {
            w.push("every pair agrees, so the bootstrap interval is a point".to_string());
        }
        (!w.is_empty()).then(|| w.join("; "))
    }
}

/// What a comparison of two methods shows ([`Improvement::verdict`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Better,
    Worse,
    NoDifferenceShown,
}

/// Spearman rank correlation (average ranks for ties).
pub fn spearman(x: &[f64], y: &[f64]) -> f64 {
    pearson(&ranks(x), &ranks(y))
}

pub fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let cov: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let vx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let vy: f64 = y.iter().map(|b| (b - my).powi(2)).sum();
    cov / (vx * vy).sqrt()
}

fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && v[idx[j + 1]] == v[idx[i]] {
            j += 1;
        }
        for &k in &idx[i..=j] {
            r[k] = (i + j) as f64 / 2.0;
        }
        i = j + 1;
    }
    r
}

/// Fraction of pairs (with different true values) whose predicted order is right.
pub fn pairwise_accuracy(pred: &[f64], truth: &[f64]) -> f64 {
    let (mut right, mut total) = (0usize, 0usize);
    for i in 0..pred.len() {
        for j in i + 1..pred.len() {
            if truth[i] != truth[j] {
                total += 1;
                right += usize::from((pred[i] > pred[j]) == (truth[i] > truth[j]));
            }
        }
    }
    right as f64 / total.max(1) as f64
}

/// Serde for f64 fields that may legitimately be NaN (a correlation of constant values, an
/// accuracy over no pairs): JSON has no NaN, serde_json writes null, and this reads it back.
pub mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        if x.is_finite() { s.serialize_f64(*x) } else { s.serialize_none() }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn holm_steps_down_and_keeps_the_order() {
        // Sorted 0.005, 0.01, 0.03, 0.04: x4 = 0.02, x3 = 0.03, x2 = 0.06, x1 = 0.04 -> 0.06.
        let got = holm(&[0.01, 0.04, 0.03, 0.005]);
        let want = [0.03, 0.06, 0.06, 0.02];
        assert!(got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-12), "{got:?}");
        // Capped at 1; a question not measured stays out of the family (m = 2 here).
        let got = holm(&[0.6, f64::NAN, 0.2]);
        assert!((got[0] - 0.6).abs() < 1e-12 && got[1].is_nan() && (got[2] - 0.4).abs() < 1e-12, "{got:?}");
        assert_eq!(holm(&[0.9, 0.8]), vec![1.0, 1.0]);
        // 10 of 10 against 19 others at 0.5: the smallest, 2^-10 x 20 = 0.0195, passes.
        let mut family = vec![0.5; 19];
        family.push(sign_test_p(10, 10));
        assert!((holm(&family)[19] - 20.0 / 1024.0).abs() < 1e-12);
    }

    use super::*;

    #[test]
    fn rank_statistics() {
        assert!((spearman(&[1.0, 2.0, 3.0], &[10.0, 20.0, 30.0]) - 1.0).abs() < 1e-12);
        assert!((spearman(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        assert_eq!(pairwise_accuracy(&[1.0, 2.0, 3.0], &[1.0, 3.0, 2.0]), 2.0 / 3.0);
        let s = ReturnStats::of(&[1.0, 3.0]);
        assert_eq!((s.mean, s.std, s.min, s.max, s.episodes), (2.0, 1.0, 1.0, 3.0, 2));
    }

    #[test]
    fn bootstrap_interval_of_the_mean() {
        assert_eq!(bootstrap_ci(&[5.0, 5.0, 5.0], 1000, 0), (5.0, 5.0));
        // Three runs 0, 1, 2: resampled means range over k/3; the 95 % interval is close to
        // the extremes but inside them.
        let (lo, hi) = bootstrap_ci(&[0.0, 1.0, 2.0], 10_000, 0);
        assert!((0.0..=1.0).contains(&lo) && (1.0..=2.0).contains(&hi) && lo < 0.5 && hi > 1.5, "{lo} {hi}");
        assert_eq!(bootstrap_ci(&[0.0, 1.0, 2.0], 10_000, 0), (lo, hi), "seeded");
    }

    /// Hand computations (and scipy's `trim_mean(x, 0.25)` for the IQM: floor(n / 4) cut
    /// from each end).
    #[test]
    fn study_statistics_by_hand() {
        assert_eq!(iqm(&[7.0, 1.0, 100.0, 3.0, 2.0, 6.0, 5.0, 4.0]), 4.5);
        assert_eq!(iqm(&[0.0, 1.0, 2.0, 3.0, 100.0]), 2.0);
        assert_eq!(iqm(&[4.0, 8.0]), 6.0);
        assert_eq!((median(&[3.0, 1.0, 2.0]), median(&[4.0, 1.0, 3.0, 2.0])), (2.0, 2.5));
        assert_eq!(probability_of_improvement(&[3.0, 1.0], &[2.0, 2.0]), 0.5);
        assert_eq!(probability_of_improvement(&[2.0, 3.0], &[2.0, 1.0]), 0.875);
        // Two replicates without spread inside: resampled means 0, 0.5, 1 with chances
        // 1/4, 1/2, 1/4, so the 2.5 % and 97.5 % points are 0 and 1.
        assert_eq!(hierarchical_ci(&[vec![0.0, 0.0], vec![1.0, 1.0]], |m| mean(m).unwrap(), 10_000, 0), (0.0, 1.0));
        // One replicate: only its runs are resampled, means 0, 1, 2 with 1/4, 1/2, 1/4.
        assert_eq!(hierarchical_ci(&[vec![0.0, 2.0]], |m| mean(m).unwrap(), 10_000, 0), (0.0, 2.0));
        // Replicates with equal means but spread runs: resampling replicates alone would give
        // [5, 5]; the runs inside widen it.
        let (lo, hi) = hierarchical_ci(&[vec![0.0, 10.0], vec![5.0, 5.0]], |m| mean(m).unwrap(), 10_000, 0);
        assert!(lo < 5.0 && hi > 5.0, "{lo} {hi}");
        assert_eq!(bootstrap_ci(&[5.0, 5.0], 1000, 0), (5.0, 5.0));
    }

    /// The figures: 5 of 5 gives p = 1/32 and a lower bound of 0.025^(1/5); 4 of 4,
    /// 1/16 and 0.025^(1/4); and scipy's `binomtest(7, 10).proportion_ci()` low end.
    #[test]
    fn sign_test_and_clopper_pearson_by_hand() {
        assert!((sign_test_p(5, 5) - 1.0 / 32.0).abs() < 1e-12);
        assert!((sign_test_p(4, 4) - 1.0 / 16.0).abs() < 1e-12);
        assert!((sign_test_p(8, 10) - 56.0 / 1024.0).abs() < 1e-12);
        assert_eq!(sign_test_p(0, 3), 1.0);
        assert!((clopper_pearson_lower(5, 5) - 0.025_f64.powf(0.2)).abs() < 1e-9);
        assert!((clopper_pearson_lower(4, 4) - 0.025_f64.powf(0.25)).abs() < 1e-9);
        assert!((clopper_pearson_lower(7, 10) - 0.34754715).abs() < 1e-6);
        assert_eq!(clopper_pearson_lower(0, 10), 0.0);
    }

    /// Five of five: rliable's interval is the point [1, 1] (every resample agrees), the
    /// paired one is not: a rate of at least 0.48, p = 1/32, and a warning on both counts.
    #[test]
    fn a_clean_sweep_on_five_replicates_is_weak_evidence() {
        let pairs: Vec<(f64, f64)> = (0..5).map(|i| (10.0 + i as f64, i as f64)).collect();
        let imp = Improvement::of(&pairs, 10_000, 0);
        assert_eq!((imp.unpaired, imp.unpaired_ci), (1.0, (1.0, 1.0)));
        assert_eq!((imp.wins, imp.ties, imp.pairs, imp.paired()), (5, 0, 5, 1.0));
        assert!((imp.paired_ci.0 - 0.4782).abs() < 1e-3 && imp.paired_ci.1 == 1.0, "{:?}", imp.paired_ci);
        assert!((imp.sign_p - 1.0 / 32.0).abs() < 1e-12);
        let w = imp.warning().unwrap();
        assert!(w.contains("only 5 replicates") && w.contains("a point"), "{w}");
        // Five of five decides at 5 % (p = 1/32); four of four does not (p = 1/16); five
        // losses decide the other way; a tie everywhere decides nothing.
        assert_eq!(imp.verdict(), Verdict::Better);
        assert_eq!(Improvement::of(&pairs[..4], 10_000, 0).verdict(), Verdict::NoDifferenceShown);
        let lost: Vec<(f64, f64)> = pairs.iter().map(|&(a, b)| (b, a)).collect();
        assert_eq!(Improvement::of(&lost, 10_000, 0).verdict(), Verdict::Worse);
        assert_eq!(Improvement::of(&[(1.0, 1.0); 6], 1000, 0).verdict(), Verdict::NoDifferenceShown);
        // Ties leave the rate and the test.
        let imp = Improvement::of(&[(1.0, 1.0), (2.0, 1.0), (0.0, 1.0)], 1000, 0);
        assert_eq!((imp.wins, imp.ties, imp.paired()), (1, 1, 0.5));
        // Independent resampling: the estimate lies inside its interval, unlike the paired
        // bootstrap's [0.16, 0.32] around 0.32 in issue 38.
        let x = [1.0, 5.0, 2.0, 8.0, 3.0];
        let y = [4.0, 6.0, 0.0, 7.0, 9.0];
        let (lo, hi) = probability_of_improvement_independent_ci(&x, &y, 10_000, 0);
        let p = probability_of_improvement(&x, &y);
        assert!(lo < p && p < hi, "{lo} {p} {hi}");
    }
}
