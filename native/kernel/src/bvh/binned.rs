//! The binary binned-SAH build: primitive references of 32 bytes (the box, the primitive's
//! index in the minimum's spare lane) partitioned in place, node by node, from a work stack.
//! Each node's box and centroid box come from its parent's partition, which gathers them as it
//! moves each reference, so a node reads its references twice: once to bin them (the three
//! axes in one pass, bin numbers computed for the three at once), once to partition them.
//! Nodes get fewer bins the fewer references they hold (4 + count / 4, at most [`BINS`]), so
//! that the many small nodes near the leaves do not pay for 32 bins they cannot fill.

use super::{blocks_of, leaf_min, max_leaf, split_cost, Node, MAX_DEPTH};
use crate::geometry::Aabb;
use glam::{Vec3A, Vec4};

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
    bins: usize,
    lo: Vec3A,
    scale: Vec3A,
    last: Vec3A,
}

impl Mapping {
    fn new(count: usize, centroids: &Aabb) -> Mapping {
        let bins = (4 + count / 4).min(BINS);
        let ext = centroids.max - centroids.min;
        let scale = Vec3A::select(
            ext.cmpgt(Vec3A::ZERO),
            Vec3A::splat(bins as f32 * 0.999_99) / ext,
            Vec3A::ZERO,
        );
        Mapping {
            bins,
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
    boxes: [[[Aabb; BINS]; 3]; 2],
    counts: [[[u32; BINS]; 3]; 2],
}

/// The best split found: SAH cost (the children's area-weighted block counts), axis, and the
/// last bin of the left side.
#[derive(Clone, Copy)]
struct Split {
    cost: f32,
    axis: usize,
    bin: i32,
}

impl Bins {
    fn new() -> Box<Bins> {
        Box::new(Bins {
            boxes: [[[Aabb::EMPTY; BINS]; 3]; 2],
            counts: [[[0; BINS]; 3]; 2],
        })
    }

    /// Adds `r` to set `set`'s bins.
    #[inline(always)]
    fn add(&mut self, set: usize, r: &BuildRef, m: &Mapping) {
        let k = m.bin(r);
        let b = r.bounds();
        let (boxes, counts) = (&mut self.boxes[set & 1], &mut self.counts[set & 1]);
        for a in 0..3 {
            let k = k[a] as usize & (BINS - 1);
            counts[a][k] += 1;
            boxes[a][k] = boxes[a][k].union(b);
        }
    }

    /// Bins `refs` on the three axes by `m`.
    fn fill(&mut self, refs: &[BuildRef], m: &Mapping) {
        for set in 0..2 {
            for a in 0..3 {
                self.boxes[set][a][..m.bins].fill(Aabb::EMPTY);
                self.counts[set][a][..m.bins].fill(0);
            }
        }
        let pairs = refs.chunks_exact(2);
        if let [last] = pairs.remainder() {
            self.add(1, last, m);
        }
        for p in pairs {
            self.add(0, &p[0], m);
            self.add(1, &p[1], m);
        }
        let [first, second] = &mut self.boxes;
        let [c0, c1] = &mut self.counts;
        for a in 0..3 {
            for k in 0..m.bins {
                first[a][k] = first[a][k].union(second[a][k]);
                c0[a][k] += c1[a][k];
            }
        }
    }

    /// The least-cost split of the filled bins over the three axes (`None` when no split
    /// separates anything).
    fn best(&self, bins: usize, block: u32) -> Option<Split> {
        let mut best = Split {
            cost: f32::INFINITY,
            axis: 0,
            bin: -1,
        };
        for a in 0..3 {
            let (boxes, counts) = (&self.boxes[0][a], &self.counts[0][a]);
            // left[k]: the cost of bins ..=k as one side (infinite when empty)
            let mut left = [0.0f32; BINS];
            let (mut acc, mut c) = (Aabb::EMPTY, 0);
            for k in 0..bins.min(BINS) - 1 {
                acc = acc.union(boxes[k]);
                c += counts[k];
                left[k] = side_cost(&acc, c, block);
            }
            let (mut acc, mut c) = (Aabb::EMPTY, 0);
            for k in (1..bins.min(BINS)).rev() {
                acc = acc.union(boxes[k]);
                c += counts[k];
                let cost = left[k - 1] + side_cost(&acc, c, block);
                if cost < best.cost {
                    best = Split {
                        cost,
                        axis: a,
                        bin: k as i32 - 1,
                    };
                }
            }
        }
        (best.bin >= 0).then_some(best)
    }
}

/// The SAH cost of one side of a split: its area times its blocks, infinite when it holds
/// nothing (a split that separates nothing is no split).
#[inline(always)]
fn side_cost(b: &Aabb, count: u32, block: u32) -> f32 {
    if count == 0 {
        f32::INFINITY
    } else {
        b.half_area() * blocks_of(count, block)
    }
}

/// Moves the references of `refs` whose bin on `s.axis` is at most `s.bin` to the front;
/// returns their number and both sides' extents. The bin test is [`Mapping::bin`]'s without
/// the integers: a truncation is at most `s.bin` exactly when its argument is below
/// `s.bin + 1` (the cap at the last bin does not matter, as `s.bin` is below it).
fn partition(refs: &mut [BuildRef], m: &Mapping, s: &Split) -> (usize, Extent, Extent) {
    let (axis, limit) = (s.axis.min(2), Vec3A::splat((s.bin + 1) as f32));
    let left_of =
        |r: &BuildRef| ((r.centroid() - m.lo) * m.scale).cmplt(limit).bitmask() >> axis & 1 != 0;
    let (mut left, mut right) = (Extent::EMPTY, Extent::EMPTY);
    let (mut l, mut r) = (0, refs.len());
    while l < r {
        if left_of(&refs[l]) {
            left.add(&refs[l]);
            l += 1;
        } else {
            r -= 1;
            refs.swap(l, r);
            right.add(&refs[r]);
        }
    }
    (l, left, right)
}

/// A node on the work stack: its index, its references' range and extent, its depth.
struct Task {
    node: usize,
    start: usize,
    end: usize,
    extent: Extent,
    depth: usize,
}

/// Binary binned-SAH build; returns the nodes and the primitive order. Leaves of up to
/// `block` primitives cost one test (they are met `block` at a time).
pub(super) fn build_binary(boxes: &[Aabb], leaf_min_chosen: usize) -> (Vec<Node>, Vec<u32>) {
    let n = boxes.len();
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    let leaf_min = leaf_min(leaf_min_chosen);
    let block = super::block_size(leaf_min_chosen);
    let max_leaf = max_leaf(block);
    let mut refs: Vec<BuildRef> = boxes
        .iter()
        .enumerate()
        .map(|(i, b)| BuildRef::new(b, i as u32))
        .collect();
    let mut nodes = Vec::with_capacity(2 * n / leaf_min.max(1) + 1);
    nodes.push(Node::new(Aabb::EMPTY, 0, 0));
    let mut bins = Bins::new();
    let mut work = vec![Task {
        node: 0,
        start: 0,
        end: n,
        extent: Extent::of(&refs),
        depth: 0,
    }];
    while let Some(t) = work.pop() {
        let rs = &mut refs[t.start..t.end];
        let count = rs.len();
        let bounds = t.extent.bounds;
        let leaf = Node::new(bounds, t.start as u32, count as u32);
        if count <= leaf_min || t.depth >= MAX_DEPTH {
            nodes[t.node] = leaf;
            continue;
        }
        let m = Mapping::new(count, &t.extent.centroids);
        bins.fill(rs, &m);
        let best = bins.best(m.bins, block);
        let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
        let leaf_cost = blocks_of(count as u32, block);
        let (mid, left, right) = match best {
            Some(s) if split_cost() + s.cost / parent_area < leaf_cost || count > max_leaf => {
                partition(rs, &m, &s)
            }
            // centroids coincide: split by position in the array to bound leaf size
            None if count > max_leaf => {
                let h = count / 2;
                (h, Extent::of(&rs[..h]), Extent::of(&rs[h..]))
            }
            _ => (0, Extent::EMPTY, Extent::EMPTY),
        };
        if mid == 0 || mid == count {
            nodes[t.node] = leaf;
            continue;
        }
        let l = nodes.len();
        nodes.push(Node::new(Aabb::EMPTY, 0, 0));
        nodes.push(Node::new(Aabb::EMPTY, 0, 0));
        nodes[t.node] = Node::new(bounds, l as u32, 0);
        let (start, end, depth) = (t.start, t.end, t.depth + 1);
        let mid = start + mid;
        work.push(Task {
            node: l + 1,
            start: mid,
            end,
            extent: right,
            depth,
        });
        work.push(Task {
            node: l,
            start,
            end: mid,
            extent: left,
            depth,
        });
    }
    let order = refs.iter().map(BuildRef::index).collect();
    (nodes, order)
}
