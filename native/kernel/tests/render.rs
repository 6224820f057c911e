//! End-to-end tests: golden pixels, determinism across spans and threads, image round trips.

use ring_tracer_kernel::files::Unreadable;
use ring_tracer_kernel::{
    encode_png, render_image, to_srgb8, trace_span, trace_span_into, work_by_row, write_image,
    Format, RayStats, Region, Scene, Settings,
};

fn no_files(_: &str) -> Result<Vec<u8>, Unreadable> {
    Err("no files".into())
}

fn nff(src: &str) -> Scene {
    Scene::parse(src.as_bytes(), Format::Nff, "test.nff", &no_files).expect("scene parses")
}

/// 8x6 image, 45 degrees over the 6 rows (centre to centre): the 1x1 half-size square at z = 0
/// covers exactly pixels x = 3, 4 and y = 2, 3; a small green sphere covers pixel (0, 0) only.
/// Light at the eye: the four square pixels all see N.L = 1/sqrt(1 + 0.5 s^2) with
/// s = 2 tan(22.5 deg) / 5, so colour = C * (0.5 ambient * Kd 1 + 0.5 * 0.993206) = C * 0.996603
/// = (0.996603, 0.498301, 0.249151). NFF colours are display values, so the 8-bit pixel is
/// round(255 v): (254, 127, 64). The sphere has Kd 0 and Ks 0: no ambient either, black.
/// Background (0.2, 0.4, 0.6) -> (51, 102, 153).
const GOLDEN: &str = "b 0.2 0.4 0.6
v
from 0 0 5
at 0 0 0
up 0 1 0
angle 45
hither 1
resolution 8 6
l 0 0 5
f 1 0.5 0.25 1 0 0 0 1
p 4
-1 -1 0
1 -1 0
1 1 0
-1 1 0
f 0 1 0 0 0 0 0 1
s -2.9 2.07 0 0.3
";

#[test]
fn golden_8x6() {
    let scene = nff(GOLDEN);
    let settings = Settings::for_scene(&scene);
    assert_eq!((settings.width, settings.height), (8, 6));
    let (rgb, stats) = render_image(&scene, &settings, 2).unwrap();
    let px = to_srgb8(&rgb);
    for y in 0..6 {
        for x in 0..8 {
            let i = (y * 8 + x) * 3;
            let got = [px[i], px[i + 1], px[i + 2]];
            let want = if (3..=4).contains(&x) && (2..=3).contains(&y) {
                [254, 127, 64]
            } else if x == 0 && y == 0 {
                [0, 0, 0]
            } else {
                [51, 102, 153]
            };
            assert_eq!(got, want, "pixel ({x}, {y})");
        }
    }
    assert_eq!(
        rays(stats),
        RayStats {
            eye: 48,
            eye_hits: 5,
            reflected: 0,
            refracted: 0,
            shadow: 5,
            work: 0
        }
    );
    // every ray is one unit, and the square and the sphere took box and primitive tests
    assert!(stats.work > stats.total());
}

/// A span's work: one unit per ray plus every BVH node visited and primitive tested, so the
/// same pixels cost more work in front of more geometry, and nothing but the rays in front of
/// none.
#[test]
fn work_follows_the_geometry_rays_pass_through() {
    let header = GOLDEN.split("f 1 0.5").next().unwrap_or_default();
    let empty = nff(header);
    let settings = Settings::for_scene(&empty);
    let (_, bare) = trace_span(&empty, &settings, 0, 48).unwrap();
    assert_eq!(bare.work, bare.total());
    let crowded = (0..40).fold(GOLDEN.to_string(), |src, i| {
        src + &format!(
            "s {} {} -1 0.1\n",
            (i % 8) as f32 * 0.6 - 2.1,
            (i / 8) as f32 * 0.6 - 1.2
        )
    });
    let (_, few) = trace_span(&nff(GOLDEN), &settings, 0, 48).unwrap();
    let (_, many) = trace_span(&nff(&crowded), &settings, 0, 48).unwrap();
    assert_eq!(few.eye, many.eye);
    assert!(
        few.work > bare.work && many.work > few.work,
        "{bare:?} {few:?} {many:?}"
    );
}

