//! Light transport: the [`Integrator`] trait and Whitted's recursive ray tracer.
//!
//! Shading at a hit (Whitted 1980 with the SPD's conventions):
//!
//! ```text
//! colour = ambient * Kd * C
//!        + sum over lights not in shadow of  Kd * C * light * max(N.L, 0)
//!                                          + Ks * light * max(R.L, 0)^Shine
//!        + Ks * reflected  +  T * refracted
//! ```
//! with `C` the surface colour, `N` the shading normal turned towards the viewer and `R` the
//! mirror direction of the incoming ray.
//!
//! - A shadow ray is cast only when `N.L > 0` (SPD rule 10), from the hit point offset along the
//!   geometric normal by the scene epsilon (scaled to the scene size). Every occluder blocks,
//!   transmitting ones included (no caustics, no attenuation).
//! - A reflection ray is spawned when `Ks > 0` or `T > 0` (the SPD counts reflection rays off all
//!   reflecting *and transmitting* surfaces); a refraction ray when `T > 0` unless total internal
//!   reflection happens, in which case the transmitted weight goes to the reflection ray.
//! - Inside/outside for refraction is decided by the sign of `dir . Ng` with the primitive's own
//!   geometric normal; `ior` is the index of the inside.
//! - The eye ray has depth 1; no ray is spawned past `max_depth`.
//! - Adaptive cut-off: a child ray whose accumulated weight (product of the Ks / T factors down
//!   the tree) is below `cutoff` is not spawned; `cutoff = 0` disables this (SPD rule 8), and
//!   then even zero-weight reflection rays of transmitters are traced, as the SPD counts them.

use crate::bvh::Scratch;
use crate::ray::{reflect, refract, Ray};
use crate::scene::{Hit, Scene};
use crate::stats::RayStats;
use glam::Vec3A;

/// Computes the radiance arriving along a ray.
pub trait Integrator: Sync {
    /// Radiance along an eye ray (linear RGB); updates `stats`. `scratch` is a per-thread
    /// traversal stack, reused across calls.
    fn radiance(
        &self,
        scene: &Scene,
        ray: &Ray,
        scratch: &mut Scratch,
        stats: &mut RayStats,
    ) -> Vec3A;
}

/// Whitted-style recursive ray tracing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Whitted {
    /// Maximum tree depth (eye ray = 1).
    pub max_depth: u32,
    /// Adaptive cut-off weight; 0 disables.
    pub cutoff: f32,
}

impl Integrator for Whitted {
    fn radiance(
        &self,
        scene: &Scene,
        ray: &Ray,
        scratch: &mut Scratch,
        stats: &mut RayStats,
    ) -> Vec3A {
        stats.eye += 1;
        self.trace(scene, ray, 1, 1.0, scratch, stats, true)
    }
}

/// Whether `n . (to / |to|)`, as the light loop computes it, is certainly <= 0, judged without
/// the square root and division: `n . to` below minus a bound far above the rounding error
/// of either form (a few units in the last place of `|n| . |to|`, here 1e-5 of it; a bound
/// under 1e-30 is not trusted, as underflow loses relative accuracy). When it says yes the
/// full test skips the light too; when it says no, the full test decides.
#[inline(always)]
fn surely_behind(n: Vec3A, to: Vec3A) -> bool {
    let bound = n.abs().dot(to.abs()) * 1e-5;
    bound > 1e-30 && n.dot(to) < -bound
}

impl Whitted {
    #[inline]
    fn spawn(&self, weight: f32) -> bool {
        self.cutoff <= 0.0 || weight >= self.cutoff
    }

