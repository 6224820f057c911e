//! Bounding volume hierarchy: binned SAH build, flattened 32-byte nodes, ordered traversal.
//!
//! Nodes are stored in one array; the two children of an interior node are adjacent
//! (`first`, `first + 1`), so a node needs only its box, one index and a count. Leaves reference
//! a contiguous range of the primitive array, which the scene reorders to BVH order after the
//! build. Memory is O(primitives): at most `2n - 1` nodes.

use crate::geometry::Aabb;
use crate::ray::Ray;
use glam::{Vec3A, Vec4};

/// Number of SAH bins per axis.
const BINS: usize = 16;
/// Leaves never hold more than this unless the primitives cannot be separated.
const MAX_LEAF: usize = 8;
/// Build depth cap; traversal stacks are sized from it.
pub(crate) const MAX_DEPTH: usize = 60;
/// Cost of one traversal step relative to one primitive test.
const TRAVERSAL_COST: f32 = 1.0;

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
    /// Entry distance of the ray into the box, if it enters before `tmax`.
    #[inline(always)]
    pub fn hit(&self, ray: &Ray, tmax: f32) -> f32 {
        let t0 = (Vec3A::from_vec4(self.a) - ray.origin) * ray.inv_dir;
        let t1 = (Vec3A::from_vec4(self.b) - ray.origin) * ray.inv_dir;
        let tnear = t0.min(t1).max_element().max(0.0);
        let tfar = t0.max(t1).min_element().min(tmax);
        if tnear <= tfar {
            tnear
        } else {
            f32::INFINITY
        }
    }
}

/// The hierarchy.
#[derive(Clone, Debug, Default)]
pub(crate) struct Bvh {
    pub nodes: Vec<Node>,
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

impl Bvh {
    /// Builds over primitive boxes; returns the hierarchy and the primitive order (new position ->
    /// old index).
    pub fn build(boxes: &[Aabb]) -> (Bvh, Vec<u32>) {
        let n = boxes.len();
        let mut order: Vec<u32> = (0..n as u32).collect();
        if n == 0 {
            return (Bvh { nodes: Vec::new() }, order);
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
            if count <= 2 || depth >= MAX_DEPTH {
                make_leaf(&mut nodes);
                continue;
            }
            let ext = cb.max - cb.min;
            // best split over all three axes
            let mut best = (f32::INFINITY, 0usize, 0usize); // cost, axis, bin
            for axis in 0..3 {
                let e = ext[axis];
                if !(e > 0.0) {
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
            let split_cost = TRAVERSAL_COST + best.0 / parent_area;
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
        (Bvh { nodes }, order)
    }

    /// Visits leaves front to back; `visit(first, count, tmax) -> new tmax`. Stops when a visit
    /// returns a negative value (used for any-hit queries).
    #[inline(always)]
    pub fn traverse(
        &self,
        ray: &Ray,
        mut tmax: f32,
        mut visit: impl FnMut(usize, usize, f32) -> f32,
    ) -> f32 {
        let Some(root) = self.nodes.first() else {
            return tmax;
        };
        if root.hit(ray, tmax) == f32::INFINITY {
            return tmax;
        }
        let mut stack = [(0u32, 0.0f32); MAX_DEPTH + 4];
        let mut sp = 0usize;
        let mut node = root;
        loop {
            let count = node.count();
            if count > 0 {
                tmax = visit(node.first() as usize, count as usize, tmax);
                if tmax < 0.0 {
                    return tmax;
                }
            } else {
                let first = node.first() as usize;
                let (Some(c0), Some(c1)) = (self.nodes.get(first), self.nodes.get(first + 1))
                else {
                    return tmax;
                };
                let d0 = c0.hit(ray, tmax);
                let d1 = c1.hit(ray, tmax);
                let (near, dn, df, fi) = if d0 <= d1 {
                    (c0, d0, d1, first + 1)
                } else {
                    (c1, d1, d0, first)
                };
                if dn != f32::INFINITY {
                    if df != f32::INFINITY && sp < stack.len() {
                        stack[sp] = (fi as u32, df);
                        sp += 1;
                    }
                    node = near;
                    continue;
                }
            }
            // pop the next node that can still hold a closer hit
            loop {
                if sp == 0 {
                    return tmax;
                }
                sp -= 1;
                let (i, d) = stack[sp];
                if d <= tmax {
                    match self.nodes.get(i as usize) {
                        Some(n) => {
                            node = n;
                            break;
                        }
                        None => return tmax,
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn build_covers_all_primitives_once() {
        let boxes: Vec<Aabb> = (0..1000)
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
            .collect();
        let (bvh, order) = Bvh::build(&boxes);
        assert!(bvh.nodes.len() < 2 * boxes.len());
        let mut seen = vec![0u32; boxes.len()];
        for n in &bvh.nodes {
            for k in n.first()..n.first() + n.count() {
                seen[order[k as usize] as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert_eq!(std::mem::size_of::<Node>(), 32);
        // identical boxes still give bounded leaves
        let same = vec![boxes[0]; 100];
        let (bvh, _) = Bvh::build(&same);
        assert!(bvh.nodes.iter().all(|n| n.count() as usize <= MAX_LEAF));
    }
}
