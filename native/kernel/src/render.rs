//! Rendering settings, pixel spans and whole images.
//!
//! Every pixel value is a pure function of (scene, settings, pixel index): sample positions come
//! from a hash of (pixel index, sample index), SPD corner values from the corner position only,
//! and accumulation order is fixed. Hence [`trace_span`] over any split of the image and
//! [`render_image`] with any thread count give bit-identical pixels, and ray counts that sum to
//! the same totals. The work units ([`RayStats::work`]) of a split differ a little: each span
//! starts with an empty shadow cache, and in SPD mode re-traces the corners it shares.

use crate::bvh::Scratch;
use crate::camera::Camera;
use crate::integrator::{Integrator, Whitted};
use crate::limits;
use crate::ray::Ray;
use crate::scene::Scene;
use crate::stats::RayStats;
use crate::Error;
use glam::Vec3A;
use std::sync::Mutex;

/// How to render. [`Settings::new`] gives the defaults of every field but the size.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Maximum ray-tree depth; the eye ray is depth 1.
    pub depth: u32,
    /// Adaptive cut-off weight: a branch whose weight falls below it is not traced; 0 disables.
    pub cutoff: f32,
    /// S: SxS stratified jittered samples per pixel; 1 shoots through the pixel centre.
    pub samples: u32,
    /// SPD corner mode (SPD testing procedure): rays through the (W+1)x(H+1) pixel corners, the
    /// four corners of a pixel averaged; forces depth 5, no cut-off and one sample.
    pub spd: bool,
    /// Only this part of the `width` x `height` image is traced (the camera still frames the whole
    /// image); span indices then count the region's pixels, row-major. `None`: the whole image.
    pub region: Option<Region>,
}

/// A rectangle of an image, in pixels: columns `x0..x0 + width`, rows `y0..y0 + height` (y=0 is
/// the top row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl Settings {
    /// A `width` x `height` image with every other setting at its default: depth 5, cut-off
    /// 1/255, one sample through the pixel centre, no SPD corner mode, the whole image.
    ///
    /// The one place these defaults are written: the NIF hands them to the Elixir side
    /// (`RingTracer.Native.settings_defaults/0`), which reads them when it compiles.
    ///
    /// ```
    /// use ring_tracer_kernel::Settings;
    /// let s = Settings::new(64, 48);
    /// assert_eq!((s.depth, s.samples, s.spd, s.region), (5, 1, false, None));
    /// assert_eq!(s.cutoff, 1.0 / 255.0);
    /// ```
    pub fn new(width: u32, height: u32) -> Settings {
        Settings {
            width,
            height,
            depth: 5,
            cutoff: 1.0 / 255.0,
            samples: 1,
            spd: false,
            region: None,
        }
    }

    /// Defaults ([`Settings::new`]) with the scene's resolution.
    pub fn for_scene(scene: &Scene) -> Settings {
        let (width, height) = scene.resolution();
        Settings::new(width, height)
    }

    /// The size of what is traced: the region's, or the whole image's.
    pub fn traced_size(&self) -> (u32, u32) {
        match self.region {
            Some(r) => (r.width, r.height),
            None => (self.width, self.height),
        }
    }

    /// Checks the settings against [`crate::limits`].
    pub fn validate(&self) -> Result<(), Error> {
        limits::check_resolution(self.width, self.height)?;
        if let Some(r) = self.region {
            let inside = r.width > 0
                && r.height > 0
                && r.x0 as u64 + r.width as u64 <= self.width as u64
                && r.y0 as u64 + r.height as u64 <= self.height as u64;
            if !inside {
                return Err(Error::InvalidArgument(format!(
                    "region {}x{} at ({}, {}) is not inside the {}x{} image",
                    r.width, r.height, r.x0, r.y0, self.width, self.height
                )));
            }
        }
        if self.depth == 0 {
            return Err(Error::InvalidArgument("depth must be at least 1".into()));
        }
        limits::check(
            "ray depth",
            self.depth as u64,
            limits::MAX_DEPTH as u64,
            "MAX_DEPTH",
        )?;
        if self.samples == 0 {
            return Err(Error::InvalidArgument("samples must be at least 1".into()));
        }
        limits::check(
            "samples per pixel side",
            self.samples as u64,
            limits::MAX_SAMPLES as u64,
            "MAX_SAMPLES",
        )?;
        if !(self.cutoff.is_finite() && self.cutoff >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "cutoff must be a finite number >= 0, got {}",
                self.cutoff
            )));
        }
        Ok(())
    }

    fn integrator(&self) -> Whitted {
        if self.spd {
            Whitted {
                max_depth: 5,
                cutoff: 0.0,
            }
        } else {
            Whitted {
                max_depth: self.depth,
                cutoff: self.cutoff,
            }
        }
    }
}

