//! Delimited text (CSV, TSV, whitespace columns, NEES `.asc`): optional preamble lines, an
//! optional column-name row, optional description and units rows (NEES's convention), then
//! numeric rows. Every column is a channel.
//!
//! Built for files of tens of MB: the file is read once and cells are parsed
//! straight from `&str` slices, with no per-cell allocation.

use super::{char_column, numbered_lines, offset_in, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DelimitedOptions {
    /// None: '\t' for .tsv/.tab, else sniffed from the column-name row (or the
    /// first data row): ',', ';', '\t', or runs of whitespace. `Some(b' ')`
    /// also means runs of whitespace.
    pub delimiter: Option<u8>,
    /// Lines skipped before the column-name row.
    pub header_lines: usize,
    /// false: there is no column-name row and columns are named col1..colN.
    pub has_column_names: bool,
    /// The 1-based line holding each column's unit (NEES: below the names and descriptions);
    /// it must come after the column-name row. Data start after the last of these rows.
    pub units_row: Option<usize>,
    /// The 1-based line holding each column's description, after the column-name row.
    pub description_row: Option<usize>,
}

impl Default for DelimitedOptions {
    fn default() -> Self {
        DelimitedOptions {
            delimiter: None,
            header_lines: 0,
            has_column_names: true,
            units_row: None,
            description_row: None,
        }
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Splitter {
    Char(char),
    Whitespace,
}

impl Splitter {
    fn describe(self) -> String {
        match self {
            Splitter::Char(',') => "comma".to_string(),
            Splitter::Char(';') => "semicolon".to_string(),
            Splitter::Char('\t') => "tab".to_string(),
            Splitter::Char(c) => format!("'{c}'"),
            Splitter::Whitespace => "whitespace".to_string(),
        }
    }

    /// Cells of a line, trimmed and unquoted. Quoted cells holding the
    /// delimiter are not supported: numeric tables do not need them.
    fn cells(self, line: &str) -> Cells<'_> {
        match self {
            Splitter::Char(c) => Cells::Char(line.split(c)),
            Splitter::Whitespace => Cells::Whitespace(line.split_ascii_whitespace()),
        }
    }
}

/// Cell iterator without boxing: one per line, on the hot path.
enum Cells<'a> {
    Char(std::str::Split<'a, char>),
    Whitespace(std::str::SplitAsciiWhitespace<'a>),
}

impl<'a> Iterator for Cells<'a> {
    type Item = &'a str;
    fn next(&mut self) -> Option<&'a str> {
        match self {
            Cells::Char(it) => it.next().map(clean),
            Cells::Whitespace(it) => it.next().map(clean),
        }
    }
}

fn clean(cell: &str) -> &str {
    let cell = cell.trim();
    cell.strip_prefix('"').and_then(|c| c.strip_suffix('"')).unwrap_or(cell)
}

pub fn read_delimited(path: &Path, opts: &DelimitedOptions) -> Result<RawRecord, ParseError> {
    parse_delimited(path, &read_bytes(path)?, opts)
}

/// [`read_delimited`] of a file's bytes; `path` only names the file in errors (and, without a
/// delimiter in `opts`, its extension picks tab for `.tsv`/`.tab`).
pub fn parse_delimited(path: &Path, bytes: &[u8], opts: &DelimitedOptions) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "rows of numbers, optionally under a column-name row")?;
    // Blank lines at the end are not rows. Cut after the last non-blank line
    // rather than trimming it, so a trailing tab (empty last cell) survives.
    let last_char = text.trim_end().len();
    let end = text[last_char..].find('\n').map_or(text.len(), |i| last_char + i);
    let body = &text[..end];
    // Only error messages need it: counting lines is a pass over the whole file.
    let last_line_number = || line_count(body);

    let mut lines = numbered_lines(body).peekable();
    let mut header = BTreeMap::new();
    for k in 1..=opts.header_lines {
        let Some((_, line)) = lines.next() else {
            return Err(no_data(
                path,
                last_line_number(),
                format!(
                    "the file has {} non-blank line(s), all inside the {} preamble line(s) to skip",
                    last_line_number(),
                    opts.header_lines
                ),
            ));
        };
        header.insert(format!("preamble_{k}"), line.trim().to_string());
    }
    let Some(&(reference_number, reference)) = lines.peek() else {
        return Err(no_data(path, last_line_number(), "no column-name row and no data after the preamble".to_string()));
    };

    let splitter = choose_splitter(path, opts, reference)?;
    let (names, names_line) = if opts.has_column_names {
        lines.next();
        let names: Vec<String> = splitter
            .cells(reference)
            .enumerate()
            .map(|(i, n)| if n.is_empty() { format!("col{}", i + 1) } else { n.to_string() })
            .collect();
        (names, Some(reference_number))
    } else {
        let n = splitter.cells(reference).count();
        ((1..=n).map(|i| format!("col{i}")).collect(), None)
    };
    if names.is_empty() {
        return Err(ParseError::new(
            path,
            Some(reference_number),
            None,
            "the first row after the preamble has no cells",
            "set header_lines to the number of lines before the column-name row",
        ));
    }
    // NEES-style rows under the names: descriptions and units, one cell per column.
    let last_name_line = names_line.unwrap_or(opts.header_lines);
    let mut units = vec![String::new(); names.len()];
    for (row, what) in [(opts.description_row, "description"), (opts.units_row, "units")] {
        if let Some(row) = row.filter(|&r| r <= last_name_line) {
            return Err(ParseError::new(
                path,
                Some(row),
                None,
                format!("the {what} row (line {row}) must come after the column-name row (line {last_name_line})"),
                "units_row and description_row are line numbers in the file, below the column names",
            ));
        }
    }
    if let Some(last) = [opts.units_row, opts.description_row].into_iter().flatten().max() {
        while let Some(&(number, line)) = lines.peek().filter(|(n, _)| *n <= last) {
            lines.next();
            let kind = if Some(number) == opts.units_row {
                "units"
            } else if Some(number) == opts.description_row {
                "description"
            } else {
                header.insert(format!("header_line_{number}"), line.trim().to_string());
                continue;
            };
            let cells: Vec<&str> = splitter.cells(line).collect();
            if cells.len() != names.len() {
                return Err(ParseError::new(
                    path,
                    Some(number),
                    None,
                    format!(
                        "the {kind} row (line {number}) has {} cell(s) but the column-name row has {}",
                        cells.len(),
                        names.len()
                    ),
                    format!("give one {kind} cell per column ({} delimiter), empty where unknown", splitter.describe()),
                ));
            }
            for ((name, cell), unit) in names.iter().zip(&cells).zip(&mut units) {
                if cell.is_empty() {
                    continue;
                }
                if kind == "description" {
                    header.insert(format!("channel.{name}.description"), cell.to_string());
                } else {
                    *unit = unit_of_cell(cell).to_string();
                    header.insert(format!("channel.{name}.units"), cell.to_string());
                    header.insert(
                        format!("channel.{name}.units_at"),
                        format!("{number}:{}", char_column(line, offset_in(line, cell))),
                    );
                }
            }
        }
        if lines.peek().is_none() {
            return Err(no_data(
                path,
                last_line_number(),
                format!(
                    "the file ends at line {} before or at its units/description row (line {last})",
                    last_line_number()
                ),
            ));
        }
    }
    let Some(&(first_data_number, first_data)) = lines.peek() else {
        return Err(no_data(
            path,
            reference_number,
            format!("only a column-name row (line {reference_number}), no data rows after it"),
        ));
    };

    let ncols = names.len();
    // Rough row count from the first data row, to allocate once.
    // A row takes at least a byte per cell: no more rows fit in the body than that allows,
    // which bounds what a wide column-name row over a short first row could reserve.
    let rows_estimate = (body.len() / (first_data.len() + 1).max(8)).min(body.len() / ncols) + 1;
    let mut columns: Vec<Vec<f64>> = (0..ncols).map(|_| Vec::with_capacity(rows_estimate)).collect();
    let ctx = Context { path, body, names: &names, names_line, splitter, opts, first_data_number };
    let mut row = Vec::with_capacity(ncols);
    // Rows are read straight from the body: the plain-row parser finds each line's end as it
    // goes, so the common row costs no separate search for its newline.
    let (bytes, mut start, mut number) = (body.as_bytes(), offset_in(body, first_data), first_data_number);
    while start < bytes.len() {
        if let Splitter::Char(c) = splitter {
            if let Some(used) = plain_row(&bytes[start..], c as u8, &mut row) {
                if row.len() == ncols {
                    columns.iter_mut().zip(&row).for_each(|(column, &v)| column.push(v));
                    (start, number) = (start + used, number + 1);
                    continue;
                }
            }
        }
        let end = body[start..].find('\n').map_or(body.len(), |i| start + i);
        let line = body[start..end].strip_suffix('\r').unwrap_or(&body[start..end]);
        let mut count = 0;
        for cell in splitter.cells(line) {
            if let Some(column) = columns.get_mut(count) {
                column.push(read_cell(cell).ok_or_else(|| ctx.bad_cell(number, line, cell, count))?);
            }
            count += 1;
        }
        if count != ncols {
            return Err(ctx.ragged(number, count));
        }
        (start, number) = (end + 1, number + 1);
    }

    let rows = columns[0].len();
    header.insert("delimiter".to_string(), splitter.describe());
    header.insert("columns".to_string(), names.join(", "));
    header.insert("npts".to_string(), rows.to_string());
    let channels = names
        .into_iter()
        .zip(columns)
        .zip(units)
        .map(|((name, values), unit)| RawChannel { name, unit, values, first_data_line: Some(first_data_number) })
        .collect();
    Ok(RawRecord { format: "delimited", dt: None, time: None, channels, header })
}

