//! Unit names accepted in pipeline files and their conversion to SI.

/// Standard gravity (CGPM 1901), the factor every accelerogram in g is converted with.
pub const G0: f64 = 9.806_65;

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
    ("m/s", "m/s", 1.0),
    ("cm/s", "m/s", 1e-2),
    ("mm/s", "m/s", 1e-3),
    ("m", "m", 1.0),
    ("cm", "m", 1e-2),
    ("mm", "m", 1e-3),
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

pub fn known_units() -> Vec<&'static str> {
    UNITS.iter().map(|(name, _, _)| *name).collect()
}

fn normalise(unit: &str) -> String {
    unit.trim().to_ascii_lowercase().replace("^", "").replace("sec", "s")
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
}
