//! Writes a scene that references one mesh many times: `sphere.obj` (a tessellated sphere,
//! 30 400 triangles, 2.0 MB) and `instances.toml` referencing it REFS times (default 3000)
//! at WxH (default 160x120), into DIR. Render it with the `render` example, e.g. to see what
//! loading costs:
//!
//! ```text
//! cd native
//! cargo run --release -p ring_tracer_kernel --example instances -- /tmp/inst 3000 160x120
//! cargo build --release -p ring_tracer_kernel --example render
//! /usr/bin/time -v target/release/examples/render /tmp/inst/instances.toml /tmp/inst/out.png
//! ```
//!
//! The test `full_size_mesh_referenced_3000_times` (tests/instancing.rs, run with
//! `--include-ignored`) loads and renders the same scene.

mod gen;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(dir) = args.first() else {
        eprintln!("usage: instances DIR [REFS] [WxH]");
        std::process::exit(2);
    };
    let refs = args.get(1).and_then(|v| v.parse().ok()).unwrap_or(3000);
    let size = args.get(2).map_or("160x120", String::as_str);
    let mut it = size.split('x').map(|v| v.parse::<u32>().ok());
    let (Some(Some(w)), Some(Some(h))) = (it.next(), it.next()) else {
        eprintln!("size must be WxH, got {size}");
        std::process::exit(2);
    };
    let dir = std::path::Path::new(dir);
    if let Err(e) = std::fs::create_dir_all(dir) {
        eprintln!("{}: {e}", dir.display());
        std::process::exit(1);
    }
    match gen::write_scene(dir, refs, w, h) {
        Ok(scene) => {
            let obj = std::fs::metadata(dir.join("sphere.obj")).map_or(0, |m| m.len());
            println!(
                "{}: {refs} references of sphere.obj ({} triangles, {obj} bytes), {w}x{h}",
                scene.display(),
                gen::sphere_triangles(gen::LON, gen::LAT),
            );
        }
        Err(e) => {
            eprintln!("{}: {e}", dir.display());
            std::process::exit(1);
        }
    }
}
