//! iD-REX: after D-REX, iterations k = 1..K-1 each build a new ranked set from the current
//! iteration's RL policies, learn a reward on every ranked set so far, and train new RL
//! policies on it. The three variants differ only in how the new set is made:
//! [`interpolation`] (variant 1), [`action_noise`] (variant 2) and [`multi_bc`] (variant 3).
//! This module holds their rollout stages and the expansion of the iterations into the DAG.
pub mod action_noise;
pub mod interpolation;
pub mod multi_bc;

use super::config::{Method, Pipeline};
use super::graph::{Graph, io, rl_runs, trex_params};
use super::stage::{Params, trex::RankedSet};

/// The three ways iD-REX makes a new ranked set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    Interpolation,
    ActionNoise,
    MultiBc,
}

impl Variant {
    pub const ALL: [Variant; 3] = [Variant::Interpolation, Variant::ActionNoise, Variant::MultiBc];

    pub fn method(self) -> Method {
        match self {
            Variant::Interpolation => Method::IdrexInterpolation,
            Variant::ActionNoise => Method::IdrexActionNoise,
            Variant::MultiBc => Method::IdrexMultiBc,
        }
    }
}

/// The D-REX nodes iD-REX starts from.
pub struct DrexNodes<'a> {
    pub demos: &'a str,
    pub bc: &'a str,
    /// D-REX's ranked set (the noise rollouts), its reward and its RL runs.
    pub noise: &'a str,
    pub trex: &'a str,
    pub ppo: &'a [String],
}

/// Adds iterations 1..K-1 of `variant` to the graph.
pub fn expand(g: &mut Graph, p: &Pipeline, variant: Variant, drex: &DrexNodes) {
    let s = &p.spec;
    let (env, m) = (p.env, variant.method());
    // The ranked sets so far with how each takes part, and the current iteration's policies.
    let mut sets: Vec<(String, RankedSet)> = vec![(drex.noise.to_string(), RankedSet { level: 0, same_group: false })];
    let mut current = drex.ppo.to_vec();
    let mut previous: Vec<String> = vec![drex.bc.to_string(); s.seeds.len()];
    let mut prev_reward = drex.trex.to_string();
    for k in 1..s.iterations {
        let prefix = format!("{}/k{k}", m.name());
        let mut inputs: Vec<(String, String)> = current.iter().enumerate().map(|(r, n)| io(&format!("policy{r}"), n)).collect();
        let params = match variant {
            Variant::Interpolation => {
                inputs.extend(previous.iter().enumerate().map(|(r, n)| io(&format!("older{r}"), n)));
                Params::InterpolationRollouts(interpolation::Params {
                    env,
                    alphas: s.idrex.alphas.clone(),
                    rollouts_per_level: s.idrex.rollouts_per_level,
                })
            }
            Variant::ActionNoise => Params::ActionNoiseRollouts(action_noise::Params {
                env,
                sigmas: s.idrex.sigmas.clone(),
                noise: s.idrex.action_noise,
                rollouts_per_level: s.idrex.rollouts_per_level,
            }),
            Variant::MultiBc => {
                inputs.push(io("reward", &prev_reward));
                inputs.push(io("baseline", &sets.last().expect("the D-REX set").0));
                Params::MultiBcRollouts(multi_bc::Params {
                    env,
                    bc: s.bc.clone(),
                    schedule: s.idrex.multi_bc_schedule.clone(),
                    rollouts_per_level: s.idrex.multi_bc_rollouts_per_level,
                    device: p.device,
                })
            }
        };
        let rollouts = g.push(format!("{prefix}/rollouts"), params, s.seeds[0], inputs);
        sets.push((rollouts, RankedSet { level: k, same_group: variant == Variant::MultiBc }));
        let mut trex_inputs: Vec<(String, String)> = sets.iter().enumerate().map(|(i, (n, _))| io(&format!("set{i}"), n)).collect();
        trex_inputs.push(io("demos", drex.demos));
        let ranked: Vec<RankedSet> = sets.iter().map(|(_, r)| *r).collect();
        let trex = g.push(format!("{prefix}/trex"), trex_params(p, m, ranked, variant == Variant::Interpolation), s.seeds[0], trex_inputs);
        previous = current;
        current = rl_runs(g, p, m, &prefix, k + 1, &trex, drex.demos);
        prev_reward = trex;
    }
}
