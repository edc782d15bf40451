//! shakeflow: declarative, cached, reproducible pipelines from shake-table records to validated
//! physics. See ARCHITECTURE.md for the map of this crate.

// `!(x > 0.0)` is how the numerics say "not positive, or NaN": a NaN must fail such checks, and
// the negated comparison says so where `partial_cmp` would hide it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cli;
pub mod declare;
pub mod demo;
pub mod diagnose;
pub mod error;
pub mod export;
pub mod inspect;
pub mod io;
pub mod physics;
pub mod pipeline;
pub mod plot;
pub mod schema;
pub mod signal;
pub mod stages;
pub mod stats;
pub mod summary;
pub mod table;
#[cfg(test)]
mod tempdir;
pub mod units;
pub mod validate;
pub mod vision;
