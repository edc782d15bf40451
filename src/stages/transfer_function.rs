//! `transfer_function`: floor → equipment transfer functions (Welch H1, H2, coherence, as
//! MATLAB `tfestimate` computes them) and the fundamental frequency picked from |H1| with a
//! half-power damping estimate, like Table 3 of the study.

use super::error::{float_column, StageError};
use rayon::prelude::*;

use super::{split_pair, Stage, StageContext};
use crate::pipeline::params;
use crate::signal::welch::{identify_peak, transfer_function, Detrend, WelchOptions, Window};
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters of `transfer_function`.
    pub struct TransferFunctionParams {
        // `input -> output`, read by `split_pair`.
        /// input -> output column pairs, e.g. `floor4_ax_mps2 -> PB1_top_ax_mps2`
        pub pairs: Vec<String> [],
        /// lower end of the band searched for the peak
        pub band_min_hz: f64 [default = 1.0, unit = "Hz", range = (0.0, 1e6)],
        /// upper end of the band searched for the peak
        pub band_max_hz: f64 [default = 20.0, unit = "Hz", range = (0.0, 1e6)],
        /// segment window (hamming: MATLAB's symmetric hamming(L); hann: scipy's periodic hann)
        pub window: WindowChoice [default = "hamming"],
        /// segment length; null: MATLAB's default of 8 segments with 50 % overlap
        pub segment_s: Option<f64> [default = null, unit = "s", range = (0.0, 1e6)],
        /// segment overlap as a fraction (with segment_s)
        pub overlap: f64 [default = 0.5, range = (0.0, 0.95)],
        /// per-segment detrending (MATLAB tfestimate: none)
        pub detrend: DetrendChoice [default = "none"],
        /// peaks with lower coherence are flagged low_coherence
        pub coherence_threshold: f64 [default = 0.5, range = (0.0, 1.0)],
    }
}

crate::choice! {
    /// `window`: the segment window.
    pub enum WindowChoice { Hamming = "hamming", Hann = "hann", Boxcar = "boxcar" }
}

crate::choice! {
    /// `detrend`: per-segment detrending.
    pub enum DetrendChoice { None = "none", Constant = "constant", Linear = "linear" }
}

super::declare_stage! {
    /// Welch transfer functions H1, H2 and coherence (MATLAB tfestimate defaults) and the identified fundamental
    /// frequency with half-power damping.
    pub struct TransferFunction: "transfer_function", version 2, reads Datasets, params TransferFunctionParams;
    outputs {
        /// per pair: frequency_hz, damping_ratio, peak_gain, coherence, low_coherence, note
        "identified": Table => Frequencies,
        /// per pair and frequency: |H1|, phase, |H2|, coherence
        "spectra": Table => Spectra,
    }
    examples {
        /// a fixed-base frame's fundamental frequency (1.0 Hz) from its ground record and its 4th floor's response; the
        /// floor record starts 1.31 s into the ground record
        GROUND_AND_FLOOR => "\
synchronize:
  type: synchronize
  inputs: [load_floor, load_ground]
  params:
    target_channel: ax_mps2
    join: case
    known_lag_s: -1.31
transfer_function:
  type: transfer_function
  inputs: [synchronize]
  params:
    pairs: [ax_mps2 -> floor4_ax_mps2]
    band_min_hz: 0.5
    band_max_hz: 3.0
    segment_s: 8.0
",
    }
}

/// The shared case demo_03: a 4th floor's record and the ground record it was made from.
const GROUND_AND_FLOOR: super::ExampleData = super::ExampleData {
    what: "the shared case demo_03 and its ground record",
    head: "\
inputs:
  ground:
    description: Northridge 1994, Sylmar Converter Station (PEER NGA-West2 RSN1084), the motion under case demo_03
    format: at2
    path: ../shared/data/ground_motions/RSN1084_NORTHR_SCS052.AT2
    partition: {case: demo_03}
  floor:
    description: the 4th floor of a fixed-base frame (period 1.0 s, 5 % damping) under it, 200 Hz
    format: csv
    path: ../shared/cases/demo/demo_03/floor.csv
    partition: {case: demo_03, floor: \"4\"}
    time_column: time_s
    columns:
      ax_mps2: {column: ax_mps2, unit: m/s^2}
stages:
  load_ground:
    type: load
    inputs: [ground]
  load_floor:
    type: load
    inputs: [floor]
",
};

impl Stage for TransferFunction {
    super::info_and_check_params!(TransferFunctionParams);

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::EachRecord
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: TransferFunctionParams = params::typed(ctx.params)?;
        let pairs: Vec<(String, String)> = p
            .pairs
            .iter()
            .map(|p| match split_pair(p) {
                (input, Some(output)) => Ok((input, output)),
                _ => Err(anyhow::anyhow!("pair `{p}` must look like `input_column -> output_column`")),
            })
            .collect::<anyhow::Result<_>>()?;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        parts.par_iter().try_for_each(|part| {
            let table = ctx.read_table(part)?;
            let (mut identified, mut spectra) =
                analyse(&table, &pairs, &p).map_err(|e| anyhow::anyhow!("{}: {e}", part.label))?;
            identified.metadata.extend(super::record_provenance(part));
            spectra.metadata.extend(super::record_provenance(part));
            ctx.sink.write("spectra", &part.partition, spectra)?;
            ctx.sink.write("identified", &part.partition, identified)
        })
    }
}

