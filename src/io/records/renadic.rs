//! RENADIC (Universidad de Chile) Vol.1 uncorrected accelerograms.
//!
//! Per channel: 13 text lines, 7 lines of 5-wide integers, 7 lines of
//! 10-wide floats, then (time, accel) pairs, 5 pairs per line in 7-character
//! fields, then a trailer line "/&  ---- END OF DATA FOR CHANNEL n ----".
//! The fields can touch ("123.800  0.040123.805"), so data and integer lines
//! are cut by fixed width, never split on whitespace.

use super::{
    char_column, numbered_lines, offset_in, parse_finite, quote, read_bytes, record_text, ParseError, RawChannel,
    RawRecord,
};
use std::collections::BTreeMap;
use std::path::Path;

const TEXT_LINES: usize = 13;
const INT_LINES: usize = 7;
const INT_WIDTH: usize = 5;
const FLOAT_LINES: usize = 7;
const FLOAT_WIDTH: usize = 10;
const FIELD: usize = 7;
const PAIRS_PER_LINE: usize = 5;
const TRAILER: &str = "/&";

struct Channel {
    name: String,
    unit: String,
    npts: usize,
    npts_line: usize,
    time: Vec<f64>,
    accel: Vec<f64>,
    /// (line number, index of the line's first point) for every data line, to
    /// map a point back to its line in messages.
    data_lines: Vec<(usize, usize)>,
}

impl Channel {
    fn line_of_point(&self, point: usize) -> Option<usize> {
        let i = self.data_lines.partition_point(|&(_, first)| first <= point);
        self.data_lines.get(i.checked_sub(1)?).map(|&(line, _)| line)
    }
}

pub fn read_renadic_v1(path: &Path) -> Result<RawRecord, ParseError> {
    parse_renadic_v1(path, &read_bytes(path)?)
}

/// [`read_renadic_v1`] of a file's bytes; `path` only names the file in errors.
pub fn parse_renadic_v1(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a RENADIC Vol.1 file (27 header lines per channel, then data)")?;
    // Trailing blank lines are not a channel.
    let lines: Vec<(usize, &str)> = numbered_lines(text.trim_end()).collect();
    let mut header = BTreeMap::new();
    let mut channels: Vec<Channel> = Vec::new();
    let mut pos = 0;
    while pos < lines.len() {
        let index = channels.len() + 1;
        let channel = read_channel(path, &lines, &mut pos, index, &mut header)?;
        channels.push(channel);
        while pos < lines.len() && lines[pos].1.trim().is_empty() {
            pos += 1;
        }
    }

    check_time_base(path, &channels)?;
    let time = channels[0].time.clone();
    let dt = uniform_step(&time);
    if let Some(dt) = dt {
        header.insert("dt_from_time_column".to_string(), dt.to_string());
    }
    header.insert("npts".to_string(), channels[0].npts.to_string());
    let raw_channels = channels
        .into_iter()
        .map(|c| RawChannel {
            first_data_line: c.data_lines.first().map(|&(line, _)| line),
            name: c.name,
            unit: c.unit,
            values: c.accel,
        })
        .collect();
    Ok(RawRecord { format: "renadic_v1", dt, time: Some(time), channels: raw_channels, header })
}

