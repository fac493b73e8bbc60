//! `idrex bench ppo`: a PPO run at CleanRL's settings broken down by phase, next to the
//! environment's mj_step bound and Stable-Baselines3's PPO at the same settings, both
//! measured in the same run.

use super::env::{env_pass, random_actions, raw_pass};
use crate::env::{Env, EnvId};

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
    /// Python with torch for the Stable-Baselines3 baseline (`analysis/bench_ppo.py
    /// --sb3-only`, on the ground-truth reward; default: the bootstrap environment's; "none"
    /// skips it).
    #[arg(long)]
    pub python: Option<String>,
}

/// Stable-Baselines3's PPO at CleanRL's settings on one thread (its steps per second).
fn sb3_rate(python: &str, env: EnvId, steps: usize) -> anyhow::Result<f64> {
    use anyhow::Context;
    let args = ["--sb3-only", "--env", env.name(), "--steps", &steps.to_string()].map(String::from);
    let out = super::scripts::Script::BenchPpo.run(python, &args)?;
    let line = String::from_utf8_lossy(&out.stdout).lines().last().unwrap_or_default().to_string();
    let v: serde_json::Value = serde_json::from_str(&line).context("the Stable-Baselines3 baseline printed no JSON")?;
    v["steps_per_s"].as_f64().context("the Stable-Baselines3 baseline printed no steps_per_s")
}

/// The environment's mj_step bound (env steps/s on one thread) over `steps` random steps.
fn mj_bound(id: EnvId, steps: usize) -> anyhow::Result<f64> {
    let mut env = Env::new(id)?;
    let actions = random_actions(steps, env.act_dim(), 0);
    env_pass(&mut env, &actions[..steps.min(2000)]);
    let (_, ends) = env_pass(&mut env, &actions);
    Ok(raw_pass(&mut env, &actions, &ends) / env.spec().frame_skip as f64)
}

pub fn ppo_bench(args: &PpoBenchArgs) -> anyhow::Result<serde_json::Value> {
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
            obs_stride: None,
            obs_offset: None,
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
                ceiling: None,
            },
        }
    };
    let run = ppo::train(args.env, &cfg, reward, args.seed, &mut |_| true, None)?;
    let steps = run.curve.last().map_or(0, |p| p.global_step) as f64;
    let p = run.phases;
    let python = args.python.clone().or_else(super::env::default_python).filter(|p| p != "none");
    let sb3 = python.map(|py| sb3_rate(&py, args.env, args.steps)).transpose()?;
    let rate = steps / run.wall_s;
    let phase = |s: f64| serde_json::json!({ "seconds": s, "fraction": s / run.wall_s, "microseconds_per_step": 1e6 * s / steps });
    let out = serde_json::json!({
        "env": args.env.name(),
        "steps": steps,
        "reward": if args.ground_truth { "ground truth" } else { "learned (3 x [256, 256])" },
        "wall_s": run.wall_s,
        "steps_per_s": steps / run.wall_s,
        "mj_bound_env_steps_per_s": bound,
        "fraction_of_bound": steps / run.wall_s / bound,
        "sb3_steps_per_s": sb3,
        "ratio_over_sb3": sb3.map(|s| rate / s),
        "sb3_reward": "ground truth (Stable-Baselines3 has no learned reward)",
        "runs": 1,
        "phases": {
            "environment": phase(p.env_s),
            "policy_inference": phase(p.policy_s),
            "reward": phase(p.reward_s),
            "update": phase(p.update_s),
            "rest": phase(p.other_s),
        },
    });
    Ok(out)
}
