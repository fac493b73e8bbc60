//! `idrex bank score`: a learned reward's scores on its task's bank of gaits (the reward
//! bench), from the store, before any PPO runs on it.
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use crate::algo::bank::{BankScore, GaitClass};
use crate::log::table::{Cell, Table};
use crate::nn::RewardEnsemble;
use crate::pipeline::role::{Role, recorded_input};
use crate::pipeline::stage::bank::score_reward;
use crate::pipeline::stage::{Metrics, Params, REWARD, StageKind, Typed};
use crate::report::bank::ProbeScore;
use crate::store::{Manifest, Store};

#[derive(Debug, Subcommand)]
pub enum BankCommand {
    /// Score learned rewards on a bank of gaits: Pearson and Spearman against the true
    /// return over the bank and within its forward gaits, and the backward, still or random
    /// gaits each pays more than a truly better forward one; beside them, the store's probe
    /// of each reward where a run with `bank.probe` made one.
    Score(ScoreArgs),
}

#[derive(Debug, Args)]
pub struct ScoreArgs {
    /// T-REX artifacts (a key or a unique prefix of one, 8 characters or more) or reward
    /// directories (holding `reward/`).
    #[arg(required = true)]
    pub rewards: Vec<String>,
    /// Artifact store directory or `s3://bucket/prefix`.
    #[arg(long, default_value = "artifacts")]
    pub store: String,
    /// The bank (a `bank` artifact's key or prefix); default: the store's bank of the reward's
    /// task, where it holds exactly one.
    #[arg(long)]
    pub bank: Option<String>,
    #[command(flatten)]
    pub table: super::TableArgs,
}

pub fn run(cmd: &BankCommand) -> anyhow::Result<()> {
    match cmd {
        BankCommand::Score(args) => score(args),
    }
}

/// The one manifest whose key starts with `prefix`.
fn by_prefix<'a>(manifests: &'a [Manifest], prefix: &str) -> anyhow::Result<&'a Manifest> {
    if prefix.len() < 8 {
        bail!("'{prefix}': give at least 8 characters of an artifact's key");
    }
    let found: Vec<&Manifest> = manifests.iter().filter(|m| m.key.starts_with(prefix)).collect();
    match found.as_slice() {
        [one] => Ok(one),
        [] => bail!("no artifact in the store has a key starting with '{prefix}'"),
        many => bail!("'{prefix}' starts {} artifacts' keys; give more of the key", many.len()),
    }
}

/// The task a T-REX artifact's reward was learned on.
fn env_of(m: &Manifest) -> Option<crate::env::EnvId> {
    match Typed::of(m).ok()?.params {
        Params::Trex(p) => Some(p.env),
        _ => None,
    }
}

fn score(args: &ScoreArgs) -> anyhow::Result<()> {
    let store = super::store::existing(&args.store, false, "give the store that holds the bank with --store")?;
    let manifests = store.manifests()?;
    let banks: Vec<&Manifest> = manifests.iter().filter(|m| m.kind == StageKind::Bank.name()).collect();
    let mut rows = Vec::new();
    for reward in &args.rewards {
        let dir = PathBuf::from(reward);
        let (label, model_dir, env, probe) = if dir.join(REWARD).is_dir() {
            (reward.clone(), dir.join(REWARD), None, None)
        } else {
            let m = by_prefix(&manifests, reward)?;
            if m.kind != StageKind::Trex.name() {
                bail!("{}: a {} artifact, not a learned reward (a trex artifact)", &m.key[..12], m.kind);
            }
            (format!("{} {}", &m.key[..12], m.node), store.input_dir(&m.key)?.join(REWARD), env_of(m), probe_of(&manifests, &m.key))
        };
        let bank = bank_for(&store, &manifests, &banks, args.bank.as_deref(), env)?;
        let model = RewardEnsemble::load(&model_dir).with_context(|| format!("loading the reward in {}", model_dir.display()))?;
        rows.push((label, bank.0, score_reward(&model, &bank.1)?, probe));
    }
    args.table.print(&table(&rows));
    Ok(())
}

