//! The pipeline file's schema, generated from the config structs: a JSON Schema (for editors
//! that validate YAML) and the reference table of `docs/schema.md`. The fields' rustdoc is
//! their one description; a test keeps the page equal to [`markdown`].
use serde_json::{Map, Value};

use super::PipelineFile;

/// The JSON Schema of a pipeline file.
pub fn json() -> Value {
    serde_json::to_value(schemars::schema_for!(PipelineFile)).expect("a schema serialises")
}

/// One row of the reference table.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// Dotted path: `idrex.multi_bc.bc.iterations`.
    pub path: String,
    /// The field's rustdoc (its type's when the field has none).
    pub description: String,
    /// What the field takes: a type, or the values of an enumeration.
    pub takes: String,
    /// The default, as YAML would write it; empty when the field is required.
    pub default: String,
}

/// Every field of the schema, sections first-level order, nested sections flattened.
pub fn fields() -> Vec<Field> {
    let root = json();
    let defs = root.get("$defs").and_then(Value::as_object).cloned().unwrap_or_default();
    let mut out = Vec::new();
    walk(&root, &defs, "", None, &mut out);
    out
}

fn resolve<'a>(s: &'a Value, defs: &'a Map<String, Value>) -> &'a Value {
    match s.get("$ref").and_then(Value::as_str).and_then(|r| r.strip_prefix("#/$defs/")) {
        Some(name) => defs.get(name).map_or(s, |d| resolve(d, defs)),
        None => s,
    }
}

/// The schema without `null` when it is an `Option`'s (`anyOf: [T, null]` or `type: [T, null]`).
fn non_null<'a>(s: &'a Value, defs: &'a Map<String, Value>) -> &'a Value {
    let s = resolve(s, defs);
    if let Some(any) = s.get("anyOf").and_then(Value::as_array) {
        let rest: Vec<&Value> = any.iter().filter(|v| v.get("type").and_then(Value::as_str) != Some("null")).collect();
        if rest.len() == 1 {
            return resolve(rest[0], defs);
        }
    }
    s
}

fn description(s: &Value) -> Option<String> {
    s.get("description").and_then(Value::as_str).map(|d| d.split_whitespace().collect::<Vec<_>>().join(" "))
}

/// A struct's schema: an object with named properties (a map has `additionalProperties`).
fn is_section(s: &Value) -> bool {
    s.get("properties").is_some_and(|p| p.as_object().is_some_and(|m| !m.is_empty()))
}

fn takes(s: &Value, defs: &Map<String, Value>) -> String {
    let s = non_null(s, defs);
    let variants = s.get("oneOf").or_else(|| s.get("anyOf")).and_then(Value::as_array);
    if let Some(values) = s.get("enum").and_then(Value::as_array) {
        return values.iter().map(|v| format!("`{}`", v.as_str().unwrap_or_default())).collect::<Vec<_>>().join(", ");
    }
    if let Some(vs) = variants {
        let one = |v: &Value| {
            let v = resolve(v, defs);
            match (v.get("const").or_else(|| v.get("enum").and_then(|e| e.get(0))), description(v)) {
                (Some(c), Some(d)) => format!("`{}` ({d})", c.as_str().unwrap_or_default()),
                (Some(c), None) => format!("`{}`", c.as_str().unwrap_or_default()),
                (None, _) => takes(v, defs),
            }
        };
        return vs.iter().map(one).collect::<Vec<_>>().join("; or ");
    }
    match s.get("type") {
        Some(Value::String(t)) if t == "array" => format!("list of {}", s.get("items").map_or("values".into(), |i| takes(i, defs))),
        Some(Value::String(t)) if t == "object" && s.get("additionalProperties").is_some() => {
            format!("map to {}", s.get("additionalProperties").map_or("values".into(), |i| takes(i, defs)))
        }
        Some(Value::String(t)) => t.clone(),
        Some(Value::Array(ts)) => ts.iter().filter_map(Value::as_str).filter(|t| *t != "null").collect::<Vec<_>>().join(" or "),
        _ if is_section(s) => "section".into(),
        _ => "any".into(),
    }
}

