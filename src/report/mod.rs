//! `idrex report`: the report's comparison tables, built with polars from the store's
//! manifests. Per environment and method: mean ± std of the ground-truth return over all
//! R runs x 20 episodes, the best average of the R runs, and the demonstrations' average and
//! best; the reward-accuracy figures the report lacked (Pearson and Spearman correlation of
//! predicted against true return on unseen evaluation rollouts, and pairwise ranking
//! accuracy); and the same return under three protocols ([`Protocol`]), each with a 95 %
//! bootstrap confidence interval over runs.
use std::collections::BTreeMap;

pub mod answer;
pub mod clones;
pub mod comparisons;
pub mod figures;
pub mod html;
pub mod improvement;
pub mod looks;
mod notes;
mod protocols;
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
use crate::pipeline::stage::{Metrics, Params, Typed};
use crate::stats::{pearson, spearman};
use crate::store::{Manifest, Store};

pub use crate::algo::scoring::{Selection, select};
use crate::pipeline::role::Role;
pub use notes::notes;
use protocols::RESAMPLES;
pub use protocols::{Protocol, ProtocolRow, over_checkpoints};
use protocols::{RunEval, protocol_rows};
pub use returns::{AccuracyRow, DemoRow, ReturnRow, markdown};

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

/// One evaluation episode per row, one demonstration episode per row, and one reward-
/// accuracy row per evaluation run.
struct Long {
    episodes: DataFrame,
    demos: DataFrame,
    accuracy: DataFrame,
    /// (env, table, method label) -> its evaluated runs.
    runs: BTreeMap<(String, TableId, String), Vec<RunEval>>,
    /// (env, table label) -> the demonstrations' returns.
    demo_returns: BTreeMap<(String, String), Vec<f64>>,
    /// Study -> its place in a sweep.
    variants: BTreeMap<String, crate::pipeline::stage::eval::VariantTag>,
}

/// The store's intact artifacts, read and verified once, and any archives' manifests
/// (`idrex export`): every table, note and figure of a report comes from this one pass
/// (verifying re-hashes every output file).
#[derive(Default)]
pub struct Artifacts {
    by_key: BTreeMap<String, Manifest>,
    /// Keys known from an archive alone: no outputs on this machine.
    archived: std::collections::BTreeSet<String>,
}

impl Artifacts {
    pub fn read(store: &Store) -> Result<Self> {
        Ok(Artifacts { by_key: store.manifests()?.into_iter().map(|m| (m.key.clone(), m)).collect(), ..Default::default() })
    }

