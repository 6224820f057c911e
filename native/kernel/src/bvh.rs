//! Bounding volume hierarchy: binned SAH build, 8-wide flattened nodes, ordered traversal.
//!
//! Build: a binary tree with binned SAH (16 bins on each axis, iterative, depth-capped) in
//! 32-byte nodes (box + first/count packed in the w lanes, children adjacent). It is then
//! collapsed into 8-wide nodes (`Node8`: the eight child boxes in SoA layout, 256 bytes, i.e.
//! 32 bytes per child) by repeatedly opening the child with the largest surface area. Leaves
//! reference contiguous ranges of the primitive array, which the scene reorders to BVH order.
//! Memory is O(primitives) (O(references): long oblique cones are referenced once per piece).
//! The same hierarchy serves two levels for mesh instances ([`crate::instance`]): one over the
//! instances' world boxes, whose leaf visits traverse a mesh's own hierarchy with a second
//! stack ([`Scratch`] holds both).
//!
//! Traversal tests the eight child boxes at once, with AVX where the CPU has it (detected at
//! run time; the whole traversal loop is then compiled for AVX) and otherwise with two SSE
//! vectors (`Vec4`; glam's scalar code off x86), the same operations on the same values either
//! way, so the same hits on every machine. Per ray, the reciprocal direction and the near/far
//! plane rows are chosen once (no min/max per axis, no branch per node). For closest-hit
//! queries the children that are hit are handled nearest first: leaves are intersected
//! immediately, the nearest inner child is descended into, the others are stacked with their
//! entry distance and skipped later if a closer hit was found. Shadow rays use the unordered
//! any-hit variant, which stops at the first occluder. The stack lives in a reusable
//! [`Scratch`], so no allocation happens per ray.

use crate::geometry::Aabb;
use crate::ray::Ray;
use glam::{Vec3A, Vec4};

/// Number of SAH bins per axis.
const BINS: usize = 16;
/// Leaves never hold more than this unless the primitives cannot be separated.
const MAX_LEAF: usize = 8;
/// Build depth cap (leaves below it are forced), bounding tree depth on pathological input.
pub(crate) const MAX_DEPTH: usize = 60;
/// Cost of one traversal step relative to one primitive test.
const TRAVERSAL_COST: f32 = 1.0;

/// Test-only instrumentation: node visits, leaf visits, tuning overrides.
#[cfg(test)]
pub(crate) mod probe {
    use std::cell::Cell;
    thread_local! {
        pub static NODES: Cell<u64> = const { Cell::new(0) };
        pub static TCOST: Cell<f32> = const { Cell::new(super::TRAVERSAL_COST) };
        pub static LEAF_MIN: Cell<usize> = const { Cell::new(0) };
    }
}

#[cfg(test)]
fn traversal_cost() -> f32 {
    probe::TCOST.with(|c| c.get())
}
#[cfg(not(test))]
fn traversal_cost() -> f32 {
    TRAVERSAL_COST
}
/// The tuning report's leaf size when it sets one (0: the builder's choice).
#[cfg(test)]
fn leaf_min(chosen: usize) -> usize {
    match probe::LEAF_MIN.with(|c| c.get()) {
        0 => chosen,
        lm => lm,
    }
}
#[cfg(not(test))]
fn leaf_min(chosen: usize) -> usize {
    chosen
}

/// A flattened node: `a = (min, first)`, `b = (max, count)` with the integers stored as f32 bits.
/// `count == 0` marks an interior node whose children are `first` and `first + 1`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct Node {
    a: Vec4,
    b: Vec4,
}

