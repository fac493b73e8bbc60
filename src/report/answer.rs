//! The report's first section: the user's question answered before the tables. Per
//! environment and table, each learned-reward method's final-policy return against BC and
//! the demonstrations, with its interval, and one sentence on what the numbers mean.
//!
//! A single pipeline's interval is over its RL runs, which share one BC policy and one
//! learned reward: it measures PPO's seed, not another seed set. A replicated study's is over
//! replicates (then runs), and its comparisons count replicates, with a sign test.
use std::collections::BTreeMap;

use super::improvement::improvement_cell;
use super::looks::LookRow;
use super::studies::{Against, AggregateRow, ImprovementRow, find};
use super::{Protocol, ProtocolRow, num};
use crate::algo::scoring::CloneGap;
use crate::pipeline::Method;
use crate::stats::{Verdict, WinCount, mean, sign_test_p};

/// How a method's return stands against a reference (BC's, or the demonstrations' average).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Standing {
    /// Its whole interval lies above the reference.
    Above,
    /// Its mean is above, but its interval reaches the reference.
    AboveOnAverage,
    /// Its mean is at or below the reference.
    Below,
}

impl Standing {
    pub fn of(mean: f64, ci: (f64, f64), reference: f64) -> Standing {
        if ci.0 > reference {
            Standing::Above
        } else if mean > reference {
            Standing::AboveOnAverage
        } else {
            Standing::Below
        }
    }

    fn words(self, diff: f64) -> String {
        match self {
            Standing::Above => format!("{diff:+.1}, interval above"),
            Standing::AboveOnAverage => format!("{diff:+.1}, interval overlaps"),
            Standing::Below => format!("{diff:+.1}, below"),
        }
    }
}

/// A method's display name from its report label (`drex`, `idrex-multi-bc (k=3)`).
fn display(label: &str) -> String {
    let (name, rest) = label.split_once(' ').map_or((label, ""), |(a, b)| (a, b));
    let shown = Method::ALL.iter().find(|m| m.name() == name).map_or(name, |m| m.label());
    if rest.is_empty() { shown.to_string() } else { format!("{shown} {rest}") }
}

/// The sentence under a table: which methods cleared both references.
fn sentence(above_both: &[String], on_average: &[String], below: &[String], scope: &str) -> String {
    let list = |v: &[String]| match v.len() {
        0 => String::new(),
        1 => v[0].clone(),
        n => format!("{} and {}", v[..n - 1].join(", "), v[n - 1]),
    };
    let mut parts = Vec::new();
    if !above_both.is_empty() {
        parts.push(format!(
            "{} beat{} both BC and the demonstrations with intervals clear of them",
            list(above_both),
            if above_both.len() == 1 { "s" } else { "" }
        ));
    }
    if !on_average.is_empty() {
        parts.push(format!(
            "{} {} above both on average only (the interval reaches one of them)",
            list(on_average),
            if on_average.len() == 1 { "is" } else { "are" }
        ));
    }
    if !below.is_empty() {
        parts.push(format!("{} {} not above both", list(below), if below.len() == 1 { "is" } else { "are" }));
    }
    format!("{}. {scope}\n", capitalise(&parts.join("; ")))
}

/// One line per comparison between learned-reward methods (against D-REX, against K - 1):
/// what it decides at the 5 % level, in words, with the figures it rests on.
fn verdicts(rows: &[&AggregateRow], improvement: &[ImprovementRow]) -> String {
    let mut lines = Vec::new();
    for r in rows.iter().filter(|r| r.method != Method::Bc.name()) {
        for (against, what) in [(Against::Drex, "D-REX"), (Against::PreviousIteration, "K - 1")] {
            let Some(i) = find(improvement, r, against) else { continue };
            let m = i.improvement;
            let words = match m.verdict() {
                Verdict::Better => "beats",
                Verdict::Worse => "is beaten by",
                Verdict::NoDifferenceShown => "shows no difference from",
            };
            let ties = if m.ties > 0 { format!(", {} tied", m.ties) } else { String::new() };
            lines.push(format!(
                "{} {words} {what} (P {:.2} [{:.2}, {:.2}]; above on {} of {} replicates{ties}, p = {:.3}).",
                display(&r.method),
                m.unpaired,
                m.unpaired_ci.0,
                m.unpaired_ci.1,
                m.wins,
                m.pairs,
                m.sign_p
            ));
        }
    }
    if lines.is_empty() {
        return String::new();
    }
    format!(
        "\nBetween learned-reward methods, at the 5 % level (a difference needs rliable's interval clear of 0.5 and the sign \
         test below 0.05): {}\n",
        lines.join(" ")
    )
}

