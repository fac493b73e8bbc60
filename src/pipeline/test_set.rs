//! Locked test sets (`role: test`). A study's replicate seeds are a test set only while one
//! configuration has been evaluated on them: every further configuration scored there is a
//! look at the test set that can steer what is tried next. The store's evaluations say which
//! configurations were scored on which seeds ([`Looks`]); before a run, [`check`] refuses to
//! add a configuration to a test set's seeds, or to lock seeds that another configuration
//! used, unless the user asks for it, and then marks what it computes.
use std::collections::{BTreeMap, BTreeSet};

use super::config::Purpose;
use super::graph::Graph;
use super::stage::eval::EvalParams;
use super::stage::{EvalInputs, Inputs, Params};
use super::{Method, Pipeline};
use crate::env::EnvId;
use crate::error::{Error, Result};
use crate::store::{Manifest, TestSetMark};

/// One stored evaluation: where it was scored and what produced its policy.
#[derive(Debug, Clone, PartialEq)]
pub struct Look {
    pub env: EnvId,
    /// The evaluation's seed: the RL run's (BC's: its pipeline's first seed).
    pub seed: u64,
    pub method: Method,
    pub iteration: usize,
    /// The key of the evaluated policy: everything upstream of it, the configuration.
    pub policy: String,
    pub study: String,
    pub mark: Option<TestSetMark>,
}

impl Look {
    /// The evaluation `m`, whose parameters are `p`.
    pub fn of(m: &Manifest, p: &EvalParams) -> Option<Look> {
        Some(Look {
            env: p.env,
            seed: m.seed,
            method: p.method,
            iteration: p.iteration,
            policy: super::role::recorded_input(m, super::role::Role::Policy)?.clone(),
            study: p.pipeline.clone(),
            mark: m.test_set.clone(),
        })
    }
}

/// Every stored evaluation, indexed by where it was scored.
pub struct Looks {
    at: BTreeMap<(EnvId, u64), Vec<Look>>,
}

impl Looks {
    pub fn new(looks: impl IntoIterator<Item = Look>) -> Looks {
        let mut at: BTreeMap<(EnvId, u64), Vec<Look>> = BTreeMap::new();
        for l in looks {
            at.entry((l.env, l.seed)).or_default().push(l);
        }
        Looks { at }
    }

    /// Every (env, study) with a stored evaluation.
    pub fn studies(&self) -> BTreeSet<(EnvId, &str)> {
        self.at.values().flatten().map(|l| (l.env, l.study.as_str())).collect()
    }

    /// How many configurations were evaluated on `study`'s seeds in `env`: per seed and
    /// method (with its iteration), the distinct policies scored there, at most.
    pub fn configurations(&self, env: EnvId, study: &str) -> usize {
        let mine: BTreeSet<(u64, Method, usize)> = self
            .at
            .iter()
            .filter(|((e, _), _)| *e == env)
            .flat_map(|(_, v)| v)
            .filter(|l| l.study == study)
            .map(|l| (l.seed, l.method, l.iteration))
            .collect();
        mine.iter()
            .map(|&(seed, method, iteration)| {
                self.at[&(env, seed)]
                    .iter()
                    .filter(|l| l.method == method && l.iteration == iteration)
                    .map(|l| &l.policy)
                    .collect::<BTreeSet<_>>()
                    .len()
            })
            .max()
            .unwrap_or(0)
    }

    /// Whether `study`'s evaluations in `env` carry a mark: its own test set's, or a reuse.
    pub fn mark(&self, env: EnvId, study: &str) -> Option<&TestSetMark> {
        let marks = self.at.iter().filter(|((e, _), _)| *e == env).flat_map(|(_, v)| v).filter(|l| l.study == study);
        let marks: Vec<&TestSetMark> = marks.filter_map(|l| l.mark.as_ref()).collect();
        marks.iter().find(|m| matches!(m, TestSetMark::Reuse { .. })).or(marks.first()).copied()
    }
}

