//! Sweeps (`sweep:` or `-S field=a,b`): per sweep, environment and protocol, one row per
//! variant and method with rliable's aggregates over its replicates, and each variant
//! compared with the sweep's baseline variant in both forms (rliable's probability of
//! improvement; paired wins with the sign test), paired by replicate: replicate r of two
//! variants shares its seeds and every stage their settings do not change.
use std::collections::BTreeMap;

use super::comparisons::compare;
use super::improvement::{LEGEND, improvement_cell};
use super::questions::{Baseline, LEVEL, Measure, Sources, studies};
use super::studies::AggregateRow;
use super::{Protocol, RESAMPLES, num};
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::Method;
use crate::pipeline::stage::eval::VariantTag;
use crate::stats::{Improvement, holm, mean};

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
    // study -> (sweep, settings, baseline): each variant's own baseline, since two sweeps of
    // one file (two `-S` runs) share the sweep's name but not their baseline.
    let mut members: BTreeMap<&str, (&str, String, &str)> = BTreeMap::new();
    for (study, t) in tags {
        members.insert(study, (&t.sweep, t.settings.join(","), &t.baseline));
    }
    for t in tags.values() {
        members.entry(&t.baseline).or_insert((&t.sweep, String::new(), &t.baseline));
    }
    let mut out = Vec::new();
    for a in aggregate {
        let Some(&(sweep, ref settings, baseline)) = members.get(a.study.as_str()) else { continue };
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
        (&x.sweep, &x.baseline, &x.env, x.protocol, x.study != x.baseline, &x.study).cmp(&(
            &y.sweep,
            &y.baseline,
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
    let mut groups: Vec<(&str, &str, &str, Protocol)> =
        rows.iter().map(|r| (r.sweep.as_str(), r.baseline.as_str(), r.env.as_str(), r.protocol)).collect();
    groups.dedup();
    for (sweep, baseline, env, protocol) in groups {
        let mine: Vec<&SweepRow> =
            rows.iter().filter(|r| r.sweep == sweep && r.baseline == baseline && r.env == env && r.protocol == protocol).collect();
        out.push_str(&format!("\n### Sweep `{sweep}`, {env}: {} (baseline `{baseline}`)\n\n", protocol.title()));
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

/// One sweep variant's method against the baseline variant's, by one measure, final policy,
/// paired by replicate: the decision a sweep exists for. Holm corrects together the variants
/// of one (sweep, baseline, env, method, measure), the family a search declares ("several
/// variants are corrected together"); which measure decides a task is the search's declared
/// choice. The methods are compared at K = 2 (an iteration past it is in `sweeps.csv` only).
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionRow {
    pub sweep: String,
    pub env: String,
    pub study: String,
    pub settings: String,
    pub baseline: String,
    pub method: Method,
    pub measure: Measure,
    /// Means over the paired replicates.
    pub variant_mean: f64,
    pub baseline_mean: f64,
    pub improvement: Improvement,
    pub holm_p: f64,
    pub family: usize,
}

impl DecisionRow {
    /// Better than the baseline: rliable's interval above 0.5 and the corrected p under
    /// [`LEVEL`], as the report's questions.
    pub fn decided(&self) -> bool {
        self.improvement.unpaired_ci.0 > 0.5 && self.holm_p < LEVEL
    }
}

/// Every variant of every sweep against its baseline, per method and measure, where both
/// have two or more paired replicates and not every pair ties (a method whose stages the
/// variant does not change, such as BC, ties on every replicate and is left out).
pub fn decide(rows: &[SweepRow], src: &Sources) -> Vec<DecisionRow> {
    let tables = studies(src.protocols);
    let mut out: Vec<DecisionRow> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for r in rows.iter().filter(|r| r.protocol == Protocol::Final && r.study != r.baseline) {
        if !seen.insert((&r.env, &r.study)) {
            continue;
        }
        let (Some(mine), Some(theirs)) = (tables.get(&(&*r.env, &*r.study)), tables.get(&(&*r.env, &*r.baseline))) else { continue };
        for method in Method::ALL {
            for measure in [Measure::Return, Measure::Forward] {
                let x = src.values(&r.env, mine, Baseline::Method(method), measure);
                let y = src.values(&r.env, theirs, Baseline::Method(method), measure);
                let pairs: Vec<(f64, f64)> = x.iter().filter_map(|(rep, a)| y.get(rep).map(|b| (*a, *b))).collect();
                if pairs.len() < 2 || pairs.iter().all(|(a, b)| a == b) {
                    continue;
                }
                let (xs, ys): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
                out.push(DecisionRow {
                    sweep: r.sweep.clone(),
                    env: r.env.clone(),
                    study: r.study.clone(),
                    settings: r.settings.clone(),
                    baseline: r.baseline.clone(),
                    method,
                    measure,
                    variant_mean: mean(&xs).unwrap_or(f64::NAN),
                    baseline_mean: mean(&ys).unwrap_or(f64::NAN),
                    improvement: Improvement::of(&pairs, RESAMPLES, 3),
                    holm_p: f64::NAN,
                    family: 0,
                });
            }
        }
    }
    let family_of = |d: &DecisionRow| (d.sweep.clone(), d.baseline.clone(), d.env.clone(), d.method, d.measure.name());
    let families: std::collections::BTreeSet<_> = out.iter().map(family_of).collect();
    for f in families {
        let members: Vec<usize> = (0..out.len()).filter(|&i| family_of(&out[i]) == f).collect();
        let corrected = holm(&members.iter().map(|&i| out[i].improvement.sign_p).collect::<Vec<_>>());
        let size = corrected.iter().filter(|p| p.is_finite()).count();
        for (&i, p) in members.iter().zip(corrected) {
            out[i].holm_p = p;
            out[i].family = size;
        }
    }
    out
}

/// `sweep_decisions.csv`: one row per (sweep, env, variant, method, measure).
impl Row for DecisionRow {
    fn header() -> Vec<&'static str> {
        let mut h = vec!["sweep", "env", "study", "settings", "baseline", "method", "measure", "variant_mean", "baseline_mean"];
        h.extend(super::improvement::COLUMNS.iter().map(|c| if *c == "replicates" { "paired_replicates" } else { c }));
        h.extend(["holm_p", "family", "decided"]);
        h
    }

    fn cells(&self) -> Vec<Cell> {
        let mut c = vec![
            Cell::text(&self.sweep),
            Cell::text(&self.env),
            Cell::text(&self.study),
            Cell::text(&self.settings),
            Cell::text(&self.baseline),
            Cell::text(self.method.name()),
            Cell::text(self.measure.name()),
            Cell::num(self.variant_mean),
            Cell::num(self.baseline_mean),
        ];
        c.extend(super::improvement::cells(&self.improvement));
        c.extend([Cell::opt(Some(self.holm_p), 3), Cell::int(self.family), Cell::text(if self.decided() { "yes" } else { "no" })]);
        c
    }
}

/// The decisions' section of `report.md`, after the sweeps'.
pub fn decisions_markdown(rows: &[DecisionRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = format!(
        "\n### Sweeps' variants against their baseline, corrected (final policy)\n\n\
         Per sweep, environment, method and measure (the true return, or the forward term alone per episode), each variant \
         against the baseline variant on the replicates both ran; the variants' sign-test p are corrected together by Holm's \
         method within that family. \"yes\" needs rliable's interval above 0.5 and the corrected p under {LEVEL}.\n\n"
    );
    let columns =
        ["sweep", "env", "method", "measure", "variant", "variant mean", "baseline mean", "P [95 % CI]; paired", "Holm p (of)", "better"];
    let cells = rows.iter().map(|d| {
        vec![
            Cell::text(&d.sweep),
            Cell::text(&d.env),
            Cell::text(d.method.label()),
            Cell::text(d.measure.name()),
            Cell::text(if d.settings.is_empty() { d.study.clone() } else { d.settings.clone() }),
            Cell::text(num(Some(d.variant_mean))),
            Cell::text(num(Some(d.baseline_mean))),
            Cell::text(improvement_cell(&d.improvement)),
            Cell::text(format!("{:.3} ({})", d.holm_p, d.family)),
            Cell::text(if d.decided() { "yes" } else { "no" }),
        ]
    });
    out.push_str(&Table { columns: columns.map(String::from).to_vec(), rows: cells.collect() }.markdown());
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

    /// Two `-S` sweeps of one file share its name, not their baseline: each variant is held
    /// against its own, and the two are shown (and corrected) apart.
    #[test]
    fn two_sweeps_of_one_file_keep_their_own_baseline() {
        let mut rows = Vec::new();
        for r in 0..3 {
            for (study, v) in [("s[c=0.5]", 1.0), ("s[c=none]", 2.0), ("s[m=3]", 10.0), ("s[m=5]", 5.0)] {
                rows.push(row(study, r, "drex", &[v + r as f64]));
            }
        }
        let (agg, _) = aggregate(&rows, &BTreeMap::new());
        let tagged = |label: &str, baseline: &str| VariantTag { baseline: baseline.into(), ..tag(label) };
        let tags: BTreeMap<String, VariantTag> = [
            ("s[c=0.5]".to_string(), tagged("c=0.5", "s[c=0.5]")),
            ("s[c=none]".to_string(), tagged("c=none", "s[c=0.5]")),
            ("s[m=3]".to_string(), tagged("m=3", "s[m=3]")),
            ("s[m=5]".to_string(), tagged("m=5", "s[m=3]")),
        ]
        .into();
        let out = super::rows(&agg, &tags);
        let got: Vec<(&str, &str, Option<usize>)> =
            out.iter().map(|r| (r.study.as_str(), r.baseline.as_str(), r.against_baseline.map(|i| i.wins))).collect();
        assert_eq!(
            got,
            [("s[c=0.5]", "s[c=0.5]", None), ("s[c=none]", "s[c=0.5]", Some(3)), ("s[m=3]", "s[m=3]", None), ("s[m=5]", "s[m=3]", Some(0))]
        );
        let md = markdown(&out);
        assert!(md.contains("(baseline `s[c=0.5]`)") && md.contains("(baseline `s[m=3]`)"), "{md}");
        let demos = BTreeMap::new();
        let decisions = decide(&out, &Sources { protocols: &rows, terms: &[], demos: &demos, accuracy: &[] });
        assert_eq!(decisions.iter().map(|d| d.family).collect::<Vec<_>>(), [1, 1], "two families of one");
    }

    /// Three variants on 10 replicates, D-REX by the true return: `a` above on all 10 by far,
    /// `c` on 9 by far, `b` on 9 by a hair (its sign test passes Holm, rliable's interval
    /// does not); BC is shared and ties, so it is no decision. By the forward term only `a`
    /// has terms, a family of one.
    #[test]
    fn variants_are_decided_by_both_forms_and_holm_per_family() {
        use crate::report::questions::tests::terms;
        let table = |s: &str, r: usize| if r == 0 { s.to_string() } else { format!("{s}/r{r}") };
        let (mut protocols, mut t) = (Vec::new(), Vec::new());
        for r in 0..10 {
            let base = 300.0 + 10.0 * r as f64;
            let one_below = |up: f64| if r == 9 { base - up } else { base + up };
            for (study, drex) in [("s", base), ("s[a]", base + 1000.0), ("s[b]", one_below(0.5)), ("s[c]", one_below(1000.0))] {
                protocols.push(row(study, r, "bc", &[100.0]));
                protocols.push(row(study, r, "drex", &[drex]));
            }
            t.push(terms(&table("s", r), "drex", 10.0, 1000.0));
            t.push(terms(&table("s[a]", r), "drex", 20.0, 1000.0));
        }
        let (agg, _) = aggregate(&protocols, &BTreeMap::new());
        let tags: BTreeMap<String, VariantTag> = ["a", "b", "c"].map(|v| (format!("s[{v}]"), tag(v))).into();
        let demos = BTreeMap::new();
        let src = Sources { protocols: &protocols, terms: &t, demos: &demos, accuracy: &[] };
        let out = decide(&super::rows(&agg, &tags), &src);
        let got: Vec<(&str, &str, usize, bool)> =
            out.iter().map(|d| (d.settings.as_str(), d.measure.name(), d.family, d.decided())).collect();
        assert_eq!(
            got,
            [("a", "return", 3, true), ("a", "forward", 1, true), ("b", "return", 3, false), ("c", "return", 3, true)],
            "BC ties everywhere and is left out"
        );
        assert!(out.iter().all(|d| d.method == Method::Drex));
        let b = &out[2];
        assert_eq!((b.improvement.wins, b.improvement.pairs), (9, 10));
        assert!(b.holm_p < LEVEL && b.improvement.unpaired_ci.0 <= 0.5, "the sign test alone would have said yes: {b:?}");
        assert!((out[0].holm_p - 3.0 / 1024.0).abs() < 1e-12 && (out[3].holm_p - 2.0 * 11.0 / 1024.0).abs() < 1e-12);
        let md = decisions_markdown(&out);
        assert!(md.contains("| s | Hopper-v5 | D-REX | return | b |") && md.contains("| 0.021 (3) | no |"), "{md}");
        let csv = Table::of(&out).csv();
        assert_eq!(csv.lines().count(), 5, "{csv}");
        assert!(csv.lines().next().unwrap().ends_with(",sign_test_p,warning,holm_p,family,decided"), "{csv}");
    }
}
