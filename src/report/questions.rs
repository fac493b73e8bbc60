//! The questions every replicated study answers ([`ASKED`]), each in both of the report's
//! forms, with Holm's correction over every question the report asks ([`ask`]); beside them,
//! untested, the learned reward's correlation with the true return computed SSRR's way, over
//! replicates with its interval, and how often each method earns its return by living.
//!
//! The family is the report: a report built from one locked set's archives asks exactly the
//! questions its files declare (five per task), and says how many it corrected for.
use std::collections::{BTreeMap, BTreeSet};

use super::terms::{DEMOS, EarnedBy, TermRow};
use super::{AccuracyRow, Protocol, ProtocolRow, RESAMPLES};
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::Method;
use crate::stats::{Improvement, hierarchical_ci, holm, mean, sign_test_p};

/// What a replicate's value of a method is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Measure {
    /// The final policy's true return: the mean of the runs' mean returns.
    Return,
    /// The forward term alone, per episode, over the same episodes.
    Forward,
}

impl Measure {
    pub fn name(self) -> &'static str {
        match self {
            Measure::Return => "return",
            Measure::Forward => "forward",
        }
    }
    fn words(self) -> &'static str {
        match self {
            Measure::Return => "by the true return",
            Measure::Forward => "by the forward term alone",
        }
    }
}

/// What a method is held against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Baseline {
    Method(Method),
    /// The replicate's own demonstrations' average.
    Demonstrations,
}

/// "`method` above `baseline`, by `measure`", one-sided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Question {
    pub method: Method,
    pub baseline: Baseline,
    pub measure: Measure,
}

impl Question {
    pub fn sentence(&self) -> String {
        let baseline = match self.baseline {
            Baseline::Method(Method::IdrexMultiBc) => "multi-BC at K = 2".to_string(),
            Baseline::Method(m) => m.label().to_string(),
            Baseline::Demonstrations => "the demonstrations' average".to_string(),
        };
        format!("{} above {baseline}, {}", display(self.method), self.measure.words())
    }
}

fn display(m: Method) -> &'static str {
    match m {
        Method::IdrexMultiBc => "multi-BC at K = 2",
        m => m.label(),
    }
}

/// The questions of every replicated study, in this order (issue 55's five): a study asks
/// those whose two sides it has on two or more replicates.
pub const ASKED: [Question; 5] = [
    Question { method: Method::Drex, baseline: Baseline::Method(Method::Bc), measure: Measure::Return },
    Question { method: Method::Drex, baseline: Baseline::Method(Method::Bc), measure: Measure::Forward },
    Question { method: Method::Drex, baseline: Baseline::Demonstrations, measure: Measure::Return },
    Question { method: Method::Drex, baseline: Baseline::Demonstrations, measure: Measure::Forward },
    Question { method: Method::IdrexMultiBc, baseline: Baseline::Method(Method::Drex), measure: Measure::Return },
];

/// Why a study with both methods cannot ask a question by the forward term.
const FORWARD_UNKNOWN: &str = "the forward term is not known on two replicates: the evaluations (or imported demonstrations) \
     carry no terms in their metrics and their rollouts are not here";

/// The level a corrected p must be under.
pub const LEVEL: f64 = 0.05;

/// One question of one study, answered.
#[derive(Debug, Clone, PartialEq)]
pub struct QuestionRow {
    pub env: String,
    pub study: String,
    pub question: Question,
    pub improvement: Improvement,
    /// The sign test's p corrected by Holm over the report's `family` questions.
    pub holm_p: f64,
    pub family: usize,
}

impl QuestionRow {
    /// Yes where both forms agree: rliable's interval clear of 0.5 and the corrected p under
    /// [`LEVEL`]. The one-sided questions do not test the other direction.
    pub fn decided(&self) -> bool {
        self.improvement.unpaired_ci.0 > 0.5 && self.holm_p < LEVEL
    }

    pub fn verdict(&self) -> String {
        let i = &self.improvement;
        let losses = i.pairs - i.ties - i.wins;
        if self.decided() {
            "yes".into()
        } else if losses > i.wins {
            format!(
                "not shown; below on {losses} of {} (not a declared test, uncorrected p = {:.3})",
                i.pairs - i.ties,
                sign_test_p(losses, i.pairs - i.ties)
            )
        } else {
            "not shown".into()
        }
    }
}

/// The learned reward's SSRR-way Pearson correlation over one study's replicates.
#[derive(Debug, Clone, PartialEq)]
pub struct CorrelationRow {
    pub env: String,
    pub study: String,
    pub method: String,
    pub replicates: usize,
    pub mean: f64,
    /// 95 % percentile bootstrap over replicates.
    pub ci: (f64, f64),
    pub min: f64,
    pub max: f64,
}

