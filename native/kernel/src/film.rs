//! Image output: 8-bit sRGB PNG and linear f32 OpenEXR.

use crate::safe_fs;
use crate::Error;
use exr::prelude::{Encoding, Image, LineOrder, SpecificChannels, Vec2, WritableImage};
use std::io::Write;
use std::path::Path;

/// sRGB transfer curve of one linear value, clamped to [0, 1] (NaN becomes 0), rounded to 8 bits.
/// Fast: the number of the 255 exact decision thresholds of [`srgb8_exact`] at or below `v`,
/// which gives identical results: a table gives the count at the bottom of `v`'s bucket (the
/// floats that share its top 16 bits; negative ones in the first, those from 1.0 up in the
/// last), and one comparison adds the threshold between there and `v`, if any (a bucket is
/// narrower than a step of the curve, so it holds at most one: `buckets_hold_one_threshold`).
#[inline]
pub fn srgb8(v: f32) -> u8 {
    srgb8_with(buckets(), stops(), v)
}

#[inline(always)]
fn srgb8_with(buckets: &[u8; TOP_BUCKET as usize + 1], stops: &[f32; 256], v: f32) -> u8 {
    let bits = v.to_bits();
    // negative (sign bit set) and NaN to the first bucket, whose count is 0 and whose
    // threshold neither reaches
    let bucket = if (bits as i32) < 0 || v.is_nan() {
        0
    } else {
        (bits >> 16).min(TOP_BUCKET) as usize
    };
    let k = buckets[bucket];
    k + (stops[k as usize] <= v) as u8
}

/// The bucket of 1.0 and every larger float.
const TOP_BUCKET: u32 = 0x3F80;

/// For each bucket, the number of thresholds at or below its smallest float (255 for the top
/// bucket).
fn buckets() -> &'static [u8; TOP_BUCKET as usize + 1] {
    static B: std::sync::OnceLock<[u8; TOP_BUCKET as usize + 1]> = std::sync::OnceLock::new();
    B.get_or_init(|| {
        let t = thresholds();
        let mut b = [0u8; TOP_BUCKET as usize + 1];
        for (i, slot) in b.iter_mut().enumerate() {
            *slot = t.partition_point(|&th| th <= f32::from_bits((i as u32) << 16)) as u8;
        }
        b
    })
}

/// The thresholds, and past the last a NaN, at or below which no value is.
fn stops() -> &'static [f32; 256] {
    static S: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    S.get_or_init(|| {
        let mut s = [f32::NAN; 256];
        s[..255].copy_from_slice(thresholds());
        s
    })
}

/// Linear values at which the 8-bit sRGB code steps up: `srgb8_exact(t[k]) == k + 1` and
/// `srgb8_exact` of the next smaller float is `k`.
fn thresholds() -> &'static [f32; 255] {
    static T: std::sync::OnceLock<[f32; 255]> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let mut t = [0.0f32; 255];
        for (k, slot) in t.iter_mut().enumerate() {
            let want = k as u8 + 1;
            // bisection on the bit patterns of non-negative floats (monotonic in value)
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if srgb8_exact(f32::from_bits(mid)) >= want {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            *slot = f32::from_bits(lo);
        }
        t
    })
}

/// Reference sRGB encoding with `powf` (see [`srgb8`]).
pub fn srgb8_exact(v: f32) -> u8 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round().clamp(0.0, 255.0) as u8
}

