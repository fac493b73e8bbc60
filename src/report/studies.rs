//! Replicated studies: per environment, method and protocol, the replicates' results
//! aggregated with the statistics of rliable (Agarwal et al., NeurIPS 2021) for few runs.
//!
//! The replicate is the unit: a replicate's runs share its BC policy and learned rewards, so
//! they are not independent of each other. Each replicate's score is the mean of its runs'
//! mean returns at the protocol's policy; the table gives the mean, interquartile mean and
//! median of those scores, 95 % intervals that resample replicates and then runs within
//! them ([`hierarchical_ci`]), the fractions of replicates above the demonstrations'
//! average and best, and each method's probability of improvement over D-REX and over BC.
use std::collections::BTreeMap;

use super::{Protocol, ProtocolRow, RESAMPLES, num};
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::Method;
use crate::stats::{Improvement, WinCount, hierarchical_ci, iqm, mean, median};

/// One (env, study, method, protocol) over its replicates.
#[derive(Debug, Clone, PartialEq)]
pub struct AggregateRow {
    pub env: String,
    pub study: String,
    pub method: String,
    pub protocol: Protocol,
    pub replicates: usize,
    pub runs: usize,
    /// Of the replicates' scores.
    pub mean: f64,
    pub iqm: f64,
    pub median: f64,
    pub mean_ci: (f64, f64),
    pub iqm_ci: (f64, f64),
    /// The replicates whose score is above their demonstrations' average, and best.
    pub above_demos_avg: WinCount,
    pub above_demos_best: WinCount,
    /// Each replicate's score, in replicate order.
    pub scores: Vec<(usize, f64)>,
}

/// What a method is compared against in its study.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Against {
    Drex,
    Bc,
    /// The same method one iteration earlier (K - 1, for K > 2).
    PreviousIteration,
}

/// P(method beats baseline) over one study's replicates.
#[derive(Debug, Clone, PartialEq)]
pub struct ImprovementRow {
    pub env: String,
    pub study: String,
    pub protocol: Protocol,
    pub method: String,
    pub against: Against,
    /// The baseline's label (`drex`, `bc`, `idrex-multi-bc` for the K = 3 row's K = 2).
    pub baseline: String,
    /// Over the replicates where both were evaluated.
    pub improvement: Improvement,
}

fn mean_of(v: &[f64]) -> f64 {
    mean(v).unwrap_or(f64::NAN)
}

/// The aggregate rows and probabilities of improvement of every study with two or more
/// replicates (a single replicate is its own table). `demos` maps (env, table) to the
/// demonstrations' returns.
pub fn aggregate(rows: &[ProtocolRow], demos: &BTreeMap<(String, String), Vec<f64>>) -> (Vec<AggregateRow>, Vec<ImprovementRow>) {
    let mut cells: BTreeMap<(&str, &str, Protocol, &str), Vec<&ProtocolRow>> = BTreeMap::new();
    for r in rows {
        cells.entry((&r.env, &r.study, r.protocol, &r.method)).or_default().push(r);
    }
    let mut replicates: BTreeMap<(&str, &str), std::collections::BTreeSet<usize>> = BTreeMap::new();
    for r in rows {
        replicates.entry((&r.env, &r.study)).or_default().insert(r.replicate);
    }
    let mut out = Vec::new();
    for ((env, study, protocol, method), mut cell) in cells {
        if replicates[&(env, study)].len() < 2 {
            continue;
        }
        cell.sort_by_key(|r| r.replicate);
        let groups: Vec<Vec<f64>> = cell.iter().map(|r| r.run_means.clone()).collect();
        let scores: Vec<f64> = groups.iter().map(|g| mean_of(g)).collect();
        let above = |pick: fn(&[f64]) -> f64| {
            let judged: Vec<bool> = cell
                .iter()
                .zip(&scores)
                .filter_map(|(r, s)| demos.get(&(env.to_string(), r.pipeline.clone())).map(|d| *s > pick(d)))
                .collect();
            WinCount { k: judged.iter().filter(|&&b| b).count(), n: judged.len() }
        };
        out.push(AggregateRow {
            env: env.into(),
            study: study.into(),
            method: method.into(),
            protocol,
            replicates: cell.len(),
            runs: groups.iter().map(Vec::len).sum(),
            mean: mean_of(&scores),
            iqm: iqm(&scores),
            median: median(&scores),
            mean_ci: hierarchical_ci(&groups, mean_of, RESAMPLES, 0),
            iqm_ci: hierarchical_ci(&groups, iqm, RESAMPLES, 1),
            above_demos_avg: above(mean_of),
            above_demos_best: above(|d| d.iter().copied().fold(f64::NEG_INFINITY, f64::max)),
            scores: cell.iter().map(|r| r.replicate).zip(scores.iter().copied()).collect(),
        });
    }
    let mut improvement = Vec::new();
    for a in &out {
        let previous = super::previous_iteration(&a.method).map(|p| (Against::PreviousIteration, p));
        let baselines = [(Against::Drex, Method::Drex.name().to_string()), (Against::Bc, Method::Bc.name().to_string())];
        for (against, baseline) in baselines.into_iter().chain(previous) {
            if a.method == baseline {
                continue;
            }
            let Some(b) = out.iter().find(|b| b.env == a.env && b.study == a.study && b.protocol == a.protocol && b.method == baseline)
            else {
                continue;
            };
            let pairs = paired(a, b);
            improvement.push(ImprovementRow {
                env: a.env.clone(),
                study: a.study.clone(),
                protocol: a.protocol,
                method: a.method.clone(),
                against,
                baseline,
                improvement: Improvement::of(&pairs, RESAMPLES, 2),
            });
        }
    }
    (out, improvement)
}

