//! The order a stream of rays is traced in ([`crate::Scene::intersect_stream`],
//! [`crate::Scene::occluded_stream`]): rays that start near each other and go the same way are
//! traced one after another, so that they find the hierarchy's nodes and triangles in the
//! caches and its branches as the predictor last saw them.
//!
//! Each ray gets a key: its direction's octant (the sign of each component, which fixes the
//! order a node's children are visited in), then a six-dimensional Morton code of its origin
//! (quantized in the box of the stream's origins) and of its direction's magnitudes,
//! 5 bits each. The keys are sorted with their ray's index by a radix sort of three
//! passes of 11 bits (short windows by `sort_unstable`), and the rays and their bounds copied
//! in that order, in arrays kept in a [`StreamScratch`] between calls.

use crate::bvh::Scratch;
use crate::geometry::Aabb;
use crate::ray::Ray;
use crate::scene::Hit;
use glam::Vec3A;

/// Bits per dimension of the Morton code.
const LEVELS: u32 = 5;

/// Bits of a key: the octant, then six dimensions of [`LEVELS`] bits.
const KEY_BITS: u32 = 3 + 6 * LEVELS;

/// A stream is ordered in windows of at most this many rays (an index fits the low bits of a
/// sort entry). The tests' windows are short, so that their streams span several.
pub(crate) const WINDOW: usize = if cfg!(test) { 1 << 12 } else { 1 << INDEX_BITS };

/// Bits of a sort entry that hold the ray's index in its window.
const INDEX_BITS: u32 = 20;

/// Bits a radix pass sorts on.
const DIGIT: u32 = 11;

/// Windows shorter than this are sorted by comparison rather than by radix passes, whose
/// histograms would cost more than the rays.
const RADIX_FROM: usize = 1024;

const _: () = assert!(KEY_BITS + INDEX_BITS <= 64);

/// What a stream query keeps between calls: the sort's two arrays, the window's rays and bounds
/// in sorted order, and the traversal's stacks and shadow cache. One per thread; it grows to
/// the longest window it has ordered (at most 84 bytes a ray, 84 MiB), so that calls after
/// the first on as many rays allocate nothing.
#[derive(Clone, Debug, Default)]
pub struct StreamScratch {
    /// The window's sort entries: key above [`INDEX_BITS`], the ray's index below.
    pub(crate) order: Vec<u64>,
    /// The radix sort's other buffer.
    spare: Vec<u64>,
    /// The window's rays in sorted order.
    pub(crate) sorted: Vec<Ray>,
    /// Their bounds.
    pub(crate) bounds: Vec<f32>,
    /// The window's closest hits, in sorted order.
    pub(crate) hits: Vec<Option<Hit>>,
    /// The window's any-hit answers, in sorted order.
    pub(crate) occluded: Vec<bool>,
    /// The single-ray traversal's stacks and shadow cache.
    pub(crate) rays: Scratch,
}

impl StreamScratch {
    /// An empty scratch area (allocates on first use, then is reused).
    pub fn new() -> StreamScratch {
        StreamScratch::default()
    }

    /// Makes room for streams of `rays` rays (windows of at most a million), so that the
    /// calls that follow allocate nothing for their sort.
    pub fn reserve(&mut self, rays: usize) {
        let n = rays.min(WINDOW);
        let more = |len: usize| n.saturating_sub(len);
        self.order.reserve(more(self.order.len()));
        self.spare.reserve(more(self.spare.len()));
        self.sorted.reserve(more(self.sorted.len()));
        self.bounds.reserve(more(self.bounds.len()));
        self.hits.reserve(more(self.hits.len()));
        self.occluded.reserve(more(self.occluded.len()));
    }
}

/// The bits of a 5-bit value spread six apart (bit `b` of the value at bit `6 b`).
const SPREAD: [u32; 32] = {
    let mut t = [0u32; 32];
    let mut v = 0;
    while v < 32 {
        let mut b = 0;
        while b < LEVELS {
            t[v] |= ((v as u32 >> b) & 1) << (6 * b);
            b += 1;
        }
        v += 1;
    }
    t
};

/// Rays whose origins are sampled for the grid of [`Keys::new`].
const SAMPLES: usize = 1024;

/// How rays are turned into keys in one stream: the corner of the box its origins are
/// quantized in and the scale that maps that box onto the Morton grid.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Keys {
    lo: Vec3A,
    scale: Vec3A,
}

