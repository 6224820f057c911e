//! A scene's closest-hit and any-hit queries over a stream of rays: each ray gets what the
//! one-ray query answers, in the caller's order, but where the scene's hierarchy is beyond a
//! core's L2 cache the rays are traced in the order of [`crate::stream`] (by octant, origin
//! and direction), one at a time.

use super::{Hit, Scene};
use crate::bvh::Scratch;
use crate::ray::Ray;
use crate::stream::{index, Keys, StreamScratch, WINDOW};
use crate::Error;

/// `Ok` when the stream's three slices are as long as each other.
fn same_lengths(rays: usize, tmax: usize, out: usize, what: &str) -> Result<(), Error> {
    if rays == tmax && rays == out {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "a stream of {rays} rays needs as many bounds and {what}, got {tmax} bounds and {out} {what}"
        )))
    }
}

/// An answer of a stream query, with the scratch array that holds a window's answers in
/// sorted order.
trait Answer: Copy {
    /// That array.
    fn buffer(scratch: &mut StreamScratch) -> &mut Vec<Self>;
}

impl Answer for Option<Hit> {
    fn buffer(scratch: &mut StreamScratch) -> &mut Vec<Self> {
        &mut scratch.hits
    }
}

impl Answer for bool {
    fn buffer(scratch: &mut StreamScratch) -> &mut Vec<Self> {
        &mut scratch.occluded
    }
}

impl Scene {
    /// Closest hits of a stream of rays: `hits[i]` gets what [`Scene::intersect_with`] returns
    /// for `rays[i]` with the bound `tmax[i]`, bit for bit. The rays are traced one at a time
    /// in an order of their own (`crate::stream`: rays from near each other, going the same
    /// way, one after another), so that a long stream of incoherent rays (reflections,
    /// refractions, a path tracer's bounces) finds the hierarchy in the caches more often than
    /// in its own order. Where the whole hierarchy fits a core's L2 cache, the sort would cost
    /// more than it saves, and the rays are traced in their own order. `scratch` keeps the
    /// sort's arrays between calls.
    ///
    /// Errors with [`Error::InvalidArgument`] when the three slices differ in length.
    pub fn intersect_stream(
        &self,
        rays: &[Ray],
        tmax: &[f32],
        hits: &mut [Option<Hit>],
        scratch: &mut StreamScratch,
    ) -> Result<(), Error> {
        same_lengths(rays.len(), tmax.len(), hits.len(), "hits")?;
        let reorder = self.reordering_pays();
        self.each_window(rays, tmax, hits, scratch, reorder, |scene, ray, t, s| {
            scene.intersect_with(ray, t, s)
        });
        Ok(())
    }

    /// Any-hit queries of a stream of rays: `occluded[i]` gets what [`Scene::occluded_with`]
    /// returns for `rays[i]` with the bound `tmax[i]`, traced in the order of
    /// [`Scene::intersect_stream`].
    ///
    /// Errors with [`Error::InvalidArgument`] when the three slices differ in length.
    pub fn occluded_stream(
        &self,
        rays: &[Ray],
        tmax: &[f32],
        occluded: &mut [bool],
        scratch: &mut StreamScratch,
    ) -> Result<(), Error> {
        same_lengths(rays.len(), tmax.len(), occluded.len(), "answers")?;
        let reorder = self.reordering_pays();
        self.each_window(
            rays,
            tmax,
            occluded,
            scratch,
            reorder,
            |scene, ray, t, s| scene.occluded_with(ray, t, s),
        );
        Ok(())
    }

    /// Whether reordering a stream pays: where a hierarchy is beyond a core's L2 cache (one
    /// that prefetches, [`crate::bvh::Bvh::prefetch`]), rays in order find its nodes in the
    /// caches far more often than in their own order; where all of it fits there, the order
    /// saves some mispredicted branches but less than the sort costs, and the rays are traced
    /// in the caller's order.
    fn reordering_pays(&self) -> bool {
        self.bvh.prefetch || self.meshes.iter().any(|m| m.bvh.prefetch)
    }

