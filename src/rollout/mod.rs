//! Rollouts: their file format ([`mcap`], and flat exports of it, [`export`]), and the one
//! rollout loop shared by noise rollouts, demonstrations, evaluation and PPO's
//! evaluations: any [`Actor`] in one environment, full episodes, actions clipped to the box
//! before the step (Gymnasium's ClipAction, as CleanRL and SB3 use). The base actors live
//! here too: a stored policy ([`PolicyActor`]) and uniform random actions; the noise that
//! wraps them is in `algo::noise`, one layer up.
pub mod export;
pub mod mcap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::data::{TrajMeta, Trajectory};
use crate::env::Env;
use crate::nn::ActorCritic;
use crate::nn::policy::CpuPolicy;
use crate::seed::{self, Purpose};

/// Anything that maps an observation to an action.
pub trait Actor {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]);
    /// Called at the start of every episode (noise processes restart here).
    fn reset(&mut self) {}
    /// The action to record for the step just acted, where it is not the one executed (a
    /// demonstrator that acts with noise but labels its steps with its mean, as DART does).
    fn label(&self) -> Option<&[f32]> {
        None
    }
}

impl<A: Actor + ?Sized> Actor for Box<A> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        (**self).act(obs, rng, out)
    }
    fn reset(&mut self) {
        (**self).reset()
    }
    fn label(&self) -> Option<&[f32]> {
        (**self).label()
    }
}

/// One full episode from a seeded reset; the actor's randomness is seeded from `seed` too.
pub fn episode(env: &mut Env, actor: &mut dyn Actor, seed: u64, meta: TrajMeta) -> Trajectory {
    let (od, ad) = (env.obs_dim(), env.act_dim());
    let mut rng = ChaCha8Rng::seed_from_u64(seed::derive(seed, Purpose::ActorNoise, 0));
    let mut obs64 = vec![0.0; od];
    env.reset(Some(seed), &mut obs64);
    let mut t = Trajectory { obs_dim: od, act_dim: ad, meta: TrajMeta { seed, ..meta }, ..Default::default() };
    t.obs.extend(obs64.iter().map(|&x| x as f32));
    actor.reset();
    let (low, high) = env.action_bounds();
    let (low, high) = (low.to_vec(), high.to_vec());
    let mut a32 = vec![0.0f32; ad];
    let mut a64 = vec![0.0f64; ad];
    loop {
        let cur = t.obs.len() - od;
        let obs_now: Vec<f32> = t.obs[cur..].to_vec();
        actor.act(&obs_now, &mut rng, &mut a32);
        for i in 0..ad {
            a64[i] = (a32[i] as f64).clamp(low[i], high[i]);
            a32[i] = a64[i] as f32;
        }
        let info = env.step(&a64, &mut obs64).expect("actor widths match the environment");
        t.obs.extend(obs64.iter().map(|&x| x as f32));
        match actor.label() {
            Some(label) => t.actions.extend(label.iter().zip(low.iter().zip(&high)).map(|(&a, (&l, &h))| (a as f64).clamp(l, h) as f32)),
            None => t.actions.extend_from_slice(&a32),
        }
        t.rewards.push(info.reward);
        t.terms.push(info.terms);
        if info.terminated || info.truncated {
            t.terminated = info.terminated;
            t.truncated = info.truncated;
            return t;
        }
    }
}

/// `episodes` episodes of `actor`, episode k from the seed `derive(seed, purpose, k)`.
pub fn episodes(env: &mut Env, actor: &mut dyn Actor, episodes: usize, seed: u64, purpose: Purpose, meta: &TrajMeta) -> Vec<Trajectory> {
    (0..episodes).map(|k| episode(env, actor, seed::derive(seed, purpose, k as u64), meta.clone())).collect()
}