    /// Adds an archive's manifests; returns how many were not known yet.
    pub fn add_archive(&mut self, path: &std::path::Path) -> Result<usize> {
        let archived = crate::store::archive::read(path, crate::pipeline::stage::recorded_key)?;
        let before: std::collections::BTreeSet<String> = self.by_key.keys().cloned().collect();
        let added = crate::store::archive::merge(&mut self.by_key, path, archived)?;
        self.archived.extend(self.by_key.keys().filter(|k| !before.contains(*k)).cloned());
        Ok(added)
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
}

fn collect(store: &Artifacts) -> Result<Long> {
    let (mut env, mut method, mut pipeline, mut run, mut ret) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut d_env, mut d_pipeline, mut d_ret) = (vec![], vec![], vec![]);
    let (mut a_env, mut a_pipeline, mut a_method) = (vec![], vec![], vec![]);
    let (mut a_pearson, mut a_spearman, mut a_pairwise) = (vec![], vec![], vec![]);
    let (mut a_spearman_checkpoints, mut a_pearson_checkpoints) = (vec![], vec![]);
    let mut a_capped: Vec<Option<f64>> = vec![];
    let mut a_ssrr = vec![];
    let ssrr = terms::ssrr_pearson(store);
    let mut demo_keys = std::collections::BTreeSet::new();
    let mut runs: BTreeMap<(String, TableId, String), Vec<RunEval>> = BTreeMap::new();
    let mut demo_returns: BTreeMap<(String, String), Vec<f64>> = BTreeMap::new();
    let mut variants = BTreeMap::new();
    let mut seen: BTreeMap<(String, TableId, String, usize), String> = BTreeMap::new();
    // (env, study) -> where each of its tables' demonstrations came from.
    let mut demo_sources: BTreeMap<(String, String), std::collections::BTreeSet<String>> = BTreeMap::new();
    for m in store.iter() {
        if m.kind != crate::pipeline::stage::StageKind::Eval.name() {
            continue;
        }
        let (p, x) = match Typed::of(m) {
            Ok(Typed { params: Params::Eval(p), metrics: Metrics::Eval(x) }) => (p, x),
            Ok(_) => continue,
            Err(e) => {
                tracing::warn!("skipping {}: {e}", m.key);
                continue;
            }
        };
        let e = p.env.name().to_string();
        let label = method_label(p.method, p.iteration);
        let table = TableId { label: p.table(), study: p.pipeline.clone(), replicate: p.replicate };
        variants.extend(p.variant.clone().map(|v| (p.pipeline.clone(), v)));
        for &r in &x.summary.returns {
            env.push(e.clone());
            method.push(label.clone());
            pipeline.push(table.label.clone());
            run.push(p.run as u32);
            ret.push(r);
        }
        if let Some(other) = seen.insert((e.clone(), table.clone(), label.clone(), p.run), m.key.clone()) {
            return Err(Error::Invalid(format!(
                "{e}: run {} of {label} in table {} is evaluated twice (artifacts {} and {}): two pipeline files named `{}` \
                 with other settings, or an older idrex's results in the same store; give one file another `name`, give \
                 the files disjoint `first_replicate` ranges, or `idrex gc` the store",
                p.run,
                table.label,
                &other[..12],
                &m.key[..12],
                p.pipeline
            )));
        }
        runs.entry((e.clone(), table.clone(), label.clone())).or_default().push(RunEval {
            run: p.run,
            final_returns: x.summary.returns.clone(),
            checkpoints: x.checkpoints.clone(),
        });
        if let Some(acc) = &x.reward {
            a_env.push(e.clone());
            a_pipeline.push(table.label.clone());
            a_method.push(label.clone());
            a_spearman.push(acc.spearman);
            a_pearson.push(acc.pearson);
            a_pairwise.push(acc.pairwise_accuracy);
            a_spearman_checkpoints.push(over_checkpoints(&x.checkpoints, spearman));
            a_pearson_checkpoints.push(over_checkpoints(&x.checkpoints, pearson));
            let reward = m.inputs.get(&Role::Reward.name()).cloned().unwrap_or_default();
            a_ssrr.push(ssrr.get(&(reward, table.label.clone())).copied().unwrap_or(f64::NAN));
            // The PPO run behind the policy: how much of its learned reward the ceiling capped.
            let ppo = m.inputs.get(&Role::Policy.name()).and_then(|k| store.get(k)).and_then(|pm| Typed::of(pm).ok());
            a_capped.push(match ppo {
                Some(Typed { metrics: Metrics::Ppo(x), .. }) => x.reward_capped,
                _ => None,
            });
        }
        // The demonstrations this evaluation was compared with (once per demos artifact).
        if let Some(dk) = m.inputs.get(&Role::Demos.name())
            && demo_keys.insert((e.clone(), table.label.clone(), dk.clone()))
            && let Some(dm) = store.get(dk)
            && let Ok(Typed { params, metrics: Metrics::Demos(d) | Metrics::DemosImport(d) }) = Typed::of(dm)
        {
            let source = match params {
                Params::DemosImport(i) => format!("the file with sha256 {}", &i.sha256[..12]),
                _ => "rollouts of its own demonstrator".to_string(),
            };
            demo_sources.entry((e.clone(), p.pipeline.clone())).or_default().insert(source);
            for &r in &d.returns {
                d_env.push(e.clone());
                d_pipeline.push(table.label.clone());
                d_ret.push(r);
            }
            demo_returns.entry((e.clone(), table.label.clone())).or_default().extend(&d.returns);
        }
    }
    if let Some(((e, study), sources)) = demo_sources.iter().find(|(_, s)| s.len() > 1) {
        let sources: Vec<&str> = sources.iter().map(String::as_str).collect();
        return Err(Error::Invalid(format!(
            "{e}: the runs of study `{study}` disagree on the demonstrations ({}); give every pipeline file named \
             `{study}` the same demos.from, or another name",
            sources.join(" and ")
        )));
    }
    let df = |cols: Vec<Column>| DataFrame::new_infer_height(cols).map_err(pe);
    Ok(Long {
        demo_returns,
        variants,
        episodes: df(vec![
            Column::new("env".into(), env),
            Column::new("pipeline".into(), pipeline),
            Column::new("method".into(), method),
            Column::new("run".into(), run),
            Column::new("return".into(), ret),
        ])?,
        demos: df(vec![Column::new("env".into(), d_env), Column::new("pipeline".into(), d_pipeline), Column::new("return".into(), d_ret)])?,
        accuracy: df(vec![
            Column::new("env".into(), a_env),
            Column::new("pipeline".into(), a_pipeline),
            Column::new("method".into(), a_method),
            Column::new("pearson".into(), a_pearson),
            Column::new("spearman".into(), a_spearman),
            Column::new("pairwise_accuracy".into(), a_pairwise),
            Column::new("spearman_over_checkpoints".into(), a_spearman_checkpoints),
            Column::new("pearson_over_checkpoints".into(), a_pearson_checkpoints),
            Column::new("pearson_ssrr".into(), a_ssrr),
            Column::new("reward_capped".into(), a_capped),
        ])?,
        runs,
    })
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
}

