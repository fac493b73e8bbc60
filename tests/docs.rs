//! The README and the pages beside it stay true: every relative link resolves, every `idrex`
//! command they show parses whole (subcommands, flags and the types of their values, with
//! placeholders replaced by samples), and every field of the pipeline schema is on the
//! schema page.
use std::path::{Path, PathBuf};

use crate::util::repo;

fn pages() -> Vec<PathBuf> {
    let mut out = vec![repo("README.md"), repo("analysis/results/README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(repo("docs")).unwrap().flatten().map(|e| e.path()).collect();
    docs.retain(|p| p.extension().is_some_and(|e| e == "md"));
    docs.sort();
    assert!(docs.len() >= 6, "{docs:?}");
    out.extend(docs);
    out
}

/// The targets of `[text](target)` links that are neither URLs nor anchors.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = rest[..end].split('#').next().unwrap_or_default();
        if !target.is_empty() && !target.contains("://") && !target.contains(' ') {
            out.push(target.to_string());
        }
        rest = &rest[end..];
    }
    out
}

#[test]
fn every_link_resolves() {
    let mut checked = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for target in links(&text) {
            let path = page.parent().unwrap().join(&target);
            assert!(path.exists(), "{}: the link {target} goes nowhere", page.display());
            checked += 1;
        }
    }
    assert!(checked >= 12, "{checked} links");
}

/// The concrete command lines a shown synopsis stands for: after `idrex ` or `./dev `, with
/// the comment cut, every optional `[...]` group included, `...` dropped, each placeholder
/// (FILE, N, ...) replaced by a sample of its type, and one line per choice of `a|b|c`.
/// None for lines that are not idrex commands (`./dev main`, `./dev test`).
fn concrete_commands(line: &str) -> Option<Result<Vec<Vec<String>>, String>> {
    let line = line.trim();
    let rest = line.strip_prefix("idrex ").or_else(|| line.strip_prefix("./dev "))?;
    let rest = rest.split("  #").next().unwrap().split(" # ").next().unwrap();
    let words: Vec<String> = rest
        .replace(['[', ']'], " ")
        .split_whitespace()
        .filter(|w| *w != "..." && *w != "|")
        .map(|w| w.trim_end_matches("...").to_string())
        .collect();
    if matches!(words.first().map(String::as_str), Some("main" | "test") | None) {
        return None;
    }
    let sample = |w: &str| -> Result<String, String> {
        // An upper-case placeholder, perhaps with an extension (FILE.mcap) or in angle
        // brackets (<key>).
        let stem = w.trim_start_matches('<').trim_end_matches('>');
        let (name, ext) = stem.split_once('.').unwrap_or((stem, ""));
        let placeholder = w.starts_with('<') || (!name.is_empty() && name.chars().all(|c| c.is_ascii_uppercase()));
        if !placeholder {
            return Ok(w.to_string());
        }
        let value = match name {
            "N" | "R" | "S" | "T" => "1",
            "FILE" if ext.is_empty() => "pipelines/smoke.yaml",
            "FILE" | "ACTIONS" | "STATE" | "OUT" => "out",
            "STORE" | "URL" => "artifacts",
            "ENV" | "E" | "ID" => "Hopper-v5",
            "D" => "cpu",
            "DIR" => "dir",
            "P" => "python3",
            "ARG" => "--x",
            "NODE" => "bc",
            "METHOD" => "drex",
            "PROTOCOL" => "final",
            "NAMES" => "ppo.,drex",
            "BASELINE" => "b",
            "LEVER" => "original",
            "key" | "KEY" => "0000000000000000000000000000000000000000000000000000000000000000",
            "STUDY:BASELINE" | "STUDY" => "a:b",
            _ => return Err(format!("no sample value for the placeholder {w}: add one to concrete_commands")),
        };
        Ok(if ext.is_empty() || w.starts_with('<') { value.to_string() } else { format!("{value}.{ext}") })
    };
    let mut lines: Vec<Vec<String>> = vec![vec![]];
    for w in &words {
        let choices: Vec<&str> = if w.starts_with('-') { vec![w.as_str()] } else { w.split('|').collect() };
        let mut next = Vec::new();
        for l in &lines {
            for c in &choices {
                let v = match sample(c) {
                    Ok(v) => v,
                    Err(e) => return Some(Err(e)),
                };
                let mut l = l.clone();
                // `--sbatch-arg ARG`: a value that starts with a dash goes with `=`.
                match (l.last_mut(), v.starts_with('-') && c.chars().all(|ch| ch.is_ascii_uppercase())) {
                    (Some(flag), true) => *flag = format!("{flag}={v}"),
                    _ => l.push(v),
                }
                next.push(l);
            }
        }
        lines = next;
    }
    Some(Ok(lines))
}

