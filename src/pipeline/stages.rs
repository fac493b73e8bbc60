//! The stage kinds a pipeline is made of, each with its implementation version (bumped
//! whenever a change would change its results, which invalidates stored artifacts), and
//! their bodies. A stage reads its inputs' artifact directories and writes into its own
//! staging directory; the runner publishes it.
//!
//! | kind | version | inputs | outputs |
//! |---|---|---|---|
//! | demonstrator | 1 | - | policy/ |
//! | demos | 1 | policy | rollouts.mcap |
//! | demos-import | 1 | - (a file) | rollouts.mcap |
//! | bc | 1 | demos | policy/ |
//! | noise-rollouts | 1 | policy | rollouts.mcap |
//! | trex | 1 | set0..setN, demos | reward/ |
//! | ppo | 1 | reward | policy/, curve.csv |
//! | eval | 1 | policy, reward?, demos | rollouts.mcap |
//! | interpolation-rollouts | 1 | policy<r>, older<r> | rollouts.mcap |
//! | action-noise-rollouts | 1 | policy<r> | rollouts.mcap |
//! | multi-bc-rollouts | 1 | policy<r>, reward, baseline | rollouts.mcap |
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::algo::noise::{EpsilonGreedy, GaussianNoise, Interpolation, OrnsteinUhlenbeck, PolicyActor, TimeCorrelated, UniformActor};
use crate::algo::trex::{Ranking, pairwise_accuracy, pearson, spearman};
use crate::algo::{bc, ppo, trex};
use crate::data::{TrajMeta, Trajectory};
use crate::env::{Env, EnvId};
use crate::error::{Error, Result};
use crate::log::mcap;
use crate::nn::{ActorCritic, RewardEnsemble};
use crate::rollout::{self, Actor, ReturnStats};

pub const ROLLOUTS: &str = "rollouts.mcap";
pub const POLICY: &str = "policy";
pub const REWARD: &str = "reward";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StageKind {
    Demonstrator,
    Demos,
    DemosImport,
    Bc,
    NoiseRollouts,
    Trex,
    Ppo,
    Eval,
    InterpolationRollouts,
    ActionNoiseRollouts,
    MultiBcRollouts,
    /// Engine tests only: writes `value` (plus its inputs' values) to value.txt.
    TestValue,
}

impl StageKind {
    pub fn name(self) -> &'static str {
        match self {
            StageKind::Demonstrator => "demonstrator",
            StageKind::Demos => "demos",
            StageKind::DemosImport => "demos-import",
            StageKind::Bc => "bc",
            StageKind::NoiseRollouts => "noise-rollouts",
            StageKind::Trex => "trex",
            StageKind::Ppo => "ppo",
            StageKind::Eval => "eval",
            StageKind::InterpolationRollouts => "interpolation-rollouts",
            StageKind::ActionNoiseRollouts => "action-noise-rollouts",
            StageKind::MultiBcRollouts => "multi-bc-rollouts",
            StageKind::TestValue => "test-value",
        }
    }

    /// Bump when a change to the stage would change its results.
    pub fn version(self) -> u32 {
        // All at 1. (BC briefly ran on the fused kernel: measured idle, libtorch's GEMMs are
        // 2.8x faster at 4 x 256 units, so it went back, and with it the version.)
        1
    }
}

/// What a stage body gets.
pub struct StageCtx<'a> {
    pub params: &'a Value,
    pub seed: u64,
    /// Input role -> artifact directory.
    pub inputs: BTreeMap<String, PathBuf>,
    pub out: &'a Path,
    pub threads: usize,
    pub progress: &'a indicatif::ProgressBar,
}

impl StageCtx<'_> {
    fn input(&self, role: &str) -> Result<&Path> {
        self.inputs.get(role).map(PathBuf::as_path).ok_or_else(|| Error::Invalid(format!("stage has no input '{role}'")))
    }
    fn param<T: serde::de::DeserializeOwned>(&self, key: &str) -> Result<T> {
        serde_json::from_value(self.params.get(key).cloned().unwrap_or(Value::Null))
            .map_err(|e| Error::Invalid(format!("parameter '{key}': {e}")))
    }
    fn env(&self) -> Result<EnvId> {
        self.param::<String>("env")?.parse()
    }
    /// Inputs named `<prefix>0`, `<prefix>1`, ... in order.
    fn numbered(&self, prefix: &str) -> Vec<&Path> {
        (0..).map_while(|i| self.inputs.get(&format!("{prefix}{i}")).map(PathBuf::as_path)).collect()
    }
}

