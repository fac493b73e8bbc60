//! Two methods compared over replicates ([`Improvement`]): the cell, the CSV columns and the
//! legend that every comparison table shares.
use polars::prelude::*;

use crate::stats::Improvement;

/// Under every table with comparisons: what its two forms mean.
pub const LEGEND: &str = "\nAgainst a baseline: rliable's probability of improvement (unpaired: every replicate of one against every \
replicate of the other) with rliable's independent-bootstrap 95 % interval; then, paired by replicate (replicate r of both \
shares its seeds), the replicates where the method scored above, the exact 95 % interval of that rate and the one-sided \
sign test's p. ⚠ marks fewer than 10 replicates, or an interval that is a point because every pair agrees.\n\n";

/// One table cell: `P 0.56 [0.08, 0.96]; 3 of 5 [0.15, 0.95], p = 0.500 ⚠ only 5 replicates`.
pub fn improvement_cell(i: &Improvement) -> String {
    let warn = i.warning().map_or(String::new(), |w| format!(" ⚠ {w}"));
    format!(
        "P {:.2} [{:.2}, {:.2}]; {} of {} [{:.2}, {:.2}], p = {:.3}{warn}",
        i.unpaired,
        i.unpaired_ci.0,
        i.unpaired_ci.1,
        i.wins,
        i.pairs - i.ties,
        i.paired_ci.0,
        i.paired_ci.1,
        i.sign_p
    )
}

/// The CSV columns of a list of comparisons, both forms, each named.
pub fn improvement_columns(rows: &[Improvement]) -> Vec<Column> {
    let x = |f: &dyn Fn(&Improvement) -> f64| -> Vec<f64> { rows.iter().map(f).collect() };
    let n = |f: &dyn Fn(&Improvement) -> usize| -> Vec<u64> { rows.iter().map(|r| f(r) as u64).collect() };
    vec![
        Column::new("replicates".into(), n(&|r| r.pairs)),
        Column::new("rliable_probability".into(), x(&|r| r.unpaired)),
        Column::new("rliable_ci_low".into(), x(&|r| r.unpaired_ci.0)),
        Column::new("rliable_ci_high".into(), x(&|r| r.unpaired_ci.1)),
        Column::new("paired_wins".into(), n(&|r| r.wins)),
        Column::new("paired_ties".into(), n(&|r| r.ties)),
        Column::new("paired_rate".into(), x(&|r| r.paired())),
        Column::new("paired_ci_low".into(), x(&|r| r.paired_ci.0)),
        Column::new("paired_ci_high".into(), x(&|r| r.paired_ci.1)),
        Column::new("sign_test_p".into(), x(&|r| r.sign_p)),
        Column::new("warning".into(), rows.iter().map(|r| r.warning().unwrap_or_default()).collect::<Vec<String>>()),
    ]
}
