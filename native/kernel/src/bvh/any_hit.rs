//! The any-hit traversal, made for occlusion: it stops at the first occluder, so it keeps no
//! order and no entry distance, and a node's entered children go onto the stack all at once.
//!
//! The stack is two arrays, the children's indices and their counts (as in [`Node8`]), so that
//! a node's entered children are pushed as two vectors: with AVX2, each of the node's two rows
//! is permuted so that the entered slots come first, in increasing order (one `vpermd` by a
//! table row chosen by the mask), and stored whole at the top of the stack; the top then moves
//! up by the number entered. No branch depends on how many children were entered, and the
//! next child is always the top of the stack (the highest slot entered, leaf or node).

use super::{
    node_test, prefetch_children, prefetch_line, Bvh, Node8, RayPre, LEAF_BLOCKS, STACK_CAP, WIDTH,
};
use crate::ray::Ray;

/// Entries of each array of an [`AnyStack`]: a push writes a whole row of [`WIDTH`] at an
/// index below [`STACK_CAP`].
const CAP: usize = STACK_CAP + WIDTH;

/// The any-hit traversal's stack: children's indices, then their counts (as in [`Node8`]),
/// [`CAP`] each, in one allocation (so that the loop keeps one base address for both).
#[derive(Clone, Debug, Default)]
pub(crate) struct AnyStack {
    entries: Vec<u32>,
}

impl AnyStack {
    /// Both arrays at their full size, as fixed arrays (so that indices taken modulo
    /// [`STACK_CAP`] need no bounds check).
    #[inline(always)]
    fn fixed(&mut self) -> Option<(&mut [u32; CAP], &mut [u32; CAP])> {
        if self.entries.len() < 2 * CAP {
            self.entries.resize(2 * CAP, 0);
        }
        let (child, count) = self.entries.get_mut(..2 * CAP)?.split_at_mut(CAP);
        Some((child.try_into().ok()?, count.try_into().ok()?))
    }
}

/// Per mask of entered children: their slots in increasing order, then the others (the
/// permutation that packs a node's entered children at the front of a row).
static PACK: [[u32; WIDTH]; 256] = pack_table();

const fn pack_table() -> [[u32; WIDTH]; 256] {
    let mut t = [[0u32; WIDTH]; 256];
    let mut mask = 0;
    while mask < 256 {
        let mut k = 0;
        let mut i = 0;
        while i < WIDTH {
            if mask >> i & 1 == 1 {
                t[mask][k] = i as u32;
                k += 1;
            }
            i += 1;
        }
        i = 0;
        while i < WIDTH {
            if mask >> i & 1 == 0 {
                t[mask][k] = i as u32;
                k += 1;
            }
            i += 1;
        }
        mask += 1;
    }
    t
}

/// Pushes the children of `node` in `mask` at `sp`, in increasing slot order; returns the new
/// top. Entries above the new top may be overwritten. `AVX` only where the CPU has AVX2, as
/// for [`node_test`].
#[inline(always)]
fn push<const AVX: bool>(
    node: &Node8,
    mask: u32,
    child: &mut [u32; CAP],
    count: &mut [u32; CAP],
    sp: usize,
) -> usize {
    let at = sp & (STACK_CAP - 1);
    #[cfg(target_arch = "x86_64")]
    if AVX {
        use std::arch::x86_64::*;
        let perm = &PACK[(mask & 0xff) as usize];
        let (dst_c, dst_n) = (&mut child[at..at + WIDTH], &mut count[at..at + WIDTH]);
        // SAFETY: AVX is only set by traverse_avx, which runs where the CPU has AVX2 and FMA,
        // and by the callers of traverse_compiled, whose contract is the same. Every load
        // reads the 8 u32 of an array of 8, every store writes the 8 u32 of a slice of 8.
        unsafe {
            let p = _mm256_loadu_si256(perm.as_ptr().cast());
            let c = _mm256_loadu_si256(node.child.as_ptr().cast());
            let n = _mm256_loadu_si256(node.count.as_ptr().cast());
            _mm256_storeu_si256(dst_c.as_mut_ptr().cast(), _mm256_permutevar8x32_epi32(c, p));
            _mm256_storeu_si256(dst_n.as_mut_ptr().cast(), _mm256_permutevar8x32_epi32(n, p));
        }
        return sp + mask.count_ones() as usize;
    }
    let mut m = mask & 0xff;
    let mut k = at;
    while m != 0 {
        let i = m.trailing_zeros() as usize & 7;
        m &= m - 1;
        child[k] = node.child[i];
        count[k] = node.count[i];
        k += 1;
    }
    sp + mask.count_ones() as usize
}

