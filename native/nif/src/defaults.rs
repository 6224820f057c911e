//! What the Elixir side learns from the kernel when it compiles, so that it writes none of it
//! down again: the settings' defaults, the limits a render's options are checked against, and
//! the ray counters' names.

use ring_tracer_kernel::{limits, RayStats, Settings};
use rustler::{Atom, Env, NifMap};

use crate::convert::{atom, RayStatsTerm};

/// The defaults of the settings a caller may leave out ([`Settings::new`]).
#[derive(NifMap)]
struct SettingsDefaults {
    depth: u32,
    cutoff: f64,
    samples: u32,
    spd: bool,
}

/// `%{depth: _, cutoff: _, samples: _, spd: _}`: the kernel's defaults. The cut-off is the
/// kernel's `f32` widened to a float, so it is passed back to the kernel unchanged.
#[rustler::nif]
fn settings_defaults() -> SettingsDefaults {
    let s = Settings::new(1, 1);
    SettingsDefaults {
        depth: s.depth,
        cutoff: f64::from(s.cutoff),
        samples: s.samples,
        spd: s.spd,
    }
}

/// The kernel's limits on a render's settings ([`limits`]).
#[derive(NifMap)]
struct SettingsLimits {
    max_side: u32,
    max_pixels: u64,
    max_samples: u32,
    max_depth: u32,
    max_frames: u32,
}

/// `%{max_side: _, max_pixels: _, max_samples: _, max_depth: _, max_frames: _}`: the bounds the
/// kernel checks a render's settings and an animation against.
#[rustler::nif]
fn settings_limits() -> SettingsLimits {
    SettingsLimits {
        max_side: limits::MAX_SIDE,
        max_pixels: limits::MAX_PIXELS,
        max_samples: limits::MAX_SAMPLES,
        max_depth: limits::MAX_DEPTH,
        max_frames: limits::MAX_FRAMES,
    }
}

/// `{zeroed_counters, ray_kinds}`: every counter at 0 under its name, and the names of those
/// that count rays (their sum is all rays traced).
#[rustler::nif]
fn ray_counters(env: Env) -> (RayStatsTerm, Vec<Atom>) {
    let zero = RayStats::default();
    let kinds = zero
        .counters()
        .iter()
        .filter(|c| c.ray)
        .map(|c| atom(env, c.name))
        .collect();
    (RayStatsTerm(zero), kinds)
}
