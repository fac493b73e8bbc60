//! The store's evaluations read once into long, typed rows (one per evaluation episode, per
//! demonstration episode, and per evaluation run's reward accuracy), each run's returns and
//! checkpoints, and the demonstrations each table was compared with; polars aggregates the
//! rows into the report's tables ([`super::build`]).
use std::collections::{BTreeMap, BTreeSet};

use polars::prelude::*;

use super::columns::Col;
use super::protocols::RunEval;
use super::{Artifacts, TableId, input_key, method_label, over_checkpoints, pe, terms};
use crate::error::{Error, Result};
use crate::pipeline::role::Role;
use crate::pipeline::stage::eval::{EvalMetrics, EvalParams};
use crate::pipeline::stage::{Metrics, Params, Typed};
use crate::stats::{pearson, spearman};
use crate::store::Manifest;

/// Each scored reward's scores on its task's bank, by its T-REX artifact's key.
type BankScores = BTreeMap<String, crate::algo::bank::BankScore>;

/// One evaluation episode's return.
struct EpisodeRow {
    env: String,
    table: String,
    method: String,
    run: u32,
    ret: f64,
}

/// One demonstration episode's return, in the table it was compared with.
struct DemoEpisodeRow {
    env: String,
    table: String,
    ret: f64,
}

/// How well one evaluation run's learned reward ranks what it scored.
struct AccuracyRunRow {
    env: String,
    table: String,
    method: String,
    pearson: f64,
    spearman: f64,
    pairwise_accuracy: f64,
    spearman_over_checkpoints: f64,
    pearson_over_checkpoints: f64,
    pearson_ssrr: f64,
    /// The reward's scores on its task's bank ([`super::bank`]), NaN where unscored.
    bank_spearman: f64,
    bank_forward_spearman: f64,
    bank_overpaid: Option<f64>,
    /// How much of its learned reward the ceiling capped, in the PPO run behind the policy.
    reward_capped: Option<f64>,
}

/// The rows as polars reads them, with each run's evaluations and the demonstrations.
pub(super) struct Long {
    pub episodes: DataFrame,
    pub demos: DataFrame,
    pub accuracy: DataFrame,
    /// (env, table, method label) -> its evaluated runs.
    pub runs: BTreeMap<(String, TableId, String), Vec<RunEval>>,
    /// (env, table label) -> the demonstrations' returns.
    pub demo_returns: BTreeMap<(String, String), Vec<f64>>,
    /// Study -> its place in a sweep.
    pub variants: BTreeMap<String, crate::pipeline::stage::eval::VariantTag>,
}

/// What the pass over the evaluations gathers.
#[derive(Default)]
struct Gathered {
    episodes: Vec<EpisodeRow>,
    demos: Vec<DemoEpisodeRow>,
    accuracy: Vec<AccuracyRunRow>,
    runs: BTreeMap<(String, TableId, String), Vec<RunEval>>,
    demo_returns: BTreeMap<(String, String), Vec<f64>>,
    variants: BTreeMap<String, crate::pipeline::stage::eval::VariantTag>,
    /// (env, table, method, run) -> the evaluation's key: a run evaluated twice is refused.
    seen: BTreeMap<(String, TableId, String, usize), String>,
    /// (env, table label, demos key) already counted.
    demo_keys: BTreeSet<(String, String, String)>,
    /// (env, study) -> where each of its tables' demonstrations came from.
    demo_sources: BTreeMap<(String, String), BTreeSet<String>>,
}

pub(super) fn collect(store: &Artifacts) -> Result<Long> {
    let ssrr = terms::ssrr_pearson(store);
    let bank = super::bank::scores(store);
    let mut g = Gathered::default();
    for (m, p, x) in store.evaluations() {
        g.add(store, (&ssrr, &bank), m, p, x)?;
    }
    if let Some(((e, study), sources)) = g.demo_sources.iter().find(|(_, s)| s.len() > 1) {
        let sources: Vec<&str> = sources.iter().map(String::as_str).collect();
        return Err(Error::Invalid(format!(
            "{e}: the runs of study `{study}` disagree on the demonstrations ({}); give every pipeline file named \
             `{study}` the same demos.from, or another name",
            sources.join(" and ")
        )));
    }
    g.into_long()
}

