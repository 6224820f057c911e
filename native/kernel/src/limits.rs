//! Documented upper bounds, all checked before anything is allocated.
//!
//! Every bound is a `pub const`; an [`Error::Limit`] names the quantity, the
//! requested value, the bound and how to raise it (change the constant here and rebuild).

use crate::Error;

/// Largest image side in pixels.
pub const MAX_SIDE: u32 = 16_384;
/// Largest image area in pixels (64 Mpixel).
pub const MAX_PIXELS: u64 = 64 * 1024 * 1024;
/// Largest `samples` value (S, giving SxS samples per pixel).
pub const MAX_SAMPLES: u32 = 16;
/// Largest ray-tree depth (the eye ray is depth 1).
pub const MAX_DEPTH: u32 = 64;
/// Largest number of primitives in a scene (after meshes are expanded to triangles).
pub const MAX_PRIMITIVES: usize = 50_000_000;
/// Largest scene or mesh file in bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 30;
/// Largest vertex count of one polygon or patch.
pub const MAX_POLYGON_VERTICES: usize = 1 << 20;
/// Largest number of triangles in one mesh file.
pub const MAX_MESH_TRIANGLES: usize = 20_000_000;
/// Largest number of lights.
pub const MAX_LIGHTS: usize = 65_536;

const HINT: &str = "raise the constant in native/kernel/src/limits.rs";

pub(crate) fn check(what: &'static str, value: u64, max: u64) -> Result<(), Error> {
    if value > max {
        Err(Error::Limit {
            what,
            value,
            max,
            hint: HINT,
        })
    } else {
        Ok(())
    }
}

/// Checks an image resolution against [`MAX_SIDE`] and [`MAX_PIXELS`]; zero sides are rejected too.
pub fn check_resolution(width: u32, height: u32) -> Result<(), Error> {
    if width == 0 || height == 0 {
        return Err(Error::InvalidArgument(format!(
            "resolution {width}x{height} has a zero side"
        )));
    }
    check("image width", width as u64, MAX_SIDE as u64)?;
    check("image height", height as u64, MAX_SIDE as u64)?;
    check(
        "image pixel count",
        width as u64 * height as u64,
        MAX_PIXELS,
    )
}
