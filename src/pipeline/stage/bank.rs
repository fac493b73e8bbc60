//! The reward bench's stages ([`crate::algo::bank`]): `bank-policy` trains PPO on the task's
//! reward, or on it with the forward term negated, keeping evenly spaced checkpoints (slow to
//! fast gaits); `bank` rolls the checkpoints out clean, with jerky (epsilon-greedy) and smooth
//! (Ornstein-Uhlenbeck) noise, beside the zero action and uniform random actions;
//! `bank-score` scores a learned reward on it. The bank's keys depend on the task and the
//! bank's settings only, so every study of a task shares one.
use std::path::{Path, PathBuf};

use rand_chacha::ChaCha8Rng;

use super::{POLICY, REWARD, StageCtx, ppo_progress, read_rollouts};
use crate::algo::bank::{self, BankEntry, BankScore, Disturbance, GaitClass};
use crate::algo::noise::{EpsilonGreedy, NoiseProcess};
use crate::algo::ppo::{self, PpoConfig};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::{Error, Result};
use crate::nn::{ActorCritic, RewardEnsemble};
use crate::pipeline::inputs::NoInputs;
use crate::rollout::{self, Actor, PolicyActor, UniformActor};
use crate::seed::{self, Purpose};

/// What a bank policy's PPO maximises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Objective {
    /// The task's reward.
    Forward,
    /// The task's reward with its forward term negated.
    Backward,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BankPolicyParams {
    /// The task PPO trains on (Ant-v5's bank trains on Ant-v5-no-cfrc, where idrex's PPO
    /// walks, and acts in Ant-v5 on the observation less its contact forces).
    pub env: EnvId,
    pub ppo: PpoConfig,
    pub objective: Objective,
    /// Checkpoints kept: evenly spaced over the run, or with `first`, geometrically from
    /// that fraction of the run to its end (slow gaits then span more of the bank).
    pub checkpoints: usize,
    /// Absent from the key when evenly spaced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first: Option<f64>,
}