/// Whether `idrex <args>` parses: the subcommands, every flag and every value's type.
fn parses(args: &[String]) -> Result<(), String> {
    use clap::Parser;
    idrex::cli::Cli::try_parse_from(std::iter::once("idrex".to_string()).chain(args.iter().cloned())).map(|_| ()).map_err(|e| e.to_string())
}

#[test]
fn every_shown_command_parses_whole() {
    let mut checked = 0;
    for page in pages() {
        for line in std::fs::read_to_string(&page).unwrap().lines().filter(|l| l.starts_with("    ")) {
            let Some(variants) = concrete_commands(line) else { continue };
            let variants = variants.unwrap_or_else(|e| panic!("{}: {line}: {e}", page.display()));
            // Every choice of every `a|b|c`, with every optional group.
            let errors: Vec<String> = variants.iter().filter_map(|v| parses(v).err()).collect();
            assert!(errors.is_empty(), "{}: `{}` does not parse:\n{}", page.display(), line.trim(), errors.join("\n"));
            checked += 1;
        }
    }
    assert!(checked >= 25, "{checked} command lines");
}

/// The `idrex ...` and `./dev ...` spans of a page's inline code (`` `idrex gc FILE` ``), with
/// each `<described placeholder>` made one placeholder word; `ARGS...` stands for anything.
fn inline_commands(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (i, span) in text.split('`').enumerate() {
        if i % 2 == 1 && (span.starts_with("idrex ") || span.starts_with("./dev ")) && !span.contains("ARGS") {
            let mut line = String::new();
            let mut rest = span;
            while let Some(open) = rest.find('<') {
                let Some(close) = rest[open..].find('>') else { break };
                line.push_str(&rest[..open]);
                line.push_str("<key>");
                rest = &rest[open + close + 1..];
            }
            line.push_str(rest);
            out.push(line);
        }
    }
    out
}

/// Whether `idrex <args>` parses as far as it goes: an inline span may leave out what a
/// command requires (`idrex gc`, `idrex report --bc-warning`), but a subcommand, a flag or a
/// value that does not exist fails.
fn parses_as_far_as_it_goes(args: &[String]) -> Result<(), String> {
    use clap::Parser;
    use clap::error::ErrorKind;
    match idrex::cli::Cli::try_parse_from(std::iter::once("idrex".to_string()).chain(args.iter().cloned())) {
        Ok(_) => Ok(()),
        Err(e)
            if matches!(
                e.kind(),
                ErrorKind::MissingRequiredArgument | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand | ErrorKind::DisplayVersion
            ) =>
        {
            Ok(())
        }
        // A flag named without its value.
        Err(e) if e.kind() == ErrorKind::InvalidValue && args.last().is_some_and(|a| a.starts_with("--")) => Ok(()),
        Err(e) => Err(e.to_string()),
    }
}

#[test]
fn every_inline_command_parses_as_far_as_it_goes() {
    let mut checked = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for span in inline_commands(&text) {
            let Some(variants) = concrete_commands(&span) else { continue };
            let variants = variants.unwrap_or_else(|e| panic!("{}: `{span}`: {e}", page.display()));
            let errors: Vec<String> = variants.iter().filter_map(|v| parses_as_far_as_it_goes(v).err()).collect();
            assert!(errors.is_empty(), "{}: `{span}` does not parse:\n{}", page.display(), errors.join("\n"));
            checked += 1;
        }
    }
    assert!(checked >= 25, "{checked} inline commands");
    // What it refuses: a misspelled subcommand, flag or value; what it lets through: a
    // fragment that stops before a required argument or a flag's value.
    let check = |span: &str| parses_as_far_as_it_goes(&concrete_commands(span).unwrap().unwrap()[0]);
    assert!(check("idrex gc").is_ok() && check("idrex report --bc-warning").is_ok() && check("idrex env rollout").is_ok());
    assert!(check("idrex gcc").is_err() && check("idrex report --bc-warnings 0.5").is_err() && check("idrex report --format pdf").is_err());
    assert_eq!(
        inline_commands("run `idrex bench trex --policy <a BC policy> --seeds 5` or `idrex ARGS...`"),
        ["idrex bench trex --policy <key> --seeds 5"]
    );
}

