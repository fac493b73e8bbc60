//! The one rollout loop shared by noise rollouts, demonstrations and evaluation: any
//! [`Actor`] in one environment, full episodes, actions clipped to the box before the step
//! (Gymnasium's ClipAction, as CleanRL and SB3 use).
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::data::{TrajMeta, Trajectory};
use crate::env::Env;

/// Anything that maps an observation to an action.
pub trait Actor {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]);
    /// Called at the start of every episode (noise processes restart here).
    fn reset(&mut self) {}
}

/// One full episode from a seeded reset; the actor's randomness is seeded from `seed` too.
pub fn episode(env: &mut Env, actor: &mut dyn Actor, seed: u64, meta: TrajMeta) -> Trajectory {
    let (od, ad) = (env.obs_dim(), env.act_dim());
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
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
        t.actions.extend_from_slice(&a32);
        t.rewards.push(info.reward);
        t.terms.push(info.terms);
        if info.terminated || info.truncated {
            t.terminated = info.terminated;
            t.truncated = info.truncated;
            return t;
        }
    }
}

/// Mean, std, min and max of a set of returns.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReturnStats {
    pub mean: f64,
    pub std: f64,
    pub min: f64,
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