/// The sRGB decoding curve: a display value in [0, 1] (clamped; NaN becomes 0) to linear light.
///
/// ```
/// use ring_tracer_kernel::film::{from_srgb, srgb8};
/// assert_eq!(from_srgb(0.0), 0.0);
/// assert_eq!(from_srgb(1.0), 1.0);
/// assert_eq!(srgb8(from_srgb(128.0 / 255.0)), 128);
/// ```
pub fn from_srgb(v: f32) -> f32 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// [`from_srgb`] over a buffer in place, bit for bit, with a small cache of the values met: an
/// image repeats a few values often (the background, surfaces in shadow), and `powf` is a
/// large part of tracing a simple scene. Each slot holds an input's bits and `from_srgb` of
/// it, so a hit gives exactly what the call would. Before the cache, each triple of values (a
/// pixel, where the buffer is RGB) is compared with the one before it: a run of equal pixels,
/// such as the background, costs a comparison and a copy per pixel.
pub fn decode_srgb_in_place(values: &mut [f32]) {
    const SLOTS: usize = 256;
    // slot k holds (bits, from_srgb(f32::from_bits(bits))); 0.0 decodes to 0.0
    let mut keys = [0u32; SLOTS];
    let mut vals = [0.0f32; SLOTS];
    let mut decode = |v: &mut f32| {
        let bits = v.to_bits();
        let k = (bits.wrapping_mul(0x9E37_79B1) >> 24) as usize % SLOTS;
        if keys[k] == bits {
            *v = vals[k];
        } else {
            let d = from_srgb(*v);
            keys[k] = bits;
            vals[k] = d;
            *v = d;
        }
    };
    // the last triple's input bits and its decoded values; all bits set is a NaN, which
    // decodes to 0.0, so the start is a true pair too
    let mut last = ([u32::MAX; 3], [0.0f32; 3]);
    let mut triples = values.chunks_exact_mut(3);
    for t in &mut triples {
        let bits = [t[0].to_bits(), t[1].to_bits(), t[2].to_bits()];
        if bits == last.0 {
            t.copy_from_slice(&last.1);
        } else {
            t.iter_mut().for_each(&mut decode);
            last = (bits, [t[0], t[1], t[2]]);
        }
    }
    triples.into_remainder().iter_mut().for_each(decode);
}

/// Converts linear RGB floats to 8-bit sRGB bytes (same length).
pub fn to_srgb8(rgb: &[f32]) -> Vec<u8> {
    let (buckets, stops) = (buckets(), stops());
    rgb.iter().map(|&v| srgb8_with(buckets, stops, v)).collect()
}

fn check_len(width: u32, height: u32, rgb: &[f32]) -> Result<(), Error> {
    let want = width as u64 * height as u64 * 3;
    if rgb.len() as u64 != want || width == 0 || height == 0 {
        return Err(Error::InvalidArgument(format!(
            "image {width}x{height} needs {want} floats, got {}",
            rgb.len()
        )));
    }
    Ok(())
}

/// Encodes linear RGB as an 8-bit sRGB PNG in memory.
pub fn encode_png(width: u32, height: u32, rgb: &[f32]) -> Result<Vec<u8>, Error> {
    check_len(width, height, rgb)?;
    let mut out = Vec::with_capacity(rgb.len() / 2);
    encode_png_to(&mut out, width, height, rgb)?;
    Ok(out)
}

/// Encodes linear RGB as an 8-bit sRGB PNG into `out`, a row at a time: no copy of the image
/// is made, in floats or in bytes.
fn encode_png_to<W: Write>(out: W, width: u32, height: u32, rgb: &[f32]) -> Result<(), Error> {
    let (buckets, stops) = (buckets(), stops());
    let mut floats = rgb.chunks_exact(width as usize * 3);
    encode_rows(out, width, height, |row| {
        if let Some(floats) = floats.next() {
            for (byte, &v) in row.iter_mut().zip(floats) {
                *byte = srgb8_with(buckets, stops, v);
            }
        }
    })
}

/// Writes a PNG of `height` rows that `fill` makes, one at a time, as 8-bit sRGB bytes.
/// fdeflate (png's `Fast`): several times faster than the default for files a little larger,
/// so that a sequence's frames are written while the ring traces the next ones.
fn encode_rows<W: Write>(
    out: W,
    width: u32,
    height: u32,
    mut fill: impl FnMut(&mut [u8]),
) -> Result<(), Error> {
    let image = |e: png::EncodingError| Error::Image(e.to_string());
    let mut enc = png::Encoder::new(out, width, height);
    enc.set_compression(png::Compression::Fast);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut header = enc.write_header().map_err(image)?;
    let mut stream = header.stream_writer().map_err(image)?;
    let mut row = vec![0u8; width as usize * 3];
    for _ in 0..height {
        fill(&mut row);
        stream
            .write_all(&row)
            .map_err(|e| Error::Image(e.to_string()))?;
    }
    stream.finish().map_err(image)
}

fn check_len8(width: u32, height: u32, srgb: &[u8]) -> Result<(), Error> {
    let want = width as u64 * height as u64 * 3;
    if srgb.len() as u64 != want || width == 0 || height == 0 {
        return Err(Error::InvalidArgument(format!(
            "image {width}x{height} needs {want} bytes of 8-bit sRGB, got {}",
            srgb.len()
        )));
    }
    Ok(())
}

