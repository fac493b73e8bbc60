//! Noise-injected policies, each seeded through the rollout's generator:
//! epsilon-greedy random actions (D-REX), Gaussian action noise, Ornstein-Uhlenbeck noise,
//! time-correlated (held) noise, and probabilistic interpolation between two policies
//! (iD-REX, the report's equation 6). Every actor's output is clipped to the action box by
//! the rollout loop.
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::data::{TrajMeta, Trajectory};
use crate::env::Env;
use crate::nn::ActorCritic;
use crate::rollout::{self, Actor, PolicyActor, UniformActor};

/// The noise processes iD-REX's action-noise variant can inject (`idrex.action_noise`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseProcess {
    /// Independent Gaussian noise every step.
    #[default]
    Gaussian,
    /// Ornstein-Uhlenbeck noise (theta 0.15, dt 0.01).
    Ou,
    /// Gaussian noise held for 10 steps.
    TimeCorrelated,
}

impl NoiseProcess {
    /// `inner`'s action plus this noise at scale `sigma`.
    pub fn around<A: Actor + 'static>(self, inner: A, sigma: f64, act_dim: usize) -> Box<dyn Actor> {
        match self {
            NoiseProcess::Gaussian => Box::new(GaussianNoise { inner, sigma }),
            NoiseProcess::Ou => Box::new(OrnsteinUhlenbeck::new(inner, sigma, act_dim)),
            NoiseProcess::TimeCorrelated => Box::new(TimeCorrelated::new(inner, sigma, 10, act_dim)),
        }
    }
}

/// What an epsilon-greedy step takes instead of the policy's action (`noise.toward`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseToward {
    /// A uniform random action in the box (D-REX's): noisier rollouts are jerkier and, on
    /// tasks that end, shorter.
    #[default]
    Random,
    /// The zero action: noisier rollouts do less, and a robot that stands still ranks below
    /// one that moves as the policy does.
    Zero,
    /// Both sets, `rollouts_per_level` each at every level; the zero-action rollouts are
    /// group 1 (with `trex.same_group` the two rank apart).
    Both,
}

impl NoiseToward {
    pub fn is_random(&self) -> bool {
        *self == NoiseToward::Random
    }
}

/// How D-REX's ranked rollouts are disturbed (`noise.disturbance`); each level of the schedule
/// is the disturbance's scale, and a larger one ranks lower.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Disturbance {
    /// Epsilon-greedy (D-REX's): each step, with probability epsilon, the `toward` action.
    #[default]
    Epsilon,
    /// Ornstein-Uhlenbeck noise on BC's mean action (theta 0.15, dt 0.01), its stationary
    /// standard deviation the level: smooth, no step-to-step jitter.
    Ou,
    /// Gaussian noise of standard deviation the level, redrawn every 10 steps and held.
    Held,
    /// BC's own weights perturbed (each layer's at the level times its weights' RMS), one
    /// perturbed policy per level acting with its mean: another gait, not a jittered one.
    Weights,
}

impl Disturbance {
    pub fn is_epsilon(&self) -> bool {
        *self == Disturbance::Epsilon
    }
}

/// `per_level` rollouts at each level of `schedule`, disturbed as `kind` says (not epsilon,
/// which [`degrade`] does); the k-th level's perturbed weights from `derive(seed,
/// WeightNoise, k)`.
pub fn disturb(
    env: &mut Env,
    policy: &ActorCritic,
    schedule: &[f64],
    per_level: usize,
    seed: u64,
    meta: &TrajMeta,
    kind: Disturbance,
) -> Vec<Trajectory> {
    use rand::SeedableRng;
    let ad = env.act_dim();
    // OU's stationary standard deviation is sigma sqrt(dt / (2 theta)).
    let ou_sigma = |level: f64| level / (1e-2f64 / (2.0 * 0.15)).sqrt();
    let mut k = 0u64;
    rollout::at_levels(env, seed, schedule, per_level, meta, |level| -> Box<dyn Actor> {
        let mean = PolicyActor::mean_of(policy);
        k += 1;
        match kind {
            Disturbance::Epsilon => unreachable!("epsilon-greedy rollouts are degrade's"),
            Disturbance::Ou => Box::new(OrnsteinUhlenbeck::new(mean, ou_sigma(level), ad)),
            Disturbance::Held => Box::new(TimeCorrelated::new(mean, level, 10, ad)),
            Disturbance::Weights => {
                let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::derive(seed, crate::seed::Purpose::WeightNoise, k - 1));
                let mut p = policy.to_cpu();
                p.actor.perturb_weights(level, &mut rng);
                Box::new(PolicyActor::new(p, false))
            }
        }
    })
}

