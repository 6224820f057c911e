//! Fixed ray sets for measuring the kernel, alone or next to another kernel (the Embree
//! harness in `native/embree_bench` traces the very same rays).
//!
//! - [`primary`]: a `n x n` pinhole view of a bounding box ([`crate::obj::default_camera`]),
//!   pixel-centre rays in row order, or in 4 x 4 pixel tiles ([`tile_order`]) for packets.
//! - [`incoherent`]: origins uniform in the central half of the box, directions uniform on the
//!   sphere, from a fixed seed (xorshift64*), like the reflected and shadow rays of a scene.

use crate::camera::Camera;
use crate::geometry::Aabb;
use crate::obj;
use crate::ray::Ray;
use glam::Vec3A;

/// Side of the square pixel tiles of [`tile_order`] (a tile is a packet of 16 rays).
pub const TILE: u32 = 4;

/// The `n x n` pixel-centre rays of the default view of `bounds`, in row order.
pub fn primary(bounds: Aabb, n: u32) -> Vec<Ray> {
    let cam: Camera = obj::default_camera(bounds);
    let span = Camera::centre_span(n, n);
    let mut rays = Vec::with_capacity((n as usize) * (n as usize));
    for y in 0..n {
        for x in 0..n {
            rays.push(cam.ray(x as f32 + 0.5, y as f32 + 0.5, n, n, span));
        }
    }
    rays
}

/// Row-order indices of an `n x n` image visited tile by tile ([`TILE`] x [`TILE`] pixels,
/// tiles in row order, pixels in row order inside a tile; partial tiles at the edges).
pub fn tile_order(n: u32) -> Vec<u32> {
    let mut order = Vec::with_capacity((n as usize) * (n as usize));
    for ty in (0..n).step_by(TILE as usize) {
        for tx in (0..n).step_by(TILE as usize) {
            for y in ty..(ty + TILE).min(n) {
                for x in tx..(tx + TILE).min(n) {
                    order.push(y * n + x);
                }
            }
        }
    }
    order
}

/// xorshift64*: the fixed-seed generator of [`incoherent`].
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (v >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `count` incoherent rays in `bounds` (fixed seed: the same rays on every call).
pub fn incoherent(bounds: Aabb, count: usize) -> Vec<Ray> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let c = bounds.centre();
    let half = (bounds.max - bounds.min) * 0.5;
    let mut rays = Vec::with_capacity(count);
    while rays.len() < count {
        let o = c + (Vec3A::new(rng.next(), rng.next(), rng.next()) - Vec3A::splat(0.5)) * half;
        let z = 2.0 * rng.next() - 1.0;
        let phi = std::f32::consts::TAU * rng.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        rays.push(Ray::new(o, Vec3A::new(r * phi.cos(), r * phi.sin(), z)));
    }
    rays
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_visit_every_pixel_once() {
        for n in [1u32, 4, 7, 16] {
            let mut seen = vec![0u32; (n * n) as usize];
            for i in tile_order(n) {
                seen[i as usize] += 1;
            }
            assert!(seen.iter().all(|&c| c == 1), "n = {n}");
        }
        assert_eq!(&tile_order(8)[..5], &[0, 1, 2, 3, 8]);
    }

    #[test]
    fn ray_sets_are_fixed() {
        let b = Aabb {
            min: Vec3A::ZERO,
            max: Vec3A::ONE,
        };
        let a = incoherent(b, 100);
        let c = incoherent(b, 100);
        assert!(a
            .iter()
            .zip(&c)
            .all(|(x, y)| x.origin == y.origin && x.dir == y.dir));
        assert!(a.iter().all(|r| (r.dir.length() - 1.0).abs() < 1e-5));
        assert_eq!(primary(b, 8).len(), 64);
    }
}
