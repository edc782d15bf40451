//! Synthetic demo archive shaped like the NEES-2009-0722 UCSD BNCS test data.
pub mod archive;
pub mod camera;
pub mod cases;
pub mod study;
