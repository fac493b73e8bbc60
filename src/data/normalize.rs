//! Running mean and variance (parallel Welford / Chan et al.), the statistics behind PPO's
//! observation and return normalisation and the learned reward's per-model normalisation.
//! Stored inside the policy and reward artifacts so that every stage uses the same numbers.

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunningMeanStd {
    pub mean: Vec<f64>,
    pub var: Vec<f64>,
    pub count: f64,
}

impl RunningMeanStd {
    /// Starts as SB3/CleanRL do: mean 0, var 1, a tiny pseudo-count.
    pub fn new(dim: usize) -> Self {
        RunningMeanStd { mean: vec![0.0; dim], var: vec![1.0; dim], count: 1e-4 }
    }

    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Adds a batch of rows (row-major, `dim` wide).
    pub fn update(&mut self, batch: &[f32]) {
        let d = self.dim();
        let n = (batch.len() / d) as f64;
        if n == 0.0 {
            return;
        }
        let mut bmean = vec![0.0; d];
        for row in batch.chunks(d) {
            for (m, &x) in bmean.iter_mut().zip(row) {
                *m += x as f64;
            }
        }
        bmean.iter_mut().for_each(|m| *m /= n);
        let mut bvar = vec![0.0; d];
        for row in batch.chunks(d) {
            for ((v, &x), m) in bvar.iter_mut().zip(row).zip(&bmean) {
                *v += (x as f64 - m).powi(2);
            }
        }
        bvar.iter_mut().for_each(|v| *v /= n);
        self.merge(&bmean, &bvar, n);
    }

    pub fn update_scalar(&mut self, x: f64) {
        self.merge(&[x], &[0.0], 1.0);
    }

    fn merge(&mut self, bmean: &[f64], bvar: &[f64], n: f64) {
        let total = self.count + n;
        for i in 0..self.dim() {
            let delta = bmean[i] - self.mean[i];
            let m2 = self.var[i] * self.count + bvar[i] * n + delta * delta * self.count * n / total;
            self.mean[i] += delta * n / total;
            self.var[i] = m2 / total;
        }
        self.count = total;
    }

    /// (x - mean) / sqrt(var + 1e-8), clipped to +-clip, in place.
    pub fn normalize(&self, x: &mut [f32], clip: f64) {
        let d = self.dim();
        for row in x.chunks_mut(d) {
            for ((v, m), s) in row.iter_mut().zip(&self.mean).zip(&self.var) {
                *v = ((*v as f64 - m) / (s + 1e-8).sqrt()).clamp(-clip, clip) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batched_updates_equal_the_plain_statistics() {
        let data: Vec<f32> = (0..200).map(|i| ((i * 37 % 101) as f32) * 0.1 - 3.0).collect();
        let mut r = RunningMeanStd::new(2);
        for chunk in data.chunks(14) {
            r.update(chunk);
        }
        for j in 0..2 {
            let col: Vec<f64> = data.iter().skip(j).step_by(2).map(|&x| x as f64).collect();
            let mean = col.iter().sum::<f64>() / col.len() as f64;
            let var = col.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / col.len() as f64;
            assert!((r.mean[j] - mean).abs() < 1e-4, "{} vs {mean}", r.mean[j]);
            assert!((r.var[j] - var).abs() < 1e-3, "{} vs {var}", r.var[j]);
        }
    }

    #[test]
    fn normalisation_clips() {
        let r = RunningMeanStd { mean: vec![0.0], var: vec![1e-6], count: 10.0 };
        let mut x = vec![1.0f32, -1.0];
        r.normalize(&mut x, 10.0);
        assert_eq!(x, vec![10.0, -10.0]);
    }
}