fn write_rollouts(ctx: &StageCtx, env: EnvId, trajs: &[Trajectory], learned: Option<&[Vec<f64>]>) -> Result<()> {
    let dt = Env::new(env)?.dt();
    mcap::write(&ctx.out.join(ROLLOUTS), env.name(), dt, trajs, learned)
}

fn read_rollouts(dir: &Path) -> Result<Vec<Trajectory>> {
    Ok(mcap::read(&dir.join(ROLLOUTS))?.trajectories)
}

fn load_policy(dir: &Path) -> Result<ActorCritic> {
    ActorCritic::load(&dir.join(POLICY))
}

/// The acting policy of a stored policy: PPO policies sample, BC policies act with the mean.
fn actor_of(p: &ActorCritic) -> PolicyActor {
    PolicyActor::new(p.to_cpu(), p.critic.is_some())
}

fn returns_summary(trajs: &[Trajectory]) -> Value {
    let r: Vec<f64> = trajs.iter().map(Trajectory::ret).collect();
    let s = ReturnStats::of(&r);
    json!({"mean": s.mean, "std": s.std, "min": s.min, "max": s.max, "episodes": s.episodes, "returns": r,
           "lengths": trajs.iter().map(Trajectory::len).collect::<Vec<_>>()})
}

/// Per-noise-level mean and std of returns: the degradation curve.
fn degradation(trajs: &[Trajectory]) -> Value {
    let mut levels: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for t in trajs {
        levels.entry(format!("{:.4}", t.meta.noise)).or_default().push(t.ret());
    }
    levels
        .into_iter()
        .map(|(k, v)| {
            let s = ReturnStats::of(&v);
            json!({"noise": k.parse::<f64>().unwrap_or(0.0), "mean": s.mean, "std": s.std, "n": v.len()})
        })
        .collect()
}

fn episode_seed(seed: u64, k: u64) -> u64 {
    seed.wrapping_mul(1_000_003).wrapping_add(k)
}

pub fn run(kind: StageKind, ctx: &StageCtx) -> Result<Value> {
    match kind {
        StageKind::TestValue => test_value(ctx),
        StageKind::Demonstrator => demonstrator(ctx),
        StageKind::Demos => demos(ctx),
        StageKind::DemosImport => demos_import(ctx),
        StageKind::Bc => bc_stage(ctx),
        StageKind::NoiseRollouts => noise_rollouts(ctx),
        StageKind::Trex => trex_stage(ctx),
        StageKind::Ppo => ppo_stage(ctx),
        StageKind::Eval => eval(ctx),
        StageKind::InterpolationRollouts => interpolation(ctx),
        StageKind::ActionNoiseRollouts => action_noise(ctx),
        StageKind::MultiBcRollouts => multi_bc(ctx),
    }
}

