//! Ray statistics in the SPD's categories, and the work they took.

use std::ops::{Add, AddAssign};

/// Counts of rays traced, in the categories of the SPD ray-count table, and the work units
/// spent on them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Eye (camera) rays shot.
    pub eye: u64,
    /// Eye rays that hit an object (not the background).
    pub eye_hits: u64,
    /// Reflection rays spawned (by reflective and transmitting surfaces, including on total internal reflection).
    pub reflected: u64,
    /// Refraction rays spawned.
    pub refracted: u64,
    /// Shadow rays actually cast towards lights.
    pub shadow: u64,
    /// Work units: BVH nodes visited, plus primitives handed to the leaf tests (and planes and
    /// shadow-cache entries tested), plus one per ray traced. With mesh instances, the nodes
    /// of the instances' BVH and of the meshes' own BVHs all count, and so do the instances
    /// handed to a leaf test and the triangles tested in a mesh. Unlike a time, it does not depend
    /// on the machine, and it follows the time a span takes closely, which ray counts alone do
    /// not (a ray that misses everything is cheap).
    pub work: u64,
}

impl RayStats {
    /// Sum of two statistics (also available as `+` and `+=`).
    #[allow(clippy::should_implement_trait)]
    pub fn add(self, other: RayStats) -> RayStats {
        RayStats {
            eye: self.eye + other.eye,
            eye_hits: self.eye_hits + other.eye_hits,
            reflected: self.reflected + other.reflected,
            refracted: self.refracted + other.refracted,
            shadow: self.shadow + other.shadow,
            work: self.work + other.work,
        }
    }

    /// Every counter by its field's name, in the fields' order, and whether it counts rays
    /// (eye hits and work units do not). The one list of the counters' names: the NIF sends
    /// the counters under these names, and the Elixir side learns them from it.
    ///
    /// ```
    /// use ring_tracer_kernel::RayStats;
    /// let s = RayStats { eye: 4, eye_hits: 3, shadow: 2, work: 90, ..RayStats::default() };
    /// let names: Vec<_> = s.counters().iter().map(|c| c.name).collect();
    /// assert_eq!(names, ["eye", "eye_hits", "reflected", "refracted", "shadow", "work"]);
    /// assert_eq!(s.total(), 6);
    /// ```
    pub fn counters(&self) -> [Counter; 6] {
        let c = |name, value, ray| Counter { name, value, ray };
        [
            c("eye", self.eye, true),
            c("eye_hits", self.eye_hits, false),
            c("reflected", self.reflected, true),
            c("refracted", self.refracted, true),
            c("shadow", self.shadow, true),
            c("work", self.work, false),
        ]
    }

    /// All rays of every kind.
    pub fn total(&self) -> u64 {
        self.counters()
            .iter()
            .filter(|c| c.ray)
            .map(|c| c.value)
            .sum()
    }
}

/// One of [`RayStats`]' counters, by name ([`RayStats::counters`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Counter {
    /// The field's name.
    pub name: &'static str,
    /// Its value.
    pub value: u64,
    /// Whether it counts rays (and so is part of [`RayStats::total`]).
    pub ray: bool,
}

impl Add for RayStats {
    type Output = RayStats;
    fn add(self, other: RayStats) -> RayStats {
        RayStats::add(self, other)
    }
}

impl AddAssign for RayStats {
    fn add_assign(&mut self, other: RayStats) {
        *self = RayStats::add(*self, other);
    }
}
