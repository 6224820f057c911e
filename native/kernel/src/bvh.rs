//! Bounding volume hierarchy: binned SAH build, 8-wide flattened nodes, ordered traversal.
//!
//! Build: a binary tree with binned SAH (up to 32 bins on each axis, fewer for small nodes,
//! the three axes binned in one pass over 32-byte primitive references, which each partition
//! copies from one array to the other;
//! iterative, depth-capped: the `binned` module) in 32-byte nodes (box + first/count packed
//! in the w lanes, children adjacent). For triangles, which are met four at a time (the `tri4` module), the SAH counts a leaf's cost in
//! blocks of four. The binary tree is then collapsed into 8-wide nodes (`Node8`: the eight
//! child boxes in SoA layout, 256 bytes, i.e. 32 bytes per child) by SAH: bottom-up, the least
//! cost of each binary subtree as at most 1..8 children of a wide node (a leaf, a small
//! subtree made one leaf, or a wide node of its own), then read top-down (`Collapse`). Leaves
//! reference contiguous ranges of the primitive array, which the scene reorders to BVH order;
//! a leaf whose triangles are stored as blocks names its first block instead
//! (`LEAF_BLOCKS`).
//! Memory is O(primitives) (O(references): long oblique cones are referenced once per piece).
//! The same hierarchy serves two levels for mesh instances ([`crate::instance`]): one over the
//! instances' world boxes, whose leaf visits traverse a mesh's own hierarchy with a second
//! stack ([`Scratch`] holds both).
//!
//! Traversal tests the eight child boxes at once, with AVX2 and FMA where the CPU has them
//! (detected at run time; the whole traversal loop is then compiled for them) and otherwise
//! with portable code, the same operations on the same values either way (one fused
//! multiply-subtract per plane, in software where the CPU has no FMA; the maxima, minima and
//! the final comparison on the distances' bits as signed integers, which order non-negative
//! floats as floats and cost a cycle each), so the same hits on every machine. Per ray, the
//! reciprocal direction and the near/far plane rows are chosen once (no min/max per axis, no
//! branch per node). Both loops keep leaves and inner nodes on one stack. For closest-hit
//! queries the children that are hit are sorted by entry distance: the nearest, leaf or node,
//! is handled next and the others are stacked far to near, each skipped when popped if a
//! closer hit was found meanwhile. Shadow rays use the any-hit loop made for occlusion
//! (`any_hit.rs`), which stops at the first occluder and so keeps no order and no entry
//! distance: every child a node enters is pushed at once, the children's indices and counts as
//! two vectors permuted by a table row chosen by the mask of those entered (no branch on how
//! many), and the highest slot entered is handled next. The scene's closest-hit and shadow
//! queries each inline their loop, the leaf tests with it, into one function compiled for AVX2
//! and FMA. The stacks live in a reusable [`Scratch`], so no allocation happens per ray.
//! Hierarchies too big for a core's L2 cache prefetch what a ray stacks, as it stacks it (a
//! child node's four cache lines, a leaf's triangle blocks), so that the memory of the nodes
//! it comes back to is on its way while it works on the nearest ones.

use crate::geometry::Aabb;
use crate::ray::Ray;
use crate::{limits, Error};
use glam::{Vec3A, Vec4};

mod binned;
mod sah;
mod triangle_tree;

use binned::build_binary;
#[cfg(test)]
use binned::BuildRef;

pub use triangle_tree::TriangleTree;

/// Leaves never hold more than this unless the primitives cannot be separated.
const MAX_LEAF: usize = 8;
/// Build depth cap (leaves below it are forced), bounding tree depth on pathological input.
pub(crate) const MAX_DEPTH: usize = 60;
/// The binary build's cost of a split relative to one leaf test: none, so that the binary tree
/// splits wherever the SAH split beats the leaf, down to the leaf size that is never split.
/// Which of its subtrees become leaves, and how big, the collapse into 8-wide nodes decides
/// ([`Collapse`], with its own cost of a wide node): a binary node left to the collapse costs
/// nothing of itself, as most vanish into a wide node. (Charged a whole node visit, the binary
/// build stops early, at leaves of up to two blocks that the collapse cannot split, and the
/// trees cost more by the collapse's own measure.)
pub(crate) const SPLIT_COST: f32 = 0.0;

/// Test-only instrumentation: node visits, leaf visits, tuning overrides.
#[cfg(test)]
pub(crate) mod probe {
    use std::cell::Cell;
    thread_local! {
        pub static NODES: Cell<u64> = const { Cell::new(0) };
        pub static SPLIT: Cell<f32> = const { Cell::new(super::SPLIT_COST) };
        pub static LEAF_MIN: Cell<usize> = const { Cell::new(0) };
        /// Node visits by (inner children hit, leaves hit).
        pub static SHAPE: std::cell::RefCell<[[u64; 9]; 9]> = const { std::cell::RefCell::new([[0; 9]; 9]) };
    }

    /// Counts a node visit that entered the children of `mask`, by kind.
    pub fn shape(node: &super::Node8, mask: u32) {
        let inner = mask & node.inner_mask();
        let leaves = mask & !inner;
        SHAPE.with(|h| {
            h.borrow_mut()[inner.count_ones() as usize][leaves.count_ones() as usize] += 1
        });
    }
}

#[cfg(test)]
fn split_cost() -> f32 {
    probe::SPLIT.with(|c| c.get())
}
#[cfg(not(test))]
fn split_cost() -> f32 {
    SPLIT_COST
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
    fn bounds(&self) -> Aabb {
        Aabb {
            min: Vec3A::from_vec4(self.a),
            max: Vec3A::from_vec4(self.b),
        }
    }
    #[inline(always)]
    pub fn count(&self) -> u32 {
        self.b.w.to_bits()
    }
}

/// Leaves at most this big are never split: for primitives tested one at a time.
pub(crate) const LEAF_MIN: usize = 2;
/// For triangles only, tested four at a time ([`crate::tri4`]): a leaf of up to four costs
/// one test, and the SAH counts a leaf's cost in blocks of four.
pub(crate) const LEAF_MIN_TRIANGLES: usize = 4;

/// Tests needed for `n` primitives met `block` at a time (`block` a power of two, as
/// [`block_size`] gives: a shift and a mask rather than a division, which the binning's sweeps
/// make per bin).
#[inline(always)]
fn blocks_of(n: u32, block: u32) -> f32 {
    let shift = block.trailing_zeros();
    ((n >> shift) + u32::from(n & (block - 1) != 0)) as f32
}

/// Primitives met at once in a leaf: four for triangle blocks, else one.
fn block_size(leaf_min_chosen: usize) -> u32 {
    if leaf_min_chosen >= LEAF_MIN_TRIANGLES {
        LEAF_MIN_TRIANGLES as u32
    } else {
        1
    }
}

