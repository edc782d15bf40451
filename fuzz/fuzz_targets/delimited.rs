//! Delimited text reader. The first byte picks the options (delimiter, preamble lines,
//! column-name row, units row), the rest is the file.
#![no_main]
use libfuzzer_sys::fuzz_target;
use shakeflow::io::records::{parse_delimited, DelimitedOptions};

fuzz_target!(|data: &[u8]| {
    let Some((&options, file)) = data.split_first() else { return };
    let opts = DelimitedOptions {
        delimiter: [None, Some(b','), Some(b'\t'), Some(b' '), Some(b';'), Some(0xe9), None, None][usize::from(options & 7)],
        header_lines: usize::from((options >> 3) & 3),
        has_column_names: options & 0x20 == 0,
        // A units row right below the column names (NEES), on the top bit.
        units_row: (options & 0x80 != 0).then_some(usize::from((options >> 3) & 3) + 2),
        description_row: None,
    };
    let name = if options & 0x40 == 0 { "fuzz.csv" } else { "fuzz.tsv" };
    let _ = parse_delimited(std::path::Path::new(name), file, &opts);
});
