//! The strong-motion readers (COSMOS, CSMIP/DMG, SMC, K-NET/KiK-net, ESM, GeoNet) on the real
//! files in ../shared/data/records: point counts, sampling, units, first and last samples and
//! peaks as each file's header states them (SOURCES.md there tabulates them), orientations,
//! detection from content, and damaged copies refused with file:line.

use super::*;
use std::sync::atomic::{AtomicUsize, Ordering};

const RECORDS_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/records");

/// A shared record; fails (never skips) when the folder is gone.
fn record(name: &str) -> PathBuf {
    let dir = Path::new(RECORDS_DIR);
    assert!(
        dir.join("SOURCES.md").is_file(),
        "the shared records folder {RECORDS_DIR} is missing: these tests need it"
    );
    let path = dir.join(name);
    assert!(path.is_file(), "shared record {} is missing", path.display());
    path
}

fn peak(values: &[f64]) -> f64 {
    values.iter().copied().fold(0.0, |m: f64, v| if v.abs() > m.abs() { v } else { m })
}

fn channel<'r>(raw: &'r RawRecord, name: &str) -> &'r RawChannel {
    raw.channels
        .iter()
        .find(|c| c.name == name)
        .unwrap_or_else(|| panic!("no channel {name}: {:?}", raw.channels.iter().map(|c| &c.name).collect::<Vec<_>>()))
}

fn meta<'r>(raw: &'r RawRecord, key: &str) -> &'r str {
    raw.header.get(key).unwrap_or_else(|| panic!("no header key {key}: {:?}", raw.header.keys().collect::<Vec<_>>()))
}

/// A reader function.
type Reader = fn(&Path) -> Result<RawRecord, ParseError>;