/// The largest leaf the build makes unless primitives cannot be separated.
fn max_leaf(block: u32) -> usize {
    MAX_LEAF.max(2 * block as usize)
}

/// Cost of one 8-wide node visit relative to one leaf test (a block of four triangles or one
/// other primitive), in the collapse's SAH.
const NODE8_COST: f32 = 1.0;

/// The SAH-driven collapse of the binary tree into 8-wide nodes: for every binary node `n` and
/// `j` in 1..=8, the least SAH cost of covering `n`'s subtree with at most `j` children of an
/// 8-wide node, each child a leaf (a binary leaf, or a whole subtree of at most `max_leaf`
/// primitives made one leaf, its primitives being contiguous) or an 8-wide node of its own.
/// Computed bottom-up (children come after their parent in the binary array), then read
/// top-down to emit the nodes.
struct Collapse {
    /// `cost[8 * n + j - 1]`: the least cost of `n`'s subtree in at most `j` slots.
    cost: Vec<f32>,
    /// How that cost is reached: [`Choice`].
    choice: Vec<Choice>,
    /// Per binary node: the split of the eight slots of its own 8-wide node between its left
    /// and right children (slots for the left one).
    node_split: Vec<u8>,
    /// Per binary node: its primitive range (first, count).
    ranges: Vec<(u32, u32)>,
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Choice {
    /// The subtree as one leaf.
    Leaf,
    /// The subtree as an 8-wide node.
    Node,
    /// `i` slots to the left child, the rest to the right.
    Split(u8),
}

/// The least costs (and how they are reached) of a binary node in 1..=8 slots, given its
/// cost in one slot (`one`) and its children's costs `lc` and `rc` in 1..=8 slots each: in
/// `j` slots, either as in `j - 1` or `i` slots to the left child and `j - i` to the right.
#[inline(always)]
fn shared_slots(
    lc: &[f32; WIDTH],
    rc: &[f32; WIDTH],
    one: (f32, Choice),
) -> ([f32; WIDTH], [Choice; WIDTH]) {
    let mut cost = [one.0; WIDTH];
    let mut choice = [one.1; WIDTH];
    for j in 2..=WIDTH {
        let mut v = (cost[j - 2], choice[j - 2]);
        for i in 1..j {
            let s = lc[i - 1] + rc[j - i - 1];
            if s < v.0 {
                v = (s, Choice::Split(i as u8));
            }
        }
        cost[j - 1] = v.0;
        choice[j - 1] = v.1;
    }
    (cost, choice)
}

impl Collapse {
    #[inline(never)]
    fn plan(bin: &[Node], block: u32, max_leaf: usize) -> Collapse {
        let n = bin.len();
        let mut c = Collapse {
            cost: vec![f32::INFINITY; WIDTH * n],
            choice: vec![Choice::Leaf; WIDTH * n],
            node_split: vec![0; n],
            ranges: vec![(0, 0); n],
        };
        // primitive ranges, bottom-up: a subtree's primitives are contiguous
        for k in (0..n).rev() {
            let b = &bin[k];
            c.ranges[k] = if b.count() > 0 {
                (b.first(), b.count())
            } else {
                let f = b.first() as usize;
                match (c.ranges.get(f), c.ranges.get(f + 1)) {
                    (Some(l), Some(r)) => (l.0.min(r.0), l.1 + r.1),
                    _ => (0, 0),
                }
            };
        }
        for k in (0..n).rev() {
            let b = &bin[k];
            // boxes without area (points, lines) cost as the smallest positive area does, so
            // that costs still grow with primitives and nodes (as for equal boxes)
            let area = b.bounds().half_area().max(f32::MIN_POSITIVE);
            let (_, count) = c.ranges[k];
            let leaf_cost = area * blocks_of(count, block);
            let base = WIDTH * k;
            if b.count() > 0 {
                for j in 0..WIDTH {
                    c.cost[base + j] = leaf_cost;
                    c.choice[base + j] = Choice::Leaf;
                }
                continue;
            }
            let (l, r) = (b.first() as usize, b.first() as usize + 1);
            if r >= n {
                continue;
            }
            let (lc, rc) = (c.slot_costs(l), c.slot_costs(r));
            // as an 8-wide node: the children share its eight slots
            let mut best = (f32::INFINITY, 1u8);
            for i in 1..WIDTH {
                let v = lc[i - 1] + rc[WIDTH - i - 1];
                if v < best.0 {
                    best = (v, i as u8);
                }
            }
            c.node_split[k] = best.1;
            let node_cost = NODE8_COST * area + best.0;
            // one slot: a leaf (when small enough) or a node
            let one = if (count as usize) <= max_leaf && leaf_cost <= node_cost {
                (leaf_cost, Choice::Leaf)
            } else {
                (node_cost, Choice::Node)
            };
            let (cost, choice) = shared_slots(&lc, &rc, one);
            c.cost[base..base + WIDTH].copy_from_slice(&cost);
            c.choice[base..base + WIDTH].copy_from_slice(&choice);
        }
        c
    }

    /// The least costs of binary node `k`'s subtree in 1..=8 slots (infinite if unknown).
    #[inline(always)]
    fn slot_costs(&self, k: usize) -> [f32; WIDTH] {
        self.cost
            .get(WIDTH * k..WIDTH * (k + 1))
            .and_then(|c| <[f32; WIDTH]>::try_from(c).ok())
            .unwrap_or([f32::INFINITY; WIDTH])
    }

    /// The primitive range of binary node `k`, as a leaf's (first, count).
    fn range(&self, k: usize) -> (u32, u32) {
        self.ranges.get(k).copied().unwrap_or((0, 0))
    }

    /// The children of the 8-wide node made for binary node `k`: (binary node, as a leaf).
    fn node_children(&self, bin: &[Node], k: usize, out: &mut Vec<(usize, bool)>) {
        match bin.get(k) {
            Some(b) if b.count() == 0 => {
                let f = b.first() as usize;
                let i = self.node_split[k] as usize;
                self.slots(bin, f, i, out);
                self.slots(bin, f + 1, WIDTH - i, out);
            }
            // a leaf as the whole tree
            _ => out.push((k, true)),
        }
    }

