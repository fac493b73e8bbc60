//! `idrex bench clones`: multi-BC's clone levers measured on a pipeline's stored D-REX runs.
//! Each variant clones every run's policy with [`clone::make`] (the stage's own code) and
//! reports the clones' fidelity: their noise-free true return normalised so that the
//! uniform-random policy scores 0 and the source's episodes 1, and their length against the
//! source's. The true return judges the levers here; the stage never reads it.
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;

use crate::algo::bc::BcConfig;
use crate::env::Env;
use crate::pipeline::config::{CloneConfig, CloneLabels, CloneSource, SourceActing};
use crate::pipeline::stage::idrex::clone;
use crate::pipeline::stage::idrex::multi_bc;
use crate::pipeline::{Pipeline, expand};
use crate::stats::median;
use crate::store::Store;

#[derive(Debug, clap::Args)]
pub struct ClonesBenchArgs {
    /// A pipeline file whose D-REX runs are stored: their policies are the sources.
    pub file: PathBuf,
    /// Store directory or `s3://bucket/prefix` (overrides the file's `store`).
    #[arg(long)]
    pub store: Option<String>,
    /// Lever settings to compare, in order (default: all).
    #[arg(long = "variant", value_enum)]
    pub variants: Vec<Lever>,
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Also write every clone's record as JSON lines here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The settings compared, each adding one lever to the previous (the first is the code
/// before the levers: the report's one sampled trajectory and the demonstrations' BC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Lever {
    /// A stochastic episode, its sampled actions as labels, 50,000 BC iterations on a 20 %
    /// split of its steps, libtorch's initialisation, raw observations.
    Original,
    /// + early stopping on a held-out source episode (at most 20,000 iterations).
    EarlyStopping,
    /// + the source's mean actions as labels.
    MeanLabels,
    /// + a deterministic (mean-action) source episode.
    Deterministic,
    /// + N(0, 0.02^2) weights and zero biases (the original code's BC).
    NormalInit,
    /// + observations normalised with the source's statistics.
    Normalize,
    /// + 4 source episodes instead of 1: today's default.
    FourEpisodes,
    /// The default, cloning the checkpoint the ground-truth-free protocol picks.
    Checkpoint,
}

impl Lever {
    const ALL: [Lever; 8] = [
        Lever::Original,
        Lever::EarlyStopping,
        Lever::MeanLabels,
        Lever::Deterministic,
        Lever::NormalInit,
        Lever::Normalize,
        Lever::FourEpisodes,
        Lever::Checkpoint,
    ];

    pub fn config(self) -> CloneConfig {
        let default = CloneConfig::default();
        let original = CloneConfig {
            source: CloneSource::Final,
            acting: SourceActing::Stochastic,
            labels: CloneLabels::Sampled,
            episodes: 1,
            held_out_episodes: 0,
            normalize: false,
            bc: BcConfig::default(),
            fidelity_episodes: default.fidelity_episodes,
        };
        let stopping = CloneConfig {
            held_out_episodes: default.held_out_episodes,
            bc: BcConfig { init: BcConfig::default().init, ..default.bc.clone() },
            ..original.clone()
        };
        match self {
            Lever::Original => original,
            Lever::EarlyStopping => stopping,
            Lever::MeanLabels => CloneConfig { labels: CloneLabels::Mean, ..stopping },
            Lever::Deterministic => CloneConfig { labels: CloneLabels::Mean, acting: SourceActing::Deterministic, ..stopping },
            Lever::NormalInit => CloneConfig { normalize: false, episodes: 1, ..default },
            Lever::Normalize => CloneConfig { episodes: 1, ..default },
            Lever::FourEpisodes => default,
            Lever::Checkpoint => CloneConfig { source: CloneSource::Checkpoint, ..default },
        }
    }
}

#[derive(Debug, serde::Serialize)]
struct Row {
    group: String,
    lever: Lever,
    record: clone::CloneRecord,
    seconds: f64,
}

