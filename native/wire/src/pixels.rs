//! An atom's pixels on the wire: one tag byte, the format, then one zstd frame of
//!
//! * `FLOAT` (1): the linear f32 RGB bytes (native-endian, 12 a pixel), byte-shuffled into
//!   4 planes (every float's first byte, then every second byte, ...): neighbouring floats
//!   share their sign, exponent and high mantissa bytes, which then sit side by side, where
//!   zstd finds them. Decoded, the exact bytes come back.
//! * `SRGB8` (2): the 8-bit sRGB bytes (3 a pixel) of the floats, by the kernel's
//!   [`to_srgb8`], its PNG writer's conversion: a PNG of them is the PNG of the floats.

use ring_tracer_kernel::film::srgb8;
use ring_tracer_kernel::to_srgb8;

use crate::Error;

const FLOAT: u8 = 1;
const SRGB8: u8 = 2;

/// zstd's level for pixels: 1, its fastest standard level (docs/protocol.md, "Pixels on the
/// wire": on a 512x512 SPD atom, levels 2 and 3 save little for more time).
const LEVEL: i32 = 1;

/// A pixel format once decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Linear f32 RGB, 12 bytes a pixel.
    Float,
    /// 8-bit sRGB, 3 bytes a pixel.
    Srgb8,
}

impl Format {
    fn tag(self) -> u8 {
        match self {
            Format::Float => FLOAT,
            Format::Srgb8 => SRGB8,
        }
    }

    /// Bytes a pixel once decoded.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Format::Float => 12,
            Format::Srgb8 => 3,
        }
    }
}

/// The 4 byte planes of `bytes` (a multiple of 4 long), a plane at a time.
fn shuffle(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    for k in 0..4 {
        out.extend(bytes.iter().skip(k).step_by(4));
    }
    out
}

/// The bytes whose planes are `planes` (`shuffle`'s inverse).
fn unshuffle(planes: &[u8]) -> Vec<u8> {
    let n = planes.len() / 4;
    let (p0, rest) = planes.split_at(n);
    let (p1, rest) = rest.split_at(n);
    let (p2, p3) = rest.split_at(n);
    let mut out = Vec::with_capacity(planes.len());
    for i in 0..n {
        out.extend_from_slice(&[p0[i], p1[i], p2[i], p3[i]]);
    }
    out
}

fn framed(tag: u8, content: &[u8]) -> Result<Vec<u8>, Error> {
    let z = zstd::bulk::compress(content, LEVEL)
        .map_err(|e| Error::InvalidArgument(format!("zstd: {e}")))?;
    let mut out = Vec::with_capacity(z.len() + 1);
    out.push(tag);
    out.extend_from_slice(&z);
    Ok(out)
}

fn whole_pixels(floats: usize) -> Result<(), Error> {
    if floats.is_multiple_of(3) {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "{floats} floats are not whole RGB pixels"
        )))
    }
}

/// Linear f32 RGB `rgb` (`bytes`: the same floats as native-endian bytes) on the wire in
/// `format`.
pub fn encode(bytes: &[u8], rgb: &[f32], format: Format) -> Result<Vec<u8>, Error> {
    whole_pixels(rgb.len())?;
    if bytes.len() != rgb.len() * 4 {
        return Err(Error::InvalidArgument(format!(
            "{} bytes are not {} floats",
            bytes.len(),
            rgb.len()
        )));
    }
    match format {
        Format::Float => framed(FLOAT, &shuffle(bytes)),
        Format::Srgb8 => framed(SRGB8, &to_srgb8(rgb)),
    }
}

/// `rgb` mixed 50/50 with `colour` in linear light, in f64 and stored as f32 (as
/// `RingTracer.Report.Ownership` tints), as 8-bit sRGB on the wire.
pub fn encode_tinted(rgb: &[f32], colour: (f64, f64, f64)) -> Result<Vec<u8>, Error> {
    whole_pixels(rgb.len())?;
    let c = [colour.0, colour.1, colour.2];
    let tinted: Vec<u8> = rgb
        .iter()
        .zip(c.iter().cycle())
        .map(|(&v, &c)| srgb8(((v as f64 + c) / 2.0) as f32))
        .collect();
    framed(SRGB8, &tinted)
}

