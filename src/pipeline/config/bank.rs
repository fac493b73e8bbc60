//! `bank:`, the reward bench's settings ([`crate::pipeline::stage::bank`]).

/// The reward bench's bank of gaits (`analysis/results/reward-bench/`): PPO checkpoints on
/// the task's reward (forward gaits, slow to fast) and on it with the forward term negated
/// (backward gaits), each rolled out as it acts, with jerky (epsilon-greedy) and with smooth
/// (Ornstein-Uhlenbeck) noise; the zero action (standing, or slumping) and uniform random
/// actions (flailing, falling). PPO runs at CleanRL's settings whatever the file's `ppo`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct BankConfig {
    /// PPO steps of the forward gaits' run.
    pub steps: usize,
    /// PPO steps of the backward gaits' run.
    pub backward_steps: usize,
    /// Checkpoints of each run, evenly spaced, the last at its end.
    pub checkpoints: usize,
    /// Checkpoints of the backward run, spaced as the forward run's.
    pub backward_checkpoints: usize,
    /// Space the checkpoints geometrically from this fraction of each run to its end (more
    /// slow gaits), instead of evenly.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first: Option<f64>,
    /// Episodes of each checkpoint acting with its mean action (calm versions of every gait).
    pub mean: usize,
    /// Episodes of each checkpoint as it acts.
    pub episodes: usize,
    /// Epsilon-greedy levels around each checkpoint's mean action.
    pub epsilon: Vec<f64>,
    /// Ornstein-Uhlenbeck sigmas around each checkpoint's mean action.
    pub smooth: Vec<f64>,
    /// Episodes per checkpoint at each epsilon and sigma.
    pub disturbed: usize,
    /// Episodes of the zero action.
    pub still: usize,
    /// Episodes of uniform random actions.
    pub random: usize,
    /// The bank's seed (its PPO runs and episodes), apart from every study's.
    pub seed: u64,
    /// PPO steps of a probe beside every reward PPO trains on: one short run on the reward
    /// as the method's first run composes it, scored by the true return of its last quarter
    /// (`drex/trex/probe`). Absent, none; not part of the bank's keys.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub probe: Option<usize>,
}

impl Default for BankConfig {
    fn default() -> Self {
        BankConfig {
            steps: 1_000_000,
            backward_steps: 500_000,
            checkpoints: 6,
            backward_checkpoints: 3,
            first: None,
            mean: 0,
            episodes: 2,
            epsilon: vec![0.25, 0.5],
            smooth: vec![0.3, 0.6],
            disturbed: 1,
            still: 3,
            random: 3,
            seed: 7_000_000,
            probe: None,
        }
    }
}
