//! Pinhole camera built from the NFF `v` entity.
//!
//! NFF.TXT defines the angle as "from the center of top pixel row to bottom pixel row and left
//! column to right column", with square pixels. We apply it to the *smaller* image side (for
//! square images both readings agree): with pixel centres at `i + 0.5`, the centres of the first
//! and last column/row of the smaller side subtend `angle`. In SPD corner mode the rays go
//! through pixel corners, and the outermost corners (0 and N) subtend `angle` instead, which is
//! how the SPD's 513x513 corner grid is defined.

use crate::ray::Ray;
use glam::Vec3A;

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub from: Vec3A,
    /// Unit viewing direction (towards `at`).
    pub forward: Vec3A,
    /// Unit vector to the right of the image.
    pub right: Vec3A,
    /// Unit vector to the top of the image.
    pub up: Vec3A,
    /// `tan(angle / 2)`.
    pub tan_half: f32,
}

impl Camera {
    /// Builds a camera; returns `None` if `from == at`, `up` is parallel to the view direction or
    /// the angle is not in (0, 180) degrees.
    pub fn new(from: Vec3A, at: Vec3A, up: Vec3A, angle_deg: f32) -> Option<Camera> {
        if !(angle_deg > 0.0 && angle_deg < 180.0) {
            return None;
        }
        // pre-scale so that huge (but finite) vectors normalise without overflow
        let unit = |v: Vec3A| {
            let m = v.abs().max_element();
            if m > 0.0 && m.is_finite() {
                (v / m).try_normalize()
            } else {
                None
            }
        };
        let forward = unit(at - from)?;
        let right = unit(forward.cross(unit(up)?))?;
        let up = right.cross(forward);
        Some(Camera {
            from,
            forward,
            right,
            up,
            tan_half: (angle_deg.to_radians() * 0.5).tan(),
        })
    }

    /// Ray through continuous image position `(x, y)` (pixel `(i, j)` covers `[i, i+1) x [j, j+1)`,
    /// `y` grows downwards) of a `width x height` image; `span` is the distance in pixel units
    /// that `angle` covers on the smaller side.
    #[inline]
    pub fn ray(&self, x: f32, y: f32, width: u32, height: u32, span: f32) -> Ray {
        let s = 2.0 * self.tan_half / span;
        let dx = (x - width as f32 * 0.5) * s;
        let dy = (y - height as f32 * 0.5) * s;
        Ray::new(self.from, self.forward + self.right * dx - self.up * dy)
    }

    /// Span for pixel-centre sampling: the centres of the first and last pixel of the smaller side.
    pub fn centre_span(width: u32, height: u32) -> f32 {
        (width.min(height) as f32 - 1.0).max(1.0)
    }

    /// Span for SPD corner sampling: corner 0 to corner N of the smaller side.
    pub fn corner_span(width: u32, height: u32) -> f32 {
        width.min(height) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_target() {
        let from = Vec3A::new(1.0, 2.0, 3.0);
        let at = Vec3A::new(-2.0, 0.5, 0.0);
        let c = Camera::new(from, at, Vec3A::Z, 45.0).unwrap();
        // odd resolution: pixel (2, 2) centre is at (2.5, 2.5) = image centre
        let r = c.ray(2.5, 2.5, 5, 5, Camera::centre_span(5, 5));
        let want = (at - from).normalize();
        assert!((r.dir - want).length() < 1e-6);
        assert_eq!(r.origin, from);
        // the centres of the edge columns are 45 degrees apart
        let l = c.ray(0.5, 2.5, 5, 5, Camera::centre_span(5, 5));
        let rr = c.ray(4.5, 2.5, 5, 5, Camera::centre_span(5, 5));
        let ang = l.dir.dot(rr.dir).acos().to_degrees();
        assert!((ang - 45.0).abs() < 1e-3, "{ang}");
        // left column is to the left: right vector points from l to rr
        assert!((rr.dir - l.dir).dot(c.right) > 0.0);
        // top row is up
        let top = c.ray(2.5, 0.5, 5, 5, Camera::centre_span(5, 5));
        assert!((top.dir - r.dir).dot(c.up) > 0.0);
    }

    #[test]
    fn degenerate_views_rejected() {
        assert!(Camera::new(Vec3A::ZERO, Vec3A::ZERO, Vec3A::Y, 45.0).is_none());
        assert!(Camera::new(Vec3A::ZERO, Vec3A::Y, Vec3A::Y, 45.0).is_none());
        assert!(Camera::new(Vec3A::ZERO, Vec3A::X, Vec3A::Y, 180.0).is_none());
    }
}
