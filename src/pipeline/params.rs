//! Stage parameters: declared once per stage type, checked, defaulted and normalised here.
//!
//! The declaration drives everything a user sees: validation errors, `shakeflow stages`,
//! `--set key=value` parsing and the JSON Schema. The normalised form (every parameter present,
//! keys sorted, canonical JSON) is what the cache key hashes, so writing a default explicitly
//! does not invalidate the cache.

use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::{Map, Value};

// Declared beside the stage's parameter struct (`crate::declare`), which io's equipment files use too.
pub use crate::declare::{ParamKind, ParamSpec};

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

/// Why a value does not fit its parameter's declaration; [`normalize`] names the parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum ValueError {
    /// Of the wrong kind: what was expected (`a number`, `text`, …).
    #[error("expected {0}")]
    Expected(&'static str),
    #[error("expected one of {options}, found {found}")]
    NotAChoice { options: String, found: Value },
    #[error("expected a list of {len} numbers, like [{like}], found {found}")]
    NotNNumbers { len: usize, like: String, found: Value },
    #[error("expected a list of numbers, like [1, 2.5], found {found}")]
    NotNumbers { found: Value },
    #[error("{value} is outside the allowed range {lo} to {hi}")]
    OutOfRange { value: f64, lo: f64, hi: f64 },
}

/// Why a `--set` assignment does not parse.
#[derive(Debug, thiserror::Error)]
pub enum SetError {
    #[error("`--set {0}` must look like key=value")]
    NotKeyValue(String),
    #[error("`--set {assignment}`: {source}")]
    Yaml { assignment: String, source: serde_yaml::Error },
}

fn check(spec: &ParamSpec, value: Value) -> Result<Value, ValueError> {
    if value.is_null() && spec.default == Some("null") {
        return Ok(value);
    }
    let checked = match spec.kind {
        ParamKind::Float => value.as_f64().map(Value::from).ok_or(ValueError::Expected("a number"))?,
        ParamKind::Int => value.as_i64().map(Value::from).ok_or(ValueError::Expected("a whole number"))?,
        ParamKind::Bool => value.as_bool().map(Value::from).ok_or(ValueError::Expected("true or false"))?,
        ParamKind::Str => value.as_str().map(Value::from).ok_or(ValueError::Expected("text"))?,
        ParamKind::Choice(options) => match value.as_str() {
            Some(s) if options.contains(&s) => Value::from(s),
            _ => return Err(ValueError::NotAChoice { options: options.join(", "), found: value }),
        },
        ParamKind::StrList => match &value {
            Value::String(s) => Value::from(vec![s.clone()]),
            Value::Array(items) if items.iter().all(Value::is_string) => value,
            _ => return Err(ValueError::Expected("a list of names")),
        },
        ParamKind::FloatList(len) => match &value {
            // A single number is a list of one where any length will do.
            Value::Number(_) if len.is_none() => Value::from(vec![value.clone()]),
            Value::Array(items) if items.iter().all(Value::is_number) && len.is_none_or(|n| items.len() == n) => {
                Value::from(items.iter().map(|v| v.as_f64().expect("checked numbers")).collect::<Vec<f64>>())
            }
            _ => {
                return Err(match len {
                    Some(n) => ValueError::NotNNumbers { len: n, like: vec!["0"; n].join(", "), found: value },
                    None => ValueError::NotNumbers { found: value },
                })
            }
        },
        ParamKind::Path => value.as_str().map(Value::from).ok_or(ValueError::Expected("a file path"))?,
    };
    if let Some((lo, hi)) = spec.range {
        let numbers = match &checked {
            Value::Array(items) => items.iter().filter_map(Value::as_f64).collect(),
            other => other.as_f64().into_iter().collect::<Vec<_>>(),
        };
        if let Some(x) = numbers.into_iter().find(|x| !(lo..=hi).contains(x)) {
            return Err(ValueError::OutOfRange { value: x, lo, hi });
        }
    }
    Ok(checked)
}

