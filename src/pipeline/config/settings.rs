//! Fields of a pipeline file set from outside its own values: a sweep's variants (the file's
//! `sweep:` block) and the command line's `-S field.path=value`, as Hydra's overrides and
//! DVC's `exp run -S` set them. A setting is applied to the file's YAML document before the
//! schema reads it, so it is checked exactly as the file's own value would be.
use std::collections::BTreeMap;

use serde_json::Value;

use super::PipelineFile;

/// Fields a setting may not change: what names, stores or locks the study, not how it runs.
const FIXED: &[(&str, &str)] = &[
    ("version", "the schema version is the file's"),
    ("name", "a variant is named by its settings"),
    ("role", "a locked test set is one configuration"),
    ("store", "give `--store` on the command line"),
    ("sweep", "a sweep's variants cannot be swept"),
];

/// The `sweep:` block: the variants a file runs as (`idrex pipeline run` expands them all).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SweepConfig {
    /// Field path (`reward.ceiling`, `overrides.drex.trex.loss`) -> the values it takes:
    /// every combination of the lists is a variant, named by its settings.
    pub grid: BTreeMap<String, Vec<Value>>,
    /// Named variants, each a map of field path -> value; a variant that sets nothing is the
    /// file itself (its keys and name are the file's). With `grid`, every named variant runs
    /// every combination.
    pub variants: BTreeMap<String, BTreeMap<String, Value>>,
    /// The variant every other is compared against in the report: a named variant, or a
    /// combination's label (`reward.ceiling=0.75`). Default: the variant that sets nothing,
    /// else the first combination (each grid list's first value).
    pub baseline: Option<String>,
}

/// Where a setting comes from, for its error messages.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// `-S` on the command line.
    CommandLine,
    /// The file's `sweep:` block, at this line and column.
    Sweep { line: usize, column: usize },
}

/// One field set to one value.
#[derive(Debug, Clone, PartialEq)]
pub struct Setting {
    /// The field's path, `reward.ceiling`.
    pub path: String,
    pub value: Value,
    pub source: Source,
}

impl Setting {
    /// `path=value`, the value as a YAML scalar would be written.
    pub fn label(&self) -> String {
        format!("{}={}", self.path, value_text(&self.value))
    }

    /// Whether a check on the field `keys` reads this setting's value (one path contains the
    /// other).
    pub fn covers(&self, keys: &[&str]) -> bool {
        let path: Vec<&str> = self.path.split('.').collect();
        let n = path.len().min(keys.len());
        n > 0 && path[..n] == keys[..n]
    }

    /// How an error message names it: `-S reward.ceiling=2` or `sweep sets reward.ceiling=2`.
    pub fn describe(&self) -> String {
        match self.source {
            Source::CommandLine => format!("-S {}", self.label()),
            Source::Sweep { .. } => format!("sweep sets {}", self.label()),
        }
    }
}