/// SplitMix64 finaliser.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Two uniform numbers in [0, 1) from (pixel, sample).
#[inline]
fn jitter(pixel: u64, sample: u64) -> (f32, f32) {
    let h = mix(pixel.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ mix(sample));
    let a = (h >> 40) as f32 * (1.0 / 16_777_216.0);
    let b = ((h >> 8) & 0xFF_FFFF) as f32 * (1.0 / 16_777_216.0);
    (a, b)
}

impl Settings {
    /// Checks the settings, and that `count` pixels from linear index `start` lie inside the
    /// image; returns the end of the span (exclusive).
    ///
    /// ```
    /// use ring_tracer_kernel::Settings;
    /// let s = Settings {
    ///     width: 4,
    ///     height: 2,
    ///     depth: 5,
    ///     cutoff: 0.0,
    ///     samples: 1,
    ///     spd: false,
    ///     region: None,
    /// };
    /// assert_eq!(s.span_end(5, 3).unwrap(), 8);
    /// assert!(s.span_end(5, 4).is_err());
    /// ```
    pub fn span_end(&self, start: u64, count: u64) -> Result<u64, Error> {
        self.validate()?;
        let (w, h) = self.traced_size();
        let total = w as u64 * h as u64;
        match start.checked_add(count) {
            Some(end) if end <= total => Ok(end),
            _ => Err(Error::InvalidArgument(format!(
                "pixel span {start}+{count} is outside the {w}x{h} image ({total} pixels)"
            ))),
        }
    }
}

/// Trace `count` pixels starting at linear pixel index `start` (row-major, index = y*width + x,
/// y=0 is the TOP row). Returns linear-light RGB f32, 3 floats per pixel, and the ray
/// statistics. A pure function of (scene, settings, pixel index): the same pixel gives
/// bit-identical values whatever span it is traced in.
pub fn trace_span(
    scene: &Scene,
    settings: &Settings,
    start: u64,
    count: u64,
) -> Result<(Vec<f32>, RayStats), Error> {
    // checked before allocating: a span outside the image must not size a buffer
    settings.span_end(start, count)?;
    let floats = count as usize * 3;
    // fallible: an image's span is up to limits::MAX_PIXELS (768 MiB of floats)
    let mut out = crate::memory::try_with_capacity(floats, || {
        format!("the pixels of a span of {count} pixels")
    })?;
    out.resize(floats, 0.0f32);
    let stats = trace_span_into(scene, settings, start, &mut out)?;
    Ok((out, stats))
}

/// [`trace_span`] into a buffer the caller owns: `out.len() / 3` pixels from `start`, each
/// written once, in place. The NIF traces straight into the binary it returns.
///
/// ```
/// use ring_tracer_kernel::{trace_span, trace_span_into, Format, Scene, Settings};
/// let nff = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 4 4\n\
///            l 0 5 5\nf 1 0 0 1 0 0 0 0\ns 0 0 0 1\n";
/// let no_files = |_: &str| Err("no files".into());
/// let scene = Scene::parse(nff.as_bytes(), Format::Nff, "doc.nff", &no_files).unwrap();
/// let settings = Settings::for_scene(&scene);
/// let mut out = vec![0.0; 5 * 3];
/// let stats = trace_span_into(&scene, &settings, 6, &mut out).unwrap();
/// assert_eq!((out, stats), trace_span(&scene, &settings, 6, 5).unwrap());
/// assert!(trace_span_into(&scene, &settings, 0, &mut [0.0; 4]).is_err());
/// ```
pub fn trace_span_into(
    scene: &Scene,
    settings: &Settings,
    start: u64,
    out: &mut [f32],
) -> Result<RayStats, Error> {
    if !out.len().is_multiple_of(3) {
        return Err(Error::InvalidArgument(format!(
            "a pixel buffer holds 3 floats a pixel, got {} floats",
            out.len()
        )));
    }
    let count = (out.len() / 3) as u64;
    let end = settings.span_end(start, count)?;
    if let Some(r) = settings.region {
        return trace_region_into(scene, settings, r, start, end, out);
    }
    let mut stats = RayStats::default();
    if count == 0 {
        return Ok(stats);
    }
    let integ = settings.integrator();
    let mut scratch = Scratch::new();
    let mut pixels = out.chunks_exact_mut(3);
    let mut put = |c: Vec3A| {
        if let Some(p) = pixels.next() {
            p.copy_from_slice(&[c.x, c.y, c.z]);
        }
    };
    if settings.spd {
        spd_span(
            scene,
            settings,
            &integ,
            start,
            end,
            &mut scratch,
            &mut put,
            &mut stats,
        );
    } else if settings.samples == 1 {
        let (w, h) = (settings.width, settings.height);
        primary_tiles(
            scene,
            &integ,
            (w, h),
            (start, end),
            &mut scratch,
            &mut put,
            &mut stats,
        );
    } else {
        stratified_span(
            scene,
            settings,
            &integ,
            (start, end),
            &mut scratch,
            &mut put,
            &mut stats,
        );
    }
    if scene.display_referred() {
        crate::film::decode_srgb_in_place(out);
    }
    stats.work = scratch.work + stats.total();
    Ok(stats)
}

