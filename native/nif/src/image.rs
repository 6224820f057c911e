//! Image files and encodings.

use std::path::Path;

use ring_tracer_kernel::{encode_png as kernel_encode_png, to_srgb8, write_image as kernel_write};
use rustler::{Atom, Binary, Env, OwnedBinary};

use crate::convert::{binary_to_floats, message};

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

/// Writes linear RGB pixels to `path`; the extension picks the format.
#[rustler::nif(schedule = "DirtyIo")]
fn write_image(path: String, width: u32, height: u32, pixels: Binary) -> Result<Atom, String> {
    let rgb = binary_to_floats(&pixels)?;
    check_size(width, height, &rgb)?;
    kernel_write(Path::new(&path), width, height, &rgb).map_err(message)?;
    Ok(ok())
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
