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
//! | [`MAX_FRAMES`] | 1 000 000 | frames of an animation (`[animation] frames`) | when the TOML scene is read |
//! | [`MAX_TOML_BYTES`] | 64 MiB | a TOML scene file (its reader needs about 50 bytes a byte) | before parsing |
//! | [`MAX_TOKEN_BYTES`] | 4 096 | one token: an NFF or OBJ word, a TOML key, string or number | by a scan of the file before parsing |
//! | [`MAX_WARNINGS`] | 100 | warnings kept per scene (the rest only counted) | [`crate::warning::Warnings::add`] |
//! | [`MEMORY_HEADROOM`] | 256 MiB | address space kept free under `RLIMIT_AS` when an input-sized array is made | [`crate::memory::check`], before each such array grows |
//! | [`BVH_BYTES_PER_BOX`], [`BVH_BYTES_PER_NODE`] | 160, 128 | what a BVH build makes per box, then its collapse per binary node | before each stage, against the address space left |
//!
//! ## Memory
//!
//! A parse, BVH included, needs at most about this multiple of the file's size at its peak
//! (resident set of `examples/scene_memory`, the file's own bytes included, for the densest
//! file of each kind; docs/benchmarks.md has the command and the table):
//!
//! | file | peak / file size | why |
//! |---|---|---|
//! | NFF of spheres (`s 1 2 3 1`, 10 bytes each) | 17x | ~160 bytes a primitive (shape, shading info, BVH build) |
//! | NFF of triangles (`p 3` + 3 vertices) | 7x | |
//! | OBJ (`v`/`f`), with or without normals | 7x | the OBJ reader's arrays, then the triangles (~230 bytes each with normals) |
//! | TOML of sphere tables | 50x | the TOML reader holds the whole document as a tree: hence [`MAX_TOML_BYTES`] |
//!
//! So no parse needs more than the smaller of 17 times its file's size and ~12 GB
//! ([`MAX_PRIMITIVES`] at ~230 bytes each, reached before a 1 GiB file of spheres is read
//! through); a TOML file at [`MAX_TOML_BYTES`] needs at most ~3.2 GiB. Through the
//! NIF add the scene's bytes once more (the binary the VM holds) and each referenced mesh twice
//! (its bytes are returned to Elixir to ship to other nodes).
//!
//! Under an address-space limit (`ulimit -v`, `prlimit --as`) the parse may need more than
//! is left: the arrays that grow with the scene are then refused before they are made, with
//! an [`Error::Memory`] naming the file, the bytes needed and the bytes left, never an abort
//! ([`crate::memory`]).
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
/// Largest number of frames of an animation: at 24 a second, over eleven hours; a frame
/// costs nothing until it is asked for, so this bounds only the frame numbers.
pub const MAX_FRAMES: u32 = 1_000_000;

/// Largest TOML scene file in bytes (64 MiB). The TOML reader holds the whole document as a
/// tree, about 50 bytes of memory per byte of file (see "Memory" in the module docs), where the NFF and OBJ
/// readers stream; large geometry belongs in OBJ meshes (`type = "mesh"`).
pub const MAX_TOML_BYTES: u64 = 64 << 20;
/// Largest token in bytes: a whitespace-separated word of an NFF or OBJ file, or a key, string
/// or bare value of a TOML file. Numbers and names are far shorter; a path is at most 4096 bytes
/// (Linux's `PATH_MAX`). Checked by a scan before the parser copies any token.
pub const MAX_TOKEN_BYTES: usize = 4096;
/// Warnings kept per parsed scene; more are counted, not stored ([`crate::warning::Warnings`]).
pub const MAX_WARNINGS: usize = 100;