/// Before `p` runs: refuses (unless `reuse`) to evaluate a configuration on a test set's seeds
/// that the test set did not, or, for a test set, to take seeds another configuration was
/// evaluated on. Returns the mark for the evaluations the run computes.
pub fn check(p: &Pipeline, g: &Graph, looks: &Looks, stored: &dyn Fn(&str) -> bool, reuse: bool) -> Result<Option<TestSetMark>> {
    let keys = g.keys();
    // (env, seed) -> the policies this run evaluates there, and whether it computes any.
    let mut mine: BTreeMap<(EnvId, u64), (BTreeSet<&str>, bool)> = BTreeMap::new();
    // A probe scores a new policy by the true return on its run's seed: any look already
    // there makes it another look.
    let mut probed: BTreeSet<(EnvId, u64)> = BTreeSet::new();
    for n in &g.nodes {
        match (&n.params, &n.inputs) {
            (Params::Eval(e), Inputs::Eval(EvalInputs { policy, .. })) => {
                let at = mine.entry((e.env, n.seed)).or_default();
                at.0.insert(keys[policy].as_str());
                at.1 |= !stored(&keys[&n.name]);
            }
            (Params::Probe(probe), _) if !stored(&keys[&n.name]) => {
                probed.insert((probe.run.env, n.seed));
            }
            _ => {}
        }
    }
    let others: Vec<&Look> = mine
        .iter()
        .filter(|(_, (_, computes))| *computes)
        .flat_map(|(at, (policies, _))| looks.at.get(at).into_iter().flatten().filter(|l| !policies.contains(l.policy.as_str())))
        .chain(probed.iter().flat_map(|at| looks.at.get(at).into_iter().flatten()))
        .collect();
    let locked = others.iter().find_map(|l| match &l.mark {
        Some(TestSetMark::Test { study }) => Some((study.clone(), *l)),
        _ => None,
    });
    let file = p.file.display();
    let hint = "use seeds no one has evaluated on, or pass --reuse-test-set (the report then marks these results as exploratory)";
    match (p.spec.role, locked, others.first()) {
        (Purpose::Test, _, Some(o)) if !reuse => Err(Error::Invalid(format!(
            "{file}: role: test, but seed {} of {} already holds an evaluation of another configuration (study `{}`); a test set \
             must be fresh: {hint}",
            o.seed,
            o.env.name(),
            o.study
        ))),
        (Purpose::Test, _, Some(_)) => Ok(Some(TestSetMark::Reuse { study: p.name.clone() })),
        (Purpose::Test, _, None) => Ok(Some(TestSetMark::Test { study: p.name.clone() })),
        (Purpose::Study, Some((study, l)), _) if !reuse => Err(Error::Invalid(format!(
            "{file}: would evaluate a configuration on seed {} of {}, which belongs to the locked test set `{study}` (a file with \
             role: test): {hint}",
            l.seed,
            l.env.name()
        ))),
        (Purpose::Study, Some((study, _)), _) => Ok(Some(TestSetMark::Reuse { study })),
        (Purpose::Study, None, _) => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::stage::StageKind;

    const BASE: &str = "version: 1\nenv: Hopper-v5\nseeds: [0, 1]\nnoise:\n  schedule: [0.0, 0.5, 1.0]\n";

    /// The evaluations `text` would store, as manifests marked `mark`.
    fn stored_evals(text: &str, mark: Option<TestSetMark>) -> Vec<Manifest> {
        let p = Pipeline::parse(std::path::Path::new("p.yaml"), text).unwrap();
        let g = super::super::expand(&p).unwrap();
        let keys = g.keys();
        g.nodes
            .iter()
            .filter(|n| n.kind() == StageKind::Eval)
            .map(|n| Manifest {
                key: keys[&n.name].clone(),
                kind: StageKind::Eval.name().into(),
                version: 1,
                node: n.name.clone(),
                params: n.params.to_json(),
                seed: n.seed,
                inputs: n.inputs.iter().map(|(r, s)| (r.name(), keys[s].clone())).collect(),
                outputs: vec![],
                metrics: serde_json::json!({}),
                started_unix: 0.0,
                ended_unix: 0.0,
                wall_s: 0.0,
                idrex_version: "test".into(),
                kernel: None,
                test_set: mark.clone(),
            })
            .collect()
    }

    /// The looks of these evaluations' manifests.
    fn looks_of(evals: &[Manifest]) -> Looks {
        let params = |m: &Manifest| match Params::from_json(StageKind::Eval, &m.params).unwrap() {
            Params::Eval(p) => p,
            _ => unreachable!("an evaluation's parameters"),
        };
        Looks::new(evals.iter().map(|m| Look::of(m, &params(m)).unwrap()))
    }

    fn check_text(text: &str, looks: &Looks, stored: &[Manifest], reuse: bool) -> Result<Option<TestSetMark>> {
        let p = Pipeline::parse(std::path::Path::new("p.yaml"), text).unwrap();
        let g = super::super::expand(&p).unwrap();
        let keys: BTreeSet<String> = stored.iter().map(|m| m.key.clone()).collect();
        check(&p, &g, looks, &|k| keys.contains(k), reuse)
    }

    #[test]
    fn a_test_set_is_looked_at_once() {
        let test = format!("{BASE}name: locked\nrole: test\n");
        let other = format!("{BASE}name: other\nreward:\n  ceiling: 0.9\n");
        let elsewhere = other.replace("seeds: [0, 1]", "seeds: [7, 8]");
        // A fresh test set is marked as one.
        let empty = Looks::new([]);
        assert_eq!(check_text(&test, &empty, &[], false).unwrap(), Some(TestSetMark::Test { study: "locked".into() }));
        let evals = stored_evals(&test, Some(TestSetMark::Test { study: "locked".into() }));
        let looks = looks_of(&evals);
        assert_eq!(looks.configurations(EnvId::Hopper, "locked"), 1);
        // Running it again, or raising nothing, is no second look.
        assert!(check_text(&test, &looks, &evals, false).is_ok());
        // Another configuration on its seeds is refused, naming the file, the seed and the way out.
        let e = check_text(&other, &looks, &[], false).unwrap_err().to_string();
        assert!(e.contains("p.yaml") && e.contains("test set `locked`") && e.contains("--reuse-test-set"), "{e}");
        // On other seeds it runs, unmarked; with the flag it runs, marked.
        assert_eq!(check_text(&elsewhere, &looks, &[], false).unwrap(), None);
        assert_eq!(check_text(&other, &looks, &[], true).unwrap(), Some(TestSetMark::Reuse { study: "locked".into() }));
        // The store counts the second configuration once it is there.
        let mut both = evals.clone();
        both.extend(stored_evals(&other, Some(TestSetMark::Reuse { study: "locked".into() })));
        let looks = looks_of(&both);
        assert_eq!((looks.configurations(EnvId::Hopper, "locked"), looks.configurations(EnvId::Hopper, "other")), (2, 2));
        assert!(matches!(looks.mark(EnvId::Hopper, "other"), Some(TestSetMark::Reuse { .. })));
        // A test set cannot take seeds another configuration used first.
        let used = looks_of(&stored_evals(&other, None));
        let e = check_text(&test, &used, &[], false).unwrap_err().to_string();
        assert!(e.contains("role: test") && e.contains("study `other`"), "{e}");
    }

    /// A probe scores a policy by the true return on a run's seed: on a test set already
    /// looked at, it is another look, refused without the flag and marked with it.
    #[test]
    fn a_probe_on_a_test_set_is_a_look() {
        let test = format!("{BASE}name: locked\nrole: test\n");
        let evals = stored_evals(&test, Some(TestSetMark::Test { study: "locked".into() }));
        let looks = looks_of(&evals);
        let probed = format!("{test}bank: {{probe: 8192}}\n");
        let e = check_text(&probed, &looks, &evals, false).unwrap_err().to_string();
        assert!(e.contains("role: test") && e.contains("--reuse-test-set"), "{e}");
        assert_eq!(check_text(&probed, &looks, &evals, true).unwrap(), Some(TestSetMark::Reuse { study: "locked".into() }));
    }

    /// Each variant of a sweep is a configuration: a sweep on a test set's seeds is refused like
    /// any other second configuration, and a test set's file cannot sweep.
    #[test]
    fn a_sweep_on_a_test_sets_seeds_is_refused() {
        let test = format!("{BASE}name: locked\nrole: test\n");
        let looks = looks_of(&stored_evals(&test, Some(TestSetMark::Test { study: "locked".into() })));
        let path = std::path::Path::new("p.yaml");
        let sweep = super::super::Sweep::parse(path, &format!("{BASE}name: tune\n"), &["reward.ceiling=0.5,none".into()]).unwrap();
        let e = check(&sweep.file, &sweep.graph().unwrap(), &looks, &|_| false, false).unwrap_err().to_string();
        assert!(e.contains("test set `locked`") && e.contains("--reuse-test-set"), "{e}");
        let e = super::super::Sweep::parse(path, &test, &["reward.ceiling=0.5,none".into()]).unwrap_err().to_string();
        assert!(e.contains("role: test locks its seeds to one configuration"), "{e}");
    }
}
