//! Our renders of the SPD scenes must look like the SPD's own pictures
//! (`priv/scenes/spd/reference/*.png`, 512 x 512, sRGB; the teapot at size 6). Both are
//! reduced to 64 x 64 by averaging 8 x 8 blocks (which forgives antialiasing and sub-pixel
//! differences) and compared by where they are light or dark (rank correlation of block
//! luminance) and by which colour each part is (block chromaticity). The same checks must
//! reject a mirrored picture and another scene's picture, so they can tell scenes apart.
//!
//! With `RING_TRACER_SPD_COMPARE=DIR` the test also writes, for each scene, `DIR/NAME.png`
//! (the SPD's picture on the left, ours on the right) and all of them, halved, in
//! `DIR/all.png`.

use ring_tracer_kernel::film::from_srgb;
use ring_tracer_kernel::glam::Vec3A;
use ring_tracer_kernel::{encode_png, render_image, to_srgb8, Scene, Settings};
use std::path::{Path, PathBuf};

const SCENES: [(&str, &str); 7] = [
    ("balls_s4", "balls"),
    ("gears_s4", "gears"),
    ("mount_s6", "mount"),
    ("rings_s7", "rings"),
    ("teapot_s6", "teapot"),
    ("tetra_s6", "tetra"),
    ("tree_s11", "tree"),
];
const SIZE: usize = 512;
const BLOCK: usize = 8;
const SMALL: usize = SIZE / BLOCK;

fn spd_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes/spd")
}

/// The reference picture as 8-bit RGB rows.
fn reference(name: &str) -> Vec<u8> {
    let file = std::fs::File::open(spd_dir().join("reference").join(format!("{name}.png")))
        .expect("reference picture");
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().expect("PNG header");
    let mut buf = vec![0; reader.output_buffer_size().expect("buffer size")];
    let info = reader.next_frame(&mut buf).expect("PNG data");
    assert_eq!((info.width as usize, info.height as usize), (SIZE, SIZE));
    let channels = info.color_type.samples();
    buf[..info.buffer_size()]
        .chunks_exact(channels)
        .flat_map(|px| match channels {
            1 | 2 => [px[0], px[0], px[0]],
            _ => [px[0], px[1], px[2]],
        })
        .collect()
}

/// Our picture, rendered the SPD way (depth 5, pixel corners averaged), as 8-bit sRGB, lit as
/// the SPD's pictures are (each of n lights at 1 / sqrt(n), no ambient: what the SPD's own
/// POV-Ray export writes) rather than with the Readme's relative intensities (half of that, and
/// as much ambient) that we use by default.
fn ours(scene: &str) -> Vec<u8> {
    let mut scene = Scene::load(&spd_dir().join(format!("{scene}.nff"))).expect("SPD scene loads");
    let n = scene.light_count() as f32;
    scene.relight(Vec3A::ZERO, Vec3A::splat(1.0 / n.sqrt()));
    let settings = Settings {
        width: SIZE as u32,
        height: SIZE as u32,
        spd: true,
        ..Settings::for_scene(&scene)
    };
    let (rgb, _) = render_image(&scene, &settings, 2).expect("renders");
    to_srgb8(&rgb)
}

/// 8 x 8 block means, per channel, in 0..1.
fn reduce(rgb: &[u8]) -> Vec<f64> {
    let mut out = vec![0.0; SMALL * SMALL * 3];
    for y in 0..SIZE {
        for x in 0..SIZE {
            for c in 0..3 {
                out[((y / BLOCK) * SMALL + x / BLOCK) * 3 + c] +=
                    rgb[(y * SIZE + x) * 3 + c] as f64;
            }
        }
    }
    let n = (BLOCK * BLOCK) as f64 * 255.0;
    out.iter().map(|v| v / n).collect()
}

fn mirrored(rgb: &[u8]) -> Vec<u8> {
    (0..SIZE * SIZE)
        .flat_map(|i| {
            let (y, x) = (i / SIZE, i % SIZE);
            let j = (y * SIZE + SIZE - 1 - x) * 3;
            [rgb[j], rgb[j + 1], rgb[j + 2]]
        })
        .collect()
}

/// Ranks of `v` (ties broken by position; enough for block means).
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    for (rank, i) in idx.into_iter().enumerate() {
        r[i] = rank as f64;
    }
    r
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (ma, mb) = (mean(a), mean(b));
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt().max(1e-12)
}