/// Runs the bench on `p`'s stored D-REX runs in `store` (the CLI loads both from `args`).
pub fn clones_bench(args: &ClonesBenchArgs, p: &Pipeline, store: &Store) -> anyhow::Result<()> {
    let g = expand(p)?;
    let keys = g.keys();
    // The D-REX runs of each environment and replicate: `<group>drex/ppo/<r>`.
    let mut groups: std::collections::BTreeMap<String, Vec<(usize, String)>> = Default::default();
    for n in &g.nodes {
        if let Some((group, run)) = n.name.rsplit_once("drex/ppo/")
            && (group.is_empty() || group.ends_with('/'))
            && let Ok(run) = run.parse::<usize>()
        {
            groups.entry(group.to_string()).or_default().push((run, n.name.clone()));
        }
    }
    anyhow::ensure!(!groups.is_empty(), "{} has no D-REX runs to clone; add drex to its methods", args.file.display());
    let levers = if args.variants.is_empty() { Lever::ALL.to_vec() } else { args.variants.clone() };
    let mut out = match &args.json {
        Some(path) => Some(std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?),
        None => None,
    };
    println!("group | lever | clone | source return (length) | clone return (length) | fidelity | BC iterations kept/run | s");
    let mut summary = Vec::new();
    for (group, runs) in &groups {
        let node = g.get(&runs[0].1).expect("a graph node");
        let crate::pipeline::stage::Params::Ppo(pp) = &node.params else { unreachable!("a PPO node") };
        let id = pp.env;
        let mut env = Env::new(id)?;
        let dirs = runs
            .iter()
            .map(|(_, name)| store.input_dir(&keys[name]).with_context(|| format!("{group}: {name} is not stored; run the pipeline first")))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let evals = runs.iter().map(|(_, name)| store.input_dir(&keys[&name.replace("/ppo/", "/eval/")])).collect::<Result<Vec<_>, _>>();
        for &lever in &levers {
            let cfg = lever.config();
            let step = match cfg.source {
                CloneSource::Final => None,
                CloneSource::Checkpoint => {
                    let evals = evals.as_ref().map_err(|e| anyhow::anyhow!("{group}: the D-REX evaluations are not stored: {e}"))?;
                    Some(multi_bc::chosen_step(&evals.iter().map(PathBuf::as_path).collect::<Vec<_>>())?)
                }
            };
            let random = clone::random_return(&mut env, cfg.fidelity_episodes, node.seed);
            let mut fid = Vec::new();
            for (r, dir) in dirs.iter().enumerate() {
                let t0 = Instant::now();
                let cloning = crate::log::progress::Activity::start(format!("bench clones: {group}, {lever:?}, clone {r}"));
                let made = clone::make(&mut env, dir, step, &cfg, id, node.seed, r, args.threads, crate::nn::Device::Cpu)?;
                drop(cloning);
                let seconds = t0.elapsed().as_secs_f64();
                let fidelity = crate::algo::scoring::Fidelity::of(&made.source_episodes, &made.fidelity_episodes, random);
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
                let len = |v: &[usize]| v.iter().sum::<usize>() as f64 / v.len().max(1) as f64;
                println!(
                    "{group} | {lever:?} | {r} | {:.1} ({:.0}) | {:.1} ({:.0}) | {:.2} | {}/{} | {seconds:.1}",
                    mean(&fidelity.source_returns),
                    len(&fidelity.source_lengths),
                    mean(&fidelity.clone_returns),
                    len(&fidelity.clone_lengths),
                    fidelity.normalised,
                    made.report.best_iteration.map_or("-".into(), |i| i.to_string()),
                    made.report.iterations_run.unwrap_or(cfg.bc.iterations),
                );
                if fidelity.normalised.is_finite() {
                    fid.push(fidelity.normalised);
                }
                let row = Row {
                    group: group.clone(),
                    lever,
                    record: clone::CloneRecord {
                        clone: r,
                        source_step: step,
                        fidelity,
                        bc: made.report,
                        score: None,
                        previous_reward_score: None,
                        kept: true,
                    },
                    seconds,
                };
                if let Some(f) = out.as_mut() {
                    use std::io::Write;
                    writeln!(f, "{}", serde_json::to_string(&row)?)?;
                }
            }
            summary.push(format!("{group} | {lever:?} | median fidelity {:.2} over {} clones", median(&fid), fid.len()));
        }
    }
    println!();
    for line in summary {
        println!("{line}");
    }
    Ok(())
}
