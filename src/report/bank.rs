//! The reward bench in the report: every learned reward PPO trained on, scored on its task's
//! bank of gaits before PPO ran ([`crate::algo::bank`]), per (env, table, method), beside
//! what PPO then made of it.
use std::collections::BTreeMap;

use super::{Artifacts, input_key, method_label};
use crate::algo::bank::{BankScore, GaitClass};
use crate::algo::ppo::PpoConfig;
use crate::log::table::{Cell, Row, Table};
use crate::pipeline::role::Role;
use crate::pipeline::stage::{Metrics, Params, StageKind, Typed};
use crate::store::Manifest;

/// Each scored reward (its T-REX artifact's key) and its scores.
pub fn scores(arts: &Artifacts) -> BTreeMap<String, BankScore> {
    arts.iter()
        .filter(|m| m.kind == StageKind::BankScore.name())
        .filter_map(|m| match arts.typed(m)? {
            Typed { metrics: Metrics::BankScore(s), .. } => Some((input_key(m, Role::Reward)?.clone(), s.clone())),
            _ => None,
        })
        .collect()
}

/// A probe's scores ([`crate::pipeline::stage::probe::ProbeMetrics`]): the true return per
/// episode of its last quarter, and its final policy's forward term per episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeScore {
    pub true_return: f64,
    pub forward: f64,
}

/// A row's identity: (env, table, method).
type RowId = (String, String, String);

/// The probe of the PPO run `ppo` ([`crate::pipeline::stage::probe`]): the one on its reward,
/// seed and inputs whose run is `ppo`'s but for its steps. Its true return and its final
/// policy's forward term per episode; the longest where several lengths were probed.
pub fn probe_of(arts: &Artifacts, ppo: &Manifest) -> Option<ProbeScore> {
    let Some(Typed { params: Params::Ppo(run), .. }) = arts.typed(ppo) else { return None };
    let reward = input_key(ppo, Role::Reward)?;
    arts.iter()
        .filter(|m| m.kind == StageKind::Probe.name() && m.seed == ppo.seed && input_key(m, Role::Reward) == Some(reward))
        .filter(|m| input_key(m, Role::Floor) == input_key(ppo, Role::Floor))
        .filter_map(|m| match arts.typed(m)? {
            Typed { params: Params::Probe(p), metrics: Metrics::Probe(x) } => {
                let ppo = PpoConfig { total_steps: run.ppo.total_steps, checkpoint_every: run.ppo.checkpoint_every, ..p.run.ppo.clone() };
                let same = ppo == run.ppo && (p.run.env, p.run.reward, p.run.device) == (run.env, run.reward, run.device);
                same.then_some((p.run.ppo.total_steps, ProbeScore { true_return: x.true_return, forward: x.final_forward }))
            }
            _ => None,
        })
        .max_by_key(|(steps, _)| *steps)
        .map(|(_, score)| score)
}

/// `bank.csv`: one row per (env, table, method) whose reward was scored; several rewards (an
/// iterated method's) are averaged.
#[derive(Debug, Clone, PartialEq)]
pub struct BankRow {
    pub env: String,
    pub pipeline: String,
    pub method: String,
    pub rewards: usize,
    pub trajectories: usize,
    pub pearson: f64,
    pub spearman: f64,
    pub forward_pearson: f64,
    pub forward_spearman: f64,
    /// Per class of [`GaitClass::ALL`] past forward: trajectories paid more than a truly
    /// better forward gait (summed over the rewards).
    pub overpaid: [usize; 3],
    pub misordered: f64,
    /// Learned reward per step on each class of [`GaitClass::ALL`] (NaN where absent).
    pub pay: [f64; 4],
    /// The probes' true return per episode (`bank.probe`; NaN where none ran), and their final
    /// policies' forward term per episode.
    pub probe: f64,
    pub probe_forward: f64,
}

impl BankRow {
    pub fn pays_a_wrong_gait(&self) -> bool {
        self.overpaid.iter().any(|&n| n > 0)
    }
}

pub fn rows(arts: &Artifacts) -> Vec<BankRow> {
    let scored = scores(arts);
    // Each row's rewards: their scores, and their probes where one ran beside an evaluated run.
    let mut groups: BTreeMap<RowId, BTreeMap<String, (&BankScore, Option<ProbeScore>)>> = BTreeMap::new();
    for (m, p, _) in arts.evaluations() {
        let Some(k) = input_key(m, Role::Reward) else { continue };
        let Some(s) = scored.get(k) else { continue };
        let id = (p.env.name().to_string(), p.table(), method_label(p.method, p.iteration));
        let probe = arts.input(m, Role::Policy).and_then(|ppo| probe_of(arts, ppo));
        let entry = groups.entry(id).or_default().entry(k.clone()).or_insert((s, None));
        entry.1 = entry.1.or(probe);
    }
    groups
        .into_iter()
        .map(|((env, pipeline, method), by_reward)| {
            // A mean over only some of the rewards would pass for all of them.
            let probes: Vec<ProbeScore> = by_reward.values().map(|v| v.1).collect::<Option<_>>().unwrap_or_default();
            let mean = |f: fn(&ProbeScore) -> f64| {
                if probes.is_empty() { f64::NAN } else { probes.iter().map(f).sum::<f64>() / probes.len() as f64 }
            };
            BankRow {
                probe: mean(|p| p.true_return),
                probe_forward: mean(|p| p.forward),
                ..row(env, pipeline, method, by_reward.values().map(|v| v.0).collect())
            }
        })
        .collect()
}

