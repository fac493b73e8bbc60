//! How often each study's seeds were looked at: per environment and study, how many
//! configurations the store evaluated on the same seeds, and whether the study is a locked
//! test set or reused one ([`crate::pipeline::test_set`]).
use std::collections::BTreeSet;

use polars::prelude::*;

use super::{Artifacts, pe};
use crate::error::Result;
use crate::pipeline::test_set::{Look, Looks};
use crate::store::{Manifest, TestSetMark};

/// One (env, study).
#[derive(Debug, Clone, PartialEq)]
pub struct LookRow {
    pub env: String,
    pub study: String,
    /// Distinct configurations evaluated on its seeds (1: only its own).
    pub configurations: usize,
    pub mark: Option<TestSetMark>,
}

impl LookRow {
    /// What the reader should make of the study's results.
    pub fn verdict(&self) -> String {
        match (&self.mark, self.configurations) {
            (Some(TestSetMark::Reuse { study }), _) => {
                format!("⚠ exploratory: evaluated with --reuse-test-set on the seeds of `{study}`")
            }
            (Some(TestSetMark::Test { .. }), 1) => "locked test set, looked at once".into(),
            (Some(TestSetMark::Test { .. }), n) => format!("⚠ locked test set, but {n} configurations scored on its seeds"),
            (None, 1) => "its seeds scored one configuration".into(),
            (None, n) => format!("⚠ {n} configurations scored on these seeds: a choice made from them makes its figures optimistic"),
        }
    }
}

pub fn rows(store: &Artifacts) -> Vec<LookRow> {
    let manifests: Vec<Manifest> = store.iter().cloned().collect();
    let looks = Looks::new(&manifests);
    let studies: BTreeSet<(String, crate::env::EnvId, String)> =
        manifests.iter().filter_map(Look::of).map(|l| (l.env.name().to_string(), l.env, l.study)).collect();
    studies
        .into_iter()
        .map(|(name, env, study)| LookRow {
            configurations: looks.configurations(env, &study),
            mark: looks.mark(env, &study).cloned(),
            env: name,
            study,
        })
        .collect()
}

pub fn markdown(rows: &[LookRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\n## How often these seeds were looked at\n\nPer study, the configurations the store evaluated on its seeds (per seed and \
         method, the distinct policies scored). A result is a clean test only where that is 1 and no choice was made from it.\n\n\
         | env | study | configurations on its seeds | what it means |\n|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!("| {} | {} | {} | {} |\n", r.env, r.study, r.configurations, r.verdict()));
    }
    out
}

/// `looks.csv`.
pub fn frame(rows: &[LookRow]) -> Result<DataFrame> {
    let s = |f: &dyn Fn(&LookRow) -> String| -> Vec<String> { rows.iter().map(f).collect() };
    DataFrame::new_infer_height(vec![
        Column::new("env".into(), s(&|r| r.env.clone())),
        Column::new("study".into(), s(&|r| r.study.clone())),
        Column::new("configurations".into(), rows.iter().map(|r| r.configurations as u64).collect::<Vec<_>>()),
        Column::new(
            "role".into(),
            s(&|r| match &r.mark {
                Some(TestSetMark::Test { .. }) => "test".into(),
                Some(TestSetMark::Reuse { .. }) => "reuses-test-set".into(),
                None => "study".into(),
            }),
        ),
        Column::new("verdict".into(), s(&|r| r.verdict())),
    ])
    .map_err(pe)
}
