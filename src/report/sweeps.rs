//! Sweeps (`sweep:` or `-S field=a,b`): per sweep, environment and protocol, one row per
//! variant and method with rliable's aggregates over its replicates, and each variant
//! compared with the sweep's baseline variant in both forms (rliable's probability of
//! improvement; paired wins with the sign test), paired by replicate: replicate r of two
//! variants shares its seeds and every stage their settings do not change.
use std::collections::BTreeMap;

use super::comparisons::compare;
use super::improvement::{LEGEND, improvement_cell};
use super::studies::AggregateRow;
use super::{Protocol, num};
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::stage::eval::VariantTag;
use crate::stats::Improvement;

/// One variant's method in a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRow {
    pub sweep: String,
    pub env: String,
    pub protocol: Protocol,
    /// The variant's study (`halfcheetah[reward.ceiling=0.5]`).
    pub study: String,
    /// What it sets (`reward.ceiling=0.5`); empty for the file itself.
    pub settings: String,
    pub method: String,
    pub aggregate: AggregateRow,
    pub baseline: String,
    /// Against the baseline variant's same method, over the replicates both ran; None for
    /// the baseline itself.
    pub against_baseline: Option<Improvement>,
}

/// The sweeps' rows: every aggregated study a tag names (a variant, or a baseline).
pub fn rows(aggregate: &[AggregateRow], tags: &BTreeMap<String, VariantTag>) -> Vec<SweepRow> {
    // sweep -> baseline study, and study -> (sweep, settings).
    let mut members: BTreeMap<&str, (&str, String)> = BTreeMap::new();
    let mut baselines: BTreeMap<&str, &str> = BTreeMap::new();
    for (study, t) in tags {
        members.insert(study, (&t.sweep, t.settings.join(",")));
        baselines.insert(&t.sweep, &t.baseline);
    }
    for (sweep, baseline) in &baselines {
        members.entry(baseline).or_insert((sweep, String::new()));
    }
    let mut out = Vec::new();
    for a in aggregate {
        let Some((sweep, settings)) = members.get(a.study.as_str()) else { continue };
        let baseline = baselines[sweep];
        let against_baseline = (a.study != baseline)
            .then(|| {
                compare(aggregate, &a.study, baseline)
                    .into_iter()
                    .find(|c| c.env == a.env && c.protocol == a.protocol && c.method == a.method)
                    .map(|c| c.improvement)
            })
            .flatten();
        out.push(SweepRow {
            sweep: sweep.to_string(),
            env: a.env.clone(),
            protocol: a.protocol,
            study: a.study.clone(),
            settings: settings.clone(),
            method: a.method.clone(),
            aggregate: a.clone(),
            baseline: baseline.to_string(),
            against_baseline,
        });
    }
    // The baseline first, then the variants in name order; methods as aggregated.
    out.sort_by(|x, y| {
        (&x.sweep, &x.env, x.protocol, x.study != x.baseline, &x.study).cmp(&(
            &y.sweep,
            &y.env,
            y.protocol,
            y.study != y.baseline,
            &y.study,
        ))
    });
    out
}

/// `sweeps.csv`: one row per (sweep, env, protocol, variant, method): the sweep, the
/// variant's settings and baseline, its `aggregate.csv` row, and the comparison's columns.
impl Row for SweepRow {
    fn header() -> Vec<&'static str> {
        let mut h = vec!["sweep", "settings", "baseline"];
        h.extend(AggregateRow::header());
        h.extend(super::improvement::COLUMNS.iter().map(|c| if *c == "replicates" { "paired_replicates" } else { c }));
        h
    }

    fn cells(&self) -> Vec<Cell> {
        let mut c = vec![Cell::text(&self.sweep), Cell::text(&self.settings), Cell::text(&self.baseline)];
        c.extend(self.aggregate.cells());
        match &self.against_baseline {
            Some(i) => c.extend(super::improvement::cells(i)),
            None => c.extend(std::iter::repeat_n(Cell::Num(None, 3), super::improvement::COLUMNS.len())),
        }
        c
    }
}

