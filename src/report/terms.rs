//! Does the learned reward pay for the task, or for staying alive? Read from the stored
//! rollouts: each method's final-policy evaluation episodes split into the task's reward terms
//! (forward, control, healthy, contact) with their length; the learned reward's mean per step
//! on those episodes against its mean on D-REX's ranked set's best and worst levels; and the
//! reward's correlation with the true return computed SSRR's way ([`ssrr_pearson`]).
use std::collections::BTreeMap;

use super::{Artifacts, method_label};
use crate::data::Trajectory;
use crate::env::EnvId;
use crate::log::table::{Cell, Row};
use crate::nn::RewardEnsemble;
use crate::pipeline::role::{Role, Series};
use crate::pipeline::stage::{EpisodeTerms, Metrics, REWARD, RolloutSummary, Typed, read_rollouts};
use crate::stats::pearson;
use crate::store::{Manifest, Store};

/// How a method's policies earn their return.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EarnedBy {
    Moving,
    /// On a task that ends: the episodes last at least [`LIVING_LENGTH`] of the time limit
    /// and forward progress earns less than [`LIVING_FORWARD`] of the healthy reward.
    Living,
}

impl EarnedBy {
    /// From the episodes' mean length and mean forward and healthy reward per episode.
    pub fn of(env: EnvId, length: f64, forward: f64, survive: f64) -> EarnedBy {
        let spec = env.spec();
        let living = spec.health.is_some() && length >= LIVING_LENGTH * spec.max_episode_steps as f64 && forward < LIVING_FORWARD * survive;
        if living { EarnedBy::Living } else { EarnedBy::Moving }
    }

    pub fn name(self) -> &'static str {
        match self {
            EarnedBy::Moving => "moving",
            EarnedBy::Living => "living",
        }
    }
}

/// The fraction of the time limit a "living" policy's episodes last on average.
pub const LIVING_LENGTH: f64 = 0.5;
/// Below this share of the healthy reward, the forward reward is no progress to speak of
/// (Ant walking at 0.25 m/s earns a quarter of its healthy reward forward).
pub const LIVING_FORWARD: f64 = 0.25;

/// `terms.csv`: one row per (env, table, method), over every run's final-policy episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct TermRow {
    pub env: String,
    pub pipeline: String,
    pub method: String,
    pub episodes: usize,
    /// Mean episode length, steps.
    pub length: f64,
    /// Mean per episode of the return and of each term.
    pub ret: f64,
    pub forward: f64,
    pub ctrl: f64,
    pub survive: f64,
    pub contact: f64,
    /// The learned reward (ensemble mean of the raw outputs) per step on these episodes, and
    /// on D-REX's ranked set's least and most noisy levels; None for BC.
    pub learned_per_step: Option<f64>,
    pub ranked_best_per_step: Option<f64>,
    pub ranked_worst_per_step: Option<f64>,
    pub earned_by: EarnedBy,
}

/// Sums over one group's episodes.
#[derive(Default)]
struct Sums {
    episodes: usize,
    steps: usize,
    terms: [f64; 5],
    learned: Option<(f64, usize)>,
    ranked: Option<(f64, f64)>,
}

/// The learned reward's ensemble mean per step of `t`, summed.
fn learned_sum(model: &RewardEnsemble, t: &Trajectory) -> f64 {
    let raw = model.raw(t.next_obs(), &t.actions);
    raw.iter().flat_map(|m| m.iter()).map(|&x| x as f64).sum::<f64>() / raw.len() as f64
}

/// The learned reward per step on the ranked set's least and most noisy levels.
fn ranked_levels(model: &RewardEnsemble, set: &[Trajectory]) -> (f64, f64) {
    let noise = |f: fn(f64, f64) -> f64, start| set.iter().map(|t| t.meta.noise).fold(start, f);
    let (best, worst) = (noise(f64::min, f64::INFINITY), noise(f64::max, f64::NEG_INFINITY));
    let per_step = |level: f64| {
        let at: Vec<&Trajectory> = set.iter().filter(|t| t.meta.noise == level && !t.is_empty()).collect();
        at.iter().map(|t| learned_sum(model, t)).sum::<f64>() / at.iter().map(|t| t.len()).sum::<usize>().max(1) as f64
    };
    (per_step(best), per_step(worst))
}

