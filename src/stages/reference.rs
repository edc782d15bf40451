//! docs/stages.md, written from the stage declarations (each stage's [`StageInfo`] and its
//! parameter struct's doc comments, defaults, units and ranges): `shakeflow stages --markdown`
//! prints it, `make docs` rewrites the file, and `committed_stage_docs_are_current` fails while
//! the checked-in file differs from what the declarations say.

use std::fmt::Write as _;

use super::{registry, stage_types, InputKind, OutputInfo, OutputKind, StageInfo, MCAP_PARAM};

/// What a stage type reads, as `shakeflow stages` and docs/stages.md say it.
pub fn reads(info: &StageInfo) -> String {
    match info.inputs {
        InputKind::Sources => "record sources declared under `inputs:`".to_string(),
        InputKind::Datasets => "outputs of other stages".to_string(),
        InputKind::Files(formats) => format!(
            "`{}` sources declared under `inputs:`",
            formats.iter().map(|f| f.name()).collect::<Vec<_>>().join("` or `")
        ),
    }
}

/// How a stage's output is written, as `shakeflow stages` and docs/stages.md say it: a time
/// series has MCAP twins only in a stage with the `mcap` parameter, which asks for them.
pub fn written_as(info: &StageInfo, output: &OutputInfo) -> &'static str {
    let twins = info.params.iter().any(|p| p.name == MCAP_PARAM.name);
    match output.kind {
        OutputKind::TimeSeries if !twins => OutputKind::Table.describe(),
        kind => kind.describe(),
    }
}

/// A table cell: `|` escaped, so a choice's `a|b` stays in its cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// docs/stages.md: an overview table, then per stage type what it reads, its outputs and its
/// parameters.
pub fn markdown() -> String {
    let mut out = String::new();
    // Writing into a String cannot fail.
    let _ = write_markdown(&mut out);
    out
}

fn write_markdown(out: &mut String) -> std::fmt::Result {
    writeln!(out, "# Stages\n")?;
    writeln!(
        out,
        "<!-- Written by `shakeflow stages --markdown` (`make docs`) from the stage declarations in src/stages/: edit those, not this file. -->\n"
    )?;
    writeln!(
        out,
        "Every stage type: what it does, what it reads, its outputs (their contract columns are what scripts read) and its \
         parameters with kinds, defaults, units and ranges. `shakeflow stages [NAME]` prints the same; \
         `schemas/pipeline.schema.json` has the parameters for editors. The models behind the simulations: \
         [docs/models/toppling.md](models/toppling.md), [docs/models/rolling.md](models/rolling.md); the study report: \
         [docs/report.md](report.md).\n"
    )?;
    writeln!(out, "| stage | what it does | outputs |\n|---|---|---|")?;
    for stage in registry().0 {
        let info = stage.info();
        let outputs: Vec<String> = info.outputs.iter().map(|o| format!("`{}`", o.name)).collect();
        writeln!(out, "| [`{0}`](#{0}) | {1} | {2} |", info.name, cell(info.summary), outputs.join(", "))?;
    }
    for stage in stage_types() {
        let info = stage.info();
        writeln!(out, "\n## {}\n\n{}\n\nReads {}. Version {}.\n", info.name, info.summary, reads(info), info.version)?;
        writeln!(out, "| output | written as | what it holds |\n|---|---|---|")?;
        for o in info.outputs {
            writeln!(out, "| `{}` | {} | {} |", o.name, cell(written_as(info, o)), cell(o.description))?;
        }
        for example in stage.examples() {
            writeln!(
                out,
                "\nExample, run as a test on {}: {}.\n\n```yaml\n{}```",
                example.data.what,
                example.title,
                example.pipeline()
            )?;
        }
        if info.params.is_empty() {
            writeln!(out, "\nNo parameters: a `load` is configured by its source (docs/formats.md).")?;
            continue;
        }
        writeln!(out, "\n| parameter | kind | default | unit | range | what it sets |\n|---|---|---|---|---|---|")?;
        for p in info.params {
            let default = p.default.map_or("required".to_string(), |d| format!("`{d}`"));
            let range = p.range.map_or(String::new(), |(lo, hi)| format!("{lo} to {hi}"));
            writeln!(
                out,
                "| `{}` | {} | {} | {} | {range} | {} |",
                p.name,
                cell(&p.kind.describe()),
                cell(&default),
                p.unit,
                cell(p.description)
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/stages.md is what the declarations say: a stage added, renamed or redescribed fails
    /// here until `make docs` rewrites the file; README names every stage type.
    #[test]
    fn committed_stage_docs_are_current() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let committed = std::fs::read_to_string(root.join("docs/stages.md")).expect("docs/stages.md exists");
        assert!(committed == markdown(), "docs/stages.md is stale: run `make docs` (shakeflow stages --markdown)");
        let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
        for name in registry().names() {
            assert!(readme.contains(&format!("`{name}`")), "README.md does not name the stage `{name}`");
        }
    }

    #[test]
    fn a_choice_stays_in_its_cell() {
        assert_eq!(cell("adaptive|rk4"), "adaptive\\|rk4");
        let text = markdown();
        assert!(text.contains("| `method` | adaptive\\|rk4 | `\"adaptive\"` |"), "{text}");
        assert!(text.contains("| `order` | integer | `3` |  | 0 to"), "{text}");
    }

    #[test]
    fn a_time_series_has_mcap_twins_only_in_a_stage_with_the_mcap_parameter() {
        const SERIES: OutputInfo = OutputInfo { name: "series", description: "", kind: OutputKind::TimeSeries };
        const TABLE: OutputInfo = OutputInfo { name: "table", description: "", kind: OutputKind::Table };
        let info = |params: &'static [crate::pipeline::params::ParamSpec]| StageInfo {
            name: "toy",
            version: 1,
            summary: "",
            inputs: InputKind::Datasets,
            outputs: &[SERIES, TABLE],
            params,
        };
        let without = info(&[]);
        assert_eq!(written_as(&without, &SERIES), "Parquet");
        assert_eq!(written_as(&without, &TABLE), "Parquet");
        let with = info(&[MCAP_PARAM]);
        assert_eq!(written_as(&with, &SERIES), "Parquet (+ MCAP with `mcap: true`)");
        assert_eq!(written_as(&with, &TABLE), "Parquet");
        // Every stage with a time series has the parameter, so the docs name the twins.
        assert!(markdown().contains("| `records` | Parquet (+ MCAP with `mcap: true`) |"));
    }
}
