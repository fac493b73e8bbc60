//! The tracker: every study in a store at a glance (`idrex exp show`) and two studies side by
//! side (`idrex exp diff`). A study is what the report calls one: the evaluations that share
//! a pipeline `name`, over all its files and replicates. Its configuration is read from the
//! manifests of everything its evaluations depend on (the fully resolved parameters, defaults
//! included, as the stages recorded them), so it needs no pipeline file.
//!
//! Manifests are read without re-hashing outputs: this is an overview; `idrex verify` is what
//! checks bytes, and `idrex report` re-hashes before it builds tables.
use std::collections::{BTreeMap, BTreeSet};

pub mod diff;
pub mod show;
pub mod synthetic;

use crate::algo::scoring::{CheckpointEval, select};
use crate::env::EnvId;
use crate::pipeline::stage::StageKind;
use crate::report::{Artifacts, Protocol, method_label};
use crate::stats::{ReturnStats, bootstrap_ci, hierarchical_ci, mean};
use crate::store::TestSetMark;

/// Resamples behind each headline interval (the report's own count).
pub const RESAMPLES: usize = 10_000;

/// One evaluated run: its final policy's returns and its checkpoints.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    pub run: usize,
    pub final_returns: Vec<f64>,
    pub checkpoints: Vec<CheckpointEval>,
}

/// One replicate of one (env, method) in a study.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Replicate {
    /// The evaluations' seeds: two studies' replicates that share them share their randomness.
    pub seeds: BTreeSet<u64>,
    /// In run order.
    pub runs: Vec<Run>,
}

impl Replicate {
    /// Each run's mean return at the policy `protocol` picks (the report's choice, pooled over
    /// this replicate's runs); None where the protocol cannot choose (checkpoints without
    /// learned scores, for the ground-truth-free one).
    pub fn run_means(&self, protocol: Protocol) -> Option<Vec<f64>> {
        let chosen = select(&self.runs.iter().map(|r| r.checkpoints.as_slice()).collect::<Vec<_>>());
        let step = match (protocol, chosen.by_ground_truth, chosen.without_ground_truth) {
            (Protocol::Final, ..) | (_, None, None) => None,
            (Protocol::BestByGroundTruth, best, _) => best,
            (Protocol::GroundTruthFree, _, Some(free)) => Some(free),
            (Protocol::GroundTruthFree, Some(_), None) => return None,
        };
        self.runs
            .iter()
            .map(|r| match step {
                None => Some(ReturnStats::of(&r.final_returns).mean),
                Some(s) => r.checkpoints.iter().find(|c| c.step == s).map(|c| ReturnStats::of(&c.returns).mean),
            })
            .collect()
    }

    /// The mean of its runs' means under `protocol`.
    pub fn score(&self, protocol: Protocol) -> Option<f64> {
        self.run_means(protocol).and_then(|v| mean(&v))
    }
}

/// One study: its shape, its resolved configuration, and its final-policy scores.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Study {
    pub name: String,
    pub envs: BTreeSet<EnvId>,
    pub methods: BTreeSet<String>,
    pub replicates: BTreeSet<usize>,
    /// Evaluated runs (one per evaluation artifact).
    pub runs: usize,
    /// Every parameter of every stage it depends on, as `kind.field` -> the values recorded.
    pub config: BTreeMap<String, BTreeSet<String>>,
    /// The idrex versions that wrote its artifacts.
    pub versions: BTreeSet<String>,
    /// When its last artifact was finished (unix seconds).
    pub ended: f64,
    /// Whether it is, or reuses, a locked test set.
    pub test_set: Option<TestSetMark>,
    /// Its place in a sweep, where it is a variant.
    pub variant: Option<crate::pipeline::stage::eval::VariantTag>,
    /// (env, method label) -> replicate -> its runs.
    pub scores: BTreeMap<(EnvId, String), BTreeMap<usize, Replicate>>,
}

/// The final-policy headline of one (env, method): the mean over replicates (over runs when
/// there is one replicate), with its 95 % bootstrap interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Headline {
    pub mean: f64,
    pub ci: (f64, f64),
    pub replicates: usize,
}

impl Study {
    pub fn headline(&self, env: EnvId, method: &str, protocol: Protocol) -> Option<Headline> {
        let reps = self.scores.get(&(env, method.to_string()))?;
        let groups: Vec<Vec<f64>> = reps.values().map(|r| r.run_means(protocol)).collect::<Option<_>>()?;
        let of = |v: &[f64]| mean(v).unwrap_or(f64::NAN);
        let (mean, ci) = if groups.len() > 1 {
            let scores: Vec<f64> = groups.iter().map(|g| of(g)).collect();
            (of(&scores), hierarchical_ci(&groups, of, RESAMPLES, 0))
        } else {
            (of(&groups[0]), bootstrap_ci(&groups[0], RESAMPLES, 0))
        };
        Some(Headline { mean, ci, replicates: groups.len() })
    }

    /// The resolved value of one parameter: its recorded values joined.
    pub fn param(&self, key: &str) -> String {
        self.config.get(key).map_or("-".to_string(), |v| v.iter().cloned().collect::<Vec<_>>().join(" | "))
    }
}

