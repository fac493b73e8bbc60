//! `idrex report`: the comparison tables from the store.
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReportFormat {
    Csv,
    Md,
    Both,
}

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Artifact store directory or `s3://bucket/prefix`.
    #[arg(long, default_value = "artifacts")]
    pub store: String,
    #[arg(long, value_enum, default_value_t = ReportFormat::Both)]
    pub format: ReportFormat,
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let store =
        super::store::existing(&args.store, false, "run a pipeline first (`idrex pipeline run pipelines/smoke.yaml`) or give --store")?;
    let store = crate::report::Artifacts::read(&store)?;
    let mut t = crate::report::build(&store)?;
    if t.returns.height() == 0 {
        bail!("{} holds no evaluation results yet; run a pipeline first (`idrex pipeline run pipelines/smoke.yaml`)", args.store);
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    if args.format != ReportFormat::Md {
        crate::report::write_csv(&mut t.returns, &args.out.join("returns.csv"))?;
        crate::report::write_csv(&mut t.demos, &args.out.join("demos.csv"))?;
        crate::report::write_csv(&mut t.accuracy, &args.out.join("reward_accuracy.csv"))?;
        crate::report::write_csv(&mut crate::report::protocols_frame(&t.protocols)?, &args.out.join("protocols.csv"))?;
        if !t.aggregate.is_empty() {
            crate::report::write_csv(&mut crate::report::studies::aggregate_frame(&t.aggregate)?, &args.out.join("aggregate.csv"))?;
            crate::report::write_csv(&mut crate::report::studies::improvement_frame(&t.improvement)?, &args.out.join("improvement.csv"))?;
        }
        if !t.clones.is_empty() {
            crate::report::write_csv(&mut crate::report::clones::frame(&t.clones)?, &args.out.join("clones.csv"))?;
        }
    }
    let figures = crate::report::figures::write(&store, &t.protocols, &t.aggregate, &t.clones, &args.out.join("figures"))?;
    let notes = crate::report::notes(&store)?;
    let md = format!("{}{notes}{}", crate::report::markdown(&t), crate::report::figures::markdown(&figures, "figures"));
    if args.format != ReportFormat::Csv {
        std::fs::write(args.out.join("report.md"), &md)?;
    }
    print!("{md}");
    Ok(())
}
