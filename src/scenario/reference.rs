//! The reference of every key of the input files (scenario, `synth`, `fit`),
//! made from the types that parse them: each key's type, its default (the
//! type's `Default`, as validation sees it) and what it does (its doc
//! comment, with unit and accepted range). The JSON Schema that `schemars`
//! derives from the serde attributes is the walk: renamed keys, defaults
//! and `Option`s come out as the parser reads them.
//!
//! docs/SCENARIO.md holds these tables between markers; a test regenerates
//! them and fails when the file differs, so a key added without its entry
//! (or with another default) cannot land.

use serde_json::{Map, Value};

use super::bounds::Bounds;

/// One table of keys: a TOML section and its keys.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// The section header as a file writes it: `[mesh]`, `[[render.lights]]`,
    /// `[material.<region>]`; empty for the file's top level.
    pub section: String,
    /// Its keys, in alphabetical order.
    pub rows: Vec<Row>,
}

/// One key of a [`Table`].
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The key.
    pub key: String,
    /// Its TOML type: `bool`, `integer`, `number`, `string`, `[number; 3]`,
    /// or the accepted words (`"fixed" \| "rollers"`).
    pub kind: String,
    /// The default as TOML, `none` for an optional key without one,
    /// `required` for a key the file must give.
    pub default: String,
    /// Whether `default` was read from the doc comment's "Default …"
    /// sentence (a default the validation fills in that no value states).
    pub default_from_comment: bool,
    /// The accepted range ([`super::bounds::Bounds`]): `> 0`, `[0, 1]`,
    /// `each ≥ 0` for an array; empty for a key without one.
    pub range: String,
    /// What it does: the field's doc comment.
    pub meaning: String,
}

/// The tables of the file type `T`, from its top level down, each section
/// before its sub-sections.
pub fn tables<T: schemars::JsonSchema>() -> Vec<Table> {
    let (root, defs) = schema_of::<T>();
    let mut out = Vec::new();
    walk(&defs, &root, "", "", &mut out);
    out
}

/// The JSON Schema of `T` and its definitions (what `$ref`s point to).
pub(super) fn schema_of<T: schemars::JsonSchema>() -> (Value, Map<String, Value>) {
    let root = schemars::schema_for!(T).to_value();
    let defs = root
        .get("$defs")
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    (root, defs)
}

/// The tables as Markdown: per table a `####` heading (none for the top
/// level) and a `key | type | default | accepted | meaning` table.
pub fn markdown(tables: &[Table]) -> String {
    let mut text = String::new();
    for table in tables {
        if !table.section.is_empty() {
            text += &format!("#### `{}`\n\n", table.section);
        }
        text += "| key | type | default | accepted | meaning |\n|---|---|---|---|---|\n";
        for row in &table.rows {
            text += &format!(
                "| `{}` | {} | {} | {} | {} |\n",
                row.key, row.kind, row.default, row.range, row.meaning
            );
        }
        text += "\n";
    }
    text
}

/// How a section nests below its parent.
#[derive(Clone, Copy)]
enum Nesting {
    /// `[parent.key]`.
    Table,
    /// `[[parent.key]]`.
    Array,
    /// `[parent.key.<name>]`: a map of tables.
    Map,
}

