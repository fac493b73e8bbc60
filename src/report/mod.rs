//! `idrex report`: the report's comparison tables, built with polars from the store's
//! manifests. Per environment and method: mean ± std of the ground-truth return over all
//! R runs x 20 episodes, the best average of the R runs, and the demonstrations' average and
//! best; the reward-accuracy figures the report lacked (Pearson and Spearman correlation of
//! predicted against true return on unseen evaluation rollouts, and pairwise ranking
//! accuracy); and the same return under three protocols ([`Protocol`]), each with a 95 %
//! bootstrap confidence interval over runs.
use std::collections::BTreeMap;

pub mod answer;
pub mod bank;
pub mod clones;
mod collect;
mod columns;
pub mod comparisons;
pub mod figures;
pub mod html;
pub mod improvement;
pub mod looks;
mod notes;
mod protocols;
pub mod questions;
mod returns;
pub mod studies;
pub mod sweeps;
pub mod terms;
#[cfg(test)]
mod tests;

use polars::prelude::*;

use crate::error::{Error, Result};
use crate::log::table::Table;
use crate::pipeline::Method;
use crate::pipeline::role::{Role, Series};
use crate::pipeline::stage::eval::{EvalMetrics, EvalParams};
use crate::pipeline::stage::{Metrics, Params, StageKind, Typed};
use crate::pipeline::test_set::{Look, Looks};
use crate::store::{Manifest, Store};
use columns::Col;

pub use crate::algo::scoring::{Selection, select};
pub use notes::notes;
use protocols::RESAMPLES;
use protocols::protocol_rows;
pub use protocols::{Protocol, ProtocolRow, over_checkpoints};
pub use returns::{AccuracyRow, DemoRow, ReturnRow, answer_markdown, markdown};

pub(crate) fn pe(e: PolarsError) -> Error {
    Error::Invalid(format!("building the report table: {e}"))
}

/// A method's label in every table: its name, with the iteration past the report's two.
pub fn method_label(method: Method, iteration: usize) -> String {
    if iteration > 2 { format!("{} (k={iteration})", method.name()) } else { method.name().to_string() }
}

/// The label of the iteration before `label`'s, where that is a separate row: K - 1 for an
/// iterated method at K > 2 (at K = 2 the iteration before is D-REX, compared already).
pub fn previous_iteration(label: &str) -> Option<String> {
    let (name, k) = label.strip_suffix(')')?.split_once(" (k=")?;
    let method = Method::ALL.into_iter().find(|m| m.name() == name)?;
    let k: usize = k.parse().ok().filter(|&k| k > 2)?;
    Some(method_label(method, k - 1))
}

/// A table of the report: one pipeline's runs, or one replicate's of a study.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct TableId {
    label: String,
    study: String,
    replicate: usize,
}

/// The store's intact artifacts, read and verified once, and any archives' manifests
/// (`idrex export`): every table, note and figure of a report comes from this one pass
/// (verifying re-hashes every output file).
#[derive(Default)]
pub struct Artifacts {
    by_key: BTreeMap<String, Manifest>,
    /// Each manifest read through its stage's types once, when first asked for (`exp` reads
    /// the evaluations and little else).
    typed: BTreeMap<String, std::sync::OnceLock<Option<Typed>>>,
    /// Keys known from an archive alone: no outputs on this machine.
    archived: std::collections::BTreeSet<String>,
}

impl Artifacts {
    pub fn read(store: &Store) -> Result<Self> {
        Ok(Self::of(store.manifests()?))
    }

    /// These manifests; each is read through its stage's types once, when first asked for.
    pub fn of(manifests: impl IntoIterator<Item = Manifest>) -> Self {
        let mut a = Artifacts { by_key: manifests.into_iter().map(|m| (m.key.clone(), m)).collect(), ..Default::default() };
        a.type_new();
        a
    }

    /// Adds an archive's manifests; returns how many were not known yet.
    pub fn add_archive(&mut self, path: &std::path::Path) -> Result<usize> {
        let archived = crate::store::archive::read(path, crate::pipeline::stage::recorded_key)?;
        let before: std::collections::BTreeSet<String> = self.by_key.keys().cloned().collect();
        let added = crate::store::archive::merge(&mut self.by_key, path, archived)?;
        self.archived.extend(self.by_key.keys().filter(|k| !before.contains(*k)).cloned());
        self.type_new();
        Ok(added)
    }

    /// A slot to type each manifest not known yet in.
    fn type_new(&mut self) {
        for key in self.by_key.keys() {
            self.typed.entry(key.clone()).or_default();
        }
    }