/// `settings.samples` squared samples per pixel over the span `start..end`: each pixel's
/// stratified jittered samples traced ray by ray, their mean put in row order. Inlined: a
/// function of its own, its loop took 2.7% more instructions (callgrind).
#[inline(always)]
fn stratified_span(
    scene: &Scene,
    settings: &Settings,
    integ: &Whitted,
    (start, end): (u64, u64),
    scratch: &mut Scratch,
    put: &mut impl FnMut(Vec3A),
    stats: &mut RayStats,
) {
    let (w, h) = (settings.width, settings.height);
    let span = Camera::centre_span(w, h);
    let s = settings.samples;
    let inv = 1.0 / (s * s) as f32;
    let (mut px_x, mut px_y) = (start % w as u64, start / w as u64);
    for idx in start..end {
        let x = px_x as f32;
        let y = px_y as f32;
        px_x += 1;
        if px_x == w as u64 {
            px_x = 0;
            px_y += 1;
        }
        let mut acc = Vec3A::ZERO;
        for j in 0..s {
            for i in 0..s {
                let k = (j * s + i) as u64;
                let (jx, jy) = jitter(idx, k);
                let px = x + (i as f32 + jx) / s as f32;
                let py = y + (j as f32 + jy) / s as f32;
                let ray = scene.camera.ray(px, py, w, h, span);
                acc += integ.radiance(scene, &ray, scratch, stats);
            }
        }
        put(acc * inv);
    }
}

/// The side of the pixel tiles whose eye rays [`primary_tiles`] traces as one packet.
const TILE: u64 = 4;

/// One sample per pixel through the pixel centres of the span `start..end` of a `w` x `h`
/// image: the eye rays in 4 x 4 pixel tiles aligned to the image grid (partial where the span
/// cuts a tile), each tile's closest hits found as one packet ([`Scene::intersect_packet`], the
/// same hits as ray by ray), then shaded ray by ray; the pixels are put in row order.
fn primary_tiles(
    scene: &Scene,
    integ: &Whitted,
    (w, h): (u32, u32),
    (start, end): (u64, u64),
    scratch: &mut Scratch,
    put: &mut impl FnMut(Vec3A),
    stats: &mut RayStats,
) {
    let span = Camera::centre_span(w, h);
    let (w64, h64) = (w as u64, h as u64);
    let mut band: Vec<Vec3A> = Vec::new();
    let mut rays = Vec::with_capacity((TILE * TILE) as usize);
    let mut at = Vec::with_capacity((TILE * TILE) as usize);
    let mut hits = [None; (TILE * TILE) as usize];
    let mut by = (start / w64) / TILE * TILE;
    while by * w64 < end {
        // the span's pixels in rows by..by + TILE
        let (lo, hi) = ((by * w64).max(start), ((by + TILE) * w64).min(end));
        band.clear();
        band.resize((hi - lo) as usize, Vec3A::ZERO);
        for tx in (0..w64).step_by(TILE as usize) {
            rays.clear();
            at.clear();
            for y in by..(by + TILE).min(h64) {
                for x in tx..(tx + TILE).min(w64) {
                    let idx = y * w64 + x;
                    if (lo..hi).contains(&idx) {
                        let (fx, fy) = (x as f32, y as f32);
                        rays.push(scene.camera.ray(fx + 0.5, fy + 0.5, w, h, span));
                        at.push((idx - lo) as usize);
                    }
                }
            }
            scene.intersect_tile(&rays, scratch, &mut hits);
            for ((ray, &i), hit) in rays.iter().zip(&at).zip(hits) {
                if let Some(px) = band.get_mut(i) {
                    *px = integ.radiance_of_hit(scene, ray, hit, scratch, stats);
                }
            }
        }
        band.iter().for_each(|&c| put(c));
        by += TILE;
    }
}