/// The sentence's first letter in upper case, unless it opens a name spelled with a
/// lower-case first letter (iD-REX).
fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    match (c.next(), c.next()) {
        (Some(_), Some(second)) if second.is_uppercase() => s.to_string(),
        (Some(first), _) => first.to_uppercase().collect::<String>() + &s[first.len_utf8()..],
        _ => String::new(),
    }
}

/// The answer for every table of the report: replicated studies from their aggregate rows,
/// single pipelines from their final-policy rows. `demos` maps (env, table) to the
/// demonstrations' returns.
pub fn markdown(
    protocols: &[ProtocolRow],
    aggregate: &[AggregateRow],
    improvement: &[ImprovementRow],
    demos: &BTreeMap<(String, String), Vec<f64>>,
    looks: &[LookRow],
    bc_warning: f64,
) -> String {
    // A study whose seeds were looked at more than once, or that reused a test set, says so.
    let caveat = |env: &str, study: &str| {
        looks
            .iter()
            .find(|l| l.env == env && l.study == study)
            .filter(|l| l.configurations > 1 || matches!(l.mark, Some(crate::store::TestSetMark::Reuse { .. })))
            .map_or(String::new(), |l| format!(" ({})", l.verdict()))
    };
    let out = single_tables(protocols, aggregate, demos, &caveat, bc_warning)
        + &replicated_studies(aggregate, improvement, demos, &caveat, bc_warning);
    if out.is_empty() {
        return out;
    }
    format!("## The answer\n\n{out}")
}

/// The answer for each single pipeline's table (a study without replicates): each method's
/// final-policy return against BC and the demonstrations, over its RL runs.
fn single_tables(
    protocols: &[ProtocolRow],
    aggregate: &[AggregateRow],
    demos: &BTreeMap<(String, String), Vec<f64>>,
    caveat: &dyn Fn(&str, &str) -> String,
    bc_warning: f64,
) -> String {
    let mut out = String::new();
    let replicated: std::collections::BTreeSet<(&str, &str)> = aggregate.iter().map(|a| (a.env.as_str(), a.study.as_str())).collect();
    // Single tables: (env, table) -> its final-policy rows.
    let mut tables: BTreeMap<(&str, &str), Vec<&ProtocolRow>> = BTreeMap::new();
    for r in protocols.iter().filter(|r| r.protocol == Protocol::Final && !replicated.contains(&(r.env.as_str(), r.study.as_str()))) {
        tables.entry((&r.env, &r.pipeline)).or_default().push(r);
    }
    for ((env, table), rows) in &tables {
        let Some(bc) = rows.iter().find(|r| r.method == Method::Bc.name()) else { continue };
        let demo = demos.get(&(env.to_string(), table.to_string())).and_then(|d| mean(d));
        let Some(demo) = demo else { continue };
        let runs = rows.iter().filter(|r| r.method != Method::Bc.name()).map(|r| r.runs).max().unwrap_or(0);
        out.push_str(&format!(
            "### {env}, {table}{}\n\nFinal policy, ground-truth return: the mean over {runs} RL runs with a 95 % bootstrap interval over runs. \
             BC {}; the demonstrations {} (average).\n\n",
            caveat(env, &bc.study),
            num(Some(bc.stats.mean)),
            num(Some(demo))
        ));
        // Before the table, not inside it: a line between a table's header and its rows ends it.
        if let Some(gap) = CloneGap::check(bc.stats.mean, demo, bc_warning) {
            out.push_str(&format!("**{}**\n\n", gap.sentence()));
        }
        out.push_str("| method | return [95 % CI] | against BC | against the demonstrations |\n|---|---|---|---|\n");
        let (mut both, mut avg, mut below) = (vec![], vec![], vec![]);
        for r in rows.iter().filter(|r| r.method != Method::Bc.name()) {
            let m = r.stats.mean;
            let (sb, sd) = (Standing::of(m, r.ci, bc.stats.mean), Standing::of(m, r.ci, demo));
            out.push_str(&format!(
                "| {} | {} [{}, {}] | {} | {} |\n",
                display(&r.method),
                num(Some(m)),
                num(Some(r.ci.0)),
                num(Some(r.ci.1)),
                sb.words(m - bc.stats.mean),
                sd.words(m - demo)
            ));
            let name = display(&r.method);
            match (sb, sd) {
                (Standing::Above, Standing::Above) => both.push(name),
                (Standing::Below, _) | (_, Standing::Below) => below.push(name),
                _ => avg.push(name),
            }
        }
        out.push('\n');
        out.push_str(&sentence(
            &both,
            &avg,
            &below,
            &format!(
                "These are {runs} RL runs on one seed set: they share one BC policy and one learned reward per method, so the \
                 interval says how much PPO's seed moves the result, not whether another seed set would agree; replicated \
                 studies (`replicates:`) answer that."
            ),
        ));
        out.push('\n');
    }
    out
}