/// One row per (env, table, method): from the evaluations' metrics, or, for evaluations
/// recorded before their metrics carried the terms, from their rollout files where `store`
/// has them (an artifact that cannot be read is left out with a warning).
pub fn rows(arts: &Artifacts, store: Option<&Store>) -> Vec<TermRow> {
    let mut ranked: BTreeMap<String, Option<(f64, f64)>> = BTreeMap::new();
    let mut groups: BTreeMap<(EnvId, String, String), Sums> = BTreeMap::new();
    let mut demos_seen = std::collections::BTreeSet::new();
    for (m, p, x) in arts.evaluations() {
        // The demonstrations the table compares with, once per table: idrex's own only (an
        // imported file's terms are not known).
        if let Some(dk) = super::input_key(m, Role::Demos)
            && demos_seen.insert((p.table(), dk.clone()))
            && let Some(dm) = arts.get(dk)
            && let Some(Typed { metrics: Metrics::Demos(d), .. }) = arts.typed(dm)
            && let Some(terms) = terms_of(d, dm, arts, store)
        {
            add(groups.entry((p.env, p.table(), DEMOS.to_string())).or_default(), d, &terms);
        }
        let Some(terms) = terms_of(&x.summary, m, arts, store) else { continue };
        let sums = groups.entry((p.env, p.table(), method_label(p.method, p.iteration))).or_default();
        add(sums, &x.summary, &terms);
        if let (Some(acc), Some(k)) = (&x.reward, reward_of(m)) {
            let (s, n) = sums.learned.get_or_insert((0.0, 0));
            *s += sum(&acc.predicted_returns);
            *n += x.summary.lengths.iter().sum::<usize>();
            let levels = ranked.entry(k.clone()).or_insert_with(|| ranked_of(arts, store, k));
            sums.ranked = sums.ranked.or(*levels);
        }
    }
    groups.into_iter().filter(|(_, s)| s.episodes > 0).map(|((env, pipeline, method), s)| row(env, pipeline, method, &s)).collect()
}

/// The label of the demonstrations' rows.
pub const DEMOS: &str = "demonstrations";

fn sum(v: &[f64]) -> f64 {
    v.iter().sum()
}

fn add(sums: &mut Sums, s: &RolloutSummary, terms: &EpisodeTerms) {
    sums.episodes += s.returns.len();
    sums.steps += s.lengths.iter().sum::<usize>();
    let add = [sum(&s.returns), sum(&terms.forward), sum(&terms.ctrl), sum(&terms.survive), sum(&terms.contact)];
    sums.terms.iter_mut().zip(add).for_each(|(a, b)| *a += b);
}

/// A stage's episodes' terms: from its metrics, or from its rollout file where `store` has it.
fn terms_of(s: &RolloutSummary, m: &Manifest, arts: &Artifacts, store: Option<&Store>) -> Option<EpisodeTerms> {
    if let Some(t) = &s.terms {
        return Some(t.clone());
    }
    let store = store.filter(|_| !arts.is_archived(&m.key))?;
    match store.input_dir(&m.key).and_then(|d| read_rollouts(&d)) {
        Ok(trajs) => Some(EpisodeTerms::of(&trajs)),
        Err(e) => {
            tracing::warn!("terms: skipping {}: {e}", &m.key[..12]);
            None
        }
    }
}

