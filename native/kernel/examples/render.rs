//! Renders a scene file to an image: `cargo run --release --example render -- scene.nff out.png
//! [--spd] [--samples S] [--threads N] [--size WxH] [--depth D] [--frame N]`; `--frame`: frame N
//! (from 0) of an animated scene (default: the first).

use ring_tracer_kernel::{render_image, write_image, AnimatedScene, Settings};
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: render SCENE OUT.png|OUT.exr [--spd] [--samples S] [--threads N] [--size WxH] [--depth D] [--frame N]");
        std::process::exit(2);
    }
    let t0 = Instant::now();
    let frame: u32 = match args.iter().position(|a| a == "--frame") {
        Some(i) => args
            .get(i + 1)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| {
                eprintln!("--frame takes a frame number (from 0)");
                std::process::exit(2);
            }),
        None => 0,
    };
    let scene = match AnimatedScene::load(Path::new(&args[0])).and_then(|a| a.frame(frame)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let setup = t0.elapsed().as_secs_f64();
    let mut settings = Settings::for_scene(&scene);
    let mut threads = 2;
    let mut i = 2;
    while i < args.len() {
        let val = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--spd" => {
                settings.spd = true;
                i += 1;
                continue;
            }
            "--frame" => {} // read above
            "--samples" => settings.samples = val.parse().unwrap_or(1),
            "--threads" => threads = val.parse().unwrap_or(2),
            "--depth" => settings.depth = val.parse().unwrap_or(5),
            "--size" => {
                let mut it = val.split('x');
                settings.width = it.next().and_then(|v| v.parse().ok()).unwrap_or(512);
                settings.height = it.next().and_then(|v| v.parse().ok()).unwrap_or(512);
            }
            other => {
                eprintln!("unknown option {other}");
                std::process::exit(2);
            }
        }
        i += 2;
    }
    let t1 = Instant::now();
    let (rgb, stats) = match render_image(&scene, &settings, threads) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let trace = t1.elapsed().as_secs_f64();
    if let Err(e) = write_image(Path::new(&args[1]), settings.width, settings.height, &rgb) {
        eprintln!("{e}");
        std::process::exit(1);
    }
    println!(
        "{}: {} prims ({} stored, {} mesh instances), setup {:.3}s, trace {:.3}s, {:?}",
        args[0],
        scene.primitive_count(),
        scene.stored_primitive_count(),
        scene.instance_count(),
        setup,
        trace,
        stats
    );
}
