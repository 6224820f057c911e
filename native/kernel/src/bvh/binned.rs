//! The binary binned-SAH build: primitive references of 32 bytes (the box, the primitive's
//! index in the minimum's spare lane), node by node from a work stack, in two arrays: a node's
//! partition copies its references from the array that holds them to the other, the left
//! side's to the front and the right side's to the back, with no branch on the side. Each
//! node's box comes from its parent's bins and its centroid box from its parent's partition,
//! so a node reads its references twice: once to bin them (the three axes in one pass, bin
//! numbers computed for the three at once, a bin's box a union of eight lanes), once to
//! partition them. Nodes get fewer bins the fewer references they hold (4 + count / 4, at most
//! [`BINS`]), so that the many small nodes near the leaves do not pay for 32 bins they cannot
//! fill; the loops over bins run over 8, 16 or 32 of them whatever the node's own number (the
//! others stay empty), and the best split is kept without a branch, so that neither
//! mispredicts. The whole build is compiled for AVX2 where the CPU has it, with the same
//! operations on the same values either way.

use super::{blocks_of, leaf_min, max_leaf, split_cost, Node, MAX_DEPTH};
use crate::geometry::Aabb;
use glam::{BVec3A, Vec3A, Vec4};

/// Most SAH bins per axis.
pub(super) const BINS: usize = 32;

/// A primitive reference during the build: its box, with the primitive's index as the bits of
/// the minimum's `w`. Centroids are taken as `min + max` (twice the centre: the factor is the
/// same for every reference, so bins and splits are those of the centres).
#[derive(Clone, Copy)]
#[repr(C)]
pub(super) struct BuildRef {
    min: Vec4,
    max: Vec4,
}

impl BuildRef {
    /// A reference of a point box at the origin (what the second array starts as).
    const ZERO: BuildRef = BuildRef {
        min: Vec4::ZERO,
        max: Vec4::ZERO,
    };
    #[inline(always)]
    fn new(b: &Aabb, index: u32) -> BuildRef {
        BuildRef {
            min: b.min.extend(f32::from_bits(index)),
            max: b.max.extend(0.0),
        }
    }
    #[inline(always)]
    fn bounds(&self) -> Aabb {
        Aabb {
            min: Vec3A::from_vec4(self.min),
            max: Vec3A::from_vec4(self.max),
        }
    }
    /// Twice the box's centre.
    #[inline(always)]
    fn centroid(&self) -> Vec3A {
        Vec3A::from_vec4(self.min + self.max)
    }
    #[inline(always)]
    fn index(&self) -> u32 {
        self.min.w.to_bits()
    }
}

/// A node's references' box and centroid box (of [`BuildRef::centroid`]s).
#[derive(Clone, Copy)]
struct Extent {
    bounds: Aabb,
    centroids: Aabb,
}

impl Extent {
    const EMPTY: Extent = Extent {
        bounds: Aabb::EMPTY,
        centroids: Aabb::EMPTY,
    };
    #[inline(always)]
    fn add(&mut self, r: &BuildRef) {
        self.bounds = self.bounds.union(r.bounds());
        self.centroids = self.centroids.grow(r.centroid());
    }
    #[inline(never)]
    fn of(refs: &[BuildRef]) -> Extent {
        let mut e = Extent::EMPTY;
        refs.iter().for_each(|r| e.add(r));
        e
    }
}

/// How a node's centroids map to bins: `bins` per axis, bin of `c` = `(c - lo) * scale`
/// truncated (at most `bins - 1`); a flat axis has scale 0 (everything in bin 0).
#[derive(Clone, Copy)]
struct Mapping {
    lo: Vec3A,
    scale: Vec3A,
    last: Vec3A,
}

impl Mapping {
    fn new(bins: usize, centroids: &Aabb) -> Mapping {
        let ext = centroids.max - centroids.min;
        let scale = Vec3A::select(
            ext.cmpgt(Vec3A::ZERO),
            Vec3A::splat(bins as f32 * 0.999_99) / ext,
            Vec3A::ZERO,
        );
        Mapping {
            lo: centroids.min,
            scale,
            last: Vec3A::splat((bins - 1) as f32),
        }
    }