/// The reward per step on D-REX's ranked set's least and most noisy levels: from the T-REX
/// stage's metrics, or (before they recorded lengths) its model and ranked set's files.
fn ranked_of(arts: &Artifacts, store: Option<&Store>, key: &str) -> Option<(f64, f64)> {
    let m = arts.get(key)?;
    let Some(Typed { metrics: Metrics::Trex(x), .. }) = arts.typed(m) else { return None };
    let t = &x.train_set;
    if t.lengths.len() == t.noise.len() {
        let at = |noise: f64| {
            let steps = |i: &usize| t.level[*i] == 0 && t.noise[*i] == noise;
            let idx: Vec<usize> = (0..t.noise.len()).filter(steps).collect();
            idx.iter().map(|&i| t.scored.predicted[i]).sum::<f64>() / idx.iter().map(|&i| t.lengths[i]).sum::<usize>().max(1) as f64
        };
        let level0 = (0..t.noise.len()).filter(|&i| t.level[i] == 0).map(|i| t.noise[i]);
        let (lo, hi) = level0.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        return lo.is_finite().then(|| (at(lo), at(hi)));
    }
    let store = store.filter(|_| !arts.is_archived(key))?;
    let load = || -> crate::error::Result<(f64, f64)> {
        let model = RewardEnsemble::load(&store.input_dir(key)?.join(REWARD))?;
        let set = super::input_key(m, Series::Set.at(0)).ok_or_else(|| crate::error::Error::Invalid("no ranked set".into()))?;
        Ok(ranked_levels(&model, &read_rollouts(&store.input_dir(set)?)?))
    };
    load().map_err(|e| tracing::warn!("terms: the reward {}: {e}", &key[..12])).ok()
}

fn row(env: EnvId, pipeline: String, method: String, s: &Sums) -> TermRow {
    let per_episode = |i: usize| s.terms[i] / s.episodes as f64;
    let length = s.steps as f64 / s.episodes as f64;
    TermRow {
        env: env.name().to_string(),
        pipeline,
        method,
        episodes: s.episodes,
        length,
        ret: per_episode(0),
        forward: per_episode(1),
        ctrl: per_episode(2),
        survive: per_episode(3),
        contact: per_episode(4),
        learned_per_step: s.learned.map(|(sum, n)| sum / n.max(1) as f64),
        ranked_best_per_step: s.ranked.map(|r| r.0),
        ranked_worst_per_step: s.ranked.map(|r| r.1),
        earned_by: EarnedBy::of(env, length, per_episode(1), per_episode(3)),
    }
}

/// The reward an evaluation scored its episodes with (the T-REX artifact's key).
fn reward_of(m: &Manifest) -> Option<&String> {
    super::input_key(m, Role::Reward)
}

/// Per (T-REX artifact, table): Pearson correlation of its predicted with the true return over
/// SSRR's pool, every trajectory of its ranked sets, the demonstrations, and the final-policy
/// evaluation episodes of the table's PPO runs trained on it (rollouts no reward saw; other
/// tables that share the reward pool their own). SSRR pools PPO checkpoints' rollouts where
/// these are the final policies'.
pub fn ssrr_pearson(arts: &Artifacts) -> BTreeMap<(String, String), f64> {
    let mut unseen: BTreeMap<(String, String), (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for (m, e, x) in arts.evaluations() {
        let Some(k) = reward_of(m) else { continue };
        if let Some(acc) = &x.reward {
            let (p, t) = unseen.entry((k.clone(), e.table())).or_default();
            p.extend(&acc.predicted_returns);
            t.extend(&x.summary.returns);
        }
    }
    unseen
        .into_iter()
        .filter_map(|((k, table), (p, t))| {
            let Some(Typed { metrics: Metrics::Trex(x), .. }) = arts.typed(arts.get(&k)?) else { return None };
            let predicted: Vec<f64> = x.train_set.scored.predicted.iter().chain(&x.demos.predicted).chain(&p).copied().collect();
            let truth: Vec<f64> = x.train_set.scored.truth.iter().chain(&x.demos.truth).chain(&t).copied().collect();
            Some(((k, table), pearson(&predicted, &truth)))
        })
        .collect()
}

impl Row for TermRow {
    fn header() -> Vec<&'static str> {
        vec![
            "env",
            "pipeline",
            "method",
            "episodes",
            "length",
            "return",
            "forward",
            "ctrl",
            "survive",
            "contact",
            "learned_per_step",
            "ranked_best_per_step",
            "ranked_worst_per_step",
            "earned_by",
        ]
    }
    fn cells(&self) -> Vec<Cell> {
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.method),
            Cell::int(self.episodes),
            Cell::num(self.length),
            Cell::num(self.ret),
            Cell::num(self.forward),
            Cell::num(self.ctrl),
            Cell::num(self.survive),
            Cell::num(self.contact),
            Cell::opt(self.learned_per_step, 3),
            Cell::opt(self.ranked_best_per_step, 3),
            Cell::opt(self.ranked_worst_per_step, 3),
            Cell::text(self.earned_by.name()),
        ]
    }
}

