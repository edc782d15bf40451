//! Readers for accelerogram file formats: PEER NGA `.AT2`, RENADIC Vol.1,
//! SimCenter event JSON and delimited text (CSV/TSV/whitespace).
//!
//! Readers return the numbers exactly as the file states them (units
//! included) in a [`RawRecord`]; unit conversion and gap handling are left to
//! the caller. Every failure is a [`ParseError`] that names the file, the
//! line and column where that makes sense, and a hint on the likely cause.

mod at2;
mod calibration;
mod cosmos;
mod delimited;
mod dmg;
mod esm;
mod fixed;
#[cfg(test)]
mod formats_tests;
mod geonet;
mod knet;
mod lvm;
mod renadic;
pub mod roles;
mod simcenter;
mod smc;
#[cfg(test)]
mod tests;

pub use at2::{parse_at2, read_at2};
pub use calibration::{parse_calibration, read_calibration, Calibration};
pub use cosmos::{parse_cosmos, read_cosmos};
pub use delimited::{parse_delimited, read_delimited, DelimitedOptions};
pub use dmg::{parse_dmg, read_dmg};
pub use esm::{parse_esm, read_esm};
pub use geonet::{parse_geonet, read_geonet};
pub use knet::{parse_knet, read_knet};
pub use lvm::{parse_lvm, read_lvm};
pub use renadic::{parse_renadic_v1, read_renadic_v1};
pub use simcenter::{parse_simcenter_json, read_simcenter_json};
pub use smc::{parse_smc, read_smc};

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

/// One file's content, before any unit conversion or gap handling.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRecord {
    /// "at2" | "renadic_v1" | "simcenter_json" | "delimited"
    pub format: &'static str,
    /// Time step in seconds, when the file states it (or, for RENADIC, when
    /// its time column is uniform).
    pub dt: Option<f64>,
    /// Explicit time column, when the format has one apart from the channels
    /// (RENADIC). Delimited files keep any time column among the channels.
    pub time: Option<Vec<f64>>,
    pub channels: Vec<RawChannel>,
    /// Facts from the header: npts, dt, event, station, component, units
    /// text, filter poles, ...
    pub header: BTreeMap<String, String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RawChannel {
    pub name: String,
    /// As stated by the file, lower-cased: "g", "g/10", or "" when unknown.
    pub unit: String,
    pub values: Vec<f64>,
    /// 1-based line of the first value, for formats where that is meaningful.
    pub first_data_line: Option<usize>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    pub path: PathBuf,
    /// 1-based.
    pub line: Option<usize>,
    /// 1-based character column.
    pub column: Option<usize>,
    pub message: String,
    pub hint: String,
}

impl ParseError {
    fn new(
        path: &Path,
        line: Option<usize>,
        column: Option<usize>,
        message: impl Into<String>,
        hint: impl Into<String>,
    ) -> Self {
        // Messages quote the file (cells, lines, names): its control characters are escaped.
        let (message, hint) = (message.into(), hint.into());
        let (message, hint) = (printable(&message).into_owned(), printable(&hint).into_owned());
        ParseError { path: path.to_path_buf(), line, column, message, hint }
    }
}

/// `text` with the characters a terminal would act on instead of showing escaped: control
/// characters (`\r`, ESC, NUL, ...) and the invisible direction and zero-width marks, so a
/// message quoting a file can neither rewrite the terminal nor disguise what it quotes.
pub fn printable(text: &str) -> Cow<'_, str> {
    let hidden = |c: char| {
        c.is_control()
            || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2060}'..='\u{2069}' | '\u{feff}')
    };
    if !text.contains(hidden) {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        match c {
            '\t' => out.push_str("\\t"),
            '\r' => out.push_str("\\r"),
            '\n' => out.push_str("\\n"),
            c if hidden(c) => out.push_str(&format!("\\u{{{:x}}}", u32::from(c))),
            c => out.push(c),
        }
    }
    Cow::Owned(out)
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(col) = self.column {
                write!(f, ":{col}")?;
            }
        }
        write!(f, ": {}", self.message)?;
        if !self.hint.is_empty() {
            write!(f, "\n  hint: {}", self.hint)?;
        }
        Ok(())
    }
}

