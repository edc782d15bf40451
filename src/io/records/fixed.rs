//! What the fixed-width strong-motion formats (COSMOS, CSMIP/DMG, SMC, GeoNet, K-NET, ESM)
//! share: a file as numbered lines, Fortran-style fields that may touch (`-1.2E+0-3.4E+0`),
//! value counts checked against the bytes left in the file before anything is allocated, and
//! errors that name the file, the line and the column. `validate` runs the readers with
//! [`Values::Count`]: data blocks are walked and their values counted, not parsed.

use super::{char_column, offset_in, parse_finite, quote, ParseError};
use std::path::Path;

/// What a reader does with a data block's values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Values {
    /// Parses them (`load`).
    Parse,
    /// Checks that each one is there (a field, a token) without parsing it, and gives zeros:
    /// `validate`'s cheap check that a file holds the values its header announces.
    Count,
}

/// A record file as lines (without `\r`), 0-based here, reported 1-based.
pub(super) struct Lines<'a> {
    pub path: &'a Path,
    lines: Vec<&'a str>,
    /// Byte offset of each line's start, to bound counts by what is left of the file.
    starts: Vec<usize>,
    len: usize,
    /// What [`Lines::fixed`] and [`Lines::free`] do with values (header blocks are always parsed).
    values: Values,
}

impl<'a> Lines<'a> {
    pub fn new(path: &'a Path, text: &'a str, values: Values) -> Self {
        let mut lines = Vec::new();
        let mut starts = Vec::new();
        let mut at = 0;
        for line in text.split('\n') {
            starts.push(at);
            at += line.len() + 1;
            lines.push(line.strip_suffix('\r').unwrap_or(line));
        }
        // A final newline does not open another line.
        if text.ends_with('\n') {
            lines.pop();
            starts.pop();
        }
        Lines { path, lines, starts, len: text.len(), values }
    }

    pub fn count(&self) -> usize {
        self.lines.len()
    }

