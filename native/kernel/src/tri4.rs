//! Triangles four at a time: the triangles of a BVH leaf made only of triangles are also kept
//! in blocks of four in SoA layout ([`Tri4`], 160 bytes), and a ray meets a block's four in one
//! SIMD Möller–Trumbore test. The blocks are stored in the order of the BVH's leaves, and such
//! a leaf names its blocks itself (see [`crate::bvh::LEAF_BLOCKS`]): no lookup between the node
//! and the triangles.
//!
//! Each lane computes exactly what [`crate::geometry::hit_triangle`] computes, operation for
//! operation (the same products, sums in the same order, one IEEE division), so the hits are
//! bit for bit those of the one-at-a-time test, and among equal distances the first triangle in
//! BVH order wins, as it does there. Unused lanes hold a degenerate triangle (zero edges), which
//! that test never hits.

use crate::bvh::Bvh;
use crate::geometry::Shape;
use crate::ray::Ray;
use glam::{Vec3A, Vec4};

/// Four triangles (`v0`, edges `e1`, `e2`), each coordinate a lane vector, and the index of
/// the first one in the primitive array (lane `i` is primitive `first + i`).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct Tri4 {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    first: u32,
}

/// A ray's origin and direction splatted across lanes, made once per ray.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayLanes {
    o: [Vec4; 3],
    d: [Vec4; 3],
}

impl RayLanes {
    #[inline(always)]
    pub fn new(ray: &Ray) -> RayLanes {
        let (o, d) = (ray.origin, ray.dir);
        RayLanes {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
        }
    }
}

impl Tri4 {
    /// A block of up to four triangles `(v0, e1, e2)`, primitives `first..`; missing ones are
    /// degenerate.
    fn new(tris: &[(Vec3A, Vec3A, Vec3A)], first: u32) -> Tri4 {
        let mut b = Tri4 {
            v0: [Vec4::ZERO; 3],
            e1: [Vec4::ZERO; 3],
            e2: [Vec4::ZERO; 3],
            first,
        };
        for (i, &(v0, e1, e2)) in tris.iter().take(4).enumerate() {
            for a in 0..3 {
                b.v0[a][i] = v0[a];
                b.e1[a][i] = e1[a];
                b.e2[a][i] = e2[a];
            }
        }
        b
    }

    /// Distances of the four triangles and the mask of the lanes hit in `(tmin, tmax)`.
    #[inline(always)]
    fn hit(&self, r: &RayLanes, tmin: f32, tmax: f32) -> (Vec4, u32) {
        let [dx, dy, dz] = r.d;
        let [e1x, e1y, e1z] = self.e1;
        let [e2x, e2y, e2z] = self.e2;
        // p = dir x e2 (glam's cross: the same products and differences)
        let px = dy * e2z - dz * e2y;
        let py = dz * e2x - dx * e2z;
        let pz = dx * e2y - dy * e2x;
        let det = e1x * px + e1y * py + e1z * pz;
        let inv = Vec4::ONE / det;
        let sx = r.o[0] - self.v0[0];
        let sy = r.o[1] - self.v0[1];
        let sz = r.o[2] - self.v0[2];
        let u = (sx * px + sy * py + sz * pz) * inv;
        // q = s x e1
        let qx = sy * e1z - sz * e1y;
        let qy = sz * e1x - sx * e1z;
        let qz = sx * e1y - sy * e1x;
        let v = (dx * qx + dy * qy + dz * qz) * inv;
        let t = (e2x * qx + e2y * qy + e2z * qz) * inv;
        // the scalar test's rejections, NaN included: det == 0, u outside [0, 1] (or NaN),
        // v < 0, u + v > 1, t outside (tmin, tmax)
        let ok = det.cmpne(Vec4::ZERO)
            & u.cmpge(Vec4::ZERO)
            & u.cmple(Vec4::ONE)
            & !v.cmplt(Vec4::ZERO)
            & !(u + v).cmpgt(Vec4::ONE)
            & t.cmpgt(Vec4::splat(tmin))
            & t.cmplt(Vec4::splat(tmax));
        (t, ok.bitmask())
    }

