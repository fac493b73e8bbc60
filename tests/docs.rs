//! The README and the pages beside it stay true: every relative link resolves, every `idrex`
//! command they show parses (its subcommand exists: `--help` succeeds), and every field of
//! the pipeline schema is on the schema page.
use std::path::{Path, PathBuf};

use crate::util::{idrex, repo, stderr};

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

/// The command words of a shown command line: `idrex pipeline run FILE ...` ->
/// [pipeline, run] (up to the first argument that is not a subcommand name).
fn command_words(line: &str) -> Option<Vec<String>> {
    let line = line.trim();
    let rest = line.strip_prefix("idrex ").or_else(|| line.strip_prefix("./dev "))?;
    let words: Vec<String> = rest
        .split_whitespace()
        .take_while(|w| w.chars().all(|c| c.is_ascii_lowercase() || c == '-') && !w.starts_with('-'))
        .take(2)
        .map(str::to_string)
        .collect();
    (!words.is_empty() && words[0] != "main" && words[0] != "test").then_some(words)
}

#[test]
fn every_shown_command_parses() {
    let mut seen = std::collections::BTreeSet::new();
    for page in pages() {
        for line in std::fs::read_to_string(&page).unwrap().lines().filter(|l| l.starts_with("    ")) {
            let Some(mut words) = command_words(line) else { continue };
            // `idrex logs list|show|export` and the like: the first alternative.
            if let Some(w) = words.get_mut(1) {
                *w = w.split('|').next().unwrap().to_string();
            }
            if seen.insert(words.clone()) {
                let mut args: Vec<&str> = words.iter().map(String::as_str).collect();
                args.push("--help");
                let out = idrex(&args);
                if !out.status.success() && words.len() == 2 {
                    // The second word was an argument, not a subcommand.
                    let alone = idrex(&[words[0].as_str(), "--help"]);
                    assert!(alone.status.success(), "{}: `idrex {}` does not parse: {}", page.display(), words[0], stderr(&alone));
                    continue;
                }
                assert!(out.status.success(), "{}: `idrex {}` does not parse: {}", page.display(), words.join(" "), stderr(&out));
            }
        }
    }
    assert!(seen.len() >= 15, "{seen:?}");
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