impl Node {
    fn new(bounds: Aabb, first: u32, count: u32) -> Node {
        Node {
            a: bounds.min.extend(f32::from_bits(first)),
            b: bounds.max.extend(f32::from_bits(count)),
        }
    }
    #[inline(always)]
    pub fn first(&self) -> u32 {
        self.a.w.to_bits()
    }
    #[inline(always)]
    pub fn count(&self) -> u32 {
        self.b.w.to_bits()
    }
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

/// Leaves at most this big are never split: for primitives tested one at a time.
pub(crate) const LEAF_MIN: usize = 2;
/// For triangles only, tested four at a time ([`crate::tri4`]): a leaf of up to four costs
/// one test.
pub(crate) const LEAF_MIN_TRIANGLES: usize = 4;

/// Binary binned-SAH build; returns the nodes and the primitive order.
fn build_binary(boxes: &[Aabb], leaf_min_chosen: usize) -> (Vec<Node>, Vec<u32>) {
    let n = boxes.len();
    let mut order: Vec<u32> = (0..n as u32).collect();
    if n == 0 {
        return (Vec::new(), order);
    }
    let centroids: Vec<Vec3A> = boxes.iter().map(|b| b.centre()).collect();
    let mut nodes = Vec::with_capacity(2 * n);
    nodes.push(Node::new(Aabb::EMPTY, 0, 0));
    // (node index, start, end, depth)
    let mut work: Vec<(usize, usize, usize, usize)> = vec![(0, 0, n, 0)];
    while let Some((ni, start, end, depth)) = work.pop() {
        let idx = &mut order[start..end];
        let mut bounds = Aabb::EMPTY;
        let mut cb = Aabb::EMPTY;
        for &i in idx.iter() {
            bounds = bounds.union(boxes[i as usize]);
            cb = cb.grow(centroids[i as usize]);
        }
        let count = end - start;
        let make_leaf = |nodes: &mut Vec<Node>| {
            nodes[ni] = Node::new(bounds, start as u32, count as u32);
        };
        if count <= leaf_min(leaf_min_chosen) || depth >= MAX_DEPTH {
            make_leaf(&mut nodes);
            continue;
        }
        let ext = cb.max - cb.min;
        // best split over all three axes
        let mut best = (f32::INFINITY, 0usize, 0usize); // cost, axis, bin
        for axis in 0..3 {
            let e = ext[axis];
            if e <= 0.0 {
                continue;
            }
            let lo = cb.min[axis];
            let scale = BINS as f32 / e * 0.999_99;
            let mut bins = [Bin {
                bounds: Aabb::EMPTY,
                count: 0,
            }; BINS];
            for &i in idx.iter() {
                let b = (((centroids[i as usize][axis] - lo) * scale) as usize).min(BINS - 1);
                bins[b].count += 1;
                bins[b].bounds = bins[b].bounds.union(boxes[i as usize]);
            }
            let mut right_area = [0.0f32; BINS];
            let mut right_count = [0u32; BINS];
            let mut acc = Aabb::EMPTY;
            let mut c = 0;
            for k in (1..BINS).rev() {
                acc = acc.union(bins[k].bounds);
                c += bins[k].count;
                right_area[k] = acc.half_area();
                right_count[k] = c;
            }
            let mut acc = Aabb::EMPTY;
            let mut c = 0;
            for k in 0..BINS - 1 {
                acc = acc.union(bins[k].bounds);
                c += bins[k].count;
                let rc = right_count[k + 1];
                if c == 0 || rc == 0 {
                    continue;
                }
                let cost = acc.half_area() * c as f32 + right_area[k + 1] * rc as f32;
                if cost < best.0 {
                    best = (cost, axis, k);
                }
            }
        }
        let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
        let split_cost = traversal_cost() + best.0 / parent_area;
        let mid;
        if best.0.is_finite() && (split_cost < count as f32 || count > MAX_LEAF) {
            let (axis, bin) = (best.1, best.2);
            let lo = cb.min[axis];
            let scale = BINS as f32 / ext[axis] * 0.999_99;
            // in-place partition
            let mut l = 0;
            let mut r = idx.len();
            while l < r {
                let c = centroids[idx[l] as usize][axis];
                let b = (((c - lo) * scale) as usize).min(BINS - 1);
                if b <= bin {
                    l += 1;
                } else {
                    r -= 1;
                    idx.swap(l, r);
                }
            }
            mid = start + l;
        } else if count > MAX_LEAF {
            // centroids coincide: split by position in the array to bound leaf size
            mid = start + count / 2;
        } else {
            make_leaf(&mut nodes);
            continue;
        }
        if mid == start || mid == end {
            make_leaf(&mut nodes);
            continue;
        }
        let left = nodes.len();
        nodes.push(Node::new(Aabb::EMPTY, 0, 0));
        nodes.push(Node::new(Aabb::EMPTY, 0, 0));
        nodes[ni] = Node::new(bounds, left as u32, 0);
        work.push((left + 1, mid, end, depth + 1));
        work.push((left, start, mid, depth + 1));
    }
    (nodes, order)
}

/// A traversal stack: (node, unused, entry distance) per deferred inner node.
pub(crate) type Stack = Vec<(u32, u32, f32)>;

/// Reusable traversal stacks (one per thread; avoids allocation and zeroing per ray).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    pub(crate) stack: Stack,
    /// The stack of a mesh's own BVH, traversed from a leaf of the instances' BVH.
    pub(crate) inner_stack: Stack,
    /// Last occluder found per shadow-cache slot: (instance or `u32::MAX` for the scene's own
    /// primitives, primitive); `(u32::MAX, u32::MAX)` = none.
    pub(crate) shadow_cache: Vec<(u32, u32)>,
    /// Work done with this scratch so far: BVH nodes visited plus primitives handed to the
    /// leaf test (see [`crate::RayStats::work`]).
    pub(crate) work: u64,
}