    /// The bins of `r` on the three axes (the fourth lane is meaningless).
    #[inline(always)]
    fn bin(&self, r: &BuildRef) -> [i32; 4] {
        let f = ((r.centroid() - self.lo) * self.scale).min(self.last);
        truncate(f)
    }
}

/// `f`'s lanes truncated to integers (all in `0..BINS` here).
#[inline(always)]
fn truncate(f: Vec3A) -> [i32; 4] {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        let mut out = [0i32; 4];
        // SAFETY: SSE2 is part of x86_64; the store writes the 16 bytes of `out`.
        unsafe {
            let i = _mm_cvttps_epi32(f.into());
            _mm_storeu_si128(out.as_mut_ptr().cast(), i);
        }
        out
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        [f.x as i32, f.y as i32, f.z as i32, 0]
    }
}

/// The bins of the three axes, reused from node to node (only a node's own bins are reset).
/// Two sets: consecutive references, often neighbours in the mesh and so in the same bins,
/// go to alternate sets, so that one's update need not wait for the other's; the second set is
/// added into the first after the pass.
struct Bins {
    boxes: [[[BinBox; BINS]; 3]; 2],
    counts: [[[u32; BINS]; 3]; 2],
}

/// A bin's box as its minimum and its negated maximum, so that a union is one minimum of
/// eight lanes (one AVX instruction where the build is compiled for it). The `w` lanes mean
/// nothing.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct BinBox {
    lo: Vec4,
    neg_hi: Vec4,
}