/// A value as a label shows it: strings bare, everything else as JSON writes it.
pub fn value_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// A `-S` argument, `field.path=value` or `field.path=a,b,c` (a sweep over the values; commas
/// inside brackets belong to a list value: `seeds=[1,2],[3,4]` is two values). Each value is
/// read as YAML reads it (`0.5`, `none`, `[1, 2]`).
pub fn parse_arg(arg: &str) -> Result<(String, Vec<Value>), String> {
    let Some((path, values)) = arg.split_once('=') else {
        return Err(format!("-S {arg}: write FIELD=VALUE, e.g. `-S reward.ceiling=0.5` (or `=0.5,none` for a sweep)"));
    };
    let path = path.trim();
    if path.is_empty() || path.split('.').any(str::is_empty) {
        return Err(format!("-S {arg}: the field path `{path}` has an empty part; write e.g. `reward.ceiling`"));
    }
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, c) in values.char_indices() {
        match c {
            '[' | '{' => depth += 1,
            ']' | '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&values[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&values[start..]);
    let values = parts
        .into_iter()
        .map(|v| {
            let v = v.trim();
            if v.is_empty() {
                return Err(format!("-S {arg}: an empty value; give one after `=` (separate a sweep's values with commas)"));
            }
            serde_yaml::from_str::<Value>(v).map_err(|e| format!("-S {arg}: `{v}` is not a YAML value: {e}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((path.to_string(), values))
}

/// The file's schema with `settings` applied in order, or the first one that fails (its
/// index) and why: a field the schema does not have, a value of the wrong type, a field a
/// setting may not change.
pub fn apply(text: &str, settings: &[Setting]) -> Result<PipelineFile, (usize, String)> {
    let mut doc: serde_yaml::Value = serde_yaml::from_str(text).map_err(|e| (0, e.to_string()))?;
    for (i, s) in settings.iter().enumerate() {
        let keys: Vec<&str> = s.path.split('.').collect();
        if let Some((field, why)) = FIXED.iter().find(|(f, _)| *f == keys[0]) {
            return Err((i, format!("{field} cannot be set by a sweep or -S: {why}")));
        }
        if let Some(x) = s.value.as_f64().filter(|x| !x.is_finite()) {
            return Err((i, format!("{x} is not a finite number; give a finite value")));
        }
        let value: serde_yaml::Value = serde_yaml::to_value(&s.value).map_err(|e| (i, e.to_string()))?;
        set(&mut doc, &keys, value).map_err(|e| (i, e))?;
        // Each setting is checked as it lands, so a mistake names the setting that made it.
        serde_yaml::from_value::<PipelineFile>(doc.clone()).map_err(|e| (i, schema_message(e, &s.path)))?;
    }
    serde_yaml::from_value(doc).map_err(|e| (settings.len().saturating_sub(1), e.to_string()))
}

/// serde's message for a setting, with the hint the file's own mistakes get.
fn schema_message(e: serde_yaml::Error, path: &str) -> String {
    let msg = e.to_string();
    let hint = if msg.contains("unknown field") {
        format!("; `{path}` is not a field of the pipeline schema (`idrex pipeline schema --format markdown` lists them)")
    } else if msg.contains("unknown variant") {
        "; write one of the names listed".to_string()
    } else {
        format!("; see the schema's type for `{path}`")
    };
    format!("{msg}{hint}")
}

/// Sets `keys` in `doc` to `value`, creating the blocks on the way.
fn set(doc: &mut serde_yaml::Value, keys: &[&str], value: serde_yaml::Value) -> Result<(), String> {
    let Some((last, parents)) = keys.split_last() else { return Err("an empty field path".into()) };
    let mut at = doc;
    for (depth, k) in parents.iter().enumerate() {
        if at.is_null() {
            *at = serde_yaml::Value::Mapping(Default::default());
        }
        let serde_yaml::Value::Mapping(m) = at else {
            return Err(format!("`{}` is a value, not a block of fields", keys[..depth].join(".")));
        };
        at = m.entry(serde_yaml::Value::String(k.to_string())).or_insert(serde_yaml::Value::Null);
    }
    if at.is_null() {
        *at = serde_yaml::Value::Mapping(Default::default());
    }
    match at {
        serde_yaml::Value::Mapping(m) => {
            m.insert(serde_yaml::Value::String(last.to_string()), value);
            Ok(())
        }
        _ => Err(format!("`{}` is a value, not a block of fields", parents.join("."))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "version: 1\nenv: Hopper-v5\nreward:\n  ctrl_coeff: 0.01\n";

    fn cli(path: &str, value: Value) -> Setting {
        Setting { path: path.into(), value, source: Source::CommandLine }
    }

    #[test]
    fn an_argument_is_a_field_and_one_value_or_a_sweep_of_them() {
        assert_eq!(parse_arg("reward.ceiling=0.5").unwrap(), ("reward.ceiling".into(), vec![serde_json::json!(0.5)]));
        assert_eq!(parse_arg("reward.ceiling=0.75,none").unwrap().1, vec![serde_json::json!(0.75), serde_json::json!("none")]);
        assert_eq!(parse_arg("seeds=[1, 2],[3,4]").unwrap().1, vec![serde_json::json!([1, 2]), serde_json::json!([3, 4])]);
        assert!(parse_arg("reward.ceiling").unwrap_err().contains("FIELD=VALUE"));
        assert!(parse_arg("reward..ceiling=1").unwrap_err().contains("empty part"));
        assert!(parse_arg("reward.ceiling=0.5,").unwrap_err().contains("an empty value"));
    }

    #[test]
    fn a_setting_is_checked_as_the_files_own_value() {
        let spec = apply(FILE, &[cli("reward.ceiling", serde_json::json!("none")), cli("trex.models", serde_json::json!(5))]).unwrap();
        assert_eq!((spec.trex.models, spec.reward.ctrl_coeff), (5, Some(0.01)), "other fields keep the file's values");
        assert_eq!(spec.reward.ceiling.quantile(), None);
        let spec = apply(FILE, &[cli("overrides.drex.trex.loss", serde_json::json!("regression"))]).unwrap();
        assert!(spec.overrides.contains_key(&super::super::Method::Drex));
        let two = [cli("trex.models", serde_json::json!(5)), cli("reward.ceilng", serde_json::json!(0.5))];
        let (i, e) = apply(FILE, &two).unwrap_err();
        assert_eq!(i, 1, "the second setting is the mistake");
        assert!(e.contains("unknown field `ceilng`") && e.contains("`reward.ceilng` is not a field"), "{e}");
        let (_, e) = apply(FILE, &[cli("trex.models", serde_json::json!("many"))]).unwrap_err();
        assert!(e.contains("invalid type"), "{e}");
        let (_, e) = apply(FILE, &[cli("name", serde_json::json!("x"))]).unwrap_err();
        assert!(e.starts_with("name cannot be set"), "{e}");
        let (_, e) = apply(FILE, &[cli("reward.ctrl_coeff.x", serde_json::json!(1))]).unwrap_err();
        assert!(e.contains("`reward.ctrl_coeff` is a value"), "{e}");
    }

    #[test]
    fn a_setting_covers_the_checks_on_its_field() {
        let s = cli("overrides.drex.trex.loss", serde_json::json!("regression"));
        assert!(s.covers(&["overrides", "drex", "trex"]) && s.covers(&["overrides", "drex", "trex", "loss"]));
        assert!(!s.covers(&["trex", "loss"]) && !s.covers(&["overrides", "bc"]));
        assert_eq!(s.describe(), "-S overrides.drex.trex.loss=regression");
    }
}
