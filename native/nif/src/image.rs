//! Image files and encodings.

use std::path::Path;

use ring_tracer_kernel::{
    encode_png as kernel_encode_png, encode_png8 as kernel_encode_png8, safe_fs, to_srgb8,
    write_image_in as kernel_write_in, write_image_mode as kernel_write,
    write_png8_in as kernel_write_png8_in,
};
use rustler::{Atom, Binary, Env, OwnedBinary, ResourceArc};

use crate::fs::DirResource;

use crate::convert::{binary_to_floats, message, mode_arg};

rustler::atoms! { ok }

fn check_size(width: u32, height: u32, rgb: &[f32]) -> Result<(), String> {
    let expected = width as u64 * height as u64 * 3;
    if rgb.len() as u64 != expected {
        return Err(format!(
            "image of {width}x{height} needs {expected} floats, got {}",
            rgb.len()
        ));
    }
    Ok(())
}

/// Writes linear RGB pixels to `path`; the extension picks the format. `mode`: the permissions
/// of a new file, or a negative number for the umask's.
#[rustler::nif(schedule = "DirtyIo")]
fn write_image(
    path: String,
    width: u32,
    height: u32,
    pixels: Binary,
    mode: i64,
) -> Result<Atom, String> {
    let rgb = binary_to_floats(&pixels)?;
    check_size(width, height, &rgb)?;
    kernel_write(Path::new(&path), width, height, &rgb, mode_arg(mode)).map_err(message)?;
    Ok(ok())
}

/// `write_image` into a folder held open (`fs_open_dir`), as `name` there.
#[rustler::nif(schedule = "DirtyIo")]
fn write_image_in(
    dir: ResourceArc<DirResource>,
    name: String,
    width: u32,
    height: u32,
    pixels: Binary,
    mode: i64,
) -> Result<Atom, String> {
    let rgb = binary_to_floats(&pixels)?;
    check_size(width, height, &rgb)?;
    kernel_write_in(&dir.dir, &name, width, height, &rgb, mode_arg(mode)).map_err(message)?;
    Ok(ok())
}

/// Writes 8-bit sRGB pixels (3 bytes a pixel) to `path`, a `.png`: the file `write_image`
/// makes of the floats they came from.
#[rustler::nif(schedule = "DirtyIo")]
fn write_png8(
    path: String,
    width: u32,
    height: u32,
    pixels: Binary,
    mode: i64,
) -> Result<Atom, String> {
    let (dir, name) = safe_fs::open_parent(Path::new(&path)).map_err(message)?;
    kernel_write_png8_in(
        &dir,
        &name,
        width,
        height,
        pixels.as_slice(),
        mode_arg(mode),
    )
    .map_err(message)?;
    Ok(ok())
}

/// `write_png8` into a folder held open (`fs_open_dir`), as `name` there.
#[rustler::nif(schedule = "DirtyIo")]
fn write_png8_in(
    dir: ResourceArc<DirResource>,
    name: String,
    width: u32,
    height: u32,
    pixels: Binary,
    mode: i64,
) -> Result<Atom, String> {
    kernel_write_png8_in(
        &dir.dir,
        &name,
        width,
        height,
        pixels.as_slice(),
        mode_arg(mode),
    )
    .map_err(message)?;
    Ok(ok())
}

/// Encodes 8-bit sRGB pixels (3 bytes a pixel) as a PNG in memory: `encode_png`'s bytes of
/// the floats they came from.
#[rustler::nif(schedule = "DirtyCpu")]
fn encode_png8<'a>(
    env: Env<'a>,
    width: u32,
    height: u32,
    pixels: Binary<'a>,
) -> Result<Binary<'a>, String> {
    let png = kernel_encode_png8(width, height, pixels.as_slice()).map_err(message)?;
    Ok(OwnedBinary::from_slice(&png).release(env))
}

/// Encodes linear RGB pixels as an 8-bit sRGB PNG in memory.
#[rustler::nif(schedule = "DirtyCpu")]
fn encode_png<'a>(
    env: Env<'a>,
    width: u32,
    height: u32,
    pixels: Binary<'a>,
) -> Result<Binary<'a>, String> {
    let rgb = binary_to_floats(&pixels)?;
    check_size(width, height, &rgb)?;
    let png = kernel_encode_png(width, height, &rgb).map_err(message)?;
    Ok(OwnedBinary::from_slice(&png).release(env))
}

/// Linear RGB floats to 8-bit sRGB bytes (3 a pixel).
#[rustler::nif(schedule = "DirtyCpu")]
fn to_srgb8_binary<'a>(env: Env<'a>, pixels: Binary<'a>) -> Result<Binary<'a>, String> {
    let rgb = binary_to_floats(&pixels)?;
    Ok(OwnedBinary::from_slice(&to_srgb8(&rgb)).release(env))
}

/// The most pixels `to_srgb8_base64` takes in one call: about a tenth of a millisecond of work,
/// short enough for a normal scheduler.
const BASE64_PIECE_PIXELS: usize = 4096;

/// 8-bit sRGB bytes (at most 4096 pixels) as base64 text: `to_srgb8_base64` of pixels already
/// 8-bit.
#[rustler::nif]
fn srgb8_base64<'a>(env: Env<'a>, pixels: Binary<'a>) -> Result<Binary<'a>, String> {
    if pixels.len() > 3 * BASE64_PIECE_PIXELS {
        return Err(format!(
            "at most {BASE64_PIECE_PIXELS} pixels a call, got {}",
            pixels.len() / 3
        ));
    }
    Ok(OwnedBinary::from_slice(&base64(pixels.as_slice())).release(env))
}

/// Linear RGB floats (at most 4096 pixels) to 8-bit sRGB bytes (3 a pixel), as base64 text
/// (standard alphabet, padded): the preview's encoding of an atom's pixels, piece by piece. On a
/// normal scheduler, so that the preview never takes a dirty one from the job's atoms; a piece
/// of a multiple of 4 pixels is a multiple of 3 bytes, so pieces' texts concatenate.
#[rustler::nif]
fn to_srgb8_base64<'a>(env: Env<'a>, pixels: Binary<'a>) -> Result<Binary<'a>, String> {
    let rgb = binary_to_floats(&pixels)?;
    if rgb.len() > 3 * BASE64_PIECE_PIXELS {
        return Err(format!(
            "at most {BASE64_PIECE_PIXELS} pixels a call, got {}",
            rgb.len() / 3
        ));
    }
    Ok(OwnedBinary::from_slice(&base64(&to_srgb8(&rgb))).release(env))
}

fn base64(bytes: &[u8]) -> Vec<u8> {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = Vec::with_capacity(bytes.len().div_ceil(3) * 4);
    for group in bytes.chunks(3) {
        let b = [
            group[0],
            *group.get(1).unwrap_or(&0),
            *group.get(2).unwrap_or(&0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        out.push(ALPHABET[(n >> 18) as usize & 63]);
        out.push(ALPHABET[(n >> 12) as usize & 63]);
        out.push(if group.len() > 1 {
            ALPHABET[(n >> 6) as usize & 63]
        } else {
            b'='
        });
        out.push(if group.len() > 2 {
            ALPHABET[n as usize & 63]
        } else {
            b'='
        });
    }
    out
}
