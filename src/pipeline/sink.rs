//! Where a running stage puts its tables: Parquet (+ MCAP for time series) in a staging
//! directory, each file stamped with the provenance of the run that made it.

use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{anyhow, bail, Context};

use super::info::{OutputInfo, OutputKind, StageInfo};
use super::layout::{fan_folder, partition_path, Partition, DATA_FILE, LOCK_FILE, MCAP_DIR, MCAP_FILE, STAGE_MARKER};
use crate::io::hash::{self, KnownHashes};
use crate::io::{mcap, parquet};
use crate::pipeline::memo::TableMemo;
use crate::table::Table;

/// Table metadata by which a stage flags a record it wrote whole but that its user should know
/// about (`load`: channels of unequal lengths, null-padded): a JSON array of objects with
/// `reason`, `file` and `line` (null where there is none). The engine lists them in the
/// stage's `status` table.
pub const FLAGS_KEY: &str = "shakeflow.flags";

/// The flags of [`FLAGS_KEY`] as lines: `reason (file:line)`; text that is not such an array
/// stays as it is.
fn describe_flags(text: &str) -> Vec<String> {
    let Ok(serde_json::Value::Array(flags)) = serde_json::from_str(text) else { return vec![text.to_string()] };
    flags
        .iter()
        .map(|flag| {
            let reason = flag["reason"].as_str().unwrap_or_default();
            match (flag["file"].as_str(), flag["line"].as_u64()) {
                (Some(file), Some(line)) => format!("{reason} ({file}:{line})"),
                (Some(file), None) => format!("{reason} ({file})"),
                _ => reason.to_string(),
            }
        })
        .collect()
}

pub struct OutputSink {
    root: PathBuf,
    stage_name: String,
    info: &'static StageInfo,
    provenance: BTreeMap<String, String>,
    written: Mutex<BTreeSet<String>>,
    progress: indicatif::ProgressBar,
    /// Whether time-series outputs also get MCAP twins (the `mcap` parameter, off by default).
    mcap: bool,
    /// Hashes of the files written so far, taken from their bytes on the way out.
    hashes: Mutex<KnownHashes>,
    /// Where tables stay in memory for the stages that read them next, and how many stages
    /// those are (none: nobody reads them this run).
    memo: Option<(Arc<TableMemo>, usize)>,
    /// Whether the memo may keep the stage's Parquet files unwritten (an intermediate's).
    unwritten: bool,
    /// What the tables written so far flag ([`FLAGS_KEY`]), as `reason (file:line)`.
    flags: Mutex<Vec<String>>,
    /// Whether records go in two-level folders (`layout::placed`): the stage has more records
    /// than a folder should hold.
    fanned: bool,
}

impl OutputSink {
    /// `inputs` maps each input name to its content hash.
    pub fn new(
        root: &Path,
        stage_name: &str,
        info: &'static StageInfo,
        params: &crate::pipeline::params::Params,
        inputs: &BTreeMap<String, String>,
        progress: indicatif::ProgressBar,
    ) -> Self {
        let provenance = BTreeMap::from([
            ("shakeflow.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
            ("shakeflow.stage".to_string(), stage_name.to_string()),
            ("shakeflow.stage_type".to_string(), info.name.to_string()),
            ("shakeflow.stage_version".to_string(), info.version.to_string()),
            ("shakeflow.params".to_string(), serde_json::to_string(params).expect("params are JSON")),
            ("shakeflow.inputs".to_string(), serde_json::to_string(inputs).expect("hashes are JSON")),
        ]);
        OutputSink {
            root: root.to_path_buf(),
            stage_name: stage_name.into(),
            info,
            provenance,
            written: Mutex::new(BTreeSet::new()),
            progress,
            mcap: params.get("mcap").and_then(|v| v.as_bool()).unwrap_or(false),
            hashes: Mutex::new(KnownHashes::new()),
            memo: None,
            unwritten: false,
            flags: Mutex::new(Vec::new()),
            fanned: false,
        }
    }

    /// Puts each record's files one folder down (`records/3f/motion=FB-4/…`, `layout::placed`).
    pub fn fanned_out(mut self, fanned: bool) -> Self {
        self.fanned = fanned;
        self
    }

    /// Keeps every table written in `memo` too, for the `readers` stages that read them next;
    /// `unwritten`: the stage is an intermediate, whose Parquet files the memo may keep
    /// unwritten (`TableMemo::keep_unwritten`).
    pub fn keeping_tables_in(mut self, memo: Arc<TableMemo>, readers: usize, unwritten: bool) -> Self {
        self.memo = Some((memo, readers));
        self.unwritten = unwritten;
        self
    }

    fn output_info(&self, output: &str) -> anyhow::Result<&'static OutputInfo> {
        self.info
            .outputs
            .iter()
            .find(|o| o.name == output)
            .ok_or_else(|| anyhow!("stage type `{}` has no output `{output}`", self.info.name))
    }

