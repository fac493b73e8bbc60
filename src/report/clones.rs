//! Multi-BC's clones against their sources (`clones.csv` and a section of `report.md`): per
//! clone, its source's and its own noise-free true return and length, the fidelity (0 = the
//! uniform-random policy, 1 = the source), BC's validation loss and iterations, and what the
//! filter decided. The true returns are measured for the reader; no stage decides on them.
use std::collections::BTreeSet;

use super::Artifacts;
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::Method;
use crate::pipeline::role::{Role, Series};
use crate::pipeline::stage::idrex::clone::CloneRecord;
use crate::pipeline::stage::{Metrics, Typed};

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
    for (m, p, _) in store.evaluations() {
        if p.method != Method::IdrexMultiBc {
            continue;
        }
        let Some(rm) = store.input(m, Role::Reward) else { continue };
        for (key, sm) in store.inputs_in(rm, Series::Set) {
            if !seen.insert((p.table(), key.clone())) {
                continue;
            }
            let Some(Typed { metrics: Metrics::MultiBcRollouts(x), .. }) = store.typed(sm) else { continue };
            out.extend(x.clones.iter().cloned().map(|record| CloneRow {
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
impl Row for CloneRow {
    fn header() -> Vec<&'static str> {
        vec![
            "env",
            "pipeline",
            "node",
            "clone",
            "source_step",
            "source_return",
            "source_length",
            "clone_return",
            "clone_length",
            "fidelity",
            "length_ratio",
            "bc_val_loss",
            "bc_best_iteration",
            "filter_score",
            "kept",
        ]
    }

    fn cells(&self) -> Vec<Cell> {
        let f = &self.record.fidelity;
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.node),
            Cell::int(self.record.clone),
            Cell::Int(self.record.source_step.map(|s| s as u64)),
            Cell::num(self.source_return()),
            Cell::num(mean_len(&f.source_lengths)),
            Cell::num(self.clone_return()),
            Cell::num(mean_len(&f.clone_lengths)),
            Cell::opt(Some(f.normalised), 2),
            Cell::opt(Some(f.length_ratio), 2),
            Cell::opt(Some(self.record.bc.val_loss), 4),
            Cell::Int(self.record.bc.best_iteration.map(|i| i as u64)),
            Cell::opt(self.record.score, 2),
            Cell::Flag(self.record.kept),
        ]
    }
}

/// The section of `report.md`, empty without clones.
pub fn markdown(rows: &[CloneRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\n## Multi-BC clones against their sources (true return of noise-free episodes; fidelity: uniform-random 0, the source's episodes 1; for the reader only, no stage reads it)\n\n",
    );
    let columns = [
        "env",
        "pipeline",
        "clone",
        "source return (length)",
        "clone return (length)",
        "fidelity",
        "BC val loss (best iteration)",
        "filter score",
        "kept",
    ];
    let mut table = Table { columns: columns.map(String::from).to_vec(), rows: vec![] };
    for r in rows {
        let f = &r.record.fidelity;
        let opt = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.2}"));
        table.rows.push(vec![
            Cell::text(&r.env),
            Cell::text(&r.pipeline),
            Cell::int(r.record.clone),
            Cell::Text(format!("{:.1} ({:.0})", r.source_return(), mean_len(&f.source_lengths))),
            Cell::Text(format!("{:.1} ({:.0})", r.clone_return(), mean_len(&f.clone_lengths))),
            Cell::Text(opt(Some(f.normalised).filter(|x| x.is_finite()))),
            Cell::Text(format!("{:.4} ({})", r.record.bc.val_loss, r.record.bc.best_iteration.map_or("-".into(), |i| i.to_string()))),
            Cell::Text(opt(r.record.score)),
            Cell::Flag(r.record.kept),
        ]);
    }
    out.push_str(&table.markdown());
    let kept = rows.iter().filter(|r| r.record.kept).count();
    out.push_str(&format!("\nThe filter kept {kept} of {} clones.\n", rows.len()));
    out
}
