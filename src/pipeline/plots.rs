//! The Rerun recording of a pipeline run (one per pipeline and environment), drawn from the
//! stages' typed metrics: degradation curves (return against noise level per source, with
//! the demonstrations' mean and spread; the report's Figures 5, 7, 9, 10), predicted against
//! true return for the demonstrations, the training set and unseen evaluation rollouts
//! (Figures 6, 8, 11), PPO learning curves, and T-REX loss and accuracy.
use std::collections::BTreeMap;
use std::path::Path;

use super::graph::Graph;
use super::runner::{Outcome, Status};
use super::stage::eval::EvalMetrics;
use super::stage::{DegradationLevel, Metrics};
use crate::error::{Error, Result};
use crate::log::rerun::Recording;
use crate::store::Store;

fn entity(node: &str) -> String {
    node.replace('/', "_")
}

fn xy(truth: &[f64], predicted: &[f64]) -> Vec<(f32, f32)> {
    truth.iter().zip(predicted).map(|(&t, &p)| (t as f32, p as f32)).collect()
}

fn status_name(s: &Status) -> &'static str {
    match s {
        Status::Cached => "cached",
        Status::Computed { .. } => "computed",
        Status::Failed { .. } => "failed",
        Status::Skipped { .. } => "skipped",
    }
}

/// Per PPO run, the true and learned (ensemble mean) returns of every checkpoint against its
/// step, with the checkpoints the report's protocols choose (pooled over the method's runs)
/// marked on each run's true-return curve.
fn checkpoint_curves(rec: &Recording, g: &Graph, metrics: &dyn Fn(&str) -> Option<Metrics>) {
    // Evaluation nodes `<method prefix>/eval/<run>`, grouped by prefix.
    let mut groups: BTreeMap<&str, Vec<(&str, EvalMetrics)>> = BTreeMap::new();
    for n in &g.nodes {
        if let (Some((prefix, run)), Some(Metrics::Eval(x))) = (n.name.rsplit_once("/eval/"), metrics(&n.name))
            && !x.checkpoints.is_empty()
        {
            groups.entry(prefix).or_default().push((run, x));
        }
    }
    for (prefix, runs) in groups {
        let chosen = crate::report::select(&runs.iter().map(|(_, x)| x.checkpoints.as_slice()).collect::<Vec<_>>());
        for (run, x) in &runs {
            let e = format!("checkpoints/{}/run{run}", entity(prefix));
            for c in &x.checkpoints {
                let mean = c.returns.iter().sum::<f64>() / c.returns.len().max(1) as f64;
                rec.scalar(&format!("{e}/true_return"), "env_step", c.step as i64, mean);
                if let Some(l) = c.learned {
                    rec.scalar(&format!("{e}/learned_return"), "env_step", c.step as i64, l.mean);
                }
                let marks = [
                    (chosen.by_ground_truth, "selected_by_ground_truth", "best checkpoint (chosen with the true reward)"),
                    (chosen.without_ground_truth, "selected_without_ground_truth", "chosen without the true reward"),
                ];
                for (step, name, label) in marks {
                    if step == Some(c.step) {
                        rec.marker(&format!("{e}/{name}"), "env_step", c.step as i64, mean, label);
                    }
                }
            }
        }
    }
}

/// Writes the recording next to `path` and renames it into place, so that a failure (a full
/// disk) never leaves the previous recording truncated.
pub fn record(g: &Graph, outcomes: &[Outcome], store: &Store, path: &Path, name: &str) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp-{}", std::process::id()));
    let tmp = std::path::PathBuf::from(tmp);
    let written = draw(g, outcomes, store, &tmp, name).and_then(|_| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e)));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

