//! Stage parameters: declared once per stage type, checked, defaulted and normalised here.
//!
//! The declaration drives everything a user sees: validation errors, `shakeflow stages`,
//! `--set key=value` parsing and the JSON Schema. The normalised form (every parameter present,
//! keys sorted, canonical JSON) is what the cache key hashes, so writing a default explicitly
//! does not invalidate the cache.

use serde_json::{Map, Value};

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamKind {
    Float,
    Int,
    Bool,
    Str,
    Choice(&'static [&'static str]),
    /// A list of names (e.g. columns); empty means "all".
    StrList,
    /// A list of numbers (e.g. scale factors), of exactly this many when given.
    FloatList(Option<usize>),
    /// A file path, relative to the pipeline file; the file's content is part of the cache key,
    /// so editing the file reruns the stage.
    Path,
}

impl ParamKind {
    pub fn describe(&self) -> String {
        match self {
            ParamKind::Float => "number".into(),
            ParamKind::Int => "integer".into(),
            ParamKind::Bool => "true|false".into(),
            ParamKind::Str => "text".into(),
            ParamKind::Choice(options) => options.join("|"),
            ParamKind::StrList => "list of names".into(),
            ParamKind::FloatList(Some(n)) => format!("list of {n} numbers"),
            ParamKind::FloatList(None) => "list of numbers".into(),
            ParamKind::Path => "file path (relative to the pipeline file)".into(),
        }
    }
}

#[derive(Debug, Clone, Copy)]
pub struct ParamSpec {
    pub name: &'static str,
    pub kind: ParamKind,
    /// JSON literal of the default; `None` makes the parameter required.
    pub default: Option<&'static str>,
    pub unit: &'static str,
    pub description: &'static str,
    /// Inclusive numeric bounds, checked on Float and Int.
    pub range: Option<(f64, f64)>,
}

pub type Params = Map<String, Value>;

/// Why a parameter was refused, with the parameter's name so the caller can point at it.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamError {
    pub key: Option<String>,
    pub message: String,
    pub hint: String,
}

pub fn normalize<'v>(
    specs: &[ParamSpec],
    stage_type: &str,
    given: impl IntoIterator<Item = (&'v str, Value)>,
) -> Result<Params, ParamError> {
    let mut out = Map::new();
    for (key, value) in given {
        let Some(spec) = specs.iter().find(|s| s.name == key) else {
            let allowed: Vec<&str> = specs.iter().map(|s| s.name).collect();
            let suggestion = crate::error::did_you_mean_hint(key, allowed.iter().copied());
            return Err(ParamError {
                key: Some(key.to_string()),
                message: format!("unknown parameter `{key}` for stage type `{stage_type}`"),
                hint: if allowed.is_empty() {
                    format!("`{stage_type}` takes no parameters")
                } else {
                    format!("{suggestion}allowed: {}", allowed.join(", "))
                },
            });
        };
        let value = check(spec, value).map_err(|message| ParamError {
            key: Some(key.to_string()),
            message: format!("parameter `{key}` of `{stage_type}`: {message}"),
            hint: format!("`{key}` is {} — {}", spec.kind.describe(), spec.description),
        })?;
        out.insert(key.to_string(), value);
    }
    for spec in specs {
        if out.contains_key(spec.name) {
            continue;
        }
        match spec.default {
            Some(literal) => {
                out.insert(spec.name.to_string(), serde_json::from_str(literal).expect("defaults are valid JSON"));
            }
            None => {
                return Err(ParamError {
                    key: None,
                    message: format!("stage type `{stage_type}` needs parameter `{}`", spec.name),
                    hint: format!(
                        "add `{}: <{}>` under `params` — {}",
                        spec.name,
                        spec.kind.describe(),
                        spec.description
                    ),
                })
            }
        }
    }
    out.sort_keys();
    Ok(out)
}

fn check(spec: &ParamSpec, value: Value) -> Result<Value, String> {
    if value.is_null() && spec.default == Some("null") {
        return Ok(value);
    }
    let checked = match spec.kind {
        ParamKind::Float => value.as_f64().map(Value::from).ok_or("expected a number")?,
        ParamKind::Int => value.as_i64().map(Value::from).ok_or("expected a whole number")?,
        ParamKind::Bool => value.as_bool().map(Value::from).ok_or("expected true or false")?,
        ParamKind::Str => value.as_str().map(Value::from).ok_or("expected text")?,
        ParamKind::Choice(options) => match value.as_str() {
            Some(s) if options.contains(&s) => Value::from(s),
            _ => return Err(format!("expected one of {}, found {value}", options.join(", "))),
        },
        ParamKind::StrList => match &value {
            Value::String(s) => Value::from(vec![s.clone()]),
            Value::Array(items) if items.iter().all(Value::is_string) => value,
            _ => return Err("expected a list of names".into()),
        },
        ParamKind::FloatList(len) => match &value {
            // A single number is a list of one where any length will do.
            Value::Number(_) if len.is_none() => Value::from(vec![value.clone()]),
            Value::Array(items) if items.iter().all(Value::is_number) && len.is_none_or(|n| items.len() == n) => {
                Value::from(items.iter().map(|v| v.as_f64().expect("checked numbers")).collect::<Vec<f64>>())
            }
            _ => {
                return Err(match len {
                    Some(n) => {
                        format!("expected a list of {n} numbers, like [{}], found {value}", vec!["0"; n].join(", "))
                    }
                    None => format!("expected a list of numbers, like [1, 2.5], found {value}"),
                })
            }
        },
        ParamKind::Path => value.as_str().map(Value::from).ok_or("expected a file path")?,
    };
    if let Some((lo, hi)) = spec.range {
        let numbers = match &checked {
            Value::Array(items) => items.iter().filter_map(Value::as_f64).collect(),
            other => other.as_f64().into_iter().collect::<Vec<_>>(),
        };
        if let Some(x) = numbers.into_iter().find(|x| !(lo..=hi).contains(x)) {
            return Err(format!("{x} is outside the allowed range {lo} to {hi}"));
        }
    }
    Ok(checked)
}

