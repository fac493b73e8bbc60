//! `idrex bench env`: environment throughput, each figure next to a baseline measured in the
//! same run: the raw mj_step rate of the same model over the same transitions, Gymnasium's
//! Python environment (run by the same command), and one thread for the vectorised env.
pub mod clones;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::env::{Env, EnvId, VecEnv};
use crate::nn::{Device, DeviceChoice};

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
    /// Python with gymnasium[mujoco] for the Gymnasium baseline; "none" skips it.
    #[arg(long)]
    pub python: Option<String>,
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

fn random_actions(n: usize, width: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| (0..width).map(|_| rng.random_range(-1.0..1.0)).collect()).collect()
}

/// Steps one env through `actions`, resetting on episode end; returns steps/s and where the
/// episodes ended, so that the raw pass can replay exactly the same transitions.
fn env_pass(env: &mut Env, actions: &[Vec<f64>]) -> (f64, Vec<usize>) {
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

fn raw_pass(env: &mut Env, actions: &[Vec<f64>], ends: &[usize]) -> f64 {
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

fn vec_pass(id: EnvId, n: usize, threads: usize, steps: usize) -> anyhow::Result<f64> {
    let mut v = VecEnv::new(id, n, 0, threads)?;
    let actions: Vec<f32> = random_actions(steps / n, n * v.act_dim(), 1).concat().into_iter().map(|x| x as f32).collect();
    let start = Instant::now();
    for row in actions.chunks(n * v.act_dim()) {
        v.step(row)?;
    }
    Ok((steps / n * n) as f64 / start.elapsed().as_secs_f64())
}

fn gymnasium_pass(python: &str, id: EnvId, steps: usize) -> anyhow::Result<f64> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("analysis/gym_bench.py");
    let out = std::process::Command::new(python)
        .arg(&script)
        .args(["--env", id.name(), "--steps", &steps.to_string()])
        .output()
        .with_context(|| format!("cannot run {python} {}", script.display()))?;
    if !out.status.success() {
        anyhow::bail!("{} failed: {}", script.display(), String::from_utf8_lossy(&out.stderr));
    }
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

pub fn env_bench(args: &EnvBenchArgs) -> anyhow::Result<()> {
    let ids = if args.envs.is_empty() { EnvId::ALL.to_vec() } else { args.envs.clone() };
    if !args.json {
        println!(
            "| env | mj_step/s | mj-bound env steps/s | env steps/s (1 thread) | vs bound | vec {n} envs, 1 thread | vec, {t} threads | speed-up | Gymnasium steps/s | vs Gymnasium |",
            n = args.num_envs,
            t = args.threads
        );
        println!("|---|---|---|---|---|---|---|---|---|---|");
    }
    for id in ids {
        let b = measure_env(id, args)?;
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

#[derive(Debug, clap::Args)]
pub struct TrexBenchArgs {
    /// A trained policy directory (policy.safetensors + policy.json).
    #[arg(long)]
    pub policy: PathBuf,
    /// Training rollouts per epsilon level (D-REX: 5).
    #[arg(long, default_value_t = 5)]
    pub per_level: usize,
    /// Held-out rollouts per epsilon level.
    #[arg(long, default_value_t = 2)]
    pub held_out_per_level: usize,
    /// T-REX iterations per model (D-REX: 3000).
    #[arg(long, default_value_t = 3000)]
    pub iterations: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where T-REX trains (`auto`: the GPU where libtorch sees one).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Auto)]
    pub device: DeviceChoice,
}

/// Epsilon-greedy rollouts of `policy` at D-REX's 20 levels, `per_level` each: the
/// pipeline's own noise-rollout helper, so bench and pipeline figures are comparable.
fn eps_rollouts(env: &mut Env, policy: &crate::nn::ActorCritic, per_level: usize, seed: u64) -> Vec<crate::data::Trajectory> {
    let schedule: Vec<f64> = (0..20).map(|level| level as f64 * 0.05).collect();
    let meta = crate::data::TrajMeta { source: "bench".into(), ..Default::default() };
    crate::rollout::epsilon_greedy(env, policy, &schedule, per_level, seed, &meta)
}

pub fn trex_bench(args: &TrexBenchArgs) -> anyhow::Result<()> {
    use crate::{algo::trex, stats};
    let policy = crate::nn::ActorCritic::load(&args.policy)?;
    let id: EnvId = policy.env.clone().context("the policy does not name its environment")?.parse()?;
    let mut env = Env::new(id)?;
    let train = eps_rollouts(&mut env, &policy, args.per_level, args.seed);
    let held = eps_rollouts(&mut env, &policy, args.held_out_per_level, args.seed + 1);
    let cfg = trex::TrexConfig { iterations: args.iterations, ..Default::default() };
    let ranking = trex::Ranking::by_score(train.iter().map(|t| -t.meta.noise).collect());
    let device = args.device.resolve();
    let start = Instant::now();
    let (model, reports) =
        trex::train(&train, &ranking, &cfg, args.seed, std::thread::available_parallelism().map_or(1, |n| n.get()), device)?;
    let secs = start.elapsed().as_secs_f64();
    let pred: Vec<f64> = held.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
    let truth: Vec<f64> = held.iter().map(|t| t.ret()).collect();
    let out = serde_json::json!({
        "env": id.name(), "device": device.name(), "train_trajectories": train.len(), "held_out_trajectories": held.len(),
        "models": cfg.models, "iterations": cfg.iterations, "train_s": secs,
        "iterations_per_s": (cfg.models * cfg.iterations) as f64 / secs,
        "val_accuracy": reports.iter().map(|r| r.val_accuracy).collect::<Vec<_>>(),
        "held_out_spearman": stats::spearman(&pred, &truth), "held_out_pearson": stats::pearson(&pred, &truth),
        "held_out_pairwise_accuracy": stats::pairwise_accuracy(&pred, &truth),
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct LearnersBenchArgs {
    /// Threads for both sides (idrex's T-REX members, libtorch and PyTorch).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// T-REX iterations per model (idrex is timed at N and 2N; the difference is the rate).
    #[arg(long, default_value_t = 150)]
    pub trex_iterations: usize,
    /// BC iterations (idrex is timed at N and 2N likewise).
    #[arg(long, default_value_t = 1500)]
    pub bc_iterations: usize,
    /// Python with torch for the baseline (default: the bootstrap environment's; "none" skips it).
    #[arg(long)]
    pub python: Option<String>,
    /// Where idrex's learners and the PyTorch loop run (`auto`: the GPU where libtorch sees
    /// one; on the GPU, idrex's CPU learners are measured too, as the figure to beat).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Auto)]
    pub device: DeviceChoice,
}

/// Synthetic HalfCheetah-sized rollouts (17-dim observations, 6-dim actions): `n` episodes of
/// `len` steps at D-REX's 20 noise levels, ranked by noise.
fn synthetic(n: usize, len: usize, seed: u64) -> Vec<crate::data::Trajectory> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (od, ad) = (17, 6);
    (0..n)
        .map(|k| crate::data::Trajectory {
            obs_dim: od,
            act_dim: ad,
            obs: (0..(len + 1) * od).map(|_| rng.random_range(-1.0..1.0f32)).collect(),
            actions: (0..len * ad).map(|_| rng.random_range(-1.0..1.0f32)).collect(),
            rewards: vec![0.0; len],
            terms: vec![Default::default(); len],
            terminated: false,
            truncated: true,
            meta: crate::data::TrajMeta { source: "bench".into(), noise: (k % 20) as f64 * 0.05, seed: k as u64, group: 0 },
        })
        .collect()
}

/// FLOPs of one model-iteration of T-REX at the report's shapes (64 pairs x 2 windows x 50
/// steps through 17-256-256-1; backward counted as twice the forward).
const TREX_FLOP: f64 = 3.0 * 2.0 * (64.0 * 2.0 * 50.0) * (17.0 * 256.0 + 256.0 * 256.0 + 256.0);
/// FLOPs of one BC iteration (128 samples through 17-256-256-256-256-6).
const BC_FLOP: f64 = 3.0 * 2.0 * 128.0 * (17.0 * 256.0 + 3.0 * 256.0 * 256.0 + 256.0 * 6.0);

/// The attainable fp32 rate of `device` (on `threads` threads on the CPU): libtorch's
/// 2048 x 2048 matrix product (MKL/oneDNN) on the CPU, 8192 x 8192 (cuBLAS, TF32 off, as
/// libtorch's default) on the GPU; best of 5.
fn gemm_gflops(threads: usize, device: Device) -> f64 {
    tch::set_num_threads(threads as i32);
    let n = if device.is_cpu() { 2048 } else { 8192 };
    let a = tch::Tensor::randn([n, n], (tch::Kind::Float, device.tch()));
    let b = tch::Tensor::randn([n, n], (tch::Kind::Float, device.tch()));
    let sync = || {
        if !device.is_cpu() {
            tch::Cuda::synchronize(0);
        }
    };
    let _ = a.matmul(&b);
    sync();
    let best = (0..5)
        .map(|_| {
            let t = Instant::now();
            let _ = a.matmul(&b);
            sync();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    crate::nn::single_threaded();
    2.0 * (n as f64).powi(3) / best / 1e9
}

/// One thread's matrix-product rate at T-REX's hidden layer (a chunk of 200 rows through
/// 256 x 256), in GFLOP/s, best of 5: idrex's kernel (`nn::gemm`, the active variant) and
/// libtorch's (MKL's) on the same operands.
fn hidden_layer_gflops() -> (f64, f64) {
    let (m, n, k) = (200usize, 256usize, 256usize);
    let a: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.37).sin()).collect();
    let b: Vec<f32> = (0..k * n).map(|i| (i as f32 * 0.91).cos()).collect();
    let mut c = vec![0.0f32; m * n];
    let reps = 200;
    let flop = 2.0 * (m * n * k * reps) as f64;
    let best = |f: &mut dyn FnMut()| {
        f();
        (0..5)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let ours = best(&mut || (0..reps).for_each(|_| crate::nn::gemm::gemm(false, false, m, n, k, &a, k, &b, n, 0.0, &mut c, n)));
    crate::nn::single_threaded();
    let (ta, tb) = (tch::Tensor::from_slice(&a).view([m as i64, k as i64]), tch::Tensor::from_slice(&b).view([k as i64, n as i64]));
    let torch = best(&mut || (0..reps).for_each(|_| _ = ta.matmul(&tb)));
    (flop / ours / 1e9, flop / torch / 1e9)
}

/// The learned reward's inference, as PPO calls it once per rollout (2,048 rows of
/// HalfCheetah's 17-dimensional observations through 3 models of [256, 256]), in rows per
/// second, best of 5: idrex's CPU path (`RewardEnsemble::raw`, over `nn::gemm`) and
/// libtorch's forward pass on the same networks and rows.
fn reward_inference_rates() -> (f64, f64) {
    use crate::nn::reward::{RewardConfig, RewardEnsemble};
    let config = RewardConfig { obs_dim: 17, act_dim: None, hidden: vec![256, 256], models: 3, clip: 100.0, init: Default::default() };
    let model = crate::nn::seeded(0, || RewardEnsemble::new(config));
    let rows = 2048;
    let obs: Vec<f32> = (0..rows * 17).map(|i| (i as f32 * 0.37).sin()).collect();
    let best = |f: &mut dyn FnMut()| {
        f();
        (0..5)
            .map(|_| {
                let t = Instant::now();
                (0..10).for_each(|_| f());
                t.elapsed().as_secs_f64() / 10.0
            })
            .fold(f64::INFINITY, f64::min)
    };
    crate::nn::single_threaded();
    let ours = best(&mut || _ = model.raw(&obs, &[]));
    let torch = best(&mut || {
        tch::no_grad(|| {
            let x = model.inputs(&obs, &[]);
            for m in 0..3 {
                let _: Vec<f32> = Vec::try_from(model.forward(m, &x)).expect("f32 rewards");
            }
        })
    });
    (rows as f64 / ours, rows as f64 / torch)
}

/// The seconds that n more iterations take: time(f(2n)) - time(f(n)), which leaves out the
/// fixed costs (pair sampling, the final accuracy pass) the Python loop does not have.
fn marginal(n: usize, mut f: impl FnMut(usize) -> anyhow::Result<()>) -> anyhow::Result<f64> {
    let t = Instant::now();
    f(n)?;
    let once = t.elapsed().as_secs_f64();
    let t = Instant::now();
    f(2 * n)?;
    Ok((t.elapsed().as_secs_f64() - once).max(1e-9))
}

/// idrex's T-REX (model-iterations/s) and BC (iterations/s) rates on `device`.
fn learner_rates(args: &LearnersBenchArgs, threads: usize, device: Device) -> anyhow::Result<(f64, f64)> {
    use crate::algo::{bc, trex};
    // T-REX: 100 episodes of 1000 steps, 3 members on `threads` workers.
    let trajs = synthetic(100, 1000, 0);
    let ranking = trex::Ranking::by_score(trajs.iter().map(|t| -t.meta.noise).collect());
    crate::nn::single_threaded();
    let trex_s = marginal(args.trex_iterations, |n| {
        let cfg = trex::TrexConfig { iterations: n, ..Default::default() };
        trex::train(&trajs, &ranking, &cfg, 0, threads, device).map(|_| ()).map_err(Into::into)
    })?;
    // BC: one 1000-step demonstration, on `threads` threads as the PyTorch side gets (the
    // pipeline gives it the stage's share of the cores).
    let demo = synthetic(1, 1000, 1);
    let bc_s = marginal(args.bc_iterations, |n| {
        let cfg = bc::BcConfig { iterations: n, ..Default::default() };
        bc::train(&demo, &cfg, 0, threads, device).map(|_| ()).map_err(Into::into)
    })?;
    Ok(((3 * args.trex_iterations) as f64 / trex_s, args.bc_iterations as f64 / bc_s))
}

pub fn learners_bench(args: &LearnersBenchArgs) -> anyhow::Result<()> {
    let threads = args.threads.max(1);
    let device = args.device.resolve();
    device.ensure_available()?;
    let peak = gemm_gflops(threads, device);
    let (kernel_gflops, libtorch_gflops) = hidden_layer_gflops();
    let (reward_rows, torch_reward_rows) = reward_inference_rates();
    let (trex_rate, bc_rate) = learner_rates(args, threads, device)?;
    // On the GPU, the CPU learners are the figure to beat.
    let cpu = if device.is_cpu() { None } else { Some(learner_rates(args, threads, Device::Cpu)?) };
    let python = args.python.clone().or_else(default_python).filter(|p| p != "none");
    let torch: Option<serde_json::Value> = match &python {
        None => None,
        Some(py) => {
            let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("analysis/bench_learners.py");
            let out = std::process::Command::new(py)
                .arg(&script)
                .args(["--threads", &threads.to_string()])
                .args(["--trex-iterations", &args.trex_iterations.to_string()])
                .args(["--bc-iterations", &args.bc_iterations.to_string()])
                .args(["--device", device.name()])
                .output()
                .with_context(|| format!("cannot run {py} {}", script.display()))?;
            anyhow::ensure!(out.status.success(), "{}: {}", script.display(), String::from_utf8_lossy(&out.stderr));
            Some(serde_json::from_slice(&out.stdout).context("the PyTorch baseline printed no JSON")?)
        }
    };
    let get = |k: &str| torch.as_ref().and_then(|t| t[k].as_f64());
    let (pt_trex, pt_bc) = (get("trex_model_iterations_per_s"), get("bc_iterations_per_s"));
    let out = serde_json::json!({
        "device": device.name(),
        "threads": threads,
        "gemm_gflops": peak,
        "kernel": crate::nn::gemm::Kernel::active().name(),
        "hidden_layer_one_thread": {
            "idrex_gflops": kernel_gflops, "libtorch_gflops": libtorch_gflops, "ratio": kernel_gflops / libtorch_gflops,
            "fraction_of_gemm_peak_per_thread": kernel_gflops / (peak / threads as f64),
        },
        "reward_inference_one_thread": {
            "idrex_rows_per_s": reward_rows, "libtorch_rows_per_s": torch_reward_rows, "ratio": reward_rows / torch_reward_rows,
        },
        "trex": {
            "idrex_model_iterations_per_s": trex_rate, "pytorch_model_iterations_per_s": pt_trex,
            "ratio": pt_trex.map(|p| trex_rate / p), "gflop_per_model_iteration": TREX_FLOP / 1e9,
            "fraction_of_gemm_peak": trex_rate * TREX_FLOP / 1e9 / peak,
            "pytorch_fraction_of_gemm_peak": pt_trex.map(|p| p * TREX_FLOP / 1e9 / peak),
            "idrex_cpu_model_iterations_per_s": cpu.map(|c| c.0), "speedup_over_idrex_cpu": cpu.map(|c| trex_rate / c.0),
        },
        "bc": {
            "idrex_iterations_per_s": bc_rate, "pytorch_iterations_per_s": pt_bc,
            "ratio": pt_bc.map(|p| bc_rate / p), "gflop_per_iteration": BC_FLOP / 1e9,
            "fraction_of_gemm_peak": bc_rate * BC_FLOP / 1e9 / peak,
            "pytorch_fraction_of_gemm_peak": pt_bc.map(|p| p * BC_FLOP / 1e9 / peak),
            "idrex_cpu_iterations_per_s": cpu.map(|c| c.1), "speedup_over_idrex_cpu": cpu.map(|c| bc_rate / c.1),
        },
        "pytorch": torch,
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct PpoBenchArgs {
    #[arg(long = "env", default_value = "HalfCheetah-v5")]
    pub env: EnvId,
    /// Environment steps of the PPO run.
    #[arg(long, default_value_t = 102_400)]
    pub steps: usize,
    /// Train on the ground-truth reward instead of a learned one (3 x [256, 256], freshly
    /// initialised: its values shape the trajectories, not the cost).
    #[arg(long)]
    pub ground_truth: bool,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// The environment's mj_step bound (env steps/s on one thread) over `steps` random steps.
fn mj_bound(id: EnvId, steps: usize) -> anyhow::Result<f64> {
    let mut env = Env::new(id)?;
    let actions = random_actions(steps, env.act_dim(), 0);
    env_pass(&mut env, &actions[..steps.min(2000)]);
    let (_, ends) = env_pass(&mut env, &actions);
    Ok(raw_pass(&mut env, &actions, &ends) / env.spec().frame_skip as f64)
}

pub fn ppo_bench(args: &PpoBenchArgs) -> anyhow::Result<()> {
    use crate::algo::ppo::{self, PpoConfig, RewardSource};
    crate::nn::single_threaded();
    let bound = mj_bound(args.env, 50_000)?;
    let cfg = PpoConfig { total_steps: args.steps, checkpoint_every: 0, ..Default::default() };
    let reward = if args.ground_truth {
        RewardSource::GroundTruth
    } else {
        use crate::nn::reward::{Combine, Composition, CtrlAction, RewardConfig, RewardEnsemble};
        let env = Env::new(args.env)?;
        let config = RewardConfig {
            obs_dim: env.obs_dim(),
            act_dim: None,
            hidden: vec![256, 256],
            models: 3,
            clip: 100.0,
            init: crate::nn::WeightInit::Normal002,
        };
        let model = crate::nn::seeded(args.seed, || RewardEnsemble::new(config));
        RewardSource::Learned {
            model,
            composition: Composition {
                ctrl_coeff: 0.1,
                combine: Combine::Mean,
                ctrl_action: CtrlAction::Raw,
                level: Default::default(),
                disagreement: 0.0,
            },
        }
    };
    let run = ppo::train(args.env, &cfg, reward, args.seed, &mut |_| true, None)?;
    let steps = run.curve.last().map_or(0, |p| p.global_step) as f64;
    let p = run.phases;
    let phase = |s: f64| serde_json::json!({ "seconds": s, "fraction": s / run.wall_s, "microseconds_per_step": 1e6 * s / steps });
    let out = serde_json::json!({
        "env": args.env.name(),
        "steps": steps,
        "reward": if args.ground_truth { "ground truth" } else { "learned (3 x [256, 256])" },
        "wall_s": run.wall_s,
        "steps_per_s": steps / run.wall_s,
        "mj_bound_env_steps_per_s": bound,
        "fraction_of_bound": steps / run.wall_s / bound,
        "phases": {
            "environment": phase(p.env_s),
            "policy_inference": phase(p.policy_s),
            "reward": phase(p.reward_s),
            "update": phase(p.update_s),
            "rest": phase(p.other_s),
        },
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