/// Converts a YAML parameter value to JSON (params are hashed and stored as JSON).
pub fn yaml_to_json(value: &serde_yaml::Value) -> Value {
    serde_json::to_value(value).unwrap_or(Value::Null)
}

/// Parses a `--set key=value` string the way YAML would (`3` is a number, `[a, b]` a list).
pub fn parse_set(assignment: &str) -> Result<(String, Value), SetError> {
    let (key, raw) = assignment.split_once('=').ok_or_else(|| SetError::NotKeyValue(assignment.into()))?;
    let yaml: serde_yaml::Value =
        serde_yaml::from_str(raw).map_err(|source| SetError::Yaml { assignment: assignment.into(), source })?;
    Ok((key.trim().to_string(), yaml_to_json(&yaml)))
}

/// The normalised parameters as a stage type's parameter struct: `#[derive(Deserialize)]
/// #[serde(deny_unknown_fields)]`, declared beside the stage, with enums for choices and `Option`
/// for parameters whose default is null (as Vector deserialises a component's config). The
/// declaration ([`ParamSpec`]) stays what users see; [`check_typed`] proves the two agree.
pub fn typed<T: DeserializeOwned>(params: &Params) -> Result<T, ParamError> {
    serde_json::from_value(Value::Object(params.clone())).map_err(|e| disagreement::<T>(e.to_string()))
}

/// [`typed`], then the struct written back: it must give the normalised parameters exactly, so
/// every declared parameter is a field (`deny_unknown_fields`), every field a declared parameter
/// (a field the declaration lacks comes back as an extra key, even an `Option` one), and every
/// value, choices included, means the same on both sides. The planner calls it through
/// `Stage::check_params` before anything runs.
pub fn check_typed<T: DeserializeOwned + Serialize>(params: &Params) -> Result<(), ParamError> {
    let back = match serde_json::to_value(typed::<T>(params)?) {
        Ok(Value::Object(map)) => map,
        Ok(other) => return Err(disagreement::<T>(format!("it is written back as {other}, not a map"))),
        Err(e) => return Err(disagreement::<T>(e.to_string())),
    };
    let mut differences: Vec<String> = Vec::new();
    for (key, value) in params {
        match back.get(key) {
            None => differences.push(format!("`{key}` is not a field")),
            Some(v) if v != value => differences.push(format!("`{key}`: {value} reads back as {v}")),
            Some(_) => {}
        }
    }
    differences
        .extend(back.keys().filter(|k| !params.contains_key(*k)).map(|k| format!("field `{k}` is not declared")));
    if differences.is_empty() {
        Ok(())
    } else {
        Err(disagreement::<T>(differences.join("; ")))
    }
}

/// A choice's value as pipelines write it (its serde name: `rk4`, `first_frame`), for messages.
pub fn choice_name<T: Serialize>(choice: &T) -> String {
    match serde_json::to_value(choice) {
        Ok(Value::String(name)) => name,
        other => format!("{other:?}"),
    }
}

fn disagreement<T>(detail: String) -> ParamError {
    ParamError {
        key: None,
        message: format!(
            "the parameters do not fit `{}`: {detail}",
            std::any::type_name::<T>().rsplit("::").next().unwrap_or_default()
        ),
        hint: "a defect of shakeflow: the stage type's declared parameters (`shakeflow stages`) and its parameter struct disagree; please report it".into(),
    }
}

impl std::fmt::Display for ParamError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}\n  help: {}", self.message, self.hint)
    }
}

