//! Benchmarks.
//!
//! `cargo run --release --example bench -- scene.nff [more.nff ...]`: for each scene, set-up time
//! (parse + BVH) and trace time at 512x512 with 2 threads, depth 5, no antialiasing, both with
//! pixel-centre rays and the default cut-off, and in SPD corner mode (513x513 rays, no cut-off).
//!
//! `cargo run --release --example bench -- --raycast mesh.obj`: closest-hit ray casting only:
//! BVH build time, then 1024x1024 primary rays from a 45-degree pinhole looking at the bounding
//! box centre from `centre + (0.3, 0.3, 1.1) * diagonal` (+y up), and 1,048,576 incoherent rays
//! (origins uniform in the central half of the box, directions uniform on the sphere, fixed
//! seed), each with 1 and 2 threads ([`ring_tracer_kernel::raysets`]). Next to Embree:
//! `cargo run --release -p ring_tracer_embree_bench -- mesh.obj`.

use ring_tracer_kernel::{raysets, render_image, Ray, Scene, Scratch, Settings};
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() {
        eprintln!("usage: bench SCENE.nff... | bench --raycast MESH.obj");
        std::process::exit(2);
    }
    if args[0] == "--raycast" {
        for a in &args[1..] {
            raycast(a);
        }
        return;
    }
    println!(
        "{:<14} {:>7} {:>8} {:>9} {:>8} {:>9} {:>8}",
        "scene", "prims", "setup_s", "trace_s", "Mrays/s", "spd_s", "Mrays/s"
    );
    for a in &args {
        let t0 = Instant::now();
        let scene = match Scene::load(Path::new(a)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{e}");
                continue;
            }
        };
        let setup = t0.elapsed().as_secs_f64();
        let base = Settings {
            width: 512,
            height: 512,
            depth: 5,
            samples: 1,
            ..Settings::for_scene(&scene)
        };
        let spd = Settings {
            spd: true,
            ..base.clone()
        };
        let mut row = Vec::new();
        for s in [&base, &spd] {
            // best of 3
            let mut best = f64::INFINITY;
            let mut rays = 0;
            for _ in 0..3 {
                let t = Instant::now();
                let (_, st) = render_image(&scene, s, 2).expect("render");
                best = best.min(t.elapsed().as_secs_f64());
                rays = st.total();
            }
            row.push((best, rays as f64 / best / 1e6));
        }
        let name = Path::new(a)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        println!(
            "{:<14} {:>7} {:>8.3} {:>9.3} {:>8.2} {:>9.3} {:>8.2}",
            name,
            scene.primitive_count(),
            setup,
            row[0].0,
            row[0].1,
            row[1].0,
            row[1].1
        );
    }
}

fn cast(scene: &Scene, rays: &[Ray], threads: usize) -> (f64, u64) {
    let t = Instant::now();
    let chunk = rays.len().div_ceil(threads * 64).max(1);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let hits: u64 = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut hits = 0u64;
                    let mut scratch = Scratch::new();
                    loop {
                        let c = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(part) = rays.chunks(chunk).nth(c) else {
                            break;
                        };
                        for r in part {
                            if scene
                                .intersect_with(r, f32::INFINITY, &mut scratch)
                                .is_some()
                            {
                                hits += 1;
                            }
                        }
                    }
                    hits
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap_or(0)).sum()
    });
    (t.elapsed().as_secs_f64(), hits)
}

fn raycast(path: &str) {
    let t0 = Instant::now();
    let scene = match Scene::load(Path::new(path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return;
        }
    };
    let build = t0.elapsed().as_secs_f64();
    let b = scene.bounds();
    println!(
        "{path}: {} triangles, load + BVH build {:.3} s",
        scene.primitive_count(),
        build
    );
    let primary = raysets::primary(b, 1024);
    let incoherent = raysets::incoherent(b, primary.len());
    for (name, rays) in [("primary", &primary), ("incoherent", &incoherent)] {
        for threads in [1, 2] {
            let mut best = f64::INFINITY;
            let mut hits = 0;
            for _ in 0..3 {
                let (t, h) = cast(&scene, rays, threads);
                best = best.min(t);
                hits = h;
            }
            println!(
                "  {name:<10} {threads} thread(s): {:>7.2} Mrays/s  ({} rays, {hits} hits, {:.3} s)",
                rays.len() as f64 / best / 1e6,
                rays.len(),
                best
            );
        }
    }
}
