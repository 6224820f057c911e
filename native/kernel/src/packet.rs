//! Coherent rays in packets: up to sixteen rays through the 8-wide BVH together.
//!
//! The rays of a packet whose directions have the same signs on every axis share the choice of
//! near and far box planes, and their reciprocal directions and origins-times-reciprocals span
//! small intervals when the rays are coherent (a 4 x 4 pixel tile of primary rays). Per node,
//! one test of the eight child boxes against those intervals (AVX where the CPU has it, else two
//! SSE halves; the same operations on the same values either way) bounds every ray's own box
//! test from the safe side: a child that none of the rays can enter is rejected for all of them
//! at the cost of one single-ray test. When the rays share their origin (eye rays), the bound
//! is taken on `(plane - origin) * reciprocal` instead, widened for rounding, which is much
//! tighter where a direction component is small. Inner children that pass are descended nearest first (by
//! the packet's lower bound of the entry distance) and deferred ones are skipped when that bound
//! is beyond every ray's current nearest hit.
//!
//! At a leaf each ray makes its own box test, exactly the single-ray traversal's (the same
//! products, differences and min/max in the same order), and only the rays that pass it test the
//! leaf's primitives. A leaf of triangle blocks is met across rays with AVX, each triangle (read
//! from the blocks themselves) against eight rays at once, or all sixteen where the CPU has
//! AVX-512 ([`crate::lanes`]), with the operations of the single-ray test; when fewer than
//! [`FEW`] of those enter a leaf of more than four triangles, they meet its blocks one at a
//! time, four triangles per test
//! ([`crate::tri4`]). Other leaves, and all of them without AVX, are met one ray at a time with
//! [`Scene::leaf_closest`], the leaf test of [`Scene::intersect_with`]. So
//! a ray meets the leaves that its single-ray traversal meets (a leaf whose box a ray enters
//! before its final hit is met in either order, and among equal distances the lowest primitive
//! index wins in both), and gets the same primitive and the same distance bits. Mesh instances
//! and planes are then handled per ray, by the single-ray code.
//!
//! Any-hit queries (shadow rays) take the same path: a ray is done at its first hit, its lanes
//! then closed (bound -inf) so that they enter no more boxes, and it is occluded exactly when
//! its single-ray any-hit query says so (that query looks for a hit of the same primitive
//! tests on the same interval; mesh instances and planes are asked per ray as it asks them).
//!
//! The rays of a packet and their nearest hits so far are kept in one SoA block ([`Soa`]). A
//! packet whose directions are close is loaded into it with 4 x 4 transposes, and what decides
//! its path is read from those rows ([`Summary`]): its spreads, its direction signs, a NaN. A
//! coherent packet of one sign class (nearly every tile of eye rays, and their shadow rays) is
//! traced as loaded, its bounds taken row by row. Rays whose direction signs differ are split
//! into groups by sign; a group of fewer than [`MIN_GROUP`] rays, where a packet would not
//! pay, is traced one ray at a time. Set-up and answers are compiled with AVX where the
//! traversal is. Work ([`Scratch::work`]) is counted for the renderer's tiles only
//! ([`trace`]'s `every_ray`).

use crate::bvh::{has_avx2_fma, Node8, Scratch, EMPTY, WIDTH};
#[cfg(target_arch = "x86_64")]
use crate::lanes::{Avx16, Avx8, Lanes};
use crate::ray::Ray;
use crate::scene::{Hit, Mailbox, Scene};
use crate::tri4::{RayLanes, Tri4};
use glam::Vec4;

/// Rays traversed together.
pub(crate) const PACKET: usize = 16;

/// Fewer rays of one direction-sign class are traced one by one.
pub(crate) const MIN_GROUP: usize = 3;

/// A packet whose unit directions differ by more than this on some axis, or whose origins lie
/// further apart than [`ORIGIN_SPREAD`] times the scene's size, is not coherent: its intervals
/// would let nearly every box through, so its rays are traced one by one
/// ([`Summary::coherent`]; a NaN in a direction or an origin makes a packet incoherent too).
const DIR_SPREAD: f32 = 0.125;

/// See [`DIR_SPREAD`]. The shadow rays of a 4 x 4 pixel tile's hit points (and the sixteens
/// that straddle two tiles) spread further than eye rays, and still gain from the packet
/// traversal at a few hundredths of the scene (counted with callgrind on the SPD teapot: 0.01
/// left most of them to single rays, 0.3 lets through packets the single rays beat).
const ORIGIN_SPREAD: f32 = 0.03;

/// The least of a row, NaN ignored (`f32::min` over it).
#[inline(always)]
fn row_min(row: &[f32; PACKET]) -> f32 {
    // `x.min(acc)` is `_mm_min_ps(x, acc)` on x86, which gives `acc` where `x` is NaN
    let mut acc = Vec4::INFINITY;
    for q in row.chunks_exact(4) {
        acc = Vec4::from_slice(q).min(acc);
    }
    acc.to_array().iter().fold(f32::INFINITY, |m, &x| m.min(x))
}

/// The greatest of a row, NaN ignored (`f32::max` over it).
#[inline(always)]
fn row_max(row: &[f32; PACKET]) -> f32 {
    let mut acc = Vec4::NEG_INFINITY;
    for q in row.chunks_exact(4) {
        acc = Vec4::from_slice(q).max(acc);
    }
    acc.to_array()
        .iter()
        .fold(f32::NEG_INFINITY, |m, &x| m.max(x))
}

/// The shared plane choice and the rays' intervals for the packet's node test.
#[derive(Clone, Copy, Debug)]
struct Frustum {
    near: [usize; 3],
    far: [usize; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    oinv_lo: [f32; 3],
    oinv_hi: [f32; 3],
    /// All rays start at `o` (eye rays) and no reciprocal is huge: the node test then bounds
    /// `(plane - o) * inv` over the rays' reciprocals, widened by `k * (|plane| + |o|)` per axis
    /// for rounding, which is much tighter than the general intervals.
    shared: bool,
    o: [f32; 3],
    k: [f32; 3],
    /// An any-hit query: a ray's lanes are closed (bound -inf) at its first hit.
    any: bool,
}

/// Relative widening of the shared-origin bounds: far above the few roundings of the ray's own
/// `plane * inv - o * inv`.
const ROUNDING: f32 = 4e-6;

/// The rays of a packet in SoA layout, for the tests across rays, and each ray's best hit so
/// far: `tmax` (the bound, then the nearest hit's distance) and `prim` (`u32::MAX`: none yet).
/// Unused lanes: zeros, with a bound of -inf, so that no box test lets them in.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Soa {
    o: [[f32; PACKET]; 3],
    d: [[f32; PACKET]; 3],
    inv: [[f32; PACKET]; 3],
    oinv: [[f32; PACKET]; 3],
    tmax: [f32; PACKET],
    prim: [u32; PACKET],
}

impl Soa {
    /// No rays.
    #[inline(always)]
    fn empty() -> Soa {
        Soa {
            o: [[0.0; PACKET]; 3],
            d: [[0.0; PACKET]; 3],
            inv: [[0.0; PACKET]; 3],
            oinv: [[0.0; PACKET]; 3],
            tmax: [f32::NEG_INFINITY; PACKET],
            prim: [u32::MAX; PACKET],
        }
    }

    /// Puts `ray` in lane `k` with the bound `tmax`; returns its reciprocal direction and
    /// origin times it, as the single-ray box test computes them.
    #[inline(always)]
    fn set(&mut self, k: usize, ray: &Ray, tmax: f32) -> ([f32; 3], [f32; 3]) {
        let k = k & (PACKET - 1);
        let (o, d) = (ray.origin, ray.inv_dir);
        let inv = [d.x, d.y, d.z];
        let oinv = [o.x * d.x, o.y * d.y, o.z * d.z];
        for a in 0..3 {
            self.o[a][k] = ray.origin[a];
            self.d[a][k] = ray.dir[a];
            self.inv[a][k] = inv[a];
            self.oinv[a][k] = oinv[a];
        }
        self.tmax[k] = tmax;
        self.prim[k] = u32::MAX;
        (inv, oinv)
    }

