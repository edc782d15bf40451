//! Tests against the real records in the shared data folder (values from its
//! SOURCES.md) and against damaged copies of them.

use super::*;
use std::fs;
use std::sync::atomic::{AtomicUsize, Ordering};

/// `../shared` beside the project root, which CI always provides.
const DATA_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/ground_motions");

/// Path of a shared record. Panics (fails the test) when the folder is gone:
/// these tests must never pass without the real data.
fn data(name: &str) -> PathBuf {
    let dir = Path::new(DATA_DIR);
    assert!(
        dir.join("SOURCES.md").is_file(),
        "the shared data folder {DATA_DIR} is missing (or has no SOURCES.md): \
         these tests need the real ground-motion records"
    );
    let path = dir.join(name);
    assert!(path.is_file(), "shared record {} is missing", path.display());
    path
}

fn data_text(name: &str) -> String {
    fs::read_to_string(data(name)).unwrap()
}

/// A fresh directory under the system temp dir, removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new() -> Self {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
        let dir = std::env::temp_dir().join(format!(
            "shakeflow-records-{}-{}-{nanos}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }

    fn write(&self, name: &str, content: impl AsRef<[u8]>) -> PathBuf {
        let path = self.0.join(name);
        fs::write(&path, content).unwrap();
        path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

fn pga(values: &[f64]) -> f64 {
    values.iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// PGA equals SOURCES.md's value to its 4 decimals.
fn assert_pga(values: &[f64], scale_to_g: f64, expected: f64, what: &str) {
    let got = pga(values) * scale_to_g;
    assert!((got - expected).abs() <= 0.5e-4, "{what}: PGA {got} g, SOURCES.md says {expected} g");
}

fn err_text(e: &ParseError) -> String {
    e.to_string()
}

// ---------------------------------------------------------------- real files

#[test]
fn at2_files_match_sources_md() {
    // file, npts, dt, PGA (g), first value, last value, channel name
    let table: [(&str, usize, f64, f64, f64, f64, &str); 9] = [
        ("Rinaldi228.AT2", 1991, 0.01, 0.8741, -0.2556093E-02, 0.5856269E-02, "228"),
        ("Rinaldi318.AT2", 1991, 0.01, 0.4723, -0.1492479E-02, 0.5608213E-02, "318"),
        ("RinaldiUP.AT2", 1991, 0.01, 0.9582, -0.8777599E-05, 0.6243671E-05, "UP"),
        ("RSN1084_NORTHR_SCS052.AT2", 8773, 0.005, 0.6230, -0.4981725E-02, 0.1139843E-02, "52"),
        ("RSN2110_DENALI_FAIGO360.AT2", 46800, 0.005, 0.0706, 0.4664905E-05, -0.1449223E-05, "360"),
        ("RSN6_IMPVALL.I_I-ELC180.AT2", 5372, 0.01, 0.2808, 0.9984852E-03, -0.1790158E-03, "180"),
        ("NIS090.AT2", 4096, 0.01, 0.5027, 0.233833E-06, 0.496963E-04, "090 (CUE)"),
        ("RSN1512_CHICHI_TCU078-E.AT2", 18000, 0.005, 0.4473, -0.1316978E-03, -0.1757745E-05, "E"),
        ("RSN763_LOMAP_GIL067.AT2", 7999, 0.005, 0.3585, -0.8075668E-03, 0.3362115E-03, "67"),
    ];
    for (file, npts, dt, expected_pga, first, last, name) in table {
        let rec = read_at2(&data(file)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rec.format, "at2");
        assert_eq!(rec.dt, Some(dt), "{file}");
        assert_eq!(rec.header["npts"], npts.to_string(), "{file}");
        assert_eq!(rec.channels.len(), 1);
        let ch = &rec.channels[0];
        assert_eq!(ch.name, name, "{file}");
        assert_eq!(ch.unit, "g", "{file}");
        assert_eq!(ch.values.len(), npts, "{file}");
        assert_eq!(ch.values[0], first, "{file}");
        assert_eq!(ch.values[npts - 1], last, "{file}");
        assert_eq!(ch.first_data_line, Some(5));
        assert_pga(&ch.values, 1.0, expected_pga, file);
    }
}

#[test]
fn at2_header_facts() {
    let rec = read_at2(&data("Rinaldi228.AT2")).unwrap();
    assert_eq!(rec.header["filter"], "0 POLE @    30.00000 HZ,  -5 POLE @      .05000");
    assert_eq!(rec.header["station"], "Rinaldi Receiving Sta");
    assert_eq!(rec.header["event"], "Northridge-01");
    assert_eq!(rec.header["date"], "1/17/1994");
    let old = read_at2(&data("NIS090.AT2")).unwrap();
    assert_eq!(old.header["station"], "NISHI-AKASHI");
    assert!(!old.header.contains_key("filter"), "the 'NPTS, DT' labels are not a filter");
}

#[test]
fn renadic_file_matches_sources_md() {
    let rec = read_renadic_v1(&data("llolleo1002271.v1")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rec.format, "renadic_v1");
    let dt = rec.dt.expect("uniform time column gives dt");
    assert!((dt - 0.005).abs() < 1e-9, "dt {dt}");
    let time = rec.time.as_ref().unwrap();
    assert_eq!(time.len(), 24923);
    assert_eq!((time[0], time[24922]), (0.0, 124.61));
    // name, PGA (g), first, last, first data line
    let expected =
        [("L", 0.3192, 0.0, 0.087, 28), ("V", 0.7019, -0.099, -0.031, 5041), ("T", 0.5644, 0.051, -0.020, 10054)];
    assert_eq!(rec.channels.len(), 3);
    for (i, (ch, (name, expected_pga, first, last, line))) in rec.channels.iter().zip(expected).enumerate() {
        assert_eq!(ch.name, name);
        assert_eq!(ch.unit, "g/10");
        assert_eq!(ch.values.len(), 24923, "{name}");
        assert_eq!(rec.header[&format!("ch{}_npts", i + 1)], "24923");
        assert_eq!((ch.values[0], ch.values[24922]), (first, last), "{name}");
        assert_eq!(ch.first_data_line, Some(line), "{name}");
        assert_pga(&ch.values, 0.1, expected_pga, name);
    }
    assert_eq!(rec.header["station"], "LLOLLEO S/N 4566");
    assert_eq!(rec.header["event"], "MAULE 2010");
}

#[test]
fn simcenter_file_matches_sources_md() {
    let rec = read_simcenter_json(&data("RSN2113.json")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rec.format, "simcenter_json");
    assert_eq!(rec.dt, Some(0.005));
    assert_eq!(rec.header["name"], "RSN2113");
    let expected = [("x", 0.0557, -8.713661e-07, 6.704674e-07), ("y", 0.0746, -2.688774e-07, 4.673708e-07)];
    assert_eq!(rec.channels.len(), 2);
    for (ch, (name, expected_pga, first, last)) in rec.channels.iter().zip(expected) {
        assert_eq!(ch.name, name);
        assert_eq!(ch.unit, "g");
        assert_eq!(ch.values.len(), 32895);
        assert_eq!((ch.values[0], ch.values[32894]), (first, last));
        assert_pga(&ch.values, 1.0, expected_pga, name);
    }
    // The file's own PGA fields agree with the data.
    assert_eq!(rec.header["PGA_x"].parse::<f64>().unwrap(), pga(&rec.channels[0].values));
}

#[test]
fn sniffing_real_and_renamed_files() {
    assert_eq!(sniff_format(&data("NIS090.AT2")), Some("at2"));
    assert_eq!(sniff_format(&data("llolleo1002271.v1")), Some("renadic_v1"));
    assert_eq!(sniff_format(&data("RSN2113.json")), Some("simcenter_json"));
    let tmp = Scratch::new();
    // Content wins over a misleading extension.
    assert_eq!(sniff_format(&tmp.write("renamed.txt", data_text("Rinaldi228.AT2"))), Some("at2"));
    assert_eq!(sniff_format(&tmp.write("a.csv", "t,a\n0,1\n")), Some("delimited"));
    assert_eq!(sniff_format(&tmp.write("a.tsv", "t\ta\n0\t1\n")), Some("delimited"));
    assert_eq!(sniff_format(&tmp.write("a.bin", "t,a\n0,1\n")), None);
    assert_eq!(sniff_format(&tmp.0.join("absent.xyz")), None);
}

// ---------------------------------------------------------------- bad AT2

#[test]
fn truncated_at2_names_both_counts() {
    let text = data_text("RSN1084_NORTHR_SCS052.AT2");
    let lines: Vec<&str> = text.lines().collect();
    // Drop the last 3 lines: 3 + 5 + 5 values.
    let kept = lines[..lines.len() - 3].join("\n");
    let tmp = Scratch::new();
    let path = tmp.write("cut.AT2", kept);
    let e = read_at2(&path).unwrap_err();
    let shown = err_text(&e);
    assert_eq!(e.line, Some(lines.len() - 3));
    assert!(shown.starts_with(&format!("{}:{}: ", path.display(), lines.len() - 3)), "{shown}");
    assert!(shown.contains("NPTS = 8773 (line 4) but only 8760 values were found"), "{shown}");
    assert!(e.hint.contains("13 values are missing") && e.hint.contains("truncated"), "{shown}");
}

#[test]
fn at2_npts_smaller_than_data() {
    let text = data_text("Rinaldi228.AT2").replacen("NPTS=   1991", "NPTS=   1990", 1);
    let tmp = Scratch::new();
    let e = read_at2(&tmp.write("npts.AT2", text)).unwrap_err();
    assert_eq!(e.line, Some(4));
    assert!(e.message.contains("NPTS = 1990 (line 4) but 1991 values were found"), "{e}");
}

#[test]
fn at2_unreadable_npts_shows_the_line() {
    let text = data_text("Rinaldi228.AT2").replacen("NPTS=   1991", "NPTS=   19x1", 1);
    let tmp = Scratch::new();
    let e = read_at2(&tmp.write("npts.AT2", text)).unwrap_err();
    assert_eq!((e.line, e.column), (Some(4), Some(9)));
    assert!(e.message.contains("NPTS '19x1'"), "{e}");
    assert!(e.hint.contains("line 4 is 'NPTS=   19x1, DT=   .0100 SEC"), "{e}");
}

#[test]
fn at2_missing_dt() {
    let text = data_text("NIS090.AT2").replacen("4096    0.0100    NPTS, DT", "4096    NPTS, DT", 1);
    let tmp = Scratch::new();
    let e = read_at2(&tmp.write("dt.AT2", text)).unwrap_err();
    assert_eq!((e.line, e.column), (Some(4), Some(9)));
    assert!(e.message.contains("cannot read DT 'NPTS,'"), "{e}");
}

#[test]
fn at2_non_numeric_token_has_line_and_column() {
    let text = data_text("Rinaldi228.AT2");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // Line 10, third value.
    let third = lines[9].split_whitespace().nth(2).unwrap().to_string();
    let at = lines[9].find(&third).unwrap();
    lines[9] = lines[9].replacen(&third, "-.27x6706E-02", 1);
    let tmp = Scratch::new();
    let path = tmp.write("token.AT2", lines.join("\n"));
    let e = read_at2(&path).unwrap_err();
    assert_eq!((e.line, e.column), (Some(10), Some(at + 1)));
    assert!(
        err_text(&e).starts_with(&format!(
            "{}:10:{}: cannot read '-.27x6706E-02' as a number (value 28 of 1991)",
            path.display(),
            at + 1
        )),
        "{e}"
    );
}

#[test]
fn at2_empty_and_header_only() {
    let tmp = Scratch::new();
    let e = read_at2(&tmp.write("empty.AT2", "")).unwrap_err();
    assert!(e.message.contains("the file is empty"), "{e}");
    let head: String = data_text("Rinaldi228.AT2").lines().take(4).map(|l| format!("{l}\n")).collect();
    let e = read_at2(&tmp.write("head.AT2", head)).unwrap_err();
    assert!(e.message.contains("no data values after the header (NPTS = 1991)"), "{e}");
    let e = read_at2(&tmp.write("short.AT2", "PEER\nline 2\n")).unwrap_err();
    assert!(e.message.contains("inside the 4-line AT2 header"), "{e}");
}

// ---------------------------------------------------------------- bad RENADIC

fn renadic_lines() -> Vec<String> {
    data_text("llolleo1002271.v1").split('\n').map(str::to_string).collect()
}

#[test]
fn renadic_missing_data_line_points_at_the_gap() {
    let mut lines = renadic_lines();
    // Line 6000 lies in channel 2's data block (lines 5041-10025).
    let removed = lines.remove(5999);
    assert!(removed.starts_with(" 23.975"), "{removed}");
    let tmp = Scratch::new();
    let path = tmp.write("gap.v1", lines.join("\n"));
    let e = read_renadic_v1(&path).unwrap_err();
    let shown = err_text(&e);
    assert_eq!(e.line, Some(6000), "{shown}");
    assert!(
        e.message.contains("channel 2 (V): header says NO. OF POINTS = 24923 (line 5024) but the data block (lines 5041-10024) holds 24918 points"),
        "{shown}"
    );
    assert!(
        e.hint.contains("jumps from 23.970 to 24.000 here (step 0.005 elsewhere)") && e.hint.contains("missing"),
        "{shown}"
    );
}

#[test]
fn renadic_missing_last_data_line() {
    let mut lines = renadic_lines();
    lines.remove(5011); // last data line of channel 1 (line 5012)
    let tmp = Scratch::new();
    let e = read_renadic_v1(&tmp.write("end.v1", lines.join("\n"))).unwrap_err();
    assert_eq!(e.line, Some(5012), "{e}");
    assert!(e.message.contains("channel 1 (L)") && e.message.contains("holds 24920 points"), "{e}");
    assert!(e.hint.contains("ends early"), "{e}");
}

#[test]
fn renadic_missing_header_line() {
    let mut lines = renadic_lines();
    lines.remove(5014 + 15); // an integer line of channel 2's header
    let tmp = Scratch::new();
    let e = read_renadic_v1(&tmp.write("hdr.v1", lines.join("\n"))).unwrap_err();
    assert_eq!((e.line, e.column), (Some(5033), Some(1)), "{e}");
    assert!(
        e.message.contains(
            "channel 2: integer header line 7 of 7 should hold 5-character number fields, found a blank field"
        ),
        "{e}"
    );
}

#[test]
fn renadic_time_base_mismatch() {
    let mut lines = renadic_lines();
    lines[10053] = lines[10053].replacen("  0.005", "  0.006", 1); // channel 3, 2nd point
    let tmp = Scratch::new();
    let e = read_renadic_v1(&tmp.write("tb.v1", lines.join("\n"))).unwrap_err();
    assert_eq!(e.line, Some(10054), "{e}");
    assert!(e.message.contains("channel 3 (T) point 2 has time 0.006 but channel 1 (L) has 0.005 (line 28)"), "{e}");
}

#[test]
fn renadic_touching_fields_bad_token() {
    let mut lines = renadic_lines();
    // "124.525  0.014124.530" -> damage the accel field touching the next time.
    lines[5008] = lines[5008].replacen("  0.014124.530", "  0.0x4124.530", 1);
    let tmp = Scratch::new();
    let e = read_renadic_v1(&tmp.write("tok.v1", lines.join("\n"))).unwrap_err();
    assert_eq!((e.line, e.column), (Some(5009), Some(10)), "{e}");
    assert!(e.message.contains("cannot read '0.0x4'"), "{e}");
}

#[test]
fn renadic_empty_header_only_and_truncated() {
    let tmp = Scratch::new();
    let e = read_renadic_v1(&tmp.write("e.v1", "\r\n")).unwrap_err();
    assert!(e.message.contains("the file is empty"), "{e}");
    let lines = renadic_lines();
    let e = read_renadic_v1(&tmp.write("h.v1", lines[..27].join("\n"))).unwrap_err();
    assert!(e.message.contains("holds 0 points") && e.hint.contains("truncated"), "{e}");
    let e = read_renadic_v1(&tmp.write("t.v1", lines[..8000].join("\n"))).unwrap_err();
    assert!(e.message.contains("channel 2 (V)") && e.hint.contains("truncated"), "{e}");
    let e = read_renadic_v1(&tmp.write("t2.v1", lines[..5020].join("\n"))).unwrap_err();
    assert!(e.message.contains("inside the header of channel 2"), "{e}");
}

// ---------------------------------------------------------------- bad JSON

#[test]
fn simcenter_missing_dt_lists_keys() {
    let tmp = Scratch::new();
    let e = read_simcenter_json(&tmp.write("a.json", r#"{"dt": 0.01, "data_x": [0.1, 0.2]}"#)).unwrap_err();
    assert_eq!((e.line, e.column), (None, None));
    assert!(e.message.contains("no \"dT\""), "{e}");
    assert!(e.hint.contains("\"dt\", \"data_x\""), "{e}"); // in file order
}

#[test]
fn simcenter_missing_data() {
    let tmp = Scratch::new();
    let e = read_simcenter_json(&tmp.write("a.json", r#"{"dT": 0.01, "name": "x"}"#)).unwrap_err();
    assert!(e.message.contains("no \"data_x\", \"data_y\" or \"data_z\""), "{e}");
    let e = read_simcenter_json(&tmp.write("b.json", r#"{"dT": 0.01, "data_x": []}"#)).unwrap_err();
    assert!(e.message.contains("\"data_x\" is an empty array"), "{e}");
}

#[test]
fn simcenter_syntax_error_has_line_and_column() {
    let text = data_text("RSN2113.json");
    let mut lines: Vec<&str> = text.split('\n').collect();
    assert_eq!(lines[6], "        -8.766006e-07,");
    lines[6] = "        -8.766006e-07 -1.0,";
    let tmp = Scratch::new();
    let path = tmp.write("syn.json", lines.join("\n"));
    let e = read_simcenter_json(&path).unwrap_err();
    assert_eq!((e.line, e.column), (Some(7), Some(23)), "{e}");
    assert!(
        err_text(&e).starts_with(&format!("{}:7:23: JSON syntax error: expected `,` or `]`", path.display())),
        "{e}"
    );
}

#[test]
fn simcenter_nan_and_truncation() {
    let tmp = Scratch::new();
    let e = read_simcenter_json(&tmp.write("nan.json", "{\"dT\": 0.01,\n \"data_x\": [0.1, NaN]}")).unwrap_err();
    assert_eq!(e.line, Some(2));
    assert!(e.hint.contains("NaN and Infinity are not valid JSON"), "{e}");
    let text = data_text("RSN2113.json");
    let e = read_simcenter_json(&tmp.write("cut.json", &text[..text.len() / 2])).unwrap_err();
    assert!(e.message.starts_with("the JSON ends early") && e.hint.contains("truncated"), "{e}");
}

#[test]
fn simcenter_non_numeric_entry_is_located() {
    let tmp = Scratch::new();
    let text = "{\"dT\": 0.01,\n\"data_x\": [0.1, 0.2],\n\"data_y\": [0.1, 0.2, \"abc\", 0.4]}";
    let e = read_simcenter_json(&tmp.write("s.json", text)).unwrap_err();
    assert_eq!(e.line, Some(3));
    assert!(e.message.starts_with("\"data_y\"[2]: invalid type: string \"abc\", expected f64"), "{e}");
    let e = read_simcenter_json(&tmp.write("n.json", "{\"dT\": 0.01, \"data_x\": [0.1, null]}")).unwrap_err();
    assert!(e.message.starts_with("\"data_x\"[1]: invalid type: null"), "{e}");
    let e = read_simcenter_json(&tmp.write("d.json", "{\"dT\": \"0.01\", \"data_x\": [0.1]}")).unwrap_err();
    assert!(e.message.starts_with("\"dT\": invalid type: string"), "{e}");
    let e = read_simcenter_json(&tmp.write("e.json", "  \n")).unwrap_err();
    assert!(e.message.contains("the file is empty"), "{e}");
}

// ---------------------------------------------------------------- delimited

/// time + two channels, `rows` rows, names on line 1.
fn csv(rows: usize) -> String {
    let mut s = String::from("time,A4_NS,A4_UD\n");
    for i in 0..rows {
        s.push_str(&format!("{},{},{}\n", i as f64 * 0.01, (i as f64).sin() * 0.1, (i as f64).cos() * 0.05));
    }
    s
}

fn csv_opts() -> DelimitedOptions {
    DelimitedOptions::default()
}

#[test]
fn csv_reads_columns() {
    let tmp = Scratch::new();
    let rec = read_delimited(&tmp.write("a.csv", csv(100)), &csv_opts()).unwrap();
    assert_eq!(rec.format, "delimited");
    let names: Vec<&str> = rec.channels.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["time", "A4_NS", "A4_UD"]);
    assert!(rec.channels.iter().all(|c| c.values.len() == 100 && c.unit.is_empty()));
    assert_eq!(rec.channels[0].values[99], 99.0 * 0.01);
    assert_eq!(rec.channels[0].first_data_line, Some(2));
    assert_eq!(rec.header["delimiter"], "comma");
}

#[test]
fn csv_non_numeric_cell_names_line_column_and_name() {
    let mut lines: Vec<String> = csv(100).lines().map(str::to_string).collect();
    lines[56] = "0.55,0.1,abc".to_string();
    let tmp = Scratch::new();
    let path = tmp.write("bad.csv", lines.join("\n"));
    let e = read_delimited(&path, &csv_opts()).unwrap_err();
    assert_eq!((e.line, e.column), (Some(57), Some(10)));
    assert_eq!(e.message, "line 57, column 3 (A4_UD): cannot read 'abc' as a number");
    assert!(err_text(&e).starts_with(&format!("{}:57:10: line 57", path.display())));
}

#[test]
fn csv_ragged_row_in_the_middle() {
    let mut lines: Vec<String> = csv(100).lines().map(str::to_string).collect();
    lines[19] = "0.18,0.1".to_string();
    let tmp = Scratch::new();
    let e = read_delimited(&tmp.write("r.csv", lines.join("\n")), &csv_opts()).unwrap_err();
    assert_eq!(e.line, Some(20));
    assert_eq!(e.message, "line 20 has 2 cell(s) but the column-name row (line 1) has 3");
    assert!(!e.message.contains("truncated"));
}

#[test]
fn csv_truncated_last_row() {
    let mut text = csv(100);
    text.push_str("1.00,0.0");
    let tmp = Scratch::new();
    let e = read_delimited(&tmp.write("t.csv", text), &csv_opts()).unwrap_err();
    assert_eq!(e.line, Some(102));
    assert!(e.message.ends_with("this is the last line: the file may be truncated"), "{e}");
    // Without names, the first data row sets the count.
    let tmp2 = Scratch::new();
    let e = read_delimited(
        &tmp2.write("n.txt", "0 1 2\n3 4 5\n6 7\n\n\n"),
        &DelimitedOptions { has_column_names: false, ..csv_opts() },
    )
    .unwrap_err();
    assert_eq!(
        e.message,
        "line 3 has 2 cell(s) but the first data row (line 1) has 3; this is the last line: the file may be truncated"
    );
}

#[test]
fn csv_empty_and_header_only() {
    let tmp = Scratch::new();
    let e = read_delimited(&tmp.write("e.csv", ""), &csv_opts()).unwrap_err();
    assert!(e.message.contains("the file is empty"), "{e}");
    let e = read_delimited(&tmp.write("h.csv", "\u{feff}time,a\r\n\r\n"), &csv_opts()).unwrap_err();
    assert_eq!(e.message, "no data rows: only a column-name row (line 1), no data rows after it");
    let e = read_delimited(
        &tmp.write("p.csv", "station X\nunits g\n"),
        &DelimitedOptions { header_lines: 2, ..csv_opts() },
    )
    .unwrap_err();
    assert!(e.message.contains("no column-name row and no data"), "{e}");
}

#[test]
fn csv_gaps_become_nan() {
    let tmp = Scratch::new();
    let text = "t,a,b,c\n0,1,,NaN\n1,nan,NA,2\n2,3,4,5\n";
    let rec = read_delimited(&tmp.write("g.csv", text), &csv_opts()).unwrap();
    let v = |c: usize| &rec.channels[c].values;
    assert_eq!(v(0), &[0.0, 1.0, 2.0]);
    assert!(v(1)[1].is_nan() && v(2)[0].is_nan() && v(2)[1].is_nan() && v(3)[0].is_nan());
    assert_eq!((v(1)[0], v(3)[1], v(3)[2]), (1.0, 2.0, 5.0));
    let e = read_delimited(&tmp.write("i.csv", "t,a\n0,inf\n"), &csv_opts()).unwrap_err();
    assert_eq!(e.message, "line 2, column 2 (a): cannot read 'inf' as a number");
}

#[test]
fn bom_crlf_tsv_whitespace_and_preamble() {
    let tmp = Scratch::new();
    let rec = read_delimited(&tmp.write("b.csv", "\u{feff}t;a\r\n0;1.5\r\n1;-2e-3\r\n"), &csv_opts()).unwrap();
    assert_eq!(rec.channels[0].name, "t");
    assert_eq!(rec.channels[1].values, [1.5, -2e-3]);
    assert_eq!(rec.header["delimiter"], "semicolon");
    // .tsv forces tab even though the names hold commas; a trailing tab is an empty cell.
    let rec = read_delimited(&tmp.write("c.tsv", "t\ta,b\tc\n0\t1\t\n"), &csv_opts()).unwrap();
    assert_eq!(rec.channels[1].name, "a,b");
    assert!(rec.channels[2].values[0].is_nan());
    let text = "Station: LLO\nunits: g\n  time    acc\n  0.00   0.1\n  0.01  -0.2\n";
    let rec = read_delimited(&tmp.write("w.txt", text), &DelimitedOptions { header_lines: 2, ..csv_opts() }).unwrap();
    assert_eq!(rec.header["delimiter"], "whitespace");
    assert_eq!(rec.header["preamble_1"], "Station: LLO");
    assert_eq!(rec.channels[1].values, [0.1, -0.2]);
    assert_eq!(rec.channels[1].first_data_line, Some(4));
    let e = read_delimited(&tmp.write("d.csv", "t;a\n0;1,5\n1;2,5\n0;3,5\n"), &csv_opts()).unwrap_err();
    assert_eq!(e.line, Some(2));
    let e = read_delimited(&tmp.write("d2.csv", "t;a\n0;1.5\n1;2,5\n"), &csv_opts()).unwrap_err();
    assert!(e.hint.contains("decimal commas"), "{e}");
}

#[test]
fn missing_file_is_an_error() {
    let tmp = Scratch::new();
    let e = read_at2(&tmp.0.join("nope.AT2")).unwrap_err();
    assert!(e.message.starts_with("cannot read the file") && e.hint.contains("check the path"), "{e}");
}

/// Damaged prefixes and byte flips of every real file through every reader:
/// errors are fine, panics are not.
#[test]
fn no_panics_on_damaged_input() {
    let tmp = Scratch::new();
    let files = ["Rinaldi228.AT2", "NIS090.AT2", "llolleo1002271.v1", "RSN2113.json"];
    for file in files {
        let bytes = fs::read(data(file)).unwrap();
        let mut seed = 0x9e37_79b9_u64;
        for k in 0..12 {
            let mut damaged = bytes[..bytes.len() * k / 12 + 1].to_vec();
            for _ in 0..3 {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                let at = (seed % damaged.len() as u64) as usize;
                damaged[at] = (seed >> 32) as u8;
            }
            let path = tmp.write(&format!("d{k}.{file}"), &damaged);
            let _ = read_at2(&path);
            let _ = read_renadic_v1(&path);
            let _ = read_simcenter_json(&path);
            let _ = read_delimited(&path, &csv_opts());
            let _ = sniff_format(&path);
        }
    }
}

/// A ~10 MB CSV (many read buffers' worth) comes back row for row: every value equals what the
/// standard library parses from the same text.
#[test]
fn large_csv_reads_every_row_exactly() {
    let mut text = String::with_capacity(11 << 20);
    text.push_str("time,A1_NS,A1_EW,A1_UD\n");
    // The time column is a channel too (the first).
    let mut rows: Vec<[f64; 4]> = Vec::new();
    while text.len() < 10 << 20 {
        let t = rows.len() as f64 * 0.005;
        let cells = [
            format!("{t:.3}"),
            format!("{:.7e}", (t * 7.0).sin() * 0.3),
            format!("{:.7e}", (t * 5.0).cos() * 0.2),
            format!("{:.7e}", (t * 3.0).sin() * 0.1),
        ];
        text.push_str(&cells.join(","));
        text.push('\n');
        rows.push(cells.map(|c| c.parse().unwrap()));
    }
    let tmp = Scratch::new();
    let path = tmp.write("big.csv", &text);
    let rec = read_delimited(&path, &csv_opts()).unwrap();
    assert_eq!(rec.channels.len(), 4);
    for (c, channel) in rec.channels.iter().enumerate() {
        assert_eq!(channel.values.len(), rows.len());
        for (k, row) in rows.iter().enumerate() {
            assert_eq!(channel.values[k].to_bits(), row[c].to_bits(), "row {k}, column {c}");
        }
    }
}

// ---------------------------------------------------------------- hostile input

/// A damaged NPTS is refused at its line and column before anything is allocated for it: the
/// count 99999999999 used to abort the process ("memory allocation of 799999999992 bytes
/// failed"), 2^64 − 1 to panic ("capacity overflow").
#[test]
fn at2_npts_beyond_the_file_size_is_refused_before_allocating() {
    let tmp = Scratch::new();
    for npts in ["99999999999", "18446744073709551615"] {
        let text = data_text("Rinaldi228.AT2").replacen("NPTS=   1991", &format!("NPTS=   {npts}"), 1);
        let e = read_at2(&tmp.write("huge.AT2", text)).unwrap_err();
        assert_eq!((e.line, e.column), (Some(4), Some(9)), "{e}");
        assert!(e.message.contains(&format!("NPTS = {npts} (line 4) cannot be right")), "{e}");
        // The older header form.
        let text = data_text("NIS090.AT2").replacen("4096    0.0100", &format!("{npts}    0.0100"), 1);
        let e = read_at2(&tmp.write("huge_old.AT2", text)).unwrap_err();
        assert_eq!((e.line, e.column), (Some(4), Some(1)), "{e}");
        assert!(e.message.contains("cannot be right"), "{e}");
    }
}

#[test]
fn renadic_point_count_beyond_the_file_size_is_refused_before_allocating() {
    let tmp = Scratch::new();
    for npts in ["99999999999", "18446744073709551615"] {
        let text =
            data_text("llolleo1002271.v1").replacen("NO. OF POINTS =  24923", &format!("NO. OF POINTS = {npts}"), 1);
        let e = read_renadic_v1(&tmp.write("huge.v1", text)).unwrap_err();
        assert_eq!(e.line, Some(11), "{e}");
        assert!(e.message.contains(&format!("NO. OF POINTS = {npts} cannot be right")), "{e}");
    }
}

/// Used to panic in `Table::push` ("column `y` has 3 rows but the table has 4") once loaded.
#[test]
fn simcenter_components_of_different_lengths_are_refused() {
    let tmp = Scratch::new();
    let text = "{\n  \"dT\": 0.01,\n  \"data_x\": [0.1, 0.2, 0.3, 0.4],\n  \"data_y\": [0.1, 0.2, 0.3]\n}\n";
    let e = read_simcenter_json(&tmp.write("ragged.json", text)).unwrap_err();
    assert_eq!(e.line, Some(4), "{e}");
    assert!(e.message.contains("\"data_y\" has 3 samples but \"data_x\" has 4"), "{e}");
}

/// UTF-16 (with or without a byte-order mark) and binary files are named as such, and nothing
/// in the message is a NUL or another control character copied from the file.
#[test]
fn binary_and_utf16_files_are_named_as_such() {
    let tmp = Scratch::new();
    let text = data_text("Rinaldi228.AT2");
    let utf16: Vec<u8> = text.encode_utf16().flat_map(u16::to_le_bytes).collect();
    let with_bom = [&[0xff, 0xfe][..], &utf16].concat();
    let gzip_like = [0x1f, 0x8b, 0x08, 0x00, 0x1b, b'[', b'2', b'J', 0x07, b'\r', 0x00, 0xff];
    for (name, bytes) in [("bom.AT2", &with_bom[..]), ("nobom.AT2", &utf16[..]), ("z.csv", &gzip_like[..])] {
        let path = tmp.write(name, bytes);
        let errors = [
            read_at2(&path).unwrap_err(),
            read_renadic_v1(&path).unwrap_err(),
            read_simcenter_json(&path).unwrap_err(),
            read_delimited(&path, &csv_opts()).unwrap_err(),
        ];
        for e in errors {
            let shown = err_text(&e);
            assert!(shown.contains("binary or UTF-16 file"), "{name}: {shown}");
            assert!(!shown.chars().any(|c| c.is_control() && c != '\n'), "{name}: {shown:?}");
        }
    }
}

/// A cell holding terminal escapes (ESC, BEL, CR) is quoted with them escaped: an error
/// message cannot clear the screen or overwrite its own first half.
#[test]
fn messages_escape_control_characters_from_the_file() {
    let tmp = Scratch::new();
    let path = tmp.write("esc.csv", "time,a\n0,1\n0.01,\u{1b}[2J\u{7}x\rfake\u{202e}\n");
    let e = read_delimited(&path, &csv_opts()).unwrap_err();
    let shown = err_text(&e);
    assert!(shown.contains("\\u{1b}[2J\\u{7}x\\rfake\\u{202e}"), "{shown}");
    assert!(!shown.chars().any(|c| (c.is_control() && c != '\n') || c == '\u{202e}'), "{shown:?}");
    assert_eq!(printable("plain text, é"), "plain text, é");
}

/// A column-name row 200 000 cells wide over a long file of one-cell rows used to reserve
/// rows × columns floats before reading the first row (terabytes: an abort); the reservation
/// now follows from the file's size and the ragged row is refused.
#[test]
fn wide_name_row_over_short_rows_reserves_by_the_file_size() {
    let tmp = Scratch::new();
    let mut text = (0..200_000).map(|i| format!("c{i}")).collect::<Vec<_>>().join(",");
    text.push('\n');
    text.push_str(&"1\n".repeat(1 << 20));
    let e = read_delimited(&tmp.write("wide.csv", text), &csv_opts()).unwrap_err();
    assert!(e.message.contains("line 2 has 1 cell(s) but the column-name row (line 1) has 200000"), "{e}");
}

/// `unchanged` passes the bytes whose hash the run took and refuses others.
#[test]
fn bytes_other_than_the_planned_ones_are_refused() {
    let path = Path::new("rec.csv");
    let planned = crate::io::hash::hash_bytes(b"time,a\n0,1\n");
    assert!(unchanged(path, &planned, b"time,a\n0,1\n").is_ok());
    assert!(unchanged(path, "", b"anything").is_ok());
    let e = unchanged(path, &planned, b"time,a\n0,2\n").unwrap_err();
    assert!(e.message.contains("`rec.csv` changed while this run was reading it"), "{e}");
    assert!(e.hint.contains("rerun when it is no longer being written"), "{e}");
}

#[test]
fn text_is_borrowed_when_valid_replaced_where_not_and_refused_with_a_nul() {
    let path = Path::new("r.txt");
    let text = decode(path, "\u{feff}time,ax\n0,1.5\n".as_bytes()).expect("valid UTF-8");
    assert!(matches!(text, Cow::Borrowed("time,ax\n0,1.5\n")), "{text:?}");
    // A Latin-1 station name (é = 0xE9) is replaced, the rest kept byte for byte.
    let text = decode(path, b"station Qu\xe9bec\n0,1.5\n").expect("lossy");
    assert_eq!(text, "station Qu\u{fffd}bec\n0,1.5\n");
    let refused = not_text(b"a\nb\nc\0d").expect("a NUL byte is not text");
    assert_eq!(refused.line, Some(3));
    assert!(refused.message.contains("byte 6, line 3"), "{}", refused.message);
    assert_eq!(not_text(b"a\nb\n"), None);
}
