//! `idrex report`: the report's comparison tables, built with polars from the store's
//! manifests. Per environment and method: mean ± std of the ground-truth return over all
//! R runs x 20 episodes, the best average of the R runs (the report's headline figure), and
//! the demonstrations' average and best; next to them the reward-accuracy figures the report
//! lacked (Pearson and Spearman correlation of predicted against true return on unseen
//! evaluation rollouts, and pairwise ranking accuracy).
use polars::prelude::*;

use crate::error::{Error, Result};
use crate::pipeline::Method;
use crate::pipeline::stage::{Metrics, Params, Typed};
use crate::store::Store;

fn pe(e: PolarsError) -> Error {
    Error::Invalid(format!("building the report table: {e}"))
}

/// One evaluation episode per row, one demonstration episode per row, and one reward-
/// accuracy row per evaluation run.
struct Long {
    episodes: DataFrame,
    demos: DataFrame,
    accuracy: DataFrame,
}

fn collect(store: &Store) -> Result<Long> {
    let (mut env, mut method, mut pipeline, mut run, mut ret) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut d_env, mut d_pipeline, mut d_ret) = (vec![], vec![], vec![]);
    let (mut a_env, mut a_method, mut a_pearson, mut a_spearman, mut a_pairwise) = (vec![], vec![], vec![], vec![], vec![]);
    let mut demo_keys = std::collections::BTreeSet::new();
    for m in store.manifests()? {
        if m.kind != crate::pipeline::stage::StageKind::Eval.name() {
            continue;
        }
        let (p, x) = match Typed::of(&m) {
            Ok(Typed { params: Params::Eval(p), metrics: Metrics::Eval(x) }) => (p, x),
            Ok(_) => continue,
            Err(e) => {
                tracing::warn!("skipping {}: {e}", m.key);
                continue;
            }
        };
        let e = p.env.name().to_string();
        let label = if p.iteration > 2 { format!("{} (k={})", p.method.name(), p.iteration) } else { p.method.name().to_string() };
        for &r in &x.summary.returns {
            env.push(e.clone());
            method.push(label.clone());
            pipeline.push(p.pipeline.clone());
            run.push(p.run as u32);
            ret.push(r);
        }
        if let Some(acc) = &x.reward {
            a_env.push(e.clone());
            a_method.push(label.clone());
            a_spearman.push(acc.spearman);
            a_pearson.push(acc.pearson);
            a_pairwise.push(acc.pairwise_accuracy);
        }
        // The demonstrations this evaluation was compared with (once per demos artifact).
        if let Some(dk) = m.inputs.get("demos")
            && demo_keys.insert((e.clone(), p.pipeline.clone(), dk.clone()))
            && let Ok(dm) = store.check(dk)
            && let Ok(Typed { metrics: Metrics::Demos(d) | Metrics::DemosImport(d), .. }) = Typed::of(&dm)
        {
            for &r in &d.returns {
                d_env.push(e.clone());
                d_pipeline.push(p.pipeline.clone());
                d_ret.push(r);
            }
        }
    }
    let df = |cols: Vec<Column>| DataFrame::new_infer_height(cols).map_err(pe);
    Ok(Long {
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
            Column::new("method".into(), a_method),
            Column::new("pearson".into(), a_pearson),
            Column::new("spearman".into(), a_spearman),
            Column::new("pairwise_accuracy".into(), a_pairwise),
        ])?,
    })
}

/// The tables: returns per (env, pipeline, method) and reward accuracy per (env, method).
pub struct Tables {
    pub returns: DataFrame,
    /// (env, pipeline, method, run) of every evaluated run, to name missing runs.
    pub runs: DataFrame,
    pub demos: DataFrame,
    pub accuracy: DataFrame,
}

pub fn build(store: &Store) -> Result<Tables> {
    let long = collect(store)?;
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
        .group_by([col("env"), col("method")])
        .agg([col("pearson").mean(), col("spearman").mean(), col("pairwise_accuracy").mean(), col("spearman").count().alias("runs")])
        .sort(["env", "method"], Default::default())
        .collect()
        .map_err(pe)?;
    Ok(Tables { returns, runs, demos, accuracy })
}

