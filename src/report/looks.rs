//! How often each study's seeds were looked at: per environment and study, how many
//! configurations the store evaluated on the same seeds, and whether the study is a locked
//! test set or reused one ([`crate::pipeline::test_set`]).
use super::Artifacts;
use crate::log::table::{Cell, Row, Table};
use crate::store::TestSetMark;

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
    let looks = store.looks();
    let mut rows: Vec<LookRow> = looks
        .studies()
        .into_iter()
        .map(|(env, study)| LookRow {
            env: env.name().to_string(),
            study: study.to_string(),
            configurations: looks.configurations(env, study),
            mark: looks.mark(env, study).cloned(),
        })
        .collect();
    // By the environment's name, as the tables are.
    rows.sort_by(|a, b| (&a.env, &a.study).cmp(&(&b.env, &b.study)));
    rows
}

pub fn markdown(rows: &[LookRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\n## How often these seeds were looked at\n\nPer study, the configurations the store evaluated on its seeds (per seed and \
         method, the distinct policies scored). A result is a clean test only where that is 1 and no choice was made from it.\n\n",
    );
    let columns = ["env", "study", "configurations on its seeds", "what it means"].map(String::from).to_vec();
    let rows = rows.iter().map(|r| vec![Cell::text(&r.env), Cell::text(&r.study), Cell::int(r.configurations), Cell::text(r.verdict())]);
    out.push_str(&Table { columns, rows: rows.collect() }.markdown());
    out
}

/// `looks.csv`.
impl Row for LookRow {
    fn header() -> Vec<&'static str> {
        vec!["env", "study", "configurations", "role", "verdict"]
    }

    fn cells(&self) -> Vec<Cell> {
        let role = match &self.mark {
            Some(TestSetMark::Test { .. }) => "test",
            Some(TestSetMark::Reuse { .. }) => "reuses-test-set",
            None => "study",
        };
        vec![Cell::text(&self.env), Cell::text(&self.study), Cell::int(self.configurations), Cell::text(role), Cell::text(self.verdict())]
    }
}