impl Bvh {
    /// Any-hit traversal, which stops at the first visit that returns a negative value. Leaves
    /// and inner nodes go through one [`AnyStack`], in no order of distance: per node, every
    /// child entered is pushed (in slot order, at once), and the top is taken next, whether
    /// leaf or node. No entry distance is kept: an any-hit visit leaves the bound as it is
    /// until it stops the traversal, so a stacked child is never skipped when popped (a visit
    /// that lowers the bound still gets the lower bound, and so do the node tests after it).
    /// The stack is addressed modulo [`STACK_CAP`], which the build's depth cap keeps it
    /// below (at most `WIDTH - 1` entries a level are left when the top is taken).
    ///
    /// Hierarchies that prefetch ([`Bvh::prefetch`]) and those that do not get a loop each, so
    /// that neither tests the flag per node. `AVX` only where the CPU has AVX2 and FMA.
    #[inline(always)]
    pub(super) fn any_loop<const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        stack: &mut AnyStack,
        work: &mut u64,
        visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        if self.prefetch {
            self.any_walk::<AVX, true>(ray, tmax, stack, work, visit, prefetch)
        } else {
            self.any_walk::<AVX, false>(ray, tmax, stack, work, visit, prefetch)
        }
    }

    /// [`Bvh::any_loop`] for a hierarchy that prefetches (`PREFETCH`) or does not.
    #[inline(always)]
    fn any_walk<const AVX: bool, const PREFETCH: bool>(
        &self,
        ray: &Ray,
        mut tmax: f32,
        stack: &mut AnyStack,
        work: &mut u64,
        mut visit: impl FnMut(usize, usize, f32) -> f32,
        prefetch: impl Fn(usize, usize),
    ) -> f32 {
        let Some((child, count)) = stack.fixed() else {
            return tmax;
        };
        let nodes = &self.nodes[..];
        let pre = RayPre::new(ray);
        // the child handled next: (index, count as in Node8); the root first
        let mut cur = (0u32, 0u32);
        let mut sp = 0usize;
        // the work is counted here and added once (not stored to memory per node)
        let mut w = 0u64;
        let t = 'run: loop {
            if cur.1 == 0 {
                // an inner node
                let Some(node) = nodes.get(cur.0 as usize) else {
                    break 'run tmax;
                };
                w += 1;
                if PREFETCH {
                    prefetch_line(node.child.as_ptr());
                }
                let (_, mask) = node_test::<AVX>(node, &pre, tmax);
                if PREFETCH {
                    // the memory of the children stacked below the top, asked for as they
                    // are stacked (the top is read at once anyway)
                    let top = 31 - (mask | 1).leading_zeros();
                    prefetch_children(nodes, node, mask & !(1 << top), &prefetch);
                }
                if mask != 0 {
                    // all entered are pushed, the top left out again: it is handled next,
                    // read from the node rather than from the stack (a load from a vector
                    // just stored would wait on the store)
                    sp = push::<AVX>(node, mask, child, count, sp) - 1;
                    let top = 31 - mask.leading_zeros() as usize;
                    cur = (node.child[top & 7], node.count[top & 7]);
                    continue;
                }
            } else {
                w += (cur.1 & !LEAF_BLOCKS) as u64;
                tmax = visit(cur.0 as usize, cur.1 as usize, tmax);
                if tmax < 0.0 {
                    break 'run tmax;
                }
            }
            if sp == 0 {
                break 'run tmax;
            }
            sp -= 1;
            let at = sp & (STACK_CAP - 1);
            cur = (child[at], count[at]);
        };
        *work += w;
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every mask of entered children pushes those children, in slot order, with their counts,
    /// and the AVX push stacks what the portable one does.
    #[test]
    fn a_push_stacks_the_children_entered_in_slot_order() {
        let mut node = Node8::empty();
        for i in 0..WIDTH {
            node.child[i] = 100 + i as u32;
            node.count[i] = [0, 3, LEAF_BLOCKS | 5, 1][i % 4];
        }
        let mut stack = AnyStack::default();
        let mut twin = AnyStack::default();
        for mask in 0..256u32 {
            for sp in [0usize, 7, STACK_CAP - 1] {
                let (child, count) = stack.fixed().unwrap();
                let top = push::<false>(&node, mask, child, count, sp);
                assert_eq!(top, sp + mask.count_ones() as usize);
                let slots: Vec<usize> = (0..WIDTH).filter(|i| mask >> i & 1 == 1).collect();
                for (k, &i) in slots.iter().enumerate() {
                    let at = sp + k;
                    assert_eq!((child[at], count[at]), (node.child[i], node.count[i]));
                }
                if crate::bvh::has_avx2_fma() {
                    let want: Vec<(u32, u32)> = (sp..top).map(|k| (child[k], count[k])).collect();
                    let (c2, n2) = twin.fixed().unwrap();
                    assert_eq!(push::<true>(&node, mask, c2, n2, sp), top);
                    let got: Vec<(u32, u32)> = (sp..top).map(|k| (c2[k], n2[k])).collect();
                    assert_eq!(got, want, "mask {mask:#x}");
                }
            }
        }
    }
}
