//! `trex`: a reward ensemble learned from every ranked rollout set so far
//! ([`crate::algo::trex`]). Within a set lower noise ranks higher; comparisons stay within
//! a set (and, where the set asks, within one source group: one clone, one source policy);
//! with `cross_level`, every trajectory of a later iD-REX iteration ranks above every
//! earlier one (the report's equation 8).
use std::path::PathBuf;

use super::{REWARD, StageCtx, read_rollouts};
use crate::algo::trex::{self, ModelReport, Ranking, TrexConfig, TrexLoss, regression};
use crate::data::Trajectory;
use crate::env::{Env, EnvId};
use crate::error::{Error, Result};
use crate::nn::Device;
use crate::stats::{nan_as_null, pearson, spearman};

/// How one ranked input set takes part.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RankedSet {
    /// The iD-REX iteration that produced it (0: D-REX's noise rollouts).
    pub level: usize,
    /// Compare only trajectories of the same group (multi-BC's clones).
    pub same_group: bool,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrexParams {
    pub env: EnvId,
    pub trex: TrexConfig,
    /// One entry per input `set<i>`, in order.
    pub sets: Vec<RankedSet>,
    pub cross_level: bool,
    /// Where it computes; absent (the CPU) from a CPU stage's parameters, and so its key.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

/// Predicted against true returns of a set of trajectories.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Scored {
    pub predicted: Vec<f64>,
    #[serde(rename = "true")]
    pub truth: Vec<f64>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrainSet {
    #[serde(flatten)]
    pub scored: Scored,
    pub noise: Vec<f64>,
    pub level: Vec<usize>,
    /// Each trajectory's length (absent from stages before it was recorded).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lengths: Vec<usize>,
    #[serde(with = "nan_as_null")]
    pub spearman: f64,
    #[serde(with = "nan_as_null")]
    pub pearson: f64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrexMetrics {
    pub models: Vec<ModelReport>,
    pub train_set: TrainSet,
    pub demos: Scored,
    /// Mean validation pair accuracy over the models.
    #[serde(with = "nan_as_null")]
    pub val_accuracy: f64,
    /// With `trex.loss: regression`: the curve the reward was regressed on and each member's
    /// fit (`models` and `val_accuracy` are then the ranking ensemble's that stood in for
    /// AIRL's reward).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub regression: Option<RegressionFit>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RegressionFit {
    pub curve: regression::Curve,
    pub members: Vec<regression::RegressionReport>,
}

crate::stage_inputs! {
    /// T-REX learns from the ranked sets (`sets[i]` is described by `TrexParams::sets[i]`)
    /// and scores the demonstrations.
    TrexInputs { sets: Many Set, demos: One Demos }
}

pub fn run(p: &TrexParams, inputs: &TrexInputs<PathBuf>, ctx: &StageCtx) -> Result<TrexMetrics> {
    let mut trajs = Vec::new();
    let mut ranking = Ranking { same_group: true, cross_level: p.cross_level, ..Default::default() };
    for (i, dir) in inputs.sets.iter().enumerate() {
        let set = p.sets.get(i).copied().unwrap_or(RankedSet { level: 0, same_group: false });
        let grouped = set.same_group || p.trex.same_group;
        for t in read_rollouts(dir)? {
            ranking.scores.push(-t.meta.noise);
            ranking.groups.push(i * 10_000 + if grouped || set.level > 0 { t.meta.group } else { 0 });
            ranking.levels.push(set.level);
            trajs.push(t);
        }
    }
    ctx.progress.set_message(format!("T-REX on {} trajectories", trajs.len()));
    let seen = p.trex.observation.seen(&Env::new(p.env)?);
    let part: Vec<Trajectory> = match &seen {
        None => Vec::new(),
        Some(range) => trajs.iter().map(|t| t.obs_part(range.clone())).collect(),
    };
    let learn_from = if seen.is_some() { &part } else { &trajs };
    let (mut model, reports) = trex::train(learn_from, &ranking, &p.trex, ctx.seed, ctx.threads, p.device)?;
    let mut fit = None;
    if p.trex.loss == TrexLoss::Regression {
        if inputs.sets.len() != 1 {
            return Err(Error::Invalid(
                "trex.loss: regression learns D-REX's reward from its one ranked set; set it for D-REX only".into(),
            ));
        }
        ctx.progress.set_message("regression on the noise curve");
        let per_step: Vec<f64> =
            learn_from.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions) / t.len().max(1) as f64).collect();
        let noise: Vec<f64> = learn_from.iter().map(|t| t.meta.noise).collect();
        let curve = regression::fit(&noise, &per_step)
            .ok_or_else(|| Error::Invalid("trex.loss: regression needs a ranked set of at least two noise levels".into()))?;
        let (regressed, members) = regression::train(learn_from, &curve, model.config.clone(), &p.trex, ctx.seed, ctx.threads)?;
        model = regressed;
        fit = Some(RegressionFit { curve, members });
    }
    // From here on the reward takes whole observations and reads the part it learned from.
    model.config.obs_stride = seen.as_ref().map(|_| trajs[0].obs_dim);
    model.config.obs_offset = seen.and_then(|range| (range.start > 0).then_some(range.start));
    model.save(&ctx.out.join(REWARD), serde_json::json!({"trex": p.trex}))?;
    let score = |ts: &[Trajectory]| Scored {
        predicted: ts.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect(),
        truth: ts.iter().map(Trajectory::ret).collect(),
    };
    let train = score(&trajs);
    let demos = score(&read_rollouts(&inputs.demos)?);
    Ok(TrexMetrics {
        val_accuracy: reports.iter().map(|r| r.val_accuracy).sum::<f64>() / reports.len() as f64,
        models: reports,
        regression: fit,
        train_set: TrainSet {
            spearman: spearman(&train.predicted, &train.truth),
            pearson: pearson(&train.predicted, &train.truth),
            noise: trajs.iter().map(|t| t.meta.noise).collect(),
            lengths: trajs.iter().map(Trajectory::len).collect(),
            level: ranking.levels,
            scored: train,
        },
        demos,
    })
}
