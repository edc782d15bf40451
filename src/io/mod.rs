//! Files in and out: record readers, image sequences, control points, artifact writers, atomic file replacement.

pub mod atomic;
pub mod case;
pub mod control_points;
pub mod equipment;
pub mod frames;
pub mod hash;
pub mod mcap;
pub mod parquet;
pub mod records;
pub mod yaml;
