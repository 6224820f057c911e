//! Primitive shapes and their ray intersection routines.
//!
//! Shapes are stored in an enum (no dynamic dispatch in the intersection loop); bulky ones
//! (polygons, see [`crate::polygon`], and cones) live in side arrays and the enum holds an
//! index. All routines take unit-length ray directions and report the nearest hit in the open
//! interval `(tmin, tmax)`.
//!
//! Sidedness: spheres, cones and polygons are intersected from both sides (the integrator flips
//! the normal towards the viewer), except shapes given with negative radii, which only exist from
//! the inside (NFF: "only the inside of the object is visible").

use crate::polygon::Polygons;
use crate::ray::Ray;
use glam::Vec3A;

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: Vec3A,
    /// Maximum corner.
    pub max: Vec3A,
}

impl Aabb {
    /// The empty box (union identity).
    pub const EMPTY: Aabb = Aabb {
        min: Vec3A::splat(f32::INFINITY),
        max: Vec3A::splat(f32::NEG_INFINITY),
    };

    /// Smallest box containing both.
    #[inline]
    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// Grows the box to contain a point.
    #[inline]
    pub fn grow(self, p: Vec3A) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// Half the surface area (0 for an empty box).
    #[inline]
    pub fn half_area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    /// Centre point.
    #[inline]
    pub fn centre(&self) -> Vec3A {
        (self.min + self.max) * 0.5
    }

    /// True if no point is inside.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Length of the diagonal (0 when empty).
    pub fn diagonal(&self) -> f32 {
        if self.is_empty() {
            0.0
        } else {
            (self.max - self.min).length()
        }
    }
}

/// A cone or cylinder frustum without end caps.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ConeData {
    pub base: Vec3A,
    /// Unit axis from base to apex.
    pub axis: Vec3A,
    pub height: f32,
    pub r0: f32,
    /// Radius change per unit length along the axis.
    pub slope: f32,
    /// The largest radius, `r0.max(r0 + slope * height)`, kept for [`ConeData::surely_missed`]
    /// (computed per test, it was a tenth of the test's instructions).
    pub rmax: f32,
    /// Only the inside exists (negative radii in NFF).
    pub inside: bool,
}

/// Intersectable shape.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Shape {
    Sphere {
        center: Vec3A,
        radius: f32,
        inside: bool,
    },
    Triangle {
        v0: Vec3A,
        e1: Vec3A,
        e2: Vec3A,
    },
    Polygon(u32),
    Cone(u32),
}

/// Bulk shape storage.
#[derive(Clone, Debug, Default)]
pub(crate) struct Geometry {
    pub shapes: Vec<Shape>,
    pub polygons: Polygons,
    pub cones: Vec<ConeData>,
}

#[inline]
pub(crate) fn hit_sphere(
    center: Vec3A,
    radius: f32,
    inside: bool,
    ray: &Ray,
    tmin: f32,
    tmax: f32,
) -> Option<f32> {
    let oc = ray.origin - center;
    let b = oc.dot(ray.dir);
    // distance from the centre to the line, computed stably
    let l = oc - ray.dir * b;
    let disc = radius * radius - l.length_squared();
    if disc < 0.0 {
        return None;
    }
    let q = disc.sqrt();
    let t0 = -b - q;
    let t1 = -b + q;
    if !inside && t0 > tmin && t0 < tmax {
        return Some(t0);
    }
    if t1 > tmin && t1 < tmax {
        return Some(t1);
    }
    None
}

/// Möller–Trumbore; returns (t, u, v). Linear in the direction, so it also takes directions
/// of any length (t is then in units of it), as mesh instances need.
#[inline]
pub(crate) fn hit_triangle(
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
    ray: &Ray,
    tmin: f32,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let p = ray.dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = ray.dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    if t > tmin && t < tmax {
        Some((t, u, v))
    } else {
        None
    }
}

