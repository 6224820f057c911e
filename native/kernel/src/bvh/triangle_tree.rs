//! A hierarchy over a bare list of triangles, built as a scene builds its own for an
//! all-triangle mesh (boxes, the binned-SAH binary build, the collapse into 8-wide nodes, the
//! leaves' blocks of four): what a benchmark times next to another library's build from the
//! same triangles, and whose tree quality it reports ([`TriangleTree::sah`]).

use super::{sah, Bvh, LEAF_MIN_TRIANGLES};
use crate::geometry::Aabb;
use crate::tri4::TriBlocks;
use crate::{memory, Error};
use glam::Vec3A;

/// A built hierarchy over triangles with its leaf blocks.
#[derive(Clone, Debug)]
pub struct TriangleTree {
    bvh: Bvh,
    blocks: TriBlocks,
}

impl TriangleTree {
    /// Builds the hierarchy over `tris` (each given by its three corners), as a scene's
    /// loader does for a mesh of triangles only. Errors when the arrays would not fit in the
    /// memory left ([`crate::memory`]).
    pub fn build(tris: &[[Vec3A; 3]]) -> Result<TriangleTree, Error> {
        let what = || format!("a list of {} triangles", tris.len());
        let mut boxes: Vec<Aabb> = memory::try_with_capacity(tris.len(), what)?;
        boxes.extend(
            tris.iter()
                .map(|t| Aabb::EMPTY.grow(t[0]).grow(t[1]).grow(t[2])),
        );
        let (mut bvh, order) = Bvh::try_build_with(&boxes, LEAF_MIN_TRIANGLES, &|| {
            format!("the BVH of {} triangles", tris.len())
        })?;
        drop(boxes);
        let blocks = TriBlocks::build_from(&mut bvh, |k| {
            let [v0, v1, v2] = *tris.get(*order.get(k)? as usize)?;
            Some((v0, v1 - v0, v2 - v0))
        });
        Ok(TriangleTree { bvh, blocks })
    }

    /// The tree's SAH figure as Embree 3's BVH statistics define it (see the `sah` module:
    /// node traversal 1, a block of four triangles 1, half areas relative to the root's).
    pub fn sah(&self) -> f64 {
        sah::embree_sah(&self.bvh.nodes)
    }

    /// Its 8-wide nodes.
    pub fn node_count(&self) -> usize {
        self.bvh.nodes.len()
    }

    /// Its blocks of four triangles.
    pub fn block_count(&self) -> usize {
        self.blocks.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of small triangles: blocks of up to four triangles, and an SAH figure above the
    /// root's own 1 that does not depend on the triangles' order.
    #[test]
    fn triangle_tree_blocks_its_triangles_and_reports_its_sah() {
        let mut tris = Vec::new();
        for i in 0..40 {
            for j in 0..30 {
                let p = Vec3A::new(i as f32, j as f32, ((i * j) % 7) as f32 * 0.1);
                tris.push([p, p + Vec3A::X, p + Vec3A::Y]);
            }
        }
        let tree = TriangleTree::build(&tris).unwrap();
        assert!(tree.block_count() >= tris.len() / 4);
        assert!(
            tree.block_count() < tris.len() / 2,
            "{}",
            tree.block_count()
        );
        assert!(tree.node_count() > 1);
        let sah = tree.sah();
        assert!(sah > 1.0 && sah.is_finite(), "{sah}");
        // the same figure for the same triangles, whatever their order
        let mut rev = tris.clone();
        rev.reverse();
        let again = TriangleTree::build(&rev).unwrap().sah();
        assert!((again - sah).abs() < 0.05 * sah, "{again} {sah}");
        assert_eq!(TriangleTree::build(&[]).unwrap().sah(), 0.0);
    }
}