/// (rank correlation of block luminance, mean difference of block chromaticity).
///
/// Light intensities and the ambient term are the renderer's choice in the SPD (ours follow its
/// Readme: `sqrt(n) / 2n` for both; its pictures use 1 and 0), so the comparison leaves out
/// absolute brightness: it ranks the blocks by luminance (where the picture is light or dark)
/// and compares their chromaticity `rgb / (r + g + b)` (which colour each part is).
fn compare(a: &[u8], b: &[u8]) -> (f64, f64) {
    let (a, b) = (reduce(a), reduce(b));
    let luma = |v: &[f64]| -> Vec<f64> {
        v.chunks_exact(3)
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .collect()
    };
    let chroma = |v: &[f64]| -> Vec<[f64; 3]> {
        v.chunks_exact(3)
            .map(|p| {
                let s = (p[0] + p[1] + p[2]).max(1e-3);
                [p[0] / s, p[1] / s, p[2] / s]
            })
            .collect()
    };
    let rho = correlation(&ranks(&luma(&a)), &ranks(&luma(&b)));
    let (ca, cb) = (chroma(&a), chroma(&b));
    let dc = ca
        .iter()
        .zip(&cb)
        .map(|(x, y)| (0..3).map(|c| (x[c] - y[c]).abs()).sum::<f64>())
        .sum::<f64>()
        / ca.len() as f64;
    (rho, dc)
}

fn looks_alike((rho, dc): (f64, f64)) -> bool {
    rho > MIN_RANK_CORRELATION && dc < MAX_CHROMA_DIFF
}

const MIN_RANK_CORRELATION: f64 = 0.88;
const MAX_CHROMA_DIFF: f64 = 0.1;

/// One row: the SPD's picture and ours, as 8-bit sRGB, `scale` times smaller.
fn side_by_side(reference: &[u8], ours: &[u8], scale: usize) -> Vec<u8> {
    let w = SIZE / scale;
    let mut row = Vec::with_capacity(w * w * 2 * 3);
    for y in 0..w {
        for img in [reference, ours] {
            for x in 0..w {
                for c in 0..3 {
                    let mut sum = 0u32;
                    for dy in 0..scale {
                        for dx in 0..scale {
                            sum += img[((y * scale + dy) * SIZE + x * scale + dx) * 3 + c] as u32;
                        }
                    }
                    row.push((sum / (scale * scale) as u32) as u8);
                }
            }
        }
    }
    row
}

fn write_png(path: &Path, width: usize, height: usize, srgb: &[u8]) {
    // `encode_png` takes linear light: decode the sRGB bytes exactly first.
    let linear: Vec<f32> = srgb.iter().map(|&v| from_srgb(v as f32 / 255.0)).collect();
    let png = encode_png(width as u32, height as u32, &linear).expect("encodes");
    std::fs::write(path, png).expect("writes");
}

#[test]
#[ignore = "slow in debug builds; run with --release -- --include-ignored"]
fn spd_scenes_look_like_the_spd_pictures() {
    let dump = std::env::var_os("RING_TRACER_SPD_COMPARE").map(PathBuf::from);
    let mut failures = Vec::new();
    let mut previous: Option<(&str, Vec<u8>)> = None;
    let mut all = Vec::new();
    for (scene, name) in SCENES {
        let (want, got) = (reference(name), ours(scene));
        let same = compare(&want, &got);
        let flipped = compare(&want, &mirrored(&got));
        println!(
            "{name}: luminance rank correlation {:.3}, chromaticity difference {:.4}; mirrored: {:.3}, {:.4}",
            same.0, same.1, flipped.0, flipped.1
        );
        if !looks_alike(same) {
            failures.push(format!(
                "{name} does not look like the SPD picture: {same:?}"
            ));
        }
        if looks_alike(flipped) {
            failures.push(format!(
                "{name}: the check cannot tell a mirrored picture: {flipped:?}"
            ));
        }
        if let Some((other, pixels)) = &previous {
            let cross = compare(&want, pixels);
            if looks_alike(cross) {
                failures.push(format!("{name} looks like our {other}: {cross:?}"));
            }
        }
        if let Some(dir) = &dump {
            std::fs::create_dir_all(dir).expect("dump dir");
            let one = side_by_side(&want, &got, 1);
            write_png(&dir.join(format!("{name}.png")), 2 * SIZE, SIZE, &one);
            all.extend(side_by_side(&want, &got, 2));
        }
        previous = Some((name, got));
    }
    if let Some(dir) = &dump {
        write_png(&dir.join("all.png"), SIZE, SIZE / 2 * SCENES.len(), &all);
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