fn draw(g: &Graph, outcomes: &[Outcome], store: &Store, path: &Path, name: &str) -> Result<()> {
    let rec = Recording::create(path, name)?;
    let done: BTreeMap<&str, &str> = outcomes
        .iter()
        .filter(|o| matches!(o.status, Status::Cached | Status::Computed { .. }))
        .map(|o| (o.node.as_str(), o.key.as_str()))
        .collect();
    let metrics = |node: &str| -> Option<Metrics> {
        let n = g.get(node)?;
        let m = store.check(done.get(node)?).ok()?;
        Metrics::from_json(n.kind(), &m.metrics).ok()
    };
    let demos = match metrics("demos") {
        Some(Metrics::Demos(s) | Metrics::DemosImport(s)) => Some((s.stats.mean, s.stats.std)),
        _ => None,
    };
    let degradation_curve = |e: &str, levels: &[DegradationLevel]| {
        for l in levels {
            let t = (l.noise * 1000.0).round() as i64;
            rec.scalar(&format!("degradation/{e}/mean"), "noise_permille", t, l.mean);
            rec.scalar(&format!("degradation/{e}/mean_plus_std"), "noise_permille", t, l.mean + l.std);
            rec.scalar(&format!("degradation/{e}/mean_minus_std"), "noise_permille", t, l.mean - l.std);
            if let Some((dm, ds)) = demos {
                rec.scalar(&format!("degradation/{e}/demos_mean"), "noise_permille", t, dm);
                rec.scalar(&format!("degradation/{e}/demos_mean_plus_std"), "noise_permille", t, dm + ds);
                rec.scalar(&format!("degradation/{e}/demos_mean_minus_std"), "noise_permille", t, dm - ds);
            }
        }
    };
    let mut unseen: BTreeMap<String, Vec<(f32, f32)>> = BTreeMap::new();
    let mut lines = vec![format!("# {name}\n\nnode | kind | status\n---|---|---")];
    for n in &g.nodes {
        let status = outcomes.iter().find(|o| o.node == n.name).map_or("-", |o| status_name(&o.status));
        lines.push(format!("{} | {} | {status}", n.name, n.kind().name()));
        let Some(m) = metrics(&n.name) else { continue };
        let e = entity(&n.name);
        match &m {
            Metrics::NoiseRollouts(x) => degradation_curve(&e, &x.degradation),
            Metrics::InterpolationRollouts(x) | Metrics::ActionNoiseRollouts(x) => degradation_curve(&e, &x.degradation),
            Metrics::MultiBcRollouts(x) => degradation_curve(&e, &x.degradation),
            Metrics::Trex(t) => {
                rec.points(&format!("reward/{e}/train_set"), &xy(&t.train_set.scored.truth, &t.train_set.scored.predicted), 2.0);
                rec.points(&format!("reward/{e}/demos"), &xy(&t.demos.truth, &t.demos.predicted), 2.0);
                for (i, model) in t.models.iter().enumerate() {
                    for p in &model.curve {
                        let it = p.iteration as i64;
                        rec.scalar(&format!("trex/{e}/model{i}/loss"), "trex_iteration", it, p.loss);
                        rec.scalar(&format!("trex/{e}/model{i}/batch_accuracy"), "trex_iteration", it, p.batch_accuracy);
                    }
                }
            }
            Metrics::Ppo(x) => {
                for p in &x.curve {
                    if let Some(r) = p.true_return {
                        rec.scalar(&format!("ppo/{e}/true_return"), "env_step", p.step as i64, r);
                    }
                    if let Some(r) = p.learned_return {
                        rec.scalar(&format!("ppo/{e}/learned_return"), "env_step", p.step as i64, r);
                    }
                }
            }
            Metrics::Eval(x) => {
                // Unseen rollouts scored by the reward this run trained on.
                if let Some(acc) = &x.reward
                    && let Some((_, src)) = n.inputs.iter().find(|(role, _)| role == "reward")
                {
                    unseen.entry(entity(src)).or_default().extend(xy(&x.summary.returns, &acc.predicted_returns));
                }
            }
            Metrics::Demonstrator(_) | Metrics::Demos(_) | Metrics::DemosImport(_) | Metrics::Bc(_) | Metrics::TestValue(_) => {}
        }
    }
    for (e, xy) in unseen {
        rec.points(&format!("reward/{e}/unseen"), &xy, 2.0);
    }
    checkpoint_curves(&rec, g, &metrics);
    rec.text("pipeline", &lines.join("\n"));
    rec.finish(path)
}