fn test_value(ctx: &StageCtx) -> Result<Value> {
    if let Some(ms) = ctx.params.get("sleep_ms").and_then(Value::as_u64) {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
    if ctx.params.get("fail").and_then(Value::as_bool) == Some(true) {
        return Err(Error::Invalid("this test stage was asked to fail".into()));
    }
    let mut v = ctx.params.get("value").and_then(Value::as_i64).unwrap_or(0);
    for dir in ctx.inputs.values() {
        let text = std::fs::read_to_string(dir.join("value.txt")).map_err(|e| Error::io(dir, e))?;
        v += text.trim().parse::<i64>().map_err(|e| Error::file(dir.join("value.txt"), e.to_string()))?;
    }
    std::fs::write(ctx.out.join("value.txt"), v.to_string()).map_err(|e| Error::io(ctx.out, e))?;
    Ok(json!({"value": v}))
}

fn ppo_progress<'a>(ctx: &'a StageCtx<'a>, total: usize) -> impl FnMut(&ppo::PpoProgress) + 'a {
    ctx.progress.set_length(total as u64);
    move |p: &ppo::PpoProgress| {
        ctx.progress.set_position(p.global_step as u64);
        if let Some(r) = p.episodic_return {
            ctx.progress.set_message(format!("return {r:.0}"));
        }
    }
}

fn demonstrator(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let mut cfg: ppo::PpoConfig = ctx.param("ppo")?;
    cfg.threads = ctx.threads;
    let target: Option<f64> = ctx.param("target_return")?;
    let mut show = ppo_progress(ctx, cfg.total_steps);
    let mut reached = None;
    let mut on_update = |p: &ppo::PpoProgress| {
        show(p);
        match (target, p.eval) {
            (Some(t), Some(e)) if e.mean >= t => {
                reached = Some(p.global_step);
                false
            }
            _ => true,
        }
    };
    let res = ppo::train(id, &cfg, ppo::RewardSource::GroundTruth, ctx.seed, &mut on_update, None)?;
    res.policy.save(&ctx.out.join(POLICY), serde_json::to_value(&cfg).unwrap_or_default())?;
    let last = res.curve.last();
    Ok(json!({"steps": last.map_or(0, |p| p.global_step), "stopped_at_target": reached, "wall_s": res.wall_s,
              "final_eval": last.and_then(|p| p.eval.map(|e| e.mean))}))
}

/// `episodes` rollouts of the stage's input `policy` (PPO policies sample, BC acts with its
/// mean), episode k from a reset seeded with `episode_seed(seed, k)`.
fn policy_rollouts(ctx: &StageCtx, id: EnvId, seed: u64, source: &str) -> Result<Vec<Trajectory>> {
    let episodes: usize = ctx.param("episodes")?;
    let policy = load_policy(ctx.input("policy")?)?;
    let mut env = Env::new(id)?;
    policy.expect_dims(env.obs_dim(), env.act_dim(), id.name())?;
    let mut actor = actor_of(&policy);
    let meta = TrajMeta { source: source.into(), ..Default::default() };
    Ok((0..episodes).map(|k| rollout::episode(&mut env, &mut actor, episode_seed(seed, k as u64), meta.clone())).collect())
}

fn demos(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let trajs = policy_rollouts(ctx, id, ctx.seed, "demonstrator")?;
    write_rollouts(ctx, id, &trajs, None)?;
    Ok(returns_summary(&trajs))
}

fn demos_import(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let path: PathBuf = ctx.param("path")?;
    let trajs = if path.extension().is_some_and(|e| e == "mcap") {
        mcap::read(&path)?.trajectories
    } else {
        crate::data::npz::read(&path, "imported")?
    };
    let env = Env::new(id)?;
    if let Some(t) = trajs.first()
        && (t.obs_dim, t.act_dim) != (env.obs_dim(), env.act_dim())
    {
        return Err(Error::file(
            &path,
            format!("has {}-dim observations and {}-dim actions; {id} has {} and {}", t.obs_dim, t.act_dim, env.obs_dim(), env.act_dim()),
        ));
    }
    write_rollouts(ctx, id, &trajs, None)?;
    Ok(returns_summary(&trajs))
}

fn bc_stage(ctx: &StageCtx) -> Result<Value> {
    let cfg: bc::BcConfig = ctx.param("bc")?;
    let trajs = read_rollouts(ctx.input("demos")?)?;
    ctx.progress.set_message("behavioural cloning");
    let (mut policy, report) = bc::train(&trajs, &cfg, ctx.seed)?;
    policy.env = Some(ctx.env()?.name().to_string());
    policy.save(&ctx.out.join(POLICY), serde_json::to_value(&cfg).unwrap_or_default())?;
    Ok(serde_json::to_value(report).unwrap_or_default())
}

/// Rollouts of `actor` for each level, `per_level` each, numbered from `first_episode`.
fn levels<A: Actor>(
    env: &mut Env,
    seed: u64,
    levels: &[f64],
    per_level: usize,
    first_episode: u64,
    meta: &TrajMeta,
    mut make: impl FnMut(f64) -> A,
) -> Vec<Trajectory> {
    let mut out = Vec::new();
    let mut k = first_episode;
    for &level in levels {
        let mut actor = make(level);
        for _ in 0..per_level {
            out.push(rollout::episode(env, &mut actor, episode_seed(seed, k), TrajMeta { noise: level, ..meta.clone() }));
            k += 1;
        }
    }
    out
}

fn epsilon_rollouts(
    env: &mut Env,
    policy: &ActorCritic,
    schedule: &[f64],
    per_level: usize,
    seed: u64,
    meta: &TrajMeta,
) -> Vec<Trajectory> {
    let (low, high) = env.action_bounds();
    let (low, high) = (low.to_vec(), high.to_vec());
    levels(env, seed, schedule, per_level, 0, meta, |eps| EpsilonGreedy {
        inner: PolicyActor::new(policy.to_cpu(), false),
        eps,
        uniform: UniformActor { low: low.clone(), high: high.clone() },
    })
}

fn noise_rollouts(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let schedule: Vec<f64> = ctx.param("schedule")?;
    let per_level: usize = ctx.param("rollouts_per_level")?;
    let policy = load_policy(ctx.input("policy")?)?;
    let mut env = Env::new(id)?;
    policy.expect_dims(env.obs_dim(), env.act_dim(), id.name())?;
    ctx.progress.set_message("epsilon-greedy rollouts");
    let trajs =
        epsilon_rollouts(&mut env, &policy, &schedule, per_level, ctx.seed, &TrajMeta { source: "bc".into(), ..Default::default() });
    write_rollouts(ctx, id, &trajs, None)?;
    Ok(json!({"degradation": degradation(&trajs), "returns": returns_summary(&trajs)}))
}

fn trex_stage(ctx: &StageCtx) -> Result<Value> {
    let cfg: trex::TrexConfig = ctx.param("trex")?;
    let ctrl: f64 = ctx.param("ctrl_coeff")?;
    let sets: Vec<Value> = ctx.param("sets")?;
    let cross_level = ctx.params.get("cross_level").and_then(Value::as_bool).unwrap_or(false);
    let mut trajs = Vec::new();
    let mut ranking = Ranking { same_group: true, cross_level, ..Default::default() };
    for (i, dir) in ctx.numbered("set").into_iter().enumerate() {
        let level = sets.get(i).and_then(|s| s["level"].as_u64()).unwrap_or(0) as usize;
        let grouped = sets.get(i).and_then(|s| s["same_group"].as_bool()).unwrap_or(false) || cfg.same_group;
        for t in read_rollouts(dir)? {
            // Lower noise ranks higher; comparisons stay within a set (and within a source
            // group of it: one clone, one source policy), except across levels.
            ranking.scores.push(-t.meta.noise);
            ranking.groups.push(i * 10_000 + if grouped || level > 0 { t.meta.group } else { 0 });
            ranking.levels.push(level);
            trajs.push(t);
        }
    }
    ctx.progress.set_message(format!("T-REX on {} trajectories", trajs.len()));
    let (model, reports) = trex::train(&trajs, &ranking, &cfg, ctrl, ctx.seed)?;
    model.save(&ctx.out.join(REWARD), json!({"trex": cfg}))?;
    let pred: Vec<f64> = trajs.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
    let truth: Vec<f64> = trajs.iter().map(Trajectory::ret).collect();
    let demos = read_rollouts(ctx.input("demos")?)?;
    let demo_pred: Vec<f64> = demos.iter().map(|t| model.predicted_return(t.next_obs(), &t.actions)).collect();
    Ok(json!({
        "models": reports,
        "train_set": {"predicted": pred, "true": truth, "noise": trajs.iter().map(|t| t.meta.noise).collect::<Vec<_>>(),
                      "level": ranking.levels, "spearman": spearman(&pred, &truth), "pearson": pearson(&pred, &truth)},
        "demos": {"predicted": demo_pred, "true": demos.iter().map(Trajectory::ret).collect::<Vec<_>>()},
        "val_accuracy": reports.iter().map(|r| r.val_accuracy).sum::<f64>() / reports.len() as f64,
    }))
}

fn ppo_stage(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let mut cfg: ppo::PpoConfig = ctx.param("ppo")?;
    cfg.threads = ctx.threads;
    let reward = RewardEnsemble::load(&ctx.input("reward")?.join(REWARD))?;
    let mut show = ppo_progress(ctx, cfg.total_steps);
    let res = ppo::train(
        id,
        &cfg,
        ppo::RewardSource::Learned(reward),
        ctx.seed,
        &mut |p| {
            show(p);
            true
        },
        None,
    )?;
    res.policy.save(&ctx.out.join(POLICY), serde_json::to_value(&cfg).unwrap_or_default())?;
    let mut csv = String::from("global_step,episodic_return,learned_return,policy_loss,value_loss,approx_kl,sps\n");
    for p in &res.curve {
        let f = |x: Option<f64>| x.map_or(String::new(), |v| v.to_string());
        csv.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            p.global_step,
            f(p.episodic_return),
            f(p.learned_return),
            p.policy_loss,
            p.value_loss,
            p.approx_kl,
            p.sps
        ));
    }
    std::fs::write(ctx.out.join("curve.csv"), csv).map_err(|e| Error::io(ctx.out, e))?;
    let curve: Vec<Value> = res.curve.iter().map(|p| json!([p.global_step, p.episodic_return, p.learned_return])).collect();
    Ok(json!({"wall_s": res.wall_s, "steps_per_s": res.curve.last().map_or(0, |p| p.global_step) as f64 / res.wall_s, "curve": curve}))
}

