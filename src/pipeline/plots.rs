//! The Rerun recording of a pipeline run (one per pipeline and environment), drawn from the
//! manifests' metrics: degradation curves (return against noise level per source, with the
//! demonstrations' mean and spread; the report's Figures 5, 7, 9, 10), predicted against true
//! return for the demonstrations, the training set and unseen evaluation rollouts (Figures 6,
//! 8, 11), PPO learning curves, and T-REX loss and accuracy.
use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use super::graph::Graph;
use super::runner::{Outcome, Status};
use crate::error::Result;
use crate::log::rerun::Recording;
use crate::store::Store;

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().map(|a| a.iter().filter_map(Value::as_f64).collect()).unwrap_or_default()
}

fn entity(node: &str) -> String {
    node.replace('/', "_")
}

pub fn record(g: &Graph, outcomes: &[Outcome], store: &Store, path: &Path, name: &str) -> Result<()> {
    let rec = Recording::create(path, name)?;
    let done: BTreeMap<&str, &str> = outcomes
        .iter()
        .filter(|o| matches!(o.status, Status::Cached | Status::Computed { .. }))
        .map(|o| (o.node.as_str(), o.key.as_str()))
        .collect();
    let metrics = |node: &str| done.get(node).and_then(|k| store.check(k).ok()).map(|m| m.metrics);
    let demos = metrics("demos").map(|m| (m["mean"].as_f64().unwrap_or(0.0), m["std"].as_f64().unwrap_or(0.0)));
    let key_to_node: BTreeMap<&str, &str> = done.iter().map(|(n, k)| (*k, *n)).collect();
    let mut unseen: BTreeMap<String, Vec<(f32, f32)>> = BTreeMap::new();
    let mut lines = vec![format!("# {name}\n\nnode | kind | status\n---|---|---")];
    for n in &g.nodes {
        let status = outcomes
            .iter()
            .find(|o| o.node == n.name)
            .map_or("-".to_string(), |o| format!("{:?}", o.status).split_whitespace().next().unwrap_or("").to_string());
        lines.push(format!("{} | {} | {status}", n.name, n.kind.name()));
        let Some(m) = metrics(&n.name) else { continue };
        let e = entity(&n.name);
        if let Some(levels) = m["degradation"].as_array() {
            for l in levels {
                let (x, mean, std) =
                    (l["noise"].as_f64().unwrap_or(0.0), l["mean"].as_f64().unwrap_or(0.0), l["std"].as_f64().unwrap_or(0.0));
                let t = (x * 1000.0).round() as i64;
                rec.scalar(&format!("degradation/{e}/mean"), "noise_permille", t, mean);
                rec.scalar(&format!("degradation/{e}/mean_plus_std"), "noise_permille", t, mean + std);
                rec.scalar(&format!("degradation/{e}/mean_minus_std"), "noise_permille", t, mean - std);
                if let Some((dm, ds)) = demos {
                    rec.scalar(&format!("degradation/{e}/demos_mean"), "noise_permille", t, dm);
                    rec.scalar(&format!("degradation/{e}/demos_mean_plus_std"), "noise_permille", t, dm + ds);
                    rec.scalar(&format!("degradation/{e}/demos_mean_minus_std"), "noise_permille", t, dm - ds);
                }
            }
        }
        if m.get("train_set").is_some() {
            for set in ["train_set", "demos"] {
                let xy: Vec<(f32, f32)> =
                    floats(&m[set]["true"]).into_iter().zip(floats(&m[set]["predicted"])).map(|(t, p)| (t as f32, p as f32)).collect();
                rec.points(&format!("reward/{e}/{set}"), &xy, 2.0);
            }
            for (i, model) in m["models"].as_array().into_iter().flatten().enumerate() {
                for p in model["curve"].as_array().into_iter().flatten() {
                    let it = p[0].as_i64().unwrap_or(0);
                    rec.scalar(&format!("trex/{e}/model{i}/loss"), "trex_iteration", it, p[1].as_f64().unwrap_or(f64::NAN));
                    rec.scalar(&format!("trex/{e}/model{i}/batch_accuracy"), "trex_iteration", it, p[2].as_f64().unwrap_or(f64::NAN));
                }
            }
        }
        if let Some(curve) = m["curve"].as_array() {
            for p in curve {
                let step = p[0].as_i64().unwrap_or(0);
                if let Some(r) = p[1].as_f64() {
                    rec.scalar(&format!("ppo/{e}/true_return"), "env_step", step, r);
                }
                if let Some(r) = p[2].as_f64() {
                    rec.scalar(&format!("ppo/{e}/learned_return"), "env_step", step, r);
                }
            }
        }
        if let (Some(pred), Some(reward_key)) =
            (m.get("predicted_returns"), n.inputs.iter().find(|(r, _)| r == "reward").and_then(|(_, src)| done.get(src.as_str())))
            && let Some(trex_node) = key_to_node.get(reward_key)
        {
            let xy = floats(&m["returns"]).into_iter().zip(floats(pred)).map(|(t, p)| (t as f32, p as f32));
            unseen.entry(entity(trex_node)).or_default().extend(xy);
        }
    }
    for (e, xy) in unseen {
        rec.points(&format!("reward/{e}/unseen"), &xy, 2.0);
    }
    rec.text("pipeline", &lines.join("\n"));
    rec.finish(path)
}