/// The report's section: the table (the answer names the living policies, [`living`]).
pub fn markdown(rows: &[TermRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(concat!(
        "\n## How each method earns its return (final policies' evaluation episodes)\n\n",
        "Mean per episode of the return and of each of the task's terms, the mean episode length, and the ",
        "learned reward per step (its members' mean raw output) on these episodes against the same on D-REX's ",
        "ranked set's least and most noisy levels. Earned by living: on a task that ends, the episodes last at ",
        "least half the time limit and the forward reward is under a quarter of the healthy reward.\n\n",
    ));
    let mut table = crate::log::table::Table::of(rows);
    table.columns = [
        "env",
        "pipeline",
        "method",
        "episodes",
        "length",
        "return",
        "forward",
        "control",
        "healthy",
        "contact",
        "learned / step",
        "ranked best / step",
        "ranked worst / step",
        "earned by",
    ]
    .map(String::from)
    .to_vec();
    out.push_str(&table.markdown());
    out
}

/// The lines the report's answer adds: each policy that earns its return by living.
pub fn living(rows: &[TermRow]) -> String {
    let lines: Vec<String> = rows
        .iter()
        .filter(|r| r.earned_by == EarnedBy::Living)
        .map(|r| {
            let limit = r.env.parse::<EnvId>().map_or(0, |e| e.spec().max_episode_steps);
            format!(
                "- {} {} ({}): {:.0} of {limit} steps, forward {:.1} against healthy {:.1} per episode.\n",
                r.env, r.method, r.pipeline, r.length, r.forward, r.survive
            )
        })
        .collect();
    if lines.is_empty() {
        return String::new();
    }
    format!("**Earned by living, not by moving** (how each method earns its return, below):\n\n{}\n", lines.concat())
}

/// What a method's gain over BC mostly came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GainFrom {
    Moving,
    StayingUp,
    Control,
    /// No term gained: the method is not above BC.
    Nothing,
}

impl GainFrom {
    pub fn name(self) -> &'static str {
        match self {
            GainFrom::Moving => "moving",
            GainFrom::StayingUp => "staying up",
            GainFrom::Control => "control",
            GainFrom::Nothing => "nothing",
        }
    }
}

/// `gains.csv`: a method's return minus BC's in the same table, split into the task's terms
/// (per episode, final policies): forward (moving), healthy (staying up), control and contact
/// costs (control).
#[derive(Debug, Clone, PartialEq)]
pub struct GainRow {
    pub env: String,
    pub pipeline: String,
    pub method: String,
    pub ret: f64,
    pub forward: f64,
    pub survive: f64,
    pub control: f64,
    pub from: GainFrom,
}

/// Every learned-reward method's gain over BC in its table, split into the terms.
pub fn gains(rows: &[TermRow]) -> Vec<GainRow> {
    let bc = crate::pipeline::Method::Bc.name();
    rows.iter()
        .filter(|r| r.method != bc && r.method != DEMOS)
        .filter_map(|r| {
            let b = rows.iter().find(|b| b.env == r.env && b.pipeline == r.pipeline && b.method == bc)?;
            let (forward, survive, control) = (r.forward - b.forward, r.survive - b.survive, (r.ctrl + r.contact) - (b.ctrl + b.contact));
            let parts = [(forward, GainFrom::Moving), (survive, GainFrom::StayingUp), (control, GainFrom::Control)];
            let best = parts.into_iter().filter(|(v, _)| *v > 0.0).max_by(|a, b| a.0.total_cmp(&b.0));
            Some(GainRow {
                env: r.env.clone(),
                pipeline: r.pipeline.clone(),
                method: r.method.clone(),
                ret: r.ret - b.ret,
                forward,
                survive,
                control,
                from: best.map_or(GainFrom::Nothing, |(_, f)| f),
            })
        })
        .collect()
}

