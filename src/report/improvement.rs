//! Two methods compared over replicates ([`Improvement`]): the cell, the CSV columns and the
//! legend that every comparison table shares.
use crate::log::table::Cell;
use crate::stats::Improvement;

/// Under every table with comparisons: what its two forms mean.
pub const LEGEND: &str = "\nAgainst a baseline: rliable's probability of improvement (unpaired: every replicate of one against every \
replicate of the other) with rliable's independent-bootstrap 95 % interval; then, paired by replicate (replicate r of both \
shares its seeds), the replicates where the method scored above, of those that did not tie, the exact 95 % interval of \
that rate and the one-sided sign test's p (ties are counted apart). ⚠ marks fewer than 10 replicates, or an interval that \
is a point because every pair agrees.\n\n";

/// One table cell: `P 0.56 [0.08, 0.96]; 3 of 5 [0.15, 0.95], p = 0.500 ⚠ only 5 replicates`, with
/// `, 2 ties` before the warning where replicates tied.
pub fn improvement_cell(i: &Improvement) -> String {
    let warn = i.warning().map_or(String::new(), |w| format!(" ⚠ {w}"));
    // Tied replicates (an iteration that repeats the one before, bit for bit) leave the count.
    let ties = match i.ties {
        0 => String::new(),
        1 => ", 1 tie".to_string(),
        n => format!(", {n} ties"),
    };
    if i.pairs == i.ties {
        // No replicate decides: the paired rate and its test are not measured.
        return format!("P {:.2} [{:.2}, {:.2}]; all {} replicates tie{warn}", i.unpaired, i.unpaired_ci.0, i.unpaired_ci.1, i.pairs);
    }
    format!(
        "P {:.2} [{:.2}, {:.2}]; {} of {} [{:.2}, {:.2}], p = {:.3}{ties}{warn}",
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

/// The CSV columns of a comparison, both forms, each named.
pub const COLUMNS: [&str; 11] = [
    "replicates",
    "rliable_probability",
    "rliable_ci_low",
    "rliable_ci_high",
    "paired_wins",
    "paired_ties",
    "paired_rate",
    "paired_ci_low",
    "paired_ci_high",
    "sign_test_p",
    "warning",
];

/// One comparison's cells under [`COLUMNS`].
pub fn cells(i: &Improvement) -> Vec<Cell> {
    let x = |v: f64| Cell::opt(Some(v), 3);
    vec![
        Cell::int(i.pairs),
        x(i.unpaired),
        x(i.unpaired_ci.0),
        x(i.unpaired_ci.1),
        Cell::int(i.wins),
        Cell::int(i.ties),
        x(i.paired()),
        x(i.paired_ci.0),
        x(i.paired_ci.1),
        x(i.sign_p),
        Cell::text(i.warning().unwrap_or_default()),
    ]
}