impl Keys {
    /// The keys of `rays`: the grid spans the box of up to [`SAMPLES`] of their origins, taken
    /// evenly through the stream (origins beyond it fall in its edge cells). Where that box
    /// is flat or unbounded on an axis, the scene's box `bounds` is used on it, and where that
    /// one is too, every origin falls in one cell on that axis.
    pub(crate) fn new(bounds: Aabb, rays: &[Ray]) -> Keys {
        let step = (rays.len() / SAMPLES).max(1);
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for r in rays.iter().step_by(step) {
            (lo, hi) = (lo.min(r.origin), hi.max(r.origin));
        }
        let usable = |lo: Vec3A, hi: Vec3A| {
            let e = hi - lo;
            e.cmpgt(Vec3A::ZERO) & e.is_finite_mask() & lo.is_finite_mask()
        };
        let own = usable(lo, hi);
        let lo = Vec3A::select(own, lo, bounds.min);
        let hi = Vec3A::select(own, hi, bounds.max);
        let cells = (1u32 << LEVELS) as f32;
        let ok = usable(lo, hi);
        Keys {
            lo: Vec3A::select(ok, lo, Vec3A::ZERO),
            scale: Vec3A::select(ok, Vec3A::splat(cells) / (hi - lo), Vec3A::ZERO),
        }
    }

    /// The key of `ray`: its octant, then the Morton code of its origin's cell and of its
    /// direction's magnitudes (NaNs and origins outside the grid fall in its edge cells).
    #[inline(always)]
    pub(crate) fn of(&self, ray: &Ray) -> u64 {
        let o = cells((ray.origin - self.lo) * self.scale);
        let d = cells(ray.dir.abs() * (1u32 << LEVELS) as f32);
        let spread = |c: u32| SPREAD[(c & 31) as usize];
        let neg = ray.inv_dir.cmplt(Vec3A::ZERO).bitmask();
        // at each level the origin's bits above the direction's: of the orders tried (origin
        // or direction first, either one alone, finer grids) the one with the fewest cache
        // misses and mispredicted branches in the traversals that follow
        let morton = spread(d[0])
            | spread(d[1]) << 1
            | spread(d[2]) << 2
            | spread(o[0]) << 3
            | spread(o[1]) << 4
            | spread(o[2]) << 5;
        (u64::from(neg) << (6 * LEVELS)) | u64::from(morton)
    }
}

/// The grid cells of `v`'s three coordinates: clamped to `0..2^LEVELS` (a NaN to 0), then
/// truncated.
#[inline(always)]
fn cells(v: Vec3A) -> [u32; 4] {
    // max first: a NaN in `v` gives its second operand, 0
    let c = v
        .max(Vec3A::ZERO)
        .min(Vec3A::splat(((1u32 << LEVELS) - 1) as f32));
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{__m128, __m128i, _mm_cvttps_epi32};
        let m: __m128 = c.into();
        // SAFETY: SSE2 is part of every x86_64 CPU; __m128i and [u32; 4] are both 16 plain
        // bytes
        unsafe { std::mem::transmute::<__m128i, [u32; 4]>(_mm_cvttps_epi32(m)) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        [c.x as u32, c.y as u32, c.z as u32, 0]
    }
}

/// Radix passes of a sort: enough [`DIGIT`]s for a key.
const PASSES: usize = KEY_BITS.div_ceil(DIGIT) as usize;

/// Buckets of a radix pass.
const BUCKETS: usize = 1 << DIGIT;

impl StreamScratch {
    /// Orders `rays` (at most [`WINDOW`]): afterwards `self.order` holds one entry per ray,
    /// sorted by key, each with its ray's index in its low [`INDEX_BITS`] bits.
    pub(crate) fn sort(&mut self, keys: &Keys, rays: &[Ray]) {
        debug_assert!(rays.len() <= WINDOW);
        self.order.clear();
        if rays.len() < RADIX_FROM {
            self.order.extend(
                rays.iter()
                    .enumerate()
                    .map(|(i, r)| keys.of(r) << INDEX_BITS | i as u64),
            );
            self.order.sort_unstable();
            return;
        }
        // the entries and every pass's counts in one pass over the rays
        let mut counts = [[0usize; BUCKETS]; PASSES];
        self.order.extend(rays.iter().enumerate().map(|(i, r)| {
            let key = keys.of(r);
            for (p, c) in counts.iter_mut().enumerate() {
                c[digit(key, p)] += 1;
            }
            key << INDEX_BITS | i as u64
        }));
        self.spare.resize(self.order.len(), 0);
        for (p, count) in counts.iter().enumerate() {
            radix_pass(&self.order, &mut self.spare, p, count);
            std::mem::swap(&mut self.order, &mut self.spare);
        }
    }

    /// Copies `rays` and their bounds `tmax` into `sorted` and `bounds`, in the order of
    /// `order` (a pass of independent reads, which the CPU overlaps, rather than a read at
    /// random before each ray's traversal).
    pub(crate) fn gather(&mut self, rays: &[Ray], tmax: &[f32]) {
        self.sorted.clear();
        self.bounds.clear();
        let ray = |e: &u64| rays.get(index(*e)).copied();
        self.sorted.extend(self.order.iter().filter_map(ray));
        let bound = |e: &u64| tmax.get(index(*e)).copied();
        self.bounds.extend(self.order.iter().filter_map(bound));
    }
}