impl ConeData {
    /// True when the line of a ray (direction `dir`, `bo` = base - origin) passes the axis' line
    /// further away than the cone's largest radius, so that no point of the ray is on the
    /// surface: most of a BVH leaf's cones, told apart with a cross product and no division.
    /// The bound is widened far past the rounding of both this test and the full one (whose
    /// error grows with the distance to the base), so it never drops a hit the full test finds.
    #[inline(always)]
    fn surely_missed(&self, bo: Vec3A, dir: Vec3A) -> bool {
        let n = dir.cross(self.axis);
        let gap = bo.dot(n);
        let slack = self.rmax * 1.001 + 1e-5 * bo.abs().max_element();
        // NaN anywhere compares false: the full test then decides
        gap * gap > slack * slack * n.length_squared()
    }

    /// Outward normal (before the inside flip) at a point on the surface.
    #[inline]
    pub fn outward_normal(&self, p: Vec3A) -> Vec3A {
        let d = p - self.base;
        let s = d.dot(self.axis);
        let radial = d - self.axis * s;
        let r = self.r0 + self.slope * s;
        let n = radial.normalize_or_zero() - self.axis * self.slope;
        let _ = r;
        n.try_normalize().unwrap_or(self.axis)
    }
}

/// Inlined into the leaf tests (the prefilter, which rejects about half the cones a ray meets
/// in a leaf, without a call); the quadratic stays a function of its own.
#[inline(always)]
fn hit_cone(c: &ConeData, ray: &Ray, tmin: f32, tmax: f32) -> Option<f32> {
    if c.surely_missed(c.base - ray.origin, ray.dir) {
        return None;
    }
    hit_cone_exact(c, ray, tmin, tmax)
}

/// The cone's quadratic, without [`ConeData::surely_missed`] before it.
#[inline(never)]
fn hit_cone_exact(c: &ConeData, ray: &Ray, tmin: f32, tmax: f32) -> Option<f32> {
    let bo = c.base - ray.origin;
    // Solved from the ray's point nearest the base, not from its origin: far from a thin cone,
    // |w|^2 - r^2 from the origin loses the radius to rounding (false hits a radius away).
    let dd = ray.dir.length_squared();
    if dd.is_nan() || dd <= 0.0 {
        return None;
    }
    let t0 = bo.dot(ray.dir) / dd;
    let near = ray.origin + ray.dir * t0;
    let oc = near - c.base;
    let so = oc.dot(c.axis);
    let sd = ray.dir.dot(c.axis);
    let w = oc - c.axis * so;
    let v = ray.dir - c.axis * sd;
    let rr = c.r0 + c.slope * so;
    let ks = c.slope * sd;
    let a = v.length_squared() - ks * ks;
    let hb = w.dot(v) - ks * rr;
    let cc = w.length_squared() - rr * rr;
    let mut roots = [f32::INFINITY; 2];
    if a.abs() < 1e-12 {
        if hb.abs() < 1e-30 {
            return None;
        }
        roots[0] = -cc / (2.0 * hb);
    } else {
        let disc = hb * hb - a * cc;
        if disc < 0.0 {
            return None;
        }
        let q = disc.sqrt();
        // numerically stable pair of roots
        let qq = -(hb + q.copysign(hb));
        let (r1, r2) = if qq != 0.0 {
            (qq / a, cc / qq)
        } else {
            let r = -hb / a;
            (r, r)
        };
        roots = if r1 <= r2 { [r1, r2] } else { [r2, r1] };
    }
    for tr in roots {
        let t = t0 + tr;
        if !(t > tmin && t < tmax) {
            continue;
        }
        let s = so + tr * sd;
        if s < 0.0 || s > c.height || c.r0 + c.slope * s < 0.0 {
            continue;
        }
        if c.inside {
            let n = c.outward_normal(ray.at(t));
            if n.dot(ray.dir) <= 0.0 {
                continue;
            }
        }
        return Some(t);
    }
    None
}