fn cell_f(df: &DataFrame, name: &str, i: usize) -> Option<f64> {
    df.column(name).ok()?.cast(&DataType::Float64).ok()?.f64().ok()?.get(i)
}
fn cell_s(df: &DataFrame, name: &str, i: usize) -> String {
    df.column(name).ok().and_then(|c| c.str().ok().and_then(|s| s.get(i).map(str::to_string))).unwrap_or_default()
}

/// The paper-style markdown: one row per (env, pipeline).
pub fn markdown(t: &Tables) -> String {
    let mut out = String::from("## Ground-truth return (mean ± std over R runs x episodes; best run average in brackets)\n\n");
    out.push_str("| env | pipeline | demos avg | demos best | BC | D-REX | iD-REX interp. | iD-REX action noise | iD-REX multi-BC |\n|---|---|---|---|---|---|---|---|---|\n");
    let mut rows: Vec<(String, String)> =
        (0..t.returns.height()).map(|i| (cell_s(&t.returns, "env", i), cell_s(&t.returns, "pipeline", i))).collect();
    rows.dedup();
    for (env, pipe) in &rows {
        let demo_row = (0..t.demos.height()).find(|&i| &cell_s(&t.demos, "env", i) == env && &cell_s(&t.demos, "pipeline", i) == pipe);
        let f = |x: Option<f64>| x.map_or("missing".to_string(), |v| format!("{v:.1}"));
        out.push_str(&format!(
            "| {env} | {pipe} | {} | {} |",
            f(demo_row.and_then(|i| cell_f(&t.demos, "demos_avg", i))),
            f(demo_row.and_then(|i| cell_f(&t.demos, "demos_best", i)))
        ));
        for m in Method::ALL.map(Method::name) {
            let i = (0..t.returns.height()).find(|&i| {
                &cell_s(&t.returns, "env", i) == env && &cell_s(&t.returns, "pipeline", i) == pipe && cell_s(&t.returns, "method", i) == m
            });
            let cell = match i {
                None => " missing |".to_string(),
                Some(i) => {
                    let runs = cell_f(&t.returns, "runs", i).unwrap_or(0.0);
                    // Runs that other methods of this pipeline have and this one lacks.
                    let seen = |method: Option<&str>| -> std::collections::BTreeSet<i64> {
                        (0..t.runs.height())
                            .filter(|&j| &cell_s(&t.runs, "env", j) == env && &cell_s(&t.runs, "pipeline", j) == pipe)
                            .filter(|&j| {
                                method.is_none_or(|m| cell_s(&t.runs, "method", j) == m)
                                    && cell_s(&t.runs, "method", j) != Method::Bc.name()
                            })
                            .filter_map(|j| cell_f(&t.runs, "run", j).map(|r| r as i64))
                            .collect()
                    };
                    let missing: Vec<String> = seen(None).difference(&seen(Some(m))).map(|r| r.to_string()).collect();
                    let missing = if m == Method::Bc.name() || missing.is_empty() {
                        String::new()
                    } else {
                        format!("; run {} missing", missing.join(", "))
                    };
                    format!(
                        " {:.1} ± {:.1} ({:.1}{}{missing}) |",
                        cell_f(&t.returns, "mean", i).unwrap_or(f64::NAN),
                        cell_f(&t.returns, "std", i).unwrap_or(f64::NAN),
                        cell_f(&t.returns, "best_run_avg", i).unwrap_or(f64::NAN),
                        if m == Method::Bc.name() { String::new() } else { format!(", {runs:.0} runs") }
                    )
                }
            };
            out.push_str(&cell);
        }
        out.push('\n');
    }
    out.push_str("\n## Learned reward on unseen evaluation rollouts (mean over runs)\n\n| env | method | Pearson | Spearman | pairwise accuracy | runs |\n|---|---|---|---|---|---|\n");
    for i in 0..t.accuracy.height() {
        let g = |c: &str| cell_f(&t.accuracy, c, i).map_or("-".into(), |v| format!("{v:.3}"));
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            cell_s(&t.accuracy, "env", i),
            cell_s(&t.accuracy, "method", i),
            g("pearson"),
            g("spearman"),
            g("pairwise_accuracy"),
            cell_f(&t.accuracy, "runs", i).unwrap_or(0.0)
        ));
    }
    out
}

pub fn write_csv(df: &mut DataFrame, path: &std::path::Path) -> Result<()> {
    let mut f = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    CsvWriter::new(&mut f).finish(df).map_err(pe)
}