/// `row`'s comparison against `against`, where its study has one.
pub(super) fn find<'a>(improvement: &'a [ImprovementRow], row: &AggregateRow, against: Against) -> Option<&'a ImprovementRow> {
    improvement
        .iter()
        .find(|i| i.env == row.env && i.study == row.study && i.protocol == row.protocol && i.method == row.method && i.against == against)
}

/// The two rows' scores on the replicates both have, replicate by replicate.
pub(super) fn paired(a: &AggregateRow, b: &AggregateRow) -> Vec<(f64, f64)> {
    a.scores.iter().filter_map(|(r, x)| b.scores.iter().find(|(rb, _)| rb == r).map(|(_, y)| (*x, *y))).collect()
}

/// `aggregate.csv`: one row per (env, study, method, protocol).
impl Row for AggregateRow {
    fn header() -> Vec<&'static str> {
        vec![
            "env",
            "study",
            "method",
            "protocol",
            "replicates",
            "runs",
            "mean",
            "mean_ci_low",
            "mean_ci_high",
            "iqm",
            "iqm_ci_low",
            "iqm_ci_high",
            "median",
            "above_demos_avg",
            "above_demos_avg_sign_p",
            "above_demos_avg_rate_low",
            "above_demos_best",
            "above_demos_best_sign_p",
            "above_demos_best_rate_low",
        ]
    }

    fn cells(&self) -> Vec<Cell> {
        let x = |v: f64| Cell::opt(Some(v), 1);
        let p = |v: f64| Cell::opt(Some(v), 3);
        vec![
            Cell::text(&self.env),
            Cell::text(&self.study),
            Cell::text(&self.method),
            Cell::text(self.protocol.name()),
            Cell::int(self.replicates),
            Cell::int(self.runs),
            x(self.mean),
            x(self.mean_ci.0),
            x(self.mean_ci.1),
            x(self.iqm),
            x(self.iqm_ci.0),
            x(self.iqm_ci.1),
            x(self.median),
            p(self.above_demos_avg.fraction()),
            p(self.above_demos_avg.sign_p()),
            p(self.above_demos_avg.lower()),
            p(self.above_demos_best.fraction()),
            p(self.above_demos_best.sign_p()),
            p(self.above_demos_best.lower()),
        ]
    }
}

