//! The code's layout stays readable: no source file holds more than 450 lines before its
//! test module, and no two modules import each other, directly or through others (a module
//! and its own submodules count as one room). Imports are read from `use` items and
//! `crate::` paths in the code, not from comments.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_LINES: usize = 450;

/// Every `.rs` file under `src/` with its module path (`pipeline::stage::eval`).
fn modules() -> BTreeMap<String, PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    walk(&root, &mut files);
    files
        .into_iter()
        .map(|p| {
            let rel = p.strip_prefix(&root).unwrap().with_extension("");
            let mut parts: Vec<String> = rel.iter().map(|s| s.to_string_lossy().into_owned()).collect();
            if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
                parts.pop();
            }
            (parts.join("::"), p)
        })
        .collect()
}

/// The code before the test module, without comment lines.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let body = text.split("#[cfg(test)]").next().unwrap();
    body.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n")
}

/// The paths a use tree names: `a::{b, c::{d, e}}` -> a::b, a::c::d, a::c::e.
fn use_paths(tree: &str) -> Vec<Vec<String>> {
    let tree: String = tree.chars().filter(|c| !c.is_whitespace()).collect();
    fn expand(prefix: &[String], t: &str, out: &mut Vec<Vec<String>>) {
        let Some(open) = t.find('{') else {
            let mut p = prefix.to_vec();
            let t = t.split("as").next().unwrap_or(t);
            p.extend(t.split("::").filter(|s| !s.is_empty() && *s != "*").map(String::from));
            out.push(p);
            return;
        };
        let mut p = prefix.to_vec();
        p.extend(t[..open].split("::").filter(|s| !s.is_empty()).map(String::from));
        let inner = &t[open + 1..t.rfind('}').unwrap()];
        let (mut depth, mut start) = (0, 0);
        for (i, c) in inner.char_indices() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    expand(&p, &inner[start..i], out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        expand(&p, &inner[start..], out);
    }
    let mut out = Vec::new();
    expand(&[], &tree, &mut out);
    out
}

/// Which other modules `module` (in `path`) imports.
fn imports(module: &str, path: &Path, known: &BTreeMap<String, PathBuf>) -> BTreeSet<String> {
    let me: Vec<String> = if module.is_empty() { vec![] } else { module.split("::").map(String::from).collect() };
    let code = code(path);
    let mut paths = Vec::new();
    for stmt in code.split(';') {
        // The statement's text from its last line that starts a `use` item.
        let lines: Vec<&str> = stmt.lines().collect();
        let item = |l: &str| ["use ", "pub use ", "pub(crate) use "].iter().find_map(|k| l.trim_start().strip_prefix(k)).is_some();
        if let Some(at) = lines.iter().rposition(|l| item(l)) {
            let first = lines[at].trim_start().splitn(2, "use ").nth(1).unwrap_or("");
            let tree = std::iter::once(first).chain(lines[at + 1..].iter().copied()).collect::<Vec<_>>().join(" ");
            paths.extend(use_paths(&tree));
        }
    }
    // Paths written in place: `crate::a::b(..)`, `super::schedule::remaining(..)`, and
    // through a submodule this file declares (`idrex::multi_bc::run`).
    let children: Vec<String> = code
        .lines()
        .filter_map(|l| {
            let l = l.trim_start();
            let l = l.strip_prefix("pub ").unwrap_or(l);
            l.strip_prefix("mod ").and_then(|r| r.strip_suffix(';')).map(|n| format!("{n}::"))
        })
        .collect();
    for start in ["crate::", "super::"].into_iter().map(String::from).chain(children.iter().cloned()) {
        let start = start.as_str();
        for (i, _) in code.match_indices(start) {
            let before = code[..i].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let rest: String = code[i..].chars().take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':').collect();
            let mut path: Vec<String> = rest.split("::").filter(|s| !s.is_empty()).map(String::from).collect();
            if !matches!(start, "crate::" | "super::") {
                path.insert(0, "self".into());
            }
            paths.push(path);
        }
    }
    let mut out = BTreeSet::new();
    for p in paths {
        let Some(first) = p.first() else { continue };
        let mut full: Vec<String> = match first.as_str() {
            "crate" => vec![],
            "self" => me.clone(),
            "super" => me[..me.len().saturating_sub(1)].to_vec(),
            _ => continue, // an outside crate
        };
        let mut rest = &p[1..];
        while rest.first().is_some_and(|s| s == "super") {
            full.pop();
            rest = &rest[1..];
        }
        full.extend(rest.iter().cloned());
        for n in (1..=full.len()).rev() {
            let target = full[..n].join("::");
            if known.contains_key(&target) {
                let ancestor = module == target || module.starts_with(&format!("{target}::"));
                if !ancestor {
                    out.insert(target);
                }
                break;
            }
        }
    }
    out
}

#[test]
fn no_source_file_is_over_450_lines_before_its_tests() {
    let long: Vec<String> = modules()
        .values()
        .filter_map(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            let n = text.split("#[cfg(test)]").next().unwrap().lines().count();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", p.display()))
        })
        .collect();
    assert!(long.is_empty(), "over {MAX_LINES} lines before the test module: {long:?}");
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let known = modules();
    let edges: BTreeMap<String, BTreeSet<String>> = known.iter().map(|(m, p)| (m.clone(), imports(m, p, &known))).collect();
    // A depth-first search that reports the first cycle it closes.
    fn visit(
        m: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, bool>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        match state.get(m) {
            Some(true) => return None,
            Some(false) => {
                let at = stack.iter().position(|s| s == m).unwrap();
                let mut cycle = stack[at..].to_vec();
                cycle.push(m.to_string());
                return Some(cycle);
            }
            None => {}
        }
        state.insert(m.to_string(), false);
        stack.push(m.to_string());
        for n in &edges[m] {
            if let Some(c) = visit(n, edges, state, stack) {
                return Some(c);
            }
        }
        stack.pop();
        state.insert(m.to_string(), true);
        None
    }
    let mut state = BTreeMap::new();
    for m in known.keys() {
        if let Some(cycle) = visit(m, &edges, &mut state, &mut Vec::new()) {
            panic!("import cycle: {}", cycle.join(" -> "));
        }
    }
    // The check sees imports at all: the pipeline's layers are there.
    assert!(edges["pipeline::graph"].contains("pipeline::stage"), "{:?}", edges["pipeline::graph"]);
    assert!(edges["pipeline::stage::eval"].contains("pipeline::config"), "{:?}", edges["pipeline::stage::eval"]);
}

#[test]
fn use_trees_expand_to_every_path() {
    let paths = use_paths("super::{Graph, io, stage::{Params, trex::RankedSet}}");
    let joined: Vec<String> = paths.iter().map(|p| p.join("::")).collect();
    assert_eq!(joined, ["super::Graph", "super::io", "super::stage::Params", "super::stage::trex::RankedSet"]);
}
