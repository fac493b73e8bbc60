//! N environments stepped together, in parallel over a thread budget, with auto-reset.
//!
//! Layout follows the learners: observations are one `(n, obs_dim)` f32 buffer, actions one
//! `(n, act_dim)` f32 buffer. When an episode ends (terminated or truncated) the environment
//! is reset at once and `obs` holds the first observation of the next episode; the last
//! observation of the finished one is kept in `final_obs`, which PPO needs to bootstrap a
//! truncated episode.
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

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
    pool: Option<SpinPool>,
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
        // The caller is one of the `threads`.
        let pool = (threads > 1 && n > 1).then(|| SpinPool::new((threads - 1).min(n - 1)));
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

    /// Where every environment's episodes end from now on ([`super::Horizon`]).
    pub fn set_horizon(&mut self, horizon: super::Horizon) {
        self.slots.iter_mut().for_each(|s| s.env.set_horizon(horizon));
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
        match &self.pool {
            Some(pool) => {
                // One contiguous chunk per thread; the caller steps the first chunk itself.
                let per = self.slots.len().div_ceil(pool.len() + 1);
                let mut chunks = self.slots.chunks_mut(per).zip(actions.chunks(per * act_dim));
                let first = chunks.next().expect("at least one environment");
                pool.run(chunks.collect(), act_dim, || step_chunk(first.0, first.1, act_dim));
            }
            None => step_chunk(&mut self.slots, actions, act_dim),
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

/// Worker threads that wait for the next step by spinning briefly before parking. An env
/// step takes 20-80 us; waking a sleeping thread through the kernel costs a comparable
/// time, which held a rayon pool to 1.25-1.6x on two cores.
struct SpinPool {
    workers: Vec<Worker>,
}

struct Job {
    slots: *mut Slot,
    len: usize,
    actions: *const f32,
    act_dim: usize,
}

struct WorkerShared {
    /// Incremented by the caller for each job; the worker answers by setting `done` to it.
    generation: AtomicU64,
    done: AtomicU64,
    stop: AtomicBool,
    /// Set when the last job panicked; the caller re-raises it.
    panicked: AtomicBool,
    job: std::sync::Mutex<Option<Job>>,
}

// SAFETY: a Job's pointers are only dereferenced by the worker between `generation` being
// bumped and `done` being set, while the caller is blocked in `SpinPool::run` holding the
// exclusive borrows they came from.
#[allow(unsafe_code)]
unsafe impl Send for Job {}

struct Worker {
    shared: Arc<WorkerShared>,
    handle: Option<std::thread::JoinHandle<()>>,
}

const SPINS: u32 = 100_000;

impl SpinPool {
    #[allow(unsafe_code)] // the workers read the slices a `Job` points at
    fn new(n: usize) -> Self {
        let workers = (0..n)
            .map(|_| {
                let shared = Arc::new(WorkerShared {
                    generation: AtomicU64::new(0),
                    done: AtomicU64::new(0),
                    stop: AtomicBool::new(false),
                    panicked: AtomicBool::new(false),
                    job: std::sync::Mutex::new(None),
                });
                let s = shared.clone();
                let handle = std::thread::spawn(move || {
                    let mut seen = 0;
                    loop {
                        let mut spins = 0;
                        while s.generation.load(Ordering::Acquire) == seen {
                            if s.stop.load(Ordering::Relaxed) {
                                return;
                            }
                            if spins < SPINS {
                                spins += 1;
                                std::hint::spin_loop();
                            } else {
                                std::thread::park_timeout(std::time::Duration::from_millis(1));
                            }
                        }
                        seen = s.generation.load(Ordering::Acquire);
                        if let Some(job) = s.job.lock().unwrap_or_else(|e| e.into_inner()).take() {
                            // SAFETY: see `Job`.
                            let slots = unsafe { std::slice::from_raw_parts_mut(job.slots, job.len) };
                            let acts = unsafe { std::slice::from_raw_parts(job.actions, job.len * job.act_dim) };
                            // A panic must still answer, or the caller would spin forever.
                            let ok =
                                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| step_chunk(slots, acts, job.act_dim))).is_ok();
                            s.panicked.store(!ok, Ordering::Relaxed);
                        }
                        s.done.store(seen, Ordering::Release);
                    }
                });
                Worker { shared, handle: Some(handle) }
            })
            .collect();
        SpinPool { workers }
    }

    fn len(&self) -> usize {
        self.workers.len()
    }

    /// Hands one chunk to each worker, runs `own` on the caller, and returns when all are done.
    fn run(&self, chunks: Vec<(&mut [Slot], &[f32])>, act_dim: usize, own: impl FnOnce()) {
        let mut started = Vec::new();
        for (w, (slots, acts)) in self.workers.iter().zip(chunks) {
            *w.shared.job.lock().unwrap_or_else(|e| e.into_inner()) =
                Some(Job { slots: slots.as_mut_ptr(), len: slots.len(), actions: acts.as_ptr(), act_dim });
            let g = w.shared.generation.fetch_add(1, Ordering::AcqRel) + 1;
            if let Some(h) = &w.handle {
                h.thread().unpark();
            }
            started.push((w, g));
        }
        own();
        for (w, g) in started {
            while w.shared.done.load(Ordering::Acquire) != g {
                std::hint::spin_loop();
            }
            assert!(!w.shared.panicked.load(Ordering::Relaxed), "an environment worker thread panicked while stepping");
        }
    }
}

impl Drop for SpinPool {
    fn drop(&mut self) {
        for w in &mut self.workers {
            w.shared.stop.store(true, Ordering::Relaxed);
            if let Some(h) = w.handle.take() {
                h.thread().unpark();
                let _ = h.join();
            }
        }
    }
}

/// Steps each slot with its row of `actions`.
fn step_chunk(slots: &mut [Slot], actions: &[f32], act_dim: usize) {
    for (s, a) in slots.iter_mut().zip(actions.chunks(act_dim)) {
        for (dst, &src) in s.action.iter_mut().zip(a) {
            *dst = src as f64;
        }
        s.info = s.env.step_unchecked(&s.action, &mut s.obs);
        s.episode_return += s.info.reward;
        s.episode_len += 1;
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