impl BinBox {
    const EMPTY: BinBox = BinBox {
        lo: Vec4::INFINITY,
        neg_hi: Vec4::INFINITY,
    };
    #[inline(always)]
    fn of(r: &BuildRef) -> BinBox {
        BinBox {
            lo: r.min,
            neg_hi: -r.max,
        }
    }
    /// The union: with `AVX`, one minimum of eight lanes.
    #[inline(always)]
    fn union<const AVX: bool>(self, o: BinBox) -> BinBox {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            use std::arch::x86_64::{__m256, _mm256_min_ps};
            // SAFETY: AVX is set only in the build compiled for AVX2 (`build_avx2`), which runs
            // where the CPU has it; BinBox and __m256 are both 32 bytes of f32 lanes, any bits
            // valid.
            return unsafe {
                let (a, b) = (
                    std::mem::transmute::<BinBox, __m256>(self),
                    std::mem::transmute::<BinBox, __m256>(o),
                );
                std::mem::transmute::<__m256, BinBox>(_mm256_min_ps(a, b))
            };
        }
        BinBox {
            lo: self.lo.min(o.lo),
            neg_hi: self.neg_hi.min(o.neg_hi),
        }
    }
    #[inline(always)]
    fn aabb(&self) -> Aabb {
        Aabb {
            min: Vec3A::from_vec4(self.lo),
            max: -Vec3A::from_vec4(self.neg_hi),
        }
    }
    /// [`Aabb::half_area`] of [`BinBox::aabb`], to the bit (`-(lo + neg_hi)` is `max - min`
    /// but for the sign of a zero, which the clamp at zero makes +0 either way).
    #[inline(always)]
    fn half_area(&self) -> f32 {
        let d = (-Vec3A::from_vec4(self.lo + self.neg_hi)).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// The best split found: SAH cost (the children's area-weighted block counts), axis, the
/// last bin of the left side, and both sides' boxes (the unions of their bins' boxes, so the
/// unions of their references' boxes).
#[derive(Clone, Copy)]
struct Split {
    cost: f32,
    axis: usize,
    bin: i32,
    left: Aabb,
    right: Aabb,
}

impl Bins {
    fn new() -> Box<Bins> {
        Box::new(Bins {
            boxes: [[[BinBox::EMPTY; BINS]; 3]; 2],
            counts: [[[0; BINS]; 3]; 2],
        })
    }

    /// Adds `r` to set `set`'s bins.
    #[inline(always)]
    fn add<const AVX: bool>(&mut self, set: usize, r: &BuildRef, m: &Mapping) {
        let k = m.bin(r);
        let b = BinBox::of(r);
        let (boxes, counts) = (&mut self.boxes[set & 1], &mut self.counts[set & 1]);
        for a in 0..3 {
            let k = k[a] as usize & (BINS - 1);
            counts[a][k] += 1;
            boxes[a][k] = boxes[a][k].union::<AVX>(b);
        }
    }

    /// The best split of `refs`, whose centroids' box is `centroids`, over `used` bins on
    /// each axis (at most `N`; those past `used` stay empty, and a split with an empty side is
    /// never the best, so the split is the one `used` bins give), and the bins' mapping.
    #[inline(always)]
    fn split<const AVX: bool, const N: usize>(
        &mut self,
        refs: &[BuildRef],
        used: usize,
        centroids: &Aabb,
        block: u32,
    ) -> Option<(Split, Mapping)> {
        let m = Mapping::new(used.min(N), centroids);
        self.fill::<AVX, N>(refs, &m);
        Some((self.best::<AVX, N>(block)?, m))
    }

    /// Bins `refs` on the three axes by `m`, whose bins are `N`: a constant, so that the loops
    /// over bins have no exit to mispredict.
    #[inline(always)]
    fn fill<const AVX: bool, const N: usize>(&mut self, refs: &[BuildRef], m: &Mapping) {
        for set in 0..2 {
            for a in 0..3 {
                self.boxes[set][a][..N].fill(BinBox::EMPTY);
                self.counts[set][a][..N].fill(0);
            }
        }
        let pairs = refs.chunks_exact(2);
        if let [last] = pairs.remainder() {
            self.add::<AVX>(1, last, m);
        }
        for p in pairs {
            self.add::<AVX>(0, &p[0], m);
            self.add::<AVX>(1, &p[1], m);
        }
        let [first, second] = &mut self.boxes;
        let [c0, c1] = &mut self.counts;
        for a in 0..3 {
            for k in 0..N {
                first[a][k] = first[a][k].union::<AVX>(second[a][k]);
                c0[a][k] += c1[a][k];
            }
        }
    }

    /// The least-cost split of the `N` filled bins over the three axes (`None` when no split
    /// separates anything): the first least cost in the order axis 0 to 2, last bin to first,
    /// kept without a branch.
    #[inline(always)]
    fn best<const AVX: bool, const N: usize>(&self, block: u32) -> Option<Split> {
        let (mut cost, mut at) = (f32::INFINITY, usize::MAX);
        for a in 0..3 {
            let (boxes, counts) = (&self.boxes[0][a], &self.counts[0][a]);
            // left[k]: the cost of bins ..=k as one side (infinite when empty)
            let mut left = [0.0f32; BINS];
            let (mut acc, mut c) = (BinBox::EMPTY, 0);
            for k in 0..N - 1 {
                acc = acc.union::<AVX>(boxes[k]);
                c += counts[k];
                left[k] = side_cost(&acc, c, block);
            }
            let (mut acc, mut c) = (BinBox::EMPTY, 0);
            for k in (1..N).rev() {
                acc = acc.union::<AVX>(boxes[k]);
                c += counts[k];
                let here = left[k - 1] + side_cost(&acc, c, block);
                let better = here < cost;
                cost = if better { here } else { cost };
                at = if better { a * BINS + k - 1 } else { at };
            }
        }
        if at == usize::MAX {
            return None;
        }
        let (axis, bin) = (at / BINS, at % BINS);
        let side = |ks: std::ops::Range<usize>| {
            ks.fold(BinBox::EMPTY, |acc, k| {
                acc.union::<AVX>(self.boxes[0][axis % 3][k % BINS])
            })
        };
        Some(Split {
            cost,
            axis,
            bin: bin as i32,
            left: side(0..bin + 1).aabb(),
            right: side(bin + 1..N).aabb(),
        })
    }
}

/// The SAH cost of one side of a split: its area times its blocks, infinite when it holds
/// nothing (a split that separates nothing is no split).
#[inline(always)]
fn side_cost(b: &BinBox, count: u32, block: u32) -> f32 {
    let cost = b.half_area() * blocks_of(count, block);
    if count == 0 {
        f32::INFINITY
    } else {
        cost
    }
}

/// Copies the references of `src` whose bin on `s.axis` is at most `s.bin` to the front of
/// `dst` and the others to its back, without a branch on the side (each goes to both ends'
/// next slots, and one end moves on); returns the front's length and both sides' extents
/// (boxes from the split, centroid boxes gathered here). The bin test is [`Mapping::bin`]'s
/// without the integers: a truncation is at most `s.bin` exactly when its argument is below
/// `s.bin + 1` (the cap at the last bin does not matter, as `s.bin` is below it), and a NaN
/// goes right in both.
#[inline(always)]
fn partition(
    src: &[BuildRef],
    dst: &mut [BuildRef],
    m: &Mapping,
    s: &Split,
) -> (usize, Extent, Extent) {
    let (axis, limit) = (s.axis.min(2), (s.bin + 1) as f32);
    let (lo, scale) = (m.lo[axis], m.scale[axis]);
    let (inf, ninf) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    let (mut left, mut right) = (Aabb::EMPTY, Aabb::EMPTY);
    let (mut l, mut r) = (0, dst.len());
    for x in src {
        let c = x.centroid();
        let is_left = (c[axis] - lo) * scale < limit;
        if let Some(d) = dst.get_mut(l) {
            *d = *x;
        }
        if let Some(d) = dst.get_mut(r.wrapping_sub(1)) {
            *d = *x;
        }
        l += usize::from(is_left);
        r -= usize::from(!is_left);
        let side = BVec3A::splat(is_left);
        left.min = left.min.min(Vec3A::select(side, c, inf));
        left.max = left.max.max(Vec3A::select(side, c, ninf));
        right.min = right.min.min(Vec3A::select(side, inf, c));
        right.max = right.max.max(Vec3A::select(side, ninf, c));
    }
    let extent = |bounds, centroids| Extent { bounds, centroids };
    (l, extent(s.left, left), extent(s.right, right))
}

/// A node on the work stack: its index, its references' range and extent, its depth, and
/// which of the two arrays of references holds them (partitions copy from one to the other).
struct Task {
    node: usize,
    start: usize,
    end: usize,
    extent: Extent,
    depth: usize,
    side: usize,
}

/// How a node is divided: its left child's references are `start..start + mid` of array
/// `side`, its right child's the rest.
struct Cut {
    mid: usize,
    left: Extent,
    right: Extent,
    side: usize,
}

/// The build's settings: leaves of up to `leaf_min` primitives are never split, those of more
/// than `max_leaf` always; a leaf's primitives are met `block` at a time.
#[derive(Clone, Copy)]
struct Sizes {
    leaf_min: usize,
    max_leaf: usize,
    block: u32,
}

/// Divides task `t`'s references by the binned SAH (`None`: it stays a leaf).
#[inline(always)]
fn divide<const AVX: bool>(
    refs: &mut [Vec<BuildRef>; 2],
    t: &Task,
    bins: &mut Bins,
    z: Sizes,
) -> Option<Cut> {
    let count = t.end - t.start;
    if count <= z.leaf_min || t.depth >= MAX_DEPTH {
        return None;
    }
    let [a, b] = refs;
    let (src, dst) = if t.side == 0 { (&*a, b) } else { (&*b, a) };
    let (src, dst) = (src.get(t.start..t.end)?, dst.get_mut(t.start..t.end)?);
    // 4 + count / 4 bins, in loops over 8, 16 or 32 (the bins past a node's own stay empty)
    let (used, c) = ((4 + count / 4).min(BINS), &t.extent.centroids);
    let best = match used {
        ..=8 => bins.split::<AVX, 8>(src, used, c, z.block),
        9..=16 => bins.split::<AVX, 16>(src, used, c, z.block),
        _ => bins.split::<AVX, BINS>(src, used, c, z.block),
    };
    let parent_area = t.extent.bounds.half_area().max(f32::MIN_POSITIVE);
    let leaf_cost = blocks_of(count as u32, z.block);
    let cut = match best {
        Some((s, m)) if split_cost() + s.cost / parent_area < leaf_cost || count > z.max_leaf => {
            let (mid, left, right) = partition(src, dst, &m, &s);
            let side = 1 - t.side;
            Cut {
                mid,
                left,
                right,
                side,
            }
        }
        // centroids coincide: split by position in the array to bound leaf size
        None if count > z.max_leaf => {
            let h = count / 2;
            let (left, right) = (Extent::of(&src[..h]), Extent::of(&src[h..]));
            let side = t.side;
            Cut {
                mid: h,
                left,
                right,
                side,
            }
        }
        _ => return None,
    };
    (cut.mid > 0 && cut.mid < count).then_some(cut)
}

/// Binary binned-SAH build; returns the nodes and the primitive order. Leaves of up to
/// `block` primitives cost one test (they are met `block` at a time). Compiled for AVX2 where
/// the CPU has it ([`super::has_avx2_fma`]): the same operations on the same values (no
/// fused products), so the same tree, in fewer instructions.
pub(super) fn build_binary(boxes: &[Aabb], leaf_min_chosen: usize) -> (Vec<Node>, Vec<u32>) {
    #[cfg(target_arch = "x86_64")]
    if super::has_avx2_fma() {
        // SAFETY: the CPU has AVX2, FMA and the bit instructions `build_avx2` is compiled for.
        return unsafe { build_avx2(boxes, leaf_min_chosen) };
    }
    build::<false>(boxes, leaf_min_chosen)
}

/// [`build`] compiled for AVX2 (VEX encodings: fewer register copies).
///
/// # Safety
/// The CPU must have AVX2, FMA, BMI1, BMI2, LZCNT and POPCNT.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
unsafe fn build_avx2(boxes: &[Aabb], leaf_min_chosen: usize) -> (Vec<Node>, Vec<u32>) {
    build::<true>(boxes, leaf_min_chosen)
}

/// [`build_binary`]'s work, inlined into each of its two compilations.
#[inline(always)]
fn build<const AVX: bool>(boxes: &[Aabb], leaf_min_chosen: usize) -> (Vec<Node>, Vec<u32>) {
    let n = boxes.len();
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    let block = super::block_size(leaf_min_chosen);
    let z = Sizes {
        leaf_min: leaf_min(leaf_min_chosen),
        max_leaf: max_leaf(block),
        block,
    };
    let first: Vec<BuildRef> = boxes
        .iter()
        .enumerate()
        .map(|(i, b)| BuildRef::new(b, i as u32))
        .collect();
    let extent = Extent::of(&first);
    let mut refs = [first, vec![BuildRef::ZERO; n]];
    let mut order = vec![0u32; n];
    let mut nodes = Vec::with_capacity(2 * n / z.leaf_min.max(1) + 1);
    nodes.push(Node::new(Aabb::EMPTY, 0, 0));
    let mut bins = Bins::new();
    let (node, start, end, depth, side) = (0, 0, n, 0, 0);
    let mut work = vec![Task {
        node,
        start,
        end,
        extent,
        depth,
        side,
    }];
    while let Some(t) = work.pop() {
        let bounds = t.extent.bounds;
        let Some(cut) = divide::<AVX>(&mut refs, &t, &mut bins, z) else {
            nodes[t.node] = Node::new(bounds, t.start as u32, (t.end - t.start) as u32);
            let (to, from) = (&mut order[t.start..t.end], &refs[t.side][t.start..t.end]);
            to.iter_mut().zip(from).for_each(|(o, r)| *o = r.index());
            continue;
        };
        let l = nodes.len();
        nodes.push(Node::new(Aabb::EMPTY, 0, 0));
        nodes.push(Node::new(Aabb::EMPTY, 0, 0));
        nodes[t.node] = Node::new(bounds, l as u32, 0);
        let (mid, depth, side) = (t.start + cut.mid, t.depth + 1, cut.side);
        work.push(Task {
            node: l + 1,
            start: mid,
            end: t.end,
            extent: cut.right,
            depth,
            side,
        });
        work.push(Task {
            node: l,
            start: t.start,
            end: mid,
            extent: cut.left,
            depth,
            side,
        });
    }
    (nodes, order)
}