    /// `m` read through its stage's types, if it parses; an evaluation that does not (an
    /// older idrex's) is left out of every table, with a warning the first time.
    pub fn typed(&self, m: &Manifest) -> Option<&Typed> {
        let slot = self.typed.get(&m.key)?;
        slot.get_or_init(|| match Typed::of(m) {
            Ok(t) => Some(t),
            Err(e) if m.kind == StageKind::Eval.name() => {
                tracing::warn!("skipping {}: {e}", m.key);
                None
            }
            Err(e) => {
                tracing::debug!("{} ({}): {e}", m.key, m.kind);
                None
            }
        })
        .as_ref()
    }

    /// Every evaluation that reads through its types, with its parameters and metrics (the
    /// other kinds' manifests are not typed for it).
    pub fn evaluations(&self) -> impl Iterator<Item = (&Manifest, &EvalParams, &EvalMetrics)> {
        self.iter().filter(|m| m.kind == StageKind::Eval.name()).filter_map(|m| match self.typed(m)? {
            Typed { params: Params::Eval(p), metrics: Metrics::Eval(x) } => Some((m, p, x)),
            _ => None,
        })
    }

    /// Which configurations the store scored on which seeds: what the test-set check and the
    /// report's `looks` read.
    pub fn looks(&self) -> Looks {
        Looks::new(self.evaluations().filter_map(|(m, p, _)| Look::of(m, p)))
    }

    /// Whether `key` is known from an archive only (its outputs are not on this machine).
    pub fn is_archived(&self, key: &str) -> bool {
        self.archived.contains(key)
    }

    pub fn iter(&self) -> impl Iterator<Item = &Manifest> {
        self.by_key.values()
    }

    pub fn get(&self, key: &str) -> Option<&Manifest> {
        self.by_key.get(key)
    }

    /// `m`'s input in `role` (an evaluation's reward, policy or demonstrations), if known here.
    pub fn input(&self, m: &Manifest, role: Role) -> Option<&Manifest> {
        input_key(m, role).and_then(|k| self.get(k))
    }

    /// `m`'s inputs in `series` that are known here, with their keys (a reward's ranked sets).
    pub fn inputs_in<'a>(&'a self, m: &'a Manifest, series: Series) -> impl Iterator<Item = (&'a String, &'a Manifest)> + 'a {
        crate::pipeline::role::recorded_series(m, series).filter_map(|k| Some((k, self.get(k)?)))
    }
}

/// The key of `m`'s input in `role`: the report's one reading of a manifest's recorded role
/// names (lineage queries on [`Artifacts`] go through it).
pub fn input_key(m: &Manifest, role: Role) -> Option<&String> {
    crate::pipeline::role::recorded_input(m, role)
}

/// The report's typed rows, every table of it (CSV, markdown, HTML and figures read these).
pub struct Tables {
    pub returns: Vec<ReturnRow>,
    /// One row per (env, pipeline, method, protocol).
    pub protocols: Vec<ProtocolRow>,
    /// (env, pipeline, method, run) of every evaluated run, to name missing runs.
    pub evaluated: std::collections::BTreeSet<(String, String, String, usize)>,
    pub demos: Vec<DemoRow>,
    pub accuracy: Vec<AccuracyRow>,
    /// Studies with several replicates: one row per (env, study, method, protocol).
    pub aggregate: Vec<studies::AggregateRow>,
    /// Their probabilities of improvement over D-REX and over BC.
    pub improvement: Vec<studies::ImprovementRow>,
    /// Sweeps' variants, each against its baseline variant.
    pub sweeps: Vec<sweeps::SweepRow>,
    /// Each sweep's variants against its baseline, corrected per sweep (needs the terms).
    pub decisions: Vec<sweeps::DecisionRow>,
    /// Multi-BC's clones against their sources.
    pub clones: Vec<clones::CloneRow>,
    /// (env, table) -> the demonstrations' returns.
    pub demo_returns: BTreeMap<(String, String), Vec<f64>>,
    /// How often each study's seeds were looked at.
    pub looks: Vec<looks::LookRow>,
    /// The answer warns where BC ends below this fraction of its demonstrations' average
    /// ([`crate::algo::scoring::CloneGap`]).
    pub bc_warning: f64,
    /// How each method's final policies earn their return ([`terms::rows`]; read from the
    /// stored rollouts, so filled by the caller that has the store).
    pub terms: Vec<terms::TermRow>,
    /// Each learned reward's scores on its task's bank ([`bank::rows`]).
    pub bank: Vec<bank::BankRow>,
    /// Each method's gain over BC split into the task's terms ([`terms::gains`]).
    pub gains: Vec<terms::GainRow>,
    /// The studies' questions with Holm's correction, the correlations and the living
    /// counts ([`questions::ask`]; they need the terms, so [`Tables::with_terms`] fills them).
    pub answers: questions::Answers,
}

