//! The any-hit query of shadow rays, with a cache of the last occluder per slot (light and
//! tree depth) kept in the caller's [`Scratch`].

use super::{Hit, Mailbox, Scene};
use crate::bvh::{has_avx2_fma, Scratch};
use crate::geometry::Shape;
use crate::ray::Ray;
use crate::tri4::RayLanes;

/// No shadow-cache entry.
const NO_CACHE: (u32, u32) = (u32::MAX, u32::MAX);

/// Shadow-cache slots a [`Scratch`] may hold ([`Scene::occluded_cached`]).
const CACHE_SLOTS: usize = 1 << 19;

/// A cached occluder is dropped once it has let this many shadow rays of its slot in a row
/// through: where few rays are blocked (most of a scene's shadow rays reach their light), a
/// stale entry costs a test per ray and saves nothing.
const CACHE_PATIENCE: u32 = 4;

/// Stores `occluder` and its count of rays let through at shadow-cache `entry` (see
/// [`Scene::occluded_cached`]), growing the cache as needed.
#[inline]
fn set_cache(scratch: &mut Scratch, entry: Option<usize>, occluder: (u32, u32), misses: u32) {
    let Some(e) = entry else { return };
    if scratch.shadow_cache.len() < e + 2 {
        scratch.shadow_cache.resize(e + 2, NO_CACHE);
    }
    if let Some([c, m]) = scratch.shadow_cache.get_mut(e..e + 2) {
        *c = occluder;
        *m = (misses, 0);
    }
}