/// Adds the table of `schema` (an object) named `path` and, after it, the
/// tables of its sub-sections.
fn walk(defs: &Map<String, Value>, schema: &Value, path: &str, header: &str, out: &mut Vec<Table>) {
    let schema = resolve(defs, schema);
    let props = schema
        .get("properties")
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    let mut keys: Vec<&String> = props.keys().collect();
    keys.sort();
    let mut rows = Vec::new();
    let mut subs = Vec::new();
    for key in keys {
        let prop = &props[key];
        let (inner, optional) = unwrap_option(defs, prop);
        let child = if path.is_empty() {
            key.clone()
        } else {
            format!("{path}.{key}")
        };
        if let Some((nest, table)) = section_of(defs, inner) {
            let header = match nest {
                Nesting::Table => format!("[{child}]"),
                Nesting::Array => format!("[[{child}]]"),
                Nesting::Map => format!("[{child}.<name>]"),
            };
            let child = match nest {
                Nesting::Map => format!("{child}.<name>"),
                _ => child,
            };
            subs.push((child, header, table.clone()));
            continue;
        }
        let (meaning, stated) = split_default(&meaning(prop, resolve(defs, inner)));
        let default_from_comment =
            matches!(prop.get("default"), Some(Value::Null) | None) && stated.is_some();
        let default = match prop.get("default") {
            // A default the validation fills in (an `Option` the file may
            // leave out), as the doc comment states it.
            Some(Value::Null) | None if stated.is_some() => stated.unwrap_or_default(),
            Some(Value::Null) | None if optional => "none".to_string(),
            Some(v) => toml_text(v),
            None if schema
                .get("required")
                .and_then(Value::as_array)
                .is_some_and(|r| r.iter().any(|k| k == key.as_str())) =>
            {
                "required".to_string()
            }
            None => "none".to_string(),
        };
        let range = match (Bounds::of(defs, prop), inner.get("items")) {
            (Some(b), _) => b.text(),
            (None, Some(items)) => Bounds::of(defs, items)
                .map(|b| format!("each {}", b.text()))
                .unwrap_or_default(),
            (None, None) => String::new(),
        };
        rows.push(Row {
            key: key.clone(),
            kind: kind(defs, inner),
            default,
            default_from_comment,
            range,
            meaning,
        });
    }
    if !rows.is_empty() {
        out.push(Table {
            section: header.to_string(),
            rows,
        });
    }
    for (child, header, table) in subs {
        walk(defs, &table, &child, &header, out);
    }
}

/// `schema` with a `$ref` (alone or as the one entry of `allOf`) followed.
pub(super) fn resolve<'a>(defs: &'a Map<String, Value>, schema: &'a Value) -> &'a Value {
    let target = schema.get("$ref").and_then(Value::as_str).or_else(|| {
        match schema.get("allOf").and_then(Value::as_array) {
            Some(all) if all.len() == 1 => all[0].get("$ref").and_then(Value::as_str),
            _ => None,
        }
    });
    match target
        .and_then(|r| r.strip_prefix("#/$defs/"))
        .and_then(|name| defs.get(name))
    {
        Some(found) => resolve(defs, found),
        None => schema,
    }
}

/// The schema inside an `Option` and whether there was one: `anyOf` with a
/// `null` entry, or a type list holding `"null"`.
pub(super) fn unwrap_option<'a>(
    defs: &'a Map<String, Value>,
    schema: &'a Value,
) -> (&'a Value, bool) {
    if let Some(any) = schema.get("anyOf").and_then(Value::as_array) {
        let rest: Vec<&Value> = any
            .iter()
            .filter(|s| s.get("type").and_then(Value::as_str) != Some("null"))
            .collect();
        if rest.len() == 1 && rest.len() < any.len() {
            return (resolve(defs, rest[0]), true);
        }
    }
    let optional = schema
        .get("type")
        .and_then(Value::as_array)
        .is_some_and(|t| t.iter().any(|t| t == "null"));
    (resolve(defs, schema), optional)
}

/// The table a key opens, if it is a section rather than a value: a struct,
/// an array of structs or a map of structs.
fn section_of<'a>(defs: &'a Map<String, Value>, schema: &'a Value) -> Option<(Nesting, &'a Value)> {
    let schema = resolve(defs, schema);
    if schema.get("properties").is_some() {
        return Some((Nesting::Table, schema));
    }
    if let Some(items) = schema.get("items") {
        let items = resolve(defs, items);
        if items.get("properties").is_some() {
            return Some((Nesting::Array, items));
        }
    }
    if let Some(values) = schema.get("additionalProperties").filter(|v| v.is_object()) {
        let values = resolve(defs, values);
        if values.get("properties").is_some() {
            return Some((Nesting::Map, values));
        }
    }
    None
}