/// Address space kept free when an array whose size the input decides is checked against
/// what the process has left under its `RLIMIT_AS` ([`crate::memory`]): room for the small
/// allocations made on the way, which cannot fail gracefully.
pub const MEMORY_HEADROOM: u64 = 256 << 20;
/// Bytes a BVH's binary build makes per box (a primitive's box; an oblique cone has up to 16):
/// the primitive order (4), two arrays of build references (64: each partition copies a node's
/// from one to the other) and up to two binary nodes (64), rounded up. Checked against the memory left before the build ([`crate::memory`]);
/// `bvh_bytes_per_box_covers_the_build` in bvh.rs keeps it honest.
pub const BVH_BYTES_PER_BOX: u64 = 160;
/// Bytes the collapse of a binary BVH into 8-wide nodes makes per binary node: its cost and
/// choice tables (57) and its share of the 8-wide nodes (64), rounded up; checked likewise
/// before the collapse.
pub const BVH_BYTES_PER_NODE: u64 = 128;

/// How to raise a bound (the usual case).
pub(crate) const RAISE: &str = "raise the constant in native/kernel/src/limits.rs and rebuild";
/// How to get past the TOML size bound.
pub(crate) const MESHES: &str = "put large geometry in OBJ meshes (type = \"mesh\") or raise the \
     constant in native/kernel/src/limits.rs";
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

/// The triangles an OBJ file can produce, from a scan of its `f` lines (a face of n vertices
/// gives n - 2 triangles, a face continued with `\` counted whole), so [`MAX_MESH_TRIANGLES`]
/// is checked before the OBJ reader allocates anything. Each triangle counts once, as the
/// check after the reader counts it.
pub(crate) fn obj_triangle_bound(bytes: &[u8]) -> u64 {
    let mut total = 0u64;
    let mut continued_face = false;
    // vertices of the face being read, over its continued lines
    let mut face = 0u64;
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
            face = face.saturating_add(tokens.count() as u64);
            if !continued_face {
                total = total.saturating_add(face.saturating_sub(2));
                face = 0;
            }
        }
    }
    total.saturating_add(face.saturating_sub(2))
}

/// How a file is split into tokens for [`first_long_token`].
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tokens {
    /// Whitespace-separated words; `#` at the start of a word comments out the rest of the line
    /// (NFF, OBJ, MTL).
    Words,
    /// TOML: bare keys and values end at whitespace or `[ ] { } , =`; a quoted string (basic,
    /// literal, or multi-line) is one token, counted without its quotes; `#` outside strings starts a comment.
    Toml,
}

/// The 1-based line and length of the first token longer than [`MAX_TOKEN_BYTES`], if any. One
/// pass over the bytes, nothing allocated; comments are not tokens, so a long comment is fine.
pub(crate) fn first_long_token(bytes: &[u8], mode: Tokens) -> Option<(usize, u64)> {
    let mut line = 1usize;
    let mut i = 0usize;
    let long = |len: usize| len > MAX_TOKEN_BYTES;
    while let Some(&c) = bytes.get(i) {
        if c == b'\n' {
            line += 1;
            i += 1;
        } else if c.is_ascii_whitespace() {
            i += 1;
        } else if c == b'#' {
            while bytes.get(i).is_some_and(|&c| c != b'\n') {
                i += 1;
            }
        } else if mode == Tokens::Toml && matches!(c, b'[' | b']' | b'{' | b'}' | b',' | b'=') {
            i += 1;
        } else if mode == Tokens::Toml && (c == b'"' || c == b'\'') {
            let (start_line, start) = (line, i);
            let triple = bytes.get(i..i + 3) == Some(&[c, c, c][..]);
            i += if triple { 3 } else { 1 };
            loop {
                match bytes.get(i) {
                    None => break,
                    Some(b'\\') if c == b'"' => i += 2,
                    Some(b'\n') if !triple => break,
                    Some(&d)
                        if d == c && (!triple || bytes.get(i..i + 3) == Some(&[c, c, c][..])) =>
                    {
                        i += if triple { 3 } else { 1 };
                        break;
                    }
                    Some(&d) => {
                        if d == b'\n' {
                            line += 1;
                        }
                        i += 1;
                    }
                }
            }
            // the content, without its quotes
            let quotes = if triple { 6 } else { 2 };
            let len = (i.min(bytes.len()) - start).saturating_sub(quotes);
            if long(len) {
                return Some((start_line, len as u64));
            }
        } else {
            let start = i;
            while let Some(&d) = bytes.get(i) {
                let ends = d.is_ascii_whitespace()
                    || (mode == Tokens::Toml
                        && matches!(
                            d,
                            b'[' | b']' | b'{' | b'}' | b',' | b'=' | b'#' | b'"' | b'\''
                        ));
                if ends {
                    break;
                }
                i += 1;
            }
            if long(i - start) {
                return Some((line, (i - start) as u64));
            }
        }
    }
    None
}

