//! `idrex logs list|show|export`: reopen MCAP rollout files.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Subcommand;

use crate::log::export::{self, ExportFormat};
use crate::log::mcap;

#[derive(Debug, Subcommand)]
pub enum LogsCommand {
    /// Episodes with length, return and noise level.
    List { file: PathBuf },
    /// The steps of one episode, one JSON line each.
    Show {
        file: PathBuf,
        #[arg(long, default_value_t = 0)]
        episode: usize,
    },
    /// Every step as CSV or NDJSON.
    Export {
        file: PathBuf,
        #[arg(long, value_enum, default_value_t = ExportFormat::Csv)]
        format: ExportFormat,
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn run(cmd: &LogsCommand) -> anyhow::Result<()> {
    match cmd {
        LogsCommand::List { file } => {
            let r = mcap::read(file)?;
            println!("{}: {} episodes of {}", file.display(), r.trajectories.len(), r.env);
            println!("{:>7} {:>7} {:>12} {:>8} {:>6} {:<11} source", "episode", "length", "return", "noise", "group", "end");
            for (i, t) in r.trajectories.iter().enumerate() {
                let end = if t.terminated {
                    "terminated"
                } else if t.truncated {
                    "truncated"
                } else {
                    "-"
                };
                println!("{i:>7} {:>7} {:>12.2} {:>8.3} {:>6} {end:<11} {}", t.len(), t.ret(), t.meta.noise, t.meta.group, t.meta.source);
            }
        }
        LogsCommand::Show { file, episode } => {
            let r = mcap::read(file)?;
            let t = r
                .trajectories
                .get(*episode)
                .with_context(|| format!("{} has {} episodes; --episode {episode} does not exist", file.display(), r.trajectories.len()))?;
            for s in 0..t.len() {
                println!("{}", export::step_json(&r, *episode, s));
            }
        }
        LogsCommand::Export { file, format, out } => {
            let r = mcap::read(file)?;
            let mut w = std::io::BufWriter::new(std::fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?);
            export::export(&r, *format, &mut w).with_context(|| format!("cannot write {}", out.display()))?;
            w.flush()?;
        }
    }
    Ok(())
}
