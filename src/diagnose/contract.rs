//! The `diagnosis.json` contract, one for both unit models (read by scripts: its keys and their
//! order are kept exactly). A rolling unit's file says `model: rolling` and its predictability;
//! each candidate carries the figures of its model ([`ModelFields`]).

use indexmap::IndexMap;
use serde::Serialize;

use super::calibration::{Calibration, Entry};
use super::verdict::{serialize_span, Candidate, Diagnosis, Discrepancy, Model, Noise, Predictability, Verdict};

/// How `rmse_before`/`rmse_after` are computed, per model.
pub trait Contracted: Model {
    /// The contract's `model` (None: the rocking block, the default, says nothing).
    const MODEL: Option<&'static str>;
    const RMSE_DEFINITION: &'static str;
    /// The figures of a candidate only this model reports.
    fn candidate_fields(candidate: &Candidate<Self>) -> ModelFields;
}

/// Candidate figures that belong to one model; None: not written.
#[derive(Debug, Clone, Default)]
pub struct ModelFields {
    /// The window's misfit where the nominal model is predictable (rolling).
    pub rmse_judged: Option<f64>,
    /// Flagged samples in the first seconds past the window's start (rolling).
    pub flagged_early_samples: Option<usize>,
    /// The predicted overturn's time and side, or null (rocking).
    pub overturn: Option<Option<(f64, i8)>>,
    /// When the effect began, or null for the nominal model (rolling).
    pub onset_s: Option<Option<f64>>,
    /// Whether the candidate's own calibration is written.
    pub calibration: bool,
}

/// One key per uncertain parameter: `{stated, fitted, sd, within}` (lists element-wise); `{}`
/// without an `uncertainty` block.
pub fn calibration_entries(c: &Calibration) -> IndexMap<String, Entry> {
    c.entries().into_iter().collect()
}

#[derive(Debug, Clone, Serialize)]
pub struct Overturn {
    pub overturn_time_s: Option<f64>,
    pub overturn_side: Option<i8>,
}

/// A candidate as the contract writes it.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateContract {
    pub effect: &'static str,
    pub params: IndexMap<&'static str, f64>,
    pub rmse: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rmse_judged: Option<f64>,
    pub score: f64,
    pub bic: f64,
    pub chi2: f64,
    pub flagged_samples: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flagged_early_samples: Option<usize>,
    pub evaluations: usize,
    #[serde(flatten)]
    pub overturn: Option<Overturn>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub onset_s: Option<Option<f64>>,
    pub explanation: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<IndexMap<String, Entry>>,
    /// χ² by which the records prefer it to the nominal model where it begins (not for the
    /// nominal model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signature_chi2: Option<f64>,
}

/// `diagnosis.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Contract {
    pub case: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<&'static str>,
    pub mismatch: bool,
    pub verdict: Verdict,
    #[serde(serialize_with = "serialize_span")]
    pub window: Option<(f64, f64)>,
    pub rmse_before: f64,
    pub rmse_after: f64,
    pub rmse_definition: &'static str,
    pub noise: Noise,
    #[serde(flatten)]
    pub predictability: Option<Predictability>,
    pub candidates: Vec<CandidateContract>,
    pub explanation: String,
    pub calibration: IndexMap<String, Entry>,
    pub discrepancy: Discrepancy,
    pub shakeflow_version: &'static str,
}

impl<M: Contracted> From<&Candidate<M>> for CandidateContract {
    fn from(c: &Candidate<M>) -> CandidateContract {
        let fields = M::candidate_fields(c);
        CandidateContract {
            effect: c.effect,
            params: c.params.iter().copied().collect(),
            rmse: c.rmse,
            rmse_judged: fields.rmse_judged,
            score: c.score,
            bic: c.bic,
            chi2: c.misfit.chi2,
            flagged_samples: c.flagged,
            flagged_early_samples: fields.flagged_early_samples,
            evaluations: c.evaluations,
            overturn: fields
                .overturn
                .map(|o| Overturn { overturn_time_s: o.map(|o| o.0), overturn_side: o.map(|o| o.1) }),
            onset_s: fields.onset_s,
            explanation: c.sentence.clone(),
            calibration: fields.calibration.then(|| calibration_entries(&c.calibration)),
            signature_chi2: c.signature_chi2,
        }
    }
}

impl<M: Contracted> From<&Diagnosis<M>> for Contract {
    fn from(d: &Diagnosis<M>) -> Contract {
        Contract {
            case: d.case.clone(),
            model: M::MODEL,
            mismatch: d.mismatch,
            verdict: d.verdict,
            window: d.window,
            rmse_before: d.rmse_before,
            rmse_after: d.rmse_after,
            rmse_definition: M::RMSE_DEFINITION,
            noise: d.noise,
            predictability: d.predictability,
            candidates: d.candidates.iter().map(CandidateContract::from).collect(),
            explanation: d.explanation.clone(),
            calibration: calibration_entries(&d.calibration),
            discrepancy: d.discrepancy.clone(),
            shakeflow_version: env!("CARGO_PKG_VERSION"),
        }
    }
}

impl Contract {
    /// The file's bytes: pretty JSON and a final newline.
    pub fn bytes(&self) -> String {
        serde_json::to_string_pretty(self).expect("the diagnosis is JSON") + "\n"
    }
}
