//! A study's manifests without their outputs, as one NDJSON file (one manifest per line, in
//! key order): what a report needs of a study (parameters, metrics, output digests), small
//! enough to commit, so the report can be rebuilt on a machine that lost the store or never
//! had it. A line's key is recomputed from its kind, version, parameters, seed and inputs
//! (by the caller's `key_of`: which parameters enter a key is the stage kind's to say), so an
//! edited definition is refused; where a store holds the same key, both must name the
//! same output digests (bytes depend on the key alone, so anything else is a defect).
//! An archive whose name ends in `.zst` is written compressed (zstd); reading recognises
//! compressed archives by their magic number, whatever their name.
use std::collections::BTreeMap;
use std::path::Path;

use super::Manifest;
use crate::error::{Error, Result};

/// One archive line: a stored `manifest.json` with the whitespace outside its strings removed,
/// so every number keeps the exact text the stage wrote (re-encoding a parsed manifest could
/// move a float by an ulp).
pub fn line(manifest_json: &str) -> String {
    let (mut out, mut in_string, mut escaped) = (String::with_capacity(manifest_json.len()), false, false);
    for c in manifest_json.chars() {
        if in_string {
            out.push(c);
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
        } else if !c.is_whitespace() {
            in_string = c == '"';
            out.push(c);
        }
    }
    out
}

/// zstd's level for archives: they are written once and committed, so the smallest file is
/// worth the second it takes (a locked replicate's 1.4 MB of manifests: about 250 kB).
const ZSTD_LEVEL: i32 = 19;

/// zstd's frame magic number (RFC 8878), little-endian.
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];

/// Writes `(key, manifest.json text)` pairs to `path` in key order, compressed where the name
/// ends in `.zst`, replacing it only once the whole file is written.
pub fn write(path: &Path, manifests: &BTreeMap<String, String>) -> Result<()> {
    let text: String = manifests.values().map(|m| line(m) + "\n").collect();
    let bytes = if path.extension().is_some_and(|e| e == "zst") {
        zstd::bulk::compress(text.as_bytes(), ZSTD_LEVEL).map_err(|e| Error::io(path, e))?
    } else {
        text.into_bytes()
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// An archive's text, decompressed where it is a zstd frame.
fn text_of(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bytes = if bytes.starts_with(&ZSTD_MAGIC) {
        zstd::stream::decode_all(bytes.as_slice())
            .map_err(|e| Error::file(path, format!("a damaged zstd archive ({e}); restore it from git")))?
    } else {
        bytes
    };
    String::from_utf8(bytes).map_err(|_| Error::file(path, "not UTF-8 text; write archives with `idrex export`"))
}

/// The text of a top-level field of a compact JSON object (an archive line).
fn field<'a>(line: &'a str, name: &str) -> Option<&'a str> {
    let (mut depth, mut in_string, mut escaped, mut start) = (0usize, false, false, None);
    let tag = format!("\"{name}\":");
    for (i, c) in line.char_indices() {
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => {
                if depth == 1 && start.is_none() && line[i..].starts_with(&tag) {
                    start = Some(i + tag.len());
                }
                in_string = true;
            }
            '{' | '[' => depth += 1,
            '}' | ']' => {
                if depth == 2 && start.is_some() && line[start?..].starts_with(['{', '[']) {
                    return Some(&line[start?..=i]);
                }
                depth -= 1;
            }
            ',' if depth == 1 && start.is_some() => return Some(&line[start?..i]),
            _ => {}
        }
    }
    None
}

/// The keys an archive holds, unchecked: enough to leave them out of another archive.
pub fn keys(path: &Path) -> Result<std::collections::BTreeSet<String>> {
    let text = text_of(path)?;
    let lines = text.lines().filter(|l| !l.trim().is_empty());
    lines
        .enumerate()
        .map(|(i, line)| {
            field(line, "key")
                .and_then(|k| k.strip_prefix('"')?.strip_suffix('"'))
                .map(str::to_string)
                .ok_or_else(|| Error::file(path, format!("line {}: no key; write archives with `idrex export`", i + 1)))
        })
        .collect()
}

/// Reads an archive, checking each line's key against `key_of(manifest, its parameters'
/// text as written)`.
pub fn read(path: &Path, key_of: impl Fn(&Manifest, &str) -> Result<String>) -> Result<Vec<Manifest>> {
    let text = text_of(path)?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let at = |why: String| Error::file(path, format!("line {}: {why}", i + 1));
        let m: Manifest =
            serde_json::from_str(line).map_err(|e| at(format!("not a manifest ({e}); write archives with `idrex export`")))?;
        let params = field(line, "params").ok_or_else(|| at("no params".into()))?;
        let expected = key_of(&m, params).map_err(|e| at(format!("artifact {}: {e}", short(&m.key))))?;
        if expected != m.key {
            return Err(at(format!(
                "key {} does not match its definition (which hashes to {}): the line was edited; restore it from git",
                short(&m.key),
                short(&expected)
            )));
        }
        out.push(m);
    }
    Ok(out)
}

