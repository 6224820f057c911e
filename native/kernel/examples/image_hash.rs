//! Pixel hashes and trace times of whole renders, for checking that a kernel change keeps every
//! image bit for bit: `cargo run --release --example image_hash -- [--size N] [--runs R]
//! [--threads T] scene.nff ...`. For each scene it prints an FNV-1a hash of the f32 pixels'
//! bits, the ray counts, and the fastest and median trace time of `runs` renders with `threads`
//! threads, and the median CPU time of a render (all threads; steadier on a busy machine), with
//! the settings of `mix ring_tracer.bench kernel` (depth 5, cut-off 1/255, one sample).
//! Every run must give the same hash; the example exits 1 if one does not.

use ring_tracer_kernel::{render_image, Scene, Settings};
use std::path::Path;
use std::time::Instant;

fn fnv(pixels: &[f32]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in pixels {
        for b in v.to_bits().to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// CPU seconds (user + system) the process has used, all threads: on a busy machine a steadier
/// figure than the wall clock.
fn cpu_seconds() -> f64 {
    // SAFETY: getrusage only writes the struct it is given, which lives on this stack.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: as above; RUSAGE_SELF is a valid `who`.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return 0.0;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut size, mut runs, mut threads) = (512u32, 1usize, 2usize);
    let mut scenes = Vec::new();
    while let Some(a) = args.next() {
        let mut num = || args.next().and_then(|v| v.parse().ok()).unwrap_or(1);
        match a.as_str() {
            "--size" => size = num() as u32,
            "--runs" => runs = num().max(1),
            "--threads" => threads = num().max(1),
            _ => scenes.push(a),
        }
    }
    let mut failed = false;
    for path in &scenes {
        let scene = match Scene::load(Path::new(path)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{path}: {e}");
                std::process::exit(1);
            }
        };
        let settings = Settings::new(size, size);
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        let mut first = None;
        for _ in 0..runs {
            let (t, c) = (Instant::now(), cpu_seconds());
            let (px, stats) = render_image(&scene, &settings, threads).expect("render");
            times.push(t.elapsed().as_secs_f64());
            cpu.push(cpu_seconds() - c);
            let h = fnv(&px);
            match first {
                None => first = Some((h, stats)),
                Some((h0, _)) if h0 != h => failed = true,
                _ => {}
            }
        }
        times.sort_by(f64::total_cmp);
        cpu.sort_by(f64::total_cmp);
        let (h, s) = first.expect("one run");
        let name = Path::new(path).file_stem().unwrap_or_default();
        println!(
            "{:>11} {h:016x} eye {} hits {} shadow {} refl {} refr {} work {}  min {:.4} med {:.4} cpu {:.4}",
            name.to_string_lossy(),
            s.eye,
            s.eye_hits,
            s.shadow,
            s.reflected,
            s.refracted,
            s.work,
            times[0],
            times[times.len() / 2],
            cpu[cpu.len() / 2]
        );
    }
    if failed {
        eprintln!("a scene's runs gave different pixels");
        std::process::exit(1);
    }
}