/// Fields that say where a node sits, not how it is configured: the study's name, its
/// replicate and run, the method and iteration (columns of their own), the environment.
fn structural(kind: &str, field: &str) -> bool {
    matches!(field, "env")
        || (kind == StageKind::Eval.name() && matches!(field, "pipeline" | "replicate" | "run" | "method" | "iteration" | "variant"))
}

/// `params` flattened into `prefix.field.subfield` -> value; a list is one value.
fn flatten(prefix: &str, v: &serde_json::Value, out: &mut Vec<(String, String)>) {
    match v {
        serde_json::Value::Object(map) => {
            for (k, x) in map {
                flatten(&format!("{prefix}.{k}"), x, out);
            }
        }
        serde_json::Value::String(s) => out.push((prefix.to_string(), s.clone())),
        other => out.push((prefix.to_string(), other.to_string())),
    }
}

/// Every study in `arts` (a store's manifests, read as written), by name.
pub fn studies(arts: &Artifacts) -> Vec<Study> {
    let mut out: BTreeMap<String, Study> = BTreeMap::new();
    let mut upstream: BTreeMap<String, BTreeSet<&str>> = BTreeMap::new();
    for (m, p, x) in arts.evaluations() {
        let s = out.entry(p.pipeline.clone()).or_insert_with(|| Study { name: p.pipeline.clone(), ..Study::default() });
        let label = method_label(p.method, p.iteration);
        s.envs.insert(p.env);
        s.methods.insert(label.clone());
        s.replicates.insert(p.replicate);
        s.runs += 1;
        if m.test_set.is_some() {
            s.test_set = m.test_set.clone();
        }
        if p.variant.is_some() {
            s.variant = p.variant.clone();
        }
        let rep = s.scores.entry((p.env, label)).or_default().entry(p.replicate).or_default();
        rep.seeds.insert(m.seed);
        rep.runs.push(Run { run: p.run, final_returns: x.summary.returns.clone(), checkpoints: x.checkpoints.clone() });
        // Everything upstream of this evaluation belongs to the study's configuration.
        let seen = upstream.entry(p.pipeline.clone()).or_default();
        let mut stack = vec![m.key.as_str()];
        while let Some(k) = stack.pop() {
            if !seen.insert(k) {
                continue;
            }
            if let Some(up) = arts.get(k) {
                stack.extend(up.inputs.values().map(String::as_str));
            }
        }
    }
    for (name, keys) in upstream {
        let s = out.get_mut(&name).expect("a study per evaluation");
        for m in keys.iter().filter_map(|k| arts.get(k)) {
            s.versions.insert(m.idrex_version.clone());
            s.ended = s.ended.max(m.ended_unix);
            s.config.entry(format!("{}.version", m.kind)).or_default().insert(m.version.to_string());
            let mut flat = Vec::new();
            flatten(&m.kind, &m.params, &mut flat);
            for (k, v) in flat {
                let field = k.split('.').nth(1).unwrap_or_default();
                if !structural(&m.kind, field) {
                    s.config.entry(k).or_default().insert(v);
                }
            }
        }
    }
    for s in out.values_mut() {
        for reps in s.scores.values_mut() {
            for r in reps.values_mut() {
                // Runs in a fixed order whatever order the store listed them in.
                r.runs.sort_by_key(|r| r.run);
            }
        }
    }
    out.into_values().collect()
}

/// The parameters whose values differ between `studies` (all of them with one study).
pub fn changed(studies: &[&Study]) -> Vec<String> {
    let keys: BTreeSet<&String> = studies.iter().flat_map(|s| s.config.keys()).collect();
    keys.into_iter().filter(|k| studies.iter().map(|s| s.config.get(*k)).collect::<BTreeSet<_>>().len() > 1).cloned().collect()
}

/// `unix` seconds as `YYYY-MM-DD HH:MM` UTC.
pub fn utc(unix: f64) -> String {
    let secs = unix.max(0.0) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02} {:02}:{:02}", rem / 3600, rem % 3600 / 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_utc_calendar_dates() {
        assert_eq!(utc(0.0), "1970-01-01 00:00");
        assert_eq!(utc(951_782_400.0), "2000-02-29 00:00");
        assert_eq!(utc(1_796_303_460.0), "2026-12-03 13:11");
    }

    #[test]
    fn a_study_is_its_evaluations_and_everything_upstream() {
        let manifests = synthetic::manifests(2, 3, 7);
        let all = studies(&Artifacts::of(manifests));
        assert_eq!(all.len(), 2);
        let s = &all[0];
        assert_eq!((s.replicates.len(), s.runs), (3, 3 * (1 + 2 * 2)));
        assert_eq!(s.methods, ["bc", "drex", "idrex-multi-bc"].map(String::from).into());
        // Upstream parameters are in, the evaluation's place in the study is not.
        assert!(s.config.contains_key("ppo.ppo.total_steps") && s.config.contains_key("eval.episodes"), "{:?}", s.config.keys());
        assert!(!s.config.contains_key("eval.pipeline") && !s.config.contains_key("eval.run") && !s.config.contains_key("ppo.env"));
        assert_eq!(changed(&all.iter().collect::<Vec<_>>()), vec!["ppo.ppo.total_steps".to_string()]);
        let h = s.headline(EnvId::Hopper, "drex", Protocol::Final).unwrap();
        assert_eq!(h.replicates, 3);
        assert!(h.ci.0 <= h.mean && h.mean <= h.ci.1, "{h:?}");
    }
}
