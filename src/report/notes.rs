//! What the tables do not show, per environment and pipeline: each learned reward's
//! validation accuracy and what multi-BC's clone filter kept.
use std::collections::BTreeMap;

use super::Artifacts;
use crate::error::Result;
use crate::pipeline::role::{Role, Series};
use crate::pipeline::stage::{Metrics, Typed};

/// Per (env, pipeline), what the tables do not show: each learned reward's validation pair
/// accuracy, and what multi-BC's clone filter kept (when it keeps none, multi-BC's reward is
/// trained on D-REX's rankings alone, and its results equal D-REX's).
pub fn notes(store: &Artifacts) -> Result<String> {
    let mut lines: BTreeMap<(String, String), std::collections::BTreeSet<String>> = BTreeMap::new();
    let mut seen = std::collections::BTreeSet::new();
    for (m, p, _) in store.evaluations() {
        let Some(reward) = super::input_key(m, Role::Reward) else { continue };
        if !seen.insert((p.pipeline.clone(), reward.clone())) {
            continue;
        }
        let Some(rm) = store.get(reward) else { continue };
        let group = lines.entry((p.env.name().to_string(), p.pipeline.clone())).or_default();
        if let Some(Typed { metrics: Metrics::Trex(t), .. }) = store.typed(rm) {
            let label = if p.iteration > 2 { format!("{} (k={})", p.method.label(), p.iteration) } else { p.method.label().to_string() };
            group.insert(format!(
                "{label}: the learned reward ({}) ranks {:.1} % of held-out training pairs correctly; on its training set Pearson {:.2}",
                rm.node,
                t.val_accuracy * 100.0,
                t.train_set.pearson
            ));
        }
        for (_, sm) in store.inputs_in(rm, Series::Set) {
            if let Some(Typed { metrics: Metrics::MultiBcRollouts(x), .. }) = store.typed(sm) {
                let kept = x.kept();
                let measured: Vec<String> = x
                    .clones
                    .iter()
                    .filter(|c| c.fidelity.normalised.is_finite())
                    .map(|c| format!("{:.2}", c.fidelity.normalised))
                    .collect();
                let fidelity = if measured.is_empty() {
                    "was not measured (no clone filter scores them: `idrex.multi_bc_filter: none`)".to_string()
                } else if measured.len() < x.clones.len() {
                    format!(
                        "(true return, random 0, source 1) {} for {} of them; the rest not measured",
                        measured.join(", "),
                        measured.len()
                    )
                } else {
                    format!("(true return, random 0, source 1) {}", measured.join(", "))
                };
                let mut line = format!("{}: the clone filter kept {kept} of {} clones; their fidelity {fidelity}", sm.node, x.clones.len());
                if kept == 0 {
                    line.push_str("; with none kept, this iteration's reward saw no rankings the previous one's had not, so its figures repeat the previous iteration's (D-REX's, at the first)");
                }
                group.insert(line);
            }
        }
    }
    let mut out = String::new();
    if !lines.is_empty() {
        out.push_str("\n## Notes\n");
        for ((env, pipeline), group) in lines {
            out.push_str(&format!("\n### {env} {pipeline}\n\n"));
            for l in group {
                out.push_str(&format!("- {l}\n"));
            }
        }
    }
    Ok(out)
}
