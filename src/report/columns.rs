//! The names of the report's long rows' and aggregates' columns, one closed set: the columns
//! [`super::collect`] builds, the aggregations and aliases of [`super::build`] and the typed
//! rows read back from polars all name a column through [`Col`]. A misspelt column does not
//! compile, and a column missing from a frame is an error, never a silent NaN or empty cell.
use polars::prelude::*;

use crate::error::{Error, Result};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Col {
    Env,
    Pipeline,
    Method,
    Run,
    Return,
    RunMean,
    Mean,
    Std,
    Episodes,
    BestRunAvg,
    Runs,
    DemosAvg,
    DemosBest,
    Demos,
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
}

impl Col {
    pub(super) fn name(self) -> &'static str {
        match self {
            Col::Env => "env",
            Col::Pipeline => "pipeline",
            Col::Method => "method",
            Col::Run => "run",
            Col::Return => "return",
            Col::RunMean => "run_mean",
            Col::Mean => "mean",
            Col::Std => "std",
            Col::Episodes => "episodes",
            Col::BestRunAvg => "best_run_avg",
            Col::Runs => "runs",
            Col::DemosAvg => "demos_avg",
            Col::DemosBest => "demos_best",
            Col::Demos => "demos",
            Col::Pearson => "pearson",
            Col::Spearman => "spearman",
            Col::PairwiseAccuracy => "pairwise_accuracy",
            Col::SpearmanOverCheckpoints => "spearman_over_checkpoints",
            Col::PearsonOverCheckpoints => "pearson_over_checkpoints",
            Col::PearsonSsrr => "pearson_ssrr",
            Col::BankSpearman => "bank_spearman",
            Col::BankForwardSpearman => "bank_forward_spearman",
            Col::BankOverpaid => "bank_overpaid",
            Col::RewardCapped => "reward_capped",
        }
    }

    /// The column in a polars expression.
    pub(super) fn expr(self) -> Expr {
        col(self.name())
    }

    /// A column of values for a frame.
    pub(super) fn column<R, T>(self, rows: &[R], cell: impl Fn(&R) -> T) -> Column
    where
        Series: NamedFrom<Vec<T>, [T]>,
    {
        Column::new(self.name().into(), rows.iter().map(cell).collect::<Vec<T>>())
    }

    fn of(self, df: &DataFrame) -> Result<&Column> {
        df.column(self.name()).map_err(|e| Error::Invalid(format!("building the report: no column `{}`: {e}", self.name())))
    }

    /// Row `i` as a number (None where polars holds a null: nothing to aggregate).
    pub(super) fn f64(self, df: &DataFrame, i: usize) -> Result<Option<f64>> {
        let c = self.of(df)?.cast(&DataType::Float64).map_err(super::pe)?;
        Ok(c.f64().map_err(super::pe)?.get(i))
    }

    /// Row `i` as text.
    pub(super) fn text(self, df: &DataFrame, i: usize) -> Result<String> {
        let c = self.of(df)?;
        let s = c.str().map_err(super::pe)?.get(i);
        s.map(str::to_string).ok_or_else(|| Error::Invalid(format!("building the report: `{}` is empty in row {i}", self.name())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_column_is_an_error_not_a_nan() {
        let df =
            DataFrame::new_infer_height(vec![Col::Mean.column(&[1.5f64, f64::NAN], |x| *x), Col::Env.column(&["a"; 2], |s| s.to_string())])
                .unwrap();
        assert_eq!(Col::Mean.f64(&df, 0).unwrap(), Some(1.5));
        assert_eq!(Col::Env.text(&df, 1).unwrap(), "a");
        let err = Col::Std.f64(&df, 0).unwrap_err().to_string();
        assert!(err.contains("no column `std`"), "{err}");
        assert!(Col::Mean.text(&df, 0).is_err(), "a number is not text");
    }
}
