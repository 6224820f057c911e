//! The ray-casting benches' shared parts: the Embree harness ([`embree`]), the rays both
//! kernels trace, our single-ray loop and the CPU clock.

pub mod embree;

use ring_tracer_kernel::{raysets, Aabb, Hit, Ray, Scene, Scratch, StreamScratch};
use std::time::Instant;

/// The rays of one bench: `size x size` primary rays of the default OBJ view in 4 x 4 pixel
/// tiles (16 consecutive rays are one tile) and as many incoherent ones.
pub struct RaySets {
    /// Primary rays, tile by tile.
    pub tiled: Vec<Ray>,
    /// Random origins in the central half of the box, directions on the sphere.
    pub incoherent: Vec<Ray>,
}

impl RaySets {
    /// The rays for a scene of bounds `b`.
    pub fn new(b: Aabb, size: u32) -> Self {
        let primary = raysets::primary(b, size);
        let tiled = raysets::tile_order(size)
            .iter()
            .map(|&i| primary[i as usize])
            .collect();
        let incoherent = raysets::incoherent(b, primary.len());
        RaySets { tiled, incoherent }
    }
}

/// Shadow rays of the primary hits of `tiled` (in their order, so nearly every sixteen come
/// from one tile): from each hit point, moved back along the eye ray by a hundred-thousandth
/// of the scene's size, towards a point light outside the box beyond its far corner (so an
/// unbounded any-hit query answers them).
pub fn shadow_rays(scene: &Scene, tiled: &[Ray]) -> Vec<Ray> {
    let b = scene.bounds();
    let size = (b.max - b.min).max_element();
    let light = b.max + (b.max - b.min) * 2.0;
    let mut s = Scratch::new();
    tiled
        .iter()
        .filter_map(|r| {
            let h = scene.intersect_with(r, f32::INFINITY, &mut s)?;
            let p = r.at(h.t) - r.dir * (1e-5 * size);
            Some(Ray::new(p, light - p))
        })
        .collect()
}

/// How many of `rays` hit `scene` (any hit: are occluded), one ray at a time
/// (`Scene::intersect_with` / `Scene::occluded_with`).
pub fn single_hits(scene: &Scene, rays: &[Ray], any: bool) -> u64 {
    let mut s = Scratch::new();
    rays.iter()
        .filter(|r| {
            if any {
                scene.occluded_with(r, f32::INFINITY, &mut s)
            } else {
                scene.intersect_with(r, f32::INFINITY, &mut s).is_some()
            }
        })
        .count() as u64
}

/// How many of `rays` hit `scene` (any hit: are occluded), sixteen consecutive rays at a time
/// (`Scene::intersect_packet` / `Scene::occluded_packet`), as the bench traces its packets.
pub fn packet_hits(scene: &Scene, rays: &[Ray], any: bool) -> u64 {
    let mut s = Scratch::new();
    let mut hits = 0u64;
    for p in rays.chunks(16) {
        if any {
            let mut out = [false; 16];
            scene.occluded_packet(p, f32::INFINITY, &mut s, &mut out);
            hits += out.iter().filter(|&&h| h).count() as u64;
        } else {
            let mut out = [None; 16];
            scene.intersect_packet(p, f32::INFINITY, &mut s, &mut out);
            hits += out.iter().filter(|h| h.is_some()).count() as u64;
        }
    }
    hits
}

/// Our stream queries (`Scene::intersect_stream` / `Scene::occluded_stream`) with their
/// arrays kept between calls, as a renderer would keep them: after the first call on as many
/// rays, a call allocates nothing.
#[derive(Default)]
pub struct Streams {
    scratch: StreamScratch,
    tmax: Vec<f32>,
    hits: Vec<Option<Hit>>,
    occluded: Vec<bool>,
}

impl Streams {
    /// Makes room for streams of `rays` rays: the calls that follow on as many allocate
    /// nothing.
    pub fn reserve(&mut self, rays: usize) {
        self.scratch.reserve(rays);
        let more = |len: usize| rays.saturating_sub(len);
        self.tmax.reserve(more(self.tmax.len()));
        self.hits.reserve(more(self.hits.len()));
        self.occluded.reserve(more(self.occluded.len()));
    }

    /// How many of `rays` hit `scene` (any hit: are occluded), all of them one stream with
    /// no bound.
    pub fn hits(&mut self, scene: &Scene, rays: &[Ray], any: bool) -> u64 {
        let n = rays.len();
        self.tmax.resize(n, f32::INFINITY);
        let done = if any {
            self.occluded.resize(n, false);
            scene
                .occluded_stream(rays, &self.tmax, &mut self.occluded, &mut self.scratch)
                .map(|()| self.occluded.iter().filter(|&&o| o).count())
        } else {
            self.hits.resize(n, None);
            scene
                .intersect_stream(rays, &self.tmax, &mut self.hits, &mut self.scratch)
                .map(|()| self.hits.iter().filter(|h| h.is_some()).count())
        };
        // the slices are as long as each other: the stream queries cannot refuse them
        done.unwrap_or(0) as u64
    }
}

/// This process's CPU time in seconds (user + system, from `/proc/self/stat`, in clock ticks
/// of 10 ms); 0 where that file is missing. On a busy machine, rays per CPU second vary less
/// than rays per wall second.
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // the fields after the command name in parentheses; utime and stime are the 14th and 15th
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|x| x.parse().ok())
        .collect();
    f.iter().sum::<f64>() / 100.0
}

/// (wall seconds, CPU seconds, result) of `f`.
pub fn timed_cpu<T>(f: impl FnOnce() -> T) -> (f64, f64, T) {
    let (t, c) = (Instant::now(), cpu_seconds());
    let r = f();
    (t.elapsed().as_secs_f64(), cpu_seconds() - c, r)
}