    /// Writes one record of one output. Records are independent, so stages call this in parallel.
    pub fn write(&self, output: &str, partition: &Partition, table: Table) -> anyhow::Result<()> {
        self.write_split(output, partition, table, None)
    }

    /// Like [`write`](Self::write) for a long table holding several series (a `point` column):
    /// the MCAP twin gets one topic per value of `key`, so each series plots on its own.
    pub fn write_series(&self, output: &str, partition: &Partition, table: Table, key: &str) -> anyhow::Result<()> {
        self.write_split(output, partition, table, Some(key))
    }

    fn write_split(
        &self,
        output: &str,
        partition: &Partition,
        mut table: Table,
        key: Option<&str>,
    ) -> anyhow::Result<()> {
        let info = self.output_info(output)?;
        if matches!(info.kind, OutputKind::Files | OutputKind::Page) {
            bail!("stage type `{}` declares `{output}` as an output of files, not of tables", self.info.name);
        }
        let relative = partition_path(partition);
        if !self.written.lock().expect("no panics while holding the lock").insert(format!("{output}/{relative}")) {
            bail!("stage `{}` wrote the record `{relative}` of `{output}` twice: two inputs share these partition keys; give the sources distinct `partition:` values", self.stage_name);
        }
        // The folder of the record's files: one level down in a fanned-out stage.
        let folder = match self.fanned && !relative.is_empty() {
            true => format!("{}/{relative}", fan_folder(&relative)),
            false => relative.clone(),
        };
        let dir = self.root.join(output).join(&folder);
        table.metadata.extend(self.provenance.clone());
        table.metadata.insert("shakeflow.output".into(), output.into());
        table.metadata.insert("shakeflow.partition".into(), relative.clone());
        if let Some(flags) = table.metadata.get(FLAGS_KEY) {
            self.flags.lock().expect("no panics while holding the lock").extend(describe_flags(flags));
        }
        let path = dir.join(DATA_FILE);
        let mcap = info.kind == OutputKind::TimeSeries && self.mcap;
        let create_dir =
            || std::fs::create_dir_all(&dir).map_err(|e| anyhow!("cannot create `{}`: {e}", dir.display()));
        let hash = match self.memo.as_ref().filter(|_| self.unwritten && !mcap) {
            // An intermediate's file: kept unwritten if the memo can hold it, else written.
            Some((memo, readers)) => {
                let (encoded, hash) = parquet::encode_table(&table).with_context(|| format!("`{}`", path.display()))?;
                let Some((kept, encoded)) = memo.keep_unwritten(&path, table, encoded, *readers) else {
                    self.hashes.lock().expect("no panics while holding the lock").insert(path, hash);
                    self.progress.inc(1);
                    return Ok(());
                };
                table = kept;
                create_dir()?;
                crate::io::atomic::write_bytes(&path, &encoded)?;
                hash
            }
            None => {
                create_dir()?;
                parquet::write_table(&path, &table)?
            }
        };
        self.hashes.lock().expect("no panics while holding the lock").insert(path.clone(), hash);
        if mcap {
            let topic = if relative.is_empty() {
                format!("/{}/{output}", self.stage_name)
            } else {
                format!("/{}/{output}/{relative}", self.stage_name)
            };
            // A separate tree: pyarrow.dataset and friends refuse folders that mix in non-Parquet files.
            let mcap_dir = self.root.join(MCAP_DIR).join(output).join(&folder);
            std::fs::create_dir_all(&mcap_dir).map_err(|e| anyhow!("cannot create `{}`: {e}", mcap_dir.display()))?;
            let split: Vec<(String, Cow<'_, Table>)> = match key {
                None => vec![(topic, Cow::Borrowed(&table))],
                Some(key) => split_by(&table, key)?
                    .into_iter()
                    .map(|(value, part)| (format!("{topic}/{value}"), Cow::Owned(part)))
                    .collect(),
            };
            let topics: Vec<mcap::Topic<'_>> =
                split.iter().map(|(name, part)| mcap::Topic { name: name.clone(), table: part }).collect();
            let mcap_path = mcap_dir.join(MCAP_FILE);
            let mcap_hash = mcap::write_timeseries(&mcap_path, &topics, &table.metadata)?;
            self.hashes.lock().expect("no panics while holding the lock").insert(mcap_path, mcap_hash);
        }
        if let Some((memo, readers)) = &self.memo {
            memo.keep(&path, table, *readers);
        }
        self.progress.inc(1);
        Ok(())
    }