    /// With `reorder`, sorts the stream window by window ([`WINDOW`] rays at most), gathers
    /// each window's rays and bounds in that order, and answers them with `query` one after
    /// another; without, answers them in their own order. The slices are as long as each
    /// other.
    #[inline(always)]
    fn each_window<A: Answer>(
        &self,
        rays: &[Ray],
        tmax: &[f32],
        out: &mut [A],
        scratch: &mut StreamScratch,
        reorder: bool,
        mut query: impl FnMut(&Scene, &Ray, f32, &mut Scratch) -> A,
    ) {
        if !reorder {
            for ((r, &t), o) in rays.iter().zip(tmax).zip(out.iter_mut()) {
                *o = query(self, r, t, &mut scratch.rays);
            }
            return;
        }
        let keys = Keys::new(self.bounds(), rays);
        for ((rays, tmax), out) in rays
            .chunks(WINDOW)
            .zip(tmax.chunks(WINDOW))
            .zip(out.chunks_mut(WINDOW))
        {
            scratch.sort(&keys, rays);
            scratch.gather(rays, tmax);
            let mut answers = std::mem::take(A::buffer(scratch));
            answers.clear();
            let StreamScratch {
                sorted,
                bounds,
                rays: s,
                ..
            } = scratch;
            answers.extend(
                sorted
                    .iter()
                    .zip(bounds.iter())
                    .map(|(ray, &t)| query(self, ray, t, s)),
            );
            // the answers in the caller's order: a pass of independent stores, rather than a
            // store at random after each ray's traversal
            for (&entry, &a) in scratch.order.iter().zip(&answers) {
                if let Some(o) = out.get_mut(index(entry)) {
                    *o = a;
                }
            }
            *A::buffer(scratch) = answers;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;
    use crate::scene::SceneBuilder;
    use crate::test_support::rng;
    use glam::Vec3A;
    use std::path::Path;

    fn v(seed: &mut u64) -> Vec3A {
        Vec3A::new(rng(seed), rng(seed), rng(seed))
    }

    /// Random triangles, and with `others` spheres and cones, around the origin.
    fn random_scene(seed: &mut u64, n: usize, others: bool) -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.material(Material::default());
        for k in 0..n {
            let c = v(seed) * 3.0;
            let s = 0.05 + 0.3 * rng(seed).abs();
            let tri = [c + v(seed) * s, c + v(seed) * s, c + v(seed) * s];
            b.triangle(tri, None, m).unwrap();
            if others && k % 9 == 0 {
                b.sphere(c, s * 0.5, m).unwrap();
                b.cone(c, s * 0.3, c + v(seed) * 2.0, s * 0.1, m).unwrap();
            }
        }
        b.build("test").unwrap()
    }

    /// `n` rays from within `reach` of the origin in random directions, some from far outside
    /// the scene's box and some pointing away from it, with bounds from 0 to infinity.
    fn random_rays(seed: &mut u64, n: usize, reach: f32) -> (Vec<Ray>, Vec<f32>) {
        let rays: Vec<Ray> = (0..n)
            .map(|k| {
                let o = v(seed) * if k % 7 == 0 { reach * 10.0 } else { reach };
                Ray::new(o, v(seed))
            })
            .collect();
        let tmax = (0..n)
            .map(|k| match k % 5 {
                0 => f32::INFINITY,
                1 => 0.0,
                2 => reach * rng(seed).abs(),
                _ => reach * 4.0 * rng(seed).abs(),
            })
            .collect();
        (rays, tmax)
    }

    /// The stream queries' answers against the one-ray queries', ray for ray (closest hits
    /// bit for bit); returns the number of hits.
    fn check(scene: &Scene, rays: &[Ray], tmax: &[f32], scratch: &mut StreamScratch) -> usize {
        let mut one = Scratch::new();
        let mut hits = vec![None; rays.len()];
        scene
            .intersect_stream(rays, tmax, &mut hits, scratch)
            .unwrap();
        let mut occluded = vec![false; rays.len()];
        scene
            .occluded_stream(rays, tmax, &mut occluded, scratch)
            .unwrap();
        for (i, (r, &t)) in rays.iter().zip(tmax).enumerate() {
            let want = scene.intersect_with(r, t, &mut one);
            let got = hits[i];
            assert_eq!(
                got.map(|h| (h.t.to_bits(), h.prim, h.instance)),
                want.map(|h| (h.t.to_bits(), h.prim, h.instance)),
                "ray {i} of {}: {r:?}, tmax {t}",
                rays.len()
            );
            assert_eq!(occluded[i], scene.occluded_with(r, t, &mut one), "ray {i}");
        }
        hits.iter().filter(|h| h.is_some()).count()
    }

    #[test]
    fn streams_answer_as_one_ray_at_a_time_on_random_scenes() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut scratch = StreamScratch::new();
        let mut hits = 0;
        for (round, n) in [0usize, 1, 2, 17, 1000, 1500, 5000].into_iter().enumerate() {
            let scene = random_scene(&mut seed, [40, 600, 3000][round % 3], round % 2 == 1);
            let (rays, tmax) = random_rays(&mut seed, n, 4.0);
            // one scratch for every stream, long and short: what a longer one left is reused
            hits += check(&scene, &rays, &tmax, &mut scratch);
        }
        assert!(hits > 200, "{hits}");
    }

    /// A scene with an infinite plane (whitted.toml) and an SPD scene of many triangles.
    #[test]
    fn streams_answer_as_one_ray_at_a_time_on_files() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes");
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut scratch = StreamScratch::new();
        for file in ["whitted.toml", "spd/teapot_s6.nff"] {
            let scene = Scene::load(&root.join(file)).unwrap();
            let b = scene.bounds();
            let reach = (b.max - b.min).max_element();
            let (mut rays, tmax) = random_rays(&mut seed, 3000, reach);
            for r in rays.iter_mut() {
                *r = Ray::new(r.origin + b.centre(), r.dir);
            }
            let hits = check(&scene, &rays, &tmax, &mut scratch);
            assert!(hits > 100, "{file}: {hits}");
        }
    }

    /// Slices of different lengths are refused with a message that names them.
    #[test]
    fn streams_of_unequal_slices_are_refused() {
        let scene = random_scene(&mut 7, 10, false);
        let rays = [Ray::new(Vec3A::ZERO, Vec3A::X); 3];
        let mut s = StreamScratch::new();
        let e = scene
            .intersect_stream(&rays, &[1.0; 2], &mut [None; 3], &mut s)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid argument: a stream of 3 rays needs as many bounds and hits, got 2 bounds and 3 hits"
        );
        let e = scene
            .occluded_stream(&rays, &[1.0; 3], &mut [false; 4], &mut s)
            .unwrap_err();
        assert!(e.to_string().contains("got 3 bounds and 4 answers"), "{e}");
    }
}
