//! Point lights.

use glam::Vec3A;

/// A positional light with an RGB intensity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Position in world space.
    pub position: Vec3A,
    /// Intensity per channel.
    pub color: Vec3A,
}

/// The SPD's suggested relative intensity for each of `n` lights and for the ambient term:
/// `sqrt(n) / (2 n)` (0.5 when there are no lights).
pub fn spd_intensity(n: usize) -> f32 {
    let n = n.max(1) as f32;
    n.sqrt() / (2.0 * n)
}