    /// The children covering binary node `k` in at most `j` slots.
    fn slots(&self, bin: &[Node], k: usize, j: usize, out: &mut Vec<(usize, bool)>) {
        let j = j.clamp(1, WIDTH);
        match self.choice.get(WIDTH * k + j - 1).copied() {
            Some(Choice::Leaf) => out.push((k, true)),
            Some(Choice::Split(i)) => {
                let f = bin.get(k).map_or(0, |b| b.first() as usize);
                self.slots(bin, f, i as usize, out);
                self.slots(bin, f + 1, j - i as usize, out);
            }
            Some(Choice::Node) | None => out.push((k, false)),
        }
    }
}

/// A traversal stack: (node, unused, entry distance) per deferred inner node.
pub(crate) type Stack = Vec<(u32, u32, f32)>;

mod any_hit;
use any_hit::AnyStack;

/// The stacks of one single-ray traversal: the ordered loop's and the any-hit loop's.
#[derive(Clone, Debug, Default)]
pub(crate) struct RayStack {
    ordered: Stack,
    any: AnyStack,
}

/// Reusable traversal stacks (one per thread; avoids allocation and zeroing per ray).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    /// The packet traversal's stack (`packet.rs`).
    pub(crate) stack: Stack,
    /// The stacks of single rays.
    pub(crate) ray: RayStack,
    /// The stacks of a mesh's own BVH, traversed from a leaf of the instances' BVH.
    pub(crate) inner: RayStack,
    /// Last occluder found per shadow-cache slot: (instance or `u32::MAX` for the scene's own
    /// primitives, primitive); `(u32::MAX, u32::MAX)` = none.
    pub(crate) shadow_cache: Vec<(u32, u32)>,
    /// The packet traversal's list of (lane, entry distance, leaf size) of every leaf a ray
    /// tested (`packet.rs`), kept between packets.
    pub(crate) entered: Vec<(usize, f32, u32)>,
    /// Work done with this scratch so far: BVH nodes visited plus primitives handed to the
    /// leaf test (see [`crate::RayStats::work`]).
    pub(crate) work: u64,
}

impl Scratch {
    /// An empty scratch area (allocates on first use, then grows as needed and is reused).
    pub fn new() -> Scratch {
        Scratch {
            stack: Vec::new(),
            ray: RayStack::default(),
            inner: RayStack::default(),
            shadow_cache: Vec::new(),
            entered: Vec::new(),
            work: 0,
        }
    }
}

/// Children per node.
pub(crate) const WIDTH: usize = 8;

/// Entries of the traversal stack that the single-ray loop addresses: a power of two above the
/// deepest the stack can get (at most `WIDTH - 1` entries per level of a path, and a path has at
/// most `MAX_DEPTH + 1` levels, as the build forces leaves at `MAX_DEPTH`).
pub(crate) const STACK_CAP: usize = 512;
const _: () = assert!((WIDTH - 1) * (MAX_DEPTH + 1) < STACK_CAP);
const _: () = assert!(STACK_CAP.is_power_of_two());

/// Marks an unused child slot of a [`Node8`].
pub(crate) const EMPTY: u32 = u32::MAX;

/// Set in a leaf's `count` when the leaf's triangles are stored as blocks of four
/// ([`crate::tri4::TriBlocks`]): then `child` is the leaf's first block rather than its first
/// primitive, and the low bits are the number of triangles. Set only by
/// [`Bvh::mark_block_leaves`].
pub(crate) const LEAF_BLOCKS: u32 = 1 << 31;

/// The number of triangles of a leaf of blocks, from the `count` a visit is handed; `None` for
/// other leaves.
#[inline(always)]
pub(crate) fn block_leaf_len(count: usize) -> Option<usize> {
    let c = u32::try_from(count).ok()?;
    (c & LEAF_BLOCKS != 0 && c != EMPTY).then_some((c & !LEAF_BLOCKS) as usize)
}

/// An 8-wide node: the boxes of up to eight children in SoA layout, tested together with SIMD
/// (one AVX vector per plane where the CPU has AVX2, else portable code; same results).
/// `bounds[a]` holds the children's minima on axis `a`, `bounds[3 + a]` their maxima.
/// `count[i] == 0`: child `i` is the node `child[i]`; `count[i] == EMPTY`: unused slot (its box
/// is empty, so it is never hit); with [`LEAF_BLOCKS`] set, a leaf of `count[i] & !LEAF_BLOCKS`
/// triangles whose blocks start at block `child[i]`; otherwise a leaf of `count[i]` primitives
/// from `child[i]`.
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

/// [`RayPre`]'s near and far rows by the signs of the reciprocal direction (bit `a` of the
/// index set: component `a` below zero): one comparison of the three components and a load
/// per ray, in place of six selections, which took a tenth of a shadow ray's instructions.
const PLANE_ROWS: [([usize; 3], [usize; 3]); 8] = {
    let mut t = [([0; 3], [0; 3]); 8];
    let mut m = 0;
    while m < 8 {
        let mut a = 0;
        while a < 3 {
            let neg = (m >> a) & 1 == 1;
            t[m].0[a] = if neg { 3 + a } else { a };
            t[m].1[a] = if neg { a } else { 3 + a };
            a += 1;
        }
        m += 1;
    }
    t
};

impl RayPre {
    #[inline(always)]
    fn new(ray: &Ray) -> RayPre {
        let o = ray.origin;
        let i = ray.inv_dir;
        // the mask of `i < 0` on each axis (as the comparison of floats: NaN and -0 are not)
        let neg = i.cmplt(Vec3A::ZERO).bitmask() as usize & 7;
        let (near, far) = PLANE_ROWS[neg];
        RayPre {
            near,
            far,
            inv: [i.x, i.y, i.z],
            oinv: [o.x * i.x, o.y * i.y, o.z * i.z],
        }
    }
}

