//! Documented upper bounds, all checked before anything is allocated.
//!
//! | constant | value | bounds | checked |
//! |---|---|---|---|
//! | [`MAX_SIDE`] | 16 384 | image width and height | settings, NFF `resolution`, TOML `camera` |
//! | [`MAX_PIXELS`] | 67 108 864 (64 Mpixel) | width x height | same, before any pixel buffer exists |
//! | [`MAX_SAMPLES`] | 16 | S of the SxS samples per pixel | [`crate::Settings::validate`] |
//! | [`MAX_DEPTH`] | 64 | ray-tree depth | [`crate::Settings::validate`] |
//! | [`MAX_PRIMITIVES`] | 50 000 000 | primitives stored: internal primitives plus each shared mesh's triangles once | before each primitive is added |
//! | [`MAX_FILE_BYTES`] | 1 GiB | scene file and each referenced mesh/MTL file | before reading / parsing |
//! | [`MAX_POLYGON_VERTICES`] | 1 048 576 | vertices of one polygon or patch | NFF: before reading the vertices |
//! | [`MAX_MESH_TRIANGLES`] | 20 000 000 | triangles of one mesh file | by a scan of the `f` lines before the OBJ reader runs, and again after |
//! | [`MAX_MESH_REFERENCES`] | 1 000 000 | mesh references (`type = "mesh"` objects) of a TOML scene, so also its mesh instances | by a count of the references before any mesh is read, and before each instance is added |
//! | [`MAX_LIGHTS`] | 65 536 | lights of a scene | before each light is added |
//!
//! Exceeding one gives [`Error::Limit`], whose message names the quantity, the value, the bound
//! and its constant, and how to raise it, e.g. `resolution 100000x100000 is 10000000000 pixels,
//! more than the limit of 67108864 (limits::MAX_PIXELS); render in tiles or raise the constant
//! in native/kernel/src/limits.rs`. Parsers wrap it in a `file:line:` parse error.

use crate::Error;

/// Largest image side in pixels.
pub const MAX_SIDE: u32 = 16_384;
/// Largest image area in pixels (64 Mpixel, 768 MiB of f32 RGB).
pub const MAX_PIXELS: u64 = 64 * 1024 * 1024;
/// Largest `samples` value (S, giving SxS samples per pixel).
pub const MAX_SAMPLES: u32 = 16;
/// Largest ray-tree depth (the eye ray is depth 1).
pub const MAX_DEPTH: u32 = 64;
/// Largest number of primitives stored for a scene: its internal primitives (after polygons
/// and flattened meshes are expanded to triangles) plus the triangles of each shared
/// (instanced) mesh once, however many instances draw it (see [`crate::instance`]).
pub const MAX_PRIMITIVES: usize = 50_000_000;
/// Largest scene or mesh file in bytes (1 GiB).
pub const MAX_FILE_BYTES: u64 = 1 << 30;
/// Largest vertex count of one polygon or patch.
pub const MAX_POLYGON_VERTICES: usize = 1 << 20;
/// Largest number of triangles in one mesh file.
pub const MAX_MESH_TRIANGLES: usize = 20_000_000;
/// Largest number of mesh references in a scene, and so of mesh instances. Each instance
/// costs a few hundred bytes (its transform, inverse, normal matrix and box, and its share
/// of the instances' BVH), so this bounds them to a few hundred MiB.
pub const MAX_MESH_REFERENCES: usize = 1_000_000;
/// Largest number of lights.
pub const MAX_LIGHTS: usize = 65_536;

/// How to raise a bound (the usual case).
pub(crate) const RAISE: &str = "raise the constant in native/kernel/src/limits.rs and rebuild";
/// How to get past the image-size bounds.
pub(crate) const TILES: &str =
    "render in tiles or raise the constant in native/kernel/src/limits.rs";

/// `Err(Error::Limit)` if `value > max`. `what` names the quantity, `unit` follows the value
/// (`" bytes"`, or `""`), `constant` is the name of the bound in this module.
/// Checks a file's (or in-memory scene's) size against [`MAX_FILE_BYTES`].
pub(crate) fn check_file_size(what: impl Into<String>, bytes: u64) -> Result<(), Error> {
    check_with(
        what,
        bytes,
        " bytes",
        MAX_FILE_BYTES,
        "MAX_FILE_BYTES",
        RAISE,
    )
}