fn row(env: String, pipeline: String, method: String, s: Vec<&BankScore>) -> BankRow {
    let mean = |f: &dyn Fn(&BankScore) -> f64| s.iter().map(|x| f(x)).sum::<f64>() / s.len() as f64;
    let pay = |class: GaitClass| {
        let v: Vec<f64> = s.iter().filter_map(|x| x.per_class.iter().find(|c| c.class == class)).map(|c| c.learned_per_step).collect();
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    };
    let overpaid = |class: GaitClass| s.iter().map(|x| x.overpaid_of(class)).sum();
    BankRow {
        env,
        pipeline,
        method,
        rewards: s.len(),
        trajectories: s.first().map_or(0, |x| x.trajectories),
        pearson: mean(&|x| x.pearson),
        spearman: mean(&|x| x.spearman),
        forward_pearson: mean(&|x| x.forward_pearson),
        forward_spearman: mean(&|x| x.forward_spearman),
        overpaid: [overpaid(GaitClass::Backward), overpaid(GaitClass::Still), overpaid(GaitClass::Random)],
        misordered: mean(&|x| x.misordered),
        pay: GaitClass::ALL.map(pay),
        probe: f64::NAN,
        probe_forward: f64::NAN,
    }
}

impl Row for BankRow {
    fn header() -> Vec<&'static str> {
        vec![
            "env",
            "pipeline",
            "method",
            "rewards",
            "trajectories",
            "pearson",
            "spearman",
            "forward_pearson",
            "forward_spearman",
            "overpaid_backward",
            "overpaid_still",
            "overpaid_random",
            "misordered",
            "pay_forward",
            "pay_backward",
            "pay_still",
            "pay_random",
            "probe_return",
            "probe_forward",
        ]
    }
    fn cells(&self) -> Vec<Cell> {
        let x = |v: f64| Cell::opt(Some(v).filter(|v| v.is_finite()), 3);
        let mut out = vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.method),
            Cell::int(self.rewards),
            Cell::int(self.trajectories),
            x(self.pearson),
            x(self.spearman),
            x(self.forward_pearson),
            x(self.forward_spearman),
        ];
        out.extend(self.overpaid.iter().map(|&n| Cell::int(n)));
        out.push(x(self.misordered));
        out.extend(self.pay.iter().map(|&v| x(v)));
        out.extend([self.probe, self.probe_forward].map(|v| Cell::opt(Some(v).filter(|v| v.is_finite()), 1)));
        out
    }
}

/// The report's section.
pub fn markdown(rows: &[BankRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(concat!(
        "\n## The reward bench: each learned reward on its task's bank of gaits, before PPO\n\n",
        "The bank (`bank:` in the pipeline file) holds PPO checkpoints on the true reward (forward gaits, slow to fast) ",
        "and on it with the forward term negated (backward gaits), each as it acts, jerky (epsilon-greedy) and smooth ",
        "(Ornstein-Uhlenbeck), beside the zero action (still) and uniform random actions; no ranked set holds any of them. ",
        "Pearson and Spearman: learned against true return over the bank, and within the forward gaits (does it order ",
        "speed?). Overpaid: backward, still and random trajectories the reward pays more than a forward gait the true ",
        "return ranks above them; misordered: the share of such pairs it orders the wrong way. Pay: the learned reward ",
        "per step on each class. Probe (with `bank.probe`): the true return per episode of a short PPO run on the ",
        "reward as the method's runs compose it, over its last quarter: the gait PPO finds on the learned reward; probe ",
        "forward: its final policy's forward term per episode (moving, not only living).\n\n",
    ));
    let mut table = Table::of(rows);
    table.columns = [
        "env",
        "pipeline",
        "method",
        "rewards",
        "trajectories",
        "Pearson",
        "Spearman",
        "forward Pearson",
        "forward Spearman",
        "overpaid backward",
        "overpaid still",
        "overpaid random",
        "misordered",
        "pay forward",
        "pay backward",
        "pay still",
        "pay random",
        "probe",
        "probe forward",
    ]
    .map(String::from)
    .to_vec();
    out.push_str(&table.markdown());
    out
}