/// The `pixels` pixels in `format` that `wire` holds; another size, another format or a
/// corrupt frame is an error.
pub fn decode(wire: &[u8], format: Format, pixels: usize) -> Result<Vec<u8>, Error> {
    let want = pixels
        .checked_mul(format.bytes_per_pixel())
        .ok_or_else(|| Error::InvalidArgument(format!("{pixels} pixels are too many")))?;
    let (&tag, frame) = wire
        .split_first()
        .ok_or_else(|| Error::Corrupt("no pixels: empty".into()))?;
    if tag != format.tag() {
        return Err(Error::Corrupt(format!(
            "pixels tagged {tag}, expected {} ({format:?})",
            format.tag()
        )));
    }
    // a frame of more than `want` bytes fails here: nothing larger is made
    let content = zstd::bulk::decompress(frame, want)
        .map_err(|e| Error::Corrupt(format!("corrupt pixels: {e}")))?;
    if content.len() != want {
        return Err(Error::Corrupt(format!(
            "pixels hold {} bytes, expected {want} ({pixels} pixels of {format:?})",
            content.len()
        )));
    }
    Ok(match format {
        Format::Float => unshuffle(&content),
        Format::Srgb8 => content,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn floats(n: usize) -> (Vec<f32>, Vec<u8>) {
        let rgb: Vec<f32> = (0..n * 3).map(|i| (i as f32 * 0.013).sin() * 1.3).collect();
        let bytes = rgb.iter().flat_map(|v| v.to_ne_bytes()).collect();
        (rgb, bytes)
    }

    #[test]
    fn float_is_lossless() {
        let (rgb, bytes) = floats(1000);
        let wire = encode(&bytes, &rgb, Format::Float).unwrap();
        assert!(wire.len() < bytes.len());
        assert_eq!(decode(&wire, Format::Float, 1000).unwrap(), bytes);
        assert_eq!(unshuffle(&shuffle(&bytes)), bytes);
        assert_eq!(shuffle(&[1, 2, 3, 4, 5, 6, 7, 8]), [1, 5, 2, 6, 3, 7, 4, 8]);
    }

    #[test]
    fn srgb8_is_the_kernels_conversion() {
        let (rgb, bytes) = floats(777);
        let wire = encode(&bytes, &rgb, Format::Srgb8).unwrap();
        assert_eq!(decode(&wire, Format::Srgb8, 777).unwrap(), to_srgb8(&rgb));
    }

    #[test]
    fn tint_mixes_in_f64() {
        let rgb = [0.2f32, 0.7, 1.5, 0.0, 0.5, 0.9];
        let wire = encode_tinted(&rgb, (0.6, 0.1, 0.3)).unwrap();
        let got = decode(&wire, Format::Srgb8, 2).unwrap();
        assert_eq!(got.len(), 6);
        assert_eq!(got[0], srgb8(((0.2f32 as f64 + 0.6) / 2.0) as f32));
        assert_eq!(got[1], srgb8(((0.7f32 as f64 + 0.1) / 2.0) as f32));
        assert_eq!(got[2], srgb8(((1.5f32 as f64 + 0.3) / 2.0) as f32));
        assert_eq!(got[3], srgb8(0.3));
    }

    #[test]
    fn bad_input_is_an_error() {
        let (rgb, bytes) = floats(100);
        let wire = encode(&bytes, &rgb, Format::Float).unwrap();
        // wrong count, wrong format, truncated, corrupt, empty
        assert!(decode(&wire, Format::Float, 99).is_err());
        assert!(decode(&wire, Format::Float, 101).is_err());
        assert!(decode(&wire, Format::Srgb8, 400).is_err());
        assert!(decode(&wire[..wire.len() / 2], Format::Float, 100).is_err());
        let mut bad = wire.clone();
        bad[5] ^= 0xff;
        bad[wire.len() - 3] ^= 0xff;
        assert!(decode(&bad, Format::Float, 100).is_err());
        assert!(decode(&[], Format::Float, 0).is_err());
        assert!(decode(&[FLOAT, 1, 2, 3], Format::Float, 1).is_err());
        assert!(decode(&wire, Format::Float, usize::MAX).is_err());
        // not whole pixels
        assert!(encode(&bytes[..20], &rgb[..5], Format::Float).is_err());
        assert!(encode_tinted(&rgb[..5], (0.0, 0.0, 0.0)).is_err());
    }
}
