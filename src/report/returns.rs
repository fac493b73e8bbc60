//! The per-pipeline tables: each method's true return over its runs' episodes, the
//! demonstrations', and the learned reward's accuracy on the policies' own rollouts; their
//! rows (`returns.csv`, `demos.csv`, `reward_accuracy.csv`) and the report's markdown, which
//! puts the answer first.
use super::protocols::{method_columns, protocols_markdown};
use super::{Tables, answer, clones, looks, num, studies};
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::Method;

/// `returns.csv`: one (env, pipeline, method)'s true return over all its runs' episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct ReturnRow {
    pub env: String,
    pub pipeline: String,
    pub method: String,
    pub mean: f64,
    /// Over runs x episodes (population).
    pub std: f64,
    pub episodes: usize,
    /// The best run's mean return (the paper's headline figure).
    pub best_run_avg: f64,
    pub runs: usize,
}

/// `demos.csv`: one table's demonstrations.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoRow {
    pub env: String,
    pub pipeline: String,
    pub demos_avg: f64,
    pub demos_best: f64,
    pub demos: usize,
}

/// `reward_accuracy.csv`: the learned reward on one (env, pipeline, method)'s evaluation
/// rollouts, the mean over its runs.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyRow {
    pub env: String,
    pub pipeline: String,
    pub method: String,
    pub pearson: f64,
    pub spearman: f64,
    pub pairwise_accuracy: f64,
    pub spearman_over_checkpoints: f64,
    /// See [`super::over_checkpoints`].
    pub pearson_over_checkpoints: f64,
    /// SSRR's number: [`super::terms::ssrr_pearson`].
    pub pearson_ssrr: f64,
    /// The reward's Spearman over its task's bank, within its forward gaits, and how many
    /// backward, still or random gaits it overpays ([`super::bank`]); NaN and None unscored.
    pub bank_spearman: f64,
    pub bank_forward_spearman: f64,
    pub bank_overpaid: Option<f64>,
    /// With `reward.ceiling`: the mean over runs of the fraction of the members' per-step
    /// values PPO trained on that the ceiling capped (None without a ceiling).
    pub reward_capped: Option<f64>,
    pub runs: usize,
}

impl Row for ReturnRow {
    fn header() -> Vec<&'static str> {
        vec!["env", "pipeline", "method", "mean", "std", "episodes", "best_run_avg", "runs"]
    }
    fn cells(&self) -> Vec<Cell> {
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.method),
            Cell::num(self.mean),
            Cell::num(self.std),
            Cell::int(self.episodes),
            Cell::num(self.best_run_avg),
            Cell::int(self.runs),
        ]
    }
}

impl Row for DemoRow {
    fn header() -> Vec<&'static str> {
        vec!["env", "pipeline", "demos_avg", "demos_best", "demos"]
    }
    fn cells(&self) -> Vec<Cell> {
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::num(self.demos_avg),
            Cell::num(self.demos_best),
            Cell::int(self.demos),
        ]
    }
}

impl Row for AccuracyRow {
    fn header() -> Vec<&'static str> {
        vec![
            "env",
            "pipeline",
            "method",
            "pearson",
            "spearman",
            "pairwise_accuracy",
            "spearman_over_checkpoints",
            "pearson_over_checkpoints",
            "pearson_ssrr",
            "bank_spearman",
            "bank_forward_spearman",
            "bank_overpaid",
            "reward_capped",
            "runs",
        ]
    }
    fn cells(&self) -> Vec<Cell> {
        let x = |v: f64| Cell::opt(Some(v), 3);
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.method),
            x(self.pearson),
            x(self.spearman),
            x(self.pairwise_accuracy),
            x(self.spearman_over_checkpoints),
            x(self.pearson_over_checkpoints),
            x(self.pearson_ssrr),
            Cell::opt(Some(self.bank_spearman).filter(|v| v.is_finite()), 3),
            Cell::opt(Some(self.bank_forward_spearman).filter(|v| v.is_finite()), 3),
            Cell::opt(self.bank_overpaid, 1),
            Cell::opt(self.reward_capped, 3),
            Cell::int(self.runs),
        ]
    }
}

/// The answer alone: what a terminal shows after a run (the report's first section).
pub fn answer_markdown(t: &Tables) -> String {
    let mut out = answer::markdown(&t.protocols, &t.aggregate, &t.improvement, &t.demo_returns, &t.looks, t.bc_warning);
    out.push_str(&super::questions::markdown(&t.answers));
    out.push_str(&super::terms::living(&t.terms));
    out
}