    /// Puts the rays `four` (at most four; missing ones: copies of the first) in lanes
    /// `4 * g..4 * g + 4`, with no bound yet; origin times reciprocal as in [`Soa::set`].
    #[inline(always)]
    fn fill4(&mut self, g: usize, four: &[Ray]) {
        let Some(r0) = four.first() else { return };
        let r = [0, 1, 2, 3].map(|j| four.get(j).unwrap_or(r0));
        let base = (4 * g) & (PACKET - 4);
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            // a 4 x 4 transpose of the rays' vectors (the fourth lane dropped)
            let rows = |v: [glam::Vec3A; 4]| {
                let [a, b, c, d] = v.map(__m128::from);
                // SAFETY: SSE is part of every x86_64 CPU (the baseline the crate is built
                // for), and these shuffles touch no memory.
                unsafe {
                    let (t0, t1) = (_mm_unpacklo_ps(a, b), _mm_unpacklo_ps(c, d));
                    let (t2, t3) = (_mm_unpackhi_ps(a, b), _mm_unpackhi_ps(c, d));
                    [
                        _mm_movelh_ps(t0, t1),
                        _mm_movehl_ps(t1, t0),
                        _mm_movelh_ps(t2, t3),
                    ]
                }
                .map(Vec4::from)
            };
            let o = rows(r.map(|r| r.origin));
            let d = rows(r.map(|r| r.dir));
            let inv = rows(r.map(|r| r.inv_dir));
            for a in 0..3 {
                o[a].write_to_slice(&mut self.o[a][base..]);
                d[a].write_to_slice(&mut self.d[a][base..]);
                inv[a].write_to_slice(&mut self.inv[a][base..]);
                (o[a] * inv[a]).write_to_slice(&mut self.oinv[a][base..]);
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        for a in 0..3 {
            let o = Vec4::new(
                r[0].origin[a],
                r[1].origin[a],
                r[2].origin[a],
                r[3].origin[a],
            );
            let d = Vec4::new(r[0].dir[a], r[1].dir[a], r[2].dir[a], r[3].dir[a]);
            let inv = Vec4::new(
                r[0].inv_dir[a],
                r[1].inv_dir[a],
                r[2].inv_dir[a],
                r[3].inv_dir[a],
            );
            o.write_to_slice(&mut self.o[a][base..]);
            d.write_to_slice(&mut self.d[a][base..]);
            inv.write_to_slice(&mut self.inv[a][base..]);
            (o * inv).write_to_slice(&mut self.oinv[a][base..]);
        }
    }

    /// Makes lanes `k..` copies of lane 0's ray, with a bound of -inf.
    #[inline(always)]
    fn pad(&mut self, k: usize) {
        for l in k.min(PACKET)..PACKET {
            for a in 0..3 {
                self.o[a][l] = self.o[a][0];
                self.d[a][l] = self.d[a][0];
                self.inv[a][l] = self.inv[a][0];
                self.oinv[a][l] = self.oinv[a][0];
            }
            self.tmax[l] = f32::NEG_INFINITY;
            self.prim[l] = u32::MAX;
        }
    }

    /// Lane `k`'s reciprocal direction and origin times it.
    #[inline(always)]
    fn lane(&self, k: usize) -> ([f32; 3], [f32; 3]) {
        let k = k & (PACKET - 1);
        (
            [0, 1, 2].map(|a| self.inv[a][k]),
            [0, 1, 2].map(|a| self.oinv[a][k]),
        )
    }

    /// The packet's bound after a leaf: the largest of the lanes' bounds, once an any-hit
    /// query (`any`) has closed the lanes that have a hit (bound -inf: they enter no more
    /// boxes).
    #[inline(always)]
    fn bound_after_leaf(&mut self, any: bool) -> f32 {
        if any {
            for (t, &p) in self.tmax.iter_mut().zip(&self.prim) {
                if p != u32::MAX {
                    *t = f32::NEG_INFINITY;
                }
            }
        }
        self.max_tmax()
    }

    /// The largest bound of the lanes (-inf for none).
    #[inline(always)]
    fn max_tmax(&self) -> f32 {
        self.tmax
            .iter()
            .fold(f32::NEG_INFINITY, |m, &t| max_ps(m, t))
    }
}

#[cfg(test)]
pub(crate) mod probe {
    use std::cell::Cell;
    thread_local! {
        /// [node tests, leaf calls (per 8 rays), leaf calls some ray entered, triangle tests
        /// (per 8 rays), ray-leaf entries, packets, leaves left to the few rays that entered]
        pub static COUNTS: Cell<[u64; 7]> = const { Cell::new([0; 7]) };
    }
    pub fn add(k: usize, n: u64) {
        COUNTS.with(|c| {
            let mut v = c.get();
            v[k] += n;
            c.set(v);
        });
    }
}

#[cfg(test)]
thread_local! {
    /// Tests set this to run the SSE traversal on a machine with AVX.
    static FORCE_SSE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

#[cfg(test)]
thread_local! {
    /// Tests set this to run the eight-lane leaf tests on a machine with AVX-512.
    static FORCE_AVX2: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Whether the leaf tests take sixteen lanes at once (the CPU has AVX-512F as well as AVX and
/// FMA, and tests did not ask for fewer).
#[inline(always)]
fn use_avx512() -> bool {
    #[cfg(test)]
    if FORCE_AVX2.with(|f| f.get()) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        use_avx() && std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the AVX traversal runs (the CPU has AVX2 and FMA, as the single-ray traversal
/// asks, and tests did not ask for SSE).
#[inline(always)]
fn use_avx() -> bool {
    #[cfg(test)]
    if FORCE_SSE.with(|f| f.get()) {
        return false;
    }
    has_avx2_fma()
}

/// The three direction-sign bits of a ray (bit `a` set: negative on axis `a`), as the
/// single-ray traversal reads them to choose its near planes.
#[inline(always)]
fn signs(ray: &Ray) -> usize {
    // the comparisons `inv.x < 0.0`, ... as a mask
    (ray.inv_dir.cmplt(glam::Vec3A::ZERO).bitmask() & 7) as usize
}

/// `_mm_max_ps(a, b)` on one lane (the second operand when either is NaN).
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// `_mm_min_ps(a, b)` on one lane.
#[inline(always)]
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The single-ray box test of child `i` (the lane `i` of the 8-wide test in [`crate::bvh`]):
/// the entry distance of the ray (reciprocal direction `inv`, origin times it `oinv`) if it
/// enters the box before `tmax`.
#[inline(always)]
fn enters(
    node: &Node8,
    i: usize,
    f: &Frustum,
    (inv, oinv): ([f32; 3], [f32; 3]),
    tmax: f32,
) -> Option<f32> {
    let p = node.planes();
    let mut tn = 0.0f32;
    let mut tf = tmax;
    for a in 0..3 {
        // fused, as that test's fmsub
        let n = p[f.near[a] & 7][i & 7].mul_add(inv[a], -oinv[a]);
        let x = p[f.far[a] & 7][i & 7].mul_add(inv[a], -oinv[a]);
        tn = max_ps(tn, n);
        tf = min_ps(tf, x);
    }
    (tn <= tf).then_some(tn)
}

/// The packet's node test with SSE (two halves; glam's scalar code off x86): per child, a
/// lower bound of every ray's entry distance, and the mask of the children some ray may enter
/// before `tmax` (the largest of the rays' bounds).
#[inline(always)]
fn node_sse(node: &Node8, f: &Frustum, tmax: f32) -> ([f32; WIDTH], u32) {
    let p = node.planes();
    let mut out = [0.0f32; WIDTH];
    let mut mask = 0u32;
    for h in 0..2 {
        let mut tn = Vec4::ZERO;
        let mut tf = Vec4::splat(tmax);
        for a in 0..3 {
            let (lo, hi) = (Vec4::splat(f.inv_lo[a]), Vec4::splat(f.inv_hi[a]));
            let n = Vec4::from_slice(&p[f.near[a] & 7][4 * h..]);
            let x = Vec4::from_slice(&p[f.far[a] & 7][4 * h..]);
            if f.shared {
                let (o, k) = (Vec4::splat(f.o[a]), Vec4::splat(f.k[a]));
                let (dn, dx) = (n - o, x - o);
                tn = tn.max((dn * lo).min(dn * hi) - (n.abs() + o.abs()) * k);
                tf = tf.min((dx * lo).max(dx * hi) + (x.abs() + o.abs()) * k);
            } else {
                // fused as the rays' own test is, so a bound of its values
                let (oh, ol) = (Vec4::splat(-f.oinv_hi[a]), Vec4::splat(-f.oinv_lo[a]));
                tn = tn.max(n.mul_add(lo, oh).min(n.mul_add(hi, oh)));
                tf = tf.min(x.mul_add(lo, ol).max(x.mul_add(hi, ol)));
            }
        }
        tn.write_to_slice(&mut out[4 * h..]);
        mask |= tn.cmple(tf).bitmask() << (4 * h);
    }
    (out, mask)
}

/// [`node_sse`] with one AVX vector per plane: the same operations on the same values (fused
/// multiply-subtracts where it has `mul_add`).
///
/// # Safety
/// The CPU must have AVX and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,fma")]
#[inline]
unsafe fn node_avx(node: &Node8, f: &Frustum, tmax: f32) -> ([f32; WIDTH], u32) {
    use std::arch::x86_64::*;
    let p = node.planes();
    let mut tn = _mm256_setzero_ps();
    let mut tf = _mm256_set1_ps(tmax);
    for a in 0..3 {
        let lo = _mm256_set1_ps(f.inv_lo[a]);
        let hi = _mm256_set1_ps(f.inv_hi[a]);
        let n = &p[f.near[a] & 7];
        let x = &p[f.far[a] & 7];
        // SAFETY: `n` and `x` are arrays of 8 f32, exactly the 32 bytes an unaligned load reads.
        let (n, x) = unsafe { (_mm256_loadu_ps(n.as_ptr()), _mm256_loadu_ps(x.as_ptr())) };
        if f.shared {
            let (o, k) = (_mm256_set1_ps(f.o[a]), _mm256_set1_ps(f.k[a]));
            let abs = |v| _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
            let (dn, dx) = (_mm256_sub_ps(n, o), _mm256_sub_ps(x, o));
            let near = _mm256_min_ps(_mm256_mul_ps(dn, lo), _mm256_mul_ps(dn, hi));
            let far = _mm256_max_ps(_mm256_mul_ps(dx, lo), _mm256_mul_ps(dx, hi));
            let wn = _mm256_mul_ps(_mm256_add_ps(abs(n), abs(o)), k);
            let wx = _mm256_mul_ps(_mm256_add_ps(abs(x), abs(o)), k);
            tn = _mm256_max_ps(tn, _mm256_sub_ps(near, wn));
            tf = _mm256_min_ps(tf, _mm256_add_ps(far, wx));
        } else {
            let (oh, ol) = (_mm256_set1_ps(f.oinv_hi[a]), _mm256_set1_ps(f.oinv_lo[a]));
            let near = _mm256_min_ps(_mm256_fmsub_ps(n, lo, oh), _mm256_fmsub_ps(n, hi, oh));
            let far = _mm256_max_ps(_mm256_fmsub_ps(x, lo, ol), _mm256_fmsub_ps(x, hi, ol));
            tn = _mm256_max_ps(tn, near);
            tf = _mm256_min_ps(tf, far);
        }
    }
    let mut out = [0.0f32; WIDTH];
    // SAFETY: `out` is 8 f32, the 32 bytes an unaligned store writes.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), tn) };
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32;
    (out, mask)
}

/// Fewer rays than this entering a leaf of more than four triangles meet its blocks one ray
/// at a time (four triangles per SSE test), rather than each triangle across eight (or sixteen)
/// rays.
const FEW: u32 = 3;

/// Each ray's own box test of child `i` of `node` (the operations of [`enters`], lane by lane)
/// for the rays `L::N * part..L::N * part + L::N` of a packet: their entry distances, and the
/// lanes of those that enter before their own bound.
///
/// # Safety
/// The CPU must have the features of the width `L` (see [`crate::lanes`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn rays_enter<L: Lanes>(
    node: &Node8,
    i: usize,
    f: &Frustum,
    soa: &Soa,
    part: usize,
) -> (L::V, L::M) {
    let base = (L::N * part) & (PACKET - 1);
    let p = node.planes();
    // SAFETY (here and below): the caller's CPU has the width's features; `soa`'s rows are
    // arrays of 16 f32 and `base + L::N <= 16` (`L::N` is 8 or 16, `part` below 16 / L::N), so
    // each load reads L::N f32 inside one row.
    let load = |row: &[f32; PACKET]| unsafe { L::load(row.as_ptr().add(base)) };
    unsafe {
        let mut tn = L::splat(0.0);
        let mut tf = load(&soa.tmax);
        for a in 0..3 {
            let (inv, oinv) = (load(&soa.inv[a]), load(&soa.oinv[a]));
            let n = L::splat(p[f.near[a] & 7][i & 7]);
            let x = L::splat(p[f.far[a] & 7][i & 7]);
            tn = L::max(tn, L::fmsub(n, inv, oinv));
            tf = L::min(tf, L::fmsub(x, inv, oinv));
        }
        (tn, L::le(tn, tf))
    }
}

/// An all-triangle leaf (child `i` of `node`: the first `n` triangles of `blocks`) against the
/// rays `L::N * part..L::N * part + L::N` of a packet, `L::N` rays to a vector: first each
/// ray's own box test (the operations of [`enters`], lane by lane), then each triangle in turn
/// against the rays that entered, with the operations of the four-triangle test of
/// [`crate::tri4`] (which are those of the one-triangle test) on the same values, so the same
/// distances; among equal distances the lowest index wins, as in [`Scene::leaf_closest`].
/// With `WORK`, records the rays that entered in `entered` (see [`traverse`]). Returns whether some ray's
/// nearest hit changed, and the mask of the rays (of these `L::N`) that entered but were left
/// to the caller, when fewer than [`FEW`] of them entered a leaf of more than four triangles.
///
/// # Safety
/// The CPU must have the features of the width `L` (see [`crate::lanes`]).
// Longer than 80 lines, kept whole: the vector leaf test, run for every leaf a packet meets.
// Its box tests and triangle tests share the vectors of the rays and of their hits so far,
// which must stay in registers; split, its parts would pass them by reference, which only an
// instruction count before and after could clear (docs/testing.md; tests/function_length.rs
// lists it).
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn leaf_lanes<L: Lanes, const WORK: bool>(
    node: &Node8,
    i: usize,
    f: &Frustum,
    soa: &mut Soa,
    part: usize,
    blocks: &[Tri4],
    n: usize,
    entered: &mut Vec<(usize, f32, u32)>,
) -> (bool, u32) {
    // SAFETY (every `unsafe` below): the caller's CPU has the width's features; the loads and
    // stores are of L::N f32 inside arrays of 16 (see rays_enter).
    let (tn, inside) = unsafe { rays_enter::<L>(node, i, f, soa, part) };
    let mask = unsafe { L::bits(inside) };
    let base = (L::N * part) & (PACKET - 1);
    let load = |row: &[f32; PACKET]| unsafe { L::load(row.as_ptr().add(base)) };
    #[cfg(test)]
    probe::add(1, 1);
    if mask == 0 {
        return (false, 0);
    }
    let few = mask.count_ones() < FEW && n > 4;
    #[cfg(test)]
    {
        probe::add(2, 1);
        probe::add(4, mask.count_ones() as u64);
        probe::add(3, if few { 0 } else { n as u64 });
        probe::add(6, few as u64);
    }
    let mut tns = [0.0f32; PACKET];
    unsafe { L::store(tns.as_mut_ptr(), tn) };
    // a hit at exactly a ray's nearest distance is taken only with a lower index
    let mut limit = [f32::NEG_INFINITY; PACKET];
    let mut m = mask;
    while m != 0 {
        let j = m.trailing_zeros() as usize & (PACKET - 1);
        m &= m - 1;
        let l = (base + j) & (PACKET - 1);
        if WORK {
            entered.push((l, tns[j], n as u32));
        }
        let (t, pr) = (soa.tmax[l], soa.prim[l]);
        limit[j] = if pr == u32::MAX { t } else { t.next_up() };
    }
    if few {
        return (false, mask);
    }
    let [ox, oy, oz] = [0, 1, 2].map(|a| load(&soa.o[a]));
    let [dx, dy, dz] = [0, 1, 2].map(|a| load(&soa.d[a]));
    let (zero, one) = unsafe { (L::splat(0.0), L::splat(1.0)) };
    let mut lim = unsafe { L::load(limit.as_ptr()) };
    let mut changed = false;
    for k in 0..n {
        let Some(b) = blocks.get(k / 4) else {
            break;
        };
        let (v0, e1, e2) = b.corners();
        let (t, mut hit) = unsafe {
            // lane `k & 3` read from memory (a broadcast), not through `Vec4`'s `Index`, whose
            // `match` becomes a jump on the lane, mispredicted as the lanes take turns
            let sp = |x: &[Vec4; 3], a: usize| {
                let row: &[f32; 4] = x[a % 3].as_ref();
                L::splat(row[k & 3])
            };
            let (e1x, e1y, e1z) = (sp(e1, 0), sp(e1, 1), sp(e1, 2));
            let (e2x, e2y, e2z) = (sp(e2, 0), sp(e2, 1), sp(e2, 2));
            let (mul, sub, add) = (L::mul, L::sub, L::add);
            // p = dir x e2
            let px = sub(mul(dy, e2z), mul(dz, e2y));
            let py = sub(mul(dz, e2x), mul(dx, e2z));
            let pz = sub(mul(dx, e2y), mul(dy, e2x));
            let det = add(add(mul(e1x, px), mul(e1y, py)), mul(e1z, pz));
            let inv = L::div(one, det);
            let sx = sub(ox, sp(v0, 0));
            let sy = sub(oy, sp(v0, 1));
            let sz = sub(oz, sp(v0, 2));
            let u = mul(add(add(mul(sx, px), mul(sy, py)), mul(sz, pz)), inv);
            // q = s x e1
            let qx = sub(mul(sy, e1z), mul(sz, e1y));
            let qy = sub(mul(sz, e1x), mul(sx, e1z));
            let qz = sub(mul(sx, e1y), mul(sy, e1x));
            let v = mul(add(add(mul(dx, qx), mul(dy, qy)), mul(dz, qz)), inv);
            let t = mul(add(add(mul(e2x, qx), mul(e2y, qy)), mul(e2z, qz)), inv);
            let and = |a, b| L::and(a, b);
            let ok = and(
                and(
                    and(L::ne(det, zero), inside),
                    and(L::ge(u, zero), L::le(u, one)),
                ),
                and(
                    and(L::not_lt(v, zero), L::not_gt(add(u, v), one)),
                    and(L::gt(t, zero), L::lt(t, lim)),
                ),
            );
            (t, L::bits(ok))
        };
        if hit == 0 {
            continue;
        }
        let mut ts = [0.0f32; PACKET];
        unsafe { L::store(ts.as_mut_ptr(), t) };
        let pk = b.prim(k & 3);
        while hit != 0 {
            let j = hit.trailing_zeros() as usize & (PACKET - 1);
            hit &= hit - 1;
            let l = (base + j) & (PACKET - 1);
            if ts[j] < soa.tmax[l] || pk < soa.prim[l] {
                soa.tmax[l] = ts[j];
                soa.prim[l] = pk;
                limit[j] = ts[j].next_up();
                changed = true;
            }
        }
        lim = unsafe { L::load(limit.as_ptr()) };
    }
    (changed, 0)
}

/// What a packet query leaves for each of its rays.
pub(crate) trait Answer: Sized {
    /// Any-hit queries: a ray is done at its first hit (its lanes then enter no more boxes).
    const ANY: bool;
    /// The answer for `ray` alone, from the single-ray query.
    fn single(scene: &Scene, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Self;
    /// The answer for a ray once the packet's traversal of the scene's own BVH is done with it.
    fn finish(scene: &Scene, left: Left<'_>, scratch: &mut Scratch) -> Self;
    /// [`Answer::finish`] in a scene without mesh instances and planes, whose answers are the
    /// BVH's: `prim` at `t` (`u32::MAX`: none).
    fn plain(t: f32, prim: u32) -> Self;
}

/// What the packet's traversal of the scene's own BVH left for a ray: `prim` at `t`
/// (`u32::MAX`: nothing before `t`, which is then its bound `tmax`).
pub(crate) struct Left<'r> {
    ray: &'r Ray,
    tmax: f32,
    t: f32,
    prim: u32,
}

/// Closest hits: what [`Scene::intersect_with`] returns.
impl Answer for Option<Hit> {
    const ANY: bool = false;
    fn single(scene: &Scene, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Self {
        scene.intersect_with(ray, tmax, scratch)
    }
    fn finish(scene: &Scene, left: Left<'_>, scratch: &mut Scratch) -> Self {
        let Left { ray, t, prim, .. } = left;
        scene.finish_closest(ray, t, prim, scratch)
    }
    #[inline(always)]
    fn plain(t: f32, prim: u32) -> Self {
        (prim != u32::MAX).then_some(Hit {
            t,
            prim,
            instance: Hit::NO_INSTANCE,
        })
    }
}

/// Occlusion: what [`Scene::occluded_with`] returns. A primitive of the scene's own BVH hit
/// before the bound is what its any-hit traversal looks for (the same tests on the same
/// interval), and the mesh instances and planes are then asked as it asks them.
impl Answer for bool {
    const ANY: bool = true;
    fn single(scene: &Scene, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Self {
        scene.occluded_with(ray, tmax, scratch)
    }
    fn finish(scene: &Scene, left: Left<'_>, scratch: &mut Scratch) -> Self {
        let Left {
            ray, tmax, prim, ..
        } = left;
        prim != u32::MAX || scene.occluded_beyond_bvh(ray, tmax, scratch).is_some()
    }
    #[inline(always)]
    fn plain(_: f32, prim: u32) -> Self {
        prim != u32::MAX
    }
}

/// A packet query: `out`'s answer for `rays[i]` is the single-ray query's with the bound
/// `tmax(i)`, for every `i < min(rays.len(), out.len())`. Unless `every_ray`, incoherent
/// packets ([`Summary::coherent`]) and sign groups of fewer than [`MIN_GROUP`] rays are traced one ray
/// at a time; with `every_ray` all go through the packet traversal, and then the work a ray
/// adds to `scratch.work` does not depend on the other rays of its packet (see [`traverse`]);
/// without it, the packet traversal adds no work.
///
/// A packet is first loaded into its rows ([`Soa`]), and what decides its path (its spreads,
/// its direction signs, a NaN) is read from them ([`Summary`]): a packet of one sign class
/// (nearly every tile of eye rays, and their shadow rays) is traced from those rows as loaded.
pub(crate) fn trace<A: Answer>(
    scene: &Scene,
    rays: &[Ray],
    tmax: impl Fn(usize) -> f32,
    scratch: &mut Scratch,
    out: &mut [A],
    every_ray: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if use_avx() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        unsafe { trace_avx(scene, rays, tmax, scratch, out, every_ray) };
        return;
    }
    trace_in(scene, rays, tmax, scratch, out, every_ray);
}

/// [`trace_in`] compiled with AVX and FMA (three-operand forms of the same operations on the
/// same values: Rust contracts no multiply and add into a fused one by itself).
///
/// # Safety
/// The CPU must have AVX and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,fma")]
unsafe fn trace_avx<A: Answer>(
    scene: &Scene,
    rays: &[Ray],
    tmax: impl Fn(usize) -> f32,
    scratch: &mut Scratch,
    out: &mut [A],
    every_ray: bool,
) {
    trace_in(scene, rays, tmax, scratch, out, every_ray);
}

/// [`trace`], compiled for the caller's features.
#[inline(always)]
fn trace_in<A: Answer>(
    scene: &Scene,
    rays: &[Ray],
    tmax: impl Fn(usize) -> f32,
    scratch: &mut Scratch,
    out: &mut [A],
    every_ray: bool,
) {
    let n = rays.len().min(out.len());
    let b = scene.bounds();
    let size = (b.max - b.min).max_element();
    for start in (0..n).step_by(PACKET) {
        let end = (start + PACKET).min(n);
        let rays = &rays[start..end];
        let k = rays.len();
        let mut bounds = [0.0f32; PACKET];
        for (i, b) in bounds.iter_mut().enumerate().take(k) {
            *b = tmax(start + i);
        }
        if !every_ray && !directions_close(rays) {
            let all = (1u32 << k) - 1;
            singles(scene, rays, all, &bounds, scratch, start, out);
            continue;
        }
        let mut soa = Soa::empty();
        for (g, four) in rays.chunks(4).enumerate() {
            soa.fill4(g, four);
        }
        soa.pad(k);
        let sum = Summary::of(&soa);
        if !every_ray && !sum.coherent(size) {
            let all = (1u32 << k) - 1;
            singles(scene, rays, all, &bounds, scratch, start, out);
            continue;
        }
        if let (false, Some(class)) = (sum.nan, sum.class()) {
            if !scene.bvh.nodes.is_empty() && (every_ray || k >= MIN_GROUP) {
                soa.tmax[..k].copy_from_slice(&bounds[..k]);
                let idx: [usize; PACKET] = std::array::from_fn(|j| j);
                let run = Run {
                    scene,
                    rays,
                    idx: &idx[..k],
                    class,
                    tmax: &bounds,
                    every_ray,
                };
                run.go(&mut soa, scratch, start, out);
                continue;
            }
        }
        // group by direction signs; small groups go one ray at a time
        let mut groups = [0u32; 8];
        for (i, r) in rays.iter().enumerate() {
            groups[signs(r)] |= 1 << i;
        }
        for (class, &members) in groups.iter().enumerate() {
            if members == 0 {
                continue;
            }
            let single = !every_ray && (members.count_ones() as usize) < MIN_GROUP;
            if single || scene.bvh.nodes.is_empty() {
                singles(scene, rays, members, &bounds, scratch, start, out);
            } else {
                group(
                    scene, rays, members, class, &bounds, scratch, start, out, every_ray,
                );
            }
        }
    }
}

/// Whether the directions of `rays` are within [`DIR_SPREAD`] of each other on every axis
/// (false for a NaN): the first test of [`Summary::coherent`], made before a packet is loaded
/// so that incoherent rays (most of them fail it) cost little more than one by one.
#[inline(always)]
fn directions_close(rays: &[Ray]) -> bool {
    let Some(r0) = rays.first() else {
        return true;
    };
    let (mut lo, mut hi) = (r0.dir, r0.dir);
    for r in rays {
        // the ray second: a NaN there is kept (_mm_min_ps gives its second operand then)
        (lo, hi) = (lo.min(r.dir), hi.max(r.dir));
    }
    (hi - lo).max_element() <= DIR_SPREAD
}

/// What decides a loaded packet's path, read from its rows in one pass: the least and the
/// greatest origin and direction per axis, whether some origin or direction holds a NaN, and
/// per axis the lanes whose direction is negative (as [`signs`] reads it).
struct Summary {
    o: [[f32; 3]; 2],
    d: [[f32; 3]; 2],
    nan: bool,
    neg: [u32; 3],
}

impl Summary {
    /// The summary of `soa`'s sixteen lanes (padding lanes are copies of lane 0).
    #[inline(always)]
    fn of(soa: &Soa) -> Summary {
        let mut nan = Vec4::ZERO.cmpne(Vec4::ZERO);
        let mut sum = Summary {
            o: [[0.0; 3]; 2],
            d: [[0.0; 3]; 2],
            nan: false,
            neg: [0; 3],
        };
        /// (least, greatest) of a row, and the lanes that are NaN.
        #[inline(always)]
        fn bounds(row: &[f32; PACKET], nan: &mut glam::BVec4A) -> (f32, f32) {
            let (mut lo, mut hi) = (Vec4::from_slice(row), Vec4::from_slice(row));
            for q in row.chunks_exact(4) {
                let v = Vec4::from_slice(q);
                *nan |= v.cmpne(v);
                (lo, hi) = (lo.min(v), hi.max(v));
            }
            (lo.min_element(), hi.max_element())
        }
        for a in 0..3 {
            (sum.o[0][a], sum.o[1][a]) = bounds(&soa.o[a], &mut nan);
            (sum.d[0][a], sum.d[1][a]) = bounds(&soa.d[a], &mut nan);
            let mut neg = 0;
            for (i, q) in soa.inv[a].chunks_exact(4).enumerate() {
                neg |= Vec4::from_slice(q).cmplt(Vec4::ZERO).bitmask() << (4 * i);
            }
            sum.neg[a] = neg;
        }
        sum.nan = nan.any();
        sum
    }

    /// Whether the packet's rays are coherent enough for a packet traversal (`size`: the scene's largest extent): no
    /// NaN, directions within [`DIR_SPREAD`] and origins within [`ORIGIN_SPREAD`] times the
    /// size on every axis.
    #[inline(always)]
    fn coherent(&self, size: f32) -> bool {
        let spread = |x: &[[f32; 3]; 2]| (0..3).fold(0.0f32, |m, a| m.max(x[1][a] - x[0][a]));
        !self.nan
            && spread(&self.d) <= DIR_SPREAD
            && (!size.is_finite() || spread(&self.o) <= ORIGIN_SPREAD * size)
    }

    /// The packet's sign class when all its rays have the same direction signs.
    #[inline(always)]
    fn class(&self) -> Option<usize> {
        let mut class = 0;
        for (a, &m) in self.neg.iter().enumerate() {
            match m & 0xffff {
                0 => {}
                0xffff => class |= 1 << a,
                _ => return None,
            }
        }
        Some(class)
    }
}

/// The rays `members` of a packet (bit `i` for `rays[i]`, with the bound `tmax[i]`) one at a
/// time; ray `i`'s answer goes to `out`'s `at + i`.
fn singles<A: Answer>(
    scene: &Scene,
    rays: &[Ray],
    members: u32,
    tmax: &[f32; PACKET],
    scratch: &mut Scratch,
    at: usize,
    out: &mut [A],
) {
    let mut m = members;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if let (Some(r), Some(&b), Some(o)) = (rays.get(i), tmax.get(i), out.get_mut(at + i)) {
            *o = A::single(scene, r, b, scratch);
        }
    }
}

/// One sign class of a packet of mixed signs (`members`: bit `i` for `rays[i]`, all with the
/// signs `class`, with the bound `tmax[i]`), gathered into a packet of its own and traced; its
/// answer goes to `out`'s `at + i`.
#[allow(clippy::too_many_arguments)]
fn group<A: Answer>(
    scene: &Scene,
    rays: &[Ray],
    members: u32,
    class: usize,
    tmax: &[f32; PACKET],
    scratch: &mut Scratch,
    at: usize,
    out: &mut [A],
    every_ray: bool,
) {
    let mut soa = Soa::empty();
    let mut idx = [0usize; PACKET];
    let mut m = members;
    let mut k = 0usize;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if let (Some(r), Some(slot)) = (rays.get(i), idx.get_mut(k)) {
            soa.set(k, r, tmax[i & 15]);
            *slot = i;
            k += 1;
        }
    }
    if k == 0 {
        return;
    }
    // lanes past the rays: copies of the first ray (so that the packet's bounds are the
    // rays'), never entering a box
    soa.pad(k);
    for (t, &i) in soa.tmax.iter_mut().zip(&idx).take(k) {
        *t = tmax[i & 15];
    }
    let run = Run {
        scene,
        rays,
        idx: &idx[..k],
        class,
        tmax,
        every_ray,
    };
    run.go(&mut soa, scratch, at, out);
}

/// A loaded packet of one sign class, to be traced: lane `j` is `rays[idx[j]]`, whose bound is
/// `tmax[idx[j]]`.
struct Run<'a> {
    scene: &'a Scene,
    rays: &'a [Ray],
    idx: &'a [usize],
    class: usize,
    tmax: &'a [f32; PACKET],
    every_ray: bool,
}

impl Run<'_> {
    /// Traces the packet loaded in `soa` (its lanes past `idx`: padding, bound -inf); ray `i`'s
    /// answer goes to `out`'s `at + i`.
    #[inline(always)]
    fn go<A: Answer>(&self, soa: &mut Soa, scratch: &mut Scratch, at: usize, out: &mut [A]) {
        let Run {
            scene,
            rays,
            idx,
            class,
            tmax,
            every_ray,
        } = *self;
        let f = Frustum::of(soa, class, A::ANY);
        #[cfg(test)]
        probe::add(5, 1);
        #[cfg(target_arch = "x86_64")]
        if use_avx512() {
            // SAFETY: the CPU has AVX, FMA and AVX-512F (checked just above).
            unsafe { traverse_avx512(scene, rays, idx, &f, soa, scratch, every_ray) };
        } else if use_avx() {
            // SAFETY: the CPU has AVX and FMA (checked just above).
            unsafe { traverse_avx(scene, rays, idx, &f, soa, scratch, every_ray) };
        } else if every_ray {
            traverse::<false, false, true>(scene, rays, idx, &f, soa, scratch);
        } else {
            traverse::<false, false, false>(scene, rays, idx, &f, soa, scratch);
        }
        #[cfg(not(target_arch = "x86_64"))]
        if every_ray {
            traverse::<false, false, true>(scene, rays, idx, &f, soa, scratch);
        } else {
            traverse::<false, false, false>(scene, rays, idx, &f, soa, scratch);
        }
        if scene.instances.is_empty() && scene.planes.is_empty() {
            for (j, &i) in idx.iter().enumerate() {
                if let Some(o) = out.get_mut(at + i) {
                    *o = A::plain(soa.tmax[j & 15], soa.prim[j & 15]);
                }
            }
            return;
        }
        for (j, &i) in idx.iter().enumerate() {
            let (t, prim) = (soa.tmax[j & 15], soa.prim[j & 15]);
            if let (Some(r), Some(o)) = (rays.get(i), out.get_mut(at + i)) {
                let left = Left {
                    ray: r,
                    tmax: tmax[i & 15],
                    t,
                    prim,
                };
                *o = A::finish(scene, left, scratch);
            }
        }
    }
}

impl Frustum {
    /// The node test's bounds of the rays loaded in `soa` (sign class `class`; padding lanes
    /// copies of lane 0), shared-origin ones when every lane starts at lane 0's origin and no
    /// reciprocal is huge; `any` for any-hit queries.
    #[inline(always)]
    fn of(soa: &Soa, class: usize, any: bool) -> Frustum {
        let mut f = Frustum {
            near: [0; 3],
            far: [0; 3],
            inv_lo: [0.0; 3],
            inv_hi: [0.0; 3],
            oinv_lo: [0.0; 3],
            oinv_hi: [0.0; 3],
            shared: false,
            o: [0.0; 3],
            k: [0.0; 3],
            any,
        };
        let mut same = true;
        let mut tame = true;
        for a in 0..3 {
            let neg = class & (1 << a) != 0;
            f.near[a] = if neg { 3 + a } else { a };
            f.far[a] = if neg { a } else { 3 + a };
            f.inv_lo[a] = row_min(&soa.inv[a]);
            f.inv_hi[a] = row_max(&soa.inv[a]);
            f.oinv_lo[a] = row_min(&soa.oinv[a]);
            f.oinv_hi[a] = row_max(&soa.oinv[a]);
            f.o[a] = soa.o[a][0];
            let o = Vec4::splat(f.o[a]);
            for q in soa.o[a].chunks_exact(4) {
                same &= Vec4::from_slice(q).cmpeq(o).all();
            }
            let wide = f.inv_lo[a].abs().max(f.inv_hi[a].abs());
            tame &= wide < 1e6;
            f.k[a] = ROUNDING * wide;
        }
        f.shared = same && tame;
        if !f.shared {
            (f.o, f.k) = ([0.0; 3], [0.0; 3]);
        }
        f
    }
}

/// [`traverse`] compiled with AVX, counting work when `work` is set.
///
/// # Safety
/// The CPU must have AVX and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,fma")]
unsafe fn traverse_avx(
    scene: &Scene,
    rays: &[Ray],
    idx: &[usize],
    f: &Frustum,
    soa: &mut Soa,
    scratch: &mut Scratch,
    work: bool,
) {
    if work {
        traverse::<true, false, true>(scene, rays, idx, f, soa, scratch);
    } else {
        traverse::<true, false, false>(scene, rays, idx, f, soa, scratch);
    }
}

/// [`traverse`] compiled with AVX-512F too, whose leaf tests take the sixteen rays of a packet
/// in one vector (the same operations on each lane, so the same bits, as eight to a vector),
/// counting work when `work` is set.
///
/// # Safety
/// The CPU must have AVX, FMA and AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,fma,avx512f")]
unsafe fn traverse_avx512(
    scene: &Scene,
    rays: &[Ray],
    idx: &[usize],
    f: &Frustum,
    soa: &mut Soa,
    scratch: &mut Scratch,
    work: bool,
) {
    if work {
        traverse::<true, true, true>(scene, rays, idx, f, soa, scratch);
    } else {
        traverse::<true, true, false>(scene, rays, idx, f, soa, scratch);
    }
}

/// The packet traversal of the scene's own BVH for the rays `idx` (lane `j` is `rays[idx[j]]`);
/// leaves each ray's nearest hit in its lane of `soa`.
///
/// Work ([`Scratch::work`]): each ray is charged one unit plus the leaf's size for every leaf
/// whose box it enters before its final nearest hit. That set does not depend on the order the
/// leaves were met in, nor on the other rays of the packet (all of them are met, since a ray's
/// bound never falls below its final hit), so a pixel costs the same in any tile. In an
/// any-hit query ([`Frustum::any`]) a ray is charged for every leaf it met. Without `WORK`
/// nothing is recorded or charged.
// Longer than 80 lines, kept whole: the packet traversal's loop, run per node. The node
// test, the leaf tests and the stacking share its state (the packet's bound, the stack and
// its pointer, the mailboxes, the children being sorted), which must stay in registers;
// split, its parts would pass it by reference, which only an instruction count before and
// after could clear (docs/testing.md; tests/function_length.rs lists it).
#[inline(always)]
fn traverse<const AVX: bool, const WIDE: bool, const WORK: bool>(
    scene: &Scene,
    rays: &[Ray],
    idx: &[usize],
    f: &Frustum,
    soa: &mut Soa,
    scratch: &mut Scratch,
) {
    // (lane, entry distance, leaf size) of every leaf a ray tested, kept in the scratch
    // between packets (no allocation per packet)
    let entered = &mut scratch.entered;
    entered.clear();
    let nodes = &scene.bvh.nodes;
    let mut mailboxes = [Mailbox::default(); PACKET];
    let mut tmax = soa.max_tmax();
    let stack = &mut scratch.stack;
    let mut sp = 0usize;
    let mut cur = 0u32;
    loop {
        if let Some(node) = nodes.get(cur as usize) {
            #[cfg(test)]
            probe::add(0, 1);
            #[cfg(target_arch = "x86_64")]
            let (tn, mut mask) = if AVX {
                // SAFETY: AVX is only set by traverse_avx and traverse_avx512, which run only
                // where the CPU has AVX2 and FMA (use_avx, use_avx512).
                unsafe { node_avx(node, f, tmax) }
            } else {
                node_sse(node, f, tmax)
            };
            #[cfg(not(target_arch = "x86_64"))]
            let (tn, mut mask) = node_sse(node, f, tmax);
            let (child, count) = (node.children(), node.counts());
            // leaves at once, inner nodes kept sorted far to near
            let mut it = [0.0f32; WIDTH];
            let mut ic = [0u32; WIDTH];
            let mut ni = 0usize;
            while mask != 0 {
                let i = mask.trailing_zeros() as usize & 7;
                mask &= mask - 1;
                let c = count[i];
                if c == 0 {
                    let mut j = ni;
                    while j > 0 && it[(j - 1) & 7] < tn[i] {
                        it[j & 7] = it[(j - 1) & 7];
                        ic[j & 7] = ic[(j - 1) & 7];
                        j -= 1;
                    }
                    it[j & 7] = tn[i];
                    ic[j & 7] = child[i];
                    ni += 1;
                } else if c != EMPTY && tn[i] <= tmax {
                    let first = child[i] as usize;
                    // a leaf of triangle blocks names its first block, not its first primitive
                    let n = crate::bvh::block_leaf_len(c as usize).unwrap_or(c as usize);
                    #[cfg(target_arch = "x86_64")]
                    if let (true, Some(blocks)) = (AVX, scene.tri_blocks.leaf(first, c as usize)) {
                        let mut changed = false;
                        let width = if WIDE { Avx16::N } else { Avx8::N };
                        for part in 0..idx.len().div_ceil(width) {
                            // SAFETY: AVX is only set by traverse_avx, and WIDE by
                            // traverse_avx512, which run where the CPU has AVX and FMA, and
                            // AVX-512F as well.
                            let (ch, mut left) = unsafe {
                                if WIDE {
                                    leaf_lanes::<Avx16, WORK>(
                                        node, i, f, soa, part, blocks, n, entered,
                                    )
                                } else {
                                    leaf_lanes::<Avx8, WORK>(
                                        node, i, f, soa, part, blocks, n, entered,
                                    )
                                }
                            };
                            changed |= ch;
                            // the few rays that entered: one at a time, by blocks of four
                            while left != 0 {
                                let l = (width * part + left.trailing_zeros() as usize) & 15;
                                left &= left - 1;
                                if let Some(r) = idx.get(l).and_then(|&ri| rays.get(ri)) {
                                    let t = scene.leaf_closest(
                                        first,
                                        c as usize,
                                        r,
                                        &RayLanes::new(r),
                                        &mut mailboxes[l],
                                        soa.tmax[l],
                                        &mut soa.prim[l],
                                    );
                                    changed |= t != soa.tmax[l];
                                    soa.tmax[l] = t;
                                }
                            }
                        }
                        if changed {
                            tmax = soa.bound_after_leaf(f.any);
                        }
                        continue;
                    }
                    for (lane, (&ri, mb)) in idx.iter().zip(mailboxes.iter_mut()).enumerate() {
                        let l = lane & 15;
                        if let Some(t) = enters(node, i, f, soa.lane(l), soa.tmax[l]) {
                            if let Some(r) = rays.get(ri) {
                                if WORK {
                                    entered.push((l, t, n as u32));
                                }
                                soa.tmax[l] = scene.leaf_closest(
                                    first,
                                    c as usize,
                                    r,
                                    &RayLanes::new(r),
                                    mb,
                                    soa.tmax[l],
                                    &mut soa.prim[l],
                                );
                            }
                        }
                    }
                    tmax = soa.bound_after_leaf(f.any);
                }
            }
            if ni > 0 {
                if stack.len() < sp + WIDTH {
                    stack.resize(sp + 64, (0, 0, 0.0));
                }
                for j in 0..ni - 1 {
                    if let Some(slot) = stack.get_mut(sp) {
                        *slot = (ic[j & 7], 0, it[j & 7]);
                        sp += 1;
                    }
                }
                cur = ic[(ni - 1) & 7];
                continue;
            }
        }
        // pop the next inner node that some ray may still enter before its nearest hit
        loop {
            if sp == 0 {
                if !WORK {
                    return;
                }
                let mut w = 0u64;
                for &(lane, t, c) in entered.iter() {
                    // (an any-hit query's closed lanes: every leaf they met)
                    if f.any || t <= soa.tmax[lane & 15] {
                        w += 1 + c as u64;
                    }
                }
                scratch.work += w;
                return;
            }
            sp -= 1;
            let (c, _, d) = stack[sp];
            if d <= tmax {
                cur = c;
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::geometry::Shape;
    use crate::material::Material;
    use crate::scene::SceneBuilder;
    use glam::Vec3A;
    use std::path::Path;

    use crate::test_support::rng;

    fn v(seed: &mut u64) -> Vec3A {
        Vec3A::new(rng(seed), rng(seed), rng(seed))
    }

    /// Hits agree bit for bit; among the pieces of one long cone (several references to the
    /// same shape, which the mailbox tests once) either reference names the same surface.
    fn same(scene: &Scene, a: Option<Hit>, b: Option<Hit>) -> bool {
        match (a, b) {
            (None, None) => true,
            (Some(a), Some(b)) => {
                let shapes = &scene.geom.shapes;
                let cone_piece = a.instance == Hit::NO_INSTANCE
                    && b.instance == Hit::NO_INSTANCE
                    && matches!(
                        (shapes.get(a.prim as usize), shapes.get(b.prim as usize)),
                        (Some(Shape::Cone(x)), Some(Shape::Cone(y))) if x == y
                    );
                a.t.to_bits() == b.t.to_bits()
                    && a.instance == b.instance
                    && (a.prim == b.prim || cone_piece)
            }
            _ => false,
        }
    }

    /// Every packet of `rays` (in sixteens, and in every partial size from the start of each
    /// sixteen) against single rays; returns the number of hits.
    fn check(scene: &Scene, rays: &[Ray], tmax: f32, partial: bool) -> usize {
        let mut scratch = Scratch::new();
        let want: Vec<Option<Hit>> = rays
            .iter()
            .map(|r| scene.intersect_with(r, tmax, &mut scratch))
            .collect();
        let mut got = vec![None; rays.len()];
        scene.intersect_packet(rays, tmax, &mut scratch, &mut got);
        let mut all = vec![None; rays.len()];
        trace(scene, rays, |_| tmax, &mut scratch, &mut all[..], true);
        for (i, (w, a)) in want.iter().zip(&all).enumerate() {
            assert!(
                same(scene, *w, *a),
                "ray {i}, all in packets: {w:?} != {a:?}"
            );
        }
        for (i, (w, g)) in want.iter().zip(&got).enumerate() {
            assert!(same(scene, *w, *g), "ray {i} {:?}: {w:?} != {g:?}", rays[i]);
        }
        if partial {
            for (c, chunk) in rays.chunks(PACKET).enumerate().step_by(7) {
                for len in 1..chunk.len() {
                    let mut out = vec![None; len];
                    scene.intersect_packet(&chunk[..len], tmax, &mut scratch, &mut out);
                    for (k, g) in out.iter().enumerate() {
                        let w = want[c * PACKET + k];
                        assert!(same(scene, w, *g), "partial {len}, ray {k}: {w:?} != {g:?}");
                    }
                }
            }
        }
        // occlusion, with a bound per ray: some at the nearest hit (which then does not count),
        // some just past it
        let bounds: Vec<f32> = want
            .iter()
            .enumerate()
            .map(|(i, w)| match (w, i % 3) {
                (Some(h), 0) => h.t,
                (Some(h), 1) => h.t.next_up(),
                _ => tmax,
            })
            .collect();
        let occluded: Vec<bool> = rays
            .iter()
            .zip(&bounds)
            .map(|(r, &b)| scene.occluded_with(r, b, &mut scratch))
            .collect();
        let mut got = vec![false; rays.len()];
        trace(
            scene,
            rays,
            |i| bounds[i],
            &mut scratch,
            &mut got[..],
            false,
        );
        let mut all = vec![false; rays.len()];
        trace(scene, rays, |i| bounds[i], &mut scratch, &mut all[..], true);
        for (i, ((w, g), a)) in occluded.iter().zip(&got).zip(&all).enumerate() {
            assert!(w == g && w == a, "ray {i}, occluded: {w} {g} {a}");
        }
        want.iter().filter(|h| h.is_some()).count()
    }

    /// Coherent bundles: 4 x 4 directions around a random one from near one origin (some with
    /// mixed signs), plus rays sharing an exact origin.
    fn bundles(seed: &mut u64, centre: Vec3A, size: f32, count: usize) -> Vec<Ray> {
        let mut rays = Vec::with_capacity(count * PACKET);
        for b in 0..count {
            let o = centre + v(seed) * size * 2.0;
            let aim = centre + v(seed) * size * 0.5;
            let d = (aim - o).normalize_or(Vec3A::Z);
            let spread = [0.002, 0.02, 0.2][b % 3];
            let jitter = if b % 2 == 0 { 0.0 } else { size * 0.01 };
            for _ in 0..PACKET {
                rays.push(Ray::new(o + v(seed) * jitter, d + v(seed) * spread));
            }
        }
        rays
    }

    /// [`rays_enter`] at the width `L` against [`enters`], lane by lane, distances bit for bit.
    ///
    /// # Safety
    /// The CPU must have the width's features.
    #[cfg(target_arch = "x86_64")]
    unsafe fn rays_enter_agrees<L: Lanes>(
        node: &Node8,
        f: &Frustum,
        soa: &Soa,
        lanes: &[([f32; 3], [f32; 3])],
        tmax: f32,
    ) {
        for i in 0..WIDTH {
            for part in 0..PACKET / L::N {
                // SAFETY: the caller's CPU has the width's features; `tl` is 16 f32.
                let (tl, bits) = unsafe {
                    let (t, inside) = rays_enter::<L>(node, i, f, soa, part);
                    let mut tl = [0.0f32; PACKET];
                    L::store(tl.as_mut_ptr(), t);
                    (tl, L::bits(inside))
                };
                for (j, l) in lanes.iter().enumerate().skip(L::N * part).take(L::N) {
                    let k = j - L::N * part;
                    let want = enters(node, i, f, *l, tmax);
                    assert_eq!((bits >> k) & 1 != 0, want.is_some(), "{} lanes", L::N);
                    if let Some(w) = want {
                        assert_eq!(tl[k].to_bits(), w.to_bits(), "{} lanes", L::N);
                    }
                }
            }
        }
    }

    #[test]
    fn packets_equal_single_rays_on_random_scenes() {
        probe::COUNTS.with(|c| c.set([0; 7]));
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut hits = 0;
        for round in 0..16 {
            // the last rounds build with a split cost of a whole node visit: bigger leaves, more
            // of them met by only a few of a packet's rays (the per-ray test at leaves)
            if round == 12 {
                crate::bvh::probe::SPLIT.with(|c| c.set(1.0));
            }
            let mut b = SceneBuilder::new();
            let m = b.material(Material::default());
            let n = [50, 400, 3000][round % 3];
            for k in 0..n {
                let c = v(&mut seed) * 3.0;
                let s = 0.05 + 0.3 * rng(&mut seed).abs();
                let mut tri = [
                    c + v(&mut seed) * s,
                    c + v(&mut seed) * s,
                    c + v(&mut seed) * s,
                ];
                if k % 11 == 0 {
                    // axis-aligned triangles, whose boxes are flat
                    tri.iter_mut().for_each(|p| p.y = c.y);
                }
                b.triangle(tri, None, m).unwrap();
                if round % 2 == 1 && k % 9 == 0 {
                    // other primitive kinds: the per-ray leaf test
                    b.sphere(c, s * 0.5, m).unwrap();
                    let apex = c + v(&mut seed) * 2.0;
                    b.cone(c, s * 0.3, apex, s * 0.1, m).unwrap();
                }
            }
            if round % 4 == 3 {
                // a shared edge hit by many rays at equal distances
                for &(x, y) in &[(0.0f32, 0.0f32), (1.0, 0.0)] {
                    b.triangle(
                        [
                            Vec3A::new(x, y, 5.0),
                            Vec3A::new(x + 1.0, y, 5.0),
                            Vec3A::new(x, y + 1.0, 5.0),
                        ],
                        None,
                        m,
                    )
                    .unwrap();
                }
            }
            let scene = b.build("test").unwrap();
            let rays = bundles(&mut seed, Vec3A::ZERO, 3.0, 100);
            let tmax = if round % 5 == 4 { 4.0 } else { f32::INFINITY };
            hits += check(&scene, &rays, tmax, round < 3);
            // the SSE traversal where the AVX one would run, and eight lanes where sixteen would
            FORCE_SSE.with(|f| f.set(true));
            check(&scene, &rays, tmax, round < 3);
            FORCE_SSE.with(|f| f.set(false));
            FORCE_AVX2.with(|f| f.set(true));
            check(&scene, &rays, tmax, round < 3);
            FORCE_AVX2.with(|f| f.set(false));
            // random incoherent rays: mostly the sign groups and the single-ray fallback
            let rays: Vec<Ray> = (0..400)
                .map(|_| Ray::new(v(&mut seed) * 4.0, v(&mut seed)))
                .collect();
            hits += check(&scene, &rays, f32::INFINITY, false);
        }
        crate::bvh::probe::SPLIT.with(|c| c.set(crate::bvh::SPLIT_COST));
        assert!(hits > 5000, "{hits}");
        // both ways of meeting a leaf of blocks: across rays, and one ray at a time
        let c = probe::COUNTS.with(|c| c.get());
        if has_avx2_fma() {
            assert!(c[3] > 10_000 && c[6] > 1000, "{c:?}");
        }
    }

    /// Primary rays of an SPD scene in 4 x 4 tiles, as the renderer traces them, and bundles.
    fn spd_scene(name: &str, n: u32) {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes/spd");
        let scene = Scene::load(&dir.join(format!("{name}.nff"))).expect("SPD scene loads");
        let span = Camera::centre_span(n, n);
        let mut rays = Vec::new();
        for ty in (0..n).step_by(4) {
            for tx in (0..n).step_by(4) {
                for y in ty..ty + 4 {
                    for x in tx..tx + 4 {
                        rays.push(scene.camera.ray(x as f32 + 0.5, y as f32 + 0.5, n, n, span));
                    }
                }
            }
        }
        let hits = check(&scene, &rays, f32::INFINITY, true);
        assert!(hits > rays.len() / 10, "{name}: {hits}");
        FORCE_SSE.with(|f| f.set(true));
        check(&scene, &rays, f32::INFINITY, false);
        FORCE_SSE.with(|f| f.set(false));
        let mut seed = 0x1234_5678_9abc_def1u64;
        let b = scene.bounds();
        let size = (b.max - b.min).length() * 0.5;
        let rays = bundles(&mut seed, b.centre(), size, 100);
        check(&scene, &rays, f32::INFINITY, false);
    }

    #[test]
    fn packets_equal_single_rays_on_the_spd_scenes() {
        for name in [
            "balls_s4",
            "gears_s4",
            "mount_s6",
            "rings_s7",
            "teapot_s12",
            "tetra_s6",
            "tree_s11",
        ] {
            spd_scene(name, 96);
        }
    }

    /// Where a packet's time goes, on the meshes named in `PACKET_STATS` (colon-separated):
    /// `PACKET_STATS=a.obj:b.obj cargo test --release packet_stats -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn packet_stats() {
        let Ok(list) = std::env::var("PACKET_STATS") else {
            return;
        };
        for mesh in list.split(':') {
            let scene = Scene::load(Path::new(mesh)).expect("mesh loads");
            let b = scene.bounds();
            let primary = crate::raysets::primary(b, 1024);
            let rays: Vec<Ray> = crate::raysets::tile_order(1024)
                .iter()
                .map(|&i| primary[i as usize])
                .collect();
            let mut scratch = Scratch::new();
            crate::bvh::probe::NODES.with(|c| c.set(0));
            let mut leaves = 0u64;
            for r in &rays {
                scene
                    .bvh
                    .traverse::<true>(r, f32::INFINITY, &mut scratch, |first, count, tm| {
                        leaves += 1;
                        let mut prim = u32::MAX;
                        scene.leaf_closest(
                            first,
                            count,
                            r,
                            &RayLanes::new(r),
                            &mut Mailbox::default(),
                            tm,
                            &mut prim,
                        )
                    });
            }
            let nodes = crate::bvh::probe::NODES.with(|c| c.get());
            probe::COUNTS.with(|c| c.set([0; 7]));
            let mut out = vec![None; PACKET];
            for p in rays.chunks(PACKET) {
                scene.intersect_packet(p, f32::INFINITY, &mut scratch, &mut out);
            }
            let c = probe::COUNTS.with(|c| c.get());
            let n = rays.len() as f64;
            let pk = c[5] as f64;
            println!(
                "{mesh}: single: {:.1} nodes, {:.1} leaves per ray; packets {pk}: {:.1} node tests, \
                 {:.1} leaf calls (of 8 rays), {:.1} entered, {:.1} triangle tests (x 8 rays), \
                 {:.1} ray-leaf entries per packet ({:.1} per ray), {:.1} leaves one ray at a time",
                nodes as f64 / n,
                leaves as f64 / n,
                c[0] as f64 / pk,
                c[1] as f64 / pk,
                c[2] as f64 / pk,
                c[3] as f64 / pk,
                c[4] as f64 / pk,
                c[4] as f64 / n,
                c[6] as f64 / pk,
            );
        }
    }

    /// What the old per-ray reading of a packet said: coherent (directions within
    /// [`DIR_SPREAD`], origins within [`ORIGIN_SPREAD`] of `size`, no NaN), and its sign class
    /// when all rays share one.
    fn reference(rays: &[Ray], size: f32) -> (bool, bool, Option<usize>) {
        let r0 = rays[0];
        let (mut dlo, mut dhi, mut olo, mut ohi) = (r0.dir, r0.dir, r0.origin, r0.origin);
        for r in rays {
            (dlo, dhi) = (dlo.min(r.dir), dhi.max(r.dir));
            (olo, ohi) = (olo.min(r.origin), ohi.max(r.origin));
        }
        let nan = rays
            .iter()
            .any(|r| r.dir.is_nan_mask().any() || r.origin.is_nan_mask().any());
        let close = (dhi - dlo).max_element() <= DIR_SPREAD;
        let coherent = !nan && close && (ohi - olo).max_element() <= ORIGIN_SPREAD * size;
        let class = rays
            .iter()
            .all(|r| signs(r) == signs(&r0))
            .then(|| signs(&r0));
        (coherent, close || nan, class)
    }

    #[test]
    fn a_loaded_packet_reads_as_its_rays() {
        let mut seed = 0x5851_f42d_4c95_7f2du64;
        let (mut coherent, mut classes) = (0, 0);
        for round in 0..20_000 {
            let k = 1 + round % PACKET;
            let o = v(&mut seed);
            let d = v(&mut seed);
            let (jo, jd) = (
                [0.0, 0.005, 0.05][round % 3],
                [0.0, 0.02, 0.3][round % 5 % 3],
            );
            let mut rays: Vec<Ray> = (0..k)
                .map(|_| Ray::new(o + v(&mut seed) * jo, d + v(&mut seed) * jd))
                .collect();
            match round % 13 {
                // a NaN, a zero component (whose reciprocal is infinite) and a negative zero
                0 => rays[k / 2].dir.y = f32::NAN,
                1 => rays[k - 1].origin.z = f32::NAN,
                2 => rays
                    .iter_mut()
                    .for_each(|r| *r = Ray::new(r.origin, r.dir * Vec3A::new(1.0, 0.0, 1.0))),
                3 => rays
                    .iter_mut()
                    .for_each(|r| *r = Ray::new(r.origin, r.dir * Vec3A::new(-0.0, 1.0, 1.0))),
                _ => {}
            }
            let mut soa = Soa::empty();
            for (g, four) in rays.chunks(4).enumerate() {
                soa.fill4(g, four);
            }
            soa.pad(k);
            let sum = Summary::of(&soa);
            let (want, close, class) = reference(&rays, 2.0);
            if round % 13 > 1 {
                // (a NaN makes the packet incoherent, whatever else it reads)
                assert_eq!(directions_close(&rays), close, "round {round}");
            }
            assert_eq!(sum.coherent(2.0), want, "round {round}");
            assert_eq!(sum.class(), class, "round {round}");
            coherent += want as u32;
            classes += class.is_some() as u32;
            if let (Some(c), false) = (class, sum.nan) {
                let f = Frustum::of(&soa, c, false);
                let same = rays.iter().all(|r| r.origin == rays[0].origin);
                let tame = (0..3).all(|a| f.inv_lo[a].abs().max(f.inv_hi[a].abs()) < 1e6);
                assert_eq!(f.shared, same && tame, "round {round}");
                for a in 0..3 {
                    assert_eq!(f.inv_lo[a].to_bits(), row_min(&soa.inv[a]).to_bits());
                    assert_eq!(f.oinv_hi[a].to_bits(), row_max(&soa.oinv[a]).to_bits());
                }
            }
        }
        assert!(coherent > 3000 && classes > 10_000, "{coherent} {classes}");
    }

    #[test]
    fn the_packet_test_bounds_every_rays_own_test_and_avx_agrees() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let (mut entered, mut shared) = (0, 0);
        for round in 0..3000 {
            let mut node = Node8::empty_for_tests();
            for i in 0..WIDTH - round % 3 {
                for a in 0..3 {
                    let (x, y) = (rng(&mut seed) * 2.0, rng(&mut seed) * 2.0);
                    let flat = round % 4 == 0 && a == 1;
                    node.set_for_tests(i, a, x.min(y), if flat { x.min(y) } else { x.max(y) });
                }
            }
            let o = v(&mut seed) * 0.5;
            let d = v(&mut seed);
            // every other packet shares its origin: the shared-origin bounds
            let jitter = if round % 2 == 0 { 0.0 } else { 0.05 };
            let rays: Vec<Ray> = (0..PACKET)
                .map(|_| Ray::new(o + v(&mut seed) * jitter, d + v(&mut seed) * 0.1))
                .filter(|r| signs(r) == signs(&Ray::new(o, d)))
                .collect();
            if rays.is_empty() {
                continue;
            }
            let class = signs(&rays[0]);
            let neg = [class & 1 != 0, class & 2 != 0, class & 4 != 0];
            let mut f = Frustum {
                near: [0, 1, 2].map(|a| if neg[a] { 3 + a } else { a }),
                far: [0, 1, 2].map(|a| if neg[a] { a } else { 3 + a }),
                inv_lo: [f32::INFINITY; 3],
                inv_hi: [f32::NEG_INFINITY; 3],
                oinv_lo: [f32::INFINITY; 3],
                oinv_hi: [f32::NEG_INFINITY; 3],
                shared: false,
                o: [0.0; 3],
                k: [0.0; 3],
                any: false,
            };
            let tmax = if round % 2 == 0 { 2.0 } else { f32::INFINITY };
            let mut soa = Soa::empty();
            let lanes: Vec<([f32; 3], [f32; 3])> = rays
                .iter()
                .enumerate()
                .map(|(k, r)| {
                    let l = soa.set(k, r, tmax);
                    assert_eq!(l, soa.lane(k));
                    for a in 0..3 {
                        f.inv_lo[a] = f.inv_lo[a].min(l.0[a]);
                        f.inv_hi[a] = f.inv_hi[a].max(l.0[a]);
                        f.oinv_lo[a] = f.oinv_lo[a].min(l.1[a]);
                        f.oinv_hi[a] = f.oinv_hi[a].max(l.1[a]);
                    }
                    l
                })
                .collect();
            let tame = (0..3).all(|a| f.inv_lo[a].abs().max(f.inv_hi[a].abs()) < 1e6);
            if jitter == 0.0 && tame {
                f.shared = true;
                f.o = [o.x, o.y, o.z];
                f.k = [0, 1, 2].map(|a| ROUNDING * f.inv_lo[a].abs().max(f.inv_hi[a].abs()));
                shared += 1;
            }
            let (tn, mask) = node_sse(&node, &f, tmax);
            #[cfg(target_arch = "x86_64")]
            if has_avx2_fma() {
                // SAFETY: the CPU has AVX and FMA (checked on the line above).
                let (ta, ma) = unsafe { node_avx(&node, &f, tmax) };
                assert_eq!(mask, ma);
                assert_eq!(tn.map(f32::to_bits), ta.map(f32::to_bits));
            }
            // the leaves' test of the rays, lane by lane, against `enters`, at both widths
            #[cfg(target_arch = "x86_64")]
            if has_avx2_fma() {
                // SAFETY: the CPU has AVX and FMA (checked above).
                unsafe { rays_enter_agrees::<Avx8>(&node, &f, &soa, &lanes, tmax) };
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: and AVX-512F (checked on the line above).
                    unsafe { rays_enter_agrees::<Avx16>(&node, &f, &soa, &lanes, tmax) };
                }
            }
            for (r, l) in rays.iter().zip(&lanes) {
                // the ray's own test, as the single-ray traversal makes it
                let single = node.single_ray_test_for_tests(r, tmax);
                for (i, &t) in tn.iter().enumerate() {
                    assert_eq!(
                        enters(&node, i, &f, *l, tmax).is_some(),
                        single.1 & (1 << i) != 0
                    );
                    if single.1 & (1 << i) != 0 {
                        entered += 1;
                        assert!(mask & (1 << i) != 0, "round {round}: child {i} missed");
                        assert!(t <= single.0[i]);
                    }
                }
            }
        }
        assert!(entered > 10_000 && shared > 1000, "{entered} {shared}");
    }
}