/// A damaged copy of a shared record, written to a fresh temp file, read by `read`.
fn damaged(name: &str, edit: impl Fn(&str) -> String, read: fn(&Path) -> Result<RawRecord, ParseError>) -> ParseError {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let text = std::fs::read_to_string(record(name)).unwrap();
    let dir = std::env::temp_dir().join(format!(
        "shakeflow-formats-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(Path::new(name).file_name().unwrap());
    std::fs::write(&path, edit(&text)).unwrap();
    let result = read(&path);
    std::fs::remove_dir_all(&dir).unwrap();
    let Err(err) = result else { panic!("the damaged copy of {name} was read without complaint") };
    assert!(err.path.ends_with(Path::new(name).file_name().unwrap()), "{err}");
    err
}

/// The first `lines` lines of `text`.
fn head(text: &str, lines: usize) -> String {
    text.split_inclusive('\n').take(lines).collect()
}

#[test]
fn cosmos_v1c_single_channel() {
    let raw = read_cosmos(&record("cosmos/NCMDH--n.00725272.HNE.--.V1c")).unwrap();
    assert_eq!(raw.dt, Some(0.01));
    assert_eq!(raw.channels.len(), 1);
    let hne = channel(&raw, "HNE");
    assert_eq!(hne.unit, "cm/s^2");
    assert_eq!(hne.values.len(), 19200);
    assert_eq!(hne.values[0], -5.328779e-04);
    assert_eq!(*hne.values.last().unwrap(), -7.088660e-02);
    // R(64) = -16.585772; the data are written with 7 significant digits.
    assert!((peak(&hne.values) - -16.585772).abs() < 5e-6, "{}", peak(&hne.values));
    assert_eq!(hne.first_data_line, Some(52));
    assert_eq!(meta(&raw, "process_level"), "V1");
    assert_eq!(meta(&raw, "station"), "MDH");
    assert_eq!(meta(&raw, "network"), "NC");
    assert_eq!(meta(&raw, "channel.HNE.orientation"), "90");
    assert_eq!(meta(&raw, "channel.HNE.peak"), "-16.585772");
    assert!(meta(&raw, "event").contains("Tonopah, NV"));
}

#[test]
fn cosmos_v0c_counts_become_g_through_the_header_sensitivity() {
    let raw = read_cosmos(&record("cosmos/NP1795-n.305.v0c")).unwrap();
    assert_eq!(raw.dt, Some(0.005));
    let names: Vec<&str> = raw.channels.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["HNE", "HNN", "HNZ"]);
    assert_eq!(meta(&raw, "process_level"), "V0");
    // LSB 0.794729 µV/count, sensitivity 1.2 V/g, gain 1 (real header 22, 42, 47).
    let factor = 0.794729e-6 / 1.2;
    for (name, raw_peak, orientation) in [("HNE", 985881.0, "90"), ("HNN", 1341667.0, "360"), ("HNZ", 2378684.0, "up")]
    {
        let c = channel(&raw, name);
        assert_eq!(c.unit, "g");
        assert_eq!(c.values.len(), 20000);
        let counts_to_g: f64 = meta(&raw, &format!("channel.{name}.counts_to_g")).parse().unwrap();
        assert!((counts_to_g / factor - 1.0).abs() < 1e-15);
        // R(64), the raw maximum, is the largest |count| (the counts carry a DC offset).
        let max_counts = peak(&c.values).abs() / counts_to_g;
        assert!((max_counts - raw_peak).abs() < 1e-6 * raw_peak, "{name}: {max_counts} vs {raw_peak}");
        assert_eq!(meta(&raw, &format!("channel.{name}.orientation")), orientation);
    }
}

#[test]
fn cosmos_v2c_vertical_known_from_its_seed_name() {
    let raw = read_cosmos(&record("cosmos/us1000hyfh_akbmrp_AKBMR--n.1000hyfh.BNZ.--.acc.V2c")).unwrap();
    // R(62) = 5 ms; R(34) = 0.02 s is the raw recording's, not this file's.
    assert_eq!(raw.dt, Some(0.005));
    let bnz = channel(&raw, "BNZ");
    assert_eq!(bnz.values.len(), 42000);
    assert_eq!(bnz.values[0], 3.437285e-04);
    assert_eq!(*bnz.values.last().unwrap(), 2.412614e-04);
    assert!((peak(&bnz.values) - -6.851512).abs() < 5e-7, "{}", peak(&bnz.values));
    assert_eq!(meta(&raw, "process_level"), "V2");
    assert_eq!(meta(&raw, "channel.BNZ.orientation"), "up");
}

#[test]
fn csmip_v1_three_channels() {
    let raw = read_dmg(&record("dmg/CE89146.V1")).unwrap();
    assert_eq!(raw.dt, Some(0.005));
    assert_eq!(meta(&raw, "process_level"), "V1");
    assert_eq!(meta(&raw, "station"), "89146");
    assert_eq!(meta(&raw, "station_name"), "Willow Creek");
    for (name, orientation, stated) in [("chan1", "360", 0.079), ("chan2", "up", 0.021), ("chan3", "90", -0.045)] {
        let c = channel(&raw, name);
        assert_eq!((c.unit.as_str(), c.values.len()), ("g", 13200), "{name}");
        assert!((peak(&c.values) - stated).abs() <= 0.0005, "{name}: {}", peak(&c.values));
        assert_eq!(meta(&raw, &format!("channel.{name}.orientation")), orientation);
    }
    assert_eq!(channel(&raw, "chan1").values[..3], [0.000010, 0.000010, -0.000007]);
    assert_eq!(*channel(&raw, "chan3").values.last().unwrap(), 0.000136);
}

#[test]
fn csmip_v2_reads_acceleration_and_skips_velocity_and_displacement() {
    let raw = read_dmg(&record("dmg/CE89146.V2")).unwrap();
    assert_eq!(raw.dt, Some(0.005));
    assert_eq!(meta(&raw, "process_level"), "V2");
    assert_eq!(raw.channels.len(), 3);
    for (name, stated) in [("chan1", 77.280), ("chan2", 20.529), ("chan3", -44.200)] {
        let c = channel(&raw, name);
        assert_eq!((c.unit.as_str(), c.values.len()), ("cm/s^2", 12000), "{name}");
        // "Peak acceleration = 77.280" (3 decimals) of values written with 6.
        assert!((peak(&c.values) - stated).abs() <= 0.0005, "{name}: {}", peak(&c.values));
        assert_eq!(meta(&raw, &format!("channel.{name}.peak")), format!("{stated:.3}").trim_start_matches('0'));
    }
    assert_eq!(channel(&raw, "chan1").values[..3], [-0.000010, -0.000009, -0.000010]);
    assert_eq!(meta(&raw, "channel.chan1.peak_velocity"), "3.150");
}

#[test]
fn csmip_raw_channels_of_different_lengths() {
    let raw = read_dmg(&record("dmg/CIWLT.RAW")).unwrap();
    assert_eq!(raw.dt, Some(0.01));
    for (name, npts, orientation, stated) in
        [("chan1", 30130, "90", 0.086), ("chan2", 30058, "360", -0.119), ("chan3", 30312, "up", 0.075)]
    {
        let c = channel(&raw, name);
        assert_eq!(c.values.len(), npts, "{name}");
        assert!((peak(&c.values) - stated).abs() <= 0.0005, "{name}: {}", peak(&c.values));
        assert_eq!(meta(&raw, &format!("channel.{name}.orientation")), orientation);
    }
    assert_eq!(meta(&raw, "station"), "WLT");
}

#[test]
fn smc_first_and_last_samples_as_gmprocess_tests_them() {
    let raw = read_smc(&record("smc/0111a.smc")).unwrap();
    assert_eq!(raw.dt, Some(0.005));
    let c = channel(&raw, "360");
    assert_eq!(c.unit, "cm/s^2");
    assert_eq!(c.values.len(), 6001);
    // gmprocess's smc_test.py: first 1.5057E+0, last -2.8745E-1.
    assert_eq!(c.values[0], 1.5057);
    assert_eq!(c.values[1], -2.2223);
    assert_eq!(*c.values.last().unwrap(), -0.28745);
    assert!((peak(&c.values).abs() - 104.4).abs() <= 0.05, "{}", peak(&c.values));
    assert_eq!(meta(&raw, "process_level"), "V2");
    assert_eq!(meta(&raw, "channel.360.orientation"), "360");
    assert_eq!(meta(&raw, "station"), "SAF0");

    let raw = read_smc(&record("smc/2825.HNE.NP.--_u.smc")).unwrap();
    let c = channel(&raw, "90");
    assert_eq!(c.values.len(), 44800);
    assert!((peak(&c.values).abs() - 35.34).abs() <= 0.005, "{}", peak(&c.values));
    assert_eq!(meta(&raw, "process_level"), "V1");
    assert_eq!(meta(&raw, "channel.90.orientation"), "90");
}

/// K-NET's `Max. Acc.` is the peak after removing the record's mean.
fn demeaned_peak(values: &[f64]) -> f64 {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    values.iter().fold(0.0f64, |m, v| m.max((v - mean).abs()))
}

#[test]
fn knet_and_kiknet_scaled_to_gal() {
    for (file, name, npts, dt, stated, orientation) in [
        ("knet/AOM0051801241951.EW", "EW", 9500, 0.01, 29.070, "90"),
        ("knet/AOM0051801241951.NS", "NS", 9500, 0.01, 28.821, "0"),
        ("knet/AOM0051801241951.UD", "UD", 9500, 0.01, 11.817, "up"),
        ("knet/AICH040010061330.EW2", "EW", 28600, 0.005, 3.896, "90"),
        ("knet/AICH040010061330.NS2", "NS", 28600, 0.005, 5.605, "0"),
        ("knet/AICH040010061330.UD2", "UD", 28600, 0.005, 1.488, "up"),
    ] {
        let raw = read_knet(&record(file)).unwrap();
        assert_eq!(raw.dt, Some(dt), "{file}");
        let c = channel(&raw, name);
        assert_eq!((c.unit.as_str(), c.values.len()), ("gal", npts), "{file}");
        assert!((demeaned_peak(&c.values) - stated).abs() <= 0.0005, "{file}: {}", demeaned_peak(&c.values));
        assert_eq!(meta(&raw, &format!("channel.{name}.orientation")), orientation, "{file}");
    }
    let raw = read_knet(&record("knet/AOM0051801241951.EW")).unwrap();
    assert_eq!(raw.channels[0].values[0], -11657.0 * (7845.0 / 8223790.0));
    assert_eq!(meta(&raw, "station"), "AOM005");
    assert_eq!(meta(&raw, "network"), "K-NET");
    let raw = read_knet(&record("knet/AICH040010061330.NS2")).unwrap();
    assert_eq!((meta(&raw, "network"), meta(&raw, "sensor")), ("KiK-net", "surface"));
}

#[test]
fn esm_records_and_their_header_keys() {
    let raw = read_esm(&record("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC")).unwrap();
    assert_eq!(raw.dt, Some(0.005));
    let c = channel(&raw, "HNE");
    assert_eq!((c.unit.as_str(), c.values.len()), ("cm/s^2", 19128));
    assert_eq!(peak(&c.values).abs(), 0.300022);
    assert_eq!(meta(&raw, "station"), "ARS1");
    assert_eq!(meta(&raw, "network"), "HI");
    assert_eq!(meta(&raw, "channel.HNE.orientation"), "90");
    assert_eq!(c.first_data_line, Some(65));

    let raw = read_esm(&record("esm/20101114230825_3104_ap_RawAcc_E.asc")).unwrap();
    assert_eq!(raw.dt, Some(0.01));
    let c = channel(&raw, "HNE");
    assert_eq!(c.values.len(), 5600);
    assert_eq!(c.values[..2], [-0.001192, -0.008821]);
    assert!((peak(&c.values).abs() - 1.632).abs() <= 0.0005, "{}", peak(&c.values));
    assert_eq!(meta(&raw, "date_time_first_sample_yyyymmdd_hhmmss"), "14/11/2010 23:09:19.300");
}

#[test]
fn geonet_v2a_three_components_in_mm_per_s2() {
    let raw = read_geonet(&record("geonet/20180212_211557_WPWS_20.V2A")).unwrap();
    assert_eq!(raw.dt, Some(0.02));
    assert_eq!(meta(&raw, "process_level"), "V2");
    assert_eq!(meta(&raw, "station"), "WPWS");
    for (name, orientation, stated) in [("S16W", "196", -41.6), ("S74E", "106", -194.0), ("Up", "up", -27.3)] {
        let c = channel(&raw, name);
        assert_eq!((c.unit.as_str(), c.values.len()), ("mm/s^2", 5800), "{name}");
        assert!((peak(&c.values) - stated).abs() <= 0.05, "{name}: {}", peak(&c.values));
        assert_eq!(meta(&raw, &format!("channel.{name}.orientation")), orientation);
    }
}

#[test]
fn every_format_is_known_by_its_content() {
    let cases = [
        ("cosmos/NP1795-n.305.v0c", "cosmos"),
        ("cosmos/NCMDH--n.00725272.HNE.--.V1c", "cosmos"),
        ("cosmos/us1000hyfh_akbmrp_AKBMR--n.1000hyfh.BNZ.--.acc.V2c", "cosmos"),
        ("dmg/CE89146.V1", "dmg"),
        ("dmg/CE89146.V2", "dmg"),
        ("dmg/CIWLT.RAW", "dmg"),
        ("smc/0111a.smc", "smc"),
        ("smc/2825.HNE.NP.--_u.smc", "smc"),
        ("knet/AOM0051801241951.EW", "knet"),
        ("knet/AICH040010061330.UD2", "knet"),
        ("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC", "esm"),
        ("esm/20101114230825_3104_ap_RawAcc_E.asc", "esm"),
        ("geonet/20180212_211557_WPWS_20.V2A", "geonet"),
        ("nga/RSN10590_ComalTX11-10-20_IU.CCM.BH1.00.AT2", "at2"),
    ];
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    for (file, format) in cases {
        assert_eq!(sniff_format(&record(file)), Some(format), "{file}");
        // Renamed to a misleading extension, the content still decides.
        let dir = std::env::temp_dir().join(format!(
            "shakeflow-sniff-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let renamed = dir.join("record.v1");
        std::fs::copy(record(file), &renamed).unwrap();
        let sniffed = sniff_format(&renamed);
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(sniffed, Some(format), "{file} renamed .v1");
    }
    // RENADIC's first line is CSMIP Vol.1's: it stays RENADIC.
    let renadic = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/ground_motions/llolleo1002271.v1"));
    assert_eq!(sniff_format(renadic), Some("renadic_v1"));
}

#[test]
fn truncated_files_are_refused_with_their_line() {
    let cases: [(&str, Reader, usize); 6] = [
        ("cosmos/NCMDH--n.00725272.HNE.--.V1c", read_cosmos, 1000),
        ("dmg/CE89146.V2", read_dmg, 1000),
        ("smc/0111a.smc", read_smc, 300),
        ("knet/AOM0051801241951.EW", read_knet, 500),
        ("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC", read_esm, 5000),
        ("geonet/20180212_211557_WPWS_20.V2A", read_geonet, 500),
    ];
    for (file, read, keep) in cases {
        let err = damaged(file, |t| head(t, keep), read);
        assert!(err.line.is_some(), "{file}: {err}");
        assert!(err.message.contains("room for at most") || err.message.contains("ends after line"), "{file}: {err}");
        assert!(err.hint.contains("truncated"), "{file}: {err}");
    }
}

#[test]
fn wrong_counts_are_refused_before_allocating() {
    // A COSMOS data line announcing 99 999 999 999 values.
    let err = damaged(
        "cosmos/NCMDH--n.00725272.HNE.--.V1c",
        |t| t.replacen("   19200 acceleration pts", "99999999999 acceleration pts", 1),
        read_cosmos,
    );
    assert_eq!(err.line, Some(51), "{err}");
    assert!(err.message.contains("99999999999 data"), "{err}");
    // SMC: I(17) says one point fewer than the file holds.
    let err = damaged("smc/0111a.smc", |t| t.replacen("      6001    -32768", "      6000    -32768", 1), read_smc);
    assert_eq!(err.line, Some(786), "{err}");
    assert!(err.message.contains("more data after the 6000 values"), "{err}");
    // CSMIP: a channel announcing fewer points than it has.
    let err = damaged(
        "dmg/CE89146.V1",
        |t| t.replacen(" 13200 Accelerogram points", " 13000 Accelerogram points", 1),
        read_dmg,
    );
    assert_eq!(err.line, Some(28 + 1625 + 1), "{err}");
    assert!(err.message.contains("expected the end-of-channel line '/&' after 13000 values"), "{err}");
    // K-NET: a duration longer than the data.
    let err = damaged(
        "knet/AOM0051801241951.EW",
        |t| t.replacen("Duration Time(s)  95", "Duration Time(s)  96", 1),
        read_knet,
    );
    assert!(err.message.contains("inside count"), "{err}");
    // ESM: NDATA larger than the file can hold.
    let err = damaged(
        "esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC",
        |t| t.replacen("NDATA: 19128", "NDATA: 18446744073709551615", 1),
        read_esm,
    );
    assert_eq!(err.line, Some(30), "{err}");
    assert!(err.message.contains("room for at most"), "{err}");
    // GeoNet: an acceleration count one too small leaves the velocity block misaligned.
    let err = damaged(
        "geonet/20180212_211557_WPWS_20.V2A",
        |t| t.replacen("    5800    5800    5800", "    5799    5800    5800", 1),
        read_geonet,
    );
    assert!(err.line.is_some(), "{err}");
}

#[test]
fn wrong_units_are_refused_with_their_line() {
    let err = damaged(
        "esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC",
        |t| t.replacen("UNITS: cm/s^2", "UNITS: furlong/fortnight^2", 1),
        read_esm,
    );
    assert_eq!(err.line, Some(33), "{err}");
    assert!(err.message.contains("unknown ESM units 'furlong/fortnight^2'"), "{err}");
    let err = damaged(
        "dmg/CE89146.V1",
        |t| t.replace("in units of g .", "in units of furlongs").replace("are sec and g", "are sec and ?"),
        read_dmg,
    );
    assert_eq!(err.line, Some(28), "{err}");
    assert!(err.message.contains("cannot find the units"), "{err}");
    // A COSMOS unit code nobody defined leaves the unit unknown, for `load` to refuse with a hint.
    let raw = {
        let text = std::fs::read_to_string(record("cosmos/NCMDH--n.00725272.HNE.--.V1c")).unwrap();
        let edited = text.replacen("units=cm/sec2(04)", "units=furlong(99)", 1).replacen(
            "       1       1       4     120",
            "       1       1      99     120",
            1,
        );
        let dir = std::env::temp_dir().join(format!("shakeflow-cosmos-units-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.V1c");
        std::fs::write(&path, edited).unwrap();
        let raw = read_cosmos(&path);
        std::fs::remove_dir_all(&dir).unwrap();
        raw.unwrap()
    };
    assert_eq!(raw.channels[0].unit, "");
}

#[test]
fn garbage_in_a_fixed_width_block_is_located() {
    let err = damaged("smc/0111a.smc", |t| t.replacen("-2.2223E+0", "-2.2x23E+0", 1), read_smc);
    assert_eq!((err.line, err.column), (Some(36), Some(11)), "{err}");
    assert!(err.message.contains("value 2 of 6001"), "{err}");
    let err = damaged("knet/AOM0051801241951.EW", |t| t.replacen("-11655", "-11x55", 1), read_knet);
    assert_eq!((err.line, err.column), (Some(18), Some(12)), "{err}");
    let err = damaged(
        "knet/AOM0051801241951.EW",
        |t| t.replacen("Scale Factor      7845(gal)/8223790", "Scale Factor      7845(gal)/0", 1),
        read_knet,
    );
    assert_eq!(err.line, Some(14), "{err}");
}

/// A copy of a shared record edited by `edit`, read by `read`, which must succeed.
fn edited(name: &str, edit: impl Fn(&str) -> String, read: Reader) -> RawRecord {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let text = std::fs::read_to_string(record(name)).unwrap();
    let dir = std::env::temp_dir().join(format!(
        "shakeflow-variants-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(Path::new(name).file_name().unwrap());
    std::fs::write(&path, edit(&text)).unwrap();
    let result = read(&path);
    std::fs::remove_dir_all(&dir).unwrap();
    result.unwrap_or_else(|e| panic!("{e}"))
}

/// Layouts met in older files of the same formats (gmprocess's test data has them): a CSMIP
/// block line without a Fortran format (fields that may touch), a COSMOS channel ended by `/&`,
/// a DOS end-of-file (Ctrl-Z) after the last channel, and lower-case `g/10` units.
#[test]
fn older_layouts_of_the_same_formats() {
    let original = read_dmg(&record("dmg/CE89146.V2")).unwrap();
    let no_format = edited("dmg/CE89146.V2", |t| t.replace("in cm/sec2. (8f10.6)", "in cm/sec2.         "), read_dmg);
    assert_eq!(no_format.channels, original.channels);
    let ctrl_z = edited("dmg/CE89146.V1", |t| format!("{t}\u{1a}\r\n"), read_dmg);
    assert_eq!(ctrl_z.channels, read_dmg(&record("dmg/CE89146.V1")).unwrap().channels);
    let cosmos = edited(
        "cosmos/NCMDH--n.00725272.HNE.--.V1c",
        |t| t.replace("End-of-data for ChanHNE acceleration", "/&  ----------  End of data for channel  1  ----------"),
        read_cosmos,
    );
    assert_eq!(cosmos.channels, read_cosmos(&record("cosmos/NCMDH--n.00725272.HNE.--.V1c")).unwrap().channels);
    let tenth = edited(
        "dmg/CE89146.V1",
        |t| t.replace("in units of g .", "in units of g/10.").replace("are sec and g .", "are sec and g/10."),
        read_dmg,
    );
    assert!(tenth.channels.iter().all(|c| c.unit == "g/10"));
}

/// Older CSMIP Vol.1 (digitised film): no data line, (time, accel) pairs after 13 + 7 + 7 header
/// lines, times printed to 1 ms. Uniform within that resolution: the grid's step is the dt;
/// otherwise the time column goes to `load` (its `non_uniform` policy).
#[test]
fn csmip_time_value_pairs() {
    let block = |chan: &str, times: &[f64], values: &[f64]| {
        let mut text = String::from("UNCORRECTED ACCELEROGRAM DATA              PROCESSED: 07/16/98, CDMG 13160\n");
        for k in 1..13 {
            text += &match k {
                6 => format!("CHAN  {chan}\n"),
                10 => format!("NO. OF POINTS = {:6}  RECORD LENGTH = 59.998 SEC\n", times.len()),
                11 => "UNITS OF UNCOR ACCEL ARE SEC AND G/10.     MAX  =  -.055 G, AT  15.992 SEC.\n".to_string(),
                _ => format!("TEXT LINE {k}\n"),
            };
        }
        text += &"    0    0    0    0    0    0    0    0    0    0    0    0    0    0    0    0\n".repeat(7);
        text += &"      .000      .000      .000      .000      .000      .000      .000      .000\n".repeat(7);
        for pairs in times.iter().zip(values).collect::<Vec<_>>().chunks(5) {
            text += &pairs.iter().map(|(t, v)| format!("{t:7.3}{v:7.3}")).collect::<String>();
            text += "\n";
        }
        text + "/&  ----------  END OF DATA FOR CHANNEL  1  ----------\n"
    };
    let dir = std::env::temp_dir().join(format!("shakeflow-pairs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("old.raw");
    // 12 samples at 4.967 ms, printed to 1 ms: uniform within the print resolution.
    let times: Vec<f64> = (0..12).map(|k| (k as f64 * 0.004967 * 1000.0).round() / 1000.0).collect();
    // Exact 3-decimal values: (k - 5) / 1000 rounds as the printed decimal parses.
    let values: Vec<f64> = (0..12).map(|k| (k as f64 - 5.0) / 1000.0).collect();
    std::fs::write(&path, block("1:  90 DEG", &times, &values) + &block("2: UP", &times, &values)).unwrap();
    let raw = read_dmg(&path).unwrap();
    assert_eq!(raw.dt, Some((times[11] - times[0]) / 11.0));
    assert_eq!(raw.time, None);
    assert_eq!(channel(&raw, "chan1").values, values);
    assert_eq!(channel(&raw, "chan1").unit, "g/10");
    assert_eq!(meta(&raw, "channel.chan2.orientation"), "up");
    // A jittered time column is kept whole, for `load` to refuse or resample.
    let mut jittered = times.clone();
    jittered[6] += 0.003;
    std::fs::write(&path, block("1:  90 DEG", &jittered, &values) + &block("2: UP", &jittered, &values)).unwrap();
    let raw = read_dmg(&path).unwrap();
    assert_eq!((raw.dt, raw.time.as_deref()), (None, Some(&jittered[..])));
    // Channels with their own jittered times cannot share one table.
    std::fs::write(&path, block("1:  90 DEG", &jittered, &values) + &block("2: UP", &times, &values)).unwrap();
    let err = read_dmg(&path).unwrap_err();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(err.message.contains("time column differs from the first channel's"), "{err}");
}

/// Deterministic damage to every shared file of these formats (cuts, deleted and duplicated
/// lines, digit runs such as 99999999999, replaced bytes): every reader returns a record or a
/// located error, never a panic.
#[test]
fn damaged_files_never_panic() {
    use crate::signal::synthetic_motion::SplitMix64;
    let files: [(&str, Reader); 17] = [
        ("cosmos/NP1795-n.305.v0c", read_cosmos),
        ("cosmos/NCMDH--n.00725272.HNE.--.V1c", read_cosmos),
        ("cosmos/us1000hyfh_akbmrp_AKBMR--n.1000hyfh.BNZ.--.acc.V2c", read_cosmos),
        ("dmg/CE89146.V1", read_dmg),
        ("dmg/CE89146.V2", read_dmg),
        ("dmg/CIWLT.RAW", read_dmg),
        ("smc/0111a.smc", read_smc),
        ("smc/2825.HNE.NP.--_u.smc", read_smc),
        ("knet/AOM0051801241951.EW", read_knet),
        ("knet/AICH040010061330.UD2", read_knet),
        ("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC", read_esm),
        ("esm/20101114230825_3104_ap_RawAcc_E.asc", read_esm),
        ("geonet/20180212_211557_WPWS_20.V2A", read_geonet),
        // Each reader on another format's file too.
        ("geonet/20180212_211557_WPWS_20.V2A", read_dmg),
        ("dmg/CE89146.V2", read_cosmos),
        ("cosmos/NP1795-n.305.v0c", read_geonet),
        ("smc/0111a.smc", read_knet),
    ];
    let dir = std::env::temp_dir().join(format!("shakeflow-mutations-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut rng = SplitMix64::new(20261125);
    for (name, read) in files {
        let original = std::fs::read(record(name)).unwrap();
        // Mutations near the headers find more: most of them hit the first 8 KB.
        let head = original.len().min(8192);
        for round in 0..24 {
            let mut bytes = original.clone();
            let at =
                if round % 3 == 0 { rng.next_u64() as usize % bytes.len() } else { rng.next_u64() as usize % head };
            match round % 6 {
                0 => bytes.truncate(at),
                1 => bytes.splice(at..at, b"99999999999".iter().copied()).for_each(drop),
                2 => bytes[at] = b"-.E+ x9\n\t0"[rng.next_u64() as usize % 10],
                3 => {
                    let end = (at + 1 + rng.next_u64() as usize % 400).min(bytes.len());
                    bytes.drain(at..end);
                }
                4 => {
                    let end = (at + 1 + rng.next_u64() as usize % 400).min(bytes.len());
                    let copy = bytes[at..end].to_vec();
                    bytes.splice(at..at, copy).for_each(drop);
                }
                _ => bytes.splice(at..at, [0xFFu8, 0x1A, b'-', b'-']).for_each(drop),
            }
            let path = dir.join("mutated");
            std::fs::write(&path, &bytes).unwrap();
            let outcome = std::panic::catch_unwind(|| read(&path));
            assert!(outcome.is_ok(), "{name}, mutation {round} at byte {at}: the reader panicked");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A reader's two modes: values parsed (`load`) and values counted (`validate`).
type Modes = (fn(&Path, &[u8]) -> Result<RawRecord, ParseError>, fn(&Path, &[u8]) -> Result<(), ParseError>);

/// `validate`'s count of a record's values agrees with its reader: every shared record passes
/// whole, and a copy cut short anywhere is refused by both at the same line.
#[test]
fn counting_refuses_truncated_copies_at_the_line_parsing_does() {
    let modes = |folder: &str| -> Modes {
        match folder {
            "nga" => (parse_at2, super::at2::count_at2),
            "cosmos" => (parse_cosmos, super::cosmos::count_cosmos),
            "dmg" => (parse_dmg, super::dmg::count_dmg),
            "smc" => (parse_smc, super::smc::count_smc),
            "knet" => (parse_knet, super::knet::count_knet),
            "esm" => (parse_esm, super::esm::count_esm),
            "geonet" => (parse_geonet, super::geonet::count_geonet),
            other => panic!("no reader for the shared folder {other}"),
        }
    };
    record("SOURCES.md");
    let mut files = 0;
    for folder in ["nga", "cosmos", "dmg", "smc", "knet", "esm", "geonet"] {
        let (parse, count) = modes(folder);
        for entry in std::fs::read_dir(Path::new(RECORDS_DIR).join(folder)).unwrap() {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            count(&path, &bytes).unwrap_or_else(|e| panic!("the whole file is refused: {e}"));
            files += 1;
            for percent in [5, 30, 50, 77, 90, 99] {
                let cut = &bytes[..bytes.len() * percent / 100];
                let parsed = parse(&path, cut).err().map(|e| e.line);
                let counted = count(&path, cut).err().map(|e| e.line);
                assert_eq!(counted, parsed, "{} cut to {percent} %", path.display());
                assert!(counted.is_some() || percent == 99, "{} cut to {percent} % passes", path.display());
            }
        }
    }
    assert_eq!(files, 18);
}
