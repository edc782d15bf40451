//! Linear structural models used to synthesise floor and equipment responses.
pub mod sdof;
pub mod shear_building;