impl Gathered {
    /// One evaluation: its episodes, its run, its reward's accuracy and its demonstrations.
    fn add(
        &mut self,
        store: &Artifacts,
        (ssrr, bank): (&BTreeMap<(String, String), f64>, &BankScores),
        m: &Manifest,
        p: &EvalParams,
        x: &EvalMetrics,
    ) -> Result<()> {
        let env = p.env.name().to_string();
        let method = method_label(p.method, p.iteration);
        let table = TableId { label: p.table(), study: p.pipeline.clone(), replicate: p.replicate };
        self.variants.extend(p.variant.clone().map(|v| (p.pipeline.clone(), v)));
        for &ret in &x.summary.returns {
            self.episodes.push(EpisodeRow { env: env.clone(), table: table.label.clone(), method: method.clone(), run: p.run as u32, ret });
        }
        if let Some(other) = self.seen.insert((env.clone(), table.clone(), method.clone(), p.run), m.key.clone()) {
            return Err(Error::Invalid(format!(
                "{env}: run {} of {method} in table {} is evaluated twice (artifacts {} and {}): two pipeline files named `{}` \
                 with other settings, or an older idrex's results in the same store; give one file another `name`, give \
                 the files disjoint `first_replicate` ranges, or `idrex gc` the store",
                p.run,
                table.label,
                &other[..12],
                &m.key[..12],
                p.pipeline
            )));
        }
        let run = RunEval { run: p.run, final_returns: x.summary.returns.clone(), checkpoints: x.checkpoints.clone() };
        self.runs.entry((env.clone(), table.clone(), method.clone())).or_default().push(run);
        if let Some(acc) = &x.reward {
            let reward = input_key(m, Role::Reward).cloned().unwrap_or_default();
            let ppo = store.input(m, Role::Policy).and_then(|pm| store.typed(pm));
            let scored = bank.get(&reward);
            self.accuracy.push(AccuracyRunRow {
                env: env.clone(),
                table: table.label.clone(),
                method,
                pearson: acc.pearson,
                spearman: acc.spearman,
                pairwise_accuracy: acc.pairwise_accuracy,
                spearman_over_checkpoints: over_checkpoints(&x.checkpoints, spearman),
                pearson_over_checkpoints: over_checkpoints(&x.checkpoints, pearson),
                pearson_ssrr: ssrr.get(&(reward, table.label.clone())).copied().unwrap_or(f64::NAN),
                bank_spearman: scored.map_or(f64::NAN, |s| s.spearman),
                bank_forward_spearman: scored.map_or(f64::NAN, |s| s.forward_spearman),
                bank_overpaid: scored.map(|s| s.overpaid.iter().sum::<usize>() as f64),
                reward_capped: match ppo {
                    Some(Typed { metrics: Metrics::Ppo(x), .. }) => x.reward_capped,
                    _ => None,
                },
            });
        }
        // The demonstrations this evaluation was compared with (once per demos artifact).
        if let Some(dk) = input_key(m, Role::Demos)
            && self.demo_keys.insert((env.clone(), table.label.clone(), dk.clone()))
            && let Some(dm) = store.get(dk)
            && let Some(Typed { params, metrics: Metrics::Demos(d) | Metrics::DemosImport(d) }) = store.typed(dm)
        {
            let source = match params {
                Params::DemosImport(i) => format!("the file with sha256 {}", &i.sha256[..12]),
                _ => "rollouts of its own demonstrator".to_string(),
            };
            self.demo_sources.entry((env.clone(), p.pipeline.clone())).or_default().insert(source);
            for &ret in &d.returns {
                self.demos.push(DemoEpisodeRow { env: env.clone(), table: table.label.clone(), ret });
            }
            self.demo_returns.entry((env, table.label)).or_default().extend(&d.returns);
        }
        Ok(())
    }

    /// The rows as columns (named by [`Col`], as [`super::build`]'s aggregations read them).
    fn into_long(self) -> Result<Long> {
        let df = |cols: Vec<Column>| DataFrame::new_infer_height(cols).map_err(pe);
        let (e, d, a) = (&self.episodes, &self.demos, &self.accuracy);
        Ok(Long {
            episodes: df(vec![
                Col::Env.column(e, |r| r.env.clone()),
                Col::Pipeline.column(e, |r| r.table.clone()),
                Col::Method.column(e, |r| r.method.clone()),
                Col::Run.column(e, |r| r.run),
                Col::Return.column(e, |r| r.ret),
            ])?,
            demos: df(vec![
                Col::Env.column(d, |r| r.env.clone()),
                Col::Pipeline.column(d, |r| r.table.clone()),
                Col::Return.column(d, |r| r.ret),
            ])?,
            accuracy: df(vec![
                Col::Env.column(a, |r| r.env.clone()),
                Col::Pipeline.column(a, |r| r.table.clone()),
                Col::Method.column(a, |r| r.method.clone()),
                Col::Pearson.column(a, |r| r.pearson),
                Col::Spearman.column(a, |r| r.spearman),
                Col::PairwiseAccuracy.column(a, |r| r.pairwise_accuracy),
                Col::SpearmanOverCheckpoints.column(a, |r| r.spearman_over_checkpoints),
                Col::PearsonOverCheckpoints.column(a, |r| r.pearson_over_checkpoints),
                Col::PearsonSsrr.column(a, |r| r.pearson_ssrr),
                Col::BankSpearman.column(a, |r| r.bank_spearman),
                Col::BankForwardSpearman.column(a, |r| r.bank_forward_spearman),
                Col::BankOverpaid.column(a, |r| r.bank_overpaid),
                Col::RewardCapped.column(a, |r| r.reward_capped),
            ])?,
            runs: self.runs,
            demo_returns: self.demo_returns,
            variants: self.variants,
        })
    }
}
