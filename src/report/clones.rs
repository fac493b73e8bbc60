//! Multi-BC's clones against their sources (`clones.csv` and a section of `report.md`): per
//! clone, its source's and its own noise-free true return and length, the fidelity (0 = the
//! uniform-random policy, 1 = the source), BC's validation loss and iterations, and what the
//! filter decided. The true returns are measured for the reader; no stage decides on them.
use std::collections::BTreeSet;

use polars::prelude::*;

use super::{Artifacts, pe};
use crate::error::Result;
use crate::pipeline::Method;
use crate::pipeline::role::{Role, Series};
use crate::pipeline::stage::idrex::clone::CloneRecord;
use crate::pipeline::stage::{Metrics, Params, Typed};

#[derive(Debug, Clone, PartialEq)]
pub struct CloneRow {
    pub env: String,
    /// The table (pipeline, and replicate past the first) whose multi-BC reward used the set.
    pub pipeline: String,
    /// The multi-BC rollout stage's node.
    pub node: String,
    pub record: CloneRecord,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn mean_len(v: &[usize]) -> f64 {
    v.iter().sum::<usize>() as f64 / v.len().max(1) as f64
}

impl CloneRow {
    pub fn source_return(&self) -> f64 {
        mean(&self.record.fidelity.source_returns)
    }
    pub fn clone_return(&self) -> f64 {
        mean(&self.record.fidelity.clone_returns)
    }
}

/// Every multi-BC clone the store's multi-BC evaluations depend on, once per table.
pub fn rows(store: &Artifacts) -> Vec<CloneRow> {
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for m in store.iter() {
        let Ok(Typed { params: Params::Eval(p), .. }) = Typed::of(m) else { continue };
        if p.method != Method::IdrexMultiBc {
            continue;
        }
        let Some(rm) = m.inputs.get(&Role::Reward.name()).and_then(|k| store.get(k)) else { continue };
        for (role, key) in &rm.inputs {
            let Some(sm) = store.get(key) else { continue };
            if !Role::named_in(role, Series::Set) || !seen.insert((p.table(), key.clone())) {
                continue;
            }
            let Ok(Typed { metrics: Metrics::MultiBcRollouts(x), .. }) = Typed::of(sm) else { continue };
            out.extend(x.clones.into_iter().map(|record| CloneRow {
                env: p.env.name().to_string(),
                pipeline: p.table(),
                node: sm.node.clone(),
                record,
            }));
        }
    }
    out.sort_by(|a, b| (&a.env, &a.pipeline, &a.node, a.record.clone).cmp(&(&b.env, &b.pipeline, &b.node, b.record.clone)));
    out
}

/// `clones.csv`: one row per clone.
pub fn frame(rows: &[CloneRow]) -> Result<DataFrame> {
    let s = |f: &dyn Fn(&CloneRow) -> String| -> Vec<String> { rows.iter().map(f).collect() };
    let x = |f: &dyn Fn(&CloneRow) -> f64| -> Vec<f64> { rows.iter().map(f).collect() };
    let o = |f: &dyn Fn(&CloneRow) -> Option<f64>| -> Vec<Option<f64>> { rows.iter().map(f).collect() };
    let fid = |r: &CloneRow| r.record.fidelity.normalised;
    DataFrame::new_infer_height(vec![
        Column::new("env".into(), s(&|r| r.env.clone())),
        Column::new("pipeline".into(), s(&|r| r.pipeline.clone())),
        Column::new("node".into(), s(&|r| r.node.clone())),
        Column::new("clone".into(), rows.iter().map(|r| r.record.clone as u64).collect::<Vec<_>>()),
        Column::new("source_step".into(), rows.iter().map(|r| r.record.source_step.map(|s| s as u64)).collect::<Vec<_>>()),
        Column::new("source_return".into(), x(&CloneRow::source_return)),
        Column::new("source_length".into(), x(&|r| mean_len(&r.record.fidelity.source_lengths))),
        Column::new("clone_return".into(), x(&CloneRow::clone_return)),
        Column::new("clone_length".into(), x(&|r| mean_len(&r.record.fidelity.clone_lengths))),
        Column::new("fidelity".into(), o(&|r| Some(fid(r)).filter(|f| f.is_finite()))),
        Column::new("length_ratio".into(), x(&|r| r.record.fidelity.length_ratio)),
        Column::new("bc_val_loss".into(), o(&|r| Some(r.record.bc.val_loss).filter(|v| v.is_finite()))),
        Column::new("bc_best_iteration".into(), rows.iter().map(|r| r.record.bc.best_iteration.map(|i| i as u64)).collect::<Vec<_>>()),
        Column::new("filter_score".into(), o(&|r| r.record.score)),
        Column::new("kept".into(), rows.iter().map(|r| r.record.kept).collect::<Vec<_>>()),
    ])
    .map_err(pe)
}

/// The section of `report.md`, empty without clones.
pub fn markdown(rows: &[CloneRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\n## Multi-BC clones against their sources (true return of noise-free episodes; fidelity: uniform-random 0, the source's episodes 1; for the reader only, no stage reads it)\n\n| env | pipeline | clone | source return (length) | clone return (length) | fidelity | BC val loss (best iteration) | filter score | kept |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let f = &r.record.fidelity;
        let opt = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.2}"));
        out.push_str(&format!(
            "| {} | {} | {} | {:.1} ({:.0}) | {:.1} ({:.0}) | {} | {:.4} ({}) | {} | {} |\n",
            r.env,
            r.pipeline,
            r.record.clone,
            r.source_return(),
            mean_len(&f.source_lengths),
            r.clone_return(),
            mean_len(&f.clone_lengths),
            opt(Some(f.normalised).filter(|x| x.is_finite())),
            r.record.bc.val_loss,
            r.record.bc.best_iteration.map_or("-".into(), |i| i.to_string()),
            opt(r.record.score),
            if r.record.kept { "yes" } else { "no" },
        ));
    }
    let kept = rows.iter().filter(|r| r.record.kept).count();
    out.push_str(&format!("\nThe filter kept {kept} of {} clones.\n", rows.len()));
    out
}