impl Row for GainRow {
    fn header() -> Vec<&'static str> {
        vec!["env", "pipeline", "method", "return", "forward", "survive", "control", "mostly_from"]
    }
    fn cells(&self) -> Vec<Cell> {
        vec![
            Cell::text(&self.env),
            Cell::text(&self.pipeline),
            Cell::text(&self.method),
            Cell::num(self.ret),
            Cell::num(self.forward),
            Cell::num(self.survive),
            Cell::num(self.control),
            Cell::text(self.from.name()),
        ]
    }
}

/// The report's section on the gains.
pub fn gains_markdown(rows: &[GainRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(concat!(
        "\n## Each method's gain over BC, by term (final policies, per episode)\n\n",
        "The method's mean return minus BC's in the same table, split into the task's terms: forward (moving), ",
        "healthy (staying up) and the control and contact costs (control); mostly from: the term that gained most.\n\n",
    ));
    let mut table = crate::log::table::Table::of(rows);
    table.columns =
        ["env", "pipeline", "method", "gain", "from moving", "from staying up", "from control", "mostly from"].map(String::from).to_vec();
    out.push_str(&table.markdown());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn living_needs_a_task_that_ends_long_episodes_and_little_forward() {
        // Ant standing for 1000 steps and creeping: living; walking at a quarter of its healthy
        // reward or more, or falling before half the limit: moving.
        assert_eq!(EarnedBy::of(EnvId::Ant, 1000.0, 100.0, 1000.0), EarnedBy::Living);
        assert_eq!(EarnedBy::of(EnvId::Ant, 1000.0, 250.0, 1000.0), EarnedBy::Moving);
        assert_eq!(EarnedBy::of(EnvId::Ant, 499.0, 0.0, 499.0), EarnedBy::Moving);
        assert_eq!(EarnedBy::of(EnvId::Ant, 500.0, 0.0, 500.0), EarnedBy::Living);
        // HalfCheetah never ends: its return is always earned by moving.
        assert_eq!(EarnedBy::of(EnvId::HalfCheetah, 1000.0, -10.0, 0.0), EarnedBy::Moving);
    }

    /// The second locked set's Walker2d: "moving" by the label, yet its gain over BC came
    /// mostly from staying up (+616 healthy, +210 forward).
    #[test]
    fn a_gain_is_split_into_its_terms() {
        let row = |method: &str, forward: f64, survive: f64, ctrl: f64| TermRow {
            env: "Walker2d-v5".into(),
            pipeline: "p".into(),
            method: method.into(),
            episodes: 20,
            length: 900.0,
            ret: forward + survive + ctrl,
            forward,
            ctrl,
            survive,
            contact: 0.0,
            learned_per_step: None,
            ranked_best_per_step: None,
            ranked_worst_per_step: None,
            earned_by: EarnedBy::Moving,
        };
        let rows = [row("bc", 529.6, 269.0, -2.0), row("drex", 739.6, 885.0, -5.0), row("idrex-multi-bc", 400.0, 269.0, -1.0)];
        let g = gains(&rows);
        assert_eq!(g.len(), 2);
        assert!((g[0].forward - 210.0).abs() < 1e-9 && (g[0].survive - 616.0).abs() < 1e-9 && (g[0].control + 3.0).abs() < 1e-9);
        assert_eq!(g[0].from, GainFrom::StayingUp);
        assert!((g[0].ret - (g[0].forward + g[0].survive + g[0].control)).abs() < 1e-9);
        assert_eq!(g[1].from, GainFrom::Control);
    }
}
