//! The full-size instancing case: a 2 MB OBJ referenced 3000 times loads as one mesh and 3000
//! instances, and renders. `cargo test --release -p ring_tracer_kernel --test instancing --
//! --include-ignored` (well under a second in release; memory is measured with the
//! `instances` example, see examples/instances/main.rs).

#[path = "../examples/instances/gen.rs"]
mod gen;

use ring_tracer_kernel::{render_image, Scene, Settings};

#[test]
#[ignore = "full size, slow in debug builds; run with --release -- --include-ignored"]
fn full_size_mesh_referenced_3000_times() {
    let dir = tempfile::tempdir().unwrap();
    let path = gen::write_scene(dir.path(), 3000, 64, 48).unwrap();
    let obj = std::fs::metadata(dir.path().join("sphere.obj"))
        .unwrap()
        .len();
    assert!((1_900_000..2_200_000).contains(&obj), "{obj} bytes");
    let t0 = std::time::Instant::now();
    let scene = Scene::load(&path).unwrap();
    let load = t0.elapsed();
    let tris = gen::sphere_triangles(gen::LON, gen::LAT);
    // one mesh stored, 3000 instances of it, and the floor
    assert_eq!(scene.mesh_count(), 1);
    assert_eq!(scene.instance_count(), 3000);
    assert_eq!(scene.internal_primitive_count(), 1);
    assert_eq!(scene.stored_primitive_count(), 1 + tris);
    assert_eq!(scene.primitive_count(), 1 + 3000 * tris);
    let settings = Settings::for_scene(&scene);
    let t1 = std::time::Instant::now();
    let (rgb, stats) = render_image(&scene, &settings, 2).unwrap();
    let trace = t1.elapsed();
    assert_eq!(rgb.len(), 64 * 48 * 3);
    assert_eq!(stats.eye, 64 * 48);
    assert!(stats.eye_hits == stats.eye && stats.shadow > 0 && stats.reflected > 0);
    // the spheres are lit: some pixel is brighter than the ambient floor
    assert!(rgb.iter().any(|&v| v > 0.5));
    eprintln!("load {load:?}, trace {trace:?}, {stats:?}");
}
