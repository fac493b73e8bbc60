//! The Rerun recording of a pipeline run (one per pipeline and environment), drawn from the
//! stages' typed metrics: degradation curves (return against noise level per source, with
//! the demonstrations' mean and spread; the report's Figures 5, 7, 9, 10), predicted against
//! true return for the demonstrations, the training set and unseen evaluation rollouts
//! (Figures 6, 8, 11), PPO learning curves, and T-REX loss and accuracy.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::Sweep;

use super::config::Method;
use super::graph::Graph;
use super::runner::{Outcome, Status};
use super::stage::eval::EvalMetrics;
use super::stage::{DegradationLevel, Metrics};
use crate::error::{Error, Result};
use crate::log::rerun::{Panel, Recording, Style};
use crate::store::Store;

fn entity(node: &str) -> String {
    node.replace('/', "_")
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
        let chosen = crate::algo::scoring::select(&runs.iter().map(|(_, x)| x.checkpoints.as_slice()).collect::<Vec<_>>());
        for (run, x) in &runs {
            let e = format!("{}/run{run}", entity(prefix));
            let (true_e, learned_e) = (format!("checkpoints_true/{e}"), format!("checkpoints_learned/{e}"));
            let colour = Method::of_node(prefix).map_or([0, 0, 0], Method::colour);
            rec.series_coloured(&true_e, &format!("{prefix} run {run}"), Style::Line, colour);
            rec.series_coloured(&learned_e, &format!("{prefix} run {run}"), Style::Line, colour);
            for c in &x.checkpoints {
                let mean = c.returns.iter().sum::<f64>() / c.returns.len().max(1) as f64;
                rec.scalar(&true_e, c.step as i64, mean);
                if let Some(l) = c.learned {
                    rec.scalar(&learned_e, c.step as i64, l.mean);
                }
                let marks = [
                    (chosen.by_ground_truth, "best", "best checkpoint (chosen with the true reward)"),
                    (chosen.without_ground_truth, "chosen_without_truth", "chosen without the true reward"),
                ];
                for (step, name, label) in marks {
                    if step == Some(c.step) {
                        rec.marker(&format!("{true_e}_{name}"), c.step as i64, mean, &format!("{prefix} run {run}: {label}"));
                    }
                }
            }
        }
    }
}