impl Geometry {
    /// Renumbers the cones in the order the shapes first name them, so that a BVH leaf's cones
    /// (its shapes are consecutive once the shapes are in BVH order) lie together in memory.
    /// Cones no shape names are dropped.
    pub fn cones_in_shape_order(&mut self) {
        let mut new_index = vec![u32::MAX; self.cones.len()];
        let mut cones = Vec::with_capacity(self.cones.len());
        for s in &mut self.shapes {
            if let Shape::Cone(k) = s {
                let Some(slot) = new_index.get_mut(*k as usize) else {
                    continue;
                };
                if *slot == u32::MAX {
                    if let Some(c) = self.cones.get(*k as usize) {
                        *slot = cones.len() as u32;
                        cones.push(*c);
                    }
                }
                *k = *slot;
            }
        }
        self.cones = cones;
    }

    /// Intersects shape `i`.
    #[inline(always)]
    pub fn hit(&self, shape: &Shape, ray: &Ray, tmin: f32, tmax: f32) -> Option<f32> {
        match *shape {
            Shape::Triangle { v0, e1, e2 } => {
                hit_triangle(v0, e1, e2, ray, tmin, tmax).map(|h| h.0)
            }
            Shape::Sphere {
                center,
                radius,
                inside,
            } => hit_sphere(center, radius, inside, ray, tmin, tmax),
            Shape::Polygon(k) => self.polygons.hit(k, ray, tmin, tmax),
            Shape::Cone(k) => hit_cone(self.cones.get(k as usize)?, ray, tmin, tmax),
        }
    }

    /// Geometric normal (outward per the primitive's convention: CCW polygon winding, inward for
    /// inside-only shapes) at hit point `p`.
    pub fn geometric_normal(&self, shape: &Shape, p: Vec3A) -> Vec3A {
        match *shape {
            Shape::Triangle { e1, e2, .. } => e1.cross(e2).normalize_or(Vec3A::Z),
            Shape::Sphere {
                center,
                radius,
                inside,
            } => {
                let n = ((p - center) / radius).normalize_or(Vec3A::Z);
                if inside {
                    -n
                } else {
                    n
                }
            }
            Shape::Polygon(k) => self.polygons.normal(k).unwrap_or(Vec3A::Z),
            Shape::Cone(k) => self.cones.get(k as usize).map_or(Vec3A::Z, |c| {
                let n = c.outward_normal(p);
                if c.inside {
                    -n
                } else {
                    n
                }
            }),
        }
    }

    /// Bounding box of a shape (needs the 3D polygon vertices, which are not kept after the build).
    pub fn bounds(&self, shape: &Shape, poly_bounds: &[Aabb]) -> Aabb {
        match *shape {
            Shape::Triangle { v0, e1, e2 } => Aabb::EMPTY.grow(v0).grow(v0 + e1).grow(v0 + e2),
            Shape::Sphere { center, radius, .. } => Aabb {
                min: center - Vec3A::splat(radius),
                max: center + Vec3A::splat(radius),
            },
            Shape::Polygon(k) => poly_bounds.get(k as usize).copied().unwrap_or(Aabb::EMPTY),
            Shape::Cone(k) => match self.cones.get(k as usize) {
                None => Aabb::EMPTY,
                Some(c) => c.segment_bounds(0.0, c.height),
            },
        }
    }

    /// Boxes that together bound a shape; long oblique cones/cylinders are cut into up to 16
    /// pieces along their axis, whose boxes are much tighter than one box around the whole.
    /// The BVH references the shape once per piece.
    pub fn split_bounds(&self, shape: &Shape, poly_bounds: &[Aabb], out: &mut Vec<Aabb>) {
        out.clear();
        if let Shape::Cone(k) = *shape {
            if let Some(c) = self.cones.get(k as usize) {
                let rmax = c.r0.max(c.r0 + c.slope * c.height).max(1e-30);
                let oblique = c.axis.abs().max_element() < 0.99;
                let pieces = if oblique {
                    (c.height / (4.0 * rmax)).ceil().clamp(1.0, 16.0) as usize
                } else {
                    1
                };
                for i in 0..pieces {
                    let s0 = c.height * i as f32 / pieces as f32;
                    let s1 = c.height * (i + 1) as f32 / pieces as f32;
                    out.push(c.segment_bounds(s0, s1));
                }
                return;
            }
        }
        out.push(self.bounds(shape, poly_bounds));
    }
}

