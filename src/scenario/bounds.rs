//! The accepted range of every numeric key, checked from the one place it
//! is written: the key's `#[schemars(range(…))]` (inclusive bounds) or
//! `#[schemars(extend("exclusiveMinimum" = …))]` attribute. The same JSON
//! Schema gives docs/SCENARIO.md its "accepted" column ([`super::reference`]),
//! so a range cannot be checked one way and documented another.
//!
//! A file's values are walked as TOML (where `nan` and `inf` stay numbers,
//! unlike JSON), beside the schema of their type: a number under a bound
//! must be finite and within it, and the error names the dotted key.

use serde::Serialize;
use serde_json::{Map, Value};

use super::reference::{resolve, schema_of, unwrap_option};
use crate::error::{shown, Error, Result};

/// Checks every bounded number of `value` (a whole file: [`super::Scenario`],
/// [`super::SynthFile`], [`super::FitSamples`]) against its type's schema.
pub fn check<T: schemars::JsonSchema + Serialize>(value: &T) -> Result<()> {
    check_at(value, "")
}

/// [`check`] for one section of a file, `key` its dotted name (`render`),
/// for the sections whose validation is also called on its own.
pub fn check_at<T: schemars::JsonSchema + Serialize>(value: &T, key: &str) -> Result<()> {
    let (root, defs) = schema_of::<T>();
    let values = toml::Value::try_from(value)
        .map_err(|e| Error::parameter("(file)", format!("cannot be checked: {e}")))?;
    walk(&defs, &root, &values, key)
}

/// The accepted range a schema states, if any.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Lower bound and whether it is excluded.
    pub low: Option<(f64, bool)>,
    /// Upper bound and whether it is excluded.
    pub high: Option<(f64, bool)>,
    /// Whether the key is an integer (ranges then read `1 … 8`).
    pub integer: bool,
}

impl Bounds {
    /// The bounds of a value's schema (its `Option` and `$ref` followed);
    /// `None` without any.
    pub fn of(defs: &Map<String, Value>, schema: &Value) -> Option<Bounds> {
        let (schema, _) = unwrap_option(defs, schema);
        let number = |key: &str| schema.get(key).and_then(Value::as_f64);
        let low = match (number("exclusiveMinimum"), number("minimum")) {
            (Some(v), _) => Some((v, true)),
            (None, Some(v)) => Some((v, false)),
            (None, None) => None,
        };
        let high = match (number("exclusiveMaximum"), number("maximum")) {
            (Some(v), _) => Some((v, true)),
            (None, Some(v)) => Some((v, false)),
            (None, None) => None,
        };
        let integer = schema.get("type").is_some_and(|t| match t {
            Value::String(s) => s == "integer",
            Value::Array(list) => list.iter().any(|t| t == "integer"),
            _ => false,
        });
        (low.is_some() || high.is_some()).then_some(Bounds { low, high, integer })
    }

    /// Whether `v` is accepted: finite and within both bounds.
    pub fn admits(&self, v: f64) -> bool {
        let above = match self.low {
            Some((lo, true)) => v > lo,
            Some((lo, false)) => v >= lo,
            None => true,
        };
        let below = match self.high {
            Some((hi, true)) => v < hi,
            Some((hi, false)) => v <= hi,
            None => true,
        };
        v.is_finite() && above && below
    }

    /// The range as the docs and the errors write it: `> 0`, `≥ 1`, `≤ 10`,
    /// `[0, 1]`, `(0, 1]`, or `1 … 8` for an integer.
    pub fn text(&self) -> String {
        match (self.low, self.high) {
            (Some((lo, false)), Some((hi, false))) if self.integer => {
                format!("{} … {}", self.shown(lo), self.shown(hi))
            }
            (Some((lo, open_lo)), Some((hi, open_hi))) => format!(
                "{}{}, {}{}",
                if open_lo { '(' } else { '[' },
                shown(lo),
                shown(hi),
                if open_hi { ')' } else { ']' }
            ),
            (Some((lo, true)), None) => format!("> {}", shown(lo)),
            (Some((lo, false)), None) => format!("≥ {}", shown(lo)),
            (None, Some((hi, true))) => format!("< {}", shown(hi)),
            (None, Some((hi, false))) => format!("≤ {}", shown(hi)),
            (None, None) => String::new(),
        }
    }