impl Tables {
    /// Sets the terms and answers the questions that need them.
    pub fn with_terms(&mut self, terms: Vec<terms::TermRow>) {
        self.gains = terms::gains(&terms);
        self.terms = terms;
        let src =
            questions::Sources { protocols: &self.protocols, terms: &self.terms, demos: &self.demo_returns, accuracy: &self.accuracy };
        self.answers = questions::ask(&src);
        self.decisions = sweeps::decide(&self.sweeps, &src);
    }

    /// Every table the report writes as a file, by file stem (`returns` -> `returns.csv`);
    /// the studies' where there are any, and the others only where they have rows.
    pub fn files(&self) -> Vec<(&'static str, Table)> {
        let mut out = vec![
            ("returns", Table::of(&self.returns)),
            ("demos", Table::of(&self.demos)),
            ("reward_accuracy", Table::of(&self.accuracy)),
            ("protocols", Table::of(&self.protocols)),
        ];
        if !self.aggregate.is_empty() {
            out.push(("aggregate", Table::of(&self.aggregate)));
            out.push(("improvement", Table::of(&self.improvement)));
        }
        let optional = [
            ("sweeps", Table::of(&self.sweeps)),
            ("looks", Table::of(&self.looks)),
            ("clones", Table::of(&self.clones)),
            ("terms", Table::of(&self.terms)),
            ("gains", Table::of(&self.gains)),
            ("bank", Table::of(&self.bank)),
            ("questions", Table::of(&self.answers.questions)),
            ("sweep_decisions", Table::of(&self.decisions)),
            ("correlations", Table::of(&self.answers.correlations)),
        ];
        out.extend(optional.into_iter().filter(|(_, t)| !t.rows.is_empty()));
        out
    }
}

pub fn build(store: &Artifacts) -> Result<Tables> {
    let mut long = collect::collect(store)?;
    let mut protocols = Vec::new();
    for ((env, table, method), runs) in &mut long.runs {
        runs.sort_by_key(|r| r.run);
        protocols.extend(protocol_rows(env, table, method, runs));
    }
    let (aggregate, improvement) = studies::aggregate(&protocols, &long.demo_returns);
    let sweeps = sweeps::rows(&aggregate, &long.variants);
    let frames = aggregated(&long)?;
    let evaluated = (0..frames.runs.height())
        .map(|i| {
            let name = |c: Col| c.text(&frames.runs, i);
            Ok((name(Col::Env)?, name(Col::Pipeline)?, name(Col::Method)?, count(&frames.runs, Col::Run, i)?))
        })
        .collect::<Result<_>>()?;
    Ok(Tables {
        returns: return_rows(&frames.returns)?,
        evaluated,
        demos: demo_rows(&frames.demos)?,
        accuracy: accuracy_rows(&frames.accuracy)?,
        protocols,
        aggregate,
        improvement,
        sweeps,
        clones: clones::rows(store),
        demo_returns: long.demo_returns,
        looks: looks::rows(store),
        bc_warning: crate::algo::scoring::BC_WARNING,
        terms: Vec::new(),
        bank: bank::rows(store),
        gains: Vec::new(),
        answers: questions::Answers::default(),
        decisions: Vec::new(),
    })
}

/// polars' aggregates of the long rows, one frame per table.
struct Frames {
    returns: DataFrame,
    /// Every evaluated (env, pipeline, method, run), once.
    runs: DataFrame,
    demos: DataFrame,
    accuracy: DataFrame,
}