/// Encodes 8-bit sRGB bytes (3 a pixel, [`to_srgb8`]'s) as a PNG in memory: the same file
/// [`encode_png`] makes of the floats they came from.
pub fn encode_png8(width: u32, height: u32, srgb: &[u8]) -> Result<Vec<u8>, Error> {
    check_len8(width, height, srgb)?;
    let mut out = Vec::with_capacity(srgb.len() / 2);
    let mut rows = srgb.chunks_exact(width as usize * 3);
    encode_rows(&mut out, width, height, |row| {
        if let Some(r) = rows.next() {
            row.copy_from_slice(r)
        }
    })?;
    Ok(out)
}

/// [`write_image_in`] of 8-bit sRGB bytes: `.png` only (the same file as of the floats they
/// came from); any other extension is an error.
pub fn write_png8_in(
    dir: &safe_fs::Dir,
    name: &str,
    width: u32,
    height: u32,
    srgb: &[u8],
    new_mode: Option<u32>,
) -> Result<(), Error> {
    check_len8(width, height, srgb)?;
    let path = &dir.path().join(name);
    let file = path.display().to_string();
    let png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !png {
        return Err(Error::Unsupported(format!(
            "{file}: 8-bit pixels are written as .png only"
        )));
    }
    dir.write_file(name, new_mode, safe_fs::Replace::Yes, |f| {
        let mut buffered = std::io::BufWriter::with_capacity(1 << 16, f);
        let mut rows = srgb.chunks_exact(width as usize * 3);
        encode_rows(&mut buffered, width, height, |row| {
            if let Some(r) = rows.next() {
                row.copy_from_slice(r)
            }
        })?;
        buffered.flush().map_err(|e| Error::Io {
            file: file.clone(),
            message: e.to_string(),
        })
    })
}

/// Writes an image: `.png` as 8-bit sRGB, `.exr` as linear f32 RGB; other extensions are an error.
///
/// Atomic: the image is written to a temporary file in the same folder, which then replaces
/// `path` (a rename). A failure leaves an earlier file at `path` as it was, never a partial
/// image, and removes the temporary file. A file replaced keeps its permissions; a new one
/// gets `0o666` less the umask, as a plain create would.
pub fn write_image(path: &Path, width: u32, height: u32, rgb: &[f32]) -> Result<(), Error> {
    write_image_mode(path, width, height, rgb, None)
}

/// [`write_image`], with `new_mode` the permissions of a new file (`None`: `0o666` less this
/// process's umask), e.g. those a client of a render server would have given it. The temporary
/// file is only its owner's until it has the image and its final permissions, so that nobody
/// can open it on the way and read what its final mode would refuse them.
pub fn write_image_mode(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[f32],
    new_mode: Option<u32>,
) -> Result<(), Error> {
    // `write_image_in` checks the pixels before it writes anything
    let (dir, name) = safe_fs::open_parent(path)?;
    write_image_in(&dir, &name, width, height, rgb, new_mode)
}

