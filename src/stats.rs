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
    let mut means: Vec<f64> = (0..resamples.max(1))
        .map(|_| (0..values.len()).map(|_| values[rng.random_range(0..values.len())]).sum::<f64>() / values.len() as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    let at = |q: f64| means[((q * means.len() as f64) as usize).min(means.len() - 1)];
    (at(0.025), at(0.975))
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
}
