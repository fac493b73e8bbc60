//! A generated store of many studies, for measuring `exp show` at a scale no real store here
//! reaches (`idrex bench exp`) and for its tests. Every study has the shape of the report's
//! grid on Hopper: per replicate a demonstrations set, BC, a learned reward, and D-REX and
//! multi-BC with two PPO runs each; study `i` differs from the others in PPO's step budget
//! only, and replicate `r` of every study shares its seeds. Returns are made up (a fixed
//! pseudo-random draw), so only the shape is real.
use std::collections::BTreeMap;
use std::path::Path;

use crate::env::EnvId;
use crate::error::{Error, Result};
use crate::pipeline::Method;
use crate::pipeline::role::Role;
use crate::pipeline::stage::demos::DemosParams;
use crate::pipeline::stage::eval::{EvalMetrics, EvalParams};
use crate::pipeline::stage::{Metrics, Params, RolloutSummary, StageKind};
use crate::stats::ReturnStats;
use crate::store::Manifest;

fn manifest(
    key: String,
    kind: &str,
    params: serde_json::Value,
    metrics: serde_json::Value,
    seed: u64,
    inputs: &[(Role, &str)],
) -> Manifest {
    Manifest {
        node: key.clone(),
        key,
        kind: kind.into(),
        version: 1,
        params,
        seed,
        inputs: inputs.iter().map(|(r, k)| (r.name(), k.to_string())).collect(),
        metrics,
        started_unix: 1_796_300_000.0,
        ended_unix: 1_796_300_000.0 + seed as f64,
        wall_s: 1.0,
        idrex_version: env!("CARGO_PKG_VERSION").into(),
        ..Default::default()
    }
}

/// A deterministic draw in [0, 1) from three integers (SplitMix64).
fn draw(a: u64, b: u64, c: u64) -> f64 {
    let mut z = a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xBF58_476D_1CE4_E5B9) ^ c.wrapping_mul(0x94D0_49BB_1331_11EB);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// The manifests of `studies` studies of `replicates` replicates each.
pub fn manifests(studies: usize, replicates: usize, salt: u64) -> Vec<Manifest> {
    let mut out = Vec::new();
    let summary =
        |returns: Vec<f64>| RolloutSummary { stats: ReturnStats::of(&returns), lengths: vec![1000; returns.len()], returns, terms: None };
    for s in 0..studies {
        let name = format!("study-{s:03}");
        for r in 0..replicates {
            let tag = format!("{s}-{r}-{salt}");
            let seed = 1000 * r as u64;
            let demos = format!("demos-{r}-{salt}");
            let dp = Params::Demos(DemosParams { env: EnvId::Hopper, episodes: 2, acting: Default::default(), noise_scale: 1.0 });
            let returns = vec![1000.0, 1100.0];
            out.push(manifest(demos.clone(), dp.kind().name(), dp.to_json(), Metrics::Demos(summary(returns)).to_json(), seed, &[]));
            let bc = format!("bc-{r}-{salt}");
            let bc_params = serde_json::json!({"env": "Hopper-v5", "bc": {"iterations": 10000, "lr": 0.0001}});
            out.push(manifest(bc.clone(), StageKind::Bc.name(), bc_params, serde_json::json!({}), seed, &[(Role::Demos, &demos)]));
            let trex = format!("trex-{tag}");
            let trex_params = serde_json::json!({"env": "Hopper-v5", "trex": {"ensemble": 5, "steps": 10000}});
            out.push(manifest(trex.clone(), StageKind::Trex.name(), trex_params, serde_json::json!({}), seed, &[]));
            for (method, runs) in [(Method::Bc, 1), (Method::Drex, 2), (Method::IdrexMultiBc, 2)] {
                for run in 0..runs {
                    let seed = seed + run as u64;
                    let policy = if method == Method::Bc {
                        bc.clone()
                    } else {
                        let ppo = format!("ppo-{tag}-{}-{run}", method.name());
                        let params = serde_json::json!({
                            "env": "Hopper-v5",
                            "ppo": {"total_steps": 1_000_000 + 1000 * s, "lr": 0.0003},
                            "reward": {"level": "ranked-floor", "ceiling": 0.75},
                        });
                        out.push(manifest(
                            ppo.clone(),
                            StageKind::Ppo.name(),
                            params,
                            serde_json::json!({}),
                            seed,
                            &[(Role::Reward, &trex)],
                        ));
                        ppo
                    };
                    let level = match method {
                        Method::Bc => 900.0,
                        _ => 1800.0 + 10.0 * s as f64,
                    };
                    let returns = (0..2).map(|e| level + 400.0 * draw(s as u64 ^ salt, (r * 10 + run) as u64, e)).collect();
                    let p = Params::Eval(EvalParams {
                        env: EnvId::Hopper,
                        episodes: 2,
                        pipeline: name.clone(),
                        method,
                        iteration: usize::from(method != Method::Bc),
                        run,
                        replicate: r,
                        variant: None,
                    });
                    let x = Metrics::Eval(EvalMetrics { summary: summary(returns), reward: None, checkpoints: vec![] });
                    let key = format!("eval-{tag}-{}-{run}", method.name());
                    out.push(manifest(
                        key,
                        StageKind::Eval.name(),
                        p.to_json(),
                        x.to_json(),
                        seed,
                        &[(Role::Policy, &policy), (Role::Demos, &demos)],
                    ));
                }
            }
        }
    }
    // One manifest per key (the demonstrations and BC are shared across studies).
    out.into_iter().map(|m| (m.key.clone(), m)).collect::<BTreeMap<_, _>>().into_values().collect()
}

/// Writes the manifests as a local store under `dir` (manifests only, no output files).
pub fn write(dir: &Path, studies: usize, replicates: usize) -> Result<usize> {
    let all = manifests(studies, replicates, 0);
    for m in &all {
        let at = dir.join(&m.key);
        std::fs::create_dir_all(&at).map_err(|e| Error::io(&at, e))?;
        let text = serde_json::to_string_pretty(m).map_err(|e| Error::Invalid(e.to_string()))?;
        std::fs::write(at.join("manifest.json"), text).map_err(|e| Error::io(&at, e))?;
    }
    Ok(all.len())
}