/// The common row of plain numbers (no spaces, quotes or gaps) at the start of `text`, parsed
/// straight from its bytes into `row`; returns the bytes it spans with its line end (`\n`,
/// `\r\n` or the end of `text`). None sends the line to the general reader, which also words
/// any error.
fn plain_row(text: &[u8], delimiter: u8, row: &mut Vec<f64>) -> Option<usize> {
    row.clear();
    let mut at = 0;
    loop {
        let rest = &text[at..];
        let (v, used) =
            short_decimal(rest).map(Ok).unwrap_or_else(|| fast_float2::parse_partial::<f64, _>(rest)).ok()?;
        if !v.is_finite() {
            return None;
        }
        row.push(v);
        at += used;
        match text.get(at) {
            None => return Some(at),
            Some(b'\n') => return Some(at + 1),
            Some(b'\r') if text.get(at + 1) == Some(&b'\n') => return Some(at + 2),
            Some(&b) if b == delimiter => at += 1,
            Some(_) => return None,
        }
    }
}

/// Exact powers of ten representable in an f64 (10^22 is the largest).
const EXACT_POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// The number at the start of `text` when it is a short decimal (`-6.493762e-4`: at most 15
/// digits, a power of ten within ±22), with the bytes it spans; None for anything else, which
/// the general parser then reads. Exact (Clinger's fast path): the digits and the power of ten
/// are both exact f64s, so one correctly rounded multiply or divide gives the nearest double.
fn short_decimal(text: &[u8]) -> Option<(f64, usize)> {
    let mut i = 0;
    let negative = sign(text, &mut i);
    let (mut mantissa, mut digits, mut fraction_digits, mut seen_point) = (0u64, 0u32, 0i32, false);
    while let Some(&b) = text.get(i) {
        match b {
            b'0'..=b'9' => {
                // Wrapping: a number too long to overflow here is refused below anyway.
                mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(b - b'0'));
                digits += 1;
                fraction_digits += i32::from(seen_point);
            }
            b'.' if !seen_point => seen_point = true,
            _ => break,
        }
        i += 1;
    }
    if digits == 0 || digits > 15 {
        return None;
    }
    let mut exponent = 0i32;
    if let Some(b'e' | b'E') = text.get(i) {
        i += 1;
        let exponent_negative = sign(text, &mut i);
        let start = i;
        while let Some(&b @ b'0'..=b'9') = text.get(i) {
            exponent = exponent.checked_mul(10)?.checked_add(i32::from(b - b'0'))?;
            i += 1;
        }
        if i == start {
            return None;
        }
        if exponent_negative {
            exponent = -exponent;
        }
    }
    let power = exponent - fraction_digits;
    let magnitude = mantissa as f64; // exact: at most 15 digits < 2^53
    let value = match power {
        0..=22 => magnitude * EXACT_POWERS_OF_TEN[power as usize],
        -22..=-1 => magnitude / EXACT_POWERS_OF_TEN[(-power) as usize],
        _ if mantissa == 0 => 0.0,
        _ => return None,
    };
    Some((if negative { -value } else { value }, i))
}