fn eval(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let trajs = policy_rollouts(ctx, id, ctx.seed ^ 0xe7a1, "eval")?;
    let mut out = returns_summary(&trajs);
    let mut learned = None;
    if let Some(dir) = ctx.inputs.get("reward") {
        let model = RewardEnsemble::load(&dir.join(REWARD))?;
        let per_step: Vec<Vec<f64>> = trajs
            .iter()
            .map(|t| {
                let raw = model.raw(t.next_obs(), &t.actions);
                (0..t.len()).map(|s| raw.iter().map(|m| m[s] as f64).sum::<f64>() / raw.len() as f64).collect()
            })
            .collect();
        let pred: Vec<f64> = per_step.iter().map(|r| r.iter().sum()).collect();
        let truth: Vec<f64> = trajs.iter().map(Trajectory::ret).collect();
        out["predicted_returns"] = json!(pred);
        out["spearman"] = json!(spearman(&pred, &truth));
        out["pearson"] = json!(pearson(&pred, &truth));
        out["pairwise_accuracy"] = json!(pairwise_accuracy(&pred, &truth));
        learned = Some(per_step);
    }
    write_rollouts(ctx, id, &trajs, learned.as_deref())?;
    out["method"] = ctx.params["method"].clone();
    out["run"] = ctx.params["run"].clone();
    out["env"] = json!(id.name());
    Ok(out)
}

