//! `idrex env rollout`: replay actions in one environment, one JSON line per step.
use std::io::Write;
use std::path::PathBuf;

use clap::{Args, Subcommand};

use crate::env::{Env, EnvId, replay};

#[derive(Debug, Subcommand)]
pub enum EnvCommand {
    /// Replay actions from a state and print one JSON line per step.
    Rollout(RolloutArgs),
}

#[derive(Debug, Args)]
pub struct RolloutArgs {
    /// Environment id: HalfCheetah-v5, Hopper-v5 or Walker2d-v5.
    #[arg(long)]
    pub env: String,
    /// JSON file {"qpos": [...], "qvel": [...]} to start from, instead of a seeded reset.
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// CSV file with one action per line (comma-separated numbers).
    #[arg(long)]
    pub actions: PathBuf,
    /// Seed of the reset when no --state is given.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

pub fn run(cmd: &EnvCommand) -> anyhow::Result<()> {
    let EnvCommand::Rollout(args) = cmd;
    // Parsed here rather than by clap so that the error is one line like every other.
    let mut env = Env::new(args.env.parse::<EnvId>()?)?;
    let mut obs = vec![0.0; env.obs_dim()];
    let actions = replay::read_actions(&args.actions, env.act_dim())?;
    match &args.state {
        Some(path) => {
            let (qpos, qvel) = replay::read_state(path)?;
            env.set_state(&qpos, &qvel, &mut obs).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        }
        None => env.reset(Some(args.seed), &mut obs),
    }
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for (t, action) in actions.iter().enumerate() {
        let info = env.step(action, &mut obs)?;
        let mut line = serde_json::json!({
            "step": t,
            "obs": obs,
            "reward": info.reward,
            "terminated": info.terminated,
            "truncated": info.truncated,
            "reward_forward": info.terms.reward_forward,
            "reward_ctrl": info.terms.reward_ctrl,
            "reward_survive": info.terms.reward_survive,
            "x_position": info.x_position,
            "x_velocity": info.x_velocity,
        });
        if env.spec().contact.is_some() {
            line["reward_contact"] = serde_json::json!(info.terms.reward_contact);
        }
        writeln!(out, "{line}")?;
        if info.terminated || info.truncated {
            break;
        }
    }
    out.flush()?;
    Ok(())
}