/// The TOML type of a value's schema.
fn kind(defs: &Map<String, Value>, schema: &Value) -> String {
    let schema = resolve(defs, schema);
    let words: Vec<String> = match (
        schema.get("enum"),
        schema.get("oneOf").or(schema.get("anyOf")),
    ) {
        (Some(Value::Array(values)), _) => values.iter().map(toml_text).collect(),
        (_, Some(Value::Array(variants))) => variants
            .iter()
            .map(
                |v| match v.get("const").or(v.get("enum").and_then(|e| e.get(0))) {
                    Some(c) => toml_text(c),
                    None => kind(defs, v),
                },
            )
            .collect(),
        _ => Vec::new(),
    };
    if !words.is_empty() {
        return words.join(" \\| ");
    }
    let types: Vec<&str> = match schema.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(list)) => list.iter().filter_map(Value::as_str).collect(),
        _ => Vec::new(),
    };
    match types.iter().find(|t| **t != "null").copied() {
        Some("boolean") => "bool".into(),
        Some("integer") => "integer".into(),
        Some("number") => "number".into(),
        Some("string") => "string".into(),
        Some("array") => {
            let item = schema
                .get("items")
                .map_or("value".to_string(), |i| kind(defs, i));
            let min = schema.get("minItems").and_then(Value::as_u64);
            let max = schema.get("maxItems").and_then(Value::as_u64);
            match (min, max) {
                (Some(a), Some(b)) if a == b => format!("[{item}; {a}]"),
                _ => format!("[{item}, …]"),
            }
        }
        Some("object") => "table".into(),
        _ => "value".into(),
    }
}

/// A value as TOML writes it (`none` for null).
fn toml_text(value: &Value) -> String {
    match value {
        Value::Null => "none".into(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) => i.to_string(),
            (None, Some(f)) if f32_exact(f) => format!("{}", f as f32),
            (None, Some(f)) => format!("{f}"),
            _ => n.to_string(),
        },
        Value::String(s) => format!("`\"{s}\"`"),
        Value::Array(items) => {
            let inner: Vec<String> = items.iter().map(toml_text).collect();
            format!("[{}]", inner.join(", ")).replace('`', "")
        }
        Value::Object(_) => "table".into(),
    }
}

/// Whether `f` is an `f32` value widened (printed then as the `f32`, whose
/// shortest form is the one the code wrote).
fn f32_exact(f: f64) -> bool {
    f.is_finite() && (f as f32) as f64 == f
}

/// The doc comment without its "Default …" sentence, and that sentence's
/// value (`Default 10.` → `10`; `Default: none, generate one.` → `none,
/// generate one`).
fn split_default(meaning: &str) -> (String, Option<String>) {
    let Some(start) = meaning.find("Default") else {
        return (meaning.to_string(), None);
    };
    let after = &meaning[start + "Default".len()..];
    let Some(value) = after.strip_prefix(' ').or_else(|| after.strip_prefix(": ")) else {
        return (meaning.to_string(), None);
    };
    // The sentence ends at ". " or at the end of the comment.
    let end = value.find(". ").unwrap_or(value.len());
    let stated = value[..end].trim_end_matches('.').trim().to_string();
    let rest = format!(
        "{}{}",
        &meaning[..start],
        value[end..].trim_start_matches(". ")
    );
    (rest.trim().to_string(), Some(stated))
}

/// A key's doc comment on one line (its type's when the field has none),
/// with the table's column separator escaped.
fn meaning(prop: &Value, resolved: &Value) -> String {
    let text_of = |s: &Value| -> String {
        let title = s.get("title").and_then(Value::as_str).unwrap_or("");
        let body = s.get("description").and_then(Value::as_str).unwrap_or("");
        match (title.is_empty(), body.is_empty()) {
            (false, false) => format!("{title}. {body}"),
            (false, true) => title.to_string(),
            _ => body.to_string(),
        }
    };
    let mut text = text_of(prop);
    if text.is_empty() {
        text = text_of(resolved);
    }
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}
