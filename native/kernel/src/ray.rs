//! Rays (f32, SIMD-friendly `Vec3A`).

use glam::Vec3A;

/// A ray `origin + t * dir` with a unit direction and a precomputed safe reciprocal direction.
/// (Inside the kernel, a ray taken into a mesh instance's object space keeps the length its
/// direction gets from the transform, see `Ray::scaled`.)
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3A,
    /// Unit direction.
    pub dir: Vec3A,
    /// `1 / dir`, with zero components replaced by a tiny signed value so slab tests never see NaN.
    pub inv_dir: Vec3A,
}

impl Ray {
    /// Builds a ray; `dir` is normalised (a zero direction becomes +z).
    #[inline]
    pub fn new(origin: Vec3A, dir: Vec3A) -> Ray {
        Ray::from_unit(origin, dir.try_normalize().unwrap_or(Vec3A::Z))
    }

    /// Builds a ray from a direction already of unit length (not re-normalised).
    #[inline]
    pub fn from_unit(origin: Vec3A, dir: Vec3A) -> Ray {
        let safe = Vec3A::select(
            dir.abs().cmplt(Vec3A::splat(1e-20)),
            Vec3A::splat(1e-20).copysign(dir),
            dir,
        );
        Ray {
            origin,
            dir,
            inv_dir: safe.recip(),
        }
    }

    /// A ray whose direction is used as given, of any non-zero length: a world ray taken into a
    /// mesh instance's object space, where `t` must name the same points as on the world ray
    /// (the intersection routines and the box test are linear in the direction).
    #[inline]
    pub(crate) fn scaled(origin: Vec3A, dir: Vec3A) -> Ray {
        Ray::from_unit(origin, dir)
    }

    /// The point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3A {
        self.origin + self.dir * t
    }
}

/// Mirror reflection of direction `d` about normal `n` (unit vectors).
#[inline]
pub fn reflect(d: Vec3A, n: Vec3A) -> Vec3A {
    d - n * (2.0 * d.dot(n))
}

/// Refraction of unit direction `d` through a surface with unit normal `n` facing against `d`
/// (`d.dot(n) <= 0`), with `eta` = n_from / n_to. Returns `None` on total internal reflection.
#[inline]
pub fn refract(d: Vec3A, n: Vec3A, eta: f32) -> Option<Vec3A> {
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((d * eta + n * (eta * cos_i - cos_t)).normalize_or_zero())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snell_and_tir() {
        let n = Vec3A::Y;
        for deg in [0.0f32, 10.0, 30.0, 45.0, 60.0, 80.0] {
            let a = deg.to_radians();
            let d = Vec3A::new(a.sin(), -a.cos(), 0.0);
            // air -> glass
            let t = refract(d, n, 1.0 / 1.5).expect("no TIR entering glass");
            let sin_t = t.x;
            assert!((a.sin() - 1.5 * sin_t).abs() < 1e-5, "snell at {deg}");
            assert!(t.y < 0.0);
            assert!((t.length() - 1.0).abs() < 1e-5);
        }
        // glass -> air: critical angle asin(1/1.5) = 41.81 degrees
        let crit = (1.0f32 / 1.5).asin().to_degrees();
        for deg in [10.0f32, 30.0, 41.0] {
            let a = deg.to_radians();
            let d = Vec3A::new(a.sin(), -a.cos(), 0.0);
            let t = refract(d, n, 1.5).expect("below critical angle");
            assert!((1.5 * a.sin() - t.x).abs() < 1e-5);
        }
        for deg in [42.0f32, 60.0, 89.0] {
            assert!(deg > crit);
            let a = deg.to_radians();
            let d = Vec3A::new(a.sin(), -a.cos(), 0.0);
            assert!(refract(d, n, 1.5).is_none(), "TIR expected at {deg}");
        }
    }

    #[test]
    fn reflect_mirror() {
        let d = Vec3A::new(1.0, -1.0, 0.0).normalize();
        let r = reflect(d, Vec3A::Y);
        assert!((r - Vec3A::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6);
    }

    #[test]
    fn zero_components_are_safe() {
        let r = Ray::new(Vec3A::ZERO, Vec3A::X);
        assert!(r.inv_dir.is_finite());
    }
}
