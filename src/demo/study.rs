//! Tables 1-3 of the seed paper (UCSD BNCS five-story building test, NEES-2009-0722, 2012).

/// Base condition of the building during a test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Base {
    /// Base-isolated ("BI").
    Isolated,
    /// Fixed-base ("FB").
    Fixed,
}

impl Base {
    pub fn code(self) -> &'static str {
        match self {
            Base::Isolated => "BI",
            Base::Fixed => "FB",
        }
    }
}

/// One row of Table 1 (earthquake motion tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    pub id: &'static str,
    /// Input name as used in the test log, e.g. "ICA100".
    pub input: &'static str,
    /// Record name without the scale, e.g. "ICA".
    pub record: &'static str,
    pub event_site: &'static str,
    pub scale_percent: f64,
    /// Achieved peak input acceleration on the table (g).
    pub pia_g: f64,
    /// Achieved peak input velocity (cm/s).
    pub piv_cm_s: f64,
    /// Achieved peak input displacement (cm).
    pub pid_cm: f64,
    pub base: Base,
}

const CNP: &str = "1994 Northridge-Canoga Park";
const LAC: &str = "1994 Northridge-LA City Terrace";
const SP: &str = "2010 Maule (Chile)-San Pedro";
const ICA: &str = "2007 Pisco (Peru)-Ica";
const DEN: &str = "2002 Denali-TAPS Pump St. #9";

/// Table 1, in test order.
pub const MOTIONS: [Motion; 12] = [
    Motion {
        id: "BI-1",
        input: "CNP100",
        record: "CNP",
        event_site: CNP,
        scale_percent: 100.0,
        pia_g: 0.21,
        piv_cm_s: 23.37,
        pid_cm: 8.42,
        base: Base::Isolated,
    },
    Motion {
        id: "BI-2",
        input: "LAC100",
        record: "LAC",
        event_site: LAC,
        scale_percent: 100.0,
        pia_g: 0.25,
        piv_cm_s: 24.48,
        pid_cm: 8.95,
        base: Base::Isolated,
    },
    Motion {
        id: "BI-3",
        input: "SP100",
        record: "SP",
        event_site: SP,
        scale_percent: 100.0,
        pia_g: 0.52,
        piv_cm_s: 34.87,
        pid_cm: 8.27,
        base: Base::Isolated,
    },
    Motion {
        id: "BI-4",
        input: "ICA50",
        record: "ICA",
        event_site: ICA,
        scale_percent: 50.0,
        pia_g: 0.17,
        piv_cm_s: 22.32,
        pid_cm: 4.76,
        base: Base::Isolated,
    },
    Motion {
        id: "BI-5",
        input: "ICA100",
        record: "ICA",
        event_site: ICA,
        scale_percent: 100.0,
        pia_g: 0.32,
        piv_cm_s: 42.59,
        pid_cm: 9.46,
        base: Base::Isolated,
    },
    Motion {
        id: "BI-6",
        input: "ICA140",
        record: "ICA",
        event_site: ICA,
        scale_percent: 140.0,
        pia_g: 0.50,
        piv_cm_s: 62.59,
        pid_cm: 12.92,
        base: Base::Isolated,
    },
    Motion {
        id: "FB-1",
        input: "CNP100",
        record: "CNP",
        event_site: CNP,
        scale_percent: 100.0,
        pia_g: 0.21,
        piv_cm_s: 23.50,
        pid_cm: 8.78,
        base: Base::Fixed,
    },
    Motion {
        id: "FB-2",
        input: "LAC100",
        record: "LAC",
        event_site: LAC,
        scale_percent: 100.0,
        pia_g: 0.18,
        piv_cm_s: 23.05,
        pid_cm: 9.31,
        base: Base::Fixed,
    },
    Motion {
        id: "FB-3",
        input: "ICA50",
        record: "ICA",
        event_site: ICA,
        scale_percent: 50.0,
        pia_g: 0.21,
        piv_cm_s: 26.22,
        pid_cm: 5.83,
        base: Base::Fixed,
    },
    Motion {
        id: "FB-4",
        input: "ICA100",
        record: "ICA",
        event_site: ICA,
        scale_percent: 100.0,
        pia_g: 0.26,
        piv_cm_s: 28.49,
        pid_cm: 7.32,
        base: Base::Fixed,
    },
    Motion {
        id: "FB-5",
        input: "DEN67",
        record: "DEN",
        event_site: DEN,
        scale_percent: 67.0,
        pia_g: 0.64,
        piv_cm_s: 63.74,
        pid_cm: 20.06,
        base: Base::Fixed,
    },
    Motion {
        id: "FB-6",
        input: "DEN100",
        record: "DEN",
        event_site: DEN,
        scale_percent: 100.0,
        pia_g: 0.80,
        piv_cm_s: 83.57,
        pid_cm: 33.62,
        base: Base::Fixed,
    },
];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Support {
    Locked,
    Unlocked,
    FreeStanding,
}