#[test]
fn work_by_row_sums_to_the_image_and_finds_the_crowded_rows() {
    let scene = nff(GOLDEN);
    let settings = Settings::for_scene(&scene);
    let rows = work_by_row(&scene, &settings).unwrap();
    assert_eq!(rows.len(), 6);
    let (_, whole) = trace_span(&scene, &settings, 0, 48).unwrap();
    assert_eq!(rows.iter().sum::<u64>(), whole.work);
    // the square covers rows 2 and 3 only: they cost more than the background rows
    assert!(rows[2] > rows[5] && rows[3] > rows[5], "{rows:?}");
    let bad = Settings {
        width: 0,
        ..settings
    };
    assert!(work_by_row(&scene, &bad).is_err());
}

const RICH: &str = "b 0.1 0.2 0.3
v
from 2.1 1.3 1.7
at 0 0 0
up 0 0 1
angle 45
hither 0.01
resolution 23 17
l 4 3 2
l 1 -4 4 0.5 0.6 0.7
f 1 0.75 0.33 0.8 0.1 20 0 1
p 4
12 12 -0.5
-12 12 -0.5
-12 -12 -0.5
12 -12 -0.5
f 1 0.9 0.7 0.5 0.5 3.0827 0 1
s 0 0 0 0.5
s 0.272166 0.272166 0.544331 0.166667
f 1 1 1 0.1 0.1 50 0.9 1.5
s 0.643951 0.172546 0.1 0.166667
c 0.5 -0.5 0 0.1 0.5 -0.5 0.6 0.05
pp 3
-0.5 0.5 0 0 0 1
0 0.8 0 0.3 0 1
-0.7 0.9 0.1 0 0.3 1
";

fn check_splits(settings: &Settings) {
    let scene = nff(RICH);
    let n = settings.width as u64 * settings.height as u64;
    let (whole, whole_stats) = render_image(&scene, settings, 3).unwrap();
    let (one, one_stats) = render_image(&scene, settings, 1).unwrap();
    assert_eq!(bits(&whole), bits(&one));
    // the same chunks whatever the thread count: the same work too
    assert_eq!(whole_stats, one_stats);
    let (span, span_stats) = trace_span(&scene, settings, 0, n).unwrap();
    assert_eq!(bits(&whole), bits(&span));
    // rays do not depend on the split; work does a little (the shadow cache starts empty in
    // every span)
    assert_eq!(rays(whole_stats), rays(span_stats));
    // arbitrary uneven splits, including single pixels and spans crossing rows
    for cuts in [
        vec![1u64, 2, 30, 31, 100, 250],
        vec![7, 8, 9, 200, 390],
        vec![n / 2],
    ] {
        let mut pixels = Vec::new();
        let mut stats = RayStats::default();
        let mut start = 0;
        for &c in cuts.iter().chain(std::iter::once(&n)) {
            let (p, s) = trace_span(&scene, settings, start, c - start).unwrap();
            pixels.extend(p);
            stats += s;
            start = c;
        }
        assert_eq!(bits(&whole), bits(&pixels), "cuts {cuts:?}");
        assert_eq!(rays(whole_stats), rays(stats), "cuts {cuts:?}");
        // the same pieces traced in place into one buffer: every float written, none twice
        let mut buffer = vec![f32::NAN; whole.len()];
        let mut start = 0;
        for &c in cuts.iter().chain(std::iter::once(&n)) {
            let piece = &mut buffer[(start * 3) as usize..(c * 3) as usize];
            trace_span_into(&scene, settings, start, piece).unwrap();
            start = c;
        }
        assert_eq!(bits(&whole), bits(&buffer), "in place, cuts {cuts:?}");
    }
    assert!(whole_stats.eye_hits > 0 && whole_stats.shadow > 0);
    assert!(whole_stats.reflected > 0 && whole_stats.refracted > 0);
}

