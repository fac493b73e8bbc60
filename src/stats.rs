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

/// A 95 % bootstrap interval of [`probability_of_improvement`] over paired replicates
/// (`pairs[r]` = (X, Y) on replicate r): each resample draws replicates with replacement and
/// keeps both methods' scores of a drawn replicate together, since they share its BC policy
/// and D-REX reward.
pub fn probability_of_improvement_ci(pairs: &[(f64, f64)], resamples: usize, seed: u64) -> (f64, f64) {
    use rand::{Rng, SeedableRng};
    if pairs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let stats = (0..resamples.max(1))
        .map(|_| {
            let (x, y): (Vec<f64>, Vec<f64>) = (0..pairs.len()).map(|_| pairs[rng.random_range(0..pairs.len())]).unzip();
            probability_of_improvement(&x, &y)
        })
        .collect();
    percentile_interval(stats)
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
        // Every X above every Y: 1 in every resample. Paired replicates keep their pair:
        // X = Y + 1 on each, so every resample has P in (0.5, 1].
        assert_eq!(probability_of_improvement_ci(&[(10.0, 1.0), (20.0, 3.0)], 1000, 0), (1.0, 1.0));
        let (lo, hi) = probability_of_improvement_ci(&[(1.0, 0.0), (3.0, 2.0), (5.0, 4.0)], 10_000, 0);
        assert!(lo > 0.5 && hi == 1.0, "{lo} {hi}");
    }
}