/// D-REX's noise injection: epsilon-greedy rollouts around a policy's mean action, `per_level`
/// per epsilon of `schedule`.
pub fn epsilon_greedy(
    env: &mut Env,
    policy: &ActorCritic,
    schedule: &[f64],
    per_level: usize,
    seed: u64,
    meta: &TrajMeta,
) -> Vec<Trajectory> {
    let uniform = UniformActor::of(env);
    rollout::at_levels(env, seed, schedule, per_level, meta, |eps| EpsilonGreedy {
        inner: PolicyActor::mean_of(policy),
        eps,
        degraded: uniform.clone(),
    })
}

/// The noise level the still set is labelled with ([`still`]): epsilon 1 toward the zero
/// action, which ranks it below every level at least `trex.min_margin` less noisy and makes it
/// the ranked set's noisiest level (the floor of `reward.level: ranked-floor`).
pub const STILL_LEVEL: f64 = 1.0;

/// `episodes` episodes of the zero action, from their own resets: the robot doing nothing,
/// ranked below the noisy rollouts as the D-REX code's Atari ranking ranks its no-op episodes
/// (`add_noop`), so that a reward cannot pay most for standing still.
pub fn still(env: &mut Env, episodes: usize, seed: u64, meta: &TrajMeta) -> Vec<Trajectory> {
    let mut nothing = ConstantActor(vec![0.0; env.act_dim()]);
    let meta = TrajMeta { noise: STILL_LEVEL, ..meta.clone() };
    rollout::episodes(env, &mut nothing, episodes, seed, crate::seed::Purpose::StillSet, &meta)
}

/// Epsilon-greedy rollouts degraded `toward` a random or the zero action (or both sets; the
/// zero-action set from its own episode seeds, so the two never share a reset).
pub fn degrade(
    env: &mut Env,
    policy: &ActorCritic,
    schedule: &[f64],
    per_level: usize,
    seed: u64,
    meta: &TrajMeta,
    toward: NoiseToward,
) -> Vec<Trajectory> {
    let zero = vec![0.0; env.act_dim()];
    let toward_zero = |env: &mut Env, seed: u64, meta: &TrajMeta| {
        rollout::at_levels(env, seed, schedule, per_level, meta, |eps| EpsilonGreedy {
            inner: PolicyActor::mean_of(policy),
            eps,
            degraded: ConstantActor(zero.clone()),
        })
    };
    match toward {
        NoiseToward::Random => epsilon_greedy(env, policy, schedule, per_level, seed, meta),
        NoiseToward::Zero => toward_zero(env, seed, meta),
        NoiseToward::Both => {
            let mut trajs = epsilon_greedy(env, policy, schedule, per_level, seed, meta);
            let zero_meta = TrajMeta { group: 1, ..meta.clone() };
            trajs.extend(toward_zero(env, crate::seed::derive(seed, crate::seed::Purpose::ZeroActionSet, 0), &zero_meta));
            trajs
        }
    }
}

/// With probability `eps` the degraded action (a uniform random one in the box, D-REX's, or
/// another actor's), else the inner policy's.
pub struct EpsilonGreedy<A, D = UniformActor> {
    pub inner: A,
    pub eps: f64,
    pub degraded: D,
}