/// The ray counts alone.
fn rays(s: RayStats) -> RayStats {
    RayStats { work: 0, ..s }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|f| f.to_bits()).collect()
}

#[test]
fn deterministic_over_splits() {
    let scene = nff(RICH);
    let base = Settings::for_scene(&scene);
    check_splits(&base);
    check_splits(&Settings {
        samples: 2,
        ..base.clone()
    });
    let spd = Settings {
        spd: true,
        ..base.clone()
    };
    check_splits(&spd);
    // SPD mode shoots one eye ray per corner, (W+1)(H+1) in all
    let (_, s) = render_image(&scene, &spd, 2).unwrap();
    assert_eq!(s.eye, 24 * 18);
}

#[test]
fn span_arguments_checked() {
    let scene = nff(GOLDEN);
    let s = Settings::for_scene(&scene);
    assert!(trace_span(&scene, &s, 40, 9).is_err());
    assert!(trace_span_into(&scene, &s, 40, &mut [0.0; 27]).is_err());
    // a buffer must hold whole pixels
    assert!(trace_span_into(&scene, &s, 0, &mut [0.0; 4]).is_err());
    assert!(trace_span(&scene, &s, u64::MAX, 2).is_err());
    assert_eq!(trace_span(&scene, &s, 48, 0).unwrap().0.len(), 0);
    let bad = Settings {
        width: 100_000,
        ..s.clone()
    };
    assert!(trace_span(&scene, &bad, 0, 1).is_err());
    let bad = Settings {
        samples: 0,
        ..s.clone()
    };
    assert!(bad.validate().is_err());
    let bad = Settings {
        depth: 1000,
        ..s.clone()
    };
    assert!(matches!(
        bad.validate(),
        Err(ring_tracer_kernel::Error::Limit { .. })
    ));
}

#[test]
fn depth_limits_the_tree() {
    let scene = nff(RICH);
    let s = Settings {
        depth: 1,
        ..Settings::for_scene(&scene)
    };
    let (_, st) = render_image(&scene, &s, 2).unwrap();
    assert_eq!(st.reflected + st.refracted, 0);
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rt_kernel_test_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn png_roundtrip() {
    let (w, h) = (5u32, 3u32);
    let rgb: Vec<f32> = (0..w * h * 3).map(|i| i as f32 / 44.0).collect();
    let data = encode_png(w, h, &rgb).unwrap();
    let dec = png::Decoder::new(std::io::Cursor::new(data));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (w, h));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(&buf[..info.buffer_size()], to_srgb8(&rgb).as_slice());
    let path = tmp("round.png");
    write_image(&path, w, h, &rgb).unwrap();
    assert_eq!(
        std::fs::read(&path).unwrap(),
        encode_png(w, h, &rgb).unwrap()
    );
    assert!(encode_png(w, h, &rgb[1..]).is_err());
    assert!(write_image(&tmp("x.bmp"), w, h, &rgb).is_err());
}

#[test]
fn exr_roundtrip() {
    let (w, h) = (4u32, 3u32);
    let rgb: Vec<f32> = (0..w * h * 3).map(|i| i as f32 * 0.37 - 1.0).collect();
    let path = tmp("round.exr");
    write_image(&path, w, h, &rgb).unwrap();
    let img = exr::prelude::read_first_rgba_layer_from_file(
        &path,
        |res, _| vec![0.0f32; res.width() * res.height() * 3],
        move |px: &mut Vec<f32>, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = (pos.y() * 4 + pos.x()) * 3;
            px[i] = r;
            px[i + 1] = g;
            px[i + 2] = b;
        },
    )
    .unwrap();
    assert_eq!(img.layer_data.channel_data.pixels, rgb);
}