fn options(p: &TransferFunctionParams, n: usize, fs: f64) -> Result<WelchOptions, StageError> {
    let window = match p.window {
        WindowChoice::Hamming => Window::HammingSymmetric,
        WindowChoice::Hann => Window::Hann,
        WindowChoice::Boxcar => Window::Boxcar,
    };
    let detrend = match p.detrend {
        DetrendChoice::None => Detrend::None,
        DetrendChoice::Constant => Detrend::Constant,
        DetrendChoice::Linear => Detrend::Linear,
    };
    let mut opts = match p.segment_s {
        None => WelchOptions::matlab_default(n),
        Some(seconds) => {
            let segment_len = (seconds * fs).round() as usize;
            if segment_len < 8 || segment_len > n {
                return Err(StageError::Record(format!(
                    "segment_s = {seconds} s gives {segment_len} samples; the record has {n}"
                )));
            }
            let overlap = ((p.overlap * segment_len as f64).floor() as usize).min(segment_len - 1);
            WelchOptions { window, segment_len, overlap, detrend, nfft: None }
        }
    };
    opts.window = window;
    opts.detrend = detrend;
    Ok(opts)
}

fn analyse(
    table: &Table,
    pairs: &[(String, String)],
    p: &TransferFunctionParams,
) -> Result<(Table, Table), StageError> {
    let time = table.f64_column(TIME_COLUMN).ok_or_else(|| StageError::Record("no time_s column".into()))?;
    let n = time.len();
    if n < 16 {
        return Err(StageError::Record(format!("{n} samples are too few for a transfer function")));
    }
    let fs = crate::table::sample_rate(time);
    let opts = options(p, n, fs)?;
    let band = (p.band_min_hz, p.band_max_hz);
    let column = |name: &str| float_column(table, name);
    let (mut outputs, mut inputs, mut freq, mut damping, mut gain, mut coh, mut low, mut notes) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut s_out, mut s_freq, mut s_h1, mut s_phase, mut s_h2, mut s_coh) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    for (input, output) in pairs {
        let tf = transfer_function(column(input)?, column(output)?, fs, &opts)
            .map_err(|e| StageError::Record(format!("{input} -> {output}: {e}")))?;
        for (k, &f) in tf.freqs_hz.iter().enumerate() {
            s_out.push(output.clone());
            s_freq.push(f);
            s_h1.push(tf.h1[k].norm());
            s_phase.push(tf.h1[k].arg());
            s_h2.push(tf.h2[k].norm());
            s_coh.push(tf.coherence[k]);
        }
        let peak = identify_peak(&tf, band, p.coherence_threshold);
        outputs.push(output.clone());
        inputs.push(input.clone());
        match peak {
            Some(p) => {
                freq.push(Some(p.frequency_hz));
                damping.push(p.damping_ratio);
                gain.push(Some(p.peak_gain));
                coh.push(Some(p.coherence));
                low.push(p.low_coherence);
                notes.push(match (p.low_coherence, p.damping_ratio) {
                    (true, _) => format!("low coherence ({:.2}) at the peak: the output is not mainly driven by the input there; treat the frequency with care", p.coherence),
                    (false, None) => "peak at the band edge or half-power points outside the band: no damping estimate".to_string(),
                    (false, Some(_)) => String::new(),
                });
            }
            None => {
                freq.push(None);
                damping.push(None);
                gain.push(None);
                coh.push(None);
                low.push(true);
                notes.push(format!("no peak found in {:.2}-{:.2} Hz", band.0, band.1));
            }
        }
    }
    let opt = |name: &str, unit: &str, description: &str, v: Vec<Option<f64>>| Column {
        name: name.into(),
        unit: unit.into(),
        description: description.into(),
        data: ColumnData::OptF64(v),
    };
    let mut identified = Table::new();
    identified.push(super::text_column("output", "output (response) channel", outputs));
    identified.push(super::text_column("input", "input (excitation) channel", inputs));
    identified.push(opt(
        "frequency_hz",
        "Hz",
        "fundamental frequency: peak of |H1| in the band (least-squares refined)",
        freq,
    ));
    identified.push(opt("damping_ratio", "", "half-power bandwidth damping estimate", damping));
    identified.push(opt("peak_gain", "", "|H1| at the peak", gain));
    identified.push(opt("coherence", "", "magnitude-squared coherence at the peak", coh));
    identified.push(Column {
        name: "low_coherence".into(),
        unit: String::new(),
        description: "coherence at the peak below the threshold".into(),
        data: ColumnData::Bool(low),
    });
    identified.push(super::text_column("note", "confidence note for a test engineer", notes));
    let mut spectra = Table::new();
    spectra.push(super::text_column("output", "output (response) channel", s_out));
    spectra.push(Column::f64("frequency_hz", "Hz", "frequency", s_freq));
    spectra.push(Column::f64("h1_gain", "", "|H1| = |Pxy/Pxx|", s_h1));
    spectra.push(Column::f64("h1_phase_rad", "rad", "phase of H1", s_phase));
    spectra.push(Column::f64("h2_gain", "", "|H2| = |Pyy/Pyx|", s_h2));
    spectra.push(Column::f64("coherence", "", "magnitude-squared coherence", s_coh));
    let welch = serde_json::json!({"window": p.window, "segment_len": opts.segment_len, "overlap": opts.overlap, "nfft": opts.nfft(), "detrend": p.detrend, "fs_hz": fs});
    identified.metadata.insert("shakeflow.welch".into(), welch.to_string());
    spectra.metadata.insert("shakeflow.welch".into(), welch.to_string());
    Ok((identified, spectra))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::test_support::Rng;
    use std::f64::consts::PI;

    const FS: f64 = 100.0;
    /// The resonator y[k] = x[k] + 2r cos(ω0) y[k-1] − r² y[k-2]: poles r·e^(±iω0).
    const R: f64 = 0.98;
    const F0: f64 = 5.0;

    /// |H(e^(iω))| of the resonator, its closed form.
    fn gain(omega: f64) -> f64 {
        let w0 = 2.0 * PI * F0 / FS;
        let re = 1.0 - 2.0 * R * w0.cos() * omega.cos() + R * R * (2.0 * omega).cos();
        let im = 2.0 * R * w0.cos() * omega.sin() - R * R * (2.0 * omega).sin();
        1.0 / re.hypot(im)
    }

    #[test]
    fn a_resonators_peak_frequency_gain_and_damping_are_its_closed_forms() {
        let w0 = 2.0 * PI * F0 / FS;
        let n = (800.0 * FS) as usize;
        let mut rng = Rng::new(37);
        let x: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let mut y = vec![0.0; n];
        for k in 0..n {
            let back = |j: usize| if k >= j { y[k - j] } else { 0.0 };
            let next = x[k] + 2.0 * R * w0.cos() * back(1) - R * R * back(2);
            y[k] = next;
        }
        let mut table = Table::new();
        table.push(Column::f64(TIME_COLUMN, "s", "", (0..n).map(|k| k as f64 / FS).collect()));
        table.push(Column::f64("x", "", "", x));
        table.push(Column::f64("y", "", "", y));
        let p = TransferFunctionParams {
            pairs: vec!["x -> y".into()],
            band_min_hz: 2.0,
            band_max_hz: 10.0,
            window: WindowChoice::Hamming,
            segment_s: Some(40.0),
            overlap: 0.5,
            detrend: DetrendChoice::None,
            coherence_threshold: 0.5,
        };
        let (identified, _) = analyse(&table, &[("x".into(), "y".into())], &p).unwrap();
        let value = |name: &str| match &identified.column(name).unwrap().data {
            ColumnData::OptF64(v) => v[0].unwrap(),
            other => panic!("{name}: {other:?}"),
        };
        // The peak of |H|: cos ω = (1 + r²)/(2r) cos ω0.
        let peak = ((1.0 + R * R) / (2.0 * R) * w0.cos()).acos();
        let peak_hz = peak * FS / (2.0 * PI);
        assert!((value("frequency_hz") - peak_hz).abs() < 0.01, "{} Hz against {peak_hz} Hz", value("frequency_hz"));
        let gain_error = value("peak_gain") / gain(peak) - 1.0;
        assert!(gain_error.abs() < 0.05, "peak gain {} against {}", value("peak_gain"), gain(peak));
        // The continuous system with the same poles: σ = −fs ln r, ζ = σ / |s|.
        let sigma = -FS * R.ln();
        let zeta = sigma / sigma.hypot(w0 * FS);
        assert!((value("damping_ratio") / zeta - 1.0).abs() < 0.1, "ζ {} against {zeta}", value("damping_ratio"));
        assert!(value("coherence") > 0.95, "coherence {}", value("coherence"));
    }
}
