//! Bounding volume hierarchy: binned SAH build, 4-wide flattened nodes, ordered traversal.
//!
//! Build: a binary tree with binned SAH (16 bins on each axis, iterative, depth-capped) in
//! 32-byte nodes (box + first/count packed in the w lanes, children adjacent). It is then
//! collapsed into 4-wide nodes (`Node4`: the four child boxes in SoA layout, 128 bytes, i.e.
//! 32 bytes per child) by repeatedly opening the child with the largest surface area. Leaves
//! reference contiguous ranges of the primitive array, which the scene reorders to BVH order.
//! Memory is O(primitives) (O(references): long oblique cones are referenced once per piece).
//! The same hierarchy serves two levels for mesh instances ([`crate::instance`]): one over the
//! instances' world boxes, whose leaf visits traverse a mesh's own hierarchy with a second
//! stack ([`Scratch`] holds both).
//!
//! Traversal tests the four child boxes at once with SSE (`Vec4`), using per-ray precomputed
//! reciprocal direction and near/far plane selection (no min/max per axis). For closest-hit
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
        pub static LEAF_MIN: Cell<usize> = const { Cell::new(2) };
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
#[cfg(test)]
fn leaf_min() -> usize {
    probe::LEAF_MIN.with(|c| c.get())
}
#[cfg(not(test))]
fn leaf_min() -> usize {
    2
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

/// Binary binned-SAH build; returns the nodes and the primitive order.
fn build_binary(boxes: &[Aabb]) -> (Vec<Node>, Vec<u32>) {
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
        if count <= leaf_min() || depth >= MAX_DEPTH {
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

/// Marks an unused child slot of a [`Node4`].
const EMPTY: u32 = u32::MAX;

/// A 4-wide node: the boxes of up to four children in SoA layout, tested together with SIMD.
/// `count[i] == 0`: child `i` is the node `child[i]`; `count[i] == EMPTY`: unused slot (its box
/// is empty, so it is never hit); otherwise a leaf of `count[i]` primitives from `child[i]`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct Node4 {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    child: [u32; 4],
    count: [u32; 4],
}

/// Per-ray constants for the 4-wide box test.
struct RayPre {
    /// Per axis: (near-plane selector is `hi`?).
    neg: [bool; 3],
    inv: [Vec4; 3],
    oinv: [Vec4; 3],
}

impl RayPre {
    #[inline(always)]
    fn new(ray: &Ray) -> RayPre {
        let o = ray.origin;
        let i = ray.inv_dir;
        RayPre {
            neg: [i.x < 0.0, i.y < 0.0, i.z < 0.0],
            inv: [Vec4::splat(i.x), Vec4::splat(i.y), Vec4::splat(i.z)],
            oinv: [
                Vec4::splat(o.x * i.x),
                Vec4::splat(o.y * i.y),
                Vec4::splat(o.z * i.z),
            ],
        }
    }
}

impl Node4 {
    /// Entry distances of the four children and the mask of those entered before `tmax`.
    #[inline(always)]
    fn hit(&self, r: &RayPre, tmax: f32) -> (Vec4, u32) {
        let mut tn = Vec4::ZERO;
        let mut tf = Vec4::splat(tmax);
        for a in 0..3 {
            let (n, f) = if r.neg[a] {
                (self.hi[a], self.lo[a])
            } else {
                (self.lo[a], self.hi[a])
            };
            tn = tn.max(n * r.inv[a] - r.oinv[a]);
            tf = tf.min(f * r.inv[a] - r.oinv[a]);
        }
        (tn, tn.cmple(tf).bitmask())
    }
}

/// The hierarchy: a binary SAH tree collapsed into 4-wide nodes.
#[derive(Clone, Debug, Default)]
pub(crate) struct Bvh {
    pub nodes: Vec<Node4>,
}

impl Bvh {
    /// Builds over primitive boxes; returns the hierarchy and the primitive order (new position ->
    /// old index).
    pub fn build(boxes: &[Aabb]) -> (Bvh, Vec<u32>) {
        let (bin, order) = build_binary(boxes);
        let mut nodes = Vec::with_capacity(bin.len() / 2 + 1);
        if let Some(root) = bin.first() {
            let bounds = |n: &Node| Aabb {
                min: Vec3A::from_vec4(n.a),
                max: Vec3A::from_vec4(n.b),
            };
            // (binary node, Node4 slot to fill)
            nodes.push(Node4::empty());
            let mut work = vec![(0usize, 0usize)];
            let _ = root;
            while let Some((bi, slot)) = work.pop() {
                // gather up to four children by opening the largest interior child
                let mut kids: Vec<usize> = Vec::with_capacity(4);
                if bin[bi].count() > 0 {
                    kids.push(bi);
                } else {
                    let f = bin[bi].first() as usize;
                    kids.extend([f, f + 1]);
                    while kids.len() < 4 {
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
                let mut n4 = Node4::empty();
                for (i, &k) in kids.iter().enumerate() {
                    let Some(n) = bin.get(k) else { continue };
                    let b = bounds(n);
                    for a in 0..3 {
                        n4.lo[a][i] = b.min[a];
                        n4.hi[a][i] = b.max[a];
                    }
                    if n.count() > 0 {
                        n4.child[i] = n.first();
                        n4.count[i] = n.count();
                    } else {
                        let ni = nodes.len();
                        nodes.push(Node4::empty());
                        n4.child[i] = ni as u32;
                        n4.count[i] = 0;
                        work.push((k, ni));
                    }
                }
                nodes[slot] = n4;
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
    /// can traverse another hierarchy (a mesh instance's) with a second stack.
    #[inline(always)]
    pub fn traverse_in<const ORDERED: bool>(
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
                let (tn, mut mask) = node.hit(&pre, tmax);
                let tn = tn.to_array();
                if mask & mask.wrapping_sub(1) == 0 {
                    // zero or one child hit: the common case, no sorting or stacking
                    if mask != 0 {
                        let i = mask.trailing_zeros() as usize & 3;
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
                    let mut it = [0.0f32; 4];
                    let mut ic = [0u32; 4];
                    let mut ni = 0usize;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize & 3;
                        mask &= mask - 1;
                        let count = node.count[i];
                        if count == 0 {
                            // insertion keeps (it, ic) sorted far to near
                            let mut j = ni;
                            while ORDERED && j > 0 && it[(j - 1) & 3] < tn[i] {
                                it[j & 3] = it[(j - 1) & 3];
                                ic[j & 3] = ic[(j - 1) & 3];
                                j -= 1;
                            }
                            it[j & 3] = tn[i];
                            ic[j & 3] = node.child[i];
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
                        if stack.len() < sp + 4 {
                            stack.resize(sp + 64, (0, 0, 0.0));
                        }
                        for j in 0..ni - 1 {
                            if let Some(slot) = stack.get_mut(sp) {
                                *slot = (ic[j & 3], 0, it[j & 3]);
                                sp += 1;
                            }
                        }
                        cur = ic[(ni - 1) & 3];
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
}

impl Bvh {
    /// Every leaf as (first primitive, count).
    pub fn leaves(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.nodes.iter().flat_map(|n| {
            (0..4).filter_map(move |i| {
                let c = n.count[i];
                (c != 0 && c != EMPTY).then_some((n.child[i] as usize, c as usize))
            })
        })
    }
}

impl Node4 {
    fn empty() -> Node4 {
        Node4 {
            lo: [Vec4::INFINITY; 3],
            hi: [Vec4::NEG_INFINITY; 3],
            child: [0; 4],
            count: [EMPTY; 4],
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
        let (bin, order) = build_binary(&boxes);
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
            for i in 0..4 {
                if n.count[i] != EMPTY && n.count[i] > 0 {
                    for k in n.child[i]..n.child[i] + n.count[i] {
                        seen[order[k as usize] as usize] += 1;
                    }
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert_eq!(std::mem::size_of::<Node4>(), 128);
        // identical boxes still give bounded leaves
        let same = vec![boxes[0]; 100];
        let (bin, _) = build_binary(&same);
        assert!(bin.iter().all(|n| n.count() as usize <= MAX_LEAF));
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
