//! `idrex bench env --envpool`: idrex's environments against EnvPool's (the C++ vectorised
//! engine), in the same run: one environment on one thread, and synchronous batches of 8 and
//! 64 environments on one thread and on two. The passes alternate (idrex, then EnvPool, run
//! after run) so that a machine that slows down slows both, and each ratio is of medians.
use anyhow::Context;

use super::env::{EnvBenchArgs, env_pass, ids, random_actions, vec_pass};
use crate::env::{Env, EnvId};

/// The configurations measured: (environments in the batch, threads); (1, 1) is one
/// environment stepped alone.
pub const CONFIGS: [(usize, usize); 5] = [(1, 1), (8, 1), (8, 2), (64, 1), (64, 2)];

/// One configuration: both sides' medians and their ratio.
#[derive(Debug, serde::Serialize)]
pub struct PeerRow {
    pub num_envs: usize,
    pub threads: usize,
    pub idrex_steps_per_s: f64,
    pub envpool_steps_per_s: f64,
    /// idrex over EnvPool (above 1: idrex is faster).
    pub ratio: f64,
    /// Timed passes per side the medians summarise.
    pub runs: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One timed pass of each EnvPool configuration, from its own Python (a process per run).
fn envpool_pass(python: &str, id: EnvId, steps: usize) -> anyhow::Result<Vec<f64>> {
    let mut args = vec!["--env".to_string(), id.name().to_string(), "--steps".into(), steps.to_string(), "--runs".into(), "1".into()];
    for (n, t) in CONFIGS {
        args.extend(["--config".to_string(), format!("{n}:{t}")]);
    }
    let out = super::scripts::Script::EnvpoolBench.run(python, &args)?;
    let text = String::from_utf8_lossy(&out.stdout);
    let rates: Vec<f64> = text
        .lines()
        .map(|l| -> anyhow::Result<f64> {
            let v: serde_json::Value = serde_json::from_str(l)?;
            v["steps_per_s"][0].as_f64().context("envpool_bench.py printed no steps_per_s")
        })
        .collect::<anyhow::Result<_>>()?;
    anyhow::ensure!(rates.len() == CONFIGS.len(), "envpool_bench.py printed {} configurations, not {}", rates.len(), CONFIGS.len());
    Ok(rates)
}

/// One timed pass of each configuration in idrex.
fn idrex_pass(id: EnvId, steps: usize) -> anyhow::Result<Vec<f64>> {
    CONFIGS
        .iter()
        .map(|&(n, t)| {
            if n == 1 {
                let mut env = Env::new(id)?;
                let actions = random_actions(steps, env.act_dim(), 0);
                env_pass(&mut env, &actions[..steps.min(2000)]);
                Ok(env_pass(&mut env, &actions).0)
            } else {
                vec_pass(id, n, t, steps)
            }
        })
        .collect()
}

/// `runs` alternating passes of both; one row per configuration.
pub fn compare(python: &str, id: EnvId, steps: usize, runs: usize) -> anyhow::Result<Vec<PeerRow>> {
    let (mut ours, mut theirs) = (vec![Vec::new(); CONFIGS.len()], vec![Vec::new(); CONFIGS.len()]);
    for _ in 0..runs {
        for (i, r) in idrex_pass(id, steps)?.into_iter().enumerate() {
            ours[i].push(r);
        }
        for (i, r) in envpool_pass(python, id, steps)?.into_iter().enumerate() {
            theirs[i].push(r);
        }
    }
    Ok(CONFIGS
        .iter()
        .zip(ours.into_iter().zip(theirs))
        .map(|(&(n, t), (a, b))| {
            let (a, b) = (median(a), median(b));
            PeerRow { num_envs: n, threads: t, idrex_steps_per_s: a, envpool_steps_per_s: b, ratio: a / b, runs }
        })
        .collect())
}

/// Every environment of the run against EnvPool: a markdown table each, or JSON lines
/// (`{"env": ..., "envpool": [rows]}`).
pub fn run(python: &str, args: &EnvBenchArgs) -> anyhow::Result<()> {
    for id in ids(args) {
        let rows = {
            let _measuring = crate::log::progress::Activity::start(format!("bench env: {} against EnvPool", id.name()));
            compare(python, id, args.steps, args.runs.max(1))?
        };
        if args.json {
            println!("{}", serde_json::json!({"env": id.name(), "envpool": rows}));
        } else {
            print!("{}", markdown(id.name(), &rows));
        }
    }
    Ok(())
}

/// The rows as a markdown table.
pub fn markdown(env: &str, rows: &[PeerRow]) -> String {
    let mut out =
        format!("\n| {env} against EnvPool | idrex steps/s | EnvPool steps/s | idrex / EnvPool | runs |\n|---|---|---|---|---|\n");
    for r in rows {
        let what = if r.num_envs == 1 {
            "1 environment, 1 thread".to_string()
        } else {
            format!("{} environments, {} thread(s)", r.num_envs, r.threads)
        };
        out.push_str(&format!("| {what} | {:.0} | {:.0} | {:.2}x | {} |\n", r.idrex_steps_per_s, r.envpool_steps_per_s, r.ratio, r.runs));
    }
    out
}