/// Whether a sign at `text[*i]` is a minus; steps over the sign.
fn sign(text: &[u8], i: &mut usize) -> bool {
    match text.get(*i) {
        Some(b'-') => {
            *i += 1;
            true
        }
        Some(b'+') => {
            *i += 1;
            false
        }
        _ => false,
    }
}

/// A units cell as DAQ exports write it: `g`, `(g)`, `[in/s^2]`.
fn unit_of_cell(cell: &str) -> &str {
    let inner = cell.strip_prefix('(').and_then(|c| c.strip_suffix(')'));
    let inner = inner.or_else(|| cell.strip_prefix('[').and_then(|c| c.strip_suffix(']')));
    inner.unwrap_or(cell).trim()
}

/// Whether a cell names a unit (physical or raw), as a units row's cells do.
fn is_unit(cell: &str) -> bool {
    let unit = unit_of_cell(cell);
    crate::units::conversion(unit).is_some() || crate::units::raw_unit(unit).is_some()
}

/// A number; NaN for an empty cell, "NaN"/"nan" or "NA" (gaps are the
/// caller's business); None for anything else, infinities included.
fn read_cell(cell: &str) -> Option<f64> {
    match fast_float2::parse::<f64, _>(cell) {
        Ok(v) if v.is_finite() || v.is_nan() => Some(v),
        Ok(_) => None,
        Err(_) if cell.is_empty() || cell.eq_ignore_ascii_case("NA") => Some(f64::NAN),
        Err(_) => None,
    }
}

