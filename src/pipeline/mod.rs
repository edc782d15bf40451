//! The pipeline engine: spec → plan (DAG) → cached, parallel, all-or-nothing execution.

pub mod executor;
pub mod hash;
pub mod locate;
pub mod lock;
pub mod memo;
pub mod params;
pub mod plan;
pub mod progress;
pub mod sink;
pub mod sources;
pub mod spec;