    /// Writes a non-table file (a figure) under an output: `<stage>/<output>/<name>`.
    pub fn write_file(&self, output: &str, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
        if self.output_info(output)?.kind != OutputKind::Files {
            bail!("stage type `{}` declares `{output}` as an output of tables, not of files", self.info.name);
        }
        let dir = self.root.join(output);
        std::fs::create_dir_all(&dir).map_err(|e| anyhow!("cannot create `{}`: {e}", dir.display()))?;
        let path = dir.join(name);
        self.write_hashed(path, bytes)
    }

    /// Writes a page output: the one file `<stage>/<output>` (an `index.html`).
    pub fn write_page(&self, output: &str, bytes: &[u8]) -> anyhow::Result<()> {
        if self.output_info(output)?.kind != OutputKind::Page {
            bail!("stage type `{}` does not declare `{output}` as a page", self.info.name);
        }
        std::fs::create_dir_all(&self.root).map_err(|e| anyhow!("cannot create `{}`: {e}", self.root.display()))?;
        let path = self.root.join(output);
        self.write_hashed(path, bytes)
    }

    /// Writes `bytes` to `path` (temp file and rename) and records its hash.
    fn write_hashed(&self, path: PathBuf, bytes: &[u8]) -> anyhow::Result<()> {
        crate::io::atomic::write_bytes(&path, bytes)?;
        self.hashes.lock().expect("no panics while holding the lock").insert(path, hash::hash_bytes(bytes));
        Ok(())
    }

    /// Writes a page output of one record: `<stage>/<record>/<output>` (the `diagnosis.json`
    /// of each case of a `diagnose` over several). `record` is one plain folder name.
    pub fn write_record_page(&self, output: &str, record: &str, bytes: &[u8]) -> anyhow::Result<()> {
        if self.output_info(output)?.kind != OutputKind::Page {
            bail!("stage type `{}` does not declare `{output}` as a page", self.info.name);
        }
        let reserved =
            self.info.outputs.iter().any(|o| o.name == record) || [MCAP_DIR, STAGE_MARKER, LOCK_FILE].contains(&record);
        let problem = super::paths::component_problem(record)
            .or_else(|| reserved.then(|| "the stage folder holds an entry of that name".to_string()));
        if let Some(problem) = problem {
            bail!("the record `{record}` cannot name a folder of stage `{}`: {problem}", self.stage_name);
        }
        let dir = self.root.join(record);
        std::fs::create_dir_all(&dir).map_err(|e| anyhow!("cannot create `{}`: {e}", dir.display()))?;
        let path = dir.join(output);
        self.write_hashed(path, bytes)
    }

    /// The hashes of the files written.
    /// What the tables written flag, each as `reason (file:line)`, in the order written.
    pub fn flags(&self) -> Vec<String> {
        self.flags.lock().expect("no panics while holding the lock").clone()
    }

    pub fn into_hashes(self) -> KnownHashes {
        self.hashes.into_inner().expect("no panics while holding the lock")
    }

    /// One unit of work done that writes no file of its own (e.g. one run of a sweep).
    pub fn tick(&self) {
        self.progress.inc(1);
    }

    pub fn set_total(&self, records: usize) {
        self.progress.set_length(records as u64);
    }

