//! A scene's closest-hit and any-hit queries, one ray at a time and in packets.

use super::{Hit, Scene};
use crate::bvh::{has_avx2_fma, Scratch};
use crate::geometry::{hit_triangle, Shape};
use crate::ray::Ray;
use crate::tri4::RayLanes;

impl Scene {
    /// Closest hit along `ray` with `0 < t < tmax`. Convenience form; loops should keep one
    /// [`Scratch`] per thread and call [`Scene::intersect_with`].
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<Hit> {
        self.intersect_with(ray, tmax, &mut Scratch::new())
    }

    /// [`Scene::intersect`] reusing a traversal stack (for hot loops: one `Scratch` per thread).
    ///
    /// Among hits at the same distance the lowest primitive index wins (whatever the order the
    /// leaves are visited in), so [`Scene::intersect_packet`] finds the same hits.
    ///
    /// Where the CPU has AVX2 and FMA, the whole query (the BVH's traversal and its leaf tests
    /// included) is one function compiled for them, so a ray pays one call.
    #[inline]
    pub fn intersect_with(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe { self.intersect_avx(ray, tmax, scratch) };
        }
        self.intersect_portable(ray, tmax, scratch)
    }

    /// [`Scene::intersect_in`] with the portable node test, for CPUs without AVX2 and FMA.
    /// Never inlined: inlined into the callers of [`Scene::intersect_with`] (the integrator's
    /// recursion), this traversal, never run where AVX2 is, made their code larger and slower.
    #[inline(never)]
    fn intersect_portable(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Option<Hit> {
        // SAFETY: without AVX, the portable node test.
        unsafe { self.intersect_in::<false>(ray, tmax, scratch) }
    }

    /// [`Scene::intersect_in`] compiled with AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA ([`has_avx2_fma`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn intersect_avx(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Option<Hit> {
        // SAFETY: the caller's contract.
        unsafe { self.intersect_in::<true>(ray, tmax, scratch) }
    }

    /// [`Scene::intersect_with`], with the AVX node test when `AVX` is set (only by
    /// [`Scene::intersect_avx`]).
    ///
    /// # Safety
    /// With `AVX`, the CPU must have AVX2 and FMA.
    #[inline(always)]
    unsafe fn intersect_in<const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<Hit> {
        let mut prim = u32::MAX;
        let mut mailbox = Mailbox::default();
        let lanes = RayLanes::new(ray);
        // SAFETY: this function's contract.
        let best = unsafe {
            self.bvh.traverse_compiled::<true, AVX>(
                ray,
                tmax,
                &mut scratch.ray,
                &mut scratch.work,
                #[inline(always)]
                |first, count, tm| {
                    self.leaf_closest(first, count, ray, &lanes, &mut mailbox, tm, &mut prim)
                },
                |first, count| self.tri_blocks.prefetch(first, count),
            )
        };
        self.finish_closest(ray, best, prim, scratch)
    }

    /// The closest-hit test of one BVH leaf `(first, count)` for `ray`, whose best hit so far is
    /// `prim` at `tm` (`prim == u32::MAX`: none, `tm` the bound). Returns the new bound and
    /// updates `prim`: a hit replaces it when nearer, or at the same distance with a lower index,
    /// so the result over several leaves does not depend on their order.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn leaf_closest(
        &self,
        first: usize,
        count: usize,
        ray: &Ray,
        lanes: &RayLanes,
        mailbox: &mut Mailbox,
        mut tm: f32,
        prim: &mut u32,
    ) -> f32 {
        // a hit at exactly `tm` is taken only if it has a lower index than the hit there
        let limit = |tm: f32, prim: u32| if prim == u32::MAX { tm } else { tm.next_up() };
        if let Some(leaf) = self.tri_blocks.leaf(first, count) {
            for b in leaf {
                if let Some((i, t)) = b.closest(lanes, 0.0, limit(tm, *prim)) {
                    let p = b.prim(i);
                    if t < tm || p < *prim {
                        tm = t;
                        *prim = p;
                    }
                }
            }
            return tm;
        }
        if let Some(range) = self.geom.shapes.get(first..first + count) {
            for (k, s) in range.iter().enumerate() {
                if mailbox.seen(s) {
                    continue;
                }
                if let Some(t) = self.geom.hit(s, ray, 0.0, limit(tm, *prim)) {
                    let p = (first + k) as u32;
                    if t < tm || p < *prim {
                        tm = t;
                        *prim = p;
                    }
                }
            }
        }
        tm
    }

    /// The rest of a closest-hit query after the scene's own BVH gave `prim` at `best`
    /// (`u32::MAX`: nothing before `best`): the mesh instances, then the planes. Without
    /// either (most scenes) the hit is the BVH's, inlined into every query, without a call
    /// (it took 1.5% of a glass scene's instructions).
    #[inline(always)]
    pub(crate) fn finish_closest(
        &self,
        ray: &Ray,
        best: f32,
        prim: u32,
        scratch: &mut Scratch,
    ) -> Option<Hit> {
        if self.instances.is_empty() && self.planes.is_empty() {
            return (prim != u32::MAX).then_some(Hit {
                t: best,
                prim,
                instance: Hit::NO_INSTANCE,
            });
        }
        self.finish_closest_beyond(ray, best, prim, scratch)
    }

    /// [`Scene::finish_closest`] where the scene has mesh instances or planes.
    #[inline]
    fn finish_closest_beyond(
        &self,
        ray: &Ray,
        mut best: f32,
        mut prim: u32,
        scratch: &mut Scratch,
    ) -> Option<Hit> {
        let shapes = &self.geom.shapes;
        let mut instance = Hit::NO_INSTANCE;
        if !self.instances.is_empty() {
            if let Some((t, i, p)) = self.intersect_instances(ray, best, scratch) {
                best = t;
                instance = i;
                prim = p;
            }
        }
        scratch.work += self.planes.len() as u64;
        for (k, pl) in self.planes.iter().enumerate() {
            let dn = pl.normal.dot(ray.dir);
            if dn != 0.0 {
                let t = (pl.d - pl.normal.dot(ray.origin)) / dn;
                if t > 0.0 && t < best {
                    best = t;
                    prim = (shapes.len() + k) as u32;
                    instance = Hit::NO_INSTANCE;
                }
            }
        }
        if prim == u32::MAX {
            None
        } else {
            Some(Hit {
                t: best,
                prim,
                instance,
            })
        }
    }

    /// Closest hit on a mesh instance before `tmax`: (t, instance, triangle). Without
    /// `ORDERED`, the first hit found (any-hit, for shadow rays; then t is negative).
    #[inline]
    pub(super) fn instances_hit<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(f32, u32, u32)> {
        let instances = &self.instances;
        let meshes = &self.meshes;
        let inner = &mut scratch.inner;
        let mut inner_work = 0u64;
        let mut found = None;
        let t = self.instance_bvh.traverse_in::<ORDERED>(
            ray,
            tmax,
            &mut scratch.ray,
            &mut scratch.work,
            |first, count, tmax| {
                let mut tm = tmax;
                let Some(range) = instances.get(first..first + count) else {
                    return tm;
                };
                for (k, inst) in range.iter().enumerate() {
                    let Some(mesh) = meshes.get(inst.mesh as usize) else {
                        continue;
                    };
                    let oray = inst.object_ray(ray);
                    let r = mesh.bvh.traverse_in::<ORDERED>(
                        &oray,
                        tm,
                        inner,
                        &mut inner_work,
                        |f, c, tm2| {
                            let mut t2 = tm2;
                            if let Some(tris) = mesh.tris.get(f..f + c) {
                                for (j, tri) in tris.iter().enumerate() {
                                    if let Some((t, _, _)) =
                                        hit_triangle(tri[0], tri[1], tri[2], &oray, 0.0, t2)
                                    {
                                        found = Some(((first + k) as u32, (f + j) as u32));
                                        if !ORDERED {
                                            return -1.0;
                                        }
                                        t2 = t;
                                    }
                                }
                            }
                            t2
                        },
                    );
                    if !ORDERED && r < 0.0 {
                        return -1.0;
                    }
                    tm = r;
                }
                tm
            },
        );
        scratch.work += inner_work;
        found.map(|(i, p)| (t, i, p))
    }

    /// [`Scene::instances_hit`] for closest-hit queries.
    #[inline]
    fn intersect_instances(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(f32, u32, u32)> {
        self.instances_hit::<true>(ray, tmax, scratch)
    }

    /// Whether `ray` hits triangle `prim` of instance `instance` before `tmax`.
    #[inline]
    pub(super) fn hits_instance_triangle(
        &self,
        instance: u32,
        prim: u32,
        ray: &Ray,
        tmax: f32,
    ) -> bool {
        let Some(inst) = self.instances.get(instance as usize) else {
            return false;
        };
        let Some(tri) = self
            .meshes
            .get(inst.mesh as usize)
            .and_then(|m| m.tris.get(prim as usize))
        else {
            return false;
        };
        hit_triangle(tri[0], tri[1], tri[2], &inst.object_ray(ray), 0.0, tmax).is_some()
    }

    /// Closest hits of a packet of rays (such as a 4 x 4 pixel tile of primary rays):
    /// `out[i]` gets what [`Scene::intersect_with`] returns for `rays[i]`, bit for bit, for
    /// `i < min(rays.len(), out.len())`. Coherent rays go through the BVH together, sixteen at
    /// a time (`packet.rs`).
    pub fn intersect_packet(
        &self,
        rays: &[Ray],
        tmax: f32,
        scratch: &mut Scratch,
        out: &mut [Option<Hit>],
    ) {
        crate::packet::trace(self, rays, |_| tmax, scratch, out, false);
    }

    /// [`Scene::intersect_packet`] for coherent rays (a tile of eye rays): every ray goes
    /// through the packet traversal, so the work it adds to `scratch` does not depend on the
    /// other rays of the packet (the renderer's work counts stay additive over any split).
    pub(crate) fn intersect_tile(
        &self,
        rays: &[Ray],
        scratch: &mut Scratch,
        out: &mut [Option<Hit>],
    ) {
        crate::packet::trace(self, rays, |_| f32::INFINITY, scratch, out, true);
    }

    /// Any-hit queries of a packet of rays (such as the shadow rays of a tile): `out[i]` gets
    /// what [`Scene::occluded_with`] returns for `rays[i]`. Coherent rays go through the BVH
    /// together, sixteen at a time, each done at its first hit (`packet.rs`).
    pub fn occluded_packet(
        &self,
        rays: &[Ray],
        tmax: f32,
        scratch: &mut Scratch,
        out: &mut [bool],
    ) {
        crate::packet::trace(self, rays, |_| tmax, scratch, out, false);
    }

    /// True if anything blocks `ray` before `tmax` (any-hit, early exit).
    pub fn occluded(&self, ray: &Ray, tmax: f32) -> bool {
        self.occluded_with(ray, tmax, &mut Scratch::new())
    }

    /// [`Scene::occluded`] reusing a traversal stack.
    #[inline]
    pub fn occluded_with(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> bool {
        self.occluded_cached(ray, tmax, scratch, usize::MAX)
    }
}

/// Remembers the last cones tested along one ray: long oblique cones are referenced by several
/// BVH leaves, and a repeated test can never find anything new (the search interval only
/// shrinks).
#[derive(Clone, Copy, Default)]
pub(crate) struct Mailbox {
    recent: [u32; 2],
    used: bool,
}

impl Mailbox {
    #[inline(always)]
    pub(super) fn seen(&mut self, s: &Shape) -> bool {
        let Shape::Cone(k) = *s else { return false };
        let key = k.wrapping_add(1);
        if self.used && (self.recent[0] == key || self.recent[1] == key) {
            return true;
        }
        self.used = true;
        self.recent[1] = self.recent[0];
        self.recent[0] = key;
        false
    }
}
