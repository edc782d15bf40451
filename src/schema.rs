//! JSON Schema of pipeline files, generated from the stage registry so it cannot drift:
//! `schemas/pipeline.schema.json` is this output (a test compares them).

use serde_json::{json, Map, Value};

use crate::pipeline::params::{ParamKind, ParamSpec};
use crate::pipeline::spec::RecordFormat;
use crate::stages;

fn param_schema(p: &ParamSpec) -> Value {
    let mut s = match p.kind {
        ParamKind::Float => json!({"type": "number"}),
        ParamKind::Int => json!({"type": "integer"}),
        ParamKind::Bool => json!({"type": "boolean"}),
        ParamKind::Str => json!({"type": "string"}),
        ParamKind::Choice(options) => json!({"enum": options}),
        ParamKind::StrList => json!({"type": "array", "items": {"type": "string"}}),
        ParamKind::FloatList(Some(n)) => {
            json!({"type": "array", "items": {"type": "number"}, "minItems": n, "maxItems": n})
        }
        ParamKind::FloatList(None) => json!({"type": "array", "items": {"type": "number"}}),
        ParamKind::Path => json!({"type": "string"}),
    };
    // A null default means "not given": null must validate too.
    if p.default == Some("null") {
        if let Some(options) = s.get_mut("enum").and_then(Value::as_array_mut) {
            options.push(Value::Null);
        } else if let Some(kind) = s.get("type").cloned() {
            s["type"] = json!([kind, "null"]);
        }
    }
    let unit = if p.unit.is_empty() { String::new() } else { format!(" [{}]", p.unit) };
    s["description"] = Value::from(format!("{}{unit}", p.description));
    if let Some(default) = p.default {
        s["default"] = serde_json::from_str(default).expect("defaults are valid JSON");
    }
    match (p.range, p.kind) {
        (Some((lo, hi)), ParamKind::Float | ParamKind::Int) => {
            s["minimum"] = json!(lo);
            s["maximum"] = json!(hi);
        }
        (Some((lo, hi)), ParamKind::FloatList(_)) => {
            s["items"]["minimum"] = json!(lo);
            s["items"]["maximum"] = json!(hi);
        }
        _ => {}
    }
    s
}

