//! The camera projection technique (CPT) as pure numerics on image buffers and structs:
//! calibration (normalised DLT + Levenberg–Marquardt, optional radial distortion), template
//! tracking (exhaustive integer ZNCC/SSD + ECC sub-pixel refinement), and back-projection of
//! tracked pixels onto known planes (the study's Eq. 1–5). No files, no pipeline types.

pub mod calibrate;
pub mod camera;
pub mod image;
pub mod linalg;
pub mod matcher;
pub mod project;
pub mod synthetic;
pub mod track;