/// Converts a YAML parameter value to JSON (params are hashed and stored as JSON).
pub fn yaml_to_json(value: &serde_yaml::Value) -> Value {
    serde_json::to_value(value).unwrap_or(Value::Null)
}

/// Parses a `--set key=value` string the way YAML would (`3` is a number, `[a, b]` a list).
pub fn parse_set(assignment: &str) -> Result<(String, Value), String> {
    let (key, raw) =
        assignment.split_once('=').ok_or_else(|| format!("`--set {assignment}` must look like key=value"))?;
    let yaml: serde_yaml::Value = serde_yaml::from_str(raw).map_err(|e| format!("`--set {assignment}`: {e}"))?;
    Ok((key.trim().to_string(), yaml_to_json(&yaml)))
}

/// Typed access for stage implementations; the values were checked by `normalize`.
pub trait ParamsExt {
    fn f64_of(&self, key: &str) -> f64;
    fn i64_of(&self, key: &str) -> i64;
    fn bool_of(&self, key: &str) -> bool;
    fn str_of(&self, key: &str) -> &str;
    fn list_of(&self, key: &str) -> Vec<String>;
    /// None when the parameter is null (its "not given" default).
    fn opt_f64(&self, key: &str) -> Option<f64>;
    fn opt_str(&self, key: &str) -> Option<&str>;
    fn f64_list_of(&self, key: &str) -> Option<Vec<f64>>;
}

impl ParamsExt for Params {
    fn f64_of(&self, key: &str) -> f64 {
        self[key].as_f64().unwrap_or_else(|| panic!("parameter `{key}` was normalised as a number"))
    }
    fn i64_of(&self, key: &str) -> i64 {
        self[key].as_i64().unwrap_or_else(|| panic!("parameter `{key}` was normalised as an integer"))
    }
    fn bool_of(&self, key: &str) -> bool {
        self[key].as_bool().unwrap_or_else(|| panic!("parameter `{key}` was normalised as a bool"))
    }
    fn str_of(&self, key: &str) -> &str {
        self[key].as_str().unwrap_or_else(|| panic!("parameter `{key}` was normalised as text"))
    }
    fn list_of(&self, key: &str) -> Vec<String> {
        self[key]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_str().map(String::from)).collect())
            .unwrap_or_default()
    }
    fn opt_f64(&self, key: &str) -> Option<f64> {
        self[key].as_f64()
    }
    fn opt_str(&self, key: &str) -> Option<&str> {
        self[key].as_str()
    }
    fn f64_list_of(&self, key: &str) -> Option<Vec<f64>> {
        self[key].as_array().map(|a| a.iter().filter_map(Value::as_f64).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    const SPECS: &[ParamSpec] = &[
        ParamSpec {
            name: "order",
            kind: ParamKind::Int,
            default: Some("3"),
            unit: "",
            description: "polynomial order",
            range: Some((0.0, 10.0)),
        },
        ParamSpec {
            name: "columns",
            kind: ParamKind::StrList,
            default: Some("[]"),
            unit: "",
            description: "channels",
            range: None,
        },
    ];

    #[test]
    fn defaults_fill_in_and_explicit_defaults_normalise_identically() {
        let implicit = normalize(SPECS, "baseline", []).unwrap();
        let explicit = normalize(SPECS, "baseline", [("order", json!(3))]).unwrap();
        assert_eq!(implicit, explicit);
        assert_eq!(serde_json::to_string(&implicit).unwrap(), r#"{"columns":[],"order":3}"#);
    }

    #[test]
    fn unknown_key_suggests_the_close_one() {
        let err = normalize(SPECS, "baseline", [("ordr", json!(2))]).unwrap_err();
        assert_eq!(err.key.as_deref(), Some("ordr"));
        assert!(err.hint.contains("did you mean `order`"), "{}", err.hint);
    }

    #[test]
    fn type_and_range_are_checked() {
        assert!(normalize(SPECS, "b", [("order", json!("three"))]).unwrap_err().message.contains("whole number"));
        assert!(normalize(SPECS, "b", [("order", json!(11))]).unwrap_err().message.contains("outside"));
    }

    #[test]
    fn number_lists_have_their_length_and_range() {
        let specs = [ParamSpec {
            name: "steer0_deg",
            kind: ParamKind::FloatList(Some(4)),
            default: Some("null"),
            unit: "deg",
            description: "one per caster",
            range: Some((-360.0, 360.0)),
        }];
        let ok = normalize(&specs, "s", [("steer0_deg", parse_set("steer0_deg=[80,0,0,80]").unwrap().1)]).unwrap();
        assert_eq!(ok["steer0_deg"], json!([80.0, 0.0, 0.0, 80.0]));
        assert_eq!(normalize(&specs, "s", []).unwrap()["steer0_deg"], Value::Null);
        let short = normalize(&specs, "s", [("steer0_deg", json!([1, 2]))]).unwrap_err();
        assert!(short.message.contains("list of 4 numbers"), "{}", short.message);
        assert!(normalize(&specs, "s", [("steer0_deg", json!([1, 2, 3, 400]))]).unwrap_err().message.contains("400"));
    }

    #[test]
    fn set_values_parse_as_yaml() {
        assert_eq!(parse_set("order=2").unwrap(), ("order".into(), json!(2)));
        assert_eq!(parse_set("columns=[a, b]").unwrap().1, json!(["a", "b"]));
        assert!(parse_set("order").is_err());
    }
}