/// The ray index of a sort entry.
#[inline(always)]
pub(crate) fn index(entry: u64) -> usize {
    (entry & ((1 << INDEX_BITS) - 1)) as usize
}

/// Digit `pass` of `key` (the lowest [`DIGIT`] bits first).
#[inline(always)]
fn digit(key: u64, pass: usize) -> usize {
    ((key >> (pass as u32 * DIGIT)) as usize) & (BUCKETS - 1)
}

/// One stable counting-sort pass of `from` into `to` by the key's digit `pass`, whose values
/// occur `count` times each.
fn radix_pass(from: &[u64], to: &mut [u64], pass: usize, count: &[usize; BUCKETS]) {
    let mut start = [0usize; BUCKETS];
    let mut sum = 0;
    for (s, &c) in start.iter_mut().zip(count) {
        (*s, sum) = (sum, sum + c);
    }
    for &e in from {
        let slot = &mut start[digit(e >> INDEX_BITS, pass)];
        if let Some(t) = to.get_mut(*slot) {
            *t = e;
        }
        *slot += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::rng;

    fn rays(n: usize, seed: u64) -> Vec<Ray> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                let o = Vec3A::new(rng(&mut s), rng(&mut s), rng(&mut s)) * 2.0;
                Ray::new(o, Vec3A::new(rng(&mut s), rng(&mut s), rng(&mut s)))
            })
            .collect()
    }

    /// The radix sort and the comparison sort order the same entries alike, and every ray
    /// appears once.
    #[test]
    fn both_sorts_give_every_ray_once_in_key_order() {
        let b = Aabb {
            min: Vec3A::splat(-1.0),
            max: Vec3A::splat(1.0),
        };
        for n in [0usize, 1, 7, RADIX_FROM - 1, RADIX_FROM, 5000] {
            let r = rays(n, 0x5eed + n as u64);
            let keys = Keys::new(b, &r);
            let mut s = StreamScratch::new();
            s.sort(&keys, &r);
            let mut want: Vec<u64> = r
                .iter()
                .enumerate()
                .map(|(i, r)| keys.of(r) << INDEX_BITS | i as u64)
                .collect();
            want.sort_unstable();
            assert_eq!(s.order, want, "n = {n}");
        }
    }

    /// A key's top bits are the octant; origins outside the box and NaNs get keys too.
    #[test]
    fn keys_put_the_octant_first_and_take_any_ray() {
        let unit = Aabb {
            min: Vec3A::ZERO,
            max: Vec3A::ONE,
        };
        // no rays to sample: the scene's box
        let keys = Keys::new(unit, &[]);
        let k = |o: Vec3A, d: Vec3A| keys.of(&Ray::new(o, d)) >> (6 * LEVELS);
        assert_eq!(k(Vec3A::splat(0.5), Vec3A::new(1.0, 1.0, 1.0)), 0);
        assert_eq!(k(Vec3A::splat(0.5), Vec3A::new(-1.0, 1.0, -1.0)), 0b101);
        assert_eq!(k(Vec3A::splat(9.0), Vec3A::new(1.0, -1.0, 1.0)), 0b010);
        let far = keys.of(&Ray::new(Vec3A::splat(1e30), Vec3A::X));
        let nan = keys.of(&Ray::new(Vec3A::splat(f32::NAN), Vec3A::X));
        assert!(far < 1 << KEY_BITS && nan < 1 << KEY_BITS);
        // one origin sampled and an unbounded scene: one cell for every origin
        let one = [Ray::new(Vec3A::splat(3.0), Vec3A::X)];
        let unbounded = Keys::new(
            Aabb {
                min: Vec3A::splat(f32::NEG_INFINITY),
                max: Vec3A::splat(f32::INFINITY),
            },
            &one,
        );
        let origin_bits = u64::from(SPREAD[31] * 0b111_000);
        assert_eq!(unbounded.of(&one[0]) & origin_bits, 0);
        assert_eq!(
            unbounded.of(&Ray::new(Vec3A::splat(-7.0), Vec3A::X)) & origin_bits,
            0
        );
        // origins sampled from the stream: the grid spans them, not the scene's box
        let spread: Vec<Ray> = (0..64)
            .map(|i| Ray::new(Vec3A::splat(i as f32 / 630.0), Vec3A::X))
            .collect();
        let own = Keys::new(unit, &spread);
        let last = own.of(&spread[63]) & origin_bits;
        assert_eq!(
            last, origin_bits,
            "the last origin is in the grid's far corner"
        );
    }
}
