//! The three protocols ([`Protocol`]) a PPO method's return is reported under: which policy
//! of each run is measured, each cell with its bootstrap interval over runs; their markdown
//! tables and CSV.
use super::{TableId, num};
use crate::algo::scoring::{CheckpointEval, select};
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::Method;
use crate::stats::{ReturnStats, bootstrap_ci};

/// Which policy of each PPO run a figure is measured on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Protocol {
    /// The policy at the end of training.
    Final,
    /// The checkpoint whose true return, pooled over the runs, is highest: the paper's
    /// protocol (and the original D-REX code's), a choice made with the ground truth.
    BestByGroundTruth,
    /// The checkpoint whose pessimistic learned return (the ensemble's most pessimistic
    /// member, in units of the demonstrations), pooled over the runs, is highest: a choice a
    /// user without the true reward can make.
    GroundTruthFree,
}

impl Protocol {
    pub const ALL: [Protocol; 3] = [Protocol::Final, Protocol::BestByGroundTruth, Protocol::GroundTruthFree];

    pub fn name(self) -> &'static str {
        match self {
            Protocol::Final => "final",
            Protocol::BestByGroundTruth => "best-by-ground-truth",
            Protocol::GroundTruthFree => "ground-truth-free",
        }
    }

    pub(super) fn title(self) -> &'static str {
        match self {
            Protocol::Final => "final policy",
            Protocol::BestByGroundTruth => "best checkpoint, SELECTED WITH THE GROUND-TRUTH REWARD (the paper's protocol)",
            Protocol::GroundTruthFree => "checkpoint chosen without the ground truth (highest pessimistic learned return)",
        }
    }
}

/// Bootstrap resamples for the confidence intervals.
pub(super) const RESAMPLES: usize = 10_000;

/// One evaluated run: its final policy's returns and its checkpoints.
pub(super) struct RunEval {
    pub run: usize,
    pub final_returns: Vec<f64>,
    pub checkpoints: Vec<CheckpointEval>,
}

/// One cell of a protocol table.
#[derive(Debug, Clone, PartialEq)]
pub struct ProtocolRow {
    pub env: String,
    /// The table: the pipeline's name, with the replicate past the first (`study/r3`).
    pub pipeline: String,
    /// The pipeline's name (a study's, across the files and replicates that share it).
    pub study: String,
    pub replicate: usize,
    /// Each run's mean return at the chosen policy, in run order.
    pub run_means: Vec<f64>,
    pub method: String,
    pub protocol: Protocol,
    /// The chosen checkpoint's global step (None for the final policy or without checkpoints).
    pub step: Option<usize>,
    pub stats: ReturnStats,
    pub runs: usize,
    pub ci: (f64, f64),
    /// Best-by-ground-truth mean minus this one (ground-truth-free rows only).
    pub gap_to_best: Option<f64>,
}

/// The three protocols' rows of one (env, pipeline, method).
pub(super) fn protocol_rows(env: &str, table: &TableId, method: &str, runs: &[RunEval]) -> Vec<ProtocolRow> {
    let row = |protocol, step: Option<usize>, per_run: Vec<Vec<f64>>| {
        let pooled: Vec<f64> = per_run.iter().flatten().copied().collect();
        let run_means: Vec<f64> = per_run.iter().map(|r| ReturnStats::of(r).mean).collect();
        ProtocolRow {
            env: env.into(),
            pipeline: table.label.clone(),
            study: table.study.clone(),
            replicate: table.replicate,
            method: method.into(),
            protocol,
            step,
            stats: ReturnStats::of(&pooled),
            runs: runs.len(),
            ci: bootstrap_ci(&run_means, RESAMPLES, 0),
            run_means,
            gap_to_best: None,
        }
    };
    let at_step = |step: usize| {
        runs.iter().map(|r| r.checkpoints.iter().find(|c| c.step == step).expect("a chosen step").returns.clone()).collect::<Vec<_>>()
    };
    let final_row = row(Protocol::Final, None, runs.iter().map(|r| r.final_returns.clone()).collect());
    let chosen = select(&runs.iter().map(|r| r.checkpoints.as_slice()).collect::<Vec<_>>());
    let (best, free) = (chosen.by_ground_truth, chosen.without_ground_truth);
    let mut out = vec![final_row.clone()];
    let best_row = match best {
        Some(s) => row(Protocol::BestByGroundTruth, Some(s), at_step(s)),
        // Without checkpoints (BC) the final policy is the only candidate.
        None => ProtocolRow { protocol: Protocol::BestByGroundTruth, ..final_row.clone() },
    };
    let mut free_row = match (free, best) {
        (Some(s), _) => row(Protocol::GroundTruthFree, Some(s), at_step(s)),
        (None, None) => ProtocolRow { protocol: Protocol::GroundTruthFree, ..final_row.clone() },
        // Checkpoints without learned scores: nothing to choose with.
        (None, Some(_)) => return vec![final_row, best_row],
    };
    if free.is_some() {
        free_row.gap_to_best = Some(best_row.stats.mean - free_row.stats.mean);
    }
    out.push(best_row);
    out.push(free_row);
    out
}

