//! SPD testing procedure: ray counts at the standard sizes must match the table in the SPD's
//! Readme.txt within 10%. Slow in debug builds, hence ignored by default; run with
//! `cargo test --release -p ring_tracer_kernel -- --include-ignored`.

use ring_tracer_kernel::{render_image, RayStats, Scene, Settings};
use std::path::Path;

/// (scene, eye hit rays, reflect rays, refract rays, shadow rays) from the SPD Readme.
const TABLE: [(&str, u64, u64, u64, u64); 7] = [
    ("balls_s4", 263_169, 175_095, 0, 954_368),
    ("gears_s4", 245_086, 304_643, 207_564, 2_246_955),
    ("mount_s6", 173_125, 354_769, 354_769, 412_922),
    ("rings_s7", 263_169, 315_236, 0, 1_085_002),
    ("teapot_s12", 161_120, 225_248, 0, 407_656),
    ("tetra_s6", 49_788, 0, 0, 46_112),
    ("tree_s11", 169_836, 0, 0, 1_097_419),
];

fn close(got: u64, want: u64) -> bool {
    let (g, w) = (got as f64, want as f64);
    (g - w).abs() <= 0.10 * w
}

#[test]
#[ignore = "slow in debug builds; run with --release -- --include-ignored"]
fn spd_ray_counts_match_table() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes/spd");
    let mut failures = Vec::new();
    for (name, eye_hits, refl, refr, shadow) in TABLE {
        let scene = Scene::load(&dir.join(format!("{name}.nff"))).expect("SPD scene loads");
        let settings = Settings {
            width: 512,
            height: 512,
            spd: true,
            ..Settings::for_scene(&scene)
        };
        let (_, s): (_, RayStats) = render_image(&scene, &settings, 2).expect("renders");
        println!(
            "{name}: eye {} eye_hits {} (table {eye_hits}) reflected {} ({refl}) refracted {} ({refr}) shadow {} ({shadow})",
            s.eye, s.eye_hits, s.reflected, s.refracted, s.shadow
        );
        assert_eq!(s.eye, 513 * 513);
        for (what, got, want) in [
            ("eye hits", s.eye_hits, eye_hits),
            ("reflected", s.reflected, refl),
            ("refracted", s.refracted, refr),
            ("shadow", s.shadow, shadow),
        ] {
            if !close(got, want) {
                failures.push(format!("{name} {what}: got {got}, table {want}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