fn choose_splitter(path: &Path, opts: &DelimitedOptions, reference: &str) -> Result<Splitter, ParseError> {
    match opts.delimiter {
        Some(b' ') => return Ok(Splitter::Whitespace),
        Some(d) if d.is_ascii() => return Ok(Splitter::Char(d as char)),
        Some(d) => {
            return Err(ParseError::new(
                path,
                None,
                None,
                format!("the delimiter byte 0x{d:02x} is not an ASCII character"),
                "use ',', ';', '\\t', ' ' or another ASCII character, or None to sniff it",
            ))
        }
        None => {}
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if matches!(ext.as_deref(), Some("tsv" | "tab")) {
        return Ok(Splitter::Char('\t'));
    }
    // Sniff from the names row: names rarely contain the delimiter, while
    // numbers might (decimal commas).
    let best = [',', '\t', ';'].into_iter().map(|c| (reference.matches(c).count(), c)).filter(|&(n, _)| n > 0).fold(
        None,
        |best: Option<(usize, char)>, cand| match best {
            Some(b) if b.0 >= cand.0 => Some(b),
            _ => Some(cand),
        },
    );
    Ok(best.map_or(Splitter::Whitespace, |(_, c)| Splitter::Char(c)))
}

fn line_count(body: &str) -> usize {
    body.bytes().filter(|&b| b == b'\n').count() + 1
}

fn no_data(path: &Path, line: usize, message: String) -> ParseError {
    ParseError::new(
        path,
        Some(line),
        None,
        format!("no data rows: {message}"),
        "the file holds a header but no numbers; check header_lines and that the export finished",
    )
}

struct Context<'a> {
    path: &'a Path,
    /// The file up to its last non-blank line.
    body: &'a str,
    names: &'a [String],
    names_line: Option<usize>,
    splitter: Splitter,
    opts: &'a DelimitedOptions,
    first_data_number: usize,
}

