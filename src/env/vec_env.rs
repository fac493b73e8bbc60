//! N environments stepped together, in parallel over a thread budget, with auto-reset.
//!
//! Layout follows the learners: observations are one `(n, obs_dim)` f32 buffer, actions one
//! `(n, act_dim)` f32 buffer. When an episode ends (terminated or truncated) the environment
//! is reset at once and `obs` holds the first observation of the next episode; the last
//! observation of the finished one is kept in `final_obs`, which PPO needs to bootstrap a
//! truncated episode.
use std::sync::Arc;

use rayon::prelude::*;

use super::{Env, EnvId, StepInfo};
use crate::error::{Error, Result};

struct Slot {
    env: Env,
    action: Vec<f64>,
    obs: Vec<f64>,
    info: StepInfo,
    episode_return: f64,
    episode_len: usize,
}

/// A finished episode: which environment, its undiscounted return and its length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Episode {
    pub env: usize,
    pub ret: f64,
    pub len: usize,
}

/// What one vectorised step returns; every vector has one entry per environment.
#[derive(Debug, Default)]
pub struct VecStep {
    pub obs: Vec<f32>,
    pub rewards: Vec<f64>,
    pub infos: Vec<StepInfo>,
    pub terminated: Vec<bool>,
    pub truncated: Vec<bool>,
    /// For each environment whose episode ended this step, its last observation.
    pub final_obs: Vec<Option<Vec<f32>>>,
    pub episodes: Vec<Episode>,
}

pub struct VecEnv {
    slots: Vec<Slot>,
    pool: Option<rayon::ThreadPool>,
    obs_dim: usize,
    act_dim: usize,
    out: VecStep,
}

impl VecEnv {
    /// `n` copies of `id` on one shared model; environment i is seeded with `seed + i`.
    /// `threads` is the thread budget (1 steps them in the caller's thread).
    pub fn new(id: EnvId, n: usize, seed: u64, threads: usize) -> Result<Self> {
        let model = super::load_model(id, None)?;
        Self::with_model(id, model, n, seed, threads)
    }