/// How many of a study's replicates a method earns its return by living.
#[derive(Debug, Clone, PartialEq)]
pub struct LivingCount {
    pub env: String,
    pub study: String,
    pub method: String,
    pub living: usize,
    pub replicates: usize,
}

/// The report's questions, correlations and living counts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Answers {
    pub questions: Vec<QuestionRow>,
    /// Questions a study has both methods for but could not ask, and why.
    pub not_asked: Vec<(String, String, Question, &'static str)>,
    pub correlations: Vec<CorrelationRow>,
    pub living: Vec<LivingCount>,
}

/// Where a report's per-replicate values come from.
pub struct Sources<'a> {
    pub protocols: &'a [ProtocolRow],
    pub terms: &'a [TermRow],
    pub demos: &'a BTreeMap<(String, String), Vec<f64>>,
    pub accuracy: &'a [AccuracyRow],
}

/// A (env, study) with two or more replicates: replicate -> its table's name.
pub(super) type Studies<'a> = BTreeMap<(&'a str, &'a str), BTreeMap<usize, &'a str>>;

pub(super) fn studies<'a>(protocols: &'a [ProtocolRow]) -> Studies<'a> {
    let mut out: Studies = BTreeMap::new();
    for r in protocols {
        out.entry((&r.env, &r.study)).or_default().insert(r.replicate, &r.pipeline);
    }
    out.retain(|_, reps| reps.len() >= 2);
    out
}

impl Sources<'_> {
    /// Per replicate of (env, study): one side's value by `measure`, where known.
    pub(super) fn values(&self, env: &str, tables: &BTreeMap<usize, &str>, side: Baseline, measure: Measure) -> BTreeMap<usize, f64> {
        let label = |m: Method| super::method_label(m, 2);
        tables
            .iter()
            .filter_map(|(&rep, &table)| {
                let value = match (side, measure) {
                    (Baseline::Method(m), Measure::Return) => self
                        .protocols
                        .iter()
                        .find(|r| r.env == env && r.pipeline == table && r.protocol == Protocol::Final && r.method == label(m))
                        .and_then(|r| mean(&r.run_means)),
                    (Baseline::Demonstrations, Measure::Return) => {
                        self.demos.get(&(env.to_string(), table.to_string())).and_then(|d| mean(d))
                    }
                    (side, Measure::Forward) => {
                        let name = match side {
                            Baseline::Method(m) => label(m),
                            Baseline::Demonstrations => DEMOS.to_string(),
                        };
                        self.terms.iter().find(|t| t.env == env && t.pipeline == table && t.method == name).map(|t| t.forward)
                    }
                };
                value.filter(|v| v.is_finite()).map(|v| (rep, v))
            })
            .collect()
    }
}

/// Every study's questions with Holm's correction over all of them, the correlations and the
/// living counts.
pub fn ask(src: &Sources) -> Answers {
    let studies = studies(src.protocols);
    let (mut questions, mut not_asked) = (Vec::new(), Vec::new());
    for (&(env, study), tables) in &studies {
        for q in ASKED {
            let x = src.values(env, tables, Baseline::Method(q.method), q.measure);
            let y = src.values(env, tables, q.baseline, q.measure);
            let pairs: Vec<(f64, f64)> = x.iter().filter_map(|(r, a)| y.get(r).map(|b| (*a, *b))).collect();
            if pairs.len() < 2 {
                let by_return = |side| src.values(env, tables, side, Measure::Return).len() >= 2;
                if q.measure == Measure::Forward && by_return(Baseline::Method(q.method)) && by_return(q.baseline) {
                    not_asked.push((env.to_string(), study.to_string(), q, FORWARD_UNKNOWN));
                }
                continue;
            }
            let improvement = Improvement::of(&pairs, RESAMPLES, 2);
            questions.push(QuestionRow { env: env.into(), study: study.into(), question: q, improvement, holm_p: f64::NAN, family: 0 });
        }
    }
    let corrected = holm(&questions.iter().map(|q| q.improvement.sign_p).collect::<Vec<_>>());
    let family = corrected.iter().filter(|p| p.is_finite()).count();
    for (q, p) in questions.iter_mut().zip(corrected) {
        q.holm_p = p;
        q.family = family;
    }
    Answers { questions, not_asked, correlations: correlations(src, &studies), living: living(src, &studies) }
}

