//! The code's layout stays readable: no source file holds more than 450 production lines
//! (every line outside a `#[cfg(test)]` item, wherever that item sits), no production
//! function more than 100 lines (signature to closing brace), no two modules import
//! each other, directly or through others (a module and its own submodules count as one
//! room), and no two folders do either. Imports are read from `use` items and `crate::`
//! paths in the code, not from comments. Each check is also run on planted violations, so a
//! broken checker fails here rather than passing everything.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_LINES: usize = 450;
const MAX_FN_LINES: usize = 100;

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

/// The production code of a file: its lines with every `#[cfg(test)]` item cut out (a
/// test module, or a test-only method in the middle of an impl).
fn production(text: &str) -> Vec<&str> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() != "#[cfg(test)]" {
            out.push(lines[i]);
            i += 1;
            continue;
        }
        // Skip the attribute and the item after it: up to its `;`, or its braces' close.
        let (mut depth, mut opened) = (0i64, false);
        i += 1;
        while i < lines.len() {
            let line = lines[i];
            i += 1;
            for c in code_chars(line) {
                match c {
                    '{' => (depth, opened) = (depth + 1, true),
                    '}' => depth -= 1,
                    _ => {}
                }
            }
            if (opened && depth <= 0) || (!opened && line.trim_end().ends_with(';')) {
                break;
            }
        }
    }
    out
}

/// A line's characters outside string and char literals and `//` comments (enough to count
/// braces in this crate: no raw strings hold braces).
fn code_chars(line: &str) -> Vec<char> {
    let mut out = Vec::new();
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '/' if chars.peek() == Some(&'/') => break,
            '"' => {
                while let Some(d) = chars.next() {
                    match d {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        _ => {}
                    }
                }
            }
            // A char literal ('{', '\''), not a lifetime ('a): its close quote is near.
            '\'' => {
                let ahead: Vec<char> = chars.clone().take(3).collect();
                let len = match ahead.as_slice() {
                    ['\\', ..] => chars.clone().position(|d| d == '\'').map_or(0, |p| if p == 1 { 3 } else { p + 1 }),
                    [_, '\'', ..] => 2,
                    _ => 0,
                };
                for _ in 0..len {
                    chars.next();
                }
            }
            _ => out.push(c),
        }
    }
    out
}

/// The production code, without comment lines.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    production(&text).into_iter().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n")
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
            let first = lines[at].trim_start().split_once("use ").map(|x| x.1).unwrap_or("");
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
fn no_source_file_holds_over_450_production_lines() {
    let long: Vec<String> = modules()
        .values()
        .filter_map(|p| {
            let n = production(&std::fs::read_to_string(p).unwrap()).len();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", p.display()))
        })
        .collect();
    assert!(long.is_empty(), "over {MAX_LINES} production lines: {long:?}");
}

/// Each function of the production code, as (name, lines from its `fn` line to its closing
/// brace); nested functions count inside their parent too.
fn function_lengths(lines: &[&str]) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let code: String = code_chars(line).into_iter().collect();
        let Some(at) = code.find("fn ").filter(|&at| at == 0 || code[..at].ends_with(' ') || code[..at].ends_with('(')) else { continue };
        let name: String = code[at + 3..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        if name.is_empty() {
            continue;
        }
        // From the signature's first `{` to the brace that closes it; a `;` first is a
        // declaration without a body.
        let (mut depth, mut opened) = (0i64, false);
        for (j, l) in lines.iter().enumerate().skip(i) {
            for c in code_chars(l) {
                match c {
                    '{' => (depth, opened) = (depth + 1, true),
                    '}' => depth -= 1,
                    ';' if !opened => depth = -1,
                    _ => {}
                }
                if depth < 0 || (opened && depth == 0) {
                    break;
                }
            }
            if depth < 0 {
                break;
            }
            if opened && depth == 0 {
                out.push((name.clone(), j - i + 1));
                break;
            }
        }
    }
    out
}

/// One convention for module files: a module with submodules is a folder with `mod.rs`,
/// never a `name.rs` beside a `name/` folder.
#[test]
fn a_module_with_submodules_is_a_folder_with_mod_rs() {
    let mixed: Vec<String> =
        modules().values().filter(|p| !p.ends_with("mod.rs") && p.with_extension("").is_dir()).map(|p| p.display().to_string()).collect();
    assert!(mixed.is_empty(), "move each into its folder as mod.rs: {mixed:?}");
    assert!(modules().values().filter(|p| p.ends_with("mod.rs")).count() > 10);
}

