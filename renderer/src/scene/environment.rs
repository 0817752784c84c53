//! The environment: a constant colour or an equirectangular HDR map (EXR), importance-sampled.
//! (Being written.)

use glam::Vec3;

/// What the scene sees at infinity.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Environment {
    /// Black.
    #[default]
    Black,
    /// Uniform radiance.
    Constant(Vec3),
}