impl Scratch {
    /// An empty scratch area (allocates on first use, then grows as needed and is reused).
    pub fn new() -> Scratch {
        Scratch {
            stack: Vec::new(),
            inner_stack: Vec::new(),
            shadow_cache: Vec::new(),
            work: 0,
        }
    }
}

/// Children per node.
pub(crate) const WIDTH: usize = 8;

/// Marks an unused child slot of a [`Node8`].
pub(crate) const EMPTY: u32 = u32::MAX;

/// An 8-wide node: the boxes of up to eight children in SoA layout, tested together with SIMD
/// (one AVX vector per plane where the CPU has AVX, else two SSE vectors; same results).
/// `bounds[a]` holds the children's minima on axis `a`, `bounds[3 + a]` their maxima.
/// `count[i] == 0`: child `i` is the node `child[i]`; `count[i] == EMPTY`: unused slot (its box
/// is empty, so it is never hit); otherwise a leaf of `count[i]` primitives from `child[i]`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct Node8 {
    bounds: [[f32; WIDTH]; 6],
    child: [u32; WIDTH],
    count: [u32; WIDTH],
}

/// Per-ray constants for the 8-wide box test: which plane row is near and which far on each
/// axis (chosen once per ray by the direction's signs, so the node test has no branches), the
/// reciprocal direction and origin times it.
struct RayPre {
    near: [usize; 3],
    far: [usize; 3],
    inv: [f32; 3],
    oinv: [f32; 3],
}

impl RayPre {
    #[inline(always)]
    fn new(ray: &Ray) -> RayPre {
        let o = ray.origin;
        let i = ray.inv_dir;
        let neg = [i.x < 0.0, i.y < 0.0, i.z < 0.0];
        RayPre {
            near: [0, 1, 2].map(|a| if neg[a] { 3 + a } else { a }),
            far: [0, 1, 2].map(|a| if neg[a] { a } else { 3 + a }),
            inv: [i.x, i.y, i.z],
            oinv: [o.x * i.x, o.y * i.y, o.z * i.z],
        }
    }
}

/// The box test with SSE (two halves of four; glam's scalar code off x86): entry distances of
/// the eight children and the mask of those entered before `tmax`.
#[inline(always)]
fn hit_sse(node: &Node8, r: &RayPre, tmax: f32) -> ([f32; WIDTH], u32) {
    let mut out = [0.0f32; WIDTH];
    let mut mask = 0u32;
    for h in 0..2 {
        let mut tn = Vec4::ZERO;
        let mut tf = Vec4::splat(tmax);
        for a in 0..3 {
            let (inv, oinv) = (Vec4::splat(r.inv[a]), Vec4::splat(r.oinv[a]));
            let n = Vec4::from_slice(&node.bounds[r.near[a] & 7][4 * h..]);
            let f = Vec4::from_slice(&node.bounds[r.far[a] & 7][4 * h..]);
            tn = tn.max(n * inv - oinv);
            tf = tf.min(f * inv - oinv);
        }
        tn.write_to_slice(&mut out[4 * h..]);
        mask |= tn.cmple(tf).bitmask() << (4 * h);
    }
    (out, mask)
}

/// [`hit_sse`] with one AVX vector per plane: the same operations on the same values, so the
/// same distances and mask.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn hit_avx(node: &Node8, r: &RayPre, tmax: f32) -> ([f32; WIDTH], u32) {
    use std::arch::x86_64::*;
    let mut tn = _mm256_setzero_ps();
    let mut tf = _mm256_set1_ps(tmax);
    for a in 0..3 {
        let inv = _mm256_set1_ps(r.inv[a]);
        let oinv = _mm256_set1_ps(r.oinv[a]);
        let n = &node.bounds[r.near[a] & 7];
        let f = &node.bounds[r.far[a] & 7];
        // SAFETY: `n` and `f` are arrays of 8 f32, exactly the 32 bytes an unaligned load reads.
        let (n, f) = unsafe { (_mm256_loadu_ps(n.as_ptr()), _mm256_loadu_ps(f.as_ptr())) };
        tn = _mm256_max_ps(tn, _mm256_sub_ps(_mm256_mul_ps(n, inv), oinv));
        tf = _mm256_min_ps(tf, _mm256_sub_ps(_mm256_mul_ps(f, inv), oinv));
    }
    let mut out = [0.0f32; WIDTH];
    // SAFETY: `out` is 8 f32, the 32 bytes an unaligned store writes.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), tn) };
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32;
    (out, mask)
}

