//! `idrex exp show`: one row per study, with the parameters that set it apart and each
//! method's headline.
use super::{Study, changed, utc};
use crate::env::EnvId;
use crate::log::table::{Cell, Table};
use crate::report::Protocol;
use crate::store::TestSetMark;

/// What to list and which columns to keep.
#[derive(Debug, Clone, Default)]
pub struct Selection {
    /// Only studies that ran one of these environments, and only their headlines (all if empty).
    pub envs: Vec<EnvId>,
    /// Only these methods' headlines (all if empty).
    pub methods: Vec<String>,
    /// The protocols whose headlines are shown (the final policy if empty).
    pub protocols: Vec<Protocol>,
    /// Every resolved parameter, not only those that differ between the listed studies.
    pub all_params: bool,
    /// Also drop every other column whose value is the same in every listed row.
    pub only_changed: bool,
    /// Keep only the columns whose names contain one of these (and the study's name).
    pub columns: Vec<String>,
}

fn role(s: &Study) -> &'static str {
    match s.test_set {
        Some(TestSetMark::Test { .. }) => "test set",
        Some(TestSetMark::Reuse { .. }) => "reuses a test set",
        None => "study",
    }
}

fn joined<T: ToString>(items: impl IntoIterator<Item = T>) -> String {
    items.into_iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ")
}

/// The table of `studies` under `sel`.
pub fn table(studies: &[Study], sel: &Selection) -> Table {
    let listed: Vec<&Study> = studies.iter().filter(|s| sel.envs.is_empty() || sel.envs.iter().any(|e| s.envs.contains(e))).collect();
    let params: Vec<String> = if sel.all_params {
        listed.iter().flat_map(|s| s.config.keys().cloned()).collect::<std::collections::BTreeSet<_>>().into_iter().collect()
    } else {
        changed(&listed)
    };
    let protocols = if sel.protocols.is_empty() { vec![Protocol::Final] } else { sel.protocols.clone() };
    // Headline columns: every (env, method) a listed study has, in a fixed order.
    let mut heads: Vec<(EnvId, String)> = listed
        .iter()
        .flat_map(|s| s.scores.keys().cloned())
        .filter(|(e, m)| (sel.envs.is_empty() || sel.envs.contains(e)) && (sel.methods.is_empty() || sel.methods.contains(m)))
        .collect();
    heads.sort();
    heads.dedup();
    let mut columns: Vec<String> = ["study", "role", "replicates", "runs", "envs", "methods"].map(String::from).to_vec();
    // A sweep's variants: what each sets, and what it is compared with.
    let swept = listed.iter().any(|s| s.variant.is_some());
    if swept {
        columns.splice(1..1, ["settings", "baseline"].map(String::from));
    }
    columns.extend(params.iter().cloned());
    for p in &protocols {
        for (e, m) in &heads {
            let suffix = if protocols.len() > 1 { format!(" ({})", p.name()) } else { String::new() };
            columns.push(format!("{} {m}{suffix}", e.name()));
        }
    }
    columns.extend(["idrex", "finished (UTC)"].map(String::from));
    let rows = listed
        .iter()
        .map(|s| {
            let mut row = vec![Cell::text(&s.name)];
            if swept {
                let v = s.variant.as_ref();
                row.push(Cell::text(v.map_or(String::new(), |v| v.settings.join(","))));
                row.push(Cell::text(v.map_or(String::new(), |v| v.baseline.clone())));
            }
            row.extend([
                Cell::text(role(s)),
                Cell::int(s.replicates.len()),
                Cell::int(s.runs),
                Cell::text(joined(s.envs.iter().map(|e| e.name()))),
                Cell::text(joined(&s.methods)),
            ]);
            row.extend(params.iter().map(|k| Cell::text(s.param(k))));
            for &p in &protocols {
                for (e, m) in &heads {
                    row.push(Cell::Estimate(s.headline(*e, m, p).map(|h| (h.mean, h.ci.0, h.ci.1)), 1));
                }
            }
            row.push(Cell::text(joined(&s.versions)));
            row.push(Cell::text(utc(s.ended)));
            row
        })
        .collect();
    let mut t = Table { columns, rows };
    if sel.only_changed && t.rows.len() > 1 {
        let keep: Vec<bool> = (0..t.columns.len()).map(|i| i == 0 || t.rows.iter().any(|r| r[i] != t.rows[0][i])).collect();
        t = t.keep(&keep);
    }
    if !sel.columns.is_empty() {
        let keep: Vec<bool> =
            t.columns.iter().enumerate().map(|(i, c)| i == 0 || sel.columns.iter().any(|p| c.contains(p.as_str()))).collect();
        t = t.keep(&keep);
    }
    t
}

/// What the table leaves out where nothing is compared: with one study listed no parameter
/// differs, so none is shown, and this says how to see them.
pub fn hint(studies: &[Study], sel: &Selection) -> Option<String> {
    let listed = studies.iter().filter(|s| sel.envs.is_empty() || sel.envs.iter().any(|e| s.envs.contains(e))).count();
    (listed == 1 && !sel.all_params).then(|| {
        "one study, nothing to compare: its parameters are left out; `--all-params` lists them, `--columns NAME` picks some".into()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exp::{studies, synthetic};

    #[test]
    fn one_row_per_study_with_what_sets_it_apart() {
        let all = studies(&crate::report::Artifacts::of(synthetic::manifests(3, 2, 1)));
        let t = table(&all, &Selection::default());
        assert_eq!(t.rows.len(), 3);
        assert!(t.columns.contains(&"ppo.ppo.total_steps".to_string()), "{:?}", t.columns);
        assert!(!t.columns.contains(&"ppo.ppo.lr".to_string()), "the same in every study");
        assert!(t.columns.contains(&"Hopper-v5 drex".to_string()));
        let all_params = table(&all, &Selection { all_params: true, ..Selection::default() });
        assert!(all_params.columns.contains(&"ppo.ppo.lr".to_string()));
        let only = table(&all, &Selection { only_changed: true, ..Selection::default() });
        assert!(!only.columns.contains(&"replicates".to_string()) && only.columns.contains(&"Hopper-v5 drex".to_string()));
        let bc = table(&all, &Selection { methods: vec!["bc".into()], columns: vec!["Hopper".into()], ..Selection::default() });
        assert_eq!(bc.columns, ["study", "Hopper-v5 bc"]);
        let none = table(&all, &Selection { envs: vec![EnvId::HalfCheetah], ..Selection::default() });
        assert!(none.rows.is_empty());
        let two = table(&all, &Selection { protocols: vec![Protocol::Final, Protocol::BestByGroundTruth], ..Selection::default() });
        assert!(two.columns.contains(&"Hopper-v5 drex (best-by-ground-truth)".to_string()));
        assert!(hint(&all, &Selection::default()).is_none(), "three studies are compared");
        // One study: the headline columns only, and a hint; --all-params still lists them all.
        let one = table(&all[..1], &Selection::default());
        assert!(one.columns.iter().all(|c| !c.contains('.')), "no parameter column: {:?}", one.columns);
        assert!(one.columns.contains(&"Hopper-v5 drex".to_string()));
        assert!(hint(&all[..1], &Selection::default()).is_some_and(|h| h.contains("--all-params")));
        assert!(hint(&all[..1], &Selection { all_params: true, ..Selection::default() }).is_none());
        assert!(table(&all[..1], &Selection { all_params: true, ..Selection::default() }).columns.contains(&"ppo.ppo.lr".to_string()));
    }
}