#[test]
fn a_misspelled_flag_or_value_in_a_shown_command_fails() {
    let one = |line: &str| concrete_commands(line).unwrap().unwrap().into_iter().map(|v| parses(&v)).collect::<Vec<_>>();
    assert!(one("    idrex pipeline run FILE [--jobs N] [--force NODE]...").iter().all(Result::is_ok));
    assert!(one("    idrex pipeline run FILE [--jbos N]").iter().all(Result::is_err));
    assert!(one("    idrex pipeline run FILE --jobs many").iter().all(Result::is_err));
    assert!(one("    idrex pipline run FILE").iter().all(Result::is_err));
    assert!(one("    idrex report --format csv|pdf").iter().any(Result::is_err));
    assert!(concrete_commands("    idrex eval --policy WHATEVER").unwrap().is_err());
    assert!(concrete_commands("    ./dev test    # every test").is_none());
}

/// The schema page is the schema generated from the config structs' rustdoc, so the two
/// cannot drift; every field the default spec serialises is on it, and every field has a
/// description.
#[test]
fn the_schema_page_is_generated_from_the_config_structs() {
    use idrex::pipeline::config::schema;
    let page = std::fs::read_to_string(repo("docs/schema.md")).unwrap();
    assert!(
        page == schema::markdown(),
        "docs/schema.md is not what the config structs generate; run `idrex pipeline schema --format markdown > docs/schema.md`"
    );
    let fields = schema::fields();
    let undocumented: Vec<&str> = fields.iter().filter(|f| f.description.is_empty()).map(|f| f.path.as_str()).collect();
    assert!(undocumented.is_empty(), "fields without rustdoc: {undocumented:?}");
    // Every serialised field of the smoke pipeline's spec has its row (sections flattened).
    let text = std::fs::read_to_string(repo("pipelines/smoke.yaml")).unwrap();
    let p = idrex::pipeline::Pipeline::parse(Path::new(&repo("pipelines/smoke.yaml")), &text).unwrap();
    let spec = serde_json::to_value(&p.spec).unwrap();
    let mut missing = Vec::new();
    for (section, v) in spec.as_object().unwrap() {
        let covered = |path: &str| fields.iter().any(|f| f.path == path || f.path.starts_with(&format!("{path}.")));
        match v.as_object() {
            Some(sub) if !sub.is_empty() && section != "overrides" => {
                missing.extend(sub.keys().map(|k| format!("{section}.{k}")).filter(|p| !covered(p)))
            }
            _ if !covered(section) => missing.push(section.clone()),
            _ => {}
        }
    }
    assert!(missing.is_empty(), "fields the schema page does not name: {missing:?}");
}

/// The stage table at the top of `pipeline/stage/mod.rs` names every production stage kind
/// with its current version.
#[test]
fn the_stage_table_gives_each_kind_its_version() {
    use idrex::pipeline::stage::StageKind;
    let text = std::fs::read_to_string(repo("src/pipeline/stage/mod.rs")).unwrap();
    let table: std::collections::BTreeMap<String, u32> = text
        .lines()
        .filter_map(|l| l.strip_prefix("//! | "))
        .filter_map(|row| {
            let cells: Vec<&str> = row.split(" | ").collect();
            Some((cells.first()?.to_string(), cells.get(1)?.parse().ok()?))
        })
        .collect();
    let code: std::collections::BTreeMap<String, u32> = StageKind::ALL.iter().map(|k| (k.name().to_string(), k.version())).collect();
    assert_eq!(table, code, "src/pipeline/stage/mod.rs's table against StageKind::version");
}

/// `analysis/` commits each figure once (as SVG; `idrex report --figures svg` writes only
/// that), no file twice (a per-replicate report keeps its words and tables; its figures are
/// rebuilt from the archives), archives compressed, all of it under 25 MB; and every relative
/// link of its pages resolves.
#[test]
fn analysis_commits_each_file_once_and_its_links_resolve() {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            // Installed packages (the Foxglove reader's node_modules) and the GPU runs' scratch
            // output are not committed.
            if p.ends_with("node_modules") || p.ends_with("gpu/out") {
                continue;
            }
            if p.is_dir() { walk(&p, out) } else { out.push(p) }
        }
    }
    let mut files = Vec::new();
    walk(&repo("analysis"), &mut files);
    let twins: Vec<&PathBuf> =
        files.iter().filter(|p| p.extension().is_some_and(|e| e == "png") && p.with_extension("svg").exists()).collect();
    assert!(twins.is_empty(), "figures committed as both PNG and SVG: {twins:?}");
    let plain: Vec<&PathBuf> = files.iter().filter(|p| p.extension().is_some_and(|e| e == "ndjson")).collect();
    assert!(plain.is_empty(), "archives are committed compressed (`idrex export --out FILE.ndjson.zst`): {plain:?}");
    let mut by_content: std::collections::BTreeMap<Vec<u8>, Vec<&PathBuf>> = Default::default();
    let mut bytes = 0;
    for f in &files {
        let content = std::fs::read(f).unwrap();
        bytes += content.len();
        by_content.entry(content).or_default().push(f);
    }
    let copies: Vec<&Vec<&PathBuf>> = by_content.values().filter(|v| v.len() > 1).collect();
    assert!(copies.is_empty(), "byte-identical files in analysis/ (keep one, link to it): {copies:?}");
    assert!(bytes < 25_000_000, "analysis/ holds {bytes} bytes, over 25 MB");
    let mut checked = 0;
    for page in files.iter().filter(|p| p.extension().is_some_and(|e| e == "md")) {
        let text = std::fs::read_to_string(page).unwrap();
        for target in links(&text) {
            assert!(page.parent().unwrap().join(&target).exists(), "{}: the link {target} goes nowhere", page.display());
            checked += 1;
        }
    }
    assert!(checked >= 100, "{checked} links");
}