impl std::error::Error for ParseError {}

/// Guess the format from the first bytes, then from the extension: content
/// wins because records are often renamed (an AT2 saved as `.txt`).
pub fn sniff_format(path: &Path) -> Option<&'static str> {
    let mut head = Vec::new();
    if let Ok(file) = std::fs::File::open(path) {
        let _ = file.take(SNIFF_BYTES as u64).read_to_end(&mut head);
    }
    sniff_bytes(path, &head)
}

/// How much of a file [`sniff_bytes`] looks at: 4 KB covers every format's telling first lines.
const SNIFF_BYTES: usize = 4096;

/// [`sniff_format`] of a file's bytes (its first [`SNIFF_BYTES`] are read): content first,
/// then the extension of `path`.
pub fn sniff_bytes(path: &Path, bytes: &[u8]) -> Option<&'static str> {
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(SNIFF_BYTES)]);
    if let Some(format) = sniff_content(&head) {
        return Some(format);
    }
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    match ext.as_str() {
        "at2" => Some("at2"),
        "v1" => Some("renadic_v1"),
        "json" => Some("simcenter_json"),
        // NEES sensor data: `.asc` (ESM's `.asc` is recognised by its content above).
        "csv" | "tsv" | "tab" | "txt" | "asc" => Some("delimited"),
        "v0c" | "v1c" | "v2c" => Some("cosmos"),
        "smc" => Some("smc"),
        "lvm" => Some("lvm"),
        "raw" => Some("dmg"),
        "v1a" | "v2a" => Some("geonet"),
        "ew" | "ns" | "ud" | "ew1" | "ns1" | "ud1" | "ew2" | "ns2" | "ud2" => Some("knet"),
        _ => None,
    }
}

/// The format the first bytes of a file (4 KB) show, when they show one.
fn sniff_content(head: &str) -> Option<&'static str> {
    let head = head.strip_prefix('\u{feff}').unwrap_or(head);
    let first: Vec<&str> = head.lines().take(4).collect();
    let upper = |i: usize| first.get(i).map(|l| l.to_ascii_uppercase()).unwrap_or_default();
    if let Some(format) = sniff_strong_motion(head, &upper(0), &upper(1)) {
        return Some(format);
    }
    if upper(0).starts_with("UNCORRECTED ACCELEROGRAM") {
        return Some("renadic_v1");
    }
    if upper(0).contains("PEER") || (upper(2).contains("UNITS OF") && upper(3).contains("NPTS")) {
        return Some("at2");
    }
    if upper(0).starts_with("LABVIEW MEASUREMENT") {
        return Some("lvm");
    }
    if head.trim_start().starts_with('{') {
        return Some("simcenter_json");
    }
    None
}

/// How much of each record file past a source's first `validate` reads.
const HEADER_BYTES: u64 = 16 * 1024;

/// `validate`'s quick look at a record file (the first is loaded whole): its first 16 KB are
/// text and, by their content, not another format than the source declares (`format`, as
/// pipelines name it); a delimited file's header rows and first data rows parse with `delimited`,
/// and its channel names are returned. A format that states its sample count (AT2, COSMOS,
/// CSMIP/DMG, SMC, K-NET, ESM, GeoNet) is read whole with its data values counted, not parsed: a
/// truncated record is refused at its last line. Not a full parse: a damaged value is found by
/// `load`.
pub fn check_header(
    path: &Path,
    format: &str,
    delimited: Option<&DelimitedOptions>,
) -> Result<Option<Vec<String>>, ParseError> {
    let mut head = Vec::new();
    std::fs::File::open(path).and_then(|file| file.take(HEADER_BYTES).read_to_end(&mut head)).map_err(|e| {
        ParseError::new(path, None, None, format!("cannot read the file: {e}"), "check the path and its permissions")
    })?;
    let text = record_text(path, &head, "a record")?;
    let format = match format {
        "auto" => sniff_bytes(path, &head).ok_or_else(|| unknown_format(path))?,
        named => named,
    };
    if let Some(found) = sniff_content(&text).filter(|found| *found != format) {
        if !(delimited.is_some() && found == "delimited") {
            return Err(ParseError::new(
                path,
                Some(1),
                None,
                format!("the file starts like a `{found}` record, but the source reads `{format}`"),
                "a file of another format among the source's files: move it, or narrow the source's path",
            ));
        }
    }
    let count: Option<fn(&Path, &[u8]) -> Result<(), ParseError>> = match format {
        "at2" => Some(at2::count_at2),
        "cosmos" => Some(cosmos::count_cosmos),
        "dmg" => Some(dmg::count_dmg),
        "smc" => Some(smc::count_smc),
        "knet" => Some(knet::count_knet),
        "esm" => Some(esm::count_esm),
        "geonet" => Some(geonet::count_geonet),
        _ => None,
    };
    if let Some(count) = count {
        count(path, &read_bytes(path)?)?;
    }
    let Some(opts) = delimited else { return Ok(None) };
    // A prefix ends at its last complete line.
    let cut = if head.len() as u64 == HEADER_BYTES {
        head.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1)
    } else {
        head.len()
    };
    let record = parse_delimited(path, &head[..cut], opts)?;
    Ok(Some(record.channels.into_iter().map(|c| c.name).collect()))
}