pub(crate) fn check_with(
    what: impl Into<String>,
    value: u64,
    unit: &'static str,
    max: u64,
    constant: &'static str,
    hint: &'static str,
) -> Result<(), Error> {
    if value > max {
        Err(Error::Limit {
            what: what.into(),
            value,
            unit,
            max,
            constant,
            hint,
        })
    } else {
        Ok(())
    }
}

/// [`check_with`] with no unit and the usual hint.
pub(crate) fn check(
    what: impl Into<String>,
    value: u64,
    max: u64,
    constant: &'static str,
) -> Result<(), Error> {
    check_with(what, value, "", max, constant, RAISE)
}

/// Checks an image resolution against [`MAX_PIXELS`] and [`MAX_SIDE`]; zero sides are rejected
/// too. Takes any unsigned width and height (parsers pass the u64 they read, so nothing is
/// truncated before the check); the pixel count saturates instead of overflowing.
pub fn check_resolution(width: impl Into<u64>, height: impl Into<u64>) -> Result<(), Error> {
    let (width, height) = (width.into(), height.into());
    if width == 0 || height == 0 {
        return Err(Error::InvalidArgument(format!(
            "resolution {width}x{height} has a zero side"
        )));
    }
    check_with(
        format!("resolution {width}x{height}"),
        width.saturating_mul(height),
        " pixels",
        MAX_PIXELS,
        "MAX_PIXELS",
        TILES,
    )?;
    check_with(
        "image width",
        width,
        " pixels",
        MAX_SIDE as u64,
        "MAX_SIDE",
        TILES,
    )?;
    check_with(
        "image height",
        height,
        " pixels",
        MAX_SIDE as u64,
        "MAX_SIDE",
        TILES,
    )
}

/// An upper bound on the triangles an OBJ file can produce, from a scan of its `f` lines (a
/// face of n vertices gives n - 2 triangles; this counts n), so [`MAX_MESH_TRIANGLES`] is checked before the
/// OBJ reader allocates anything.
pub(crate) fn obj_triangle_bound(bytes: &[u8]) -> u64 {
    let mut total = 0u64;
    let mut continued_face = false;
    for line in bytes.split(|&c| c == b'\n') {
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        let mut tokens = line
            .split(|c| c.is_ascii_whitespace())
            .filter(|t| !t.is_empty() && *t != b"\\")
            .peekable();
        let is_face = if continued_face {
            true
        } else if tokens.peek() == Some(&&b"f"[..]) {
            tokens.next();
            true
        } else {
            false
        };
        continued_face = is_face && line.ends_with(b"\\");
        if is_face {
            // vertices on this line (an over-count of 2 per face)
            total = total.saturating_add(tokens.count() as u64);
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolution_message_names_everything() {
        let e = check_resolution(100_000u32, 100_000u32).unwrap_err();
        assert_eq!(
            e.to_string(),
            "resolution 100000x100000 is 10000000000 pixels, more than the limit of 67108864 \
             (limits::MAX_PIXELS); render in tiles or raise the constant in \
             native/kernel/src/limits.rs"
        );
        let e = check_resolution(100_000u32, 10u32).unwrap_err().to_string();
        assert_eq!(
            e,
            "image width is 100000 pixels, more than the limit of 16384 (limits::MAX_SIDE); \
             render in tiles or raise the constant in native/kernel/src/limits.rs"
        );
        assert!(check_resolution(u64::MAX, u64::MAX).is_err());
        assert!(check_resolution(0u32, 5u32).is_err());
        assert!(check_resolution(MAX_SIDE, MAX_PIXELS / MAX_SIDE as u64).is_ok());
    }

    #[test]
    fn obj_bound_counts_face_vertices() {
        assert_eq!(obj_triangle_bound(b"v 0 0 0\nf 1 2 3\nf 1 2 3 4\n"), 7);
        assert_eq!(obj_triangle_bound(b"f 1 2 \\\n 3 4\r\nvn 0 0 1\n"), 4);
        assert_eq!(obj_triangle_bound(b"fo 1 2 3\n# f 1 2 3\n"), 0);
    }
}
