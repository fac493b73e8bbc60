//! Where a pipeline's BC ends far below its demonstrations ([`CloneGap`]), read from the
//! stored manifests of its BC evaluations and the demonstrations they were cloned from: what
//! `pipeline run` and `pipeline plan` say first, before anything downstream is trusted.
use std::collections::BTreeMap;

use super::stage::{Inputs, Metrics, Params, Typed};
use super::{Graph, Method};
use crate::algo::scoring::CloneGap;
use crate::store::Manifest;

/// (BC evaluation node, gap) for every stored BC evaluation of `g` below `fraction`.
pub fn clone_gaps(g: &Graph, manifests: &[Manifest], fraction: f64) -> Vec<(String, CloneGap)> {
    let keys = g.keys();
    let by_key: BTreeMap<&str, &Manifest> = manifests.iter().map(|m| (m.key.as_str(), m)).collect();
    // The mean return of a node's stored evaluation or demonstrations, read typed.
    let mean = |node: &str| match Typed::of(by_key.get(keys.get(node)?.as_str())?).ok()?.metrics {
        Metrics::Eval(e) => Some(e.summary.stats.mean),
        Metrics::Demos(d) | Metrics::DemosImport(d) => Some(d.stats.mean),
        _ => None,
    };
    // A BC policy a sweep's variants share is evaluated in each: one warning for it.
    let mut policies = std::collections::BTreeSet::new();
    g.nodes
        .iter()
        .filter_map(|n| match (&n.params, &n.inputs) {
            (Params::Eval(e), Inputs::Eval(i)) if e.method == Method::Bc && policies.insert(keys.get(&i.policy)?) => {
                CloneGap::check(mean(&n.name)?, mean(&i.demos)?, fraction).map(|gap| (n.name.clone(), gap))
            }
            _ => None,
        })
        .collect()
}

/// One line per gap, naming the BC node.
pub fn lines(gaps: &[(String, CloneGap)]) -> Vec<String> {
    gaps.iter().map(|(node, gap)| format!("warning: {}: {}", node.trim_end_matches("/eval"), gap.sentence())).collect()
}

/// Prints [`lines`] of `g`'s gaps on stdout (what `pipeline run` and `plan` say).
pub fn print(g: &Graph, manifests: &[Manifest], fraction: f64) {
    for line in lines(&clone_gaps(g, manifests, fraction)) {
        println!("{line}");
    }
}