    /// The nearest hit in `(tmin, tmax)`: (lane, t), the lowest lane among equal distances.
    #[inline(always)]
    pub fn closest(&self, r: &RayLanes, tmin: f32, tmax: f32) -> Option<(usize, f32)> {
        let (t, mask) = self.hit(r, tmin, tmax);
        if mask == 0 {
            return None;
        }
        let t = t.to_array();
        let mut best = mask.trailing_zeros() as usize & 3;
        let mut m = mask & (mask - 1);
        while m != 0 {
            let i = m.trailing_zeros() as usize & 3;
            m &= m - 1;
            if t[i] < t[best] {
                best = i;
            }
        }
        Some((best, t[best]))
    }

    /// The four triangles' `v0`, `e1` and `e2`, one lane vector per coordinate (for tests of
    /// one triangle across several rays).
    #[inline(always)]
    pub(crate) fn corners(&self) -> (&[Vec4; 3], &[Vec4; 3], &[Vec4; 3]) {
        (&self.v0, &self.e1, &self.e2)
    }

    /// The primitive index of lane `lane`.
    #[inline(always)]
    pub fn prim(&self, lane: usize) -> u32 {
        self.first + lane as u32
    }

    /// The first lane hit in `(tmin, tmax)`, if any (any-hit queries).
    #[inline(always)]
    pub fn any(&self, r: &RayLanes, tmin: f32, tmax: f32) -> Option<usize> {
        let (_, mask) = self.hit(r, tmin, tmax);
        (mask != 0).then(|| mask.trailing_zeros() as usize)
    }
}

/// The blocks of a BVH's all-triangle leaves, in the order of the leaves.
#[derive(Clone, Debug, Default)]
pub(crate) struct TriBlocks {
    blocks: Vec<Tri4>,
}

impl TriBlocks {
    /// The number of blocks.
    pub fn len(&self) -> usize {
        self.blocks.len()
    }

    /// Blocks for every leaf of `bvh` over `shapes` (in BVH order) that holds triangles only;
    /// each such leaf is rewritten to name its blocks ([`Bvh::mark_block_leaves`]).
    pub fn build(bvh: &mut Bvh, shapes: &[Shape]) -> TriBlocks {
        TriBlocks::build_from(bvh, |k| match shapes.get(k)? {
            Shape::Triangle { v0, e1, e2 } => Some((*v0, *e1, *e2)),
            _ => None,
        })
    }

    /// [`TriBlocks::build`] over primitives given by `tri(k)`: primitive `k` (in BVH order)
    /// as a triangle `(v0, e1, e2)`, or `None` for any other primitive. The blocks' array is
    /// allocated once, at the size the leaves need.
    pub fn build_from(
        bvh: &mut Bvh,
        tri: impl Fn(usize) -> Option<(Vec3A, Vec3A, Vec3A)>,
    ) -> TriBlocks {
        let needed: usize = bvh
            .nodes
            .iter()
            .flat_map(|n| n.counts().iter())
            .filter(|&&c| c != 0 && c != crate::bvh::EMPTY && c & crate::bvh::LEAF_BLOCKS == 0)
            .map(|&c| (c as usize).div_ceil(4))
            .sum();
        let mut blocks = Vec::with_capacity(needed);
        let mut tris = Vec::with_capacity(8);
        bvh.mark_block_leaves(|first, count| {
            tris.clear();
            tris.extend((first..first + count).map_while(&tri));
            if tris.len() != count || count == 0 || blocks.len() >= (u32::MAX / 2) as usize {
                return None;
            }
            let at = blocks.len() as u32;
            blocks.extend(
                tris.chunks(4)
                    .enumerate()
                    .map(|(k, t)| Tri4::new(t, (first + 4 * k) as u32)),
            );
            Some(at)
        });
        TriBlocks { blocks }
    }