    pub fn with_model(id: EnvId, model: Arc<mujoco_rs::prelude::MjModel>, n: usize, seed: u64, threads: usize) -> Result<Self> {
        if n == 0 {
            return Err(Error::Invalid("a vectorised environment needs at least one environment".into()));
        }
        let slots: Vec<Slot> = (0..n)
            .map(|_| {
                let env = Env::with_model(id, model.clone());
                Slot {
                    action: vec![0.0; env.act_dim()],
                    obs: vec![0.0; env.obs_dim()],
                    env,
                    info: StepInfo::default(),
                    episode_return: 0.0,
                    episode_len: 0,
                }
            })
            .collect();
        let (obs_dim, act_dim) = (slots[0].env.obs_dim(), slots[0].env.act_dim());
        let pool = if threads > 1 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads.min(n))
                    .build()
                    .map_err(|e| Error::Invalid(format!("cannot start {threads} threads: {e}")))?,
            )
        } else {
            None
        };
        let mut v = VecEnv { slots, pool, obs_dim, act_dim, out: VecStep::default() };
        v.reset(seed);
        Ok(v)
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }
    pub fn env(&self, i: usize) -> &Env {
        &self.slots[i].env
    }

    /// Reseeds every environment (i gets `seed + i`) and returns the first observations.
    pub fn reset(&mut self, seed: u64) -> &[f32] {
        for (i, s) in self.slots.iter_mut().enumerate() {
            s.env.reset(Some(seed.wrapping_add(i as u64)), &mut s.obs);
            s.episode_return = 0.0;
            s.episode_len = 0;
        }
        let n = self.slots.len();
        self.out = VecStep {
            obs: vec![0.0; n * self.obs_dim],
            rewards: vec![0.0; n],
            infos: vec![StepInfo::default(); n],
            terminated: vec![false; n],
            truncated: vec![false; n],
            final_obs: vec![None; n],
            episodes: Vec::new(),
        };
        for (chunk, s) in self.out.obs.chunks_mut(self.obs_dim).zip(&self.slots) {
            to_f32(&s.obs, chunk);
        }
        &self.out.obs
    }

    /// The current observations, `(n, obs_dim)`.
    pub fn obs(&self) -> &[f32] {
        &self.out.obs
    }

    /// Steps every environment with its row of `actions` (`(n, act_dim)`).
    pub fn step(&mut self, actions: &[f32]) -> Result<&VecStep> {
        if actions.len() != self.slots.len() * self.act_dim {
            return Err(Error::Shape {
                what: "vectorised actions".into(),
                expected: self.slots.len() * self.act_dim,
                got: actions.len(),
                hint: format!(" ({} environments x {} action dims)", self.slots.len(), self.act_dim),
            });
        }
        let act_dim = self.act_dim;
        let step_one = |(s, a): (&mut Slot, &[f32])| {
            for (dst, &src) in s.action.iter_mut().zip(a) {
                *dst = src as f64;
            }
            s.info = s.env.step_unchecked(&s.action, &mut s.obs);
            s.episode_return += s.info.reward;
            s.episode_len += 1;
        };
        match &self.pool {
            Some(pool) => pool.install(|| self.slots.par_iter_mut().zip(actions.par_chunks(act_dim)).for_each(step_one)),
            None => self.slots.iter_mut().zip(actions.chunks(act_dim)).for_each(step_one),
        }
        let out = &mut self.out;
        out.episodes.clear();
        for (i, s) in self.slots.iter_mut().enumerate() {
            let row = &mut out.obs[i * self.obs_dim..(i + 1) * self.obs_dim];
            to_f32(&s.obs, row);
            out.rewards[i] = s.info.reward;
            out.infos[i] = s.info;
            out.terminated[i] = s.info.terminated;
            out.truncated[i] = s.info.truncated;
            out.final_obs[i] = None;
            if s.info.terminated || s.info.truncated {
                out.final_obs[i] = Some(row.to_vec());
                out.episodes.push(Episode { env: i, ret: s.episode_return, len: s.episode_len });
                s.episode_return = 0.0;
                s.episode_len = 0;
                s.env.reset(None, &mut s.obs);
                to_f32(&s.obs, row);
            }
        }
        Ok(&self.out)
    }
}

fn to_f32(src: &[f64], dst: &mut [f32]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = s as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_reset_keeps_the_final_observation() {
        let mut v = VecEnv::new(EnvId::Hopper, 3, 1, 2).unwrap();
        // Full torque on every joint makes the hopper fall within a few dozen steps.
        let actions = vec![1.0f32; 3 * 3];
        let mut ended = None;
        for _ in 0..300 {
            let out = v.step(&actions).unwrap();
            if let Some(i) = out.terminated.iter().position(|&t| t) {
                ended = Some((i, out.final_obs[i].clone().unwrap(), out.obs[i * 11..(i + 1) * 11].to_vec()));
                break;
            }
        }
        let (i, final_obs, new_obs) = ended.expect("the hopper should fall");
        assert_ne!(final_obs, new_obs);
        // The new episode starts near qpos0 (z = 1.25); the fallen one is below 0.7 or tilted.
        assert!((new_obs[0] - 1.25).abs() < 0.01, "{new_obs:?}");
        assert_eq!(v.env(i).elapsed_steps(), 0);
    }

    #[test]
    fn parallel_and_serial_stepping_agree() {
        let mut a = VecEnv::new(EnvId::HalfCheetah, 4, 3, 1).unwrap();
        let mut b = VecEnv::new(EnvId::HalfCheetah, 4, 3, 2).unwrap();
        let actions: Vec<f32> = (0..24).map(|i| ((i * 7 % 11) as f32 / 5.0) - 1.0).collect();
        for _ in 0..50 {
            let oa = a.step(&actions).unwrap().obs.clone();
            let ob = b.step(&actions).unwrap().obs.clone();
            assert_eq!(oa, ob);
        }
    }
}