/// Adds the archives' manifests to `by_key` (the store's), refusing two manifests of one key
/// whose outputs differ.
pub fn merge(by_key: &mut BTreeMap<String, Manifest>, path: &Path, archived: Vec<Manifest>) -> Result<usize> {
    let mut added = 0;
    for m in archived {
        match by_key.get(&m.key) {
            Some(have) if have.outputs != m.outputs => {
                return Err(Error::file(
                    path,
                    format!(
                        "artifact {} ({}) has other output digests here than in the store or an earlier archive: \
                         the same key computed different bytes; `idrex verify --recompute` it",
                        short(&m.key),
                        m.node
                    ),
                ));
            }
            Some(_) => {}
            None => {
                by_key.insert(m.key.clone(), m);
                added += 1;
            }
        }
    }
    Ok(added)
}

fn short(key: &str) -> &str {
    &key[..key.len().min(12)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{OutputFile, key};

    fn key_of(m: &Manifest, params: &str) -> Result<String> {
        assert_eq!(
            key(&m.kind, m.version, &m.params, m.seed, &m.inputs),
            crate::store::key_of_text(&m.kind, m.version, params, m.seed, &m.inputs)
        );
        Ok(key(&m.kind, m.version, &m.params, m.seed, &m.inputs))
    }

    #[test]
    fn a_field_is_found_at_the_top_level_only() {
        let line = r#"{"a":{"params":1},"params":{"x":[0.1,{"y":"}"}]},"seed":3,"z":[1]}"#;
        assert_eq!(field(line, "params"), Some(r#"{"x":[0.1,{"y":"}"}]}"#));
        assert_eq!(field(line, "seed"), Some("3"));
        assert_eq!(field(line, "z"), Some("[1]"));
        assert_eq!(field(line, "none"), None);
    }

    fn manifest(seed: u64, digest: &str) -> Manifest {
        let params = serde_json::json!({"env": "Hopper-v5"});
        let inputs = BTreeMap::new();
        Manifest {
            key: key("eval", 1, &params, seed, &inputs),
            kind: "eval".into(),
            version: 1,
            node: format!("eval-{seed}"),
            params,
            seed,
            inputs,
            outputs: vec![OutputFile { path: "rollouts.mcap".into(), sha256: digest.into(), size: 3 }],
            metrics: serde_json::json!({"summary": {"returns": [1.5]}}),
            ended_unix: 1.0,
            wall_s: 1.0,
            idrex_version: "test".into(),
            ..Default::default()
        }
    }

    #[test]
    fn an_archive_reads_back_what_was_written_in_key_order() {
        let dir = std::env::temp_dir().join(format!("idrex-archive-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.ndjson");
        let (a, b) = (manifest(1, "aa"), manifest(2, "bb"));
        let texts = [&b, &a].map(|m| (m.key.clone(), serde_json::to_string_pretty(m).unwrap())).into_iter().collect();
        write(&path, &texts).unwrap();
        let back = read(&path, key_of).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap().lines().count(), 2);
        let mut expected = vec![a, b];
        expected.sort_by(|x, y| x.key.cmp(&y.key));
        assert_eq!(back, expected);
        assert!(!path.with_extension("ndjson.partial").exists());
        // The same, compressed: smaller, and read back to the same manifests.
        let zst = dir.join("a.ndjson.zst");
        write(&zst, &texts).unwrap();
        assert!(std::fs::read(&zst).unwrap().starts_with(&ZSTD_MAGIC));
        assert_eq!(read(&zst, key_of).unwrap(), expected);
        let keys: Vec<String> = expected.iter().map(|m| m.key.clone()).collect();
        assert_eq!(super::keys(&zst).unwrap().into_iter().collect::<Vec<_>>(), keys);
        assert!(!dir.join("a.ndjson.zst.partial").exists());
        std::fs::write(&zst, &std::fs::read(&zst).unwrap()[..20]).unwrap();
        let err = read(&zst, key_of).unwrap_err().to_string();
        assert!(err.contains("a.ndjson.zst") && err.contains("damaged zstd archive"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_line_keeps_strings_and_numbers_as_written() {
        let text = "{\n  \"node\": \"a b\\\" c\",\n  \"x\": 0.30000000000000004\n}";
        assert_eq!(line(text), "{\"node\":\"a b\\\" c\",\"x\":0.30000000000000004}");
    }

    #[test]
    fn an_edited_definition_and_differing_bytes_are_refused() {
        let dir = std::env::temp_dir().join(format!("idrex-archive-edit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.ndjson");
        let m = manifest(1, "aa");
        write(&path, &BTreeMap::from([(m.key.clone(), serde_json::to_string_pretty(&m).unwrap())])).unwrap();
        let edited = std::fs::read_to_string(&path).unwrap().replace("\"seed\":1", "\"seed\":7");
        std::fs::write(&path, edited).unwrap();
        let err = read(&path, key_of).unwrap_err().to_string();
        assert!(err.contains("line 1") && err.contains("does not match its definition"), "{err}");

        let mut by_key = BTreeMap::from([(m.key.clone(), m.clone())]);
        assert_eq!(merge(&mut by_key, &path, vec![m.clone(), manifest(2, "bb")]).unwrap(), 1);
        let err = merge(&mut by_key, &path, vec![manifest(1, "cc")]).unwrap_err().to_string();
        assert!(err.contains("other output digests"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