fn correlations(src: &Sources, studies: &Studies) -> Vec<CorrelationRow> {
    let mut out = Vec::new();
    for (&(env, study), tables) in studies {
        let methods: BTreeSet<&str> = src.accuracy.iter().filter(|a| a.env == env).map(|a| a.method.as_str()).collect();
        for method in methods {
            let values: Vec<f64> = tables
                .values()
                .filter_map(|&t| src.accuracy.iter().find(|a| a.env == env && a.pipeline == t && a.method == method))
                .map(|a| a.pearson_ssrr)
                .filter(|v| v.is_finite())
                .collect();
            if values.len() < 2 {
                continue;
            }
            let groups: Vec<Vec<f64>> = values.iter().map(|&v| vec![v]).collect();
            let of = |v: &[f64]| mean(v).unwrap_or(f64::NAN);
            out.push(CorrelationRow {
                env: env.into(),
                study: study.into(),
                method: method.into(),
                replicates: values.len(),
                mean: of(&values),
                ci: hierarchical_ci(&groups, of, RESAMPLES, 3),
                min: values.iter().copied().fold(f64::INFINITY, f64::min),
                max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            });
        }
    }
    out
}

fn living(src: &Sources, studies: &Studies) -> Vec<LivingCount> {
    let mut out = Vec::new();
    for (&(env, study), tables) in studies {
        let rows: Vec<&TermRow> = src.terms.iter().filter(|t| t.env == env && tables.values().any(|&p| p == t.pipeline)).collect();
        let methods: BTreeSet<&str> = rows.iter().map(|t| t.method.as_str()).collect();
        for method in methods {
            let of: Vec<&&TermRow> = rows.iter().filter(|t| t.method == method).collect();
            let living = of.iter().filter(|t| t.earned_by == EarnedBy::Living).count();
            out.push(LivingCount { env: env.into(), study: study.into(), method: method.into(), living, replicates: of.len() });
        }
    }
    out
}

/// `questions.csv`: one row per (env, study, question).
impl Row for QuestionRow {
    fn header() -> Vec<&'static str> {
        let mut h = vec!["env", "study", "method", "baseline", "measure"];
        h.extend(super::improvement::COLUMNS);
        h.extend(["holm_p", "family", "decided"]);
        h
    }

    fn cells(&self) -> Vec<Cell> {
        let baseline = match self.question.baseline {
            Baseline::Method(m) => m.name(),
            Baseline::Demonstrations => DEMOS,
        };
        let mut c = vec![
            Cell::text(&self.env),
            Cell::text(&self.study),
            Cell::text(self.question.method.name()),
            Cell::text(baseline),
            Cell::text(self.question.measure.name()),
        ];
        c.extend(super::improvement::cells(&self.improvement));
        c.extend([Cell::opt(Some(self.holm_p), 3), Cell::int(self.family), Cell::text(if self.decided() { "yes" } else { "no" })]);
        c
    }
}

/// `correlations.csv`: one row per (env, study, method with a learned reward).
impl Row for CorrelationRow {
    fn header() -> Vec<&'static str> {
        vec!["env", "study", "method", "replicates", "pearson_ssrr_mean", "ci_low", "ci_high", "min", "max"]
    }

    fn cells(&self) -> Vec<Cell> {
        let x = |v: f64| Cell::opt(Some(v), 3);
        vec![
            Cell::text(&self.env),
            Cell::text(&self.study),
            Cell::text(&self.method),
            Cell::int(self.replicates),
            x(self.mean),
            x(self.ci.0),
            x(self.ci.1),
            x(self.min),
            x(self.max),
        ]
    }
}