fn interpolation(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let alphas: Vec<f64> = ctx.param("alphas")?;
    let per_level: usize = ctx.param("rollouts_per_level")?;
    let mut env = Env::new(id)?;
    let (newer, older) = (ctx.numbered("policy"), ctx.numbered("older"));
    let mut trajs = Vec::new();
    for (r, (n, o)) in newer.iter().zip(&older).enumerate() {
        let (pn, po) = (load_policy(n)?, load_policy(o)?);
        let meta = TrajMeta { source: format!("interpolation/{r}"), group: r, ..Default::default() };
        // Ranked by alpha; stored as noise = 1 - alpha so that lower noise ranks higher.
        let levels_noise: Vec<f64> = alphas.iter().map(|a| 1.0 - a).collect();
        trajs.extend(levels(&mut env, episode_seed(ctx.seed, r as u64), &levels_noise, per_level, 0, &meta, |noise| Interpolation {
            newer: actor_of(&pn),
            older: actor_of(&po),
            alpha: 1.0 - noise,
        }));
    }
    write_rollouts(ctx, id, &trajs, None)?;
    Ok(json!({"degradation": degradation(&trajs)}))
}

fn action_noise(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let sigmas: Vec<f64> = ctx.param("sigmas")?;
    let kind: String = ctx.param("noise")?;
    let per_level: usize = ctx.param("rollouts_per_level")?;
    let mut env = Env::new(id)?;
    let ad = env.act_dim();
    let mut trajs = Vec::new();
    for (r, dir) in ctx.numbered("policy").into_iter().enumerate() {
        let p = load_policy(dir)?;
        let meta = TrajMeta { source: format!("action-noise/{r}"), group: r, ..Default::default() };
        let seed = episode_seed(ctx.seed, r as u64);
        // The policy's mean action plus noise of the given scale (the report's equation 9).
        let base = || PolicyActor::new(p.to_cpu(), false);
        trajs.extend(match kind.as_str() {
            "ou" => levels(&mut env, seed, &sigmas, per_level, 0, &meta, |s| OrnsteinUhlenbeck::new(base(), s, ad)),
            "time-correlated" => levels(&mut env, seed, &sigmas, per_level, 0, &meta, |s| TimeCorrelated::new(base(), s, 10, ad)),
            _ => levels(&mut env, seed, &sigmas, per_level, 0, &meta, |s| GaussianNoise { inner: base(), sigma: s }),
        });
    }
    write_rollouts(ctx, id, &trajs, None)?;
    Ok(json!({"degradation": degradation(&trajs)}))
}