/// The paper-style markdown, the answer first: one row per (env, pipeline).
pub fn markdown(t: &Tables) -> String {
    let mut out = answer_markdown(t);
    out.push_str(&looks::markdown(&t.looks));
    out.push_str(&studies::markdown(&t.aggregate, &t.improvement));
    out.push_str(&super::sweeps::markdown(&t.sweeps));
    out.push_str(&super::sweeps::decisions_markdown(&t.decisions));
    out.push_str("## Ground-truth return (mean ± std over R runs x episodes; best run average in brackets)\n\n");
    let mut table = Table { columns: method_columns(&["env", "pipeline", "demos avg", "demos best"]), rows: vec![] };
    let mut groups: Vec<(&str, &str)> = t.returns.iter().map(|r| (r.env.as_str(), r.pipeline.as_str())).collect();
    groups.dedup();
    for (env, pipe) in groups {
        let demo = t.demos.iter().find(|d| d.env == env && d.pipeline == pipe);
        let shown = |x: Option<f64>| Cell::Text(x.map_or("missing".to_string(), |v| num(Some(v))));
        let mut row = vec![Cell::text(env), Cell::text(pipe), shown(demo.map(|d| d.demos_avg)), shown(demo.map(|d| d.demos_best))];
        // Runs that the pipeline's learned-reward methods have, to name those one lacks.
        let runs_of = |method: Option<&str>| -> std::collections::BTreeSet<usize> {
            t.evaluated
                .iter()
                .filter(|(e, p, m, _)| e == env && p == pipe && m != Method::Bc.name() && method.is_none_or(|x| m == x))
                .map(|x| x.3)
                .collect()
        };
        for m in Method::ALL.map(Method::name) {
            let cell = match t.returns.iter().find(|r| r.env == env && r.pipeline == pipe && r.method == m) {
                None => "missing".to_string(),
                Some(r) => {
                    let missing: Vec<String> = runs_of(None).difference(&runs_of(Some(m))).map(|r| r.to_string()).collect();
                    let missing = if m == Method::Bc.name() || missing.is_empty() {
                        String::new()
                    } else {
                        format!("; run {} missing", missing.join(", "))
                    };
                    let counts = if m == Method::Bc.name() {
                        format!(", {} episodes", r.episodes)
                    } else {
                        format!(", {} runs, {} episodes", r.runs, r.episodes)
                    };
                    format!("{} ± {} ({}{counts}{missing})", num(Some(r.mean)), num(Some(r.std)), num(Some(r.best_run_avg)))
                }
            };
            row.push(Cell::Text(cell));
        }
        table.rows.push(row);
    }
    out.push_str(&table.markdown());
    out.push_str(concat!(
        "\n## Learned reward on the policies' own evaluation rollouts (mean over runs)\n\n",
        "Pearson, Spearman and pairwise accuracy: predicted against true return over the final policy's episodes. ",
        "Over checkpoints: Spearman and Pearson correlation of learned and true return across each PPO run's checkpoints ",
        "(does climbing the learned reward climb the true one?). Pearson, SSRR's way: over every trajectory of the ",
        "reward's ranked sets, the demonstrations and the final policies' evaluation episodes (SSRR's number; SSRR ",
        "pools checkpoints' rollouts where this pools the final policies'). Bank: Spearman over the task's bank of gaits, ",
        "within its forward gaits, and the backward, still or random gaits it pays more than a truly better forward one ",
        "(the reward bench, below; n/a where the file has no `bank`). Capped by the ceiling: the fraction of the learned ",
        "reward's per-step values PPO trained on that `reward.ceiling` cut (n/a without a ceiling).\n\n",
    ));
    let mut accuracy = Table::of(&t.accuracy);
    accuracy.columns = [
        "env",
        "pipeline",
        "method",
        "Pearson",
        "Spearman",
        "pairwise accuracy",
        "Spearman over checkpoints",
        "Pearson over checkpoints",
        "Pearson, SSRR's way",
        "bank Spearman",
        "bank forward Spearman",
        "bank overpaid",
        "capped by the ceiling",
        "runs",
    ]
    .map(String::from)
    .to_vec();
    out.push_str(&accuracy.markdown());
    out.push_str(&super::bank::markdown(&t.bank));
    out.push_str(&super::terms::markdown(&t.terms));
    out.push_str(&super::terms::gains_markdown(&t.gains));
    out.push_str(&protocols_markdown(&t.protocols));
    out.push_str(&clones::markdown(&t.clones));
    out
}