impl<A: Actor, D: Actor> Actor for EpsilonGreedy<A, D> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        if rng.random_bool(self.eps.clamp(0.0, 1.0)) {
            self.degraded.act(obs, rng, out);
        } else {
            self.inner.act(obs, rng, out);
        }
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
}

/// The inner action plus `sigma * N(0, I)` (iD-REX variant 2).
pub struct GaussianNoise<A> {
    pub inner: A,
    pub sigma: f64,
}

impl<A: Actor> Actor for GaussianNoise<A> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        self.inner.act(obs, rng, out);
        for o in out.iter_mut() {
            *o += (self.sigma * rng.sample::<f64, _>(StandardNormal)) as f32;
        }
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
}

/// The inner action plus Ornstein-Uhlenbeck noise
/// `x += theta (0 - x) dt + sigma sqrt(dt) N(0, I)`, restarted at 0 every episode.
pub struct OrnsteinUhlenbeck<A> {
    pub inner: A,
    pub sigma: f64,
    pub theta: f64,
    pub dt: f64,
    state: Vec<f64>,
}

impl<A> OrnsteinUhlenbeck<A> {
    /// The usual DDPG constants: theta 0.15, dt 0.01.
    pub fn new(inner: A, sigma: f64, act_dim: usize) -> Self {
        OrnsteinUhlenbeck { inner, sigma, theta: 0.15, dt: 1e-2, state: vec![0.0; act_dim] }
    }
}

impl<A: Actor> Actor for OrnsteinUhlenbeck<A> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        self.inner.act(obs, rng, out);
        for (o, x) in out.iter_mut().zip(&mut self.state) {
            *x += -self.theta * *x * self.dt + self.sigma * self.dt.sqrt() * rng.sample::<f64, _>(StandardNormal);
            *o += *x as f32;
        }
    }
    fn reset(&mut self) {
        self.state.iter_mut().for_each(|x| *x = 0.0);
        self.inner.reset();
    }
}

/// The inner action plus Gaussian noise that is redrawn every `period` steps and held
/// in between: perturbations that persist long enough to change the gait.
pub struct TimeCorrelated<A> {
    pub inner: A,
    pub sigma: f64,
    pub period: usize,
    step: usize,
    noise: Vec<f64>,
}

impl<A> TimeCorrelated<A> {
    pub fn new(inner: A, sigma: f64, period: usize, act_dim: usize) -> Self {
        TimeCorrelated { inner, sigma, period: period.max(1), step: 0, noise: vec![0.0; act_dim] }
    }
}

impl<A: Actor> Actor for TimeCorrelated<A> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        self.inner.act(obs, rng, out);
        if self.step.is_multiple_of(self.period) {
            for n in &mut self.noise {
                *n = self.sigma * rng.sample::<f64, _>(StandardNormal);
            }
        }
        self.step += 1;
        for (o, n) in out.iter_mut().zip(&self.noise) {
            *o += *n as f32;
        }
    }
    fn reset(&mut self) {
        self.step = 0;
        self.inner.reset();
    }
}

/// pi(.|alpha): with probability alpha the newer policy's action, else the older one's
/// (the report's equation 6).
pub struct Interpolation<A, B> {
    pub newer: A,
    pub older: B,
    pub alpha: f64,
}

impl<A: Actor, B: Actor> Actor for Interpolation<A, B> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        if rng.random_bool(self.alpha.clamp(0.0, 1.0)) {
            self.newer.act(obs, rng, out);
        } else {
            self.older.act(obs, rng, out);
        }
    }
    fn reset(&mut self) {
        self.newer.reset();
        self.older.reset();
    }
}

/// Acts with a fixed action (the zero action of `noise.toward: zero`; a stand-in policy in tests).
pub struct ConstantActor(pub Vec<f32>);