    pub fn get(&self, i: usize) -> Option<&'a str> {
        self.lines.get(i).copied()
    }

    /// Line `i`, or an error saying the file ends inside `what`.
    pub fn line(&self, i: usize, what: &str) -> Result<&'a str, ParseError> {
        self.get(i).ok_or_else(|| self.ends_inside(what))
    }

    fn ends_inside(&self, what: &str) -> ParseError {
        ParseError::new(
            self.path,
            Some(self.count()),
            None,
            format!("the file ends after line {} inside {what}", self.count()),
            "the file looks truncated: get a fresh copy of the record",
        )
    }

    /// An error at 0-based line `i`, 1-based character column `column`.
    pub fn error(
        &self,
        i: usize,
        column: Option<usize>,
        message: impl Into<String>,
        hint: impl Into<String>,
    ) -> ParseError {
        ParseError::new(self.path, Some(i + 1), column, message, hint)
    }

    /// Bytes from the start of line `i` to the end of the file.
    fn bytes_from(&self, i: usize) -> usize {
        self.starts.get(i).map_or(0, |&s| self.len - s)
    }

    /// Refuses a count the rest of the file cannot hold (each value takes at least `min_bytes`),
    /// before anything is allocated for it.
    pub fn check_room(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        min_bytes: usize,
        what: &str,
    ) -> Result<(), ParseError> {
        let room = self.bytes_from(first) / min_bytes.max(1);
        if count > room {
            return Err(self.error(
                count_line,
                None,
                format!(
                    "the header says {count} {what}, but the rest of the file has room for at most {room} (line {} on)",
                    first + 1
                ),
                "the file is truncated or the count on this line is wrong: get a fresh copy of the record",
            ));
        }
        Ok(())
    }

    /// A data block: `count` numbers in fields `width` characters wide, `per_line` to a line,
    /// from line `first`; returns them (zeros when counting) and the index of the line after the
    /// last one read.
    pub fn fixed(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        per_line: usize,
        width: usize,
        what: &str,
    ) -> Result<(Vec<f64>, usize), ParseError> {
        self.fixed_as(count_line, first, count, per_line, width, what, self.values)
    }

    /// [`Lines::fixed`] for a block whose values the reader needs even when counting (a header).
    pub fn fixed_parsed(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        per_line: usize,
        width: usize,
        what: &str,
    ) -> Result<(Vec<f64>, usize), ParseError> {
        self.fixed_as(count_line, first, count, per_line, width, what, Values::Parse)
    }

    #[allow(clippy::too_many_arguments)]
    fn fixed_as(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        per_line: usize,
        width: usize,
        what: &str,
        mode: Values,
    ) -> Result<(Vec<f64>, usize), ParseError> {
        self.check_room(count_line, first, count, width, what)?;
        let per_line = per_line.max(1);
        let mut values = Vec::with_capacity(count);
        let mut i = first;
        while values.len() < count {
            // The message is built only when the file ends: this runs once per line.
            let line =
                self.get(i).ok_or_else(|| self.ends_inside(&format!("{what} ({} of {count} read)", values.len())))?;
            let on_line = per_line.min(count - values.len());
            for k in 0..on_line {
                let start = k * width;
                let field = line.get(start..(start + width).min(line.len())).unwrap_or("");
                let token = field.trim();
                let value = match mode {
                    _ if token.is_empty() => None,
                    Values::Parse => parse_finite(token),
                    Values::Count => Some(0.0),
                };
                let Some(value) = value else {
                    let column = if token.is_empty() { start.min(line.len()) } else { offset_in(line, token) };
                    let found = if token.is_empty() { "nothing".to_string() } else { format!("'{token}'") };
                    return Err(self.error(
                        i,
                        Some(char_column(line, column)),
                        format!("expected {what} value {} of {count} here, found {found}", values.len() + 1),
                        format!(
                            "this block holds {per_line} values of {width} characters per line; line {} is {}: \
                             the file may be truncated, edited or not of this format",
                            i + 1,
                            quote(line)
                        ),
                    ));
                };
                values.push(value);
            }
            // The block's last line: anything after its last value belongs to no block.
            let rest = line.get(on_line * width..).unwrap_or("");
            if on_line < per_line && !rest.trim().is_empty() {
                let column = offset_in(line, rest.trim_start());
                return Err(self.error(
                    i,
                    Some(char_column(line, column)),
                    format!("more {what} values on this line than the {count} the header announces"),
                    "the count in the header is wrong or the file was edited",
                ));
            }
            i += 1;
        }
        Ok((values, i))
    }

    /// A data block: `count` numbers separated by blanks, any number to a line, from line
    /// `first` (zeros when counting); a line holding more than the count needs is an error (two
    /// blocks run together).
    pub fn free(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        what: &str,
    ) -> Result<(Vec<f64>, usize), ParseError> {
        self.free_as(count_line, first, count, what, self.values)
    }

    /// [`Lines::free`] for a block whose values the reader needs even when counting.
    pub fn free_parsed(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        what: &str,
    ) -> Result<(Vec<f64>, usize), ParseError> {
        self.free_as(count_line, first, count, what, Values::Parse)
    }

    fn free_as(
        &self,
        count_line: usize,
        first: usize,
        count: usize,
        what: &str,
        mode: Values,
    ) -> Result<(Vec<f64>, usize), ParseError> {
        self.check_room(count_line, first, count, 2, what)?;
        let mut values = Vec::with_capacity(count);
        let mut i = first;
        while values.len() < count {
            // The message is built only when the file ends: this runs once per line.
            let line =
                self.get(i).ok_or_else(|| self.ends_inside(&format!("{what} ({} of {count} read)", values.len())))?;
            for token in line.split_ascii_whitespace() {
                let column = || char_column(line, offset_in(line, token));
                if values.len() == count {
                    return Err(self.error(
                        i,
                        Some(column()),
                        format!("'{token}' is one value more than the {count} {what} the header announces"),
                        "the count in the header is wrong or two blocks run together",
                    ));
                }
                let value = match mode {
                    Values::Parse => parse_finite(token),
                    Values::Count => Some(0.0),
                };
                let Some(value) = value else {
                    return Err(self.error(
                        i,
                        Some(column()),
                        format!("cannot read '{token}' as a number ({what} value {} of {count})", values.len() + 1),
                        "data lines hold only numbers separated by blanks: the file may be truncated or edited",
                    ));
                };
                values.push(value);
            }
            i += 1;
        }
        Ok((values, i))
    }
}

/// A line with nothing but blanks and control characters (old DOS files end in Ctrl-Z).
pub(super) fn is_blank(line: &str) -> bool {
    line.chars().all(|c| c.is_whitespace() || c.is_control())
}