/// Whether the AVX node test can run here (checked once by std, then a cached flag).
#[inline(always)]
pub(crate) fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The hierarchy: a binary SAH tree collapsed into 8-wide nodes.
#[derive(Clone, Debug, Default)]
pub(crate) struct Bvh {
    pub nodes: Vec<Node8>,
}

impl Bvh {
    /// Builds over primitive boxes; returns the hierarchy and the primitive order (new position ->
    /// old index).
    pub fn build(boxes: &[Aabb]) -> (Bvh, Vec<u32>) {
        Bvh::build_with(boxes, LEAF_MIN)
    }

    /// [`Bvh::build`] never splitting leaves of up to `leaf_min` primitives.
    pub fn build_with(boxes: &[Aabb], leaf_min: usize) -> (Bvh, Vec<u32>) {
        let (bin, order) = build_binary(boxes, leaf_min);
        let mut nodes = Vec::with_capacity(bin.len() / 4 + 1);
        if !bin.is_empty() {
            let bounds = |n: &Node| Aabb {
                min: Vec3A::from_vec4(n.a),
                max: Vec3A::from_vec4(n.b),
            };
            // (binary node, Node8 slot to fill)
            nodes.push(Node8::empty());
            let mut work = vec![(0usize, 0usize)];
            let mut kids: Vec<usize> = Vec::with_capacity(WIDTH);
            while let Some((bi, slot)) = work.pop() {
                // gather up to eight children by opening the largest interior child
                kids.clear();
                if bin[bi].count() > 0 {
                    kids.push(bi);
                } else {
                    let f = bin[bi].first() as usize;
                    kids.extend([f, f + 1]);
                    while kids.len() < WIDTH {
                        let best = kids
                            .iter()
                            .enumerate()
                            .filter(|(_, &k)| bin.get(k).is_some_and(|n| n.count() == 0))
                            .max_by(|a, b| {
                                bounds(&bin[*a.1])
                                    .half_area()
                                    .total_cmp(&bounds(&bin[*b.1]).half_area())
                            })
                            .map(|(i, _)| i);
                        let Some(i) = best else { break };
                        let k = kids.swap_remove(i);
                        let f = bin[k].first() as usize;
                        kids.extend([f, f + 1]);
                    }
                }
                let mut n8 = Node8::empty();
                for (i, &k) in kids.iter().enumerate() {
                    let Some(n) = bin.get(k) else { continue };
                    let b = bounds(n);
                    for a in 0..3 {
                        n8.bounds[a][i] = b.min[a];
                        n8.bounds[3 + a][i] = b.max[a];
                    }
                    if n.count() > 0 {
                        n8.child[i] = n.first();
                        n8.count[i] = n.count();
                    } else {
                        let ni = nodes.len();
                        nodes.push(Node8::empty());
                        n8.child[i] = ni as u32;
                        n8.count[i] = 0;
                        work.push((k, ni));
                    }
                }
                nodes[slot] = n8;
            }
        }
        (Bvh { nodes }, order)
    }

