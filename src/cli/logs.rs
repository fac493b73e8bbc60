//! `idrex logs list|show|export`: reopen MCAP rollout files.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Subcommand;

use crate::log::table::{Cell, Table};
use crate::rollout::export::{self, ExportFormat};
use crate::rollout::mcap;

#[derive(Debug, Subcommand)]
pub enum LogsCommand {
    /// Episodes with length, return and noise level.
    List {
        file: PathBuf,
        #[command(flatten)]
        table: super::TableArgs,
    },
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
        LogsCommand::List { file, table } => {
            let r = mcap::read(file)?;
            if !table.machine() {
                println!("{}: {} episodes of {}", file.display(), r.trajectories.len(), r.env);
            }
            let rows = r.trajectories.iter().enumerate().map(|(i, t)| {
                let end = if t.terminated {
                    "terminated"
                } else if t.truncated {
                    "truncated"
                } else {
                    "-"
                };
                vec![
                    Cell::int(i),
                    Cell::int(t.len()),
                    Cell::opt(Some(t.ret()), 2),
                    Cell::opt(Some(t.meta.noise), 3),
                    Cell::int(t.meta.group),
                    Cell::text(end),
                    Cell::text(&t.meta.source),
                ]
            });
            let columns = ["episode", "length", "return", "noise", "group", "end", "source"].map(String::from).to_vec();
            table.print(&Table { columns, rows: rows.collect() });
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