pub fn pipeline_schema() -> Value {
    let names = stages::registry().names();
    let mut conditionals = Vec::new();
    for stage in stages::registry().0 {
        let info = stage.info();
        let properties: Map<String, Value> =
            info.params.iter().map(|p| (p.name.to_string(), param_schema(p))).collect();
        let required: Vec<&str> = info.params.iter().filter(|p| p.default.is_none()).map(|p| p.name).collect();
        conditionals.push(json!({
            "if": {"properties": {"type": {"const": info.name}}},
            "then": {"properties": {"params": {
                "type": "object", "additionalProperties": false, "properties": properties, "required": required,
                "description": format!("parameters of `{}`", info.name)
            }}}
        }));
    }
    // Its own value: one `json!` of the whole schema would pass the macro recursion limit.
    let components = json!({"type": "object", "additionalProperties": false, "required": ["key"], "description": "records whose components are files of their own (K-NET .EW/.NS/.UD, PEER .AT2, COSMOS .V2c per channel): files whose partition keys agree but for `key` are one record (docs/formats.md)", "properties": {
        "key": {"type": "string", "description": "the {key} of `path` naming a file's component; not a partition key"},
        "require": {"type": "array", "items": {"enum": ["x", "y", "z"]}, "default": ["x", "y", "z"], "description": "axes every record must have; a record missing one is refused, naming its files"},
        "axes": {"type": "object", "additionalProperties": {"enum": ["x", "y", "z"]}, "description": "component (the key's value) → axis, for files whose header does not say where they point"}
    }});
    json!({
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": "shakeflow pipeline",
        "description": "A shakeflow pipeline: record sources, and stages that read them or each other. Paths are relative to the pipeline file.",
        "type": "object",
        "additionalProperties": false,
        "required": ["version", "output_dir", "stages"],
        "properties": {
            "version": {"const": 1, "description": "pipeline format version"},
            "description": {"type": "string"},
            "output_dir": {"type": "string", "description": "where artifacts and shakeflow.lock are written"},
            "executor": {
                "type": "object",
                "additionalProperties": false,
                "description": "Slurm options for `shakeflow run --executor slurm` (flags override them; docs/slurm.md)",
                "properties": {
                    "partition": {"type": "string"},
                    "account": {"type": "string"},
                    "time_limit": {"type": "string", "description": "per array task: MM, HH:MM:SS, D-HH:MM:SS"},
                    "cpus_per_task": {"type": "integer", "minimum": 1},
                    "mem": {"type": "string", "description": "per task, e.g. 4G"},
                    "array_throttle": {"type": "integer", "minimum": 1, "description": "at most this many tasks of one array at once"},
                    "retries": {"type": "integer", "minimum": 0, "description": "resubmits the failed shards this many times"},
                    "requeue": {"type": "boolean", "description": "let Slurm requeue preempted tasks"},
                    "in_allocation": {"type": "boolean", "description": "run each shard as an srun step inside the current sbatch/salloc allocation"},
                    "sbatch_args": {"type": "array", "items": {"type": "string"}}
                }
            },
            "inputs": {"type": "object", "description": "record sources by name", "additionalProperties": {"$ref": "#/definitions/source"}},
            "stages": {"type": "object", "description": "processing stages by name", "additionalProperties": {"$ref": "#/definitions/stage"}}
        },
        "definitions": {
            "source": {
                "type": "object",
                "additionalProperties": false,
                "required": ["format", "path"],
                "properties": {
                    "format": {"enum": RecordFormat::ALL.map(|f| f.name()), "description": "record file format (read by `load`), or `frames` (an image sequence: a folder of PNG/JPEG frames or a video file, for `cpt_track`) or `control_points` (X_mm, Y_mm, Z_mm, u_px, v_px CSV, for `cpt_calibrate`), or `case` (a diagnosis case folder, named by its equipment.yaml, for `diagnose`), or `auto` (each file's record format from its content, else its extension; the load metadata names the reader used), or `dataset` (tables another stage or pipeline wrote: a dataset folder of `key=value/…/data.parquet` parts or one Parquet file, for stages that read stage outputs; record-file options do not apply)"},
                    "path": {"type": "string", "description": "file (or, for `frames` and `dataset`, a folder), glob, or template whose {key} parts become partition keys"},
                    "description": {"type": "string"},
                    "partition": {"type": "object", "additionalProperties": {"type": "string"}, "description": "constant partition keys for every record"},
                    "header_lines": {"type": "integer", "minimum": 0, "default": 0, "description": "delimited: lines before the column-name row"},
                    "column_names": {"type": "boolean", "default": true, "description": "delimited: a column-name row follows the header lines"},
                    "delimiter": {"type": ["string", "null"], "description": "delimited: one character, \\t, or whitespace; absent: detected"},
                    "units_row": {"type": ["integer", "null"], "minimum": 1, "description": "delimited: the file's line (1-based, below the column names) holding each column's unit, as NEES files have; converted to SI like declared units"},
                    "description_row": {"type": ["integer", "null"], "minimum": 1, "description": "delimited: the file's line (1-based, below the column names) holding each column's description"},
                    "calibration": {"type": ["string", "null"], "description": "raw data (V, mV, counts): a sensitivity table, CSV `channel,sensitivity,unit,offset`; a channel it names is (raw − offset) / sensitivity in `unit` (docs/formats.md)"},
                    "time_column": {"type": ["string", "null"], "description": "delimited: the time column"},
                    "time_unit": {"type": ["string", "null"], "description": "unit of the time column (s, ms)"},
                    "dt": {"type": ["number", "null"], "exclusiveMinimum": 0, "description": "sample interval [s] when the file has no time"},
                    "unit": {"type": ["string", "null"], "description": "unit of the channels (g, g/10, m/s^2, cm/s^2, ...)"},
                    "columns": {"type": "object", "additionalProperties": {"$ref": "#/definitions/column"}, "description": "output column name → file column"},
                    "scale": {"type": "number", "default": 1.0, "description": "factor applied after unit conversion"},
                    "gaps": {"enum": ["error", "interpolate"], "default": "error", "description": "what to do with empty/NaN samples"},
                    "non_uniform": {"enum": ["error", "resample"], "default": "error", "description": "what to do with a non-uniform time column"},
                    "on_error": {"enum": ["fail", "skip"], "default": "fail", "description": "a record that cannot be read: `fail` fails its work unit; `skip` lists it in the load stage's `flagged` table and goes on (exit status 2)"},
                    "component_as": {"enum": ["ax", "ay", "label"], "default": "ax", "description": "accelerogram formats without `columns`: the axis a record's lone horizontal component becomes, or `label` to keep the file's channel names (docs/formats.md)"},
                    "components": components
                }
            },
            "column": {
                "oneOf": [
                    {"type": "string", "description": "the file's column name"},
                    {"type": "object", "additionalProperties": false, "required": ["column"], "properties": {
                        "column": {"type": "string"},
                        "unit": {"type": ["string", "null"]},
                        "scale": {"type": ["number", "null"]},
                        "description": {"type": ["string", "null"]}
                    }}
                ]
            },
            "stage": {
                "type": "object",
                "additionalProperties": false,
                "required": ["type"],
                "properties": {
                    "type": {"enum": names, "description": "stage type (shakeflow stages)"},
                    "description": {"type": "string"},
                    "inputs": {"type": "array", "items": {"type": "string"}, "description": "sources or stages (stage or stage.output)"},
                    "params": {"type": "object"},
                    "select": {"type": "object", "additionalProperties": {"type": "array", "items": {"type": "string"}}, "description": "only input records whose partition keys take these values"},
                    "keep": {"type": "boolean", "default": true, "description": "false: an intermediate; its files go once the stages reading it are up to date and are made again when one reruns"}
                },
                "allOf": conditionals
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::spec::SourceSpec;

    #[test]
    fn source_properties_match_the_parser() {
        // `component_as`, `units_row`, `description_row`, `calibration`, `on_error` and `components`
        // are left out of the serialised spec when absent (source hashes stay as they were): give
        // them, so every key shows.
        let spec: SourceSpec = serde_json::from_value(json!({"format": "at2", "path": "x", "component_as": "ax", "units_row": 3, "description_row": 2, "calibration": "c.csv", "on_error": "skip", "components": {"key": "component"}})).unwrap();
        let parsed: Vec<String> = serde_json::to_value(spec).unwrap().as_object().unwrap().keys().cloned().collect();
        let schema = pipeline_schema();
        let documented: Vec<String> =
            schema["definitions"]["source"]["properties"].as_object().unwrap().keys().cloned().collect();
        let mut a = parsed.clone();
        let mut b = documented.clone();
        a.sort();
        b.sort();
        assert_eq!(a, b);
    }

    #[test]
    fn committed_schema_is_current() {
        let committed = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/schemas/pipeline.schema.json"))
            .expect("schemas/pipeline.schema.json exists");
        let generated = serde_json::to_string_pretty(&pipeline_schema()).unwrap() + "\n";
        assert!(
            committed == generated,
            "schemas/pipeline.schema.json is stale: run `shakeflow schema > schemas/pipeline.schema.json`"
        );
    }
}
