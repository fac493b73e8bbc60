//! `idrex exp show|diff`: the store's studies at a glance, and two of them side by side.
use anyhow::bail;
use clap::{Args, Subcommand};

use crate::env::EnvId;
use crate::exp::{Study, diff, show, studies};
use crate::log::table::Format;
use crate::report::Protocol;

#[derive(Debug, Subcommand)]
pub enum ExpCommand {
    /// One row per study in the store: replicates and runs, environments and methods, the
    /// resolved parameters that differ between the listed studies, each method's final-policy
    /// mean with its 95 % interval, the idrex version and when it finished.
    Show(ShowArgs),
    /// The resolved parameters that differ between two studies, then per environment and
    /// method the change in score with the probability of improvement, paired by replicate
    /// where the two share seeds. CSV gives the metrics table; JSON gives both.
    Diff(DiffArgs),
}

#[derive(Debug, Args)]
pub struct Output {
    /// Artifact store directory or `s3://bucket/prefix`.
    #[arg(long, default_value = "artifacts")]
    pub store: String,
    /// Headlines under these protocols (repeatable; the final policy by default).
    #[arg(long, value_parser = parse_protocol)]
    pub protocol: Vec<Protocol>,
    #[command(flatten)]
    pub table: super::TableArgs,
}

impl Output {
    fn format(&self) -> Format {
        self.table.format()
    }

    fn protocols(&self) -> Vec<Protocol> {
        if self.protocol.is_empty() { vec![Protocol::Final] } else { self.protocol.clone() }
    }

    fn studies(&self) -> anyhow::Result<Vec<Study>> {
        let store = super::store::existing(&self.store, false, "give --store, or run a pipeline first")?;
        let _reading = crate::log::progress::Activity::start("reading the store's manifests");
        Ok(studies(&crate::report::Artifacts::of(store.unverified_manifests()?)))
    }
}

fn parse_protocol(s: &str) -> Result<Protocol, String> {
    Protocol::ALL
        .into_iter()
        .find(|p| p.name() == s)
        .ok_or_else(|| format!("`{s}` is no protocol; give one of {}", Protocol::ALL.map(Protocol::name).join(", ")))
}

fn parse_env(s: &str) -> Result<EnvId, String> {
    s.parse::<EnvId>().map_err(|e| e.to_string())
}

#[derive(Debug, Args)]
pub struct ShowArgs {
    #[command(flatten)]
    pub out: Output,
    /// Only studies that ran this environment, and only its headlines (repeatable).
    #[arg(long, value_parser = parse_env)]
    pub env: Vec<EnvId>,
    /// Only this method's headlines (repeatable; `drex`, `idrex-multi-bc (k=3)`, ...).
    #[arg(long)]
    pub method: Vec<String>,
    /// Every resolved parameter (defaults included), not only those that differ.
    #[arg(long)]
    pub all_params: bool,
    /// Drop every column whose value is the same in every listed row.
    #[arg(long)]
    pub only_changed: bool,
    /// Keep only columns whose names contain one of these (comma-separated; e.g. `ppo.,drex`).
    #[arg(long, value_delimiter = ',')]
    pub columns: Vec<String>,
}

#[derive(Debug, Args)]
pub struct DiffArgs {
    /// The study compared (a pipeline `name`).
    pub a: String,
    /// The study it is compared with.
    pub b: String,
    #[command(flatten)]
    pub out: Output,
}

pub fn run(cmd: &ExpCommand) -> anyhow::Result<()> {
    match cmd {
        ExpCommand::Show(args) => {
            let all = args.out.studies()?;
            let known: std::collections::BTreeSet<&String> = all.iter().flat_map(|s| &s.methods).collect();
            if let Some(m) = args.method.iter().find(|m| !known.contains(m)) {
                bail!(
                    "--method {m}: no study in {} evaluated it; methods there: {}",
                    args.out.store,
                    known.into_iter().cloned().collect::<Vec<_>>().join(", ")
                );
            }
            let sel = show::Selection {
                envs: args.env.clone(),
                methods: args.method.clone(),
                protocols: args.out.protocols(),
                all_params: args.all_params,
                only_changed: args.only_changed,
                columns: args.columns.clone(),
            };
            print!("{}", show::table(&all, &sel).write(args.out.format()));
            if let Some(hint) = show::hint(&all, &sel).filter(|_| !args.out.table.machine()) {
                println!("{hint}");
            }
        }
        ExpCommand::Diff(args) => {
            let all = args.out.studies()?;
            let find = |name: &str| {
                all.iter().find(|s| s.name == name).ok_or_else(|| {
                    let names: Vec<&str> = all.iter().map(|s| s.name.as_str()).collect();
                    anyhow::anyhow!("no study `{name}` in {}; studies there: {}", args.out.store, names.join(", "))
                })
            };
            let (a, b) = (find(&args.a)?, find(&args.b)?);
            let (params, metrics) = (diff::params(a, b), diff::metrics(a, b, &args.out.protocols()));
            match args.out.format() {
                Format::Csv => print!("{}", metrics.csv()),
                Format::Json => println!("{{\"params\": {}, \"metrics\": {}}}", params.json().trim_end(), metrics.json().trim_end()),
                f => {
                    let md = f == Format::Markdown;
                    let head = |t: &str| if md { format!("## {t}\n\n") } else { format!("{t}\n\n") };
                    println!("{}{}", head(&format!("Parameters that differ ({})", params.rows.len())), params.write(f));
                    print!("{}{}", head(&format!("`{}` against `{}`", a.name, b.name)), metrics.write(f));
                    if f == Format::Text {
                        print!("{}", crate::report::improvement::LEGEND);
                    }
                }
            }
        }
    }
    Ok(())
}
