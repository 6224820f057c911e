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
    // SAFETY: `rusage` is a C struct of plain integers (two timevals and longs), for which all
    // zeros is a valid value.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage only writes the struct it is given, which lives on this stack and is
    // of the type it expects; RUSAGE_SELF is a valid `who`.
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

#[cfg(test)]
mod tests {
    use super::cpu_seconds;

    #[test]
    fn cpu_seconds_count_this_process_work() {
        let before = cpu_seconds();
        assert!(before > 0.0, "{before} s");
        let t = std::time::Instant::now();
        let mut x = 1u64;
        // busy until 20 ms of CPU time show, within 20 s of the wall clock even on busy cores
        while cpu_seconds() - before < 0.02 {
            assert!(t.elapsed().as_secs() < 20, "no CPU time counted");
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
            }
        }
        // no more CPU than wall time on this thread (the test harness's other threads idle or
        // on the other core)
        assert!(cpu_seconds() - before <= 2.0 * t.elapsed().as_secs_f64() + 0.02);
    }
}
