//! The pipeline engine: spec → plan (DAG) → work units, cached, run locally or on Slurm, committed atomically.

pub mod executor;
pub mod failpoint;
pub mod info;
pub mod layout;
pub mod lease;
pub mod locate;
pub mod lock;
pub mod memo;
pub mod ownership;
pub mod params;
pub mod paths;
pub mod plan;
pub mod progress;
pub mod sink;
pub mod slurm;
pub mod sources;
pub mod spec;
pub mod stage;
pub mod txn;
pub mod work_units;