impl Support {
    pub fn label(self) -> &'static str {
        match self {
            Support::Locked => "locked",
            Support::Unlocked => "unlocked",
            Support::FreeStanding => "free standing",
        }
    }
}

/// One row of Table 2 (equipment), with the Table 3 frequencies attached.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Equipment {
    pub id: &'static str,
    pub description: &'static str,
    pub floor: u8,
    pub support: Support,
    pub width_m: f64,
    pub length_m: f64,
    pub height_m: f64,
    pub weight_kg: f64,
    /// Table 3: identified fundamental frequency before FB-1 (double pulse + white noise).
    pub freq_before_fb1_hz: f64,
    /// Table 3: identified fundamental frequency before FB-6 (white noise).
    pub freq_before_fb6_hz: f64,
}

/// Which Table 3 column applies to a test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrequencySet {
    BeforeFb1,
    BeforeFb6,
}

impl FrequencySet {
    pub fn label(self) -> &'static str {
        match self {
            FrequencySet::BeforeFb1 => "before FB-1",
            FrequencySet::BeforeFb6 => "before FB-6",
        }
    }
}

impl Equipment {
    pub fn frequency_hz(&self, set: FrequencySet) -> f64 {
        match set {
            FrequencySet::BeforeFb1 => self.freq_before_fb1_hz,
            FrequencySet::BeforeFb6 => self.freq_before_fb6_hz,
        }
    }
}

/// Tables 2 and 3, in DAQ2 column order (floor 4 then floor 5).
pub const EQUIPMENT: [Equipment; 7] = [
    Equipment {
        id: "UI3",
        description: "ultrasound imaging unit",
        floor: 4,
        support: Support::Unlocked,
        width_m: 0.55,
        length_m: 0.70,
        height_m: 1.47,
        weight_kg: 180.0,
        freq_before_fb1_hz: 3.90,
        freq_before_fb6_hz: 3.03,
    },
    Equipment {
        id: "MC2",
        description: "metal cart",
        floor: 4,
        support: Support::Unlocked,
        width_m: 0.90,
        length_m: 0.65,
        height_m: 2.03,
        weight_kg: 118.0,
        freq_before_fb1_hz: 3.50,
        freq_before_fb6_hz: 2.70,
    },
    Equipment {
        id: "PB1",
        description: "patient bed",
        floor: 4,
        support: Support::Locked,
        width_m: 1.05,
        length_m: 2.36,
        height_m: 0.76,
        weight_kg: 259.0,
        freq_before_fb1_hz: 3.10,
        freq_before_fb6_hz: 2.90,
    },
    Equipment {
        id: "PB2",
        description: "patient bed",
        floor: 4,
        support: Support::Unlocked,
        width_m: 1.05,
        length_m: 2.36,
        height_m: 0.76,
        weight_kg: 259.0,
        freq_before_fb1_hz: 3.60,
        freq_before_fb6_hz: 2.40,
    },
    Equipment {
        id: "PS1",
        description: "stretcher",
        floor: 5,
        support: Support::Unlocked,
        width_m: 1.00,
        length_m: 2.20,
        height_m: 0.76,
        weight_kg: 150.0,
        freq_before_fb1_hz: 3.26,
        freq_before_fb6_hz: 3.62,
    },
    Equipment {
        id: "PS2",
        description: "stretcher",
        floor: 5,
        support: Support::Locked,
        width_m: 1.00,
        length_m: 2.20,
        height_m: 0.76,
        weight_kg: 150.0,
        freq_before_fb1_hz: 2.90,
        freq_before_fb6_hz: 2.70,
    },
    Equipment {
        id: "WSU1",
        description: "wire shelving unit",
        floor: 5,
        support: Support::FreeStanding,
        width_m: 0.66,
        length_m: 1.22,
        height_m: 1.88,
        weight_kg: 43.6,
        freq_before_fb1_hz: 3.20,
        freq_before_fb6_hz: 3.00,
    },
];

pub fn motion_by_id(id: &str) -> Option<&'static Motion> {
    MOTIONS.iter().find(|m| m.id == id)
}

pub fn equipment_by_id(id: &str) -> Option<&'static Equipment> {
    EQUIPMENT.iter().find(|e| e.id == id)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_consistent() {
        assert_eq!(MOTIONS.iter().filter(|m| m.base == Base::Isolated).count(), 6);
        for m in &MOTIONS {
            assert!(m.id.starts_with(m.base.code()));
            assert_eq!(m.input, format!("{}{}", m.record, m.scale_percent as u32));
        }
        assert_eq!(motion_by_id("FB-4").unwrap().pia_g, 0.26);
        assert_eq!(equipment_by_id("PS2").unwrap().frequency_hz(FrequencySet::BeforeFb6), 2.70);
        assert_eq!(EQUIPMENT.iter().filter(|e| e.floor == 4).count(), 4);
    }
}