impl ConeData {
    /// Box around the part of the surface with axial coordinate in `[s0, s1]`.
    pub fn segment_bounds(&self, s0: f32, s1: f32) -> Aabb {
        let e = (Vec3A::ONE - self.axis * self.axis).max(Vec3A::ZERO);
        let e = Vec3A::new(e.x.sqrt(), e.y.sqrt(), e.z.sqrt());
        let disc = |s: f32| {
            let c = self.base + self.axis * s;
            let r = (self.r0 + self.slope * s).max(0.0);
            Aabb {
                min: c - e * r,
                max: c + e * r,
            }
        };
        disc(s0).union(disc(s1))
    }
}

/// Builds cone data; `None` if the axis has zero length or both radii are zero.
pub(crate) fn make_cone(base: Vec3A, r0: f32, apex: Vec3A, r1: f32) -> Option<ConeData> {
    let inside = r0 < 0.0 && r1 < 0.0;
    let (r0, r1) = (r0.abs(), r1.abs());
    let d = apex - base;
    let height = d.length();
    let axis = d.try_normalize()?;
    if height <= 0.0 || (r0 == 0.0 && r1 == 0.0) {
        return None;
    }
    let slope = (r1 - r0) / height;
    Some(ConeData {
        base,
        axis,
        height,
        r0,
        slope,
        rmax: r0.max(r0 + slope * height),
        inside,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sure-miss test before the cone's quadratic never drops a hit the quadratic finds,
    /// over thin and wide cones and cylinders, rays from near and far (origins up to 1e6 away),
    /// and still rejects most rays that pass wide of the cone.
    #[test]
    fn cone_sure_miss_keeps_every_hit() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || crate::test_support::rng(&mut seed);
        let (mut hits, mut rejected) = (0, 0);
        for round in 0..200_000 {
            let base = Vec3A::new(rnd(), rnd(), rnd()) * 10.0;
            let apex = base + Vec3A::new(rnd(), rnd(), rnd()) * 5.0;
            let scale = [1e-4, 1e-2, 1.0][round % 3];
            let (r0, r1) = (rnd().abs() * scale, rnd().abs() * scale);
            let r1 = if round % 4 == 0 { r0 } else { r1 };
            let Some(c) = make_cone(base, r0, apex, r1) else {
                continue;
            };
            let far = [1.0, 1e3, 1e6][(round / 3) % 3];
            let o = Vec3A::new(rnd(), rnd(), rnd()) * far;
            // aimed at a point near the surface, or anywhere
            let s = rnd().abs() * c.height;
            let side = Vec3A::new(rnd(), rnd(), rnd()).normalize_or_zero();
            let target = c.base + c.axis * s + side * (c.r0 + c.slope * s) * (1.0 + rnd() * 0.01);
            let d = if round % 2 == 0 {
                target - o
            } else {
                Vec3A::new(rnd(), rnd(), rnd())
            };
            let r = Ray::new(o, d);
            let exact = hit_cone_exact(&c, &r, 0.0, f32::INFINITY);
            let missed = c.surely_missed(c.base - r.origin, r.dir);
            assert!(
                !(missed && exact.is_some()),
                "round {round}: {c:?}, {r:?} hits at {exact:?} but was called a sure miss"
            );
            assert_eq!(hit_cone(&c, &r, 0.0, f32::INFINITY), exact);
            hits += exact.is_some() as u32;
            rejected += missed as u32;
        }
        assert!(
            hits > 20_000 && rejected > 50_000,
            "{hits} hits, {rejected} rejected"
        );
    }

    fn ray(o: [f32; 3], d: [f32; 3]) -> Ray {
        Ray::new(Vec3A::from_array(o), Vec3A::from_array(d))
    }

    #[test]
    fn sphere_hits_and_misses() {
        let c = Vec3A::new(0.0, 0.0, -5.0);
        let t = hit_sphere(
            c,
            1.0,
            false,
            &ray([0.0; 3], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY,
        );
        assert!((t.unwrap() - 4.0).abs() < 1e-5);
        // from inside: far root
        let t = hit_sphere(
            c,
            1.0,
            false,
            &ray([0.0, 0.0, -5.0], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY,
        );
        assert!((t.unwrap() - 1.0).abs() < 1e-5);
        // miss beside
        assert!(hit_sphere(
            c,
            1.0,
            false,
            &ray([1.01, 0.0, 0.0], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY
        )
        .is_none());
        // behind
        assert!(hit_sphere(
            c,
            1.0,
            false,
            &ray([0.0; 3], [0.0, 0.0, 1.0]),
            0.0,
            f32::INFINITY
        )
        .is_none());
        // tmax respected
        assert!(hit_sphere(c, 1.0, false, &ray([0.0; 3], [0.0, 0.0, -1.0]), 0.0, 3.9).is_none());
        // inside-only sphere is invisible from outside until the far side
        let t = hit_sphere(
            c,
            1.0,
            true,
            &ray([0.0; 3], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY,
        );
        assert!((t.unwrap() - 6.0).abs() < 1e-5);
    }

    fn poly(vs: &[[f32; 3]]) -> (Geometry, Shape) {
        let mut g = Geometry::default();
        let v: Vec<Vec3A> = vs.iter().map(|a| Vec3A::from_array(*a)).collect();
        let plane = crate::polygon::plane(&v).unwrap();
        let k = g.polygons.add(&v, plane).unwrap();
        (g, Shape::Polygon(k))
    }

    #[test]
    fn polygon_hits_and_misses() {
        // unit square in z=0, CCW seen from +z
        let (g, s) = poly(&[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ]);
        let t = g.hit(
            &s,
            &ray([0.5, 0.5, 2.0], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY,
        );
        assert!((t.unwrap() - 2.0).abs() < 1e-6);
        assert!(g
            .hit(
                &s,
                &ray([1.5, 0.5, 2.0], [0.0, 0.0, -1.0]),
                0.0,
                f32::INFINITY
            )
            .is_none());
        // from behind too (two-sided intersection)
        assert!(g
            .hit(
                &s,
                &ray([0.5, 0.5, -2.0], [0.0, 0.0, 1.0]),
                0.0,
                f32::INFINITY
            )
            .is_some());
        // parallel
        assert!(g
            .hit(
                &s,
                &ray([0.5, 0.5, 2.0], [1.0, 0.0, 0.0]),
                0.0,
                f32::INFINITY
            )
            .is_none());
        assert!((g.geometric_normal(&s, Vec3A::ZERO) - Vec3A::Z).length() < 1e-6);
        // concave "L" shape: the notch is outside
        let (g, s) = poly(&[
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [2.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [1.0, 2.0, 0.0],
            [0.0, 2.0, 0.0],
        ]);
        assert!(g
            .hit(
                &s,
                &ray([1.5, 1.5, 1.0], [0.0, 0.0, -1.0]),
                0.0,
                f32::INFINITY
            )
            .is_none());
        assert!(g
            .hit(
                &s,
                &ray([0.5, 1.5, 1.0], [0.0, 0.0, -1.0]),
                0.0,
                f32::INFINITY
            )
            .is_some());
        assert!(g
            .hit(
                &s,
                &ray([1.5, 0.5, 1.0], [0.0, 0.0, -1.0]),
                0.0,
                f32::INFINITY
            )
            .is_some());
    }

    #[test]
    fn triangle_hits_and_misses() {
        let v0 = Vec3A::new(0.0, 0.0, 0.0);
        let e1 = Vec3A::new(1.0, 0.0, 0.0);
        let e2 = Vec3A::new(0.0, 1.0, 0.0);
        let h = hit_triangle(
            v0,
            e1,
            e2,
            &ray([0.25, 0.25, 1.0], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY,
        )
        .unwrap();
        assert!((h.0 - 1.0).abs() < 1e-6 && (h.1 - 0.25).abs() < 1e-6 && (h.2 - 0.25).abs() < 1e-6);
        assert!(hit_triangle(
            v0,
            e1,
            e2,
            &ray([0.6, 0.6, 1.0], [0.0, 0.0, -1.0]),
            0.0,
            f32::INFINITY
        )
        .is_none());
    }

    #[test]
    fn cylinder_and_cone() {
        let mut g = Geometry::default();
        g.cones
            .push(make_cone(Vec3A::ZERO, 1.0, Vec3A::new(0.0, 0.0, 2.0), 1.0).unwrap());
        let s = Shape::Cone(0);
        let t = g
            .hit(
                &s,
                &ray([5.0, 0.0, 1.0], [-1.0, 0.0, 0.0]),
                0.0,
                f32::INFINITY,
            )
            .unwrap();
        assert!((t - 4.0).abs() < 1e-5);
        let n = g.geometric_normal(&s, Vec3A::new(1.0, 0.0, 1.0));
        assert!((n - Vec3A::X).length() < 1e-5);
        // above the top: miss; down the open axis: miss (no caps)
        assert!(g
            .hit(
                &s,
                &ray([5.0, 0.0, 2.5], [-1.0, 0.0, 0.0]),
                0.0,
                f32::INFINITY
            )
            .is_none());
        assert!(g
            .hit(
                &s,
                &ray([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]),
                0.0,
                f32::INFINITY
            )
            .is_none());
        // cone: radius 1 at z=0 to 0 at z=1; at z=0.5 the radius is 0.5
        g.cones
            .push(make_cone(Vec3A::ZERO, 1.0, Vec3A::Z, 0.0).unwrap());
        let s = Shape::Cone(1);
        let t = g
            .hit(
                &s,
                &ray([5.0, 0.0, 0.5], [-1.0, 0.0, 0.0]),
                0.0,
                f32::INFINITY,
            )
            .unwrap();
        assert!((t - 4.5).abs() < 1e-5);
        let n = g.geometric_normal(&s, Vec3A::new(0.5, 0.0, 0.5));
        assert!((n - Vec3A::new(1.0, 0.0, 1.0).normalize()).length() < 1e-5);
    }

    #[test]
    fn a_thin_cone_far_away_is_hit_only_within_its_radius() {
        // a branch tip of tree_s11: radius 0.0018, seen from about five units away
        let base = Vec3A::new(0.3, 0.9, 0.2);
        let axis = Vec3A::new(0.48, 0.6, 0.64);
        let (r, h) = (0.00183f32, 0.0137f32);
        let c = make_cone(base, r, base + axis * h, r).expect("a cone");
        let mid = base + axis * (h / 2.0);
        let side = axis.cross(Vec3A::Z).normalize();
        let eye = mid + axis.cross(side).normalize() * 5.0;
        for (k, d) in [0.0f32, 0.5, 0.9, 1.1, 1.3, 1.6, 2.0, 3.0]
            .into_iter()
            .enumerate()
        {
            for j in 0..50 {
                // aim past the axis at distance d * r, from eyes spread around the first
                let o = eye + Vec3A::new(0.01 * j as f32, -0.007 * j as f32, 0.003 * k as f32);
                let target = mid + side * (d * r);
                let hit = hit_cone(&c, &Ray::new(o, (target - o).normalize()), 0.0, 1e9);
                assert_eq!(
                    hit.is_some(),
                    d < 1.0,
                    "passing {d} radii from the axis, eye {j}"
                );
            }
        }
    }
}
