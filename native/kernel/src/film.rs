//! Image output: 8-bit sRGB PNG and linear f32 OpenEXR.

use crate::Error;
use std::path::Path;

/// sRGB transfer curve of one linear value, clamped to [0, 1] (NaN becomes 0), rounded to 8 bits.
#[inline]
pub fn srgb8(v: f32) -> u8 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round().clamp(0.0, 255.0) as u8
}

/// Converts linear RGB floats to 8-bit sRGB bytes (same length).
pub fn to_srgb8(rgb: &[f32]) -> Vec<u8> {
    rgb.iter().map(|&v| srgb8(v)).collect()
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
    let bytes = to_srgb8(rgb);
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut w = enc
            .write_header()
            .map_err(|e| Error::Image(e.to_string()))?;
        w.write_image_data(&bytes)
            .map_err(|e| Error::Image(e.to_string()))?;
        w.finish().map_err(|e| Error::Image(e.to_string()))?;
    }
    Ok(out)
}

/// Writes an image: `.png` as 8-bit sRGB, `.exr` as linear f32 RGB; other extensions are an error.
pub fn write_image(path: &Path, width: u32, height: u32, rgb: &[f32]) -> Result<(), Error> {
    check_len(width, height, rgb)?;
    let file = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => {
            let data = encode_png(width, height, rgb)?;
            std::fs::write(path, data).map_err(|e| Error::Io {
                file,
                message: e.to_string(),
            })
        }
        Some("exr") => {
            let w = width as usize;
            exr::prelude::write_rgb_file(path, w, height as usize, |x, y| {
                let i = (y * w + x) * 3;
                match rgb.get(i..i + 3) {
                    Some(p) => (p[0], p[1], p[2]),
                    None => (0.0, 0.0, 0.0),
                }
            })
            .map_err(|e| Error::Image(format!("{file}: {e}")))
        }
        _ => Err(Error::Unsupported(format!(
            "{file}: unknown image format (expected .png or .exr)"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