    /// Tells the user about something that does not stop the stage (a low-contrast template).
    /// Stages also record warnings in the artifact's metadata, where they stay.
    pub fn warn(&self, message: &str) {
        let line = format!("warning: {}: {message}", self.stage_name);
        if self.progress.is_hidden() {
            eprintln!("{line}");
        } else {
            self.progress.println(line);
        }
    }
}

/// Rows of `table` grouped by the text column `key`, in order of first appearance.
fn split_by(table: &Table, key: &str) -> anyhow::Result<Vec<(String, Table)>> {
    let Some(crate::table::ColumnData::Str(keys)) = table.column(key).map(|c| &c.data) else {
        bail!("the table has no text column `{key}` to split its MCAP topics by");
    };
    let mut groups: Vec<(String, Vec<usize>)> = Vec::new();
    for (row, k) in keys.iter().enumerate() {
        match groups.iter_mut().find(|(g, _)| g == k) {
            Some((_, rows)) => rows.push(row),
            None => groups.push((k.clone(), vec![row])),
        }
    }
    Ok(groups.into_iter().map(|(k, rows)| (k, table.select_rows(&rows))).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::info::{InputKind, OutputInfo};
    use crate::pipeline::memo::TableMemo;
    use crate::pipeline::stage::{InputPart, StageContext};
    use crate::table::Column;

    static INFO: StageInfo = StageInfo {
        name: "t",
        version: 1,
        summary: "",
        inputs: InputKind::Datasets,
        outputs: &[OutputInfo { name: "records", description: "", kind: OutputKind::TimeSeries }],
        params: &[],
    };

    fn sink(root: &Path) -> OutputSink {
        let params = Default::default();
        OutputSink::new(root, "s", &INFO, &params, &BTreeMap::new(), indicatif::ProgressBar::hidden())
    }

    #[test]
    fn an_intermediate_kept_unwritten_has_its_files_hash_and_reads_as_its_table() {
        let dir = crate::tempdir::tempdir().unwrap();
        let mut table = Table::new();
        table.push(Column::f64("time_s", "s", "time", vec![0.0, 0.005, 0.01]));
        let partition: Partition = vec![("motion".to_string(), "FB-1".to_string())];
        let written = sink(&dir.path().join("written"));
        written.write("records", &partition, table.clone()).unwrap();
        let memo = Arc::new(TableMemo::new(1 << 20));
        let unwritten = sink(&dir.path().join("unwritten")).keeping_tables_in(memo.clone(), 1, true);
        unwritten.write("records", &partition, table).unwrap();
        let path = |side: &str| dir.path().join(side).join("records/motion=FB-1").join(DATA_FILE);
        assert!(!dir.path().join("unwritten").exists(), "no file, no folder");
        let file = std::fs::read(path("written")).unwrap();
        assert_eq!(memo.unwritten(&path("unwritten")).unwrap(), file, "the file's bytes");
        let hash = |sink: OutputSink, side: &str| sink.into_hashes().get(&path(side)).cloned();
        assert_eq!(hash(written, "written"), Some(hash::hash_bytes(&file)));
        assert_eq!(hash(unwritten, "unwritten"), Some(hash::hash_bytes(&file)));
        // Read twice by one stage: the kept table, then the bytes, each the file's table.
        let reader = sink(&dir.path().join("reader"));
        let params = Default::default();
        let ctx = StageContext {
            stage_name: "r",
            params: &params,
            inputs: &[],
            sink: &reader,
            base_dir: dir.path(),
            memo: Some(&memo),
        };
        let part = InputPart {
            partition: partition.clone(),
            path: path("unwritten"),
            label: String::new(),
            hash: String::new(),
        };
        let from_file = parquet::read_table(&path("written")).unwrap();
        assert_eq!(*ctx.read_table(&part).unwrap(), from_file);
        assert!(memo.take(&part.path).is_none(), "taken by its one reader");
        assert_eq!(*ctx.read_table(&part).unwrap(), from_file);
        // Past the memo's budgets the file is written after all, the same bytes.
        let full = sink(&dir.path().join("full")).keeping_tables_in(Arc::new(TableMemo::new(0)), 1, true);
        full.write("records", &partition, from_file).unwrap();
        assert_eq!(std::fs::read(path("full")).unwrap(), file);
        assert_eq!(hash(full, "full"), Some(hash::hash_bytes(&file)));
    }
}
