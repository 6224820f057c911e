//! Atoms' pixels on the wire (`RingTracer.Pixels`) and plain zstd frames
//! (`RingTracer.Codec`): `ring_tracer_wire`'s functions.
//!
//! The pixels' functions come in two NIFs each, one on a normal scheduler and one on a dirty
//! CPU scheduler: the caller takes the dirty one for inputs that would hold a normal
//! scheduler too long (`RingTracer.Pixels`), the normal one for the many small atoms, which
//! would pay more for the switch to a dirty scheduler than for the work.

use ring_tracer_wire::{frames, pixels, Format};
use rustler::{Atom, Binary, Env, OwnedBinary};

use crate::convert::binary_to_floats;

mod names {
    rustler::atoms! { float, srgb8 }
}

fn format(a: Atom) -> Result<Format, String> {
    if a == names::float() {
        Ok(Format::Float)
    } else if a == names::srgb8() {
        Ok(Format::Srgb8)
    } else {
        Err("unknown pixel format; expected :float or :srgb8".into())
    }
}

fn release<'a>(env: Env<'a>, bytes: &[u8]) -> Binary<'a> {
    OwnedBinary::from_slice(bytes).release(env)
}

fn encode<'a>(env: Env<'a>, bin: Binary<'a>, fmt: Atom) -> Result<Binary<'a>, String> {
    let rgb = binary_to_floats(&bin)?;
    let wire = pixels::encode(bin.as_slice(), &rgb, format(fmt)?).map_err(|e| e.to_string())?;
    Ok(release(env, &wire))
}

fn tint<'a>(env: Env<'a>, bin: Binary<'a>, colour: (f64, f64, f64)) -> Result<Binary<'a>, String> {
    let rgb = binary_to_floats(&bin)?;
    let wire = pixels::encode_tinted(&rgb, colour).map_err(|e| e.to_string())?;
    Ok(release(env, &wire))
}

fn decode<'a>(env: Env<'a>, wire: Binary<'a>, fmt: Atom, count: u64) -> Result<Binary<'a>, String> {
    let count = usize::try_from(count).map_err(|_| "too many pixels".to_string())?;
    let bytes = pixels::decode(wire.as_slice(), format(fmt)?, count).map_err(|e| e.to_string())?;
    Ok(release(env, &bytes))
}

/// Linear f32 RGB `pixels` on the wire in `format` (`:float` or `:srgb8`).
#[rustler::nif]
fn pixels_encode<'a>(env: Env<'a>, pixels: Binary<'a>, format: Atom) -> Result<Binary<'a>, String> {
    encode(env, pixels, format)
}

/// `pixels_encode` on a dirty CPU scheduler.
#[rustler::nif(schedule = "DirtyCpu")]
fn pixels_encode_dirty<'a>(
    env: Env<'a>,
    pixels: Binary<'a>,
    format: Atom,
) -> Result<Binary<'a>, String> {
    encode(env, pixels, format)
}

/// Linear f32 RGB `pixels` mixed with `colour` (linear) as the ownership map does, on the
/// wire as `:srgb8`.
#[rustler::nif]
fn pixels_tint<'a>(
    env: Env<'a>,
    pixels: Binary<'a>,
    colour: (f64, f64, f64),
) -> Result<Binary<'a>, String> {
    tint(env, pixels, colour)
}

/// `pixels_tint` on a dirty CPU scheduler.
#[rustler::nif(schedule = "DirtyCpu")]
fn pixels_tint_dirty<'a>(
    env: Env<'a>,
    pixels: Binary<'a>,
    colour: (f64, f64, f64),
) -> Result<Binary<'a>, String> {
    tint(env, pixels, colour)
}

/// The `count` pixels in `format` that `wire` holds.
#[rustler::nif]
fn pixels_decode<'a>(
    env: Env<'a>,
    wire: Binary<'a>,
    format: Atom,
    count: u64,
) -> Result<Binary<'a>, String> {
    decode(env, wire, format, count)
}

/// `pixels_decode` on a dirty CPU scheduler.
#[rustler::nif(schedule = "DirtyCpu")]
fn pixels_decode_dirty<'a>(
    env: Env<'a>,
    wire: Binary<'a>,
    format: Atom,
    count: u64,
) -> Result<Binary<'a>, String> {
    decode(env, wire, format, count)
}

/// `bytes` as a zstd frame. On a dirty scheduler: it is for large things (scenes).
#[rustler::nif(schedule = "DirtyCpu")]
fn zstd_compress<'a>(env: Env<'a>, bytes: Binary<'a>) -> Result<Binary<'a>, String> {
    let z = frames::compress(bytes.as_slice()).map_err(|e| e.to_string())?;
    Ok(release(env, &z))
}

/// The bytes of zstd frames, at most `max_bytes` of them.
#[rustler::nif(schedule = "DirtyCpu")]
fn zstd_decompress<'a>(
    env: Env<'a>,
    frames: Binary<'a>,
    max_bytes: u64,
) -> Result<Binary<'a>, String> {
    let bytes = frames::decompress(frames.as_slice(), max_bytes).map_err(|e| e.to_string())?;
    Ok(release(env, &bytes))
}
