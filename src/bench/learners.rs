//! `idrex bench learners`: T-REX and BC training speed at the report's shapes next to the same
//! loops in PyTorch (run by this command), and the machine's matrix-product rate.
use std::time::Instant;

use anyhow::Context;

use super::env::default_python;
use crate::kernels::bf16::Precision;
use crate::nn::{Device, DeviceChoice};

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
/// 256 x 256), in GFLOP/s, best of 5: idrex's kernel (`kernels::gemm`, the active variant),
/// libtorch's (MKL's) on the same operands, and idrex's bf16 product (`kernels::bf16`, its active
/// path).
fn hidden_layer_gflops() -> (f64, f64, f64) {
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
    use crate::kernels::gemm::{Factor, Product};
    let product = |a, b| Product { m, n, k, a: Factor::new(a, k), b: Factor::new(b, n), accumulate: false };
    let ours = best(&mut || (0..reps).for_each(|_| crate::kernels::gemm::gemm(product(&a, &b), &mut c, n)));
    let bf16 = best(&mut || (0..reps).for_each(|_| crate::kernels::bf16::gemm_bf16(product(&a, &b), &mut c, n)));
    crate::nn::single_threaded();
    let (ta, tb) = (tch::Tensor::from_slice(&a).view([m as i64, k as i64]), tch::Tensor::from_slice(&b).view([k as i64, n as i64]));
    let torch = best(&mut || (0..reps).for_each(|_| _ = ta.matmul(&tb)));
    (flop / ours / 1e9, flop / torch / 1e9, flop / bf16 / 1e9)
}

/// The learned reward's inference, as PPO calls it once per rollout (2,048 rows of
/// HalfCheetah's 17-dimensional observations through 3 models of [256, 256]), in rows per
/// second, best of 5: idrex's CPU path (`RewardEnsemble::raw`, over `kernels::gemm`) and
/// libtorch's forward pass on the same networks and rows.
fn reward_inference_rates() -> (f64, f64) {
    use crate::nn::reward::{RewardConfig, RewardEnsemble};
    let config = RewardConfig {
        obs_dim: 17,
        obs_stride: None,
        obs_offset: None,
        act_dim: None,
        hidden: vec![256, 256],
        models: 3,
        clip: 100.0,
        init: Default::default(),
    };
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

/// idrex's T-REX (model-iterations/s, its products at `precision`) and BC (iterations/s)
/// rates on `device`.
fn learner_rates(args: &LearnersBenchArgs, threads: usize, device: Device, precision: Precision) -> anyhow::Result<(f64, f64)> {
    use crate::algo::{bc, trex};
    // T-REX: 100 episodes of 1000 steps, 3 members on `threads` workers.
    let trajs = synthetic(100, 1000, 0);
    let ranking = trex::Ranking::by_score(trajs.iter().map(|t| -t.meta.noise).collect());
    crate::nn::single_threaded();
    let trex_s = marginal(args.trex_iterations, |n| {
        let cfg = trex::TrexConfig { iterations: n, precision, ..Default::default() };
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

pub fn learners_bench(args: &LearnersBenchArgs) -> anyhow::Result<serde_json::Value> {
    let threads = args.threads.max(1);
    let device = args.device.resolve();
    device.ensure_available()?;
    let peak = gemm_gflops(threads, device);
    let (kernel_gflops, libtorch_gflops, bf16_gflops) = hidden_layer_gflops();
    let (reward_rows, torch_reward_rows) = reward_inference_rates();
    let (trex_rate, bc_rate) = learner_rates(args, threads, device, Precision::F32)?;
    // On the GPU, the CPU learners are the figure to beat; on the CPU, T-REX in bf16.
    let cpu = if device.is_cpu() { None } else { Some(learner_rates(args, threads, Device::Cpu, Precision::F32)?) };
    let trex_bf16 = if device.is_cpu() { Some(learner_rates(args, threads, device, Precision::Bf16)?.0) } else { None };
    let python = args.python.clone().or_else(default_python).filter(|p| p != "none");
    let torch: Option<serde_json::Value> = match &python {
        None => None,
        Some(py) => {
            let script_args = [
                "--threads",
                &threads.to_string(),
                "--trex-iterations",
                &args.trex_iterations.to_string(),
                "--bc-iterations",
                &args.bc_iterations.to_string(),
                "--device",
                device.name(),
            ]
            .map(String::from);
            let out = super::scripts::Script::BenchLearners.run(py, &script_args)?;
            Some(serde_json::from_slice(&out.stdout).context("the PyTorch baseline printed no JSON")?)
        }
    };
    let get = |k: &str| torch.as_ref().and_then(|t| t[k].as_f64());
    let (pt_trex, pt_bc) = (get("trex_model_iterations_per_s"), get("bc_iterations_per_s"));
    let out = serde_json::json!({
        "device": device.name(),
        "threads": threads,
        "gemm_gflops": peak,
        "kernel": crate::kernels::gemm::Kernel::active().name(),
        "hidden_layer_one_thread": {
            "idrex_gflops": kernel_gflops, "libtorch_gflops": libtorch_gflops, "ratio": kernel_gflops / libtorch_gflops,
            "fraction_of_gemm_peak_per_thread": kernel_gflops / (peak / threads as f64),
            "idrex_bf16_gflops": bf16_gflops, "bf16_over_f32": bf16_gflops / kernel_gflops,
            "bf16_path": crate::kernels::bf16::Bf16Path::active().name(),
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
            "idrex_bf16_model_iterations_per_s": trex_bf16, "bf16_over_f32": trex_bf16.map(|b| b / trex_rate),
            "bf16_ratio_over_pytorch": trex_bf16.zip(pt_trex).map(|(b, p)| b / p),
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
    Ok(out)
}