/// A rollout set over noise levels: `per_level` episodes of `make(level)` for each level, the
/// k-th episode of the set (counted over all levels) from `derive(seed, Episode, k)`, each
/// labelled with its level.
pub fn at_levels<A: Actor>(
    env: &mut Env,
    seed: u64,
    levels: &[f64],
    per_level: usize,
    meta: &TrajMeta,
    mut make: impl FnMut(f64) -> A,
) -> Vec<Trajectory> {
    let mut out = Vec::with_capacity(levels.len() * per_level);
    for &level in levels {
        let mut actor = make(level);
        for _ in 0..per_level {
            let k = out.len() as u64;
            out.push(episode(env, &mut actor, seed::derive(seed, Purpose::Episode, k), TrajMeta { noise: level, ..meta.clone() }));
        }
    }
    out
}

/// How a stored policy's steps are taken and recorded.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Acting {
    /// Sample from the policy's Gaussian; record the sampled action (clipped to the box).
    #[default]
    Sampled,
    /// Act with the mean action and record it.
    Mean,
    /// Sample from the Gaussian but record the mean action: the demonstrator's own noise
    /// widens the states seen while every label stays noise-free (DART, Laskey et al. 2017).
    SampledMeanLabels,
}

impl Acting {
    pub fn is_sampled(&self) -> bool {
        *self == Acting::Sampled
    }
}

/// A policy acting with its mean action or sampling from its Gaussian.
pub struct PolicyActor {
    pub policy: CpuPolicy,
    pub stochastic: bool,
    /// Record the mean action while sampling ([`Acting::SampledMeanLabels`]).
    pub mean_labels: bool,
    /// Scales the sampled deviation from the mean (1: the policy's own standard deviation).
    pub noise_scale: f32,
    nobs: Vec<f32>,
    mean: Vec<f32>,
    scratch: Vec<f32>,
}

impl PolicyActor {
    pub fn new(policy: CpuPolicy, stochastic: bool) -> Self {
        let (od, ad) = (policy.obs_dim(), policy.act_dim());
        PolicyActor {
            policy,
            stochastic,
            mean_labels: false,
            noise_scale: 1.0,
            nobs: vec![0.0; od],
            mean: vec![0.0; ad],
            scratch: Vec::new(),
        }
    }

    /// A stored policy acting and recording as `acting` says, its sampled deviations scaled
    /// by `noise_scale`.
    pub fn with(policy: &ActorCritic, acting: Acting, noise_scale: f64) -> Self {
        let mut a = PolicyActor::new(policy.to_cpu(), acting != Acting::Mean);
        a.mean_labels = acting == Acting::SampledMeanLabels;
        a.noise_scale = noise_scale as f32;
        a
    }

    /// How a stored policy acts: PPO policies (with a critic) sample, BC policies act with
    /// their mean.
    pub fn acting(policy: &ActorCritic) -> Self {
        PolicyActor::new(policy.to_cpu(), policy.critic.is_some())
    }

    /// The policy's mean action, whatever kind it is (the base of injected noise).
    pub fn mean_of(policy: &ActorCritic) -> Self {
        PolicyActor::new(policy.to_cpu(), false)
    }
}

impl Actor for PolicyActor {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        self.policy.normalize(obs, &mut self.nobs);
        self.policy.mean(&self.nobs, &mut self.mean, &mut self.scratch);
        if self.stochastic {
            self.policy.sample(&self.mean, rng, out);
            if self.noise_scale != 1.0 {
                for (o, &m) in out.iter_mut().zip(&self.mean) {
                    *o = m + self.noise_scale * (*o - m);
                }
            }
        } else {
            out.copy_from_slice(&self.mean);
        }
    }
    fn label(&self) -> Option<&[f32]> {
        self.mean_labels.then_some(&self.mean[..])
    }
}

/// Uniform actions in the box. Used alone and as the random part of epsilon-greedy.
#[derive(Debug, Clone)]
pub struct UniformActor {
    pub low: Vec<f64>,
    pub high: Vec<f64>,
}

impl UniformActor {
    pub fn of(env: &Env) -> Self {
        let (low, high) = env.action_bounds();
        UniformActor { low: low.to_vec(), high: high.to_vec() }
    }
}

impl Actor for UniformActor {
    fn act(&mut self, _obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        for ((o, &l), &h) in out.iter_mut().zip(&self.low).zip(&self.high) {
            *o = rng.random_range(l..h) as f32;
        }
    }
}