    /// The error for `v` under `key`.
    fn refuse(&self, key: &str, v: f64) -> Error {
        let range = self.text();
        let phrase = if range.starts_with(['[', '(']) || range.contains('…') {
            format!("must be in {range}")
        } else {
            format!("must be {range}")
        };
        Error::parameter(key, format!("{phrase}, got {}", self.shown(v)))
    }

    /// A value of this key as written: whole numbers of an integer key in
    /// full, others as [`shown`].
    fn shown(&self, v: f64) -> String {
        if self.integer && v.fract() == 0.0 && v.abs() < 9e15 {
            format!("{}", v as i64)
        } else {
            shown(v)
        }
    }
}

/// Checks `value` (at `key`) and everything below it against `schema`.
fn walk(defs: &Map<String, Value>, schema: &Value, value: &toml::Value, key: &str) -> Result<()> {
    let (inner, _) = unwrap_option(defs, schema);
    let inner = resolve(defs, inner);
    match value {
        toml::Value::Table(table) => {
            let props = inner.get("properties").and_then(Value::as_object);
            let each = inner.get("additionalProperties").filter(|v| v.is_object());
            for (name, v) in table {
                let child = if key.is_empty() {
                    name.clone()
                } else {
                    format!("{key}.{name}")
                };
                match (props.and_then(|p| p.get(name)), each) {
                    (Some(s), _) | (None, Some(s)) => walk(defs, s, v, &child)?,
                    (None, None) => {}
                }
            }
            Ok(())
        }
        toml::Value::Array(items) => match inner.get("items") {
            Some(item) => items
                .iter()
                .enumerate()
                .try_for_each(|(i, v)| walk(defs, item, v, &format!("{key}[{i}]"))),
            None => Ok(()),
        },
        toml::Value::Integer(i) => number(defs, schema, key, *i as f64),
        toml::Value::Float(f) => number(defs, schema, key, *f),
        _ => Ok(()),
    }
}

