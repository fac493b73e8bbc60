//! `idrex bench env`: environment throughput, each figure next to a baseline measured in the
//! same run: the raw mj_step rate of the same model over the same transitions, Gymnasium's
//! Python environment (run by the same command), and one thread for the vectorised env.
use std::time::Instant;

use anyhow::Context;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::env::{Env, EnvId, VecEnv};

#[derive(Debug, clap::Args)]
pub struct EnvBenchArgs {
    /// Environments to measure (default: all).
    #[arg(long = "env")]
    pub envs: Vec<EnvId>,
    /// Steps per measurement.
    #[arg(long, default_value_t = 50_000)]
    pub steps: usize,
    /// Environments in the vectorised measurement.
    #[arg(long, default_value_t = 8)]
    pub num_envs: usize,
    /// Threads for the parallel vectorised measurement.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Python with `gymnasium[mujoco]` for the Gymnasium baseline; "none" skips it.
    #[arg(long)]
    pub python: Option<String>,
    /// Python with EnvPool 1.2.5 (`analysis/envpool/env.sh` prints it): measure EnvPool's
    /// environments beside idrex's, one and in batches of 8 and 64 on one and two threads.
    #[arg(long, value_name = "PYTHON")]
    pub envpool: Option<String>,
    /// Alternating passes per side in the EnvPool comparison (each ratio is of medians).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Print the results as one JSON object per environment.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, serde::Serialize)]
pub struct EnvBench {
    pub env: String,
    pub frame_skip: usize,
    /// mj_step calls per second over the same transitions as `env_steps_per_s`.
    pub mj_steps_per_s: f64,
    /// mj_steps_per_s / frame_skip: the most env steps/s the simulator allows.
    pub mj_bound_env_steps_per_s: f64,
    pub env_steps_per_s: f64,
    pub env_vs_mj_bound: f64,
    pub vec_1_thread_steps_per_s: f64,
    pub vec_n_threads_steps_per_s: f64,
    pub vec_threads: usize,
    pub vec_speedup: f64,
    pub gymnasium_steps_per_s: Option<f64>,
    pub env_vs_gymnasium: Option<f64>,
}

pub(super) fn random_actions(n: usize, width: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| (0..width).map(|_| rng.random_range(-1.0..1.0)).collect()).collect()
}

/// Steps one env through `actions`, resetting on episode end; returns steps/s and where the
/// episodes ended, so that the raw pass can replay exactly the same transitions.
pub(super) fn env_pass(env: &mut Env, actions: &[Vec<f64>]) -> (f64, Vec<usize>) {
    let mut obs = vec![0.0; env.obs_dim()];
    let mut ends = Vec::new();
    env.reset(Some(0), &mut obs);
    let start = Instant::now();
    for (t, a) in actions.iter().enumerate() {
        let info = env.step(a, &mut obs).expect("action width checked by construction");
        if info.terminated || info.truncated {
            ends.push(t);
            env.reset(None, &mut obs);
        }
    }
    (actions.len() as f64 / start.elapsed().as_secs_f64(), ends)
}

pub(super) fn raw_pass(env: &mut Env, actions: &[Vec<f64>], ends: &[usize]) -> f64 {
    let mut obs = vec![0.0; env.obs_dim()];
    env.reset(Some(0), &mut obs);
    let mut next_end = ends.iter().peekable();
    let start = Instant::now();
    for (t, a) in actions.iter().enumerate() {
        env.raw_step(a);
        if next_end.peek() == Some(&&t) {
            next_end.next();
            env.reset(None, &mut obs);
        }
    }
    (actions.len() * env.spec().frame_skip) as f64 / start.elapsed().as_secs_f64()
}

pub(super) fn vec_pass(id: EnvId, n: usize, threads: usize, steps: usize) -> anyhow::Result<f64> {
    let mut v = VecEnv::new(id, n, 0, threads)?;
    let actions: Vec<f32> = random_actions(steps / n, n * v.act_dim(), 1).concat().into_iter().map(|x| x as f32).collect();
    let start = Instant::now();
    for row in actions.chunks(n * v.act_dim()) {
        v.step(row)?;
    }
    Ok((steps / n * n) as f64 / start.elapsed().as_secs_f64())
}