/// A traversal's test of `node`'s eight boxes (see [`hit_portable`]), with AVX when `AVX` is set,
/// counted for the tests' probes.
#[inline(always)]
fn node_test<const AVX: bool>(node: &Node8, pre: &RayPre, tmax: f32) -> ([f32; WIDTH], u32) {
    #[cfg(test)]
    probe::NODES.with(|c| c.set(c.get() + 1));
    #[cfg(target_arch = "x86_64")]
    let hit = if AVX {
        // SAFETY: AVX is only set by traverse_avx, which runs where the CPU has AVX2 and FMA,
        // and by the callers of traverse_compiled, whose contract is the same.
        unsafe { hit_avx(node, pre, tmax) }
    } else {
        hit_portable(node, pre, tmax)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let hit = hit_portable(node, pre, tmax);
    #[cfg(test)]
    probe::shape(node, hit.1);
    hit
}

/// The bits of `x` as a signed integer: among non-negative floats (and +inf) the same order
/// as the floats, and every negative float (-0 included) below every non-negative one. The
/// box test takes its maxima and minima and its final comparison in this order: one-cycle
/// integer operations in place of four-cycle float ones on the traversal's critical path.
/// Entry distances are clamped at +0, so an entered child's distance is exactly the float
/// maximum; an exit distance below zero on any axis (or a bound `tmax` below zero) gives a
/// negative integer, which every entry distance exceeds, so such a child is never entered,
/// as with float order (-0 included: a box left exactly at the origin is not entered).
#[inline(always)]
fn order_bits(x: f32) -> i32 {
    x.to_bits() as i32
}

/// The box test without SIMD intrinsics (x86 without AVX2 and FMA, and other targets; the
/// compiler vectorises it where it can): entry distances of the eight children and the mask
/// of those entered before `tmax`. Per lane, one fused multiply-subtract per plane, then the
/// maxima and minima pairwise in [`order_bits`]'s order, as [`hit_avx`] does.
#[inline(always)]
fn hit_portable(node: &Node8, r: &RayPre, tmax: f32) -> ([f32; WIDTH], u32) {
    let mut out = [0.0f32; WIDTH];
    let mut mask = 0u32;
    let plane = |row: usize, a: usize, i: usize| {
        order_bits(node.bounds[row & 7][i].mul_add(r.inv[a], -r.oinv[a]))
    };
    for (i, o) in out.iter_mut().enumerate() {
        let n = [0, 1, 2].map(|a| plane(r.near[a], a, i));
        let f = [0, 1, 2].map(|a| plane(r.far[a], a, i));
        let tn = n[0].max(n[1]).max(n[2].max(0));
        let tf = f[0].min(f[1]).min(f[2].min(order_bits(tmax)));
        *o = f32::from_bits(tn as u32);
        mask |= u32::from(tn <= tf) << i;
    }
    (out, mask)
}

/// [`hit_portable`] with one AVX vector per plane: the same operations on the same values (one
/// fused multiply-subtract per plane, integer maxima and minima in the same pairs), so the
/// same distances and mask.
///
/// Always inlined, and only into the traversal compiled for AVX2 and FMA
/// ([`Bvh::traverse_avx`]), where the intrinsics it calls are inlined in turn (a call to it
/// would cost more than the test).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn hit_avx(node: &Node8, r: &RayPre, tmax: f32) -> ([f32; WIDTH], u32) {
    use std::arch::x86_64::*;
    let plane = |row: usize, a: usize| {
        let b = &node.bounds[row & 7];
        // SAFETY: `b` is an array of 8 f32, exactly the 32 bytes an unaligned load reads.
        let b = unsafe { _mm256_loadu_ps(b.as_ptr()) };
        let d = _mm256_fmsub_ps(b, _mm256_set1_ps(r.inv[a]), _mm256_set1_ps(r.oinv[a]));
        _mm256_castps_si256(d)
    };
    let (n0, n1, n2) = (
        plane(r.near[0], 0),
        plane(r.near[1], 1),
        plane(r.near[2], 2),
    );
    let (f0, f1, f2) = (plane(r.far[0], 0), plane(r.far[1], 1), plane(r.far[2], 2));
    let tn = _mm256_max_epi32(
        _mm256_max_epi32(n0, n1),
        _mm256_max_epi32(n2, _mm256_setzero_si256()),
    );
    let tf = _mm256_min_epi32(
        _mm256_min_epi32(f0, f1),
        _mm256_min_epi32(f2, _mm256_set1_epi32(order_bits(tmax))),
    );
    let mut out = [0.0f32; WIDTH];
    // SAFETY: `out` is 8 f32, the 32 bytes an unaligned store writes.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), _mm256_castsi256_ps(tn)) };
    // entered: not tn > tf
    let missed = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(tn, tf))) as u32;
    (out, !missed & 0xff)
}