/// The paper's column headings after `env` and `pipeline`: one per method.
pub(super) fn method_columns(first: &[&str]) -> Vec<String> {
    first.iter().map(|c| c.to_string()).chain(Method::ALL.iter().map(|m| m.label().to_string())).collect()
}

/// One table per protocol, in the paper's layout; each cell: mean ± std over runs x
/// episodes, the 95 % bootstrap interval of the mean over runs, the checkpoint's step.
pub(super) fn protocols_markdown(rows: &[ProtocolRow]) -> String {
    let mut out = String::from(
        "\n## Three protocols (mean ± std over runs x episodes [95 % bootstrap CI of the mean over runs] @ checkpoint step)\n",
    );
    let mut groups: Vec<(&str, &str)> = rows.iter().map(|r| (r.env.as_str(), r.pipeline.as_str())).collect();
    groups.dedup();
    for protocol in Protocol::ALL {
        out.push_str(&format!("\n### {}\n\n", protocol.title()));
        let mut table = Table { columns: method_columns(&["env", "pipeline"]), rows: vec![] };
        for (env, pipeline) in &groups {
            let mut row = vec![Cell::text(*env), Cell::text(*pipeline)];
            for m in Method::ALL {
                let cell = rows.iter().find(|r| r.env == *env && r.pipeline == *pipeline && r.method == m.name() && r.protocol == protocol);
                row.push(Cell::Text(match cell {
                    None => "missing".to_string(),
                    Some(r) => {
                        let step = r.step.map_or(String::new(), |s| format!(" @{s}"));
                        let gap = r.gap_to_best.map_or(String::new(), |g| format!("; {} below the best", num(Some(g))));
                        let [mean, std, lo, hi] = [r.stats.mean, r.stats.std, r.ci.0, r.ci.1].map(|x| num(Some(x)));
                        format!("{mean} ± {std} [{lo}, {hi}]{step}{gap}")
                    }
                }));
            }
            table.rows.push(row);
        }
        out.push_str(&table.markdown());
    }
    out
}

/// `protocols.csv`: one row per (env, pipeline, method, protocol).
impl Row for ProtocolRow {
    fn header() -> Vec<&'static str> {
        vec!["env", "pipeline", "method", "protocol", "step", "mean", "std", "episodes", "runs", "ci_low", "ci_high", "gap_to_best"]
    }

    fn cells(&self) -> Vec<Cell> {
        let x = |v: f64| Cell::opt(Some(v), 1);
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.method),
            Cell::text(self.protocol.name()),
            Cell::Int(self.step.map(|s| s as u64)),
            x(self.stats.mean),
            x(self.stats.std),
            Cell::int(self.stats.episodes),
            Cell::int(self.runs),
            x(self.ci.0),
            x(self.ci.1),
            Cell::opt(self.gap_to_best, 1),
        ]
    }
}

/// How well the learned reward tracks one PPO run's own policies over training: the
/// `correlation` (Spearman or Pearson), over the checkpoints, of the ensemble-mean learned
/// return with the true return, each the mean over the checkpoint's evaluation episodes
/// (NaN without learned scores). Negative means PPO climbing the learned reward walked down
/// the true one. These policies are trajectories T-REX never saw, from poor to trained:
/// Pearson over them is the number SSRR reports as the reward's correlation with the true
/// return (SSRR pools single episodes, and its training set, where this takes checkpoint
/// means).
pub fn over_checkpoints(checkpoints: &[CheckpointEval], correlation: fn(&[f64], &[f64]) -> f64) -> f64 {
    let scored: Vec<(f64, f64)> = checkpoints
        .iter()
        .filter_map(|c| c.learned.map(|l| (l.mean, c.returns.iter().sum::<f64>() / c.returns.len().max(1) as f64)))
        .collect();
    if scored.len() < 2 || scored.len() != checkpoints.len() {
        return f64::NAN;
    }
    let (learned, truth): (Vec<f64>, Vec<f64>) = scored.into_iter().unzip();
    correlation(&learned, &truth)
}