fn read_channel(
    path: &Path,
    lines: &[(usize, &str)],
    pos: &mut usize,
    index: usize,
    header: &mut BTreeMap<String, String>,
) -> Result<Channel, ParseError> {
    let start = *pos;
    let header_len = TEXT_LINES + INT_LINES + FLOAT_LINES;
    if lines.len() < start + header_len {
        let last = lines.last().map_or(0, |l| l.0);
        return Err(ParseError::new(
            path,
            Some(last),
            None,
            format!("the file ends inside the header of channel {index} (a channel header has {header_len} lines)"),
            "the file looks truncated; get a fresh copy",
        ));
    }
    let text = &lines[start..start + TEXT_LINES];
    let first_line = text[0].0;

    let (npts_line, npts) = find_after(text, "NO. OF POINTS")
        .and_then(|(line, rest)| {
            let token = rest.trim_start_matches([' ', '=']).split_ascii_whitespace().next()?;
            Some((line, token.parse::<usize>().ok()?))
        })
        .ok_or_else(|| {
            ParseError::new(
                path,
                Some(first_line),
                None,
                format!(
                    "channel {index}: no readable 'NO. OF POINTS =' in header lines {}-{}",
                    first_line,
                    first_line + TEXT_LINES - 1
                ),
                format!(
                    "a RENADIC Vol.1 channel starts with 13 text lines; line {first_line} is {} \
                     (if that is a data line, the previous channel has more lines than its NO. OF POINTS says)",
                    quote(text[0].1)
                ),
            )
        })?;
    // "UNITS OF UNCOR ACCEL ARE SEC AND G/10." -> "g/10"
    let unit = find_after(text, "SEC AND")
        .and_then(|(_, rest)| rest.split_ascii_whitespace().next())
        .map(|u| u.trim_end_matches(['.', ',']).to_lowercase())
        .unwrap_or_default();
    // "CHAN  1: L        (STA CHN:  1)" -> "L"
    let name = text
        .iter()
        .find(|(_, l)| l.starts_with("CHAN"))
        .and_then(|(_, line)| line.split_once(':'))
        .and_then(|(_, rest)| rest.split_ascii_whitespace().next())
        .map_or_else(|| format!("ch{index}"), str::to_string);

    if index == 1 {
        header.insert("title".to_string(), text[0].1.trim().to_string());
        header.insert("event".to_string(), text[1].1.trim().to_string());
        header.insert("station".to_string(), text[5].1.trim().to_string());
        header.insert("agency".to_string(), text[7].1.trim().to_string());
        if let Some((_, rest)) = find_after(text, "RECORD LENGTH") {
            let value = rest.trim_start_matches([' ', '=']).split_ascii_whitespace().next();
            header.insert("record_length_s".to_string(), value.unwrap_or("").to_string());
        }
    }
    let key = |what: &str| format!("ch{index}_{what}");
    header.insert(key("name"), name.clone());
    header.insert(key("npts"), npts.to_string());
    for (what, needle) in [("units", "UNITS OF"), ("instrument", "INSTR PERIOD")] {
        if let Some(&(_, line)) = text.iter().find(|(_, l)| l.contains(needle)) {
            header.insert(key(what), line.trim().to_string());
        }
    }

    let ints = &lines[start + TEXT_LINES..start + TEXT_LINES + INT_LINES];
    check_fixed_numbers(path, ints, INT_WIDTH, index, "integer", |s| s.parse::<i64>().is_ok())?;
    let floats = &lines[start + TEXT_LINES + INT_LINES..start + header_len];
    check_fixed_numbers(path, floats, FLOAT_WIDTH, index, "real", |s| parse_finite(s).is_some())?;

    *pos = start + header_len;
    // A point is two fields, the second at least one character of the last: a count the rest
    // of the file has no room for is a damaged header, refused before anything is allocated.
    // (Without data, the channel holds only its header: said when its points are counted.)
    let rest = lines.get(*pos).map_or(0, |&(_, line)| text_len(lines) - offset_in(lines[0].1, line));
    let room = rest / (FIELD + 1) + 1;
    if npts > room && rest > 0 {
        return Err(ParseError::new(
            path,
            Some(npts_line),
            None,
            format!(
                "channel {index} ({name}): NO. OF POINTS = {npts} cannot be right: the {rest} bytes after its header hold at most {room} points"
            ),
            "the point count in the header is damaged, or the file was cut short; get a fresh copy",
        ));
    }
    let mut channel = Channel {
        name,
        unit,
        npts,
        npts_line,
        time: Vec::with_capacity(npts.min(room)),
        accel: Vec::with_capacity(npts.min(room)),
        data_lines: Vec::with_capacity(npts.min(room).div_ceil(PAIRS_PER_LINE)),
    };
    let mut trailer_line = None;
    while *pos < lines.len() && channel.time.len() < npts {
        let (number, line) = lines[*pos];
        *pos += 1;
        if line.trim_start().starts_with(TRAILER) {
            trailer_line = Some(number);
            break;
        }
        read_data_line(path, number, line, &mut channel, index)?;
    }
    if trailer_line.is_none() {
        if let Some(&(number, line)) = lines.get(*pos) {
            if line.trim_start().starts_with(TRAILER) {
                *pos += 1;
                trailer_line = Some(number);
            } else if looks_like_data(line) {
                return Err(ParseError::new(
                    path,
                    Some(number),
                    None,
                    format!(
                        "channel {index} ({}): more data than NO. OF POINTS = {npts} (line {npts_line})",
                        channel.name
                    ),
                    "the point count in the header is wrong, or lines were duplicated",
                ));
            }
        }
    }
    if channel.time.len() != npts {
        return Err(count_mismatch(path, &channel, index, trailer_line, lines));
    }
    Ok(channel)
}