fn gymnasium_pass(python: &str, id: EnvId, steps: usize) -> anyhow::Result<f64> {
    let out = super::scripts::Script::GymBench.run(python, &["--env", id.name(), "--steps", &steps.to_string()].map(String::from))?;
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    v["steps_per_s"].as_f64().context("gym_bench.py printed no steps_per_s")
}

pub fn default_python() -> Option<String> {
    let built = env!("IDREX_BUILD_PYTHON");
    (!built.is_empty()).then(|| built.to_string())
}

pub fn measure_env(id: EnvId, args: &EnvBenchArgs) -> anyhow::Result<EnvBench> {
    let mut env = Env::new(id)?;
    let actions = random_actions(args.steps, env.act_dim(), 0);
    // Warm-up: page in the model and let the CPU clock settle.
    env_pass(&mut env, &actions[..args.steps.min(2000)]);
    let (env_rate, ends) = env_pass(&mut env, &actions);
    let mj_rate = raw_pass(&mut env, &actions, &ends);
    let frame_skip = env.spec().frame_skip;
    let bound = mj_rate / frame_skip as f64;
    // Alternate one-thread and n-thread passes and keep the medians: on a shared machine a
    // single pair of short passes swings by +-20 %.
    let (mut v1, mut vn) = (Vec::new(), Vec::new());
    for _ in 0..5 {
        v1.push(vec_pass(id, args.num_envs, 1, args.steps)?);
        vn.push(vec_pass(id, args.num_envs, args.threads, args.steps)?);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (vec1, vecn) = (median(&mut v1), median(&mut vn));
    let python = args.python.clone().or_else(default_python).filter(|p| p != "none");
    let gym = match python {
        Some(p) => Some(gymnasium_pass(&p, id, args.steps.min(20_000))?),
        None => None,
    };

    Ok(EnvBench {
        env: id.name().into(),
        frame_skip,
        mj_steps_per_s: mj_rate,
        mj_bound_env_steps_per_s: bound,
        env_steps_per_s: env_rate,
        env_vs_mj_bound: env_rate / bound,
        vec_1_thread_steps_per_s: vec1,
        vec_n_threads_steps_per_s: vecn,
        vec_threads: args.threads,
        vec_speedup: vecn / vec1,
        gymnasium_steps_per_s: gym,
        env_vs_gymnasium: gym.map(|g| env_rate / g),
    })
}

/// The environments a run measures: those named, else all.
pub fn ids(args: &EnvBenchArgs) -> Vec<EnvId> {
    if args.envs.is_empty() { EnvId::TASKS.to_vec() } else { args.envs.clone() }
}

/// The table of idrex's environments against mj_step and Gymnasium.
pub fn table(args: &EnvBenchArgs) -> anyhow::Result<()> {
    let ids = ids(args);
    if !args.json {
        println!(
            "| env | mj_step/s | mj-bound env steps/s | env steps/s (1 thread) | vs bound | vec {n} envs, 1 thread | vec, {t} threads | speed-up | Gymnasium steps/s | vs Gymnasium |",
            n = args.num_envs,
            t = args.threads
        );
        println!("|---|---|---|---|---|---|---|---|---|---|");
    }
    for id in ids {
        let b = {
            // Cleared before the row is printed.
            let _measuring = crate::log::progress::Activity::start(format!("bench env: {}", id.name()));
            measure_env(id, args)?
        };
        if args.json {
            println!("{}", serde_json::to_string(&b)?);
        } else {
            let opt = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map_or("-".to_string(), f);
            println!(
                "| {} | {:.0} | {:.0} | {:.0} | {:.1} % | {:.0} | {:.0} | {:.2}x | {} | {} |",
                b.env,
                b.mj_steps_per_s,
                b.mj_bound_env_steps_per_s,
                b.env_steps_per_s,
                100.0 * b.env_vs_mj_bound,
                b.vec_1_thread_steps_per_s,
                b.vec_n_threads_steps_per_s,
                b.vec_speedup,
                opt(b.gymnasium_steps_per_s, &|g| format!("{g:.0}")),
                opt(b.env_vs_gymnasium, &|r| format!("{r:.1}x")),
            );
        }
    }
    Ok(())
}
