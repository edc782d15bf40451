//! Work units: a stage split into what is cached, run, committed and reported on its own — one
//! record of a per-record stage, or the whole of a gathering stage (see [`WorkUnits`]).

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde_json::json;

use super::plan::PlannedStage;
use super::stage::{partition_path, InputPart, StageInput, WorkUnits};
use crate::io::hash;

/// The id of a gathering stage's one unit.
pub const GATHER: &str = "*";

pub struct Unit {
    /// The record's partition (`motion=FB-4/floor=5`; empty for a record without keys), or [`GATHER`].
    pub id: String,
    /// The stage's inputs, each holding only the parts this unit reads.
    pub inputs: Vec<StageInput>,
    /// What the unit reads → content hash: its parts (by label), the way each source is read,
    /// and the files its parameters name.
    pub hashes: BTreeMap<String, String>,
}

impl Unit {
    /// blake3 of type, version, params, select and input hashes: equal key, equal result.
    /// `prefix` is the stage's [`key_prefix`], encoded once for all its units.
    pub fn key(&self, prefix: &str) -> String {
        let mut material = String::with_capacity(prefix.len() + 64 * self.hashes.len());
        material.push_str(prefix);
        material.push_str(&serde_json::to_string(&self.hashes).expect("hashes are JSON"));
        material.push('}');
        hash::hash_bytes(material.as_bytes())
    }

    /// The source a per-record unit's record comes from, when it is a raw record file.
    pub fn source(&self) -> Option<(&str, &crate::pipeline::spec::SourceSpec, &InputPart)> {
        self.inputs.iter().find_map(|input| match input {
            // A record of several files (`components:`) is named by its first.
            StageInput::Source { name, spec, files, .. }
                if files.len() == 1 || spec.components.is_some() && !files.is_empty() =>
            {
                Some((name.as_str(), spec.as_ref(), &files[0]))
            }
            _ => None,
        })
    }
}

/// The JSON a unit's key hashes, up to its input hashes (which come last): `{"type":…,
/// "version":…,"params":…,"select":…,"inputs":`. The same for every unit of a stage.
pub fn key_prefix(stage: &PlannedStage) -> String {
    let info = stage.stage.info();
    let material = json!({"type": info.name, "version": info.version, "params": stage.params,
        "select": stage.select, "inputs": null});
    material.to_string().strip_suffix("null}").expect("`inputs` is the last key (preserve_order)").to_string()
}

/// How messages name a unit: `record motion=FB-4/floor=5`, or the whole stage.
pub fn describe(id: &str) -> String {
    match id {
        "" => "(the record)".to_string(),
        GATHER => "(all inputs)".to_string(),
        id => format!("record {id}"),
    }
}

/// Splits a stage over its (selected) inputs into units, in a deterministic order.
pub fn split(
    stage: &PlannedStage,
    inputs: &[StageInput],
    param_files: &BTreeMap<String, String>,
) -> anyhow::Result<Vec<Unit>> {
    // How each source's files are read (`on_error` changes what a failure does, not what is
    // read): encoded once per source, not once per unit.
    let how: BTreeMap<String, String> = inputs
        .iter()
        .filter_map(|input| match input {
            StageInput::Source { name, spec, .. } => {
                let spec = crate::pipeline::spec::SourceSpec { on_error: Default::default(), ..spec.as_ref().clone() };
                let how = serde_json::to_string(&spec).expect("specs serialise");
                Some((format!("source {name}"), hash::hash_bytes(how.as_bytes())))
            }
            StageInput::Dataset { .. } => None,
        })
        .collect();
    let unit = |id: String, inputs: Vec<StageInput>| {
        let mut hashes: BTreeMap<String, String> = param_files.clone();
        for input in &inputs {
            if let StageInput::Source { name, .. } = input {
                let label = format!("source {name}");
                let hash = how[&label].clone();
                hashes.insert(label, hash);
            }
            for part in input.parts() {
                hashes.insert(part.label.clone(), part.hash.clone());
            }
        }
        Unit { id, inputs, hashes }
    };
    // Units are built in parallel: a no-op rerun builds every unit of every stage.
    let mut units: Vec<Unit> = match stage.stage.work_units() {
        WorkUnits::Gather => vec![unit(GATHER.to_string(), inputs.to_vec())],
        WorkUnits::EachRecord => {
            let records: Vec<(&StageInput, Vec<InputPart>)> = inputs
                .iter()
                .flat_map(|input| record_files(input).into_iter().map(move |parts| (input, parts)))
                .collect();
            records
                .into_par_iter()
                .map(|(input, parts)| unit(partition_path(&parts[0].partition), vec![only(input, parts)]))
                .collect()
        }
        WorkUnits::PerRecordOf { primary } => {
            let Some(main) = inputs.get(primary) else {
                anyhow::bail!(
                    "stage `{}` reads its records from input number {} but has {} input(s)",
                    stage.name,
                    primary + 1,
                    inputs.len()
                );
            };
            // Each secondary input's companions of every primary record, asked once per input,
            // then handed to the records they belong to (moved, not copied).
            let mut companions: Vec<Option<std::vec::IntoIter<Vec<InputPart>>>> = inputs
                .iter()
                .enumerate()
                .map(|(i, input)| {
                    (i != primary).then(|| stage.stage.companions(&stage.params, main.parts(), input).into_iter())
                })
                .collect();
            let records: Vec<(&InputPart, Vec<Vec<InputPart>>)> = main
                .parts()
                .iter()
                .map(|part| {
                    let chosen = companions
                        .iter_mut()
                        .map(|c| match c {
                            Some(c) => c.next().expect("one list of companions per primary record"),
                            None => vec![part.clone()],
                        })
                        .collect();
                    (part, chosen)
                })
                .collect();
            records
                .into_par_iter()
                .map(|(part, chosen)| {
                    let parts = inputs.iter().zip(chosen).map(|(input, chosen)| only(input, chosen)).collect();
                    unit(partition_path(&part.partition), parts)
                })
                .collect()
        }
    };
    units.sort_by(|a, b| a.id.cmp(&b.id));
    if let Some(pair) = units.windows(2).find(|w| w[0].id == w[1].id) {
        anyhow::bail!(
            "stage `{}` has two records with the partition `{}`: two inputs share these partition keys; give the sources distinct `partition:` values",
            stage.name,
            describe(&pair[0].id)
        );
    }
    Ok(units)
}

/// The files of each record of `input`: one each, but a `components:` source's files that
/// share a partition (a station's `.EW`, `.NS`, `.UD`) are one record.
fn record_files(input: &StageInput) -> Vec<Vec<InputPart>> {
    let grouped = matches!(input, StageInput::Source { spec, .. } if spec.components.is_some());
    if !grouped {
        return input.parts().iter().map(|part| vec![part.clone()]).collect();
    }
    let mut records: BTreeMap<String, Vec<InputPart>> = BTreeMap::new();
    for part in input.parts() {
        records.entry(partition_path(&part.partition)).or_default().push(part.clone());
    }
    records.into_values().collect()
}

/// `input` holding only `parts`.
fn only(input: &StageInput, parts: Vec<InputPart>) -> StageInput {
    match input {
        StageInput::Source { name, spec, base_dir, .. } => {
            StageInput::Source { name: name.clone(), spec: spec.clone(), base_dir: base_dir.clone(), files: parts }
        }
        StageInput::Dataset { name, .. } => StageInput::Dataset { name: name.clone(), parts },
    }
}