/// [`write_image_mode`] into the folder `dir` already open, as `name` there (so that a
/// caller that keeps what was at the name first, in the same folder, writes where it kept).
pub fn write_image_in(
    dir: &safe_fs::Dir,
    name: &str,
    width: u32,
    height: u32,
    rgb: &[f32],
    new_mode: Option<u32>,
) -> Result<(), Error> {
    check_len(width, height, rgb)?;
    let path = &dir.path().join(name);
    let file = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let png = match ext.as_deref() {
        Some("png") => true,
        Some("exr") => false,
        _ => {
            return Err(Error::Unsupported(format!(
                "{file}: unknown image format (expected .png or .exr)"
            )))
        }
    };
    let io = |e: std::io::Error| Error::Io {
        file: file.clone(),
        message: e.to_string(),
    };
    // made 0600 in the folder held, given its final mode on its descriptor, renamed into
    // place; removed on any failure
    dir.write_file(name, new_mode, safe_fs::Replace::Yes, |f| match png {
        true => {
            let mut buffered = std::io::BufWriter::with_capacity(1 << 16, f);
            encode_png_to(&mut buffered, width, height, rgb)?;
            buffered.flush().map_err(io)
        }
        false => {
            let w = width as usize;
            let pixels = SpecificChannels::rgb(|pos: Vec2<usize>| {
                let i = (pos.y() * w + pos.x()) * 3;
                match rgb.get(i..i + 3) {
                    Some(p) => (p[0], p[1], p[2]),
                    None => (0.0, 0.0, 0.0),
                }
            });
            // Blocks in increasing order: exr's default (`Unspecified`) writes them as its
            // threads finish compressing them, so the same pixels made different files.
            let encoding = Encoding {
                line_order: LineOrder::Increasing,
                ..Encoding::FAST_LOSSLESS
            };
            Image::from_encoded_channels((w, height as usize), encoding, pixels)
                .write()
                .to_buffered(std::io::BufWriter::new(f))
                .map_err(|e| Error::Image(format!("{file}: {e}")))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::names;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn buckets_hold_one_threshold() {
        let t = thresholds();
        for b in 0..TOP_BUCKET {
            let (lo, hi) = (f32::from_bits(b << 16), f32::from_bits((b + 1) << 16));
            let inside = t.iter().filter(|&&th| lo < th && th < hi).count();
            assert!(inside <= 1, "bucket {b:#x} holds {inside} thresholds");
        }
    }

    #[test]
    fn fast_srgb_matches_exact() {
        let mut v = -0.01f32;
        while v < 1.01 {
            assert_eq!(srgb8(v), srgb8_exact(v), "{v}");
            v += 1.0e-6;
        }
        for k in thresholds() {
            for x in [
                f32::from_bits(k.to_bits() - 1),
                *k,
                f32::from_bits(k.to_bits() + 1),
            ] {
                assert_eq!(srgb8(x), srgb8_exact(x), "{x}");
            }
        }
        for b in 1..=TOP_BUCKET {
            let lo = b << 16;
            for x in [
                f32::from_bits(lo - 1),
                f32::from_bits(lo),
                f32::from_bits(lo + 1),
            ] {
                assert_eq!(srgb8(x), srgb8_exact(x), "{x}");
            }
        }
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -0.0] {
            assert_eq!(srgb8(x), srgb8_exact(x), "{x}");
        }
    }

    #[test]
    fn writes_are_atomic() {
        let t = tempfile::tempdir().unwrap();
        let rgb = [0.5f32; 2 * 2 * 3];
        for name in ["a.png", "a.exr"] {
            let out = t.path().join(name);
            std::fs::write(&out, b"earlier image").unwrap();
            // a failure leaves the earlier file as it was
            let e = write_image(&out, 2, 2, &rgb[..11]).unwrap_err();
            assert!(matches!(e, Error::InvalidArgument(_)), "{e}");
            assert_eq!(std::fs::read(&out).unwrap(), b"earlier image");
            // a success replaces it
            write_image(&out, 2, 2, &rgb).unwrap();
            let bytes = std::fs::read(&out).unwrap();
            assert_ne!(bytes, b"earlier image");
            let magic: &[u8] = if name.ends_with(".png") {
                b"\x89PNG"
            } else {
                b"\x76\x2f\x31\x01"
            };
            assert!(bytes.starts_with(magic), "{name}");
        }
        assert_eq!(names(t.path()), ["a.exr", "a.png"]);
        // a failure after the temporary file exists (the rename onto a folder) removes it
        let dir_out = t.path().join("folder.png");
        std::fs::create_dir(&dir_out).unwrap();
        std::fs::write(dir_out.join("keep"), b"x").unwrap();
        assert!(matches!(
            write_image(&dir_out, 2, 2, &rgb),
            Err(Error::Fs { .. })
        ));
        assert_eq!(names(t.path()), ["a.exr", "a.png", "folder.png"]);
        assert_eq!(names(&dir_out), ["keep"]);
        // a new file: as a plain create makes one, or as asked
        let t2 = tempfile::tempdir().unwrap();
        let plain = t2.path().join("plain");
        std::fs::File::create(&plain).unwrap();
        let mode_of = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        let fresh = t2.path().join("fresh.png");
        write_image(&fresh, 2, 2, &rgb).unwrap();
        assert_eq!(mode_of(&fresh), mode_of(&plain));
        let asked = t2.path().join("asked.png");
        write_image_mode(&asked, 2, 2, &rgb, Some(0o640)).unwrap();
        assert_eq!(mode_of(&asked), 0o640);
        // ... but a file replaced keeps its own
        write_image_mode(&asked, 2, 2, &rgb, Some(0o666)).unwrap();
        assert_eq!(mode_of(&asked), 0o640);
        assert_eq!(names(t2.path()), ["asked.png", "fresh.png", "plain"]);
        // permissions of a replaced file are kept
        let out = t.path().join("a.png");
        std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_image(&out, 2, 2, &rgb).unwrap();
        let mode = std::fs::metadata(&out).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640);
        assert!(write_image(&t.path().join("a.bmp"), 2, 2, &rgb).is_err());
        assert_eq!(names(t.path()), ["a.exr", "a.png", "folder.png"]);
    }

    #[test]
    fn png_of_srgb8_bytes_is_the_png_of_the_floats() {
        let (w, h) = (37u32, 23u32);
        let rgb: Vec<f32> = (0..w * h * 3)
            .map(|i| (i as f32 * 0.37).sin() * 1.2)
            .collect();
        let bytes = to_srgb8(&rgb);
        assert_eq!(
            encode_png8(w, h, &bytes).unwrap(),
            encode_png(w, h, &rgb).unwrap()
        );
        assert!(encode_png8(w, h, &bytes[1..]).is_err());
        let t = tempfile::tempdir().unwrap();
        let dir = safe_fs::Dir::open(t.path()).unwrap();
        write_png8_in(&dir, "a.png", w, h, &bytes, None).unwrap();
        write_image_in(&dir, "b.png", w, h, &rgb, None).unwrap();
        let read = |n: &str| std::fs::read(t.path().join(n)).unwrap();
        assert_eq!(read("a.png"), read("b.png"));
        let e = write_png8_in(&dir, "a.exr", w, h, &bytes, None).unwrap_err();
        assert!(matches!(e, Error::Unsupported(_)), "{e}");
        assert_eq!(names(t.path()), ["a.png", "b.png"]);
    }

    #[test]
    fn exr_files_are_the_same_for_the_same_pixels() {
        // many blocks (16 rows each), compressed on several threads
        let (w, h) = (200u32, 160u32);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| (i as f32 * 0.37).sin()).collect();
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("a.exr");
        write_image(&out, w, h, &rgb).unwrap();
        let first = std::fs::read(&out).unwrap();
        let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
        assert_eq!(meta.headers[0].line_order, LineOrder::Increasing);
        for _ in 0..8 {
            write_image(&out, w, h, &rgb).unwrap();
            assert!(std::fs::read(&out).unwrap() == first);
        }
    }

    #[test]
    fn cached_decoding_is_from_srgb() {
        let mut rng = 0x1234_5678u32;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            rng
        };
        // repeats, colliding slots, specials and values outside [0, 1]
        let vals: Vec<f32> = (0..20_000)
            .map(|i| match i % 5 {
                0 => 0.25,
                1 => f32::from_bits(next()),
                2 => (next() % 1000) as f32 / 999.0,
                3 => [0.0, -0.0, 1.0, f32::NAN, f32::INFINITY, -1.0, 0.04045][i % 7],
                _ => f32::from_bits(0x3F00_0000 | (next() % 64)),
            })
            .collect();
        // runs of equal pixels (triples), the first of all-ones NaNs (the start's pair); the
        // length is not a multiple of 3
        let nan = f32::from_bits(u32::MAX);
        let runs = [
            [nan; 3],
            [0.5, 0.25, 0.75],
            [0.5, 0.25, 0.7],
            [-0.0, 0.0, 2.0],
        ];
        let mut pixels: Vec<f32> = runs.iter().flat_map(|p| p.repeat(4)).collect();
        pixels.extend(&vals[..19_998]);
        pixels.extend(runs.iter().rev().flat_map(|p| p.repeat(3)));
        pixels.push(0.5);
        let mut vals = pixels;
        assert_eq!(vals.len() % 3, 1);
        let want: Vec<u32> = vals.iter().map(|&v| from_srgb(v).to_bits()).collect();
        decode_srgb_in_place(&mut vals);
        let got: Vec<u32> = vals.iter().map(|v| v.to_bits()).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn srgb_curve() {
        assert_eq!(srgb8(0.0), 0);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(2.0), 255);
        assert_eq!(srgb8(-1.0), 0);
        assert_eq!(srgb8(f32::NAN), 0);
        assert_eq!(srgb8(0.5), 188); // 0.7354 * 255 = 187.5 -> 188
        assert_eq!(srgb8(0.2140), 127); // 0.49996 * 255 = 127.49
        assert_eq!(srgb8(0.2142), 128); // 0.50020 * 255 = 127.55
        assert_eq!(srgb8(0.002), 7); // linear segment: 0.02584 * 255 = 6.59
    }
}