/// One recording per variant and environment, each holding that pipeline's nodes under the
/// names its own file would give them (outcomes are matched by key).
pub fn record_sweep(sweep: &Sweep, recording: Option<&Path>, outcomes: &[Outcome], store: &Store) -> Result<Vec<String>> {
    let by_key: BTreeMap<&str, &Outcome> = outcomes.iter().map(|o| (o.key.as_str(), o)).collect();
    let mut recordings = Vec::new();
    for v in &sweep.variants {
        let p = &v.pipeline;
        let own = super::expand(p)?;
        let own_keys = own.keys();
        for &env in &p.envs {
            let stem = if sweep.is_sweep() { format!("{}-{}", p.name, env.name()) } else { env.name().to_string() };
            let rec = match recording {
                Some(r) if !p.is_study() && !sweep.is_sweep() => r.to_path_buf(),
                Some(r) => r.with_file_name(format!("{}-{stem}.rrd", r.file_stem().unwrap_or_default().to_string_lossy())),
                None => PathBuf::from("recordings").join(format!("{}-{}.rrd", p.name, env.name())),
            };
            if let Some(dir) = rec.parent() {
                std::fs::create_dir_all(dir).ok();
            }
            let prefix = if p.is_study() { format!("{}/", env.name()) } else { String::new() };
            let sub = own.subgraph(&prefix);
            let mine: Vec<Outcome> = own
                .nodes
                .iter()
                .filter_map(|n| {
                    let o = by_key.get(own_keys[&n.name].as_str())?;
                    n.name.strip_prefix(&prefix).map(|name| Outcome { node: name.to_string(), ..(*o).clone() })
                })
                .collect();
            record(&sub, &mine, store, &rec, &p.name)?;
            println!("recording: {}", rec.display());
            recordings.push(rec.display().to_string());
        }
    }
    Ok(recordings)
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

/// The demonstrations' mean and spread as flat lines across the degradation plot.
fn demonstrations_band(rec: &Recording, (mean, std): (f64, f64)) {
    for (leaf, value, name, style) in [
        ("mean", mean, "demonstrations: mean", Style::Line),
        ("plus_std", mean + std, "demonstrations: + std", Style::ThinLine),
        ("minus_std", mean - std, "demonstrations: - std", Style::ThinLine),
    ] {
        let e = format!("degradation/demonstrations/{leaf}");
        rec.series(&e, name, style);
        rec.scalar(&e, 0, value);
        rec.scalar(&e, 1000, value);
    }
}

/// A ranked set's return against its noise level (x in ‰), with its spread.
fn degradation_curve(rec: &Recording, node: &str, levels: &[DegradationLevel]) {
    let e = entity(node);
    for (leaf, name, style) in
        [("mean", "mean", Style::Line), ("plus_std", "+ std", Style::ThinLine), ("minus_std", "- std", Style::ThinLine)]
    {
        rec.series(&format!("degradation/{e}/{leaf}"), &format!("{node}: {name}"), style);
    }
    for l in levels {
        let t = (l.noise * 1000.0).round() as i64;
        rec.scalar(&format!("degradation/{e}/mean"), t, l.mean);
        rec.scalar(&format!("degradation/{e}/plus_std"), t, l.mean + l.std);
        rec.scalar(&format!("degradation/{e}/minus_std"), t, l.mean - l.std);
    }
}

/// Predicted against true return as a point series over the true return.
fn scatter(rec: &Recording, e: &str, name: &str, truth: &[f64], predicted: &[f64]) {
    let r = crate::stats::pearson(truth, predicted);
    let name = if r.is_finite() { format!("{name} (Pearson {r:.2})") } else { name.to_string() };
    rec.series(e, &name, Style::Points);
    for (&t, &p) in truth.iter().zip(predicted) {
        rec.scalar(e, t.round() as i64, p);
    }
}

/// What the nodes' plots gather for the plots drawn after them.
#[derive(Default)]
struct Gathered {
    /// Reward node entity -> (its name, unseen evaluation returns, their predicted returns).
    unseen: BTreeMap<String, (String, Vec<f64>, Vec<f64>)>,
    has_clones: bool,
    /// (method, replicate) -> each run's final-policy mean return.
    finals: BTreeMap<(Method, usize), Vec<f64>>,
}

/// The plots of one stage's metrics.
fn plot_node(rec: &Recording, n: &super::graph::Node, m: &Metrics, gathered: &mut Gathered) {
    let e = entity(&n.name);
    match m {
        Metrics::NoiseRollouts(x) => degradation_curve(rec, &n.name, &x.degradation),
        Metrics::InterpolationRollouts(x) | Metrics::ActionNoiseRollouts(x) => degradation_curve(rec, &n.name, &x.degradation),
        Metrics::MultiBcRollouts(x) => {
            degradation_curve(rec, &n.name, &x.degradation);
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
            let (sources, clones): (Vec<f64>, Vec<f64>) =
                x.clones.iter().map(|c| (mean(&c.fidelity.source_returns), mean(&c.fidelity.clone_returns))).unzip();
            scatter(rec, &format!("clones/{e}"), &format!("{}: clones", n.name), &sources, &clones);
            gathered.has_clones = true;
        }
        Metrics::Trex(t) => {
            let set = &t.train_set.scored;
            scatter(rec, &format!("reward/{e}/training_set"), &format!("{}: training set", n.name), &set.truth, &set.predicted);
            scatter(rec, &format!("reward/{e}/demonstrations"), &format!("{}: demonstrations", n.name), &t.demos.truth, &t.demos.predicted);
            for (i, model) in t.models.iter().enumerate() {
                let loss = format!("trex_loss/{e}/model{i}");
                rec.series(&loss, &format!("{} model {i}", n.name), Style::ThinLine);
                for p in &model.curve {
                    rec.scalar(&loss, p.iteration as i64, p.loss);
                }
            }
        }
        Metrics::Ppo(x) => {
            let e = format!("ppo_true/{e}");
            rec.series_coloured(&e, &n.name, Style::ThinLine, Method::of_node(&n.name).map_or([0, 0, 0], Method::colour));
            for p in &x.curve {
                if let Some(r) = p.true_return {
                    rec.scalar(&e, p.step as i64, r);
                }
            }
        }
        Metrics::Eval(x) => {
            if let super::stage::Params::Eval(p) = &n.params {
                gathered.finals.entry((p.method, p.replicate)).or_default().push(x.summary.stats.mean);
            }
            // Unseen rollouts scored by the reward this run trained on.
            if let Some(acc) = &x.reward
                && let super::stage::Inputs::Eval(i) = &n.inputs
                && let Some(src) = &i.reward
            {
                let entry = gathered.unseen.entry(entity(src)).or_insert_with(|| (src.clone(), vec![], vec![]));
                entry.1.extend(&x.summary.returns);
                entry.2.extend(&acc.predicted_returns);
            }
        }
        Metrics::Demonstrator(_)
        | Metrics::Demos(_)
        | Metrics::DemosImport(_)
        | Metrics::Bc(_)
        | Metrics::BankPolicy(_)
        | Metrics::Bank(_)
        | Metrics::BankScore(_)
        | Metrics::Probe(_) => {}
    }
}

/// A replicated study's final returns per method and replicate (the mean over its runs);
/// whether there was more than one replicate to draw.
fn replicate_points(rec: &Recording, finals: &BTreeMap<(Method, usize), Vec<f64>>) -> bool {
    let replicates: std::collections::BTreeSet<usize> = finals.keys().map(|(_, r)| *r).collect();
    if replicates.len() < 2 {
        return false;
    }
    let mut named = std::collections::BTreeSet::new();
    for ((m, r), runs) in finals {
        let e = format!("replicates/{}", m.name());
        if named.insert(*m) {
            rec.series_coloured(&e, m.label(), Style::Points, m.colour());
        }
        rec.scalar(&e, *r as i64, runs.iter().sum::<f64>() / runs.len() as f64);
    }
    true
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
    if let Some(Metrics::Demos(s) | Metrics::DemosImport(s)) = metrics("demos") {
        demonstrations_band(&rec, (s.stats.mean, s.stats.std));
    }
    let mut gathered = Gathered::default();
    let mut lines = vec![format!("# {name}\n\n| node | kind | status |\n|---|---|---|")];
    for n in &g.nodes {
        let status = outcomes.iter().find(|o| o.node == n.name).map_or("-", |o| status_name(&o.status));
        lines.push(format!("| {} | {} | {status} |", n.name, n.kind().name()));
        if let Some(m) = metrics(&n.name) {
            plot_node(&rec, n, &m, &mut gathered);
        }
    }
    for (e, (src, truth, predicted)) in &gathered.unseen {
        scatter(&rec, &format!("reward/{e}/unseen"), &format!("{src}: unseen evaluation rollouts"), truth, predicted);
    }
    checkpoint_curves(&rec, g, &metrics);
    rec.markdown("pipeline", &lines.join("\n"));
    let plot = |title: &str, root: &str| Panel::Plot { title: title.into(), root: root.into() };
    let mut panels = vec![
        plot("Return against noise level (x: noise level in ‰)", "degradation"),
        plot("Learned against true return (x: true return; y: predicted return)", "reward"),
        plot("PPO checkpoints: true return (x: environment step; ◆ chosen checkpoints)", "checkpoints_true"),
        plot("PPO checkpoints: learned return, ensemble mean (x: environment step)", "checkpoints_learned"),
        plot("PPO training episodes: true return (x: environment step)", "ppo_true"),
        plot("T-REX loss (x: iteration)", "trex_loss"),
        Panel::Text { title: "Pipeline stages".into(), entity: "pipeline".into() },
    ];
    if replicate_points(&rec, &gathered.finals) {
        panels.push(plot("Each replicate's final policy: true return, mean over its runs (x: replicate)", "replicates"));
    }
    if gathered.has_clones {
        panels.push(plot("Multi-BC clones against their sources (x: source's true return; y: clone's, noise-free)", "clones"));
    }
    rec.layout(path, panels)?;
    rec.finish(path)
}