/// A span of a region: each run of it within one row of the region is the span of the whole
/// image that holds those pixels, traced as such, so a region gives exactly the whole render's
/// pixels (samples, SPD corners and all).
fn trace_region_into(
    scene: &Scene,
    settings: &Settings,
    r: Region,
    start: u64,
    end: u64,
    out: &mut [f32],
) -> Result<RayStats, Error> {
    let whole = Settings {
        region: None,
        ..settings.clone()
    };
    let (rw, w) = (r.width as u64, settings.width as u64);
    let mut stats = RayStats::default();
    let mut p = start;
    while p < end {
        let (row, col) = (p / rw, p % rw);
        let run = (rw - col).min(end - p);
        let from = (r.y0 as u64 + row) * w + r.x0 as u64 + col;
        let at = ((p - start) * 3) as usize;
        let part = trace_span_into(scene, &whole, from, &mut out[at..at + run as usize * 3])?;
        stats += part;
        p += run;
    }
    Ok(stats)
}

/// SPD corner mode: each needed corner traced once per span; a corner's rays counted only in the
/// span owning it (owner of corner (cx, cy) = pixel (min(cx, W-1), min(cy, H-1))).
#[allow(clippy::too_many_arguments)]
fn spd_span(
    scene: &Scene,
    settings: &Settings,
    integ: &Whitted,
    start: u64,
    end: u64,
    scratch: &mut Scratch,
    put: &mut impl FnMut(Vec3A),
    stats: &mut RayStats,
) {
    let (w, h) = (settings.width, settings.height);
    let w64 = w as u64;
    let span = Camera::corner_span(w, h);
    let cols = w as usize + 1;
    let y0 = start / w64;
    let y1 = (end - 1) / w64;
    // columns of pixel row y inside the span
    let row_range = |y: u64| -> Option<(u64, u64)> {
        if y < y0 || y > y1 {
            return None;
        }
        let a = if y == y0 { start % w64 } else { 0 };
        let b = if y == y1 { (end - 1) % w64 } else { w64 - 1 };
        Some((a, b))
    };
    let mut top: Vec<Option<Vec3A>> = vec![None; cols];
    let mut bottom: Vec<Option<Vec3A>> = vec![None; cols];
    let fill = |row: &mut Vec<Option<Vec3A>>,
                cy: u64,
                a: u64,
                b: u64,
                scratch: &mut Scratch,
                stats: &mut RayStats| {
        // the corners still missing, sixteen eye rays to a packet (the same hits as one by one)
        let todo: Vec<u64> = (a..=b + 1)
            .filter(|&cx| matches!(row.get(cx as usize), Some(None)))
            .collect();
        for part in todo.chunks(16) {
            let rays: Vec<Ray> = part
                .iter()
                .map(|&cx| scene.camera.ray(cx as f32, cy as f32, w, h, span))
                .collect();
            let mut hits = [None; 16];
            scene.intersect_tile(&rays, scratch, &mut hits);
            for ((&cx, ray), hit) in part.iter().zip(&rays).zip(hits) {
                let owner = cy.min(h as u64 - 1) * w64 + cx.min(w64 - 1);
                let c = if owner >= start && owner < end {
                    integ.radiance_of_hit(scene, ray, hit, scratch, stats)
                } else {
                    // another span's corner: its rays are counted there, but the work is done here
                    let mut scratch_stats = RayStats::default();
                    let c = integ.radiance_of_hit(scene, ray, hit, scratch, &mut scratch_stats);
                    scratch.work += scratch_stats.total();
                    c
                };
                if let Some(slot) = row.get_mut(cx as usize) {
                    *slot = Some(c);
                }
            }
        }
    };
    for y in y0..=y1 {
        let Some((a, b)) = row_range(y) else { continue };
        // corners of row y (top) are shared with pixel row y-1, which already filled them
        fill(&mut top, y, a, b, scratch, stats);
        fill(&mut bottom, y + 1, a, b, scratch, stats);
        for x in a..=b {
            let x = x as usize;
            let get = |r: &Vec<Option<Vec3A>>, i: usize| {
                r.get(i).copied().flatten().unwrap_or(Vec3A::ZERO)
            };
            let c =
                (get(&top, x) + get(&top, x + 1) + get(&bottom, x) + get(&bottom, x + 1)) * 0.25;
            put(c);
        }
        std::mem::swap(&mut top, &mut bottom);
        bottom.iter_mut().for_each(|s| *s = None);
    }
}