/// iD-REX variant 3. For each of the previous iteration's policies: one trajectory, a BC
/// clone of it, and epsilon-greedy rollouts of the clone (group = the clone). A clone is
/// kept only if its noise-free rollouts score at least as high under the previous learned
/// reward as the previous set's noise-free rollouts (the automatic version of the report's
/// hand filtering; the ground-truth reward is never consulted).
fn multi_bc(ctx: &StageCtx) -> Result<Value> {
    let id = ctx.env()?;
    let cfg: bc::BcConfig = ctx.param("bc")?;
    let schedule: Vec<f64> = ctx.param("schedule")?;
    let per_level: usize = ctx.param("rollouts_per_level")?;
    let reward = RewardEnsemble::load(&ctx.input("reward")?.join(REWARD))?;
    let baseline = read_rollouts(ctx.input("baseline")?)?;
    let min_noise = |ts: &[Trajectory]| ts.iter().map(|t| t.meta.noise).fold(f64::INFINITY, f64::min);
    let clean_score = |ts: &[Trajectory]| {
        let m = min_noise(ts);
        let scores: Vec<f64> = ts.iter().filter(|t| t.meta.noise == m).map(|t| reward.predicted_return(t.next_obs(), &t.actions)).collect();
        scores.iter().sum::<f64>() / scores.len().max(1) as f64
    };
    let threshold = clean_score(&baseline);
    let mut env = Env::new(id)?;
    let mut kept = Vec::new();
    let mut report = Vec::new();
    for (r, dir) in ctx.numbered("policy").into_iter().enumerate() {
        let p = load_policy(dir)?;
        let demo = rollout::episode(
            &mut env,
            &mut actor_of(&p),
            episode_seed(ctx.seed, 10_000 + r as u64),
            TrajMeta { source: format!("multi-bc/{r}/demo"), ..Default::default() },
        );
        let (clone, _) = bc::train(std::slice::from_ref(&demo), &cfg, episode_seed(ctx.seed, r as u64))?;
        let meta = TrajMeta { source: format!("multi-bc/{r}"), group: r, ..Default::default() };
        let trajs = epsilon_rollouts(&mut env, &clone, &schedule, per_level, episode_seed(ctx.seed, 20_000 + r as u64), &meta);
        let score = clean_score(&trajs);
        let keep = score >= threshold;
        report.push(json!({"clone": r, "predicted_clean_return": score, "kept": keep}));
        if keep {
            kept.extend(trajs);
        }
    }
    write_rollouts(ctx, id, &kept, None)?;
    Ok(json!({"threshold": threshold, "clones": report, "degradation": degradation(&kept)}))
}