/// The updates after which a run of `updates` keeps its policy: `n` evenly spaced (the first
/// one interval in), or geometric from `first` of the run to its end.
pub fn kept_updates(updates: usize, n: usize, first: Option<f64>) -> Vec<usize> {
    let n = n.max(1);
    let mut out: Vec<usize> = match first {
        None => {
            let every = (updates / n).max(1);
            (1..=updates).filter(|u| u % every == 0).collect()
        }
        Some(f) => {
            let start = (f * updates as f64).round().max(1.0);
            let ratio = if n > 1 { (updates as f64 / start).powf(1.0 / (n - 1) as f64) } else { 1.0 };
            (0..n).map(|k| if k + 1 == n { updates } else { (start * ratio.powi(k as i32)).round() as usize }).collect()
        }
    };
    out.dedup();
    out
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BankPolicyMetrics {
    pub wall_s: f64,
    /// The checkpoints' global steps.
    pub checkpoints: Vec<usize>,
    /// The mean true return of the last update's finished training episodes.
    pub final_return: Option<f64>,
}

pub fn policy(p: &BankPolicyParams, _: &NoInputs<PathBuf>, ctx: &StageCtx) -> Result<BankPolicyMetrics> {
    let mut cfg = p.ppo.clone();
    let updates = cfg.total_steps / (cfg.num_envs * cfg.num_steps).max(1);
    let keep = kept_updates(updates, p.checkpoints, p.first);
    // PPO offers the policy every `checkpoint_every` updates (recorded in each policy's
    // sidecar, so evenly spaced banks keep their interval); the save keeps those of `keep`.
    cfg.checkpoint_every = if p.first.is_none() { (updates / p.checkpoints.max(1)).max(1) } else { 1 };
    let mut show = ppo_progress(ctx, cfg.total_steps);
    let mut on_update = |u: &ppo::PpoProgress| {
        show(u);
        true
    };
    let hyper = serde_json::to_value(&cfg).unwrap_or_default();
    let batch = cfg.num_envs * cfg.num_steps;
    let mut kept = Vec::new();
    let mut save = |policy: &ActorCritic, step: usize| {
        if !keep.contains(&(step / batch)) {
            return Ok(());
        }
        kept.push(step);
        policy.save(&ppo::checkpoint_dir(ctx.out, step), hyper.clone())
    };
    let source = match p.objective {
        Objective::Forward => ppo::RewardSource::GroundTruth,
        Objective::Backward => ppo::RewardSource::Backward,
    };
    let res = ppo::train(p.env, &cfg, source, ctx.seed, &mut on_update, Some(&mut save))?;
    res.policy.save(&ctx.out.join(POLICY), hyper)?;
    Ok(BankPolicyMetrics { wall_s: res.wall_s, checkpoints: kept, final_return: res.curve.last().and_then(|u| u.episodic_return) })
}

crate::stage_inputs! {
    /// The checkpoints of PPO on the task's reward and on its backward twin.
    BankPolicyInputs { forward: One Forward, backward: One Backward }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BankParams {
    pub env: EnvId,
    /// Episodes of each checkpoint as it acts (its sampled actions).
    pub episodes: usize,
    /// Epsilon-greedy levels (uniform random actions), each `disturbed` episodes per checkpoint.
    pub epsilon: Vec<f64>,
    /// Ornstein-Uhlenbeck sigmas on the mean action, each `disturbed` episodes per checkpoint.
    pub smooth: Vec<f64>,
    pub disturbed: usize,
    /// Episodes of the zero action and of uniform random actions.
    pub still: usize,
    pub random: usize,
    /// Episodes of each checkpoint acting with its mean action, its calmest version (absent
    /// from the key at 0).
    #[serde(default, skip_serializing_if = "super::is_zero")]
    pub mean: usize,
}

/// The bank's entries, beside its rollout file, in its order.
pub const ENTRIES: &str = "bank.json";

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BankMetrics {
    pub entries: Vec<BankEntry>,
}

/// A policy trained on a task whose observation is a prefix of this one's (Ant-v5-no-cfrc's
/// of Ant-v5's, the contact forces appended), acting on that prefix.
struct Prefix<A> {
    inner: A,
    len: usize,
}

impl<A: Actor> Actor for Prefix<A> {
    fn act(&mut self, obs: &[f32], rng: &mut ChaCha8Rng, out: &mut [f32]) {
        self.inner.act(&obs[..self.len], rng, out)
    }
    fn reset(&mut self) {
        self.inner.reset()
    }
}

/// A bank checkpoint, checked against the task it acts in: the same actions, and its
/// observation the task's or the task's less its contact forces.
fn load_gait(dir: &Path, env: &Env, id: EnvId) -> Result<ActorCritic> {
    let p = ActorCritic::load(dir)?;
    let prefix = id.spec().observed_contact().is_some() && p.config.obs_dim == env.nq() - id.spec().obs_skip_qpos + env.nv();
    if p.config.act_dim != env.act_dim() || (p.config.obs_dim != env.obs_dim() && !prefix) {
        return Err(Error::Invalid(format!(
            "{}: a {}-observation, {}-action policy cannot act in {} ({} observations, {} actions)",
            dir.display(),
            p.config.obs_dim,
            p.config.act_dim,
            id.name(),
            env.obs_dim(),
            env.act_dim()
        )));
    }
    Ok(p)
}

pub fn run(p: &BankParams, inputs: &BankPolicyInputs<PathBuf>, ctx: &StageCtx) -> Result<BankMetrics> {
    let mut env = Env::new(p.env)?;
    let ad = env.act_dim();
    let mut trajs: Vec<Trajectory> = Vec::new();
    let mut entries: Vec<BankEntry> = Vec::new();
    let mut roll = |env: &mut Env, actor: &mut dyn Actor, n: usize, class: GaitClass, d: Disturbance, level: f64, step: usize| {
        for _ in 0..n {
            let k = trajs.len() as u64;
            let meta = TrajMeta { source: format!("bank-{}-{}", class.name(), d.name()), noise: level, seed: 0, group: 0 };
            let t = rollout::episode(env, actor, seed::derive(ctx.seed, Purpose::Episode, k), meta);
            entries.push(BankEntry {
                class,
                disturbance: d,
                level,
                checkpoint: step,
                ret: t.ret(),
                forward: t.terms.iter().map(|x| x.reward_forward).sum(),
                length: t.len(),
                terminated: t.terminated,
            });
            trajs.push(t);
        }
    };
    ctx.progress.set_message("the reward bench's gaits");
    for (class, dir) in [(GaitClass::Forward, &inputs.forward), (GaitClass::Backward, &inputs.backward)] {
        for (step, cdir) in ppo::checkpoints(dir)? {
            let policy = load_gait(&cdir, &env, p.env)?;
            let len = policy.config.obs_dim;
            let mean = || Prefix { inner: PolicyActor::mean_of(&policy), len };
            roll(&mut env, &mut Prefix { inner: PolicyActor::acting(&policy), len }, p.episodes, class, Disturbance::None, 0.0, step);
            roll(&mut env, &mut mean(), p.mean, class, Disturbance::MeanAction, 0.0, step);
            for &eps in &p.epsilon {
                let mut a = EpsilonGreedy { inner: mean(), eps, degraded: UniformActor::of(&env) };
                roll(&mut env, &mut a, p.disturbed, class, Disturbance::Epsilon, eps, step);
            }
            for &sigma in &p.smooth {
                let mut a = NoiseProcess::Ou.around(mean(), sigma, ad);
                roll(&mut env, &mut a, p.disturbed, class, Disturbance::Smooth, sigma, step);
            }
        }
    }
    let mut zero = crate::algo::noise::ConstantActor(vec![0.0; ad]);
    roll(&mut env, &mut zero, p.still, GaitClass::Still, Disturbance::None, 0.0, 0);
    let mut uniform = UniformActor::of(&env);
    roll(&mut env, &mut uniform, p.random, GaitClass::Random, Disturbance::None, 0.0, 0);
    ctx.write_rollouts(p.env, &trajs, None)?;
    let text = serde_json::to_string_pretty(&entries).expect("entries serialise");
    std::fs::write(ctx.out.join(ENTRIES), text).map_err(|e| Error::io(ctx.out.join(ENTRIES), e))?;
    Ok(BankMetrics { entries })
}

/// A stored bank's entries and trajectories, in one order.
pub fn read_bank(dir: &Path) -> Result<(Vec<BankEntry>, Vec<Trajectory>)> {
    let path = dir.join(ENTRIES);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
    let entries: Vec<BankEntry> = serde_json::from_str(&text).map_err(|e| Error::file(&path, e.to_string()))?;
    let trajs = read_rollouts(dir)?;
    if trajs.len() != entries.len() {
        return Err(Error::file(&path, format!("{} entries for {} rollouts", entries.len(), trajs.len())));
    }
    Ok((entries, trajs))
}

/// A learned reward's scores on a stored bank.
pub fn score_reward(model: &RewardEnsemble, bank_dir: &Path) -> Result<BankScore> {
    let (entries, trajs) = read_bank(bank_dir)?;
    let learned: Vec<f64> = trajs.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
    if let Some(i) = learned.iter().position(|x| !x.is_finite()) {
        return Err(Error::Invalid(format!("the learned reward's return on bank trajectory {i} is {}", learned[i])));
    }
    Ok(bank::score(&entries, &learned))
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScoreParams {
    pub env: EnvId,
}

crate::stage_inputs! {
    /// A learned reward and its task's bank.
    ScoreInputs { reward: One Reward, bank: One Bank }
}

pub fn score(_: &ScoreParams, inputs: &ScoreInputs<PathBuf>, ctx: &StageCtx) -> Result<BankScore> {
    ctx.progress.set_message("scoring the reward on the bank");
    score_reward(&RewardEnsemble::load(&inputs.reward.join(REWARD))?, &inputs.bank)
}