    /// The blocks of the leaf `(child, count)` handed to a traversal's visit, if it is a leaf of
    /// triangle blocks ([`crate::bvh::LEAF_BLOCKS`] set in `count`).
    #[inline(always)]
    pub fn leaf(&self, child: usize, count: usize) -> Option<&[Tri4]> {
        let n = crate::bvh::block_leaf_len(count)?;
        self.blocks.get(child..child + n.div_ceil(4))
    }

    /// Asks early for the cache lines of the blocks of the leaf `(child, count)`, if it is a
    /// leaf of blocks (a hint: nothing is read).
    #[inline(always)]
    pub fn prefetch(&self, child: usize, count: usize) {
        if let Some(leaf) = self.leaf(child, count) {
            crate::bvh::prefetch_lines(leaf);
        }
    }

    /// The primitive range `(first, count)` of any leaf `(child, count)` handed to a visit.
    #[cfg(test)]
    pub fn prims(&self, child: usize, count: usize) -> (usize, usize) {
        match crate::bvh::block_leaf_len(count) {
            Some(n) => (self.blocks.get(child).map_or(0, |b| b.first as usize), n),
            None => (child, count),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::hit_triangle;

    use crate::test_support::rng;

    #[test]
    fn lanes_agree_bit_for_bit_with_the_scalar_test() {
        let mut seed = 0x1234_5678_9abc_def1u64;
        let v = |s: &mut u64| Vec3A::new(rng(s), rng(s), rng(s));
        let mut hits = 0;
        for round in 0..20_000 {
            let tris: Vec<(Vec3A, Vec3A, Vec3A)> = (0..4)
                .map(|k| {
                    let v0 = v(&mut seed);
                    // some degenerate and some shared-edge triangles
                    match (round + k) % 7 {
                        0 => (v0, Vec3A::ZERO, v(&mut seed)),
                        1 => (v0, Vec3A::X, Vec3A::X * 2.0),
                        _ => (v0, v(&mut seed), v(&mut seed)),
                    }
                })
                .collect();
            let n = 1 + round % 4;
            let b = Tri4::new(&tris[..n], 0);
            // aimed near a triangle's corner or centre, so that about half hit
            let o = v(&mut seed) * 3.0;
            let (v0, e1, e2) = tris[round % n];
            let aim = v0 + e1 * (0.5 * rng(&mut seed).abs()) + e2 * (0.5 * rng(&mut seed).abs());
            let ray = Ray::new(o, aim - o);
            let tmax = if round % 3 == 0 { 1.5 } else { f32::INFINITY };
            let lanes = RayLanes::new(&ray);
            // the scalar loop: nearest, first among equals
            let mut want = None;
            let mut tm = tmax;
            for (i, &(v0, e1, e2)) in tris[..n].iter().enumerate() {
                if let Some((t, _, _)) = hit_triangle(v0, e1, e2, &ray, 0.0, tm) {
                    tm = t;
                    want = Some((i, t));
                }
            }
            let got = b.closest(&lanes, 0.0, tmax);
            assert_eq!(
                got.map(|(i, t)| (i, t.to_bits())),
                want.map(|(i, t)| (i, t.to_bits()))
            );
            let first = tris[..n]
                .iter()
                .position(|&(v0, e1, e2)| hit_triangle(v0, e1, e2, &ray, 0.0, tmax).is_some());
            assert_eq!(b.any(&lanes, 0.0, tmax), first);
            hits += want.is_some() as u32;
        }
        assert!(hits > 5000, "{hits}");
    }

    #[test]
    fn equal_distances_go_to_the_first_lane() {
        let t = (Vec3A::ZERO, Vec3A::X, Vec3A::Y);
        let b = Tri4::new(&[(Vec3A::splat(5.0), Vec3A::X, Vec3A::Y), t, t], 0);
        let ray = Ray::new(Vec3A::new(0.25, 0.25, 1.0), -Vec3A::Z);
        let got = b.closest(&RayLanes::new(&ray), 0.0, f32::INFINITY);
        assert_eq!(got, Some((1, 1.0)));
    }
}