/// The work units ([`RayStats::work`]) of each row of the image `settings` describes, top row
/// first. Traced small, it is a preview of where an image's work lies: the ring's children use
/// it to guess how much work a sibling they have not heard from yet still holds.
pub fn work_by_row(scene: &Scene, settings: &Settings) -> Result<Vec<u64>, Error> {
    settings.validate()?;
    let (w, h) = settings.traced_size();
    let w = w as u64;
    (0..h as u64)
        .map(|y| trace_span(scene, settings, y * w, w).map(|(_, stats)| stats.work))
        .collect()
}

/// Whole image with `threads` OS threads (rows handed out in chunks, in order, as threads ask).
/// Identical bits to [`trace_span`] over all pixels.
pub fn render_image(
    scene: &Scene,
    settings: &Settings,
    threads: usize,
) -> Result<(Vec<f32>, RayStats), Error> {
    settings.validate()?;
    let (w, h) = settings.traced_size();
    let floats = w as usize * h as usize * 3;
    let mut image =
        crate::memory::try_with_capacity(floats, || format!("the pixels of a {w}x{h} image"))?;
    image.resize(floats, 0.0f32);
    let stats = render_image_into(scene, settings, threads, &mut image)?;
    Ok((image, stats))
}

/// [`render_image`] into a buffer the caller owns, of exactly 3 floats a pixel of the traced
/// size; each chunk of rows is traced straight into its part of it. The NIF traces into the
/// binary it returns.
///
/// ```
/// use ring_tracer_kernel::{render_image, render_image_into, Format, Scene, Settings};
/// let nff = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 4 4\n\
///            l 0 5 5\nf 1 0 0 1 0 0 0 0\ns 0 0 0 1\n";
/// let no_files = |_: &str| Err("no files".into());
/// let scene = Scene::parse(nff.as_bytes(), Format::Nff, "doc.nff", &no_files).unwrap();
/// let settings = Settings::for_scene(&scene);
/// let mut out = vec![0.0; 16 * 3];
/// let stats = render_image_into(&scene, &settings, 2, &mut out).unwrap();
/// assert_eq!((out, stats), render_image(&scene, &settings, 1).unwrap());
/// assert!(render_image_into(&scene, &settings, 2, &mut [0.0; 15 * 3]).is_err());
/// ```
pub fn render_image_into(
    scene: &Scene,
    settings: &Settings,
    threads: usize,
    out: &mut [f32],
) -> Result<RayStats, Error> {
    settings.validate()?;
    let (w, h) = settings.traced_size();
    let (w, h) = (w as u64, h as u64);
    if out.len() as u64 != w * h * 3 {
        return Err(Error::InvalidArgument(format!(
            "a {w}x{h} image needs {} floats, got {}",
            w * h * 3,
            out.len()
        )));
    }
    let threads = threads.clamp(1, 256);
    // SPD mode re-traces one corner row per chunk, so use taller chunks there; otherwise a
    // chunk is one band of primary_tiles' 4 x 4 tiles, so that no chunk cuts a packet in half
    let rows_per_chunk = if settings.spd { 16 } else { TILE }.min(h.max(1));
    let chunk_len = (rows_per_chunk * w * 3) as usize;
    // (chunk index, its pixels), taken in order by whichever thread asks next
    let chunks = Mutex::new(out.chunks_mut(chunk_len.max(1)).enumerate());
    let work = || -> Result<RayStats, Error> {
        let mut stats = RayStats::default();
        loop {
            let next = chunks.lock().map_err(|_| poisoned())?.next();
            let Some((c, px)) = next else {
                return Ok(stats);
            };
            let start = c as u64 * rows_per_chunk * w;
            stats += trace_span_into(scene, settings, start, px)?;
        }
    };
    let results: Vec<Result<RayStats, Error>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads).map(|_| s.spawn(work)).collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|_| Err(poisoned())))
            .collect()
    });
    let mut stats = RayStats::default();
    for r in results {
        stats += r?;
    }
    Ok(stats)
}

fn poisoned() -> Error {
    Error::InvalidArgument("a render thread panicked".into())
}
