//! Renders one large polygon through the NFF reader:
//! `cargo run --release -p ring_tracer_kernel --example polygon -- [--vertices N] [--threads T]
//! [--png OUT.png] [--nff OUT.nff]`.
//!
//! The scene is written as NFF text in memory (`--nff` also saves it, for `examples/render` or
//! the app): a 512x512 view of a tilted, concave flower-shaped `p` polygon of N vertices
//! (default 1,000,000; at most `limits::MAX_POLYGON_VERTICES`), a mirror sphere above it and
//! one light. Prints the set-up (parse + build) and trace times, the ray counts and an FNV-1a
//! hash of the image's f32 bits, so two builds can be checked to draw the same image.

use ring_tracer_kernel::{render_image, write_image, Format, Scene, Settings};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

fn scene_text(n: usize) -> String {
    let mut s = String::with_capacity(n * 40 + 512);
    s.push_str(
        "v\nfrom 0 -0.6 2.6\nat 0 0 0\nup 0 1 0\nangle 45\nhither 0.01\nresolution 512 512\n\
         b 0.05 0.05 0.1\nl 2 -1 4\n\
         f 0.9 0.9 0.9 0 1 1000 0 0\ns 0.25 0.1 0.45 0.2\n\
         f 0.9 0.5 0.2 0.8 0.2 20 0 0\n",
    );
    let _ = writeln!(s, "p {n}");
    // r(a) = 0.75 + 0.2 cos 9a + 0.03 cos 150a, in a plane tilted 30 degrees about x
    let (sin_t, cos_t) = 30f64.to_radians().sin_cos();
    for i in 0..n {
        let a = i as f64 / n as f64 * std::f64::consts::TAU;
        let r = 0.75 + 0.2 * (9.0 * a).cos() + 0.03 * (150.0 * a).cos();
        let (x, y) = (r * a.cos(), r * a.sin());
        let _ = writeln!(s, "{:.7} {:.7} {:.7}", x, y * cos_t, y * sin_t);
    }
    s
}

fn fnv1a(rgb: &[f32]) -> u64 {
    rgb.iter()
        .flat_map(|v| v.to_bits().to_le_bytes())
        .fold(0xcbf2_9ce4_8422_2325, |h, b| {
            (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
        })
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mut n, mut threads, mut png, mut nff) = (1_000_000usize, 2usize, None, None);
    let mut i = 0;
    while i < args.len() {
        let val = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--vertices" => n = val.parse().unwrap_or(n),
            "--threads" => threads = val.parse().unwrap_or(threads),
            "--png" => png = Some(val),
            "--nff" => nff = Some(val),
            other => {
                eprintln!("unknown option {other}; usage: polygon [--vertices N] [--threads T] [--png OUT.png] [--nff OUT.nff]");
                std::process::exit(2);
            }
        }
        i += 2;
    }
    let text = scene_text(n.max(3));
    if let Some(path) = &nff {
        if let Err(e) = std::fs::write(path, &text) {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        }
    }
    let t0 = Instant::now();
    let no_files = |_: &str| Err("no files".into());
    let scene = match Scene::parse(text.as_bytes(), Format::Nff, "polygon.nff", &no_files) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let setup = t0.elapsed().as_secs_f64();
    let settings = Settings::for_scene(&scene);
    let t1 = Instant::now();
    let (rgb, stats) = match render_image(&scene, &settings, threads) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let trace = t1.elapsed().as_secs_f64();
    if let Some(path) = &png {
        if let Err(e) = write_image(Path::new(path), settings.width, settings.height, &rgb) {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
    println!(
        "{n} vertices, {}x{}, {threads} threads: setup {setup:.3}s, trace {trace:.3}s, \
         image hash {:016x}, {stats:?}",
        settings.width,
        settings.height,
        fnv1a(&rgb)
    );
}