/// Whether the AVX node test can run here: the CPU has AVX2 and FMA, and the bit instructions
/// every such CPU has (BMI1, BMI2, LZCNT, POPCNT), with which the single-ray traversals are
/// compiled too. Asked of std once, then read from one flag. Elsewhere the portable test
/// computes the same fused products in software.
#[inline(always)]
pub(crate) fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::sync::atomic::{AtomicU8, Ordering};
        // 0: not asked yet; 1: no; 2: yes
        static KNOWN: AtomicU8 = AtomicU8::new(0);
        match KNOWN.load(Ordering::Relaxed) {
            0 => {
                use std::arch::is_x86_feature_detected as has;
                let yes = has!("avx2")
                    && has!("fma")
                    && has!("bmi1")
                    && has!("bmi2")
                    && has!("lzcnt")
                    && has!("popcnt");
                KNOWN.store(1 + u8::from(yes), Ordering::Relaxed);
                yes
            }
            k => k == 2,
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Asks for the cache line at `p` ahead of its use (a hint: it never faults).
#[inline(always)]
fn prefetch_line<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing and never faults, whatever the address.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(p.cast::<i8>())
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Asks early for every cache line `v` occupies (a hint: nothing is read).
#[inline(always)]
pub(crate) fn prefetch_lines<T: ?Sized>(v: &T) {
    let p = (v as *const T).cast::<u8>();
    // from the start of the line `v` begins in
    let skew = p as usize & 63;
    for at in (0..skew + std::mem::size_of_val(v)).step_by(64) {
        prefetch_line(p.wrapping_sub(skew).wrapping_add(at));
    }
}

/// Asks early for the memory of a stacked child `(index, count)`: an inner node's four cache
/// lines, and whatever `leaf` asks for a leaf.
#[inline(always)]
fn prefetch_child(nodes: &[Node8], child: u32, count: u32, leaf: &impl Fn(usize, usize)) {
    if count != 0 {
        leaf(child as usize, count as usize);
    } else if let Some(c) = nodes.get(child as usize) {
        prefetch_lines(c);
    }
}

/// [`prefetch_child`] for each child of `node` in `mask`.
#[inline(always)]
fn prefetch_children(nodes: &[Node8], node: &Node8, mut mask: u32, leaf: &impl Fn(usize, usize)) {
    while mask != 0 {
        let i = mask.trailing_zeros() as usize & 7;
        mask &= mask - 1;
        prefetch_child(nodes, node.child[i], node.count[i], leaf);
    }
}

/// The first [`STACK_CAP`] entries of a traversal stack, grown to that size if needed, as a
/// fixed array (so that indices taken modulo its size need no bounds check).
#[inline(always)]
fn fixed_stack(stack: &mut Stack) -> Option<&mut [(u32, u32, f32); STACK_CAP]> {
    if stack.len() < STACK_CAP {
        stack.resize(STACK_CAP, (0, 0, 0.0));
    }
    <&mut [(u32, u32, f32); STACK_CAP]>::try_from(stack.get_mut(..STACK_CAP)?).ok()
}

/// The lowest child left in `mask` as a stack entry (index, count as in [`Node8`], entry
/// distance from `tn`), taken out of `mask`, which must not be empty.
#[inline(always)]
fn take_child(node: &Node8, tn: &[f32; WIDTH], mask: &mut u32) -> (u32, u32, f32) {
    let i = mask.trailing_zeros() as usize & 7;
    *mask &= mask.wrapping_sub(1);
    (node.child[i], node.count[i], tn[i])
}

/// Pops the next stacked child that may still hold a hit before `tmax` (entry distance at most
/// `tmax`), skipping the others; `None` when the stack is empty.
#[inline(always)]
fn pop(st: &[(u32, u32, f32); STACK_CAP], sp: &mut usize, tmax: f32) -> Option<(u32, u32, f32)> {
    while *sp > 0 {
        *sp -= 1;
        let e = st[*sp & (STACK_CAP - 1)];
        if e.2 <= tmax {
            return Some(e);
        }
    }
    None
}

/// Hierarchies of at least this many nodes ask for the memory of the children a ray stacks
/// as it stacks them ([`Bvh::prefetch`]): 1 MiB of nodes, about 6 MiB with their triangle
/// blocks, more than a core's L2 cache holds. Smaller ones mostly stay in the caches, where
/// the hints cost more instructions than they save waiting.
const PREFETCH_NODES: usize = 4096;

/// The hierarchy: a binary SAH tree collapsed into 8-wide nodes.
#[derive(Clone, Debug, Default)]
pub(crate) struct Bvh {
    pub nodes: Vec<Node8>,
    /// Whether traversals prefetch the children they stack at each node (and a node's line of
    /// child indices as the node is entered, while its boxes are tested): set for hierarchies
    /// of at least [`PREFETCH_NODES`] nodes, whose incoherent rays wait on memory more than on
    /// arithmetic. A hint only: the same nodes and leaves are visited either way.
    pub prefetch: bool,
}

impl Bvh {
    /// Builds over primitive boxes; returns the hierarchy and the primitive order (new position ->
    /// old index).
    #[cfg(test)]
    pub fn build(boxes: &[Aabb]) -> (Bvh, Vec<u32>) {
        Bvh::build_with(boxes, LEAF_MIN)
    }

    /// [`Bvh::build`] never splitting leaves of up to `leaf_min` primitives.
    #[cfg(test)]
    pub fn build_with(boxes: &[Aabb], leaf_min: usize) -> (Bvh, Vec<u32>) {
        let (bin, order) = build_binary(boxes, leaf_min);
        Bvh::collapse(&bin, order, leaf_min)
    }

    /// [`Bvh::build_with`], each of its two stages checked first against the memory left
    /// ([`crate::memory::check`]): the binary build at [`limits::BVH_BYTES_PER_BOX`] a box,
    /// then the 8-wide collapse at [`limits::BVH_BYTES_PER_NODE`] a binary node. `what` names
    /// the BVH (and its file) in the error.
    pub(crate) fn try_build_with(
        boxes: &[Aabb],
        leaf_min: usize,
        what: &dyn Fn() -> String,
    ) -> Result<(Bvh, Vec<u32>), Error> {
        crate::memory::check(
            || format!("{} ({} boxes)", what(), boxes.len()),
            (boxes.len() as u64).saturating_mul(limits::BVH_BYTES_PER_BOX),
        )?;
        let (bin, order) = build_binary(boxes, leaf_min);
        crate::memory::check(
            || format!("{} ({} binary nodes)", what(), bin.len()),
            (bin.len() as u64).saturating_mul(limits::BVH_BYTES_PER_NODE),
        )?;
        Ok(Bvh::collapse(&bin, order, leaf_min))
    }

    /// The binary tree `bin` collapsed into 8-wide nodes.
    #[inline(never)]
    fn collapse(bin: &[Node], order: Vec<u32>, leaf_min: usize) -> (Bvh, Vec<u32>) {
        let block = block_size(leaf_min);
        let plan = Collapse::plan(bin, block, max_leaf(block));
        let mut nodes = Vec::with_capacity(bin.len() / 4 + 1);
        if !bin.is_empty() {
            // (binary node, Node8 slot to fill)
            nodes.push(Node8::empty());
            let mut work = vec![(0usize, 0usize)];
            let mut kids: Vec<(usize, bool)> = Vec::with_capacity(WIDTH);
            while let Some((bi, slot)) = work.pop() {
                kids.clear();
                plan.node_children(bin, bi, &mut kids);
                let mut n8 = Node8::empty();
                for (i, &(k, leaf)) in kids.iter().enumerate().take(WIDTH) {
                    let Some(n) = bin.get(k) else { continue };
                    let b = n.bounds();
                    for a in 0..3 {
                        n8.bounds[a][i] = b.min[a];
                        n8.bounds[3 + a][i] = b.max[a];
                    }
                    if leaf {
                        let (first, count) = plan.range(k);
                        n8.child[i] = first;
                        n8.count[i] = count;
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
        let prefetch = nodes.len() >= PREFETCH_NODES;
        (Bvh { nodes, prefetch }, order)
    }

    /// Visits leaves, `visit(first, count, tmax) -> new tmax`. With `ORDERED`, the children hit
    /// at each node are handled nearest first, leaves and inner nodes alike. Stops when a visit
    /// returns a negative value (any-hit queries).
    #[cfg(test)]
    #[inline(always)]
    pub fn traverse<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
        visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        self.traverse_in::<ORDERED>(ray, tmax, &mut scratch.ray, &mut scratch.work, visit)
    }

    /// Visits leaves, `visit(first, count, tmax) -> new tmax`, with the given stack and work
    /// counter (a leaf visit can traverse another hierarchy, a mesh instance's, with a second
    /// stack). With `ORDERED`, the children hit at each node are handled nearest first, leaves
    /// and inner nodes alike. Stops when a visit returns a negative value (any-hit queries).
    #[inline(always)]
    pub fn traverse_in<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut RayStack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        self.traverse_prefetching::<ORDERED>(ray, tmax, stack, work, visit, |_, _| {})
    }

    /// [`Bvh::traverse_in`] that, where this hierarchy prefetches ([`Bvh::prefetch`]), also
    /// calls `prefetch(first, count)` for every leaf it stacks, so that the leaf's primitives
    /// can be asked for early (the traversal itself does so for the inner nodes it stacks).
    /// Runs the AVX node test where the CPU has it (the whole loop compiled for AVX2 and FMA),
    /// else the portable one.
    #[inline(always)]
    pub fn traverse_prefetching<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut RayStack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe {
                self.traverse_avx::<ORDERED>(ray, tmax, stack, work, visit, prefetch)
            };
        }
        self.traverse_loop::<ORDERED, false>(ray, tmax, stack, work, visit, prefetch)
    }

    /// [`Bvh::traverse_prefetching`] for a caller that chose the node test itself: `AVX` in a
    /// function compiled for AVX2 and FMA (`#[target_feature]`), into which the whole loop is
    /// then inlined, the visit's leaf tests with it.
    ///
    /// # Safety
    /// With `AVX`, the CPU must have AVX2 and FMA.
    #[inline(always)]
    pub(crate) unsafe fn traverse_compiled<const ORDERED: bool, const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut RayStack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        self.traverse_loop::<ORDERED, AVX>(ray, tmax, stack, work, visit, prefetch)
    }

    /// [`Bvh::traverse_loop`] compiled with AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn traverse_avx<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut RayStack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        self.traverse_loop::<ORDERED, true>(ray, tmax, stack, work, visit, prefetch)
    }

    /// The traversal; `AVX` only where the CPU has it (see [`Bvh::traverse_in`]): the ordered
    /// loop for closest hits, [`Bvh::any_loop`] for any-hit queries.
    #[inline(always)]
    fn traverse_loop<const ORDERED: bool, const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut RayStack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        if ORDERED {
            self.ordered_loop::<AVX>(ray, tmax, &mut stack.ordered, work, visit, prefetch)
        } else {
            self.any_loop::<AVX>(ray, tmax, &mut stack.any, work, visit, prefetch)
        }
    }

    /// Closest-hit traversal through one stack of leaves and nodes: the children hit at each
    /// node are sorted by entry distance, the nearest (leaf or node) is handled next and the
    /// others are stacked far to near, each skipped when popped if a closer hit was found
    /// meanwhile. The stack is addressed modulo [`STACK_CAP`], which the build's depth cap
    /// keeps it below.
    ///
    /// Hierarchies that prefetch ([`Bvh::prefetch`]) and those that do not get a loop each, so
    /// that neither tests the flag per node.
    #[inline(always)]
    fn ordered_loop<const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut Stack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        if self.prefetch {
            self.ordered_walk::<AVX, true>(ray, tmax, stack, work, visit, prefetch)
        } else {
            self.ordered_walk::<AVX, false>(ray, tmax, stack, work, visit, prefetch)
        }
    }

    /// [`Bvh::ordered_loop`] for a hierarchy that prefetches (`PREFETCH`) or does not.
    // Longer than 80 lines, kept whole: the loop of every closest-hit query, run per node.
    // The node test, the sorted stacking and the leaf visit share its state (the ray's
    // planes, the stack and its pointer, the bound, the work count), which must stay in
    // registers; split, its parts would pass it by reference, which only an instruction count
    // before and after could clear (docs/testing.md; tests/function_length.rs lists it).
    #[inline(always)]
    fn ordered_walk<const AVX: bool, const PREFETCH: bool>(
        &self,
        ray: &Ray,
        mut tmax: f32,
        stack: &mut Stack,
        work: &mut u64,
        mut visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        if self.nodes.is_empty() {
            return tmax;
        }
        let Some(st) = fixed_stack(stack) else {
            return tmax;
        };
        let nodes = &self.nodes[..];
        let pre = RayPre::new(ray);
        let mut sp = 0usize;
        // the child handled next: (index, count as in Node8, entry distance)
        let mut cur = (0u32, 0u32, 0.0f32);
        // the work is counted here and added once (not stored to memory per node)
        let mut w = 0u64;
        let t = 'run: loop {
            if cur.1 == 0 {
                let Some(node) = nodes.get(cur.0 as usize) else {
                    break 'run tmax;
                };
                w += 1;
                if PREFETCH {
                    prefetch_line(node.child.as_ptr());
                }
                let (tn, mut mask) = node_test::<AVX>(node, &pre, tmax);
                // a stacked child's memory is asked for as it is stacked (the nearest one is
                // read at once anyway)
                let stacked = |e: (u32, u32, f32)| {
                    if PREFETCH {
                        prefetch_child(nodes, e.0, e.1, &prefetch);
                    }
                };
                if mask != 0 {
                    let mut near = take_child(node, &tn, &mut mask);
                    if mask != 0 {
                        // the second child: the farther of the two is stacked
                        let mut far = take_child(node, &tn, &mut mask);
                        if far.2 < near.2 {
                            std::mem::swap(&mut near, &mut far);
                        }
                        stacked(far);
                        if mask == 0 {
                            st[sp & (STACK_CAP - 1)] = far;
                            sp += 1;
                        } else {
                            // three or more: insertion into the top of the stack, far to near
                            let base = sp;
                            st[sp & (STACK_CAP - 1)] = far;
                            sp += 1;
                            while mask != 0 {
                                let mut e = take_child(node, &tn, &mut mask);
                                if e.2 < near.2 {
                                    std::mem::swap(&mut near, &mut e);
                                }
                                stacked(e);
                                let mut j = sp;
                                while j > base && st[(j - 1) & (STACK_CAP - 1)].2 < e.2 {
                                    st[j & (STACK_CAP - 1)] = st[(j - 1) & (STACK_CAP - 1)];
                                    j -= 1;
                                }
                                st[j & (STACK_CAP - 1)] = e;
                                sp += 1;
                            }
                        }
                    }
                    cur = near;
                    continue;
                }
            } else {
                w += (cur.1 & !LEAF_BLOCKS) as u64;
                tmax = visit(cur.0 as usize, cur.1 as usize, tmax);
                if tmax < 0.0 {
                    break 'run tmax;
                }
            }
            match pop(st, &mut sp, tmax) {
                Some(e) => cur = e,
                None => break 'run tmax,
            }
        };
        *work += w;
        t
    }

    /// Gives each leaf `(first primitive, count)` to `blocks`, which may store the leaf's
    /// primitives as blocks and return the first block's index: the leaf then names that block
    /// and is marked with [`LEAF_BLOCKS`]. Leaves already marked are left alone.
    pub fn mark_block_leaves(&mut self, mut blocks: impl FnMut(usize, usize) -> Option<u32>) {
        for n in &mut self.nodes {
            for i in 0..WIDTH {
                let c = n.count[i];
                if c == 0 || c == EMPTY || c & LEAF_BLOCKS != 0 {
                    continue;
                }
                if let Some(b) = blocks(n.child[i] as usize, c as usize) {
                    n.child[i] = b;
                    n.count[i] = c | LEAF_BLOCKS;
                }
            }
        }
    }

    /// Every leaf as (first primitive, count); after [`Bvh::mark_block_leaves`], a marked leaf
    /// appears as (first block, count with [`LEAF_BLOCKS`]).
    #[cfg(test)]
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
    /// The slots holding inner nodes (`count == 0`), as a bit mask.
    #[cfg(test)]
    fn inner_mask(&self) -> u32 {
        let mut m = 0u32;
        for (i, &c) in self.count.iter().enumerate() {
            m |= ((c == 0) as u32) << i;
        }
        m
    }

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
        hit_portable(self, &RayPre::new(ray), tmax)
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

    /// `limits::BVH_BYTES_PER_BOX` and `BVH_BYTES_PER_NODE`, checked against the memory left
    /// before the binary build and before the collapse, cover the arrays each stage makes, as
    /// allocated (capacities), for coincident boxes (the worst leaves) and for a grid, of
    /// either leaf size.
    #[test]
    fn bvh_bytes_per_box_covers_the_build() {
        let same = vec![grid()[0]; 1000];
        for boxes in [grid(), same] {
            for leaf in [LEAF_MIN, LEAF_MIN_TRIANGLES] {
                let n = boxes.len();
                let (bin, order) = build_binary(&boxes, leaf);
                let block = block_size(leaf);
                let plan = Collapse::plan(&bin, block, max_leaf(block));
                let (bvh, _) = Bvh::build_with(&boxes, leaf);
                let binary = order.capacity() * 4
                    + bin.capacity() * std::mem::size_of::<Node>()
                    + 2 * n * std::mem::size_of::<BuildRef>();
                assert!(
                    binary as u64 <= crate::limits::BVH_BYTES_PER_BOX * n as u64,
                    "{} bytes a box",
                    binary / n
                );
                let collapse = plan.cost.capacity() * 4
                    + plan.choice.capacity() * std::mem::size_of::<Choice>()
                    + plan.node_split.capacity()
                    + plan.ranges.capacity() * 8
                    + bvh.nodes.capacity() * std::mem::size_of::<Node8>();
                assert!(
                    collapse as u64 <= crate::limits::BVH_BYTES_PER_NODE * bin.len() as u64,
                    "{} bytes a node",
                    collapse / bin.len()
                );
            }
        }
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
        // in [-2, 2)
        let mut f = || crate::test_support::rng(&mut seed) * 2.0;
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
            let (t, m) = hit_portable(&node, &pre, tmax);
            hits += m.count_ones();
            // the integer order against float maxima and minima: the same children entered
            // (a negative exit, -0 included, is not entered) at the same distances
            for (i, ti) in t.iter().enumerate() {
                let d =
                    |row: usize, a: usize| node.bounds[row][i].mul_add(pre.inv[a], -pre.oinv[a]);
                let tn = (0..3).fold(0.0f32, |m, a| m.max(d(pre.near[a], a)));
                let tf = (0..3).fold(tmax, |m, a| m.min(d(pre.far[a], a)));
                let entered = tn <= tf && tf.is_sign_positive();
                assert_eq!(m >> i & 1 == 1, entered, "round {round}, child {i}");
                if entered {
                    assert_eq!(ti.to_bits(), tn.to_bits(), "round {round}, child {i}");
                }
            }
            if has_avx2_fma() {
                // SAFETY: the CPU has AVX2 and FMA (checked on the line above).
                let (ta, ma) = unsafe { hit_avx(&node, &pre, tmax) };
                assert_eq!(m, ma);
                assert_eq!(t.map(f32::to_bits), ta.map(f32::to_bits));
            }
        }
        assert!(hits > 5000, "{hits}");
    }

    /// The any-hit loop (one stack of leaves and nodes) and the ordered loop meet a box in front
    /// of the ray exactly when one exists, on rays in every direction from inside and outside.
    #[test]
    fn any_hit_and_ordered_traversals_agree_with_brute_force() {
        let boxes = grid();
        let (built, order) = Bvh::build(&boxes);
        // leaves the prefetching traversal hinted at
        let hinted = std::cell::Cell::new(0u64);
        // the same answers and work with and without prefetching
        for prefetch in [false, true] {
            let bvh = Bvh {
                prefetch,
                ..built.clone()
            };
            let mut scratch = Scratch::new();
            let mut seed = 0x9e37_79b9_7f4a_7c15u64;
            let mut f = || {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 40) as f32 / (1u64 << 24) as f32
            };
            // the entry distance of a box, if the ray enters it before tmax (a plain slab test)
            let enter = |b: &Aabb, r: &Ray, tmax: f32| -> Option<f32> {
                let (mut lo, mut hi) = (0.0f32, tmax);
                for a in 0..3 {
                    let (t0, t1) = (
                        (b.min[a] - r.origin[a]) * r.inv_dir[a],
                        (b.max[a] - r.origin[a]) * r.inv_dir[a],
                    );
                    lo = lo.max(t0.min(t1));
                    hi = hi.min(t0.max(t1));
                }
                (lo <= hi).then_some(lo)
            };
            let (mut hits, mut misses) = (0, 0);
            for round in 0..4000 {
                let o = Vec3A::new(f() * 14.0 - 2.0, f() * 14.0 - 2.0, f() * 34.0 - 2.0);
                let d = Vec3A::new(f() - 0.5, f() - 0.5, f() - 0.5);
                let ray = Ray::new(o, d);
                let tmax = if round % 2 == 0 { 4.0 } else { f32::INFINITY };
                // boxes a clear margin inside or outside the ray's reach, so rounding cannot matter
                let want = boxes
                    .iter()
                    .filter_map(|b| enter(b, &ray, tmax))
                    .fold(f32::INFINITY, f32::min);
                let grown = |b: &Aabb, g: f32| Aabb {
                    min: b.min - Vec3A::splat(g),
                    max: b.max + Vec3A::splat(g),
                };
                let near_miss = boxes.iter().any(|b| {
                    enter(&grown(b, 1e-3), &ray, tmax).is_some()
                        != enter(&grown(b, -1e-3), &ray, tmax).is_some()
                });
                if near_miss {
                    continue;
                }
                let any = bvh.traverse::<false>(&ray, tmax, &mut scratch, |first, count, t| {
                    let leaf = &order[first..first + count];
                    if leaf
                        .iter()
                        .any(|&k| enter(&boxes[k as usize], &ray, t).is_some())
                    {
                        -1.0
                    } else {
                        t
                    }
                });
                assert_eq!(any < 0.0, want.is_finite(), "round {round}");
                // the portable loop (what runs without AVX2): the same answer and the same work
                let (mut w_sse, mut w) = (0u64, 0u64);
                let leaf_any = |first: usize, count: usize, t: f32| {
                    let leaf = &order[first..first + count];
                    if leaf
                        .iter()
                        .any(|&k| enter(&boxes[k as usize], &ray, t).is_some())
                    {
                        -1.0
                    } else {
                        t
                    }
                };
                let sse = bvh.traverse_loop::<false, false>(
                    &ray,
                    tmax,
                    &mut scratch.ray,
                    &mut w_sse,
                    leaf_any,
                    |_, _| {},
                );
                let all = bvh.traverse_in::<false>(&ray, tmax, &mut scratch.ray, &mut w, leaf_any);
                assert_eq!((sse.to_bits(), w_sse), (all.to_bits(), w), "round {round}");
                let mut best = f32::INFINITY;
                bvh.traverse_prefetching::<true>(
                    &ray,
                    tmax,
                    &mut scratch.ray,
                    &mut scratch.work,
                    |first, count, t| {
                        for &k in &order[first..first + count] {
                            if let Some(e) = enter(&boxes[k as usize], &ray, t) {
                                best = best.min(e);
                            }
                        }
                        t
                    },
                    |first, count| {
                        // hints come only where asked for, and name real leaves
                        assert!(prefetch && count > 0 && first + count <= order.len());
                        hinted.set(hinted.get() + 1);
                    },
                );
                assert_eq!(best.to_bits(), want.to_bits(), "round {round}");
                if want.is_finite() {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
            assert!(hits > 500 && misses > 500, "{hits} {misses}");
        }
        assert!(hinted.get() > 100, "{}", hinted.get());
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

#[cfg(test)]
mod stats_report {
    use super::*;
    use crate::{raysets, Scene};

    /// Shape of the hierarchy and work per ray on a big mesh, for tuning:
    /// `RT_MESH=/tmp/knot600k.obj cargo test --release -p ring_tracer_kernel bvh_stats_report --
    /// --ignored --nocapture` (`RT_SPLIT_COST=C` builds with split cost `C`). Not a check.
    #[test]
    #[ignore]
    fn bvh_stats_report() {
        let Ok(path) = std::env::var("RT_MESH") else {
            return;
        };
        // RT_SPLIT_COST: the binary build's cost of a split, for trying other trees
        if let Some(c) = std::env::var("RT_SPLIT_COST")
            .ok()
            .and_then(|c| c.parse().ok())
        {
            probe::SPLIT.with(|t| t.set(c));
        }
        let t = std::time::Instant::now();
        let scene = Scene::load(std::path::Path::new(&path)).unwrap();
        println!("load + build {:.3} s", t.elapsed().as_secs_f64());
        let boxes: Vec<Aabb> = scene
            .triangles()
            .iter()
            .map(|t| Aabb::EMPTY.grow(t[0]).grow(t[1]).grow(t[2]))
            .collect();
        for _ in 0..3 {
            let t = std::time::Instant::now();
            let (b, _) = Bvh::build_with(&boxes, LEAF_MIN_TRIANGLES);
            println!(
                "BVH build alone {:.3} s ({} nodes)",
                t.elapsed().as_secs_f64(),
                b.nodes.len()
            );
        }
        let bvh = &scene.bvh;
        let leaves: Vec<(usize, usize)> = bvh
            .leaves()
            .map(|(f, c)| scene.tri_blocks.prims(f, c))
            .collect();
        let prims: usize = leaves.iter().map(|l| l.1).sum();
        let blocks: usize = leaves.iter().map(|l| l.1.div_ceil(4)).sum();
        let mut slots = 0;
        for n in &bvh.nodes {
            slots += n.count.iter().filter(|&&c| c != EMPTY).count();
        }
        println!(
            "nodes {} leaves {} prims {} blocks {} fill {:.2} children/node",
            bvh.nodes.len(),
            leaves.len(),
            prims,
            blocks,
            slots as f64 / bvh.nodes.len() as f64
        );
        // Embree's SAH figure (its `verbose=2` statistics), see the `sah` module
        println!("SAH as Embree counts it {:.3}", sah::embree_sah(&bvh.nodes));
        let mut hist = [0usize; 9];
        for l in &leaves {
            hist[l.1.min(8)] += 1;
        }
        println!("leaves by size (0..=8+): {hist:?}");
        let mut s = Scratch::new();
        let b = scene.bounds();
        for (kind, rays) in [
            ("primary", raysets::primary(b, 512)),
            ("incoherent", raysets::incoherent(b, 1 << 18)),
        ] {
            // (label, ordered, stop at the first hit)
            for (mode, any) in [("closest", false), ("any, unordered", true)] {
                probe::NODES.with(|c| c.set(0));
                probe::SHAPE.with(|h| *h.borrow_mut() = [[0; 9]; 9]);
                let (mut leafv, mut blockv) = (0u64, 0u64);
                for r in &rays {
                    let visit = |f: usize, c: usize, t: f32| {
                        leafv += 1;
                        let (f, c) = scene.tri_blocks.prims(f, c);
                        let mut tm = t;
                        for (k, sh) in scene.geom.shapes[f..f + c].iter().enumerate() {
                            if k % 4 == 0 {
                                blockv += 1;
                            }
                            if let Some(x) = scene.geom.hit(sh, r, 0.0, tm) {
                                tm = x;
                                if any {
                                    return -1.0;
                                }
                            }
                        }
                        tm
                    };
                    if any {
                        bvh.traverse_in::<false>(r, f32::INFINITY, &mut s.ray, &mut s.work, visit);
                    } else {
                        bvh.traverse_in::<true>(r, f32::INFINITY, &mut s.ray, &mut s.work, visit);
                    }
                }
                let nodes = probe::NODES.with(|c| c.get());
                let shape = probe::SHAPE.with(|h| std::mem::take(&mut *h.borrow_mut()));
                for (k, row) in shape.iter().enumerate().take(5) {
                    let tot: u64 = shape.iter().flatten().sum();
                    let pct: Vec<String> = row[..5]
                        .iter()
                        .map(|&x| format!("{:5.1}", 100.0 * x as f64 / tot as f64))
                        .collect();
                    println!("  {k} inner hit, 0..4 leaves hit: {}", pct.join(" "));
                }
                let n = rays.len() as f64;
                println!(
                    "{kind} {mode}: nodes/ray {:.2} leaves/ray {:.2} blocks/ray {:.2}",
                    nodes as f64 / n,
                    leafv as f64 / n,
                    blockv as f64 / n
                );
            }
        }
        // the node walk alone: every leaf entered is visited and nothing is hit
        for (kind, rays) in [
            ("primary", raysets::primary(b, 512)),
            ("incoherent", raysets::incoherent(b, 1 << 18)),
        ] {
            for any in [false, true] {
                probe::NODES.with(|c| c.set(0));
                let t = std::time::Instant::now();
                let mut leafv = 0u64;
                for _ in 0..4 {
                    for r in &rays {
                        let visit = |_: usize, _: usize, t: f32| {
                            leafv += 1;
                            t
                        };
                        if any {
                            bvh.traverse_in::<false>(
                                r,
                                f32::INFINITY,
                                &mut s.ray,
                                &mut s.work,
                                visit,
                            );
                        } else {
                            bvh.traverse_in::<true>(
                                r,
                                f32::INFINITY,
                                &mut s.ray,
                                &mut s.work,
                                visit,
                            );
                        }
                    }
                }
                let secs = t.elapsed().as_secs_f64();
                let n = 4.0 * rays.len() as f64;
                let nodes = probe::NODES.with(|c| c.get()) as f64;
                println!(
                    "walk only {kind} ordered={}: nodes/ray {:.2} leaves/ray {:.2}, {:.1} ns/ray, {:.2} ns/node",
                    !any,
                    nodes / n,
                    leafv as f64 / n,
                    secs * 1e9 / n,
                    secs * 1e9 / nodes
                );
            }
        }
        let rays = raysets::incoherent(b, 1 << 18);
        for round in 0..2 {
            let t = std::time::Instant::now();
            let hits = rays
                .iter()
                .filter(|r| scene.intersect_with(r, f32::INFINITY, &mut s).is_some())
                .count();
            let a = t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            let occ = rays
                .iter()
                .filter(|r| scene.occluded_with(r, f32::INFINITY, &mut s))
                .count();
            let b = t.elapsed().as_secs_f64();
            let m = rays.len() as f64 / 1e6;
            println!(
                "round {round}: closest {:.2} Mrays/s ({hits}), any {:.2} Mrays/s ({occ})",
                m / a,
                m / b
            );
        }
    }
}