#[test]
fn no_function_holds_over_100_lines() {
    let long: Vec<String> = modules()
        .values()
        .flat_map(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            let lines = production(&text);
            function_lengths(&lines)
                .into_iter()
                .filter(|(_, n)| *n > MAX_FN_LINES)
                .map(|(f, n)| format!("{} `{f}` ({n} lines)", p.display()))
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(long.is_empty(), "functions over {MAX_FN_LINES} lines: {long:?}");
}

#[test]
fn function_lengths_count_from_the_signature_to_the_closing_brace() {
    let text = "pub fn short(a: u8) -> u8 {\n    a\n}\nfn decl(x: u8);\nimpl A {\n    pub(crate) fn long(\n        x: u8,\n    ) -> String {\n        let s = \"}\";\n        if x > 0 { f(|y| { y }) }\n        s.into()\n    }\n}\n";
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(function_lengths(&lines), [("short".to_string(), 3), ("long".to_string(), 7)]);
    // A planted function one line over the limit is found.
    let long = format!("fn big() {{\n{}}}\n", "    step();\n".repeat(MAX_FN_LINES - 1));
    let lines: Vec<&str> = long.lines().collect();
    assert_eq!(function_lengths(&lines), [("big".to_string(), MAX_FN_LINES + 1)]);
}

#[test]
fn production_lines_include_those_after_a_test_only_method() {
    let text = "struct A;\nimpl A {\n    #[cfg(test)]\n    fn probe(&self) -> char {\n        '{'\n    }\n    fn real(&self) {\n        let s = \"}\";\n    }\n}\n#[cfg(test)]\nmod tests {\n    #[test]\n    fn t() {}\n}\n";
    let kept = production(text);
    assert_eq!(kept, ["struct A;", "impl A {", "    fn real(&self) {", "        let s = \"}\";", "    }", "}"]);
    assert_eq!(production("#[cfg(test)]\nmod tests;\nfn f() {}\n"), ["fn f() {}"]);
    let braces = |l: &str| code_chars(l).into_iter().filter(|c| "{}".contains(*c)).collect::<String>();
    assert_eq!(braces("let (a, b) = ('\\'', '{'); f::<'a>(\"}\\\"\", '\\u{7b}') { // }"), "{");
}

type Edges = BTreeMap<String, BTreeSet<String>>;

/// The first cycle a depth-first search closes, as a path that ends where it starts.
fn find_cycle(edges: &Edges) -> Option<Vec<String>> {
    fn visit(m: &str, edges: &Edges, state: &mut BTreeMap<String, bool>, stack: &mut Vec<String>) -> Option<Vec<String>> {
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
        for n in edges.get(m).into_iter().flatten() {
            if let Some(c) = visit(n, edges, state, stack) {
                return Some(c);
            }
        }
        stack.pop();
        state.insert(m.to_string(), true);
        None
    }
    let mut state = BTreeMap::new();
    edges.keys().find_map(|m| visit(m, edges, &mut state, &mut Vec::new()))
}

/// For each folder (the crate root included), the graph between its rooms: every module
/// under it collapses to the file or subfolder of that folder it lives in. `cli/x.rs` ->
/// `bench/y.rs` and `bench/z.rs` -> `cli/w.rs` is no module cycle but a root-level one.
fn folder_graphs(edges: &Edges) -> BTreeMap<String, Edges> {
    let under = |m: &str, folder: &str| -> Option<String> {
        let rest = if folder.is_empty() { m } else { m.strip_prefix(folder)?.strip_prefix("::")? };
        let room = rest.split("::").next().filter(|r| !r.is_empty())?;
        Some(if folder.is_empty() { room.to_string() } else { format!("{folder}::{room}") })
    };
    // Folders: the root and every module that has modules under it.
    let mut folders: BTreeSet<String> = BTreeSet::from([String::new()]);
    for m in edges.keys() {
        let parts: Vec<&str> = m.split("::").collect();
        for n in 1..parts.len() {
            folders.insert(parts[..n].join("::"));
        }
    }
    folders
        .into_iter()
        .map(|f| {
            let mut g = Edges::new();
            for (m, targets) in edges {
                let Some(from) = under(m, &f) else { continue };
                for t in targets {
                    if let Some(to) = under(t, &f).filter(|to| *to != from) {
                        g.entry(from.clone()).or_default().insert(to);
                    }
                }
            }
            (f, g)
        })
        .collect()
}

#[test]
fn no_module_or_folder_imports_one_that_imports_it_back() {
    let known = modules();
    let edges: Edges = known.iter().map(|(m, p)| (m.clone(), imports(m, p, &known))).collect();
    if let Some(cycle) = find_cycle(&edges) {
        panic!("import cycle: {}", cycle.join(" -> "));
    }
    let graphs = folder_graphs(&edges);
    for (folder, g) in &graphs {
        if let Some(cycle) = find_cycle(g) {
            panic!("import cycle between the rooms of {}/: {}", if folder.is_empty() { "src" } else { folder }, cycle.join(" -> "));
        }
    }
    // The check sees imports at all: the pipeline's layers are there, and folders too.
    assert!(edges["pipeline::graph"].contains("pipeline::stage"), "{:?}", edges["pipeline::graph"]);
    assert!(edges["pipeline::stage::eval"].contains("pipeline::config"), "{:?}", edges["pipeline::stage::eval"]);
    assert!(graphs[""]["cli"].contains("pipeline"), "{:?}", graphs[""]);
}

#[test]
fn a_folder_cycle_without_a_module_cycle_is_found() {
    let edge = |a: &str, b: &str| (a.to_string(), BTreeSet::from([b.to_string()]));
    let edges: Edges =
        [edge("cli::x", "bench::y"), edge("bench::z", "cli::w"), edge("bench::y", "stats"), edge("cli::w", "stats")].into_iter().collect();
    assert_eq!(find_cycle(&edges), None);
    let graphs = folder_graphs(&edges);
    assert_eq!(find_cycle(&graphs[""]), Some(vec!["bench".to_string(), "cli".into(), "bench".into()]));
    assert_eq!(find_cycle(&graphs["cli"]), None);
}

#[test]
fn use_trees_expand_to_every_path() {
    let paths = use_paths("super::{Graph, io, stage::{Params, trex::RankedSet}}");
    let joined: Vec<String> = paths.iter().map(|p| p.join("::")).collect();
    assert_eq!(joined, ["super::Graph", "super::io", "super::stage::Params", "super::stage::trex::RankedSet"]);
}