/// The refusal of a file whose format neither its content nor its extension tells (`format: auto`).
pub fn unknown_format(path: &Path) -> ParseError {
    let ext = path.extension().map(|e| format!("`.{}`", e.to_string_lossy())).unwrap_or_else(|| "none".into());
    ParseError::new(
        path,
        Some(1),
        None,
        format!("`format: auto` cannot tell this file's format: its first lines match no reader, and its extension ({ext}) is none of theirs"),
        "give the source the file's `format:` (docs/formats.md lists them), or narrow its path to record files",
    )
}

/// The strong-motion formats by content (COSMOS, CSMIP/DMG, SMC, K-NET, ESM, GeoNet): their
/// extensions overlap (`.V1`, `.V2`, `.asc`), their first lines do not.
fn sniff_strong_motion(head: &str, line1: &str, line2: &str) -> Option<&'static str> {
    let upper_head = head.to_ascii_uppercase();
    if line1.contains("(FORMAT V") {
        return Some("cosmos");
    }
    if line1.starts_with("ORIGIN TIME") && upper_head.contains("SCALE FACTOR") {
        return Some("knet");
    }
    if line1.starts_with("EVENT_NAME:") && upper_head.contains("NDATA:") {
        return Some("esm");
    }
    let kind = line1.trim_start_matches(|c: char| c.is_ascii_digit()).trim_start();
    if line1.starts_with(|c: char| c.is_ascii_digit()) && kind.contains("ACCELEROGRAM") && line2.trim() == "*" {
        return Some("smc");
    }
    if line1.contains("ACCELEROGRAM") && line2.starts_with("SITE ") {
        return Some("geonet");
    }
    // CSMIP Vol.1 shares its first line with RENADIC's; RENADIC names itself.
    let csmip = ["CSMIP", "CGS", "CDMG", "ACCELEROGRAM POINTS", "POINTS OF ACCEL"];
    if line1.contains("ACCELEROGRAM") && !upper_head.contains("RENADIC") && csmip.iter().any(|m| upper_head.contains(m))
    {
        return Some("dmg");
    }
    None
}

/// The bytes of a file, read once: readers parse these very bytes, so a run can hash what it
/// parses ([`unchanged`]).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>, ParseError> {
    std::fs::read(path).map_err(|e| {
        let hint = match e.kind() {
            std::io::ErrorKind::NotFound => "check the path and the current directory",
            std::io::ErrorKind::PermissionDenied => "check the file's permissions",
            _ => "check that the path is a readable file",
        };
        ParseError::new(path, None, None, format!("cannot read the file: {e}"), hint)
    })
}

/// Refuses `bytes` when `expected_hash` (the blake3 hex taken when the run was planned; empty:
/// unknown) is not their hash: the file was replaced or still being written while the run read
/// it, and the artifact would hold other bytes than its provenance names.
pub fn unchanged(path: &Path, expected_hash: &str, bytes: &[u8]) -> Result<(), ParseError> {
    if expected_hash.is_empty() || crate::io::hash::hash_bytes(bytes) == expected_hash {
        return Ok(());
    }
    Err(ParseError::new(
        path,
        None,
        None,
        format!(
            "`{}` changed while this run was reading it: its content is no longer what the run hashed when it started",
            path.display()
        ),
        "another program is writing or replacing it (an export or a copy still in progress?); rerun when it is no longer being written",
    ))
}