/// A default as a pipeline file would write it (YAML's flow style), numbers at 9 digits.
fn yaml(v: &Value) -> String {
    let num = |x: &Value| x.as_f64().map_or(x.to_string(), |f| format!("{}", (f * 1e9).round() / 1e9));
    match v {
        Value::Null => "none".into(),
        Value::String(s) => s.clone(),
        Value::Number(_) => num(v),
        Value::Array(a) if a.len() > 6 && a.iter().all(Value::is_number) => {
            format!("[{}, {}, ..., {}] ({} values)", num(&a[0]), num(&a[1]), num(&a[a.len() - 1]), a.len())
        }
        Value::Array(a) => format!("[{}]", a.iter().map(yaml).collect::<Vec<_>>().join(", ")),
        _ => v.to_string(),
    }
}

/// A map keyed by a closed set (stage kinds, methods): every property is the same section.
fn keyed_map<'a>(s: &'a Value, defs: &'a Map<String, Value>) -> Option<(Vec<String>, &'a Value)> {
    let props = s.get("properties")?.as_object()?;
    let mut refs = props.values().map(|v| v.get("$ref"));
    let first = refs.next()??;
    (props.len() > 2 && refs.all(|r| r == Some(first)))
        .then(|| (props.keys().cloned().collect(), resolve(props.values().next().unwrap(), defs)))
}

/// Rows of the section `s` at `prefix`; `defaults` are the enclosing field's (a section's
/// default can differ from its type's: the clones' `bc` is not the demonstrations').
fn walk(s: &Value, defs: &Map<String, Value>, prefix: &str, defaults: Option<&Value>, out: &mut Vec<Field>) {
    let s = non_null(s, defs);
    let Some(props) = s.get("properties").and_then(Value::as_object) else { return };
    let required: Vec<&str> = s.get("required").and_then(Value::as_array).map_or(vec![], |r| r.iter().filter_map(Value::as_str).collect());
    for (name, prop) in props {
        let path = if prefix.is_empty() { name.clone() } else { format!("{prefix}.{name}") };
        let target = non_null(prop, defs);
        let description = description(prop).or_else(|| description(target)).unwrap_or_default();
        let default = defaults.and_then(|d| d.get(name)).or_else(|| prop.get("default"));
        if let Some((keys, section)) = keyed_map(target, defs) {
            let takes = format!("a section per key: {}", keys.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", "));
            out.push(Field { path: path.clone(), description, takes, default: "none".into() });
            walk(section, defs, &format!("{path}.<key>"), None, out);
            continue;
        }
        if is_section(target) {
            walk(target, defs, &path, default, out);
            continue;
        }
        let default = match default {
            Some(d) => yaml(d),
            None if required.contains(&name.as_str()) => String::new(),
            None => "none".into(),
        };
        out.push(Field { path, description, takes: takes(prop, defs), default });
    }
}

/// `docs/schema.md`: every field, what it takes, its default, its rustdoc.
pub fn markdown() -> String {
    let mut out = String::from(
        "# Pipeline schema (version 1)\n\n\
         Generated from the config structs' rustdoc by `idrex pipeline schema --format markdown`;\n\
         `tests/docs.rs` keeps this page equal to it. `idrex pipeline schema` prints the JSON\n\
         Schema, for editors that check YAML. How a pipeline expands and ranks:\n\
         [pipelines.md](pipelines.md).\n\n\
         | field | takes | default | meaning |\n|---|---|---|---|\n",
    );
    for f in fields() {
        let cell = |s: &str| s.replace('|', "\\|");
        let default = if f.default.is_empty() { "required".into() } else { format!("`{}`", cell(&f.default)) };
        out.push_str(&format!("| `{}` | {} | {default} | {} |\n", f.path, cell(&f.takes), cell(&f.description)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_field_of_the_file_is_a_row_with_its_default() {
        let fields = fields();
        let get = |p: &str| fields.iter().find(|f| f.path == p).unwrap_or_else(|| panic!("no row {p}"));
        assert_eq!(get("version").default, "", "version is required");
        assert_eq!(get("bc.iterations").default, "50000");
        assert_eq!(get("idrex.multi_bc.bc.iterations").default, "20000");
        assert!(get("reward.level").takes.contains("`ranked-floor`"), "{}", get("reward.level").takes);
        assert!(get("ppo.total_steps").description.contains("steps"), "{:?}", get("ppo.total_steps"));
    }
}