fn number(defs: &Map<String, Value>, schema: &Value, key: &str, v: f64) -> Result<()> {
    match Bounds::of(defs, schema) {
        Some(bounds) if !bounds.admits(v) => Err(bounds.refuse(key, v)),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use serde::Serialize;

    use super::*;

    #[derive(Serialize, schemars::JsonSchema)]
    struct Inner {
        #[schemars(range(min = 1, max = 8))]
        count: usize,
        #[schemars(inner(range(min = 0.0)))]
        colour: [f64; 3],
    }

    #[derive(Serialize, schemars::JsonSchema)]
    struct File {
        #[schemars(extend("exclusiveMinimum" = 0.0))]
        width: f64,
        #[schemars(range(min = 0.0, max = 1.0))]
        share: Option<f64>,
        free: f64,
        list: Vec<Inner>,
        map: BTreeMap<String, Inner>,
    }

    fn file() -> File {
        let inner = || Inner {
            count: 4,
            colour: [1.0, 0.5, 0.0],
        };
        File {
            width: 2.0,
            share: None,
            free: f64::NAN,
            list: vec![inner(), inner()],
            map: BTreeMap::from([("dermis".to_string(), inner())]),
        }
    }

    fn refused(f: &File) -> String {
        check(f).unwrap_err().to_string()
    }

    /// Every bound is held where the value sits: at the top, in an
    /// `Option`, in a list of tables, in a map of tables and in an array;
    /// NaN and infinity are refused wherever a bound applies, and a key
    /// without one is left alone.
    #[test]
    fn every_bound_is_checked_with_its_key() {
        assert!(check(&file()).is_ok());
        let mut f = file();
        f.width = 0.0;
        assert_eq!(refused(&f), "width must be > 0, got 0");
        f.width = f64::NAN;
        assert_eq!(refused(&f), "width must be > 0, got NaN");
        let mut f = file();
        f.share = Some(1.5);
        assert_eq!(refused(&f), "share must be in [0, 1], got 1.5");
        f.share = Some(f64::INFINITY);
        assert_eq!(refused(&f), "share must be in [0, 1], got inf");
        let mut f = file();
        f.list[1].count = 9;
        assert_eq!(refused(&f), "list[1].count must be in 1 … 8, got 9");
        let mut f = file();
        f.map.get_mut("dermis").unwrap().colour[2] = -1e-9;
        assert_eq!(refused(&f), "map.dermis.colour[2] must be ≥ 0, got -1e-9");
    }

    /// Every bounded key of an input file, as `(key, a file holding just
    /// that key with a value outside its range)`: a table for a section,
    /// one entry for a list or map of tables, one item for an array.
    fn outside_each_bound(
        defs: &Map<String, Value>,
        schema: &Value,
        key: &str,
    ) -> Vec<(String, toml::Value)> {
        let (inner, _) = unwrap_option(defs, schema);
        let inner = resolve(defs, inner);
        let mut out = Vec::new();
        if let Some(props) = inner.get("properties").and_then(Value::as_object) {
            for (name, prop) in props {
                let child = if key.is_empty() {
                    name.clone()
                } else {
                    format!("{key}.{name}")
                };
                for (k, v) in outside_each_bound(defs, prop, &child) {
                    out.push((
                        k,
                        toml::Value::Table([(name.clone(), v)].into_iter().collect()),
                    ));
                }
            }
        } else if let Some(each) = inner.get("additionalProperties").filter(|v| v.is_object()) {
            for (k, v) in outside_each_bound(defs, each, &format!("{key}.x")) {
                out.push((
                    k,
                    toml::Value::Table([("x".to_string(), v)].into_iter().collect()),
                ));
            }
        } else if let Some(item) = inner.get("items") {
            for (k, v) in outside_each_bound(defs, item, &format!("{key}[0]")) {
                out.push((k, toml::Value::Array(vec![v])));
            }
        } else if let Some(b) = Bounds::of(defs, schema) {
            let v = match (b.low, b.high) {
                (Some((lo, _)), _) if lo > 0.0 || !b.integer => lo - 1.0,
                (_, Some((hi, _))) => hi + 1.0,
                _ => return out, // an unsigned integer: serde refuses negatives
            };
            let v = if b.integer {
                toml::Value::Integer(v as i64)
            } else {
                toml::Value::Float(v)
            };
            out.push((key.to_string(), v));
        }
        out
    }

    fn refuses_every_bound<T: schemars::JsonSchema>(least: usize) {
        let (root, defs) = schema_of::<T>();
        let cases = outside_each_bound(&defs, &root, "");
        assert!(cases.len() >= least, "{} bounded keys", cases.len());
        for (key, file) in cases {
            let err = walk(&defs, &root, &file, "").map_err(|e| e.to_string());
            assert!(
                err.as_ref()
                    .is_err_and(|e| e.starts_with(&format!("{key} must be"))),
                "{key}: {err:?}"
            );
        }
    }

    /// Each range the docs' tables show is held by the check, wherever the
    /// key sits in the file: the walk follows every `Option`, list, map and
    /// array the schema has.
    #[test]
    fn every_documented_range_is_enforced() {
        refuses_every_bound::<super::super::Scenario>(90);
        refuses_every_bound::<super::super::SynthFile>(30);
        refuses_every_bound::<super::super::FitSamples>(6);
    }

    #[test]
    fn ranges_read_as_written() {
        let b = |low, high, integer| Bounds { low, high, integer }.text();
        assert_eq!(b(Some((0.0, true)), Some((1.0, false)), false), "(0, 1]");
        assert_eq!(b(Some((1.0, false)), Some((64.0, false)), true), "1 … 64");
        assert_eq!(b(Some((1.0, false)), Some((64.0, false)), false), "[1, 64]");
        assert_eq!(b(None, Some((10.0, false)), false), "≤ 10");
        assert_eq!(
            b(Some((0.01, false)), Some((170.0, true)), false),
            "[0.01, 170)"
        );
    }
}