/// `improvement.csv`: one row per (env, study, protocol, method, baseline).
impl Row for ImprovementRow {
    fn header() -> Vec<&'static str> {
        let mut h = vec!["env", "study", "protocol", "method", "baseline"];
        h.extend(super::improvement::COLUMNS);
        h
    }

    fn cells(&self) -> Vec<Cell> {
        let mut c = vec![
            Cell::text(&self.env),
            Cell::text(&self.study),
            Cell::text(self.protocol.name()),
            Cell::text(&self.method),
            Cell::text(&self.baseline),
        ];
        c.extend(super::improvement::cells(&self.improvement));
        c
    }
}

/// The studies' section of `report.md`: per environment and protocol, every method's
/// aggregate, then the probabilities of improvement.
pub fn markdown(rows: &[AggregateRow], improvement: &[ImprovementRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\n## Replicated studies (per replicate: the mean of its runs' mean returns; 95 % intervals resample replicates, then runs within them)\n",
    );
    let mut groups: Vec<(&str, &str, Protocol)> = rows.iter().map(|r| (r.env.as_str(), r.study.as_str(), r.protocol)).collect();
    groups.sort();
    groups.dedup();
    for (env, study, protocol) in groups {
        out.push_str(&format!("\n### {env}, study `{study}`: {}\n\n", protocol.title()));
        let columns = [
            "method",
            "replicates (runs)",
            "mean [95 % CI]",
            "IQM [95 % CI]",
            "median",
            "above demos avg",
            "above demos best",
            "against D-REX",
            "against BC",
            "against K - 1",
        ];
        let mut table = Table { columns: columns.map(String::from).to_vec(), rows: vec![] };
        for r in rows.iter().filter(|r| r.env == env && r.study == study && r.protocol == protocol) {
            let p = |against: Against| {
                find(improvement, r, against).map_or("-".to_string(), |i| super::improvement::improvement_cell(&i.improvement))
            };
            let ci = |v: f64, (lo, hi): (f64, f64)| format!("{} [{}, {}]", num(Some(v)), num(Some(lo)), num(Some(hi)));
            table.rows.push(
                [
                    r.method.clone(),
                    format!("{} ({})", r.replicates, r.runs),
                    ci(r.mean, r.mean_ci),
                    ci(r.iqm, r.iqm_ci),
                    num(Some(r.median)),
                    r.above_demos_avg.to_string(),
                    r.above_demos_best.to_string(),
                    p(Against::Drex),
                    p(Against::Bc),
                    p(Against::PreviousIteration),
                ]
                .map(Cell::Text)
                .to_vec(),
            );
        }
        out.push_str(&table.markdown());
    }
    out.push_str(super::improvement::LEGEND);
    out.push_str("\"Against K - 1\": an iterated method against itself one iteration earlier, on the same replicates.\n\n");
    out
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::stats::ReturnStats;

    /// One (study, replicate, method)'s final-policy row from its runs' means.
    pub(in crate::report) fn row(study: &str, replicate: usize, method: &str, run_means: &[f64]) -> ProtocolRow {
        ProtocolRow {
            env: "Hopper-v5".into(),
            pipeline: if replicate == 0 { study.into() } else { format!("{study}/r{replicate}") },
            study: study.into(),
            replicate,
            run_means: run_means.to_vec(),
            method: method.into(),
            protocol: Protocol::Final,
            step: None,
            stats: ReturnStats::of(run_means),
            runs: run_means.len(),
            ci: (0.0, 0.0),
            gap_to_best: None,
        }
    }

    /// Replicates 0-1 from one file and 2-3 from another of the same study are one study;
    /// a single-replicate pipeline beside them is left to its own table.
    #[test]
    fn aggregates_a_study_over_its_files_and_replicates() {
        let mut rows = Vec::new();
        for (r, drex, bc) in [(0, [0.0, 2.0], 1.0), (1, [10.0, 10.0], 1.0), (2, [4.0, 4.0], 5.0), (3, [6.0, 8.0], 1.0)] {
            rows.push(row("s", r, "drex", &drex));
            rows.push(row("s", r, "bc", &[bc]));
        }
        rows.push(row("alone", 0, "drex", &[3.0]));
        let demos: BTreeMap<(String, String), Vec<f64>> =
            ["s", "s/r1", "s/r2", "s/r3"].iter().map(|t| (("Hopper-v5".to_string(), t.to_string()), vec![2.0, 6.0])).collect();
        let (agg, imp) = aggregate(&rows, &demos);
        assert!(agg.iter().all(|a| a.study == "s"), "one replicate is no study");
        let d = agg.iter().find(|a| a.method == "drex").unwrap();
        // Scores 1, 10, 4, 7.
        assert_eq!((d.replicates, d.runs), (4, 8));
        assert_eq!((d.mean, d.median), (5.5, 5.5));
        assert_eq!(d.iqm, 5.5, "the middle two of 1, 4, 7, 10");
        assert!(d.mean_ci.0 < 5.5 && d.mean_ci.1 > 5.5 && d.mean_ci.0 >= 1.0 && d.mean_ci.1 <= 10.0, "{:?}", d.mean_ci);
        // Above the demonstrations' average 4: 10 and 7; above their best 6: the same two.
        assert_eq!((d.above_demos_avg, d.above_demos_best), (WinCount { k: 2, n: 4 }, WinCount { k: 2, n: 4 }));
        // D-REX against BC's 1, 1, 5, 1: 1 vs {1,1,5,1} = 1.5, 10 and 7 win all 4, 4 wins 3.
        let p = imp.iter().find(|i| i.method == "drex" && i.baseline == "bc").unwrap().improvement;
        assert_eq!((p.pairs, p.unpaired), (4, (1.5 + 4.0 + 3.0 + 4.0) / 16.0));
        assert!(p.unpaired_ci.0 <= p.unpaired && p.unpaired <= p.unpaired_ci.1);
        // Paired: 1 ties 1, 10 > 1, 4 < 5, 7 > 1.
        assert_eq!((p.wins, p.ties), (2, 1));
        assert!(imp.iter().all(|i| i.method != i.baseline));
        let md = markdown(&agg, &imp);
        assert!(md.contains("| drex | 4 (8) | 5.5 [") && md.contains("study `s`"), "{md}");
        let csv = Table::of(&agg).csv();
        assert_eq!(csv.lines().count(), 3, "a header and two rows: {csv}");
    }

    /// K = 3 is compared with K = 2 on the same replicates; K = 2's iteration before is
    /// D-REX, compared already.
    #[test]
    fn an_iteration_past_two_is_compared_with_the_one_before() {
        let mut rows = Vec::new();
        for (r, k2, k3) in [(0, 1.0, 2.0), (1, 5.0, 3.0), (2, 4.0, 6.0), (3, 7.0, 7.0)] {
            rows.push(row("s", r, "drex", &[0.0]));
            rows.push(row("s", r, "idrex-multi-bc", &[k2]));
            rows.push(row("s", r, "idrex-multi-bc (k=3)", &[k3]));
        }
        let (agg, imp) = aggregate(&rows, &BTreeMap::new());
        let previous: Vec<&ImprovementRow> = imp.iter().filter(|i| i.against == Against::PreviousIteration).collect();
        assert_eq!(previous.len(), 1, "{imp:?}");
        let p = previous[0];
        assert_eq!((p.method.as_str(), p.baseline.as_str()), ("idrex-multi-bc (k=3)", "idrex-multi-bc"));
        assert_eq!((p.improvement.wins, p.improvement.ties, p.improvement.pairs), (2, 1, 4));
        assert!(super::super::improvement::improvement_cell(&p.improvement).contains("; 2 of 3 ["), "ties leave the count");
        assert!(super::super::improvement::improvement_cell(&p.improvement).contains(", 1 tie ⚠ only 4 replicates"));
        let k3 = agg.iter().find(|a| a.method == "idrex-multi-bc (k=3)").unwrap();
        assert_eq!(find(&imp, k3, Against::PreviousIteration), Some(p));
        assert!(markdown(&agg, &imp).contains("against K - 1"));
        assert!(Table::of(&imp).csv().contains("idrex-multi-bc (k=3),idrex-multi-bc,4,"));
    }
}