impl Scene {
    /// Any-hit query with a shadow cache: `slot` (e.g. light and tree depth) remembers the last
    /// occluder found, which is tested first. The answer does not depend on the cache.
    ///
    /// Where the CPU has AVX2 and FMA, the whole query (the BVH's traversal and its leaf tests
    /// included) is one function compiled for them, so a shadow ray pays one call.
    #[inline]
    pub(crate) fn occluded_cached(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
        slot: usize,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe { self.occluded_cached_avx(ray, tmax, scratch, slot) };
        }
        self.occluded_portable(ray, tmax, scratch, slot)
    }

    /// [`Scene::occluded_in`] with the portable node test, for CPUs without AVX2 and FMA. Never
    /// inlined: inlined into the callers of [`Scene::occluded_cached`] (the shading of a hit),
    /// this traversal, never run where AVX2 is, made their code larger and slower.
    #[inline(never)]
    fn occluded_portable(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch, slot: usize) -> bool {
        // SAFETY: without AVX, the portable node test.
        unsafe { self.occluded_in::<false>(ray, tmax, scratch, slot) }
    }

    /// [`Scene::occluded_in`] compiled with AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn occluded_cached_avx(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
        slot: usize,
    ) -> bool {
        // SAFETY: the caller's contract.
        unsafe { self.occluded_in::<true>(ray, tmax, scratch, slot) }
    }

    /// [`Scene::occluded_cached`], with the AVX node test when `AVX` is set (only by
    /// [`Scene::occluded_cached_avx`]).
    ///
    /// # Safety
    /// With `AVX`, the CPU must have AVX2 and FMA.
    #[inline(always)]
    unsafe fn occluded_in<const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
        slot: usize,
    ) -> bool {
        // the slot's occluder at 2 slot, and at 2 slot + 1 how many rays in a row it let through
        let entry = (slot < CACHE_SLOTS).then_some(2 * slot);
        let (cached, misses) = match entry.map(|e| scratch.shadow_cache.get(e..e + 2)) {
            Some(Some(&[c, (m, _)])) => (c, m),
            _ => (NO_CACHE, 0),
        };
        if cached != NO_CACHE && self.cached_blocks(cached, ray, tmax, scratch) {
            if misses != 0 {
                self::set_cache(scratch, entry, cached, 0);
            }
            return true;
        }
        // SAFETY: this function's contract.
        if let Some(found) = unsafe { self.occluder_in_bvh::<AVX>(ray, tmax, scratch) } {
            self::set_cache(scratch, entry, found, 0);
            return true;
        }
        // the instances and planes: no call where there are none (most scenes)
        let beyond = if self.instances.is_empty() && self.planes.is_empty() {
            None
        } else {
            self.occluded_beyond_bvh(ray, tmax, scratch)
        };
        if let Some(f) = beyond.filter(|&f| f != NO_CACHE) {
            self::set_cache(scratch, entry, f, 0);
            return true;
        }
        if cached != NO_CACHE {
            // a cached occluder that keeps letting rays through is tested no more
            if misses + 1 >= CACHE_PATIENCE {
                self::set_cache(scratch, entry, NO_CACHE, 0);
            } else {
                self::set_cache(scratch, entry, cached, misses + 1);
            }
        }
        beyond.is_some()
    }

    /// Whether the cached occluder `cached` (instance or [`Hit::NO_INSTANCE`], primitive)
    /// blocks `ray` before `tmax`: one test, counted in `scratch.work`.
    #[inline(always)]
    fn cached_blocks(
        &self,
        cached: (u32, u32),
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> bool {
        let (ci, c) = cached;
        scratch.work += 1;
        if ci == Hit::NO_INSTANCE {
            let geom = &self.geom;
            geom.shapes
                .get(c as usize)
                .is_some_and(|s| geom.hit(s, ray, 0.0, tmax).is_some())
        } else {
            self.hits_instance_triangle(ci, c, ray, tmax)
        }
    }

    /// The first of the scene's own primitives found to block `ray` before `tmax`, through
    /// its BVH, as a shadow-cache entry; `None` if none does.
    ///
    /// # Safety
    /// With `AVX`, the CPU must have AVX2 and FMA.
    #[inline(always)]
    unsafe fn occluder_in_bvh<const AVX: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(u32, u32)> {
        let shapes = &self.geom.shapes;
        let geom = &self.geom;
        let mut found = NO_CACHE;
        let mut mailbox = Mailbox::default();
        let blocks = &self.tri_blocks;
        // made at the first triangle leaf: most shadow rays of an analytic scene meet none
        let mut lanes = None;
        // SAFETY: this function's contract.
        let r = unsafe {
            self.bvh.traverse_compiled::<false, AVX>(
                ray,
                tmax,
                &mut scratch.ray,
                &mut scratch.work,
                #[inline(always)]
                |first, count, tmax| {
                    if let Some(leaf) = blocks.leaf(first, count) {
                        let lanes = lanes.get_or_insert_with(|| RayLanes::new(ray));
                        for b in leaf {
                            if let Some(i) = b.any(lanes, 0.0, tmax) {
                                found = (Hit::NO_INSTANCE, b.prim(i));
                                return -1.0;
                            }
                        }
                        return tmax;
                    }
                    if let Some(range) = shapes.get(first..first + count) {
                        // any hit will do: the cheap tests first, the cones (dearer) after
                        for (k, s) in range.iter().enumerate() {
                            if !matches!(s, Shape::Cone(_)) && geom.hit(s, ray, 0.0, tmax).is_some()
                            {
                                found = (Hit::NO_INSTANCE, (first + k) as u32);
                                return -1.0;
                            }
                        }
                        for (k, s) in range.iter().enumerate() {
                            if !matches!(s, Shape::Cone(_)) || mailbox.seen(s) {
                                continue;
                            }
                            if geom.hit(s, ray, 0.0, tmax).is_some() {
                                found = (Hit::NO_INSTANCE, (first + k) as u32);
                                return -1.0;
                            }
                        }
                    }
                    tmax
                },
                |first, count| blocks.prefetch(first, count),
            )
        };
        (r < 0.0).then_some(found)
    }

    /// The rest of an any-hit query once the scene's own BVH let `ray` through: the mesh
    /// instances, then the planes. `Some((instance, triangle))` for an instance's triangle,
    /// `Some(NO_CACHE)` for a plane, `None` when nothing blocks the ray before `tmax`.
    #[inline]
    pub(crate) fn occluded_beyond_bvh(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(u32, u32)> {
        if !self.instances.is_empty() {
            if let Some((_, i, p)) = self.instances_hit::<false>(ray, tmax, scratch) {
                return Some((i, p));
            }
        }
        scratch.work += self.planes.len() as u64;
        self.planes
            .iter()
            .any(|pl| {
                let dn = pl.normal.dot(ray.dir);
                dn != 0.0 && {
                    let t = (pl.d - pl.normal.dot(ray.origin)) / dn;
                    t > 0.0 && t < tmax
                }
            })
            .then_some(NO_CACHE)
    }
}

#[cfg(test)]
mod shadow_cache_tests {
    use super::*;
    use crate::material::Material;
    use crate::scene::SceneBuilder;
    use glam::Vec3A;

    /// Spheres, cones (oblique ones split over several leaves), triangles and a plane, laid
    /// out on a grid so that shadow rays are blocked in runs and let through in runs.
    fn scene() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.material(Material::default());
        for i in 0..12 {
            for j in 0..12 {
                let p = Vec3A::new(i as f32, j as f32, 0.0);
                match (i + j) % 3 {
                    0 => b.sphere(p, 0.3, m).unwrap(),
                    1 => b
                        .cone(p, 0.2, p + Vec3A::new(0.7, 0.5, 1.5), 0.1, m)
                        .unwrap(),
                    _ => b
                        .triangle(
                            [
                                p,
                                p + Vec3A::new(0.6, 0.0, 0.2),
                                p + Vec3A::new(0.0, 0.6, 0.4),
                            ],
                            None,
                            m,
                        )
                        .unwrap(),
                }
            }
        }
        b.plane(Vec3A::new(0.0, 0.0, -3.0), Vec3A::Z, m).unwrap();
        b.build("test").unwrap()
    }

    /// Every primitive tested, no cache, no BVH.
    fn brute(s: &Scene, ray: &Ray, tmax: f32) -> bool {
        s.geom
            .shapes
            .iter()
            .any(|sh| s.geom.hit(sh, ray, 0.0, tmax).is_some())
            || s.planes.iter().any(|pl| {
                let dn = pl.normal.dot(ray.dir);
                dn != 0.0 && {
                    let t = (pl.d - pl.normal.dot(ray.origin)) / dn;
                    t > 0.0 && t < tmax
                }
            })
    }

    #[test]
    fn the_cache_changes_no_answer() {
        let s = scene();
        let mut scratch = Scratch::new();
        let lights = [
            Vec3A::new(5.0, 5.0, 8.0),
            Vec3A::new(-4.0, 14.0, 3.0),
            Vec3A::new(20.0, -3.0, 1.0),
        ];
        let (mut blocked, mut free) = (0, 0);
        // shading points in scanline order, as a renderer meets them
        for y in 0..60 {
            for x in 0..60 {
                let p = Vec3A::new(x as f32 * 0.2 - 0.5, y as f32 * 0.2 - 0.5, -0.6);
                for (li, l) in lights.iter().enumerate() {
                    let to = *l - p;
                    let dist = to.length();
                    let ray = Ray::from_unit(p, to / dist);
                    let want = brute(&s, &ray, dist);
                    for slot in [li * 8 + 1, usize::MAX, 1 << 30] {
                        assert_eq!(
                            s.occluded_cached(&ray, dist, &mut scratch, slot),
                            want,
                            "point {p:?} light {li} slot {slot}"
                        );
                    }
                    if want {
                        blocked += 1;
                    } else {
                        free += 1;
                    }
                }
            }
        }
        assert!(
            blocked > 1000 && free > 1000,
            "{blocked} blocked, {free} free"
        );
        // slots far apart: the cache grows, and the bound on slots holds
        assert!(scratch.shadow_cache.len() <= 2 * CACHE_SLOTS);
    }
}
