//! Statistics on results: fragility curves (lognormal, by maximum likelihood).
pub mod fragility;