impl Actor for ConstantActor {
    fn act(&mut self, _obs: &[f32], _rng: &mut ChaCha8Rng, out: &mut [f32]) {
        out.copy_from_slice(&self.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn run(actor: &mut dyn Actor, n: usize, seed: u64) -> Vec<Vec<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        actor.reset();
        (0..n)
            .map(|_| {
                let mut a = vec![0.0; 2];
                actor.act(&[0.0], &mut rng, &mut a);
                a
            })
            .collect()
    }

    #[test]
    fn epsilon_one_is_uniform_over_the_box() {
        let mut a = EpsilonGreedy {
            inner: ConstantActor(vec![0.5, 0.5]),
            eps: 1.0,
            degraded: UniformActor { low: vec![-1.0, -2.0], high: vec![1.0, 2.0] },
        };
        let acts = run(&mut a, 20_000, 0);
        for (d, (lo, hi)) in [(-1.0f32, 1.0f32), (-2.0, 2.0)].into_iter().enumerate() {
            let xs: Vec<f32> = acts.iter().map(|a| a[d]).collect();
            assert!(xs.iter().all(|&x| x >= lo && x < hi));
            // Ten equal bins, each within 10 % of its expected 2,000.
            let mut bins = [0usize; 10];
            for x in &xs {
                bins[(((x - lo) / (hi - lo)) * 10.0) as usize] += 1;
            }
            assert!(bins.iter().all(|&b| (1800..=2200).contains(&b)), "{bins:?}");
            let mean = xs.iter().sum::<f32>() / xs.len() as f32;
            assert!(mean.abs() < 0.02 * (hi - lo), "mean {mean}");
        }
    }

    #[test]
    fn epsilon_zero_is_the_policy_and_seeds_reproduce() {
        let mut a = EpsilonGreedy {
            inner: ConstantActor(vec![0.5, 0.5]),
            eps: 0.0,
            degraded: UniformActor { low: vec![-1.0; 2], high: vec![1.0; 2] },
        };
        assert!(run(&mut a, 100, 0).iter().all(|x| x == &vec![0.5, 0.5]));
        let mut g = GaussianNoise { inner: ConstantActor(vec![0.0, 0.0]), sigma: 0.3 };
        assert_eq!(run(&mut g, 50, 3), run(&mut g, 50, 3));
        assert_ne!(run(&mut g, 50, 3), run(&mut g, 50, 4));
    }

    #[test]
    fn epsilon_toward_zero_takes_the_zero_action_in_proportion() {
        let mut a = EpsilonGreedy { inner: ConstantActor(vec![0.5, 0.5]), eps: 0.3, degraded: ConstantActor(vec![0.0, 0.0]) };
        let acts = run(&mut a, 10_000, 5);
        assert!(acts.iter().all(|x| x == &vec![0.5, 0.5] || x == &vec![0.0, 0.0]));
        let zeros = acts.iter().filter(|x| x[0] == 0.0).count();
        assert!((2_800..=3_200).contains(&zeros), "{zeros} zero actions of 10,000 at epsilon 0.3");
    }

    /// The still set: the zero action every step from resets of its own, labelled epsilon 1,
    /// so T-REX ranks every level at least the margin less noisy above it; on Ant the robot
    /// doing nothing stays healthy to the time limit.
    #[test]
    fn the_still_set_does_nothing_and_ranks_below_the_levels() {
        let mut env = Env::new(crate::env::EnvId::Ant).unwrap();
        let meta = TrajMeta { source: "bc".into(), ..Default::default() };
        let still = still(&mut env, 2, 11, &meta);
        assert_eq!(still.len(), 2);
        assert_ne!(still[0].meta.seed, still[1].meta.seed);
        assert_ne!(still[0].obs[..27], still[1].obs[..27], "each episode from its own reset");
        for t in &still {
            assert!(t.actions.iter().all(|&a| a == 0.0));
            assert_eq!((t.meta.noise, t.len(), t.truncated, t.terminated), (STILL_LEVEL, 1000, true, false));
        }
        let levels = [0.0, 0.5, 0.7, 0.8];
        let mut scores: Vec<f64> = levels.iter().map(|e| -e).collect();
        scores.extend(still.iter().map(|t| -t.meta.noise));
        let ranking = crate::algo::trex::Ranking::by_score(scores);
        let cfg = crate::algo::trex::TrexConfig::default();
        let above_still: Vec<bool> = (0..levels.len()).map(|i| ranking.prefers(i, levels.len(), cfg.min_margin)).collect();
        assert_eq!(above_still, [true, true, true, false], "margin {}", cfg.min_margin);
        assert!(!ranking.prefers(levels.len(), 0, cfg.min_margin));
    }

    /// The disturbances without jitter: at level 0 each is BC's mean action exactly; above it
    /// each changes the actions, the same seed the same episode.
    #[test]
    fn ranked_disturbances_are_the_policy_at_zero_and_move_it_above() {
        use crate::nn::{ActorCritic, PolicyConfig};
        let mut env = Env::new(crate::env::EnvId::Hopper).unwrap();
        let policy = crate::nn::seeded(4, || ActorCritic::new(PolicyConfig::ppo(11, 3)));
        let meta = TrajMeta { source: "bc".into(), ..Default::default() };
        let clean = epsilon_greedy(&mut env, &policy, &[0.0], 1, 9, &meta);
        for kind in [Disturbance::Ou, Disturbance::Held, Disturbance::Weights] {
            let set = disturb(&mut env, &policy, &[0.0, 0.5], 1, 9, &meta, kind);
            assert_eq!(set.len(), 2);
            assert_eq!(set[0].actions, clean[0].actions, "{kind:?} at level 0 is the policy");
            assert_ne!(set[1].actions[..30], set[0].actions[..30], "{kind:?} at 0.5 moves it");
            assert_eq!(set[1].meta.noise, 0.5);
            assert_eq!(disturb(&mut env, &policy, &[0.0, 0.5], 1, 9, &meta, kind)[1].actions, set[1].actions, "seeded");
        }
    }

    #[test]
    fn noise_processes_have_their_shape() {
        let mut g = GaussianNoise { inner: ConstantActor(vec![0.0, 0.0]), sigma: 0.5 };
        let xs: Vec<f32> = run(&mut g, 20_000, 1).iter().map(|a| a[0]).collect();
        let var = xs.iter().map(|x| x * x).sum::<f32>() / xs.len() as f32;
        assert!((var - 0.25).abs() < 0.01, "variance {var}");
        // Held noise changes only every `period` steps.
        let mut t = TimeCorrelated::new(ConstantActor(vec![0.0, 0.0]), 1.0, 5, 2);
        let xs = run(&mut t, 20, 2);
        assert!(xs[0] == xs[4] && xs[4] != xs[5] && xs[5] == xs[9]);
        // OU noise is correlated step to step.
        let mut o = OrnsteinUhlenbeck::new(ConstantActor(vec![0.0, 0.0]), 1.0, 2);
        let xs: Vec<f32> = run(&mut o, 5000, 3).iter().map(|a| a[0]).collect();
        let lag1 = xs.windows(2).map(|w| w[0] * w[1]).sum::<f32>() / xs.iter().map(|x| x * x).sum::<f32>();
        assert!(lag1 > 0.9, "lag-1 autocorrelation {lag1}");
    }

    #[test]
    fn interpolation_takes_the_newer_policy_with_probability_alpha() {
        let mut i = Interpolation { newer: ConstantActor(vec![1.0, 1.0]), older: ConstantActor(vec![-1.0, -1.0]), alpha: 0.3 };
        let newer = run(&mut i, 10_000, 5).iter().filter(|a| a[0] > 0.0).count();
        assert!((2800..=3200).contains(&newer), "{newer}");
    }
}