/// The report's section: the questions with their corrected p, the correlations, the living.
pub fn markdown(a: &Answers) -> String {
    if a.questions.is_empty() {
        return String::new();
    }
    let family = a.questions[0].family;
    // A question whose replicates all tie has no sign test and leaves the family.
    let mut out = format!(
        "## The questions, corrected together (Holm over the {family} this report asks)\n\n\
         Each replicated study's questions, one-sided, each in both forms: rliable's probability of improvement P with its \
         independent-bootstrap 95 % interval, and the replicates where the method scored above (paired by replicate, ties \
         left out) with the exact 95 % interval of that rate and the one-sided sign test's p. The {family} sign-test p are \
         corrected together by Holm's method; \"yes\" needs P's interval clear of 0.5 and the corrected p under {LEVEL}.\n\n"
    );
    let mut table =
        Table { columns: ["env", "study", "question", "P [95 % CI]; paired", "Holm p", "answer"].map(String::from).to_vec(), rows: vec![] };
    for q in &a.questions {
        table.rows.push(vec![
            Cell::text(&q.env),
            Cell::text(&q.study),
            Cell::text(q.question.sentence()),
            Cell::text(super::improvement::improvement_cell(&q.improvement)),
            Cell::opt(Some(q.holm_p), 3),
            Cell::text(q.verdict()),
        ]);
    }
    out.push_str(&table.markdown());
    for (env, study, q, why) in &a.not_asked {
        out.push_str(&format!("\nNot asked, so not in the family: {env} {study}, {}: {why}.\n", q.sentence()));
    }
    if !a.correlations.is_empty() {
        out.push_str(
            "\nNot tested: the learned reward's Pearson correlation with the true return computed SSRR's way (each replicate's \
             reward over its ranked sets, its demonstrations and its final policies' evaluation episodes), the mean over \
             replicates with a 95 % bootstrap interval over replicates.\n\n",
        );
        let mut table = Table {
            columns: ["env", "study", "method", "replicates", "Pearson [95 % CI]", "range"].map(String::from).to_vec(),
            rows: vec![],
        };
        for c in &a.correlations {
            table.rows.push(vec![
                Cell::text(&c.env),
                Cell::text(&c.study),
                Cell::text(&c.method),
                Cell::int(c.replicates),
                Cell::text(format!("{:.3} [{:.3}, {:.3}]", c.mean, c.ci.0, c.ci.1)),
                Cell::text(format!("{:.3} to {:.3}", c.min, c.max)),
            ]);
        }
        out.push_str(&table.markdown());
    }
    if a.living.is_empty() {
        out.push_str(
            "\nHow each method earns its return is not measured here: no evaluation carries its terms or has its rollouts here.\n\n",
        );
        return out;
    }
    let living: Vec<String> = a
        .living
        .iter()
        .filter(|l| l.living > 0)
        .map(|l| format!("{} {} ({}): {} of {} replicates", l.env, l.method, l.study, l.living, l.replicates))
        .collect();
    out.push_str(&format!(
        "\nEarned by living, not moving (episodes at least half the time limit, forward under a quarter of the healthy reward): {}.\n\n",
        if living.is_empty() { "no method on any replicate".to_string() } else { living.join("; ") }
    ));
    out
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::report::studies::tests::row;

    pub(in crate::report) fn terms(table: &str, method: &str, forward: f64, length: f64) -> TermRow {
        TermRow {
            env: "Hopper-v5".into(),
            pipeline: table.into(),
            method: method.into(),
            episodes: 20,
            length,
            ret: 0.0,
            forward,
            ctrl: 0.0,
            survive: length,
            contact: 0.0,
            learned_per_step: None,
            ranked_best_per_step: None,
            ranked_worst_per_step: None,
            earned_by: if forward < 0.25 * length && length >= 500.0 { EarnedBy::Living } else { EarnedBy::Moving },
        }
    }

    fn table(study: &str, r: usize) -> String {
        if r == 0 { study.into() } else { format!("{study}/r{r}") }
    }

    /// Study `a`: D-REX above BC on all 10 replicates by the return, on 9 by the forward term
    /// (it stands on replicate 9); multi-BC above D-REX on 5. Study `b`: no forward terms.
    type Demos = BTreeMap<(String, String), Vec<f64>>;

    fn sources() -> (Vec<ProtocolRow>, Vec<TermRow>, Demos) {
        let (mut protocols, mut t, mut demos) = (vec![], vec![], BTreeMap::new());
        for r in 0..10 {
            let x = r as f64;
            protocols.push(row("a", r, "bc", &[100.0 + x, 110.0 + x]));
            protocols.push(row("a", r, "drex", &[300.0 + x, 320.0 + x]));
            protocols.push(row("a", r, "idrex-multi-bc", &[if r % 2 == 0 { 400.0 } else { 200.0 }; 2]));
            demos.insert(("Hopper-v5".to_string(), table("a", r)), vec![250.0, 260.0]);
            t.push(terms(&table("a", r), "bc", 50.0 + x, 200.0));
            t.push(terms(&table("a", r), "drex", if r == 9 { 10.0 } else { 300.0 + x }, 1000.0));
            t.push(terms(&table("a", r), DEMOS, 120.0, 300.0));
        }
        for r in 0..4 {
            protocols.push(row("b", r, "bc", &[10.0]));
            protocols.push(row("b", r, "drex", &[5.0]));
        }
        (protocols, t, demos)
    }

    #[test]
    fn a_study_asks_its_questions_and_holm_corrects_them_together() {
        let (protocols, terms, demos) = sources();
        let a = ask(&Sources { protocols: &protocols, terms: &terms, demos: &demos, accuracy: &[] });
        let found = |study: &str, q: Question| a.questions.iter().find(|r| r.study == study && r.question == q);
        let [by_return, by_forward, demos_return, demos_forward, multi] = ASKED;
        let r = found("a", by_return).unwrap().improvement;
        assert_eq!((r.wins, r.pairs, r.ties), (10, 10, 0));
        assert_eq!(found("a", by_forward).unwrap().improvement.wins, 9);
        assert_eq!(found("a", demos_return).unwrap().improvement.wins, 10);
        // D-REX's forward term against the demonstrations' 120: above on 9 (300 + r), below on one.
        assert_eq!(found("a", demos_forward).unwrap().improvement.wins, 9);
        assert_eq!(found("a", multi).unwrap().improvement.wins, 5);
        // Study b: two questions by the return (no multi-BC, no demonstrations), none by the forward term.
        assert!(found("b", by_return).is_some() && found("b", by_forward).is_none() && found("b", demos_return).is_none());
        assert_eq!(a.not_asked.len(), 1, "{:?}", a.not_asked);
        assert_eq!((a.not_asked[0].1.as_str(), a.not_asked[0].2), ("b", by_forward));
        // Six questions, one family: the corrected p is Holm's over all six.
        assert_eq!(a.questions.len(), 6);
        let ps: Vec<f64> = a.questions.iter().map(|q| q.improvement.sign_p).collect();
        for (q, want) in a.questions.iter().zip(holm(&ps)) {
            assert_eq!((q.holm_p, q.family), (want, 6));
            assert!(q.holm_p >= q.improvement.sign_p);
        }
        // Sorted: 10 of 10 twice (p = 1/1024: x 6, x 5), then 9 of 10 twice (11/1024: x 4 and
        // x 3, stepped up to x 4), 5 of 10 (x 2) and 0 of 4 (x 1).
        assert!((found("a", by_return).unwrap().holm_p - 6.0 / 1024.0).abs() < 1e-12 && found("a", by_return).unwrap().decided());
        assert!((found("a", by_forward).unwrap().holm_p - 44.0 / 1024.0).abs() < 1e-12);
        assert!((found("a", demos_forward).unwrap().holm_p - 44.0 / 1024.0).abs() < 1e-12);
        assert!(!found("a", multi).unwrap().decided() && found("a", multi).unwrap().holm_p > 0.6);
        // Study b's D-REX is below BC on all four: said, not tested.
        assert!(found("b", by_return).unwrap().verdict().starts_with("not shown; below on 4 of 4"));
        // Replicate 9's D-REX lives 1000 steps and hardly moves.
        let drex = a.living.iter().find(|l| l.study == "a" && l.method == "drex").unwrap();
        assert_eq!((drex.living, drex.replicates), (1, 10));
        let md = markdown(&a);
        assert!(
            md.contains("Holm over the 6 this report asks")
                && md.contains("Not asked, so not in the family: Hopper-v5 b, D-REX above BC, by the forward term alone"),
            "{md}"
        );
        assert!(md.contains("Hopper-v5 drex (a): 1 of 10 replicates"), "{md}");
    }

    #[test]
    fn the_correlation_is_averaged_over_replicates_with_its_interval() {
        let (protocols, _, demos) = sources();
        let accuracy: Vec<AccuracyRow> = (0..10)
            .map(|r| AccuracyRow {
                env: "Hopper-v5".into(),
                pipeline: table("a", r),
                method: "drex".into(),
                pearson: 0.0,
                spearman: 0.0,
                pairwise_accuracy: 0.0,
                spearman_over_checkpoints: 0.0,
                pearson_over_checkpoints: 0.0,
                pearson_ssrr: 0.8 + 0.01 * r as f64,
                bank_spearman: f64::NAN,
                bank_forward_spearman: f64::NAN,
                bank_overpaid: None,
                reward_capped: None,
                runs: 3,
            })
            .collect();
        let a = ask(&Sources { protocols: &protocols, terms: &[], demos: &demos, accuracy: &accuracy });
        assert_eq!(a.correlations.len(), 1);
        let c = &a.correlations[0];
        assert_eq!((c.replicates, c.min, c.max), (10, 0.8, 0.8 + 0.09));
        assert!((c.mean - 0.845).abs() < 1e-12 && c.ci.0 < c.mean && c.mean < c.ci.1 && c.ci.0 >= 0.8 && c.ci.1 <= 0.89, "{c:?}");
        assert!(markdown(&a).contains("not measured here"), "{}", markdown(&a));
    }
}
