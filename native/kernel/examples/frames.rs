//! What the frames of an animated scene cost to make (not to trace): `cargo run --release
//! --example frames -- SCENE.toml`. Prints the load, then the frames' mean and worst build
//! time and how many share the first frame's BVH (or its primitives and mesh BVHs).

use ring_tracer_kernel::AnimatedScene;
use std::path::Path;
use std::time::Instant;

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: frames SCENE");
        std::process::exit(2);
    };
    let t0 = Instant::now();
    let scene = match AnimatedScene::load(Path::new(&path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let load = t0.elapsed().as_secs_f64();
    let a = scene.animation();
    println!(
        "{path}: load {:.3} ms, {} frames, clock {:?}, cyclic {}, objects move: {}, \
         frames rebuild their primitives: {}",
        load * 1e3,
        a.frames(),
        a.clock_range(),
        a.cyclic(),
        scene.moves_objects(),
        scene.rebuilds_primitives()
    );
    let (mut total, mut worst, mut shared, mut primitives) = (0.0f64, 0.0f64, 0, 0);
    for n in 0..a.frames() {
        let t = Instant::now();
        let frame = match scene.frame(n) {
            Ok(f) => f,
            Err(e) => {
                eprintln!("frame {n}: {e}");
                std::process::exit(1);
            }
        };
        let dt = t.elapsed().as_secs_f64();
        total += dt;
        worst = worst.max(dt);
        if frame.shares_geometry_with(scene.first_frame()) {
            shared += 1;
        }
        if frame.shares_primitives_with(scene.first_frame()) {
            primitives += 1;
        }
    }
    println!(
        "frames: mean {:.1} us, worst {:.1} us; of {}, {shared} share the first frame's BVH, \
         {primitives} its primitives and mesh BVHs",
        total / a.frames() as f64 * 1e6,
        worst * 1e6,
        a.frames()
    );
}