impl Tables {
    /// Every table the report writes as a file, by file stem (`returns` -> `returns.csv`);
    /// the studies', looks' and clones' only where the store has any.
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
        if !self.sweeps.is_empty() {
            out.push(("sweeps", Table::of(&self.sweeps)));
        }
        if !self.looks.is_empty() {
            out.push(("looks", Table::of(&self.looks)));
        }
        if !self.clones.is_empty() {
            out.push(("clones", Table::of(&self.clones)));
        }
        if !self.terms.is_empty() {
            out.push(("terms", Table::of(&self.terms)));
        }
        out
    }
}

pub fn build(store: &Artifacts) -> Result<Tables> {
    let mut long = collect(store)?;
    let mut protocols = Vec::new();
    for ((env, table, method), runs) in &mut long.runs {
        runs.sort_by_key(|r| r.run);
        protocols.extend(protocol_rows(env, table, method, runs));
    }
    let (aggregate, improvement) = studies::aggregate(&protocols, &long.demo_returns);
    let sweeps = sweeps::rows(&aggregate, &long.variants);
    let keys = [col("env"), col("pipeline"), col("method")];
    let per_run = long
        .episodes
        .clone()
        .lazy()
        .group_by([col("env"), col("pipeline"), col("method"), col("run")])
        .agg([col("return").mean().alias("run_mean")])
        .group_by(keys.clone())
        .agg([col("run_mean").max().alias("best_run_avg"), col("run").n_unique().alias("runs")]);
    let runs = long
        .episodes
        .clone()
        .lazy()
        .select([col("env"), col("pipeline"), col("method"), col("run")])
        .unique(None, Default::default())
        .collect()
        .map_err(pe)?;
    let returns = long
        .episodes
        .lazy()
        .group_by(keys.clone())
        .agg([col("return").mean().alias("mean"), col("return").std(0).alias("std"), col("return").count().alias("episodes")])
        .join(per_run, keys.clone(), keys.clone(), JoinArgs::new(JoinType::Left))
        .sort(["env", "pipeline", "method"], Default::default())
        .collect()
        .map_err(pe)?;
    let demos = long
        .demos
        .lazy()
        .group_by([col("env"), col("pipeline")])
        .agg([col("return").mean().alias("demos_avg"), col("return").max().alias("demos_best"), col("return").count().alias("demos")])
        .sort(["env", "pipeline"], Default::default())
        .collect()
        .map_err(pe)?;
    let accuracy = long
        .accuracy
        .lazy()
        .group_by(keys.clone())
        .agg([
            col("pearson").mean(),
            col("spearman").mean(),
            col("pairwise_accuracy").mean(),
            col("spearman_over_checkpoints").mean(),
            col("pearson_over_checkpoints").mean(),
            col("pearson_ssrr").mean(),
            col("reward_capped").mean(),
            col("spearman").count().alias("runs"),
        ])
        .sort(["env", "pipeline", "method"], Default::default())
        .collect()
        .map_err(pe)?;
    // polars' aggregates, read into typed rows once; everything downstream reads the rows.
    let f = |df: &DataFrame, c: &str, i: usize| cell_f(df, c, i).unwrap_or(f64::NAN);
    let n = |df: &DataFrame, c: &str, i: usize| cell_f(df, c, i).unwrap_or(0.0) as usize;
    let s = cell_s;
    Ok(Tables {
        returns: (0..returns.height())
            .map(|i| ReturnRow {
                env: s(&returns, "env", i),
                pipeline: s(&returns, "pipeline", i),
                method: s(&returns, "method", i),
                mean: f(&returns, "mean", i),
                std: f(&returns, "std", i),
                episodes: n(&returns, "episodes", i),
                best_run_avg: f(&returns, "best_run_avg", i),
                runs: n(&returns, "runs", i),
            })
            .collect(),
        evaluated: (0..runs.height())
            .map(|i| (s(&runs, "env", i), s(&runs, "pipeline", i), s(&runs, "method", i), n(&runs, "run", i)))
            .collect(),
        demos: (0..demos.height())
            .map(|i| DemoRow {
                env: s(&demos, "env", i),
                pipeline: s(&demos, "pipeline", i),
                demos_avg: f(&demos, "demos_avg", i),
                demos_best: f(&demos, "demos_best", i),
                demos: n(&demos, "demos", i),
            })
            .collect(),
        accuracy: (0..accuracy.height())
            .map(|i| AccuracyRow {
                env: s(&accuracy, "env", i),
                pipeline: s(&accuracy, "pipeline", i),
                method: s(&accuracy, "method", i),
                pearson: f(&accuracy, "pearson", i),
                spearman: f(&accuracy, "spearman", i),
                pairwise_accuracy: f(&accuracy, "pairwise_accuracy", i),
                spearman_over_checkpoints: f(&accuracy, "spearman_over_checkpoints", i),
                pearson_over_checkpoints: f(&accuracy, "pearson_over_checkpoints", i),
                pearson_ssrr: f(&accuracy, "pearson_ssrr", i),
                reward_capped: cell_f(&accuracy, "reward_capped", i),
                runs: n(&accuracy, "runs", i),
            })
            .collect(),
        protocols,
        aggregate,
        improvement,
        sweeps,
        clones: clones::rows(store),
        demo_returns: long.demo_returns,
        looks: looks::rows(store),
        bc_warning: crate::algo::scoring::BC_WARNING,
        terms: Vec::new(),
    })
}

/// A figure with one decimal; never "NaN" (a figure that could not be computed says so).
fn num(x: Option<f64>) -> String {
    match x {
        Some(v) if v.is_finite() => format!("{v:.1}"),
        _ => "n/a".into(),
    }
}

fn cell_f(df: &DataFrame, name: &str, i: usize) -> Option<f64> {
    df.column(name).ok()?.cast(&DataType::Float64).ok()?.f64().ok()?.get(i)
}
fn cell_s(df: &DataFrame, name: &str, i: usize) -> String {
    df.column(name).ok().and_then(|c| c.str().ok().and_then(|s| s.get(i).map(str::to_string))).unwrap_or_default()
}
