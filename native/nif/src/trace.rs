//! Tracing: one atom (a span of pixels) for a grandchild, or a whole image
//! with the kernel's own threads for benchmarks and references.

use ring_tracer_kernel::{
    render_image as kernel_render_image, render_image_into, trace_span, trace_span_into,
    work_by_row,
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