/// The sweeps' section of `report.md`: per sweep, environment and protocol, a row per
/// variant and method.
pub fn markdown(rows: &[SweepRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\n## Sweeps (per replicate: the mean of its runs' mean returns; 95 % intervals resample replicates, then runs within them)\n",
    );
    let mut groups: Vec<(&str, &str, Protocol)> = rows.iter().map(|r| (r.sweep.as_str(), r.env.as_str(), r.protocol)).collect();
    groups.dedup();
    for (sweep, env, protocol) in groups {
        let mine: Vec<&SweepRow> = rows.iter().filter(|r| r.sweep == sweep && r.env == env && r.protocol == protocol).collect();
        out.push_str(&format!("\n### Sweep `{sweep}`, {env}: {} (baseline `{}`)\n\n", protocol.title(), mine[0].baseline));
        let columns = ["variant", "settings", "method", "replicates (runs)", "mean [95 % CI]", "IQM [95 % CI]", "against the baseline"];
        let ci = |v: f64, (lo, hi): (f64, f64)| format!("{} [{}, {}]", num(Some(v)), num(Some(lo)), num(Some(hi)));
        let cells = mine.iter().map(|r| {
            let a = &r.aggregate;
            let against = match (&r.against_baseline, r.study == r.baseline) {
                (Some(i), _) => improvement_cell(i),
                (None, true) => "baseline".to_string(),
                (None, false) => "no shared replicate".to_string(),
            };
            let settings = if r.settings.is_empty() { "(the file's)".to_string() } else { r.settings.clone() };
            [
                r.study.clone(),
                settings,
                r.method.clone(),
                format!("{} ({})", a.replicates, a.runs),
                ci(a.mean, a.mean_ci),
                ci(a.iqm, a.iqm_ci),
                against,
            ]
            .map(Cell::Text)
            .to_vec()
        });
        out.push_str(&Table { columns: columns.map(String::from).to_vec(), rows: cells.collect() }.markdown());
    }
    out.push_str(LEGEND);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::studies::aggregate;
    use crate::report::studies::tests::row;

    fn tag(label: &str) -> VariantTag {
        VariantTag { sweep: "s".into(), label: label.into(), settings: vec![label.into()], baseline: "s".into() }
    }

    /// Two variants against the file itself, replicate by replicate; a study outside the
    /// sweep is left out.
    #[test]
    fn each_variant_is_compared_with_the_baseline() {
        let mut rows = Vec::new();
        for (r, base, high, low) in [(0, 1.0, 5.0, 0.0), (1, 2.0, 6.0, 3.0), (2, 3.0, 7.0, 1.0)] {
            rows.push(row("s", r, "drex", &[base]));
            rows.push(row("s[c=0.5]", r, "drex", &[high]));
            rows.push(row("s[c=none]", r, "drex", &[low]));
            rows.push(row("other", r, "drex", &[9.0]));
        }
        let (agg, _) = aggregate(&rows, &BTreeMap::new());
        let tags: BTreeMap<String, VariantTag> = [("s[c=0.5]".to_string(), tag("c=0.5")), ("s[c=none]".to_string(), tag("c=none"))].into();
        let out = super::rows(&agg, &tags);
        let studies: Vec<&str> = out.iter().map(|r| r.study.as_str()).collect();
        assert_eq!(studies, ["s", "s[c=0.5]", "s[c=none]"], "the baseline first, `other` left out");
        assert!(out[0].against_baseline.is_none() && out[0].settings.is_empty());
        let high = out[1].against_baseline.unwrap();
        assert_eq!((high.wins, high.pairs, high.unpaired), (3, 3, 1.0));
        let low = out[2].against_baseline.unwrap();
        assert_eq!((low.wins, low.pairs), (1, 3), "3 beats 2; 0 and 1 lose");
        let md = markdown(&out);
        assert!(md.contains("### Sweep `s`, Hopper-v5") && md.contains("| s | (the file's) | drex | 3 (3) |"), "{md}");
        assert!(md.contains("| s[c=0.5] | c=0.5 | drex | 3 (3) | 6.0 [") && md.contains("P 1.00"), "{md}");
        let csv = Table::of(&out).csv();
        assert_eq!(csv.lines().count(), 4, "{csv}");
        assert!(csv.lines().next().unwrap().starts_with("sweep,settings,baseline,env,study,method,protocol,replicates,"), "{csv}");
        assert!(csv.lines().next().unwrap().contains(",paired_replicates,rliable_probability,"), "{csv}");
    }
}
