//! iD-REX: after D-REX, iterations k = 1..K-1 each build a new ranked set from the current
//! iteration's RL policies, learn a reward on every ranked set so far, and train new RL
//! policies on it. The three variants differ only in how the new set is made:
//! [`interpolation`] (variant 1), [`action_noise`] (variant 2) and [`multi_bc`] (variant 3).
//! Their rollout stages are in [`crate::pipeline::stage::idrex`]; this module expands the
//! iterations into the DAG.
use super::{Graph, rl_runs, trex_params};
use crate::pipeline::Pipeline;
use crate::pipeline::config::{CloneFilter, CloneSource, Method};
use crate::pipeline::stage::idrex::{action_noise, interpolation, multi_bc};
use crate::pipeline::stage::{ActionNoiseInputs, Inputs, InterpolationInputs, MultiBcInputs, Params, TrexInputs, trex::RankedSet};

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

/// Multi-BC's judge trains from the previous reward's seed plus this (and the iteration).
const JUDGE_SEED_OFFSET: u64 = 0x1d9e_0000;

/// The evaluation node of a PPO run node (`drex/ppo/1` -> `drex/eval/1`).
fn eval_of(ppo: &str) -> String {
    let (prefix, run) = ppo.rsplit_once("/ppo/").expect("a PPO node name");
    format!("{prefix}/eval/{run}")
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
        let (params, inputs) = match variant {
            Variant::Interpolation => (
                Params::InterpolationRollouts(interpolation::Params {
                    env,
                    alphas: s.idrex.alphas.clone(),
                    rollouts_per_level: s.idrex.rollouts_per_level,
                    horizon: s.noise.horizon.on(env),
                }),
                Inputs::InterpolationRollouts(InterpolationInputs { policies: current.clone(), older: previous.clone() }),
            ),
            Variant::ActionNoise => (
                Params::ActionNoiseRollouts(action_noise::Params {
                    env,
                    sigmas: s.idrex.sigmas.clone(),
                    noise: s.idrex.action_noise,
                    rollouts_per_level: s.idrex.rollouts_per_level,
                    horizon: s.noise.horizon.on(env),
                }),
                Inputs::ActionNoiseRollouts(ActionNoiseInputs { policies: current.clone() }),
            ),
            Variant::MultiBc => {
                let filter = s.idrex.multi_bc_filter;
                let judge = (filter == CloneFilter::HeldOutReward).then(|| {
                    let reward = g.get(&prev_reward).expect("the previous reward is in the graph").clone();
                    // An offset, not a hash: replicate r's seeds stay the replicate's shift of
                    // replicate 0's ([`crate::pipeline::config::replicate_seed`]).
                    let seed = reward.seed.wrapping_add(JUDGE_SEED_OFFSET + k as u64);
                    g.push(format!("{prefix}/judge"), reward.params, seed, reward.inputs)
                });
                let inputs = MultiBcInputs {
                    demos: drex.demos.to_string(),
                    // The previous reward always: the stage records what the previous-reward
                    // filter would decide, whichever filter runs.
                    reward: prev_reward.clone(),
                    judge,
                    policies: current.clone(),
                    // Every earlier set, newest last: the filter compares with the newest
                    // that kept rollouts.
                    baselines: sets.iter().map(|(n, _)| n.clone()).collect(),
                    evals: match s.idrex.multi_bc.source {
                        CloneSource::Checkpoint => current.iter().map(|n| eval_of(n)).collect(),
                        CloneSource::Final => Vec::new(),
                    },
                };
                let params = Params::MultiBcRollouts(multi_bc::Params {
                    env,
                    clone: s.idrex.multi_bc.clone(),
                    filter,
                    schedule: s.idrex.multi_bc_schedule.clone(),
                    rollouts_per_level: s.idrex.multi_bc_rollouts_per_level,
                    horizon: s.noise.horizon.on(env),
                    device: p.device,
                });
                (params, Inputs::MultiBcRollouts(inputs))
            }
        };
        let rollouts = g.push(format!("{prefix}/rollouts"), params, s.seeds[0], inputs);
        sets.push((rollouts, RankedSet { level: k, same_group: variant == Variant::MultiBc }));
        let trex_inputs = Inputs::Trex(TrexInputs { demos: drex.demos.to_string(), sets: sets.iter().map(|(n, _)| n.clone()).collect() });
        let ranked: Vec<RankedSet> = sets.iter().map(|(_, r)| *r).collect();
        let trex = g.push(format!("{prefix}/trex"), trex_params(p, m, ranked, variant == Variant::Interpolation), s.seeds[0], trex_inputs);
        previous = current;
        current = rl_runs(g, p, m, &prefix, k + 1, &trex, drex.demos);
        prev_reward = trex;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::expand;
    use crate::pipeline::stage::idrex::clone;

    fn graph(extra: &str) -> Graph {
        let text = format!("version: 1\nenv: Hopper-v5\nseeds: [0, 1]\nmethods: [drex, idrex-multi-bc]\n{extra}");
        expand(&Pipeline::parse(std::path::Path::new("p.yaml"), &text).unwrap()).unwrap()
    }

    fn roles(g: &Graph, node: &str) -> Vec<String> {
        g.get(node).unwrap().inputs.iter().map(|(r, _)| r.name()).collect()
    }

    /// Multi-BC's inputs follow its options: every earlier set as a baseline (at K = 3 the
    /// second iteration sees D-REX's set and the first multi-BC set), the judge (a T-REX
    /// stage like the previous reward, on its inputs, from another seed) or the previous
    /// reward or nothing, and the source runs' evaluations for a checkpoint source.
    #[test]
    fn multi_bc_inputs_follow_its_options() {
        let g = graph("iterations: 3\n");
        let r = roles(&g, "idrex-multi-bc/k2/rollouts");
        for role in ["policy0", "policy1", "baseline0", "baseline1", "judge", "demos"] {
            assert!(r.contains(&role.to_string()), "{role} in {r:?}");
        }
        assert!(r.contains(&"reward".to_string()) && !r.iter().any(|x| x.starts_with("eval")), "{r:?}");
        let judge = g.get("idrex-multi-bc/k2/judge").unwrap();
        let prev = g.get("idrex-multi-bc/k1/trex").unwrap();
        assert_eq!((&judge.params, &judge.inputs), (&prev.params, &prev.inputs));
        assert_ne!(judge.seed, prev.seed);
        assert_eq!(g.get("idrex-multi-bc/k1/judge").unwrap().inputs, g.get("drex/trex").unwrap().inputs);

        let g = graph("idrex:\n  multi_bc_filter: previous-reward\n  multi_bc:\n    source: checkpoint\n");
        let r = roles(&g, "idrex-multi-bc/k1/rollouts");
        assert!(r.contains(&"reward".to_string()) && r.contains(&"eval1".to_string()) && !r.contains(&"judge".to_string()), "{r:?}");
        assert!(g.get("idrex-multi-bc/k1/judge").is_none());
        let Inputs::MultiBcRollouts(inputs) = &g.get("idrex-multi-bc/k1/rollouts").unwrap().inputs else { panic!("multi-BC's inputs") };
        assert_eq!(inputs.evals, ["drex/eval/0", "drex/eval/1"], "{inputs:?}");

        let g = graph("idrex:\n  multi_bc_filter: none\n");
        let r = roles(&g, "idrex-multi-bc/k1/rollouts");
        assert!(!r.iter().any(|x| x == "judge"), "{r:?}");
    }

    /// A clone option changes multi-BC's rollouts and what depends on them, nothing else.
    #[test]
    fn a_clone_option_changes_only_multi_bc() {
        let (a, b) = (graph("").keys(), graph("idrex:\n  multi_bc:\n    labels: sampled\n").keys());
        let changed: Vec<&String> = a.keys().filter(|n| a[*n] != b[*n]).collect();
        assert!(!changed.is_empty());
        assert!(changed.iter().all(|n| n.starts_with("idrex-multi-bc/") && !n.ends_with("/judge")), "{changed:?}");
    }

    /// The stage's metrics survive the manifest's JSON, a missing fidelity (NaN) as null.
    #[test]
    fn multi_bc_metrics_round_trip_through_json() {
        use crate::pipeline::stage::{Metrics, StageKind};
        let fidelity = crate::algo::scoring::Fidelity::of(&[], &[], 0.0);
        assert!(fidelity.normalised.is_nan());
        let record = clone::CloneRecord {
            clone: 1,
            source_step: Some(40_960),
            fidelity,
            bc: crate::algo::bc::BcReport {
                train_steps: 800,
                val_steps: 1000,
                train_loss: 0.01,
                val_loss: 0.02,
                best_iteration: Some(750),
                iterations_run: Some(2750),
            },
            score: Some(-0.25),
            previous_reward_score: Some(0.5),
            kept: false,
        };
        let m = Metrics::MultiBcRollouts(multi_bc::Metrics {
            random_return: -280.5,
            baseline_set: Some(0),
            clones: vec![record],
            degradation: vec![],
        });
        let json = m.to_json();
        assert!(json["clones"][0]["fidelity"]["normalised"].is_null(), "{json}");
        let back = Metrics::from_json(StageKind::MultiBcRollouts, &json).unwrap();
        let (Metrics::MultiBcRollouts(a), Metrics::MultiBcRollouts(b)) = (&m, &back) else { panic!() };
        assert!(b.clones[0].fidelity.normalised.is_nan());
        assert_eq!(
            (a.random_return, a.baseline_set, &a.clones[0].bc, a.clones[0].score),
            (b.random_return, b.baseline_set, &b.clones[0].bc, b.clones[0].score)
        );
    }
}