/// The answer for each replicated study: the mean over replicates, and replicate-by-replicate
/// counts with the sign test.
fn replicated_studies(
    aggregate: &[AggregateRow],
    improvement: &[ImprovementRow],
    demos: &BTreeMap<(String, String), Vec<f64>>,
    caveat: &dyn Fn(&str, &str) -> String,
    bc_warning: f64,
) -> String {
    let mut out = String::new();
    let mut studies: BTreeMap<(&str, &str), Vec<&AggregateRow>> = BTreeMap::new();
    for a in aggregate.iter().filter(|a| a.protocol == Protocol::Final) {
        studies.entry((&a.env, &a.study)).or_default().push(a);
    }
    for ((env, study), rows) in &studies {
        let Some(bc) = rows.iter().find(|r| r.method == Method::Bc.name()) else { continue };
        let n = rows.iter().map(|r| r.replicates).max().unwrap_or(0);
        out.push_str(&format!(
            "### {env}, {study} ({n} replicates){}\n\nFinal policy, ground-truth return: the mean over replicates of each replicate's mean \
             over its runs, with a 95 % interval that resamples replicates and then runs. BC {}. \"k of n\" counts replicates; p is the \
             one-sided sign test, and \"rate ≥\" the 95 % Clopper-Pearson lower bound on the rate. Against another method: \
             rliable's probability of improvement P with its independent-bootstrap interval, then the replicates where the \
             method scored above (paired by replicate) with the exact interval of that rate and the sign test's p.\n\n",
            caveat(env, study),
            num(Some(bc.mean))
        ));
        // Per replicate: its BC against its own demonstrations (table `study/rK`; replicate 0's
        // is the study's own name, its keys those of a file without replicates).
        let demos_of = |rep: usize| {
            let table = |name: String| demos.get(&(env.to_string(), name));
            table(format!("{study}/r{rep}")).or_else(|| if rep == 0 { table(study.to_string()) } else { None }).and_then(|d| mean(d))
        };
        let gaps: Vec<CloneGap> =
            bc.scores.iter().filter_map(|&(rep, b)| demos_of(rep).and_then(|d| CloneGap::check(b, d, bc_warning))).collect();
        if !gaps.is_empty() {
            let worst = gaps.iter().min_by(|a, b| (a.bc - a.demos).total_cmp(&(b.bc - b.demos))).expect("not empty");
            out.push_str(&format!(
                "**On {} of {} replicates {}**\n\n",
                gaps.len(),
                bc.scores.len(),
                worst.sentence().replacen("BC ends", "BC ends (the widest gap)", 1)
            ));
        }
        out.push_str(
            "| method | return [95 % CI] | against BC | against D-REX | against K - 1 | above the demonstrations' average |\n\
             |---|---|---|---|---|---|\n",
        );
        let (mut both, mut avg, mut below) = (vec![], vec![], vec![]);
        for r in rows.iter().filter(|r| r.method != Method::Bc.name()) {
            let bc_of: BTreeMap<usize, f64> = bc.scores.iter().copied().collect();
            let paired: Vec<bool> = r.scores.iter().filter_map(|(rep, s)| bc_of.get(rep).map(|b| s > b)).collect();
            let over_bc = WinCount { k: paired.iter().filter(|&&w| w).count(), n: paired.len() };
            let over_demos = r.above_demos_avg;
            let cell = |a: Against| find(improvement, r, a).map(|i| improvement_cell(&i.improvement));
            let against = |a: Against| cell(a).unwrap_or_else(|| "-".to_string());
            let over_bc_cell = cell(Against::Bc).unwrap_or_else(|| over_bc.to_string());
            out.push_str(&format!(
                "| {} | {} [{}, {}] | {over_bc_cell} | {} | {} | {over_demos} |\n",
                display(&r.method),
                num(Some(r.mean)),
                num(Some(r.mean_ci.0)),
                num(Some(r.mean_ci.1)),
                against(Against::Drex),
                against(Against::PreviousIteration),
            ));
            let name = display(&r.method);
            if over_bc.k == over_bc.n && over_demos.k == over_demos.n && r.mean_ci.0 > bc.mean {
                both.push(name);
            } else if over_bc.k * 2 > over_bc.n && over_demos.k * 2 > over_demos.n {
                avg.push(name);
            } else {
                below.push(name);
            }
        }
        out.push('\n');
        let small = if n < 10 {
            format!(" With {n} replicates, even a clean sweep is weak evidence (p ≥ {:.3}).", sign_test_p(n, n))
        } else {
            String::new()
        };
        let s = sentence(&both, &avg, &below, &format!("Each replicate has its own seeds, BC and learned rewards.{small}"));
        out.push_str(&s.replace("with intervals clear of them", "on every replicate, the mean's interval clear of BC's"));
        out.push_str(&verdicts(rows, improvement));
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::ReturnStats;

    fn row(method: &str, mean: f64, ci: (f64, f64), runs: usize) -> ProtocolRow {
        ProtocolRow {
            env: "Hopper-v5".into(),
            pipeline: "p".into(),
            study: "p".into(),
            replicate: 0,
            run_means: vec![mean; runs],
            method: method.into(),
            protocol: Protocol::Final,
            step: None,
            stats: ReturnStats { mean, std: 0.0, min: mean, max: mean, episodes: runs * 20 },
            runs,
            ci,
            gap_to_best: None,
        }
    }

    #[test]
    fn each_method_stands_against_bc_and_the_demonstrations() {
        let rows = vec![
            row("bc", 100.0, (100.0, 100.0), 1),
            row("drex", 300.0, (250.0, 350.0), 3),
            row("idrex-multi-bc", 180.0, (90.0, 260.0), 3),
            row("idrex-action-noise", 50.0, (0.0, 90.0), 3),
        ];
        let demos = BTreeMap::from([(("Hopper-v5".to_string(), "p".to_string()), vec![140.0, 160.0])]);
        assert_eq!(
            (capitalise("iD-REX multi-BC is"), capitalise("d-REX is"), capitalise("")),
            ("iD-REX multi-BC is".into(), "D-REX is".into(), String::new())
        );
        let md = markdown(&rows, &[], &[], &demos, &[], 0.7);
        assert!(md.starts_with("## The answer\n\n### Hopper-v5, p\n"), "{md}");
        assert!(md.contains("BC 100.0; the demonstrations 150.0 (average)"), "{md}");
        assert!(md.contains("| D-REX | 300.0 [250.0, 350.0] | +200.0, interval above | +150.0, interval above |"), "{md}");
        assert!(md.contains("| iD-REX multi-BC | 180.0 [90.0, 260.0] | +80.0, interval overlaps | +30.0, interval overlaps |"), "{md}");
        assert!(md.contains("| iD-REX action noise | 50.0 [0.0, 90.0] | -50.0, below | -100.0, below |"), "{md}");
        assert!(
            md.contains(
                "D-REX beats both BC and the demonstrations with intervals clear of them; iD-REX multi-BC is above both on average only"
            ),
            "{md}"
        );
        assert!(md.contains("iD-REX action noise is not above both. These are 3 RL runs on one seed set"), "{md}");
        // BC at 67 % of its demonstrations: under a 0.7 threshold the answer says so first.
        assert!(md.contains("**BC ends far below its demonstrations: 100.0 against their 150.0 (67 % of it"), "{md}");
        assert!(md.find("far below") < md.find("| method |"), "the warning comes before the table, not inside it: {md}");
        assert!(!markdown(&rows, &[], &[], &demos, &[], 0.6).contains("far below"));
        // Without BC or the demonstrations there is nothing to answer against.
        assert_eq!(markdown(&rows[1..], &[], &[], &demos, &[], 0.7), "");
        assert_eq!(markdown(&rows, &[], &[], &BTreeMap::new(), &[], 0.7), "");
    }

    /// Ten replicates: multi-BC above D-REX on 9 decides; K = 3 against K = 2, tied on four
    /// and split on the rest, does not, and the answer says so in words.
    #[test]
    fn a_replicated_answer_says_which_comparisons_decide() {
        use crate::report::studies::{aggregate, tests::row as replicate};
        let mut rows = Vec::new();
        for r in 0..10 {
            let k2 = if r == 0 { 1.0 } else { 300.0 + r as f64 };
            let k3 = if r < 4 {
                k2
            } else if r % 2 == 0 {
                k2 + 1.0
            } else {
                k2 - 1.0
            };
            rows.push(replicate("s", r, "bc", &[100.0]));
            rows.push(replicate("s", r, "drex", &[200.0]));
            rows.push(replicate("s", r, "idrex-multi-bc", &[k2]));
            rows.push(replicate("s", r, "idrex-multi-bc (k=3)", &[k3]));
        }
        let (agg, imp) = aggregate(&rows, &BTreeMap::new());
        let md = markdown(&rows, &agg, &imp, &BTreeMap::new(), &[], 0.7);
        assert!(md.contains("iD-REX multi-BC beats D-REX (P 0.90 ["), "{md}");
        assert!(md.contains("above on 9 of 10 replicates, p = 0.011)"), "{md}");
        assert!(md.contains("iD-REX multi-BC (k=3) shows no difference from K - 1 (P "), "{md}");
        assert!(md.contains("above on 3 of 10 replicates, 4 tied, p = 0.656)"), "{md}");
        assert!(!md.contains("BC shows") && !md.contains("BC is beaten"), "BC is no learned-reward method: {md}");
        assert!(!md.contains("far below"), "no demonstrations, no warning: {md}");
        // Each replicate's BC against its own demonstrations: replicate 0's table is the study's name.
        let key = |t: &str| ("Hopper-v5".to_string(), t.to_string());
        let demos = BTreeMap::from([(key("s"), vec![200.0]), (key("s/r1"), vec![120.0]), (key("s/r2"), vec![300.0])]);
        let md = markdown(&rows, &agg, &imp, &demos, &[], 0.7);
        assert!(
            md.contains("**On 2 of 10 replicates BC ends (the widest gap) far below its demonstrations: 100.0 against their 300.0"),
            "{md}"
        );
        assert!(md.find("far below") < md.find("| method |"), "the warning comes before the table, not inside it: {md}");
    }
}
