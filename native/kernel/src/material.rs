//! Whitted materials (the NFF `f` entity plus an optional checker texture).

use glam::Vec3A;

/// A two-colour 3D checker texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checker {
    /// The second colour (the first is the material colour).
    pub color2: Vec3A,
    /// Edge length of one check in world units (> 0).
    pub scale: f32,
}

/// Surface description in Whitted's model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Surface colour (linear RGB, 0..1).
    pub color: Vec3A,
    /// Diffuse coefficient.
    pub kd: f32,
    /// Specular coefficient: Phong highlight weight and mirror-reflection weight.
    pub ks: f32,
    /// Phong exponent.
    pub shine: f32,
    /// Transmittance: weight of the refracted ray.
    pub t: f32,
    /// Index of refraction (used when `t > 0`; values <= 0 are treated as 1).
    pub ior: f32,
    /// Optional checker texture.
    pub checker: Option<Checker>,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            color: Vec3A::ONE,
            kd: 1.0,
            ks: 0.0,
            shine: 0.0,
            t: 0.0,
            ior: 1.0,
            checker: None,
        }
    }
}

impl Material {
    /// Surface colour at world point `p`.
    #[inline]
    pub fn color_at(&self, p: Vec3A) -> Vec3A {
        match self.checker {
            None => self.color,
            Some(c) => {
                let q = (p / c.scale + Vec3A::splat(1e-4)).floor();
                let s = q.x as i64 + q.y as i64 + q.z as i64;
                if s & 1 == 0 {
                    self.color
                } else {
                    c.color2
                }
            }
        }
    }

    /// Effective index of refraction.
    #[inline]
    pub fn eta(&self) -> f32 {
        if self.ior > 0.0 {
            self.ior
        } else {
            1.0
        }
    }
}
