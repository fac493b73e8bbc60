//! One PPO batch: `num_steps` transitions of each of `num_envs` environments, stored
//! step-major (row `t * num_envs + i`), and what is computed from it once the rollout ends:
//! the truncation bootstrap and GAE(lambda) advantages.

pub struct RolloutBuffer {
    pub num_envs: usize,
    pub num_steps: usize,
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Normalised observations the actions were taken in.
    pub nobs: Vec<f32>,
    /// Sampled actions (before clipping), their log-probabilities and the critic's values.
    pub actions: Vec<f32>,
    pub logp: Vec<f32>,
    pub values: Vec<f32>,
    pub env_rewards: Vec<f64>,
    /// The forward term of each environment reward (what [`super::RewardSource::Backward`]
    /// turns around).
    pub env_forward: Vec<f64>,
    /// Raw next observations and the clipped actions, what a learned reward reads.
    pub raw_next: Vec<f32>,
    pub clipped_actions: Vec<f32>,
    pub terminated: Vec<bool>,
    pub truncated: Vec<bool>,
    /// (row, normalised final observation) of every step truncated by the time limit.
    truncations: Vec<(usize, Vec<f32>)>,
}

impl RolloutBuffer {
    pub fn new(num_envs: usize, num_steps: usize, obs_dim: usize, act_dim: usize) -> Self {
        let batch = num_envs * num_steps;
        RolloutBuffer {
            num_envs,
            num_steps,
            obs_dim,
            act_dim,
            nobs: vec![0.0; batch * obs_dim],
            actions: vec![0.0; batch * act_dim],
            logp: vec![0.0; batch],
            values: vec![0.0; batch],
            env_rewards: vec![0.0; batch],
            env_forward: vec![0.0; batch],
            raw_next: vec![0.0; batch * obs_dim],
            clipped_actions: vec![0.0; batch * act_dim],
            terminated: vec![false; batch],
            truncated: vec![false; batch],
            truncations: Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.num_envs * self.num_steps
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Forgets the previous rollout's truncations (every other field is overwritten).
    pub fn clear(&mut self) {
        self.truncations.clear();
    }

    /// Records that `row` ended by the time limit in (normalised) observation `final_obs`.
    pub fn push_truncation(&mut self, row: usize, final_obs: Vec<f32>) {
        self.truncations.push((row, final_obs));
    }

    /// Whether the episode ended at `row`, by termination or truncation.
    pub fn done(&self, row: usize) -> bool {
        self.terminated[row] || self.truncated[row]
    }

    /// A truncated episode did not end in the MDP: its last reward gets `gamma * V(s_final)`
    /// (SB3's treatment; CleanRL treats truncation as termination).
    pub fn bootstrap_truncations(&self, rewards: &mut [f64], gamma: f64, mut value: impl FnMut(&[f32]) -> f32) {
        for (row, f) in &self.truncations {
            rewards[*row] += gamma * value(f) as f64;
        }
    }

    /// GAE(lambda) advantages and the value targets (advantage + value) of the batch, given
    /// the (scaled, bootstrapped) rewards and the values of the observations after the last
    /// step. Every episode end, terminated or truncated, cuts the recursion.
    pub fn advantages(&self, rewards: &[f64], next_values: &[f32], gamma: f64, lambda: f64) -> (Vec<f32>, Vec<f32>) {
        let n = self.num_envs;
        let mut adv = vec![0.0f32; self.len()];
        let mut last = vec![0.0f64; n];
        for t in (0..self.num_steps).rev() {
            for i in 0..n {
                let k = t * n + i;
                let next_v = if t + 1 == self.num_steps { next_values[i] } else { self.values[k + n] } as f64;
                let nonterminal = if self.done(k) { 0.0 } else { 1.0 };
                let delta = rewards[k] + gamma * next_v * nonterminal - self.values[k] as f64;
                last[i] = delta + gamma * lambda * nonterminal * last[i];
                adv[k] = last[i] as f32;
            }
        }
        let returns = adv.iter().zip(&self.values).map(|(a, v)| a + v).collect();
        (adv, returns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gae_matches_a_hand_computation() {
        // One environment, three steps, the episode ends after step 1.
        let mut b = RolloutBuffer::new(1, 3, 1, 1);
        b.values = vec![1.0, 2.0, 3.0];
        b.terminated = vec![false, true, false];
        let (gamma, lambda) = (0.5, 0.5);
        let (adv, ret) = b.advantages(&[1.0, 1.0, 1.0], &[4.0], gamma, lambda);
        // t = 2: delta = 1 + 0.5 * 4 - 3 = 0;            A = 0
        // t = 1: delta = 1 + 0 - 2 = -1 (episode ends);   A = -1
        // t = 0: delta = 1 + 0.5 * 2 - 1 = 1;             A = 1 + 0.25 * (-1) = 0.75
        assert_eq!(adv, vec![0.75, -1.0, 0.0]);
        assert_eq!(ret, vec![1.75, 1.0, 3.0]);
    }

    #[test]
    fn two_environments_do_not_mix_and_truncation_is_bootstrapped() {
        let mut b = RolloutBuffer::new(2, 2, 1, 1);
        b.values = vec![0.0; 4];
        b.truncated = vec![false, false, true, false];
        b.push_truncation(2, vec![7.0]);
        let mut rewards = vec![1.0, 2.0, 3.0, 4.0];
        b.bootstrap_truncations(&mut rewards, 0.9, |obs| obs[0] * 10.0);
        assert_eq!(rewards, vec![1.0, 2.0, 3.0 + 0.9 * 70.0, 4.0]);
        let (adv, _) = b.advantages(&rewards, &[0.0, 100.0], 1.0, 1.0);
        // Env 0 (rows 0, 2): the truncation cuts the recursion, so the final value is unused.
        assert_eq!(adv[2], 66.0);
        assert_eq!(adv[0], 1.0 + 66.0);
        // Env 1 (rows 1, 3): no end, bootstrapped from its next value 100.
        assert_eq!(adv[3], 104.0);
        assert_eq!(adv[1], 2.0 + 104.0);
    }
}
