//! Benchmarks.
//!
//! `cargo run --release --example bench -- scene.nff [more.nff ...]`: for each scene, set-up time
//! (parse + BVH) and trace time at 512x512 with 2 threads, depth 5, no antialiasing, both with
//! pixel-centre rays and the default cut-off, and in SPD corner mode (513x513 rays, no cut-off).
//!
//! Ray casting alone, ours next to Embree's on the same rays
//! ([`ring_tracer_kernel::raysets`]), is `cargo run --release -p ring_tracer_embree_bench --
//! mesh.obj` (`mix ring_tracer.bench rays`).

use ring_tracer_kernel::{render_image, Scene, Settings};
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() {
        eprintln!("usage: bench SCENE.nff...");
        std::process::exit(2);
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