    /// Visits leaves, `visit(first, count, tmax) -> new tmax`. With `ORDERED`, the children hit
    /// at each node are handled nearest first: leaves are visited at once, the nearest inner
    /// child is descended into and the others are stacked. Stops when a visit returns a negative
    /// value (any-hit queries).
    #[inline(always)]
    pub fn traverse<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
        visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        self.traverse_in::<ORDERED>(ray, tmax, &mut scratch.stack, &mut scratch.work, visit)
    }

    /// [`Bvh::traverse`] with the stack and the work counter given apart, so that a leaf visit
    /// can traverse another hierarchy (a mesh instance's) with a second stack. Runs the AVX
    /// node test where the CPU has it (the whole loop compiled for AVX), else SSE.
    #[inline(always)]
    pub fn traverse_in<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut Stack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        #[cfg(target_arch = "x86_64")]
        if has_avx() {
            // SAFETY: the CPU has AVX (checked just above).
            return unsafe { self.traverse_avx::<ORDERED>(ray, tmax, stack, work, visit) };
        }
        self.traverse_loop::<ORDERED, false>(ray, tmax, stack, work, visit)
    }

    /// [`Bvh::traverse_loop`] compiled with AVX.
    ///
    /// # Safety
    /// The CPU must have AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn traverse_avx<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut Stack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        self.traverse_loop::<ORDERED, true>(ray, tmax, stack, work, visit)
    }

    /// The traversal; `AVX` only where the CPU has it (see [`Bvh::traverse_in`]).
    #[inline(always)]
    fn traverse_loop<const ORDERED: bool, const AVX: bool>(
        &self,
        ray: &Ray,
        mut tmax: f32,
        stack: &mut Stack,
        work: &mut u64,
        mut visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        if self.nodes.is_empty() {
            return tmax;
        }
        let pre = RayPre::new(ray);
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            if let Some(node) = self.nodes.get(cur as usize) {
                #[cfg(test)]
                probe::NODES.with(|c| c.set(c.get() + 1));
                *work += 1;
                #[cfg(target_arch = "x86_64")]
                let (tn, mut mask) = if AVX {
                    // SAFETY: AVX is only set by traverse_avx, which runs where the CPU has it.
                    unsafe { hit_avx(node, &pre, tmax) }
                } else {
                    hit_sse(node, &pre, tmax)
                };
                #[cfg(not(target_arch = "x86_64"))]
                let (tn, mut mask) = hit_sse(node, &pre, tmax);
                if mask & mask.wrapping_sub(1) == 0 {
                    // zero or one child hit: the common case, no sorting or stacking
                    if mask != 0 {
                        let i = mask.trailing_zeros() as usize & 7;
                        let count = node.count[i];
                        if count == 0 {
                            cur = node.child[i];
                            continue;
                        }
                        if count != EMPTY {
                            *work += count as u64;
                            tmax = visit(node.child[i] as usize, count as usize, tmax);
                            if tmax < 0.0 {
                                return tmax;
                            }
                        }
                    }
                } else {
                    // several children: leaves at once, inner nodes nearest first
                    let mut it = [0.0f32; WIDTH];
                    let mut ic = [0u32; WIDTH];
                    let mut ni = 0usize;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize & 7;
                        mask &= mask - 1;
                        let count = node.count[i];
                        if count == 0 {
                            // insertion keeps (it, ic) sorted far to near
                            let mut j = ni;
                            while ORDERED && j > 0 && it[(j - 1) & 7] < tn[i] {
                                it[j & 7] = it[(j - 1) & 7];
                                ic[j & 7] = ic[(j - 1) & 7];
                                j -= 1;
                            }
                            it[j & 7] = tn[i];
                            ic[j & 7] = node.child[i];
                            ni += 1;
                        } else if count != EMPTY && tn[i] <= tmax {
                            *work += count as u64;
                            tmax = visit(node.child[i] as usize, count as usize, tmax);
                            if tmax < 0.0 {
                                return tmax;
                            }
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
            }
            // pop the next inner node that may still hold a closer hit
            loop {
                if sp == 0 {
                    return tmax;
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

    /// Every leaf as (first primitive, count).
    pub fn leaves(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.nodes.iter().flat_map(|n| {
            (0..WIDTH).filter_map(move |i| {
                let c = n.count[i];
                (c != 0 && c != EMPTY).then_some((n.child[i] as usize, c as usize))
            })
        })
    }
}

impl Node8 {
    /// The children's box planes: `[a]` minima on axis `a`, `[3 + a]` maxima (SoA).
    #[inline(always)]
    pub(crate) fn planes(&self) -> &[[f32; WIDTH]; 6] {
        &self.bounds
    }

    /// Per child: the node index, or the first primitive of a leaf.
    #[inline(always)]
    pub(crate) fn children(&self) -> &[u32; WIDTH] {
        &self.child
    }

    /// Per child: 0 for an inner node, [`EMPTY`] for an unused slot, else the leaf's size.
    #[inline(always)]
    pub(crate) fn counts(&self) -> &[u32; WIDTH] {
        &self.count
    }

    /// An empty node (for tests of other modules).
    #[cfg(test)]
    pub(crate) fn empty_for_tests() -> Node8 {
        Node8::empty()
    }

    /// Sets child `i`'s extent on axis `a` (for tests of other modules).
    #[cfg(test)]
    pub(crate) fn set_for_tests(&mut self, i: usize, a: usize, min: f32, max: f32) {
        self.bounds[a][i] = min;
        self.bounds[3 + a][i] = max;
        self.count[i] = 1;
    }

    /// The single-ray node test: entry distances and the mask of children entered.
    #[cfg(test)]
    pub(crate) fn single_ray_test_for_tests(&self, ray: &Ray, tmax: f32) -> ([f32; WIDTH], u32) {
        hit_sse(self, &RayPre::new(ray), tmax)
    }

    fn empty() -> Node8 {
        let (inf, ninf) = ([f32::INFINITY; WIDTH], [f32::NEG_INFINITY; WIDTH]);
        Node8 {
            bounds: [inf, inf, inf, ninf, ninf, ninf],
            child: [0; WIDTH],
            count: [EMPTY; WIDTH],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Vec<Aabb> {
        (0..1000)
            .map(|i| {
                let p = Vec3A::new(
                    (i % 10) as f32,
                    ((i / 10) % 10) as f32,
                    (i / 100) as f32 * 3.0,
                );
                Aabb {
                    min: p,
                    max: p + Vec3A::splat(0.5),
                }
            })
            .collect()
    }

    #[test]
    fn build_covers_all_primitives_once() {
        let boxes = grid();
        let (bin, order) = build_binary(&boxes, LEAF_MIN);
        assert!(bin.len() < 2 * boxes.len());
        assert_eq!(std::mem::size_of::<Node>(), 32);
        let mut seen = vec![0u32; boxes.len()];
        for n in &bin {
            for k in n.first()..n.first() + n.count() {
                seen[order[k as usize] as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        let (bvh, order) = Bvh::build(&boxes);
        let mut seen = vec![0u32; boxes.len()];
        for n in &bvh.nodes {
            for i in 0..WIDTH {
                if n.count[i] != EMPTY && n.count[i] > 0 {
                    for k in n.child[i]..n.child[i] + n.count[i] {
                        seen[order[k as usize] as usize] += 1;
                    }
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert_eq!(std::mem::size_of::<Node8>(), 256);
        // identical boxes still give bounded leaves
        let same = vec![boxes[0]; 100];
        let (bin, _) = build_binary(&same, LEAF_MIN);
        assert!(bin.iter().all(|n| n.count() as usize <= MAX_LEAF));
    }

    #[test]
    fn avx_and_sse_node_tests_agree_bit_for_bit() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut f = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 4.0 - 2.0
        };
        let mut hits = 0;
        for round in 0..5000 {
            let mut node = Node8::empty();
            for i in 0..WIDTH - round % 3 {
                for a in 0..3 {
                    let (x, y) = (f(), f());
                    node.bounds[a][i] = x.min(y);
                    node.bounds[3 + a][i] = x.max(y);
                }
            }
            let mut d = Vec3A::new(f(), f(), f());
            if round % 5 == 0 {
                d.y = 0.0; // an axis-parallel ray: the tiny safe reciprocal
            }
            let ray = Ray::new(Vec3A::new(f(), f(), f()) * 0.25, d);
            let pre = RayPre::new(&ray);
            let tmax = if round % 2 == 0 { 3.0 } else { f32::INFINITY };
            let (t, m) = hit_sse(&node, &pre, tmax);
            hits += m.count_ones();
            if has_avx() {
                // SAFETY: the CPU has AVX (checked on the line above).
                let (ta, ma) = unsafe { hit_avx(&node, &pre, tmax) };
                assert_eq!(m, ma);
                assert_eq!(t.map(f32::to_bits), ta.map(f32::to_bits));
            }
        }
        assert!(hits > 5000, "{hits}");
    }

    #[test]
    fn traversal_finds_every_box_along_a_line() {
        let boxes = grid();
        let (bvh, order) = Bvh::build(&boxes);
        let mut scratch = Scratch::new();
        // a ray along +z through column (3, 4) meets the 10 boxes of that column
        let ray = Ray::new(Vec3A::new(3.25, 4.25, -5.0), Vec3A::Z);
        let mut found = Vec::new();
        bvh.traverse::<false>(&ray, f32::INFINITY, &mut scratch, |f, c, t| {
            for k in f..f + c {
                let b = boxes[order[k] as usize];
                if b.min.x <= 3.25 && b.max.x >= 3.25 && b.min.y <= 4.25 && b.max.y >= 4.25 {
                    found.push(order[k]);
                }
            }
            t
        });
        found.sort();
        assert_eq!(found, (0..10).map(|z| z * 100 + 43).collect::<Vec<u32>>());
    }
}
