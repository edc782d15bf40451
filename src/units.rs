//! Unit names accepted in pipeline files and their conversion to SI.

/// Standard gravity (CGPM 1901), the factor every accelerogram in g is converted with.
pub const G0: f64 = 9.806_65;

/// The international inch (1959), exactly.
pub const INCH: f64 = 0.0254;
/// The international foot, exactly 12 in.
pub const FOOT: f64 = 0.3048;

/// A unit the loader accepts: the SI unit it converts to and the factor to get there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitConversion {
    pub si_unit: &'static str,
    pub factor: f64,
}

const UNITS: &[(&str, &str, f64)] = &[
    ("g", "m/s^2", G0),
    ("g/10", "m/s^2", G0 / 10.0),
    ("mg", "m/s^2", G0 * 1e-3),
    ("m/s^2", "m/s^2", 1.0),
    ("cm/s^2", "m/s^2", 1e-2),
    ("gal", "m/s^2", 1e-2),
    ("mm/s^2", "m/s^2", 1e-3),
    ("in/s^2", "m/s^2", INCH),
    ("ft/s^2", "m/s^2", FOOT),
    // g as 386.4 in/s² (= 9.81456 m/s², correctly rounded), for the US files that define it so.
    ("g386", "m/s^2", 9.81456),
    ("m/s", "m/s", 1.0),
    ("cm/s", "m/s", 1e-2),
    ("mm/s", "m/s", 1e-3),
    ("in/s", "m/s", INCH),
    ("ft/s", "m/s", FOOT),
    ("m", "m", 1.0),
    ("cm", "m", 1e-2),
    ("mm", "m", 1e-3),
    ("in", "m", INCH),
    ("ft", "m", FOOT),
    ("s", "s", 1.0),
    ("ms", "s", 1e-3),
    ("rad", "rad", 1.0),
    ("deg", "rad", std::f64::consts::PI / 180.0),
    ("1", "", 1.0),
];

/// Looks a unit up by its name as written in a pipeline (case-insensitive, `m/s2` = `m/s^2`).
pub fn conversion(unit: &str) -> Option<UnitConversion> {
    let wanted = normalise(unit);
    UNITS
        .iter()
        .find(|(name, _, _)| normalise(name) == wanted)
        .map(|&(_, si_unit, factor)| UnitConversion { si_unit, factor })
}

/// Units of raw DAQ data (volts, counts): not physical quantities, they need a per-channel
/// calibration (sensitivity and offset) before they mean anything.
const RAW_UNITS: &[&str] = &["V", "volts", "volt", "mV", "counts", "count"];

/// The raw unit `unit` names (`Volts` → `V`, `mV`, `counts`), or None for any other name.
pub fn raw_unit(unit: &str) -> Option<&'static str> {
    let wanted = normalise(unit);
    RAW_UNITS.iter().find(|name| normalise(name) == wanted).map(|name| match *name {
        "volts" | "volt" => "V",
        "count" => "counts",
        other => other,
    })
}

pub fn known_units() -> Vec<&'static str> {
    UNITS.iter().map(|(name, _, _)| *name).collect()
}

fn normalise(unit: &str) -> String {
    unit.trim().to_ascii_lowercase().replace("^", "").replace("sec", "s").replace("/s/s", "/s2")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn g_converts_with_standard_gravity() {
        let c = conversion("G").unwrap();
        assert_eq!(c.si_unit, "m/s^2");
        assert_eq!(c.factor, 9.80665);
        assert!((conversion("g/10").unwrap().factor - 0.980665).abs() < 1e-15);
        assert_eq!(conversion("cm/s2").unwrap().factor, 0.01);
        assert!(conversion("furlong").is_none());
    }

    #[test]
    fn raw_units_are_recognised_but_not_converted() {
        assert_eq!(raw_unit("Volts"), Some("V"));
        assert_eq!(raw_unit("mv"), Some("mV"));
        assert_eq!(raw_unit(" Counts "), Some("counts"));
        assert_eq!(raw_unit("g"), None);
        assert!(conversion("V").is_none());
    }

    /// The US customary and CGS factors are exact by definition (NIST SP 811 B.8/B.9: 1 in =
    /// 0.0254 m, 1 ft = 0.3048 m, gal = 1 cm/s², g0 = 9.80665 m/s²): each stored factor is the
    /// double nearest the exact decimal, compared to the last bit with the literal.
    #[test]
    fn us_customary_and_cgs_factors_are_nist_exact() {
        let bits = |unit: &str| conversion(unit).unwrap_or_else(|| panic!("{unit} unknown")).factor.to_bits();
        for (unit, exact) in [
            ("in/s^2", 0.0254),
            ("in/s2", 0.0254),
            ("in/sec/sec", 0.0254),
            ("in/s", 0.0254),
            ("in", 0.0254),
            ("ft/s^2", 0.3048),
            ("ft/s", 0.3048),
            ("ft", 0.3048),
            ("gal", 0.01),
            ("cm/s^2", 0.01),
            ("cm/s", 0.01),
            ("cm", 0.01),
            ("mm", 0.001),
            ("g", 9.80665),
            ("g386", 9.81456),
        ] {
            assert_eq!(bits(unit), f64::to_bits(exact), "{unit}");
        }
        // 386.4 in/s² is 9.81456 m/s² exactly; the product of the two doubles is not (1 ulp off).
        assert_ne!(bits("g386"), (386.4 * INCH).to_bits());
        assert_eq!(conversion("in/s^2").unwrap().si_unit, "m/s^2");
        assert_eq!(conversion("ft").unwrap().si_unit, "m");
    }
}
