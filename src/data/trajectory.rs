//! One episode: observations s_0..s_T (T + 1 rows), actions a_0..a_{T-1}, the environment's
//! reward and its terms, how it ended, and where it came from. BC reads (s_t, a_t); the
//! reward model reads s_{t+1}, the observation the reward of step t is paid on.
use crate::env::RewardTerms;

#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrajMeta {
    /// The policy that acted (a stage key or a name such as "bc", "demonstrator").
    pub source: String,
    /// Injected noise level (epsilon, sigma or 1 - alpha); 0 for the clean policy.
    pub noise: f64,
    pub seed: u64,
    /// Pairs for reward learning may be restricted to one group (multi-BC ranks within a clone).
    pub group: usize,
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// (T + 1) x obs_dim.
    pub obs: Vec<f32>,
    /// T x act_dim, as sent to the environment (clipped to the action box).
    pub actions: Vec<f32>,
    pub rewards: Vec<f64>,
    pub terms: Vec<RewardTerms>,
    pub terminated: bool,
    pub truncated: bool,
    pub meta: TrajMeta,
}

impl Trajectory {
    pub fn len(&self) -> usize {
        self.rewards.len()
    }
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }
    pub fn ret(&self) -> f64 {
        self.rewards.iter().sum()
    }
    pub fn obs_row(&self, t: usize) -> &[f32] {
        &self.obs[t * self.obs_dim..(t + 1) * self.obs_dim]
    }
    pub fn action_row(&self, t: usize) -> &[f32] {
        &self.actions[t * self.act_dim..(t + 1) * self.act_dim]
    }
    /// The same trajectory seeing only the entries `seen` of each observation.
    pub fn obs_part(&self, seen: std::ops::Range<usize>) -> Trajectory {
        let obs = self.obs.chunks(self.obs_dim).flat_map(|row| &row[seen.clone()]).copied().collect();
        Trajectory { obs_dim: seen.len(), obs, ..self.clone() }
    }
    /// s_1..s_T, the observations rewards are paid on.
    pub fn next_obs(&self) -> &[f32] {
        &self.obs[self.obs_dim..]
    }
}