impl std::error::Error for ParamError {}

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

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(deny_unknown_fields)]
    struct Agrees {
        order: usize,
        columns: Vec<String>,
    }

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(deny_unknown_fields)]
    struct UndeclaredField {
        order: usize,
        columns: Vec<String>,
        window: Option<f64>,
    }

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(deny_unknown_fields)]
    struct MissingField {
        order: usize,
    }

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(deny_unknown_fields)]
    struct OtherType {
        order: f64,
        columns: Vec<String>,
    }

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(rename_all = "lowercase")]
    enum Zero {
        FirstFrame,
        Upright,
    }

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(deny_unknown_fields)]
    struct Choices {
        theta_zero: Zero,
    }

    #[test]
    fn a_struct_agrees_with_its_declaration_only_when_fields_and_values_match() {
        let params = normalize(SPECS, "baseline", [("columns", json!("ax_mps2"))]).unwrap();
        check_typed::<Agrees>(&params).unwrap();
        assert_eq!(typed::<Agrees>(&params).unwrap().columns, ["ax_mps2"]);
        let undeclared = check_typed::<UndeclaredField>(&params).unwrap_err().message;
        assert!(undeclared.contains("`UndeclaredField`: field `window` is not declared"), "{undeclared}");
        let missing = check_typed::<MissingField>(&params).unwrap_err().message;
        assert!(missing.contains("unknown field `columns`"), "{missing}");
        let other = check_typed::<OtherType>(&params).unwrap_err().message;
        assert!(other.contains("`order`: 3 reads back as 3.0"), "{other}");
        let choice = [ParamSpec {
            name: "theta_zero",
            kind: ParamKind::Choice(&["first_frame", "upright"]),
            default: Some("\"upright\""),
            unit: "",
            description: "",
            range: None,
        }];
        check_typed::<Choices>(&normalize(&choice, "p", []).unwrap()).unwrap();
        let first = normalize(&choice, "p", [("theta_zero", json!("first_frame"))]).unwrap();
        let renamed = check_typed::<Choices>(&first).unwrap_err().message;
        assert!(renamed.contains("unknown variant `first_frame`"), "{renamed}");
    }

    #[test]
    fn set_values_parse_as_yaml() {
        assert_eq!(parse_set("order=2").unwrap(), ("order".into(), json!(2)));
        assert_eq!(parse_set("columns=[a, b]").unwrap().1, json!(["a", "b"]));
        assert_eq!(parse_set("order").unwrap_err().to_string(), "`--set order` must look like key=value");
        let yaml = parse_set("order=[1").unwrap_err().to_string();
        assert!(yaml.starts_with("`--set order=[1`: "), "{yaml}");
    }

    /// The wording of every refusal of a value, as users read it after `parameter `k` of `s`: `.
    #[test]
    fn value_refusals_keep_their_wording() {
        let spec = |kind, range| ParamSpec { name: "k", kind, default: None, unit: "", description: "", range };
        let refuse = |kind, range, value| check(&spec(kind, range), value).unwrap_err().to_string();
        assert_eq!(refuse(ParamKind::Float, None, json!("x")), "expected a number");
        assert_eq!(refuse(ParamKind::Int, None, json!(1.5)), "expected a whole number");
        assert_eq!(refuse(ParamKind::Bool, None, json!(1)), "expected true or false");
        assert_eq!(refuse(ParamKind::Str, None, json!(1)), "expected text");
        assert_eq!(refuse(ParamKind::Path, None, json!(1)), "expected a file path");
        assert_eq!(refuse(ParamKind::StrList, None, json!([1])), "expected a list of names");
        assert_eq!(refuse(ParamKind::Choice(&["a", "b"]), None, json!("c")), "expected one of a, b, found \"c\"");
        assert_eq!(
            refuse(ParamKind::FloatList(Some(2)), None, json!([1])),
            "expected a list of 2 numbers, like [0, 0], found [1]"
        );
        assert_eq!(
            refuse(ParamKind::FloatList(None), None, json!("x")),
            "expected a list of numbers, like [1, 2.5], found \"x\""
        );
        assert_eq!(refuse(ParamKind::Float, Some((0.0, 1.5)), json!(2.5)), "2.5 is outside the allowed range 0 to 1.5");
    }
}
