//! pixguide's CPU path tracer: scenes from files, an obvhs BVH, physically based materials and
//! a unidirectional path tracer with next-event estimation and MIS.
//!
//! Conventions used everywhere:
//! - world space is right-handed, +Y up; colours are linear RGB (`Vec3`);
//! - local shading space has the shading normal on +Z; `wo` and `wi` both point away from the
//!   surface;
//! - every error a user can cause is an [`Error`] naming the file and the field or line.

pub mod bench;
pub mod camera;
pub mod embree;
pub mod error;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod light;
pub mod material;
pub mod math;
pub mod randomize;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod sky;
pub mod stats;
pub mod texture;

pub use error::{Error, Result};