#[test]
fn whitted_toml_scene_loads() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes/whitted.toml");
    let scene = Scene::load(&path).unwrap();
    assert_eq!(scene.resolution(), (640, 480));
    assert_eq!(scene.primitive_count(), 3);
    let s = Settings {
        width: 32,
        height: 24,
        ..Settings::for_scene(&scene)
    };
    let (rgb, st) = render_image(&scene, &s, 2).unwrap();
    assert!(rgb.iter().all(|v| v.is_finite()));
    assert!(st.refracted > 0 && st.reflected > 0);
}

#[test]
fn obj_scene_and_format() {
    assert_eq!(Format::from_path("a/b.NFF").unwrap(), Format::Nff);
    assert_eq!(Format::from_path("x.toml").unwrap(), Format::Toml);
    assert_eq!(Format::from_path("x.obj").unwrap(), Format::Obj);
    let e = Format::from_path("scene.txt").unwrap_err().to_string();
    assert!(e.contains("scene.txt"), "{e}");
    let obj = "mtllib m.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nusemtl red\nf 1 2 3 4\n";
    let mtl = "newmtl red\nKd 1 0 0\n";
    let resolve = |p: &str| -> Result<Vec<u8>, Unreadable> {
        if p == "m.mtl" {
            Ok(mtl.as_bytes().to_vec())
        } else {
            Err("missing".into())
        }
    };
    let scene = Scene::parse(obj.as_bytes(), Format::Obj, "q.obj", &resolve).unwrap();
    assert_eq!(scene.primitive_count(), 2);
    let s = Settings {
        width: 9,
        height: 9,
        ..Settings::for_scene(&scene)
    };
    let (rgb, _) = trace_span(&scene, &s, 40, 1).unwrap();
    assert!(rgb[0] > 0.3 && rgb[1] == 0.0 && rgb[2] == 0.0, "{rgb:?}");
    assert!(Scene::parse(b"f 1 2 3\n", Format::Obj, "bad.obj", &no_files).is_err());
    assert!(Scene::parse(
        b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        Format::Obj,
        "nan.obj",
        &no_files
    )
    .is_err());
}

/// A region traces exactly the whole render's pixels there, in every mode (pixel centres, jittered
/// samples, SPD corners), whatever spans it is cut into.
#[test]
fn a_region_gives_exactly_the_whole_renders_pixels() {
    let scene = nff(GOLDEN);
    let r = Region {
        x0: 2,
        y0: 1,
        width: 5,
        height: 4,
    };
    for (samples, spd) in [(1, false), (2, false), (1, true)] {
        let whole = Settings {
            samples,
            spd,
            ..Settings::for_scene(&scene)
        };
        let (full, _) = render_image(&scene, &whole, 1).unwrap();
        let part = Settings {
            region: Some(r),
            ..whole.clone()
        };
        let (region, _) = render_image(&scene, &part, 2).unwrap();
        let mut expected = Vec::new();
        for y in r.y0..r.y0 + r.height {
            let from = ((y * whole.width + r.x0) * 3) as usize;
            expected.extend_from_slice(&full[from..from + r.width as usize * 3]);
        }
        assert_eq!(region, expected, "samples {samples}, spd {spd}");
        // cut into odd spans that cross the region's rows
        let mut pieces = Vec::new();
        let mut start = 0;
        for count in [3u64, 7, 1, 9] {
            pieces.extend(trace_span(&scene, &part, start, count).unwrap().0);
            start += count;
        }
        assert_eq!(pieces, expected);
    }
}

#[test]
fn a_region_outside_the_image_is_refused() {
    let scene = nff(GOLDEN);
    let s = Settings {
        region: Some(Region {
            x0: 6,
            y0: 0,
            width: 3,
            height: 1,
        }),
        ..Settings::for_scene(&scene)
    };
    let e = trace_span(&scene, &s, 0, 1).unwrap_err().to_string();
    assert!(e.contains("not inside the 8x6 image"), "{e}");
}
