//! `idrex exp diff A B`: the resolved parameters that differ between two studies, then per
//! environment, method and protocol the change in score with its probability of improvement.
//! Replicates are paired where they share their seeds (replicate r of two studies on the same
//! seed set shares its randomness, and its rewards where only PPO changed); without a shared
//! replicate only rliable's unpaired form can be given.
use super::{RESAMPLES, Study};
use crate::log::table::{Cell, Table};
use crate::report::Protocol;
use crate::stats::{Improvement, mean, probability_of_improvement, probability_of_improvement_independent_ci};

/// Parameter, A's values, B's values: every resolved parameter whose values differ.
pub fn params(a: &Study, b: &Study) -> Table {
    let rows = super::changed(&[a, b]).into_iter().map(|k| vec![Cell::text(&k), Cell::text(a.param(&k)), Cell::text(b.param(&k))]);
    Table { columns: vec!["parameter".into(), a.name.clone(), b.name.clone()], rows: rows.collect() }
}

/// How A compares with B on one (env, method, protocol).
#[derive(Debug, Clone, PartialEq)]
pub enum Comparison {
    /// Over the replicates whose seeds both studies share.
    Paired(Improvement),
    /// No shared replicate: rliable's statistic over all of both, with its interval.
    Unpaired { p: f64, ci: (f64, f64) },
}

/// Env, method, protocol, both means, the change, the replicates behind it, the comparison.
pub fn metrics(a: &Study, b: &Study, protocols: &[Protocol]) -> Table {
    let columns = [
        "env",
        "method",
        "protocol",
        "a_mean",
        "b_mean",
        "a_minus_b",
        "a_replicates",
        "b_replicates",
        "paired",
        "rliable_p",
        "paired_wins",
        "paired_rate",
        "sign_test_p",
        "warning",
    ];
    let mut rows = Vec::new();
    for &protocol in protocols {
        for ((env, method), ra) in &a.scores {
            let Some(rb) = b.scores.get(&(*env, method.clone())) else { continue };
            let score = |reps: &std::collections::BTreeMap<usize, super::Replicate>| -> Vec<(usize, f64)> {
                reps.iter().filter_map(|(&r, x)| x.score(protocol).map(|s| (r, s))).collect()
            };
            let (xa, xb) = (score(ra), score(rb));
            if xa.is_empty() || xb.is_empty() {
                continue;
            }
            let pairs: Vec<(f64, f64)> = xa
                .iter()
                .filter_map(|(r, x)| {
                    let seeds = &ra[r].seeds;
                    rb.iter()
                        .find(|(_, y)| !y.seeds.is_disjoint(seeds))
                        .and_then(|(q, _)| xb.iter().find(|(rq, _)| rq == q))
                        .map(|(_, y)| (*x, *y))
                })
                .collect();
            let (va, vb): (Vec<f64>, Vec<f64>) = (xa.iter().map(|x| x.1).collect(), xb.iter().map(|x| x.1).collect());
            let comparison = if pairs.is_empty() {
                Comparison::Unpaired {
                    p: probability_of_improvement(&va, &vb),
                    ci: probability_of_improvement_independent_ci(&va, &vb, RESAMPLES, 5),
                }
            } else {
                Comparison::Paired(Improvement::of(&pairs, RESAMPLES, 5))
            };
            let (ma, mb) = (mean(&va).unwrap_or(f64::NAN), mean(&vb).unwrap_or(f64::NAN));
            rows.push(vec![
                Cell::text(env.name()),
                Cell::text(method),
                Cell::text(protocol.name()),
                Cell::num(ma),
                Cell::num(mb),
                Cell::num(ma - mb),
                Cell::int(va.len()),
                Cell::int(vb.len()),
                Cell::int(pairs.len()),
            ]);
            let row = rows.last_mut().expect("just pushed");
            let estimate = |v: f64, (lo, hi): (f64, f64)| Cell::Estimate(Some((v, lo, hi)).filter(|_| v.is_finite() && lo.is_finite()), 2);
            match comparison {
                Comparison::Paired(i) => row.extend([
                    estimate(i.unpaired, i.unpaired_ci),
                    Cell::text(format!("{} of {}", i.wins, i.pairs - i.ties)),
                    estimate(i.paired(), i.paired_ci),
                    Cell::opt(Some(i.sign_p), 3),
                    Cell::text(i.warning().unwrap_or_default()),
                ]),
                Comparison::Unpaired { p, ci } => row.extend([
                    estimate(p, ci),
                    Cell::text("-"),
                    Cell::Estimate(None, 2),
                    Cell::opt(None, 3),
                    Cell::text("unpaired: no replicate shares its seeds"),
                ]),
            }
        }
    }
    Table { columns: columns.map(String::from).to_vec(), rows }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exp::{studies, synthetic};

    #[test]
    fn two_studies_differ_in_one_parameter_and_pair_by_seeds() {
        let all = studies(&crate::report::Artifacts::of(synthetic::manifests(2, 3, 4)));
        let p = params(&all[0], &all[1]);
        assert_eq!(p.rows.len(), 1);
        assert_eq!(p.rows[0][0], Cell::text("ppo.ppo.total_steps"));
        assert_eq!(p.rows[0][1], Cell::text("1000000"));
        let m = metrics(&all[0], &all[1], &[Protocol::Final]);
        assert_eq!(m.rows.len(), 3, "bc, drex, multi-bc");
        let drex = m.rows.iter().find(|r| r[1] == Cell::text("drex")).unwrap();
        assert_eq!(drex[8], Cell::int(3), "every replicate shares its seeds");
        assert!(matches!(&drex[10], Cell::Text(t) if t.ends_with(" of 3")), "{drex:?}");
        assert!(matches!(drex[9], Cell::Estimate(Some((p, lo, hi)), _) if lo <= p && p <= hi), "{drex:?}");
        // Study 1 on other seeds: nothing pairs, and the comparison says so.
        let mut other = all[1].clone();
        for reps in other.scores.values_mut() {
            for r in reps.values_mut() {
                r.seeds = r.seeds.iter().map(|s| s + 7).collect();
            }
        }
        let m = metrics(&all[0], &other, &[Protocol::Final]);
        assert!(m.rows.iter().all(|r| r[8] == Cell::int(0) && matches!(&r[13], Cell::Text(t) if t.contains("unpaired"))));
    }
}
