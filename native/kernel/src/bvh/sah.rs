//! The SAH figure of a built hierarchy, defined as Embree 3's BVH statistics define theirs
//! (`BVHNStatistics`, printed with the device configuration `verbose=2` or on the
//! `BENCHMARK_BUILD` line of `benchmark=1`), so that the two trees can be compared by one
//! formula: every inner node costs its box's half area times 1 (one node traversal), every
//! leaf its box's half area times its blocks of four triangles (one intersection cost per
//! block), and the sum is divided by the half area of the root's box, which counts itself
//! as a node (a tree that is one node over leaves costs at least 1).

use super::{block_leaf_len, Node8, EMPTY, WIDTH};
use crate::geometry::Aabb;
use glam::Vec3A;

/// Cost of traversing one node, relative to one leaf block's intersection (Embree's
/// statistics count both as 1).
const NODE_COST: f64 = 1.0;
/// Cost of intersecting one leaf block of up to four triangles.
const BLOCK_COST: f64 = 1.0;
/// Triangles in a leaf block.
const BLOCK: usize = 4;

/// Child `i`'s box in `n`.
fn child_box(n: &Node8, i: usize) -> Aabb {
    Aabb {
        min: Vec3A::from([0, 1, 2].map(|a| n.bounds[a][i])),
        max: Vec3A::from([0, 1, 2].map(|a| n.bounds[3 + a][i])),
    }
}

/// The SAH of the 8-wide hierarchy `nodes` (root first) as Embree's statistics count it:
/// `(A(root) + sum over inner children of A + sum over leaves of A x blocks) / A(root)`,
/// `A` the half area, in f64. 0 for an empty hierarchy or a root without area.
pub(crate) fn embree_sah(nodes: &[Node8]) -> f64 {
    let Some(root_node) = nodes.first() else {
        return 0.0;
    };
    let mut sum = 0.0f64;
    for n in nodes {
        for i in (0..WIDTH).filter(|&i| n.count[i] != EMPTY) {
            let cost = match n.count[i] {
                0 => NODE_COST,
                c => {
                    let tris = block_leaf_len(c as usize).unwrap_or(c as usize);
                    BLOCK_COST * tris.div_ceil(BLOCK) as f64
                }
            };
            sum += f64::from(child_box(n, i).half_area()) * cost;
        }
    }
    let root = (0..WIDTH)
        .filter(|&i| root_node.count[i] != EMPTY)
        .fold(Aabb::EMPTY, |b, i| b.union(child_box(root_node, i)));
    let root = f64::from(root.half_area());
    if root > 0.0 {
        (NODE_COST * root + sum) / root
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::Bvh;

    /// Two unit cubes side by side, each one leaf: the root (area 2 x 1 + 1 x 1 + 1 x 2 = 5)
    /// counts 1, each leaf 3 / 5 times its blocks.
    #[test]
    fn sah_counts_the_root_once_and_each_leaf_by_its_blocks() {
        let cube = |x: f32, n: usize| {
            vec![
                Aabb {
                    min: Vec3A::new(x, 0.0, 0.0),
                    max: Vec3A::new(x + 1.0, 1.0, 1.0),
                };
                n
            ]
        };
        // four boxes a cube: one block a leaf
        let boxes = [cube(0.0, 4), cube(1.0, 4)].concat();
        let (bvh, _) = Bvh::build_with(&boxes, super::super::LEAF_MIN_TRIANGLES);
        let sah = embree_sah(&bvh.nodes);
        assert!((sah - (1.0 + 2.0 * 3.0 / 5.0)).abs() < 1e-6, "{sah}");
        // five a cube: two blocks a leaf
        let boxes = [cube(0.0, 5), cube(1.0, 5)].concat();
        let (bvh, _) = Bvh::build_with(&boxes, super::super::LEAF_MIN_TRIANGLES);
        let sah = embree_sah(&bvh.nodes);
        assert!((sah - (1.0 + 4.0 * 3.0 / 5.0)).abs() < 1e-6, "{sah}");
        assert_eq!(embree_sah(&[]), 0.0);
    }
}
