//! `idrex report`: the comparison tables from the store.
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReportFormat {
    Csv,
    Md,
    /// CSV and markdown.
    Both,
    /// One self-contained page, `report.html`: sortable tables, figures inline, details
    /// folded, links to the rollouts and recordings.
    Html,
    /// Every table as JSON (`returns.json`, ...: an array of objects, keys in column order).
    Json,
}

/// What the command prints when it has written the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Print {
    /// The whole markdown report.
    All,
    /// The answer, then where the report, the page, the recordings and the store are.
    Answer,
    Nothing,
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
    /// Compare two replicated studies method by method, paired by replicate
    /// (`comparisons.csv`); repeatable.
    #[arg(long, value_name = "STUDY:BASELINE")]
    pub compare: Vec<String>,
    /// The figures' files (`svg` for what is committed: half the size, and it scales).
    #[arg(long, value_enum, default_value_t = crate::report::figures::FigureFormats::Both)]
    pub figures: crate::report::figures::FigureFormats,
    /// Which replicates' tables get their own figures (`first` for a committed report of
    /// many replicates; the study's intervals and profile are always drawn).
    #[arg(long, value_enum, default_value_t = crate::report::figures::ReplicateFigures::All)]
    pub replicate_figures: crate::report::figures::ReplicateFigures,
    /// An archive of a study's manifests (`idrex export`) to report with the store's results
    /// (repeatable); with archives only, the store may be absent.
    #[arg(long, value_name = "FILE.ndjson")]
    pub archive: Vec<PathBuf>,
    /// A Rerun recording the HTML page links to (repeatable).
    #[arg(long, value_name = "FILE.rrd")]
    pub recording: Vec<PathBuf>,
    /// The answer warns where BC ends below this fraction of its demonstrations' average
    /// return (a pipeline file's `eval.bc_warning`).
    #[arg(long, default_value_t = crate::algo::scoring::BC_WARNING)]
    pub bc_warning: f64,
    /// What to print on the terminal (the files are written the same).
    #[arg(long, value_enum, default_value_t = Print::All)]
    pub print: Print,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let absent = matches!(crate::store::Location::parse(&args.store)?, crate::store::Location::Local(d) if !d.is_dir());
    let handle = if absent && !args.archive.is_empty() {
        None
    } else {
        Some(super::store::existing(
            &args.store,
            false,
            "run a pipeline first (`idrex pipeline run pipelines/smoke.yaml`), give --store, or report from --archive files",
        )?)
    };
    let mut store = match &handle {
        Some(h) => crate::report::Artifacts::read(h)?,
        None => crate::report::Artifacts::default(),
    };
    for a in &args.archive {
        let added = store.add_archive(a)?;
        tracing::info!("{}: {added} artifacts not in the store", a.display());
    }
    let building = crate::log::progress::Activity::start("report: tables, intervals and figures");
    let mut t = crate::report::build(&store)?;
    t.bc_warning = args.bc_warning;
    t.with_terms(crate::report::terms::rows(&store, handle.as_ref()));
    if t.returns.is_empty() {
        bail!(
            "{} holds no evaluation results yet; run a pipeline first (`idrex pipeline run pipelines/smoke.yaml`)",
            if handle.is_some() { args.store.clone() } else { "the archives".into() }
        );
    }
    let mut comparisons = Vec::new();
    for pair in &args.compare {
        use crate::report::comparisons;
        let Some((study, baseline)) = pair.split_once(':') else {
            bail!("--compare {pair}: give STUDY:BASELINE, two study names of the report joined by a colon");
        };
        let rows = comparisons::compare(&t.aggregate, study, baseline);
        if rows.is_empty() {
            let mut names: Vec<&str> = t.aggregate.iter().map(|a| a.study.as_str()).collect();
            names.sort_unstable();
            names.dedup();
            bail!("--compare {pair}: no method of both studies on a shared replicate; replicated studies here: {}", names.join(", "));
        }
        comparisons.extend(rows);
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut files = t.files();
    if !comparisons.is_empty() {
        files.push(("comparisons", crate::log::table::Table::of(&comparisons)));
    }
    for (stem, table) in &files {
        let (ext, text) = match args.format {
            ReportFormat::Csv | ReportFormat::Both => ("csv", table.csv()),
            ReportFormat::Json => ("json", table.json()),
            ReportFormat::Md | ReportFormat::Html => continue,
        };
        let path = args.out.join(format!("{stem}.{ext}"));
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    let figures = crate::report::figures::write(
        &store,
        &t.protocols,
        &t.aggregate,
        &t.clones,
        &args.out.join("figures"),
        (args.figures, args.replicate_figures),
    )?;
    let notes = crate::report::notes(&store)?;
    drop(building);
    let md = format!(
        "{}{}{notes}{}",
        crate::report::markdown(&t),
        crate::report::comparisons::comparison_markdown(&comparisons),
        crate::report::figures::markdown(&figures, "figures", args.figures)
    );
    if matches!(args.format, ReportFormat::Md | ReportFormat::Both) {
        std::fs::write(args.out.join("report.md"), &md)?;
    }
    if args.format == ReportFormat::Html {
        use crate::report::html;
        let recordings = args.recording.iter().map(|r| std::fs::canonicalize(r).unwrap_or(r.clone()).display().to_string()).collect();
        let links = html::Links { rollouts: html::rollout_links(&store, handle.as_ref()), recordings };
        let page = args.out.join("report.html");
        std::fs::write(&page, html::page(&md, &args.out, &links)).with_context(|| format!("cannot write {}", page.display()))?;
        eprintln!("wrote {}", page.display());
    }
    match args.print {
        Print::All => print!("{md}"),
        Print::Answer => print!("{}{}", crate::report::answer_markdown(&t), whereabouts(args)),
        Print::Nothing => {}
    }
    Ok(())
}

/// Where everything the run and the report wrote is, for the end of a terminal answer.
fn whereabouts(args: &ReportArgs) -> String {
    let mut lines = vec![String::from("\nWhere everything is:")];
    let mut add = |path: std::path::PathBuf, what: &str| {
        if path.exists() {
            lines.push(format!("  {:<44} {what}", path.display()));
        }
    };
    add(args.out.join("report.md"), "every table and figure (the CSV files beside it)");
    add(args.out.join("report.html"), "the report as one page, for a browser");
    for r in &args.recording {
        add(r.clone(), "the plots: .idrex/venv/bin/rerun FILE");
    }
    if !args.store.starts_with("s3://") {
        add(std::path::PathBuf::from(&args.store), "the store: idrex exp show --store DIR");
    } else {
        lines.push(format!("  {:<44} the store: idrex exp show --store URL", args.store));
    }
    lines.join("\n") + "\n"
}