/// A Fortran edit descriptor such as `(8f9.6)`, `(1E15.6)`, `(10I8)`, `Format= (5F15.6)`:
/// values per line and field width.
pub(super) fn fortran_format(text: &str) -> Option<(usize, usize)> {
    let open = text.rfind('(')?;
    let close = open + text[open..].find(')')?;
    let inner = text[open + 1..close].trim();
    let letter = inner.find(|c: char| c.is_ascii_alphabetic())?;
    let repeat = if letter == 0 { 1 } else { inner[..letter].trim().parse().ok()? };
    let rest = &inner[letter + 1..];
    let width = rest.split('.').next()?.trim().parse().ok()?;
    (repeat > 0 && width > 0).then_some((repeat, width))
}

/// The first whitespace-separated token of `line` as a count.
pub(super) fn leading_count(line: &str) -> Option<usize> {
    line.split_ascii_whitespace().next()?.parse().ok()
}

/// The text after `key` on `line` (case-insensitive), trimmed; `None` if `key` is absent.
pub(super) fn after<'l>(line: &'l str, key: &str) -> Option<&'l str> {
    let at = line.to_ascii_uppercase().find(&key.to_ascii_uppercase())?;
    line.get(at + key.len()..).map(str::trim)
}

/// Azimuth in degrees of a compass component label: `N10E` → 10, `S16W` → 196, `S74E` → 106,
/// `N80W` → 280; plain `N`/`E`/`S`/`W` too.
pub(super) fn compass_azimuth(label: &str) -> Option<f64> {
    let l = label.trim().to_ascii_uppercase();
    let bytes = l.as_bytes();
    match bytes {
        [b'N'] => return Some(0.0),
        [b'E'] => return Some(90.0),
        [b'S'] => return Some(180.0),
        [b'W'] => return Some(270.0),
        _ => {}
    }
    if bytes.len() < 3 {
        return None;
    }
    let (from, to) = (bytes[0], bytes[bytes.len() - 1]);
    let angle: f64 = l[1..l.len() - 1].trim().parse().ok()?;
    if !(0.0..=90.0).contains(&angle) {
        return None;
    }
    let azimuth = match (from, to) {
        (b'N', b'E') => angle,
        (b'N', b'W') => 360.0 - angle,
        (b'S', b'E') => 180.0 - angle,
        (b'S', b'W') => 180.0 + angle,
        _ => return None,
    };
    Some(azimuth.rem_euclid(360.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fortran_formats_give_count_and_width() {
        assert_eq!(fortran_format("Format: (8f9.6)"), Some((8, 9)));
        assert_eq!(fortran_format("units=cm/sec2(04),Format=(1E15.6)"), Some((1, 15)));
        assert_eq!(fortran_format("Format = (10I8)"), Some((10, 8)));
        assert_eq!(fortran_format("(E15.6)"), Some((1, 15)));
        assert_eq!(fortran_format("no format"), None);
    }

    #[test]
    fn compass_labels_become_azimuths() {
        assert_eq!(compass_azimuth("N10E"), Some(10.0));
        assert_eq!(compass_azimuth("S16W"), Some(196.0));
        assert_eq!(compass_azimuth("S74E"), Some(106.0));
        assert_eq!(compass_azimuth("N80W"), Some(280.0));
        assert_eq!(compass_azimuth("Up"), None);
    }

    #[test]
    fn touching_fields_are_split_by_width_and_counts_bounded_by_the_file() {
        let text = " 1.5057E+0-2.2223E+0\n-1.9234E+0\n";
        let lines = Lines::new(Path::new("x.smc"), text, Values::Parse);
        let (values, next) = lines.fixed(0, 0, 3, 2, 10, "acceleration").unwrap();
        assert_eq!(values, vec![1.5057, -2.2223, -1.9234]);
        assert_eq!(next, 2);
        let err = lines.fixed(0, 0, 99_999_999_999, 2, 10, "acceleration").unwrap_err();
        assert_eq!(err.line, Some(1));
        assert!(err.message.contains("room for at most 3"), "{}", err.message);
        let bad = Lines::new(Path::new("x.smc"), " 1.5057E+0-2.2223E+0\n-1.9234E+0   abc    \n", Values::Parse);
        let err = bad.fixed(0, 0, 4, 2, 10, "acceleration").unwrap_err();
        assert!(err.message.contains("value 4 of 4 here, found 'abc'"), "{err}");
        assert_eq!((err.line, err.column), (Some(2), Some(14)));
    }
}