impl Context<'_> {
    fn bad_cell(&self, number: usize, line: &str, cell: &str, index: usize) -> ParseError {
        let column = char_column(line, offset_in(line, cell));
        let name = &self.names[index];
        let hint = if number == self.first_data_number && !self.opts.has_column_names {
            "if this line holds column names, set has_column_names = true".to_string()
        } else if number == self.first_data_number && is_unit(cell) {
            format!("line {number} looks like a units row (NEES files have one below the column names): set `units_row: {number}`")
        } else if number == self.first_data_number {
            format!(
                "if line {number} is still part of the file's header, raise header_lines (now {})",
                self.opts.header_lines
            )
        } else if cell.contains(',') && self.splitter != Splitter::Char(',') {
            "decimal commas are not supported: write numbers with a '.'".to_string()
        } else {
            "cells must be numbers; empty cells, NaN and NA are read as gaps (NaN)".to_string()
        };
        ParseError::new(
            self.path,
            Some(number),
            Some(column),
            format!("line {number}, column {} ({name}): cannot read '{cell}' as a number", index + 1),
            hint,
        )
    }

    fn ragged(&self, number: usize, count: usize) -> ParseError {
        let expected = self.names.len();
        let reference = match self.names_line {
            Some(l) => format!("the column-name row (line {l})"),
            None => format!("the first data row (line {})", self.first_data_number),
        };
        let mut message = format!("line {number} has {count} cell(s) but {reference} has {expected}");
        let hint = if number == line_count(self.body) {
            message.push_str("; this is the last line: the file may be truncated");
            "the last row was cut mid-row; re-export the file or delete its partial last line".to_string()
        } else {
            format!(
                "every row needs one cell per column ({} delimiter); look for a missing value or a stray delimiter",
                self.splitter.describe()
            )
        };
        ParseError::new(self.path, Some(number), None, message, hint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast path against Rust's own (correctly rounded) parser, on numbers written the ways
    /// DAQ exports write them, over the whole range it accepts and beyond.
    #[test]
    fn short_decimals_parse_exactly_like_std() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut fast = 0;
        for _ in 0..200_000 {
            let digits = 1 + next() % 17;
            let mantissa: String = (0..digits).map(|_| char::from(b'0' + (next() % 10) as u8)).collect();
            let point = (next() % (digits + 1)) as usize;
            let sign = ["", "-", "+"][(next() % 3) as usize];
            let exponent = match next() % 3 {
                0 => String::new(),
                1 => format!("e{}", next() % 30),
                _ => format!("E-{:02}", next() % 30),
            };
            let text = format!("{sign}{}.{}{exponent}", &mantissa[..point], &mantissa[point..]);
            let expected: f64 = text.parse().unwrap();
            if let Some((value, used)) = short_decimal(text.as_bytes()) {
                fast += 1;
                assert_eq!(used, text.len(), "{text}");
                assert_eq!(value.to_bits(), expected.to_bits(), "{text}: {value} vs {expected}");
            }
        }
        assert!(fast > 100_000, "the fast path took only {fast} of 200000");
        for odd in ["", "-", ".", "e5", "1e", "1e+", "nan", "inf", "1.2.3", "1234567890123456789012345.5"] {
            let fast = short_decimal(odd.as_bytes());
            assert!(fast.is_none() || fast.unwrap().1 < odd.len(), "{odd}: {fast:?}");
        }
    }
}
