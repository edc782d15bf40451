//! Files in and out: record readers, artifact writers, atomic file replacement.

pub mod atomic;
pub mod case;
pub mod equipment;
pub mod mcap;
pub mod parquet;
pub mod records;