/// The store's probe of a reward (`bank.probe`): its true return and its final policy's
/// forward term per episode, where the store holds one; with several (other compositions,
/// seeds or lengths), none: the report pairs each with its own PPO run.
fn probe_of(manifests: &[Manifest], reward: &str) -> Option<ProbeScore> {
    let mut found =
        manifests.iter().filter(|m| m.kind == StageKind::Probe.name() && recorded_input(m, Role::Reward).is_some_and(|k| k == reward));
    let (one, more) = (found.next()?, found.next());
    if more.is_some() {
        eprintln!("{}: several probes of this reward; the report pairs each with its PPO run", &reward[..12]);
        return None;
    }
    match Typed::of(one).ok()?.metrics {
        Metrics::Probe(x) => Some(ProbeScore { true_return: x.true_return, forward: x.final_forward }),
        _ => None,
    }
}

/// The bank to score on: `--bank`, or the store's one bank of `env`; its key and directory.
fn bank_for(
    store: &Store,
    all: &[Manifest],
    banks: &[&Manifest],
    chosen: Option<&str>,
    env: Option<crate::env::EnvId>,
) -> anyhow::Result<(String, PathBuf)> {
    let m = match (chosen, env) {
        (Some(prefix), _) => by_prefix(all, prefix)?,
        (None, Some(env)) => {
            let of_env: Vec<&Manifest> =
                banks.iter().copied().filter(|m| matches!(Typed::of(m).map(|t| t.params), Ok(Params::Bank(p)) if p.env == env)).collect();
            match of_env.as_slice() {
                [one] => *one,
                [] => bail!("the store holds no bank of {}; run a pipeline file with `bank: {{}}` on it first", env.name()),
                _ => bail!("the store holds {} banks of {}; choose one with --bank", of_env.len(), env.name()),
            }
        }
        (None, None) => bail!("a reward directory does not say its task; choose the bank with --bank"),
    };
    if m.kind != StageKind::Bank.name() {
        bail!("{}: a {} artifact, not a bank", &m.key[..12], m.kind);
    }
    Ok((m.key[..12].to_string(), store.input_dir(&m.key)?))
}

/// A scored reward: its label, its bank, its scores and its probe.
type Scored = (String, String, BankScore, Option<ProbeScore>);

fn table(rows: &[Scored]) -> Table {
    let mut columns = vec!["reward", "bank", "pearson", "spearman", "forward_pearson", "forward_spearman"];
    columns.extend(["overpaid_backward", "overpaid_still", "overpaid_random", "misordered"]);
    columns.extend(["pay_forward", "pay_backward", "pay_still", "pay_random", "probe_return", "probe_forward"]);
    let x = |v: f64| Cell::opt(Some(v).filter(|v| v.is_finite()), 3);
    let rows = rows
        .iter()
        .map(|(reward, bank, s, probe)| {
            let mut r =
                vec![Cell::text(reward), Cell::text(bank), x(s.pearson), x(s.spearman), x(s.forward_pearson), x(s.forward_spearman)];
            r.extend([GaitClass::Backward, GaitClass::Still, GaitClass::Random].map(|c| Cell::int(s.overpaid_of(c))));
            r.push(x(s.misordered));
            let pay = |c: GaitClass| s.per_class.iter().find(|p| p.class == c).map_or(f64::NAN, |p| p.learned_per_step);
            r.extend(GaitClass::ALL.map(|c| x(pay(c))));
            let one = |v: f64| Cell::opt(Some(v).filter(|v| v.is_finite()), 1);
            r.extend([probe.map_or(f64::NAN, |p| p.true_return), probe.map_or(f64::NAN, |p| p.forward)].map(one));
            r
        })
        .collect();
    Table { columns: columns.into_iter().map(String::from).collect(), rows }
}