    /// The radiance along `ray`: its closest hit, shaded. Inlined into [`Whitted::shade`]'s
    /// two recursive calls, so a child ray pays one call, not a call here and one to `shade`
    /// (a function of its own, it took 3% of a glass scene's instructions passing them on).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn trace(
        &self,
        scene: &Scene,
        ray: &Ray,
        depth: u32,
        weight: f32,
        scratch: &mut Scratch,
        stats: &mut RayStats,
        eye: bool,
    ) -> Vec3A {
        let hit = scene.intersect_with(ray, f32::INFINITY, scratch);
        self.shade(scene, ray, hit, depth, weight, scratch, stats, eye)
    }

    /// Radiance along an eye ray whose closest hit is already known (`hit` is what
    /// [`Scene::intersect_with`] returns for it, e.g. from [`Scene::intersect_packet`]): the
    /// same value and counts as [`Integrator::radiance`].
    pub(crate) fn radiance_of_hit(
        &self,
        scene: &Scene,
        ray: &Ray,
        hit: Option<Hit>,
        scratch: &mut Scratch,
        stats: &mut RayStats,
    ) -> Vec3A {
        stats.eye += 1;
        self.shade(scene, ray, hit, 1, 1.0, scratch, stats, true)
    }

    // Longer than 80 lines, kept whole: the shading of every hit. Split into #[inline(always)]
    // parts (the view of the hit, the direct light), the same renders took 4% more
    // instructions in it (callgrind, balls_s3 at 256 x 256).
    /// The rest of [`Whitted::trace`] once the ray's closest hit is known.
    #[allow(clippy::too_many_arguments)]
    fn shade(
        &self,
        scene: &Scene,
        ray: &Ray,
        hit: Option<Hit>,
        depth: u32,
        weight: f32,
        scratch: &mut Scratch,
        stats: &mut RayStats,
        eye: bool,
    ) -> Vec3A {
        let Some(hit) = hit else {
            return scene.background;
        };
        if eye {
            stats.eye_hits += 1;
        }
        let s = scene.surface(&hit, ray);
        let m = scene.material(s.material);
        let d = ray.dir;
        let entering = d.dot(s.ng) < 0.0;
        // normals turned towards the viewer
        let (nf, ngf) = if entering {
            (s.ns, s.ng)
        } else {
            (-s.ns, -s.ng)
        };
        let eps = scene.epsilon;
        let c = m.color_at(s.p);
        let mut out = scene.ambient * c * m.kd;
        let above = s.p + ngf * eps;
        let refl_dir = reflect(d, nf);
        for (li, light) in scene.lights.iter().enumerate() {
            let to = light.position - s.p;
            if surely_behind(nf, to) {
                continue;
            }
            let dist = to.length();
            if dist <= 0.0 {
                continue;
            }
            let l = to / dist;
            let ndl = nf.dot(l);
            if ndl <= 0.0 {
                continue;
            }
            stats.shadow += 1;
            let slot = li * 8 + depth.min(7) as usize;
            if scene.occluded_cached(&Ray::from_unit(above, l), dist - eps, scratch, slot) {
                continue;
            }
            out += c * light.color * (m.kd * ndl);
            if m.ks > 0.0 {
                let rl = refl_dir.dot(l);
                if rl > 0.0 {
                    out += light.color * (m.ks * rl.powf(m.shine));
                }
            }
        }
        if depth >= self.max_depth || (m.ks <= 0.0 && m.t <= 0.0) {
            return out;
        }
        let mut refl_w = m.ks;
        if m.t > 0.0 {
            let eta = if entering { 1.0 / m.eta() } else { m.eta() };
            match refract(d, nf, eta) {
                Some(tdir) => {
                    if self.spawn(weight * m.t) {
                        stats.refracted += 1;
                        let r = Ray::new(s.p - ngf * eps, tdir);
                        out +=
                            self.trace(scene, &r, depth + 1, weight * m.t, scratch, stats, false)
                                * m.t;
                    }
                }
                None => refl_w += m.t,
            }
        }
        if self.spawn(weight * refl_w) {
            stats.reflected += 1;
            let r = Ray::from_unit(above, refl_dir);
            out +=
                self.trace(scene, &r, depth + 1, weight * refl_w, scratch, stats, false) * refl_w;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The light loop's own test, as it was before the prefilter.
    fn skipped(n: Vec3A, to: Vec3A) -> bool {
        let dist = to.length();
        dist <= 0.0 || n.dot(to / dist) <= 0.0
    }

    #[test]
    fn prefilter_skips_only_lights_the_loop_skips() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut f = || {
            let r = next();
            let m = (r >> 11) as f32 / (1u64 << 53) as f32 * 2.0 - 1.0;
            m * 10f32.powi((r % 61) as i32 - 30)
        };
        let (mut skips, mut cases) = (0, 0);
        for i in 0..300_000 {
            let n = Vec3A::new(f(), f(), f()).normalize_or(Vec3A::Z);
            let mut to = Vec3A::new(f(), f(), f());
            if i % 3 == 0 {
                // nearly perpendicular to n: where rounding decides the sign
                to -= n * n.dot(to) * (1.0 + f() * 1e-6);
            }
            cases += 1;
            if surely_behind(n, to) {
                skips += 1;
                assert!(skipped(n, to), "n {n:?} to {to:?}");
            }
        }
        assert!(skips > cases / 5, "{skips} of {cases}");
        for (n, to) in [
            (Vec3A::Z, Vec3A::ZERO),
            (Vec3A::Z, Vec3A::new(0.0, 0.0, -f32::INFINITY)),
            (Vec3A::Z, Vec3A::splat(f32::NAN)),
            (Vec3A::Z, Vec3A::new(0.0, 0.0, -1e-30)),
        ] {
            assert!(!surely_behind(n, to) || skipped(n, to));
        }
    }
}
