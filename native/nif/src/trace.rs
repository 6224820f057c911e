//! Tracing: one atom (a span of pixels) for a grandchild, or a whole image
//! with the kernel's own threads for benchmarks and references.

use ring_tracer_kernel::{
    render_image as kernel_render_image, render_image_into, trace_span, trace_span_into,
    work_by_row, RayStats,
};
use std::time::Instant;

use rustler::{Binary, Env, OwnedBinary, ResourceArc};

use crate::convert::{copy_floats, floats_to_binary, message, RayStatsTerm, SettingsTerm};
use crate::scene::SceneResource;

/// Traces `count` pixels from linear index `start`: linear RGB as f32
/// binary, the ray counters, and the microseconds spent tracing (measured
/// here, so time spent waiting for a dirty scheduler is not counted).
///
/// The pixels are traced straight into the binary returned. Tracing into a
/// vector and copying it into a binary cost 51 µs (allocation and copy) and
/// 27 µs (freeing the vector) a 16,384-pixel atom, on a dirty scheduler but
/// outside the measured time.
#[rustler::nif(schedule = "DirtyCpu")]
fn trace_atom<'a>(
    env: Env<'a>,
    scene: ResourceArc<SceneResource>,
    settings: SettingsTerm,
    start: u64,
    count: u64,
) -> Result<(Binary<'a>, RayStatsTerm, u64), String> {
    let settings = settings.to_kernel()?;
    // checked before allocating the binary
    settings.span_end(start, count).map_err(message)?;
    let mut bin = OwnedBinary::new(count as usize * 12);
    let t0 = Instant::now();
    let stats = match bytemuck::try_cast_slice_mut::<u8, f32>(bin.as_mut_slice()) {
        Ok(out) => trace_span_into(&scene.scene, &settings, start, out),
        // Not aligned for f32 (the runtime does not promise it): through a vector.
        Err(_) => trace_span(&scene.scene, &settings, start, count).map(|(rgb, stats)| {
            copy_floats(bin.as_mut_slice(), &rgb);
            stats
        }),
    }
    .map_err(message)?;
    let micros = t0.elapsed().as_micros() as u64;
    Ok((bin.release(env), stats.into(), micros))
}

/// Pixels traced at a time by [`trace_atom_short`], between two looks at the clock.
const SHORT_CHUNK: u64 = 8;

/// Traces up to `count` pixels from `start` on a normal scheduler, in chunks of
/// [`SHORT_CHUNK`] pixels, and stops after the chunk that takes it past `budget_us`
/// microseconds: the pixels traced (a prefix of the span), the ray counters, the
/// microseconds spent and how many pixels that is.
///
/// A dirty call costs two scheduler switches, tens of microseconds on a busy
/// machine, more than a few cheap pixels take to trace; a short atom is traced
/// here instead, and what the budget leaves goes to [`trace_atom`]. Any split of
/// a span gives the same bits (the kernel's pixels are independent), and the
/// budget keeps this call within the time a normal scheduler may be held.
#[rustler::nif]
fn trace_atom_short<'a>(
    env: Env<'a>,
    scene: ResourceArc<SceneResource>,
    settings: SettingsTerm,
    start: u64,
    count: u64,
    budget_us: u64,
) -> Result<(Binary<'a>, RayStatsTerm, u64, u64), String> {
    let settings = settings.to_kernel()?;
    // checked before allocating the binary
    settings.span_end(start, count).map_err(message)?;
    let mut bin = OwnedBinary::new(count as usize * 12);
    let t0 = Instant::now();
    let mut stats = RayStats::default();
    let mut done = 0u64;
    // at least one chunk, so that every call makes progress
    while done < count && (done == 0 || (t0.elapsed().as_micros() as u64) < budget_us) {
        let n = SHORT_CHUNK.min(count - done);
        let bytes = &mut bin.as_mut_slice()[done as usize * 12..(done + n) as usize * 12];
        let chunk = match bytemuck::try_cast_slice_mut::<u8, f32>(bytes) {
            Ok(out) => trace_span_into(&scene.scene, &settings, start + done, out),
            Err(_) => trace_span(&scene.scene, &settings, start + done, n).map(|(rgb, s)| {
                copy_floats(bytes, &rgb);
                s
            }),
        }
        .map_err(message)?;
        stats += chunk;
        done += n;
    }
    let micros = t0.elapsed().as_micros() as u64;
    // what a normal scheduler's time slice (about a millisecond) this took
    let percent = (micros / 10).clamp(1, 100) as i32;
    rustler::schedule::consume_timeslice(env, percent);
    let bin = bin.release(env);
    let prefix = bin
        .make_subbinary(0, done as usize * 12)
        .map_err(|_| "the traced pixels outgrew their binary".to_string())?;
    Ok((prefix, stats.into(), micros, done))
}

/// The kernel work units of each row of the (small) image `settings` describes: a preview of
/// where the work lies, traced in one call.
#[rustler::nif(schedule = "DirtyCpu")]
fn row_work(scene: ResourceArc<SceneResource>, settings: SettingsTerm) -> Result<Vec<u64>, String> {
    let settings = settings.to_kernel()?;
    work_by_row(&scene.scene, &settings).map_err(message)
}

/// Traces the whole image with `threads` OS threads inside this one NIF call.
#[rustler::nif(schedule = "DirtyCpu")]
fn render_image<'a>(
    env: Env<'a>,
    scene: ResourceArc<SceneResource>,
    settings: SettingsTerm,
    threads: u32,
) -> Result<(Binary<'a>, RayStatsTerm), String> {
    let settings = settings.to_kernel()?;
    // checked before allocating the binary
    settings.validate().map_err(message)?;
    let (w, h) = settings.traced_size();
    let threads = threads.max(1) as usize;
    let mut bin = OwnedBinary::new(w as usize * h as usize * 12);
    // traced straight into the binary, as trace_atom does
    let stats = match bytemuck::try_cast_slice_mut::<u8, f32>(bin.as_mut_slice()) {
        Ok(out) => render_image_into(&scene.scene, &settings, threads, out).map_err(message)?,
        Err(_) => {
            let (rgb, stats) =
                kernel_render_image(&scene.scene, &settings, threads).map_err(message)?;
            return Ok((floats_to_binary(env, &rgb)?, stats.into()));
        }
    };
    Ok((bin.release(env), stats.into()))
}

/// Checks settings against the kernel's limits before a job starts.
#[rustler::nif]
fn validate_settings(settings: SettingsTerm) -> Result<bool, String> {
    settings.to_kernel().map(|_| true)
}
