//! Physical models: linear structures that synthesise floor and equipment responses, the rocking
//! block of the toppling model, the caster cart of the rolling model, the integrators they
//! share (`ode`) and the one driver of those hybrid models (`hybrid`) (pure numerics, no I/O).
pub mod error;
pub mod hybrid;
pub mod ode;
pub mod rocking;
pub mod rolling;
pub mod sdof;
pub mod shear_building;