/// The text of a record file. Invalid UTF-8 (e.g. a Latin-1 station name) is replaced rather
/// than rejected: only the numbers matter, and a mangled number still fails with a precise
/// message. A UTF-16 file or one holding NUL bytes (binary, compressed, UTF-16 without a
/// byte-order mark) is refused as such, before any message could quote its bytes.
pub fn decode<'a>(path: &Path, bytes: &'a [u8]) -> Result<Cow<'a, str>, ParseError> {
    if let Some(problem) = not_text(bytes) {
        return Err(ParseError::new(path, problem.line, None, problem.message, problem.hint));
    }
    let bytes = bytes.strip_prefix("\u{feff}".as_bytes()).unwrap_or(bytes);
    // Nearly every record is valid UTF-8, which the standard library checks a word at a time;
    // the lossy decoder, byte by byte, is for the files it refuses.
    Ok(match std::str::from_utf8(bytes) {
        Ok(text) => Cow::Borrowed(text),
        Err(_) => String::from_utf8_lossy(bytes),
    })
}

/// Why bytes are not a text file: a binary file, or UTF-16 text.
#[derive(Debug, Clone, PartialEq)]
pub struct NotText {
    pub line: Option<usize>,
    pub message: String,
    pub hint: &'static str,
}

/// Whether `bytes` are a binary or UTF-16 file rather than (UTF-8 or ASCII) text: a UTF-16
/// byte-order mark, or a NUL byte (never in text; in every UTF-16 file of ASCII text).
pub fn not_text(bytes: &[u8]) -> Option<NotText> {
    const HINT: &str = "this is a binary or UTF-16 file, not plain text: check that it is the right file \
                        (not a compressed or binary export); save UTF-16 text as UTF-8";
    if bytes.starts_with(&[0xff, 0xfe]) || bytes.starts_with(&[0xfe, 0xff]) {
        return Some(NotText {
            line: None,
            message: "binary or UTF-16 file: it starts with a UTF-16 byte-order mark".to_string(),
            hint: HINT,
        });
    }
    let at = memchr::memchr(0, bytes)?;
    let line = bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
    Some(NotText {
        line: Some(line),
        message: format!("binary or UTF-16 file: it holds a NUL byte (byte {}, line {line})", at + 1),
        hint: HINT,
    })
}

/// The text of a record file ([`decode`]), refused when it holds nothing but blanks: `what` says
/// what the file should have held.
fn record_text<'a>(path: &Path, bytes: &'a [u8], what: &str) -> Result<Cow<'a, str>, ParseError> {
    let text = decode(path, bytes)?;
    if text.trim().is_empty() {
        return Err(ParseError::new(
            path,
            None,
            None,
            "the file is empty",
            format!("expected {what}; the download or export probably failed"),
        ));
    }
    Ok(text)
}

/// Lines numbered from 1, without the `\r` of CRLF endings.
fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.split('\n').enumerate().map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)))
}

/// 1-based character column of byte offset `byte` in `line`.
fn char_column(line: &str, byte: usize) -> usize {
    line.get(..byte).map_or(byte, |s| s.chars().count()) + 1
}

/// Byte offset of `part` inside `whole`; `part` must be a sub-slice of it.
fn offset_in(whole: &str, part: &str) -> usize {
    (part.as_ptr() as usize).saturating_sub(whole.as_ptr() as usize)
}

/// A line quoted for a message, shortened so errors stay readable.
fn quote(line: &str) -> String {
    const MAX: usize = 90;
    let trimmed = line.trim_end();
    if trimmed.chars().count() <= MAX {
        format!("'{trimmed}'")
    } else {
        let short: String = trimmed.chars().take(MAX).collect();
        format!("'{short}...'")
    }
}

/// A finite number, or None. Infinities are refused: in an accelerogram they
/// only come from corrupt data.
fn parse_finite(token: &str) -> Option<f64> {
    fast_float2::parse::<f64, _>(token).ok().filter(|v| v.is_finite())
}