/// `Err(Error::Limit)` if a token of `len` bytes is longer than [`MAX_TOKEN_BYTES`].
pub(crate) fn check_token(len: u64) -> Result<(), Error> {
    check_with(
        "a token",
        len,
        " bytes",
        MAX_TOKEN_BYTES as u64,
        "MAX_TOKEN_BYTES",
        RAISE,
    )
}

/// [`first_long_token`] as the error a parser returns: `file:line: a token is N bytes, more than
/// the limit of 4096 (limits::MAX_TOKEN_BYTES); ...`.
pub(crate) fn check_tokens(bytes: &[u8], mode: Tokens, file: &str) -> Result<(), Error> {
    match first_long_token(bytes, mode) {
        None => Ok(()),
        Some((line, len)) => check_token(len).map_err(|e| Error::parse(file, line, e.to_string())),
    }
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
        // once per triangle: a triangle and a quad (1 + 2); a quad over two lines and a pentagon (2 + 3)
        assert_eq!(obj_triangle_bound(b"v 0 0 0\nf 1 2 3\nf 1 2 3 4\n"), 3);
        assert_eq!(obj_triangle_bound(b"f 1 2 \\\n 3 4\r\nf 1 2 3 4 5\n"), 5);
        assert_eq!(obj_triangle_bound(b"f 1 2 \\\n 3 4 \\"), 2);
        // a face of fewer than three vertices makes none
        assert_eq!(obj_triangle_bound(b"f 1 2\nf 1\nf\n"), 0);
        assert_eq!(obj_triangle_bound(b"fo 1 2 3\n# f 1 2 3\n"), 0);
        let n = 1000;
        assert_eq!(
            obj_triangle_bound("f 1 2 3\n".repeat(n).as_bytes()),
            n as u64
        );
    }

    #[test]
    fn long_tokens_found_with_their_line() {
        let big = "x".repeat(MAX_TOKEN_BYTES + 1);
        let fits = "y".repeat(MAX_TOKEN_BYTES);
        let words = format!("a b\n{fits}\n# {big}\nc {big} d\n");
        assert_eq!(
            first_long_token(words.as_bytes(), Tokens::Words),
            Some((4, MAX_TOKEN_BYTES as u64 + 1))
        );
        assert_eq!(first_long_token(fits.as_bytes(), Tokens::Words), None);
        // TOML: arrays split at their punctuation, strings are whole, comments are skipped
        let many = "[0,".repeat(5000);
        assert_eq!(first_long_token(many.as_bytes(), Tokens::Toml), None);
        let spaced = format!("a = \"{}\"\n", "w ".repeat(3000));
        assert_eq!(
            first_long_token(spaced.as_bytes(), Tokens::Toml),
            Some((1, 6000))
        );
        let multi = format!("# {big}\nb = \"\"\"\n{}\"\"\"\nc = 1\n", "z\n".repeat(3000));
        assert_eq!(
            first_long_token(multi.as_bytes(), Tokens::Toml),
            Some((2, 6001))
        );
        let lit = format!("k = '{fits}'\nl = '{big}'\n");
        assert_eq!(
            first_long_token(lit.as_bytes(), Tokens::Toml),
            Some((2, 4097))
        );
        let esc = "q = \"a\\\"b\"\n".to_string();
        assert_eq!(first_long_token(esc.as_bytes(), Tokens::Toml), None);
        let e = check_tokens(format!("\n{big}").as_bytes(), Tokens::Toml, "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml:2: a token is 4097 bytes, more than the limit of 4096 \
             (limits::MAX_TOKEN_BYTES); raise the constant in native/kernel/src/limits.rs and \
             rebuild"
        );
    }
}
