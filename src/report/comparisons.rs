//! One method in two studies compared over their shared replicates: `idrex report --compare
//! STUDY:BASELINE`.
use super::improvement::{LEGEND, improvement_cell};
use super::studies::{AggregateRow, paired};
use super::{Protocol, RESAMPLES};
use crate::log::table::{Cell, Row, Table};
use crate::stats::{Improvement, mean};

/// One method in two studies over the replicates both ran (`idrex report --compare
/// STUDY:BASELINE`): paired by replicate, since replicate r of two studies on the same seeds
/// shares its seeds and every stage the two files do not change (its rewards, where only
/// PPO's settings differ).
#[derive(Debug, Clone, PartialEq)]
pub struct ComparisonRow {
    pub env: String,
    pub protocol: Protocol,
    pub method: String,
    pub study: String,
    pub baseline: String,
    /// Replicates both studies evaluated.
    pub replicates: usize,
    /// Their mean scores over those replicates.
    pub study_mean: f64,
    pub baseline_mean: f64,
    /// Study against baseline over those replicates.
    pub improvement: Improvement,
}

/// Every (env, protocol, method) that both studies aggregate, compared on their shared
/// replicates.
pub fn compare(rows: &[AggregateRow], study: &str, baseline: &str) -> Vec<ComparisonRow> {
    rows.iter()
        .filter(|a| a.study == study)
        .filter_map(|a| {
            let b = rows.iter().find(|b| b.study == baseline && b.env == a.env && b.protocol == a.protocol && b.method == a.method)?;
            let pairs = paired(a, b);
            if pairs.is_empty() {
                return None;
            }
            let (x, y): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
            Some(ComparisonRow {
                env: a.env.clone(),
                protocol: a.protocol,
                method: a.method.clone(),
                study: study.into(),
                baseline: baseline.into(),
                replicates: pairs.len(),
                study_mean: mean(&x).unwrap_or(f64::NAN),
                baseline_mean: mean(&y).unwrap_or(f64::NAN),
                improvement: Improvement::of(&pairs, RESAMPLES, 3),
            })
        })
        .collect()
}

/// `comparisons.csv`: one row per (env, protocol, method, study, baseline).
impl Row for ComparisonRow {
    fn header() -> Vec<&'static str> {
        let mut h = vec!["env", "protocol", "method", "study", "baseline", "study_mean", "baseline_mean"];
        h.extend(super::improvement::COLUMNS);
        h
    }

    fn cells(&self) -> Vec<Cell> {
        let mut c = vec![
            Cell::text(&self.env),
            Cell::text(self.protocol.name()),
            Cell::text(&self.method),
            Cell::text(&self.study),
            Cell::text(&self.baseline),
            Cell::num(self.study_mean),
            Cell::num(self.baseline_mean),
        ];
        c.extend(super::improvement::cells(&self.improvement));
        c
    }
}

/// The comparisons' section of `report.md`.
pub fn comparison_markdown(rows: &[ComparisonRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from("\n## Studies against each other (paired by replicate)\n\n");
    let columns = ["env", "protocol", "method", "study", "baseline", "replicates", "study mean", "baseline mean", "study against baseline"];
    let rows = rows.iter().map(|r| {
        vec![
            Cell::text(&r.env),
            Cell::text(r.protocol.name()),
            Cell::text(&r.method),
            Cell::text(&r.study),
            Cell::text(&r.baseline),
            Cell::int(r.replicates),
            Cell::num(r.study_mean),
            Cell::num(r.baseline_mean),
            Cell::Text(improvement_cell(&r.improvement)),
        ]
    });
    out.push_str(&Table { columns: columns.map(String::from).to_vec(), rows: rows.collect() }.markdown());
    out.push_str(LEGEND);
    out
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::report::studies::aggregate;
    use crate::report::studies::tests::row;

    /// Two studies compared replicate by replicate, on the replicates both ran.
    #[test]
    fn compares_two_studies_on_their_shared_replicates() {
        let mut rows = Vec::new();
        for (r, new, old) in [(1, 5.0, 1.0), (2, 6.0, 7.0), (3, 8.0, 2.0)] {
            rows.push(row("new", r, "drex", &[new]));
            rows.push(row("old", r, "drex", &[old]));
        }
        rows.push(row("old", 4, "drex", &[100.0]));
        let (agg, _) = aggregate(&rows, &BTreeMap::new());
        let c = compare(&agg, "new", "old");
        assert_eq!(c.len(), 1);
        let c = &c[0];
        assert_eq!((c.replicates, c.improvement.wins), (3, 2), "replicate 4 is the old study's alone");
        assert_eq!((c.study_mean, c.baseline_mean), (19.0 / 3.0, 10.0 / 3.0));
        // 5 beats 1 and 2; 6 beats 1 and 2; 8 beats all three.
        assert_eq!(c.improvement.unpaired, 7.0 / 9.0);
        assert!(c.improvement.unpaired_ci.0 <= 7.0 / 9.0 && 7.0 / 9.0 <= c.improvement.unpaired_ci.1);
        assert!(compare(&agg, "new", "missing").is_empty());
        let md = comparison_markdown(std::slice::from_ref(c));
        assert!(md.contains("| Hopper-v5 | final | drex | new | old | 3 | 6.3 | 3.3 | P 0.78 ["), "{md}");
        assert_eq!(Table::of(std::slice::from_ref(c)).csv().lines().count(), 2);
        assert!(md.contains("2 of 3 [") && md.contains("⚠ only 3 replicates"), "{md}");
    }
}