/// Every study in `analysis/results/` has one layout: `README.md`, its pipeline files
/// (`*.yaml`) and `report/` (what idrex and the scripts wrote), nothing else at its top; its
/// figures are SVG only; and no two of its pipeline files are copies that differ only in which
/// replicates they run (one file with a range does that, run with `--only-replicate`).
#[test]
fn analysis_studies_share_one_layout() {
    let results = repo("analysis/results");
    let mut studies = 0;
    for e in std::fs::read_dir(&results).unwrap().flatten() {
        let study = e.path();
        if !study.is_dir() {
            assert_eq!(e.file_name(), "README.md", "{}: only study folders and the index belong here", study.display());
            continue;
        }
        studies += 1;
        assert!(study.join("README.md").is_file(), "{}: no README.md", study.display());
        let mut pipelines = Vec::new();
        for f in std::fs::read_dir(&study).unwrap().flatten() {
            let (path, name) = (f.path(), f.file_name().to_string_lossy().into_owned());
            if name.ends_with(".yaml") {
                pipelines.push(std::fs::read_to_string(&path).unwrap());
            } else {
                assert!(name == "README.md" || (name == "report" && path.is_dir()), "{}: move it under report/", path.display());
            }
        }
        let mut stack = vec![study.clone()];
        while let Some(dir) = stack.pop() {
            for f in std::fs::read_dir(&dir).unwrap().flatten() {
                let p = f.path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    assert!(p.extension().is_none_or(|x| x != "png"), "{}: figures are committed as SVG", p.display());
                }
            }
        }
        // Without comments and the replicate range, two files must still differ.
        let core = |t: &String| -> Vec<String> {
            t.lines()
                .filter(|l| !l.trim_start().starts_with('#') && !l.starts_with("replicates:") && !l.starts_with("first_replicate:"))
                .map(str::to_string)
                .collect()
        };
        for (i, a) in pipelines.iter().enumerate() {
            for b in &pipelines[i + 1..] {
                assert_ne!(core(a), core(b), "{}: two pipeline files differ only in their replicates", study.display());
            }
        }
    }
    assert!(studies >= 15, "{studies} studies");
}

/// Every command the binary has answers `--help`, and docs/cli.md shows it: walking clap's
/// own command tree, so a new command without a line there fails here.
#[test]
fn every_command_answers_help_and_the_docs_list_it() {
    use clap::CommandFactory;
    fn leaves(cmd: &clap::Command, path: Vec<String>, out: &mut Vec<Vec<String>>) {
        let subs: Vec<&clap::Command> = cmd.get_subcommands().filter(|c| c.get_name() != "help").collect();
        if subs.is_empty() {
            out.push(path.clone());
        }
        for s in subs {
            let mut p = path.clone();
            p.push(s.get_name().to_string());
            leaves(s, p, out);
        }
    }
    let mut all = Vec::new();
    leaves(&idrex::cli::Cli::command(), vec![], &mut all);
    let page = std::fs::read_to_string(repo("docs/cli.md")).unwrap();
    let mut missing = Vec::new();
    for path in &all {
        let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
        args.push("--help");
        let out = crate::util::idrex(&args);
        assert!(out.status.success() && !crate::util::stdout(&out).is_empty(), "idrex {}: {}", args.join(" "), crate::util::stderr(&out));
        let shown = format!("    idrex {}", path.join(" "));
        if !page.lines().any(|l| l == shown || l.starts_with(&format!("{shown} "))) {
            missing.push(path.join(" "));
        }
    }
    assert!(all.len() >= 20, "{} commands", all.len());
    assert!(missing.is_empty(), "docs/cli.md shows no `idrex ...` line for: {missing:?}");
}