fn aggregated(long: &collect::Long) -> Result<Frames> {
    use Col::*;
    let keys = [Env.expr(), Pipeline.expr(), Method.expr()];
    let sorted = [Env.name(), Pipeline.name(), Method.name()];
    let per_run = long
        .episodes
        .clone()
        .lazy()
        .group_by([Env.expr(), Pipeline.expr(), Method.expr(), Run.expr()])
        .agg([Return.expr().mean().alias(RunMean.name())])
        .group_by(keys.clone())
        .agg([RunMean.expr().max().alias(BestRunAvg.name()), Run.expr().n_unique().alias(Runs.name())]);
    let runs = long
        .episodes
        .clone()
        .lazy()
        .select([Env.expr(), Pipeline.expr(), Method.expr(), Run.expr()])
        .unique(None, Default::default())
        .collect()
        .map_err(pe)?;
    let returns = long
        .episodes
        .clone()
        .lazy()
        .group_by(keys.clone())
        .agg([
            Return.expr().mean().alias(Mean.name()),
            Return.expr().std(0).alias(Std.name()),
            Return.expr().count().alias(Episodes.name()),
        ])
        .join(per_run, keys.clone(), keys.clone(), JoinArgs::new(JoinType::Left))
        .sort(sorted, Default::default())
        .collect()
        .map_err(pe)?;
    let demos = long
        .demos
        .clone()
        .lazy()
        .group_by([Env.expr(), Pipeline.expr()])
        .agg([
            Return.expr().mean().alias(DemosAvg.name()),
            Return.expr().max().alias(DemosBest.name()),
            Return.expr().count().alias(Demos.name()),
        ])
        .sort([Env.name(), Pipeline.name()], Default::default())
        .collect()
        .map_err(pe)?;
    let means = [
        Pearson,
        Spearman,
        PairwiseAccuracy,
        SpearmanOverCheckpoints,
        PearsonOverCheckpoints,
        PearsonSsrr,
        BankSpearman,
        BankForwardSpearman,
        BankOverpaid,
        RewardCapped,
    ];
    let accuracy = long
        .accuracy
        .clone()
        .lazy()
        .group_by(keys)
        .agg(means.iter().map(|c| c.expr().mean()).chain([Spearman.expr().count().alias(Runs.name())]).collect::<Vec<_>>())
        .sort(sorted, Default::default())
        .collect()
        .map_err(pe)?;
    Ok(Frames { returns, runs, demos, accuracy })
}

// polars' aggregates, read into typed rows once; everything downstream reads the rows.
fn value(df: &DataFrame, c: Col, i: usize) -> Result<f64> {
    Ok(c.f64(df, i)?.unwrap_or(f64::NAN))
}
fn count(df: &DataFrame, c: Col, i: usize) -> Result<usize> {
    Ok(c.f64(df, i)?.unwrap_or(0.0) as usize)
}

fn return_rows(df: &DataFrame) -> Result<Vec<ReturnRow>> {
    (0..df.height())
        .map(|i| {
            Ok(ReturnRow {
                env: Col::Env.text(df, i)?,
                pipeline: Col::Pipeline.text(df, i)?,
                method: Col::Method.text(df, i)?,
                mean: value(df, Col::Mean, i)?,
                std: value(df, Col::Std, i)?,
                episodes: count(df, Col::Episodes, i)?,
                best_run_avg: value(df, Col::BestRunAvg, i)?,
                runs: count(df, Col::Runs, i)?,
            })
        })
        .collect()
}

fn demo_rows(df: &DataFrame) -> Result<Vec<DemoRow>> {
    (0..df.height())
        .map(|i| {
            Ok(DemoRow {
                env: Col::Env.text(df, i)?,
                pipeline: Col::Pipeline.text(df, i)?,
                demos_avg: value(df, Col::DemosAvg, i)?,
                demos_best: value(df, Col::DemosBest, i)?,
                demos: count(df, Col::Demos, i)?,
            })
        })
        .collect()
}

fn accuracy_rows(df: &DataFrame) -> Result<Vec<AccuracyRow>> {
    (0..df.height())
        .map(|i| {
            Ok(AccuracyRow {
                env: Col::Env.text(df, i)?,
                pipeline: Col::Pipeline.text(df, i)?,
                method: Col::Method.text(df, i)?,
                pearson: value(df, Col::Pearson, i)?,
                spearman: value(df, Col::Spearman, i)?,
                pairwise_accuracy: value(df, Col::PairwiseAccuracy, i)?,
                spearman_over_checkpoints: value(df, Col::SpearmanOverCheckpoints, i)?,
                pearson_over_checkpoints: value(df, Col::PearsonOverCheckpoints, i)?,
                pearson_ssrr: value(df, Col::PearsonSsrr, i)?,
                bank_spearman: value(df, Col::BankSpearman, i)?,
                bank_forward_spearman: value(df, Col::BankForwardSpearman, i)?,
                bank_overpaid: Col::BankOverpaid.f64(df, i)?,
                reward_capped: Col::RewardCapped.f64(df, i)?,
                runs: count(df, Col::Runs, i)?,
            })
        })
        .collect()
}

/// A figure with one decimal; never "NaN" (a figure that could not be computed says so).
fn num(x: Option<f64>) -> String {
    match x {
        Some(v) if v.is_finite() => format!("{v:.1}"),
        _ => "n/a".into(),
    }
}