/// Bytes from the start of the first line to the end of the last.
fn text_len(lines: &[(usize, &str)]) -> usize {
    match (lines.first(), lines.last()) {
        (Some(first), Some(last)) => offset_in(first.1, last.1) + last.1.len(),
        _ => 0,
    }
}

/// First header line containing `key`, with the text after it.
fn find_after<'a>(text: &[(usize, &'a str)], key: &str) -> Option<(usize, &'a str)> {
    text.iter().find_map(|&(number, line)| {
        let i = line.find(key)?;
        Some((number, &line[i + key.len()..]))
    })
}

fn check_fixed_numbers(
    path: &Path,
    block: &[(usize, &str)],
    width: usize,
    index: usize,
    kind: &str,
    ok: impl Fn(&str) -> bool,
) -> Result<(), ParseError> {
    for (k, &(number, line)) in block.iter().enumerate() {
        let fields = fixed_fields(line, width).ok_or_else(|| non_ascii(path, number, line))?;
        for (col, field) in fields {
            if !ok(field.trim()) {
                let found = if field.trim().is_empty() { "a blank field".to_string() } else { quote(field.trim()) };
                return Err(ParseError::new(
                    path,
                    Some(number),
                    Some(col),
                    format!(
                        "channel {index}: {kind} header line {} of {} should hold {width}-character number fields, found {found}",
                        k + 1,
                        block.len()
                    ),
                    format!(
                        "each RENADIC channel header has {TEXT_LINES} text, {INT_LINES} integer and {FLOAT_LINES} real lines; \
                         a missing or extra header line shifts this block. Line {number} is {}",
                        quote(line)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Cut a line into fixed-width fields, with the 1-based column of each; the
/// last field may be short. None when the line is not ASCII (a fixed-width
/// cut could split a character).
fn fixed_fields(line: &str, width: usize) -> Option<Vec<(usize, &str)>> {
    let line = line.trim_end();
    if !line.is_ascii() {
        return None;
    }
    Some((0..line.len()).step_by(width).map(|a| (a + 1, &line[a..line.len().min(a + width)])).collect())
}

fn non_ascii(path: &Path, number: usize, line: &str) -> ParseError {
    let col = line.char_indices().find(|(_, c)| !c.is_ascii()).map(|(i, _)| char_column(line, i));
    ParseError::new(
        path,
        Some(number),
        col,
        "non-ASCII character in a fixed-width numeric line",
        "RENADIC numeric lines are plain ASCII; the file may be corrupt or was re-encoded",
    )
}

fn read_data_line(
    path: &Path,
    number: usize,
    line: &str,
    channel: &mut Channel,
    index: usize,
) -> Result<(), ParseError> {
    let fields = fixed_fields(line, FIELD).ok_or_else(|| non_ascii(path, number, line))?;
    if fields.is_empty() || fields.len() % 2 != 0 || fields.len() > 2 * PAIRS_PER_LINE {
        return Err(ParseError::new(
            path,
            Some(number),
            None,
            format!(
                "channel {index} ({}): a data line should hold 1 to {PAIRS_PER_LINE} (time, accel) pairs in {FIELD}-character fields, \
                 this one has {} field(s): {}",
                channel.name,
                fields.len(),
                quote(line)
            ),
            format!(
                "{} of NO. OF POINTS = {} were read before this line; the line may be cut short or the file corrupt",
                channel.time.len(),
                channel.npts
            ),
        ));
    }
    channel.data_lines.push((number, channel.time.len()));
    for pair in fields.chunks_exact(2) {
        let t = data_value(path, number, line, pair[0], channel, index)?;
        let a = data_value(path, number, line, pair[1], channel, index)?;
        channel.time.push(t);
        channel.accel.push(a);
    }
    Ok(())
}

fn data_value(
    path: &Path,
    number: usize,
    line: &str,
    (col, field): (usize, &str),
    channel: &Channel,
    index: usize,
) -> Result<f64, ParseError> {
    let token = field.trim();
    parse_finite(token).ok_or_else(|| {
        let col = col + (field.len() - field.trim_start().len());
        let hint = if token.is_empty() {
            "a blank field inside a data line: the line may be damaged".to_string()
        } else {
            format!(
                "{} of NO. OF POINTS = {} were read; data lines hold {FIELD}-character fields. \
                 If this is the next channel's header, this channel's data ended early",
                channel.time.len(),
                channel.npts
            )
        };
        ParseError::new(
            path,
            Some(number),
            Some(col),
            format!("channel {index} ({}): cannot read '{token}' as a number in line {}", channel.name, quote(line)),
            hint,
        )
    })
}

fn looks_like_data(line: &str) -> bool {
    fixed_fields(line, FIELD).is_some_and(|f| !f.is_empty() && f.iter().all(|(_, s)| parse_finite(s.trim()).is_some()))
}

fn count_mismatch(
    path: &Path,
    channel: &Channel,
    index: usize,
    trailer_line: Option<usize>,
    lines: &[(usize, &str)],
) -> ParseError {
    let found = channel.time.len();
    let span = match (channel.data_lines.first(), channel.data_lines.last()) {
        (Some(a), Some(b)) => format!(" (lines {}-{})", a.0, b.0),
        _ => String::new(),
    };
    let message = format!(
        "channel {index} ({}): header says NO. OF POINTS = {} (line {}) but the data block{span} holds {found} points",
        channel.name, channel.npts, channel.npts_line
    );
    // A dropped line shows as a jump in the otherwise uniform time column.
    if let Some((point, step)) = time_gap(&channel.time) {
        let line = channel.line_of_point(point);
        return ParseError::new(
            path,
            line,
            None,
            message,
            format!(
                "the time column jumps from {:.3} to {:.3} here (step {} elsewhere): a data line is probably missing",
                channel.time[point - 1],
                channel.time[point],
                // Rounded: the step is a difference of 3-decimal times.
                (step * 1e6).round() / 1e6
            ),
        );
    }
    let end = trailer_line.or_else(|| lines.last().map(|l| l.0));
    let hint = if trailer_line.is_some() {
        "the data block ends early; lines at its end were lost, or the header count is wrong"
    } else {
        "the file ends inside the data block: it looks truncated"
    };
    ParseError::new(path, end, None, message, hint)
}

/// First point where the time step differs from the typical step by more than
/// the 0.001 s print resolution, and that typical step.
fn time_gap(time: &[f64]) -> Option<(usize, f64)> {
    if time.len() < 3 {
        return None;
    }
    let step = time[1] - time[0];
    let i = time.windows(2).position(|w| ((w[1] - w[0]) - step).abs() > 0.0015)?;
    Some((i + 1, step))
}

/// The step of a uniform time column (within the 0.001 s print resolution).
fn uniform_step(time: &[f64]) -> Option<f64> {
    if time.len() < 2 || time_gap(time).is_some() {
        return None;
    }
    let step = (time[time.len() - 1] - time[0]) / (time.len() - 1) as f64;
    (step > 0.0).then_some(step)
}

fn check_time_base(path: &Path, channels: &[Channel]) -> Result<(), ParseError> {
    let first = &channels[0];
    for (i, c) in channels.iter().enumerate().skip(1) {
        if c.time.len() != first.time.len() {
            return Err(ParseError::new(
                path,
                Some(c.npts_line),
                None,
                format!(
                    "channel {} ({}) has {} points but channel 1 ({}) has {}",
                    i + 1,
                    c.name,
                    c.time.len(),
                    first.name,
                    first.time.len()
                ),
                "the channels of one record must share one time base",
            ));
        }
        if let Some(k) = c.time.iter().zip(&first.time).position(|(a, b)| a != b) {
            return Err(ParseError::new(
                path,
                c.line_of_point(k),
                None,
                format!(
                    "channel {} ({}) point {} has time {} but channel 1 ({}) has {} (line {})",
                    i + 1,
                    c.name,
                    k + 1,
                    c.time[k],
                    first.name,
                    first.time[k],
                    first.line_of_point(k).map_or("?".to_string(), |l| l.to_string())
                ),
                "the channels of one record must share one time base; the file may be corrupt",
            ));
        }
    }
    Ok(())
}
