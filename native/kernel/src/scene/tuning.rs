//! Deterministic traversal cost on the SPD scenes, for tuning the BVH build (a report, not a
//! check).

use super::*;
use crate::bvh::{probe, Scratch};
use crate::ray::Ray;

/// for tuning the BVH build: `cargo test --release -p ring_tracer_kernel bvh_cost_report --
/// --ignored --nocapture`. Not a check; add (split cost, leaf size) variants to compare.
#[test]
#[ignore]
fn bvh_cost_report() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes/spd");
    let variants: Vec<(f32, usize)> = vec![(crate::bvh::SPLIT_COST, 0), (1.0, 0)];
    for (tc, lm) in variants {
        probe::SPLIT.with(|c| c.set(tc));
        probe::LEAF_MIN.with(|c| c.set(lm));
        let mut line = format!("split cost {tc} leaf size {lm} (0: the build's):");
        for f in [
            "balls_s4",
            "gears_s4",
            "mount_s6",
            "rings_s7",
            "teapot_s12",
            "tetra_s6",
            "tree_s11",
        ] {
            let scene = Scene::load(&dir.join(format!("{f}.nff"))).unwrap();
            let cam = scene.camera;
            let mut sc = Scratch::new();
            let (mut prims, mut rays) = (0u64, 0u64);
            probe::NODES.with(|c| c.set(0));
            for y in (0..512).step_by(3) {
                for x in (0..512).step_by(3) {
                    let r = cam.ray(x as f32 + 0.5, y as f32 + 0.5, 512, 512, 511.0);
                    rays += 1;
                    let mut hitp = None;
                    let mut tbest = f32::INFINITY;
                    scene
                        .bvh
                        .traverse::<true>(&r, f32::INFINITY, &mut sc, |first, count, tmax| {
                            let (first, count) = scene.tri_blocks.prims(first, count);
                            let mut tm = tmax;
                            for (k, s) in scene.geom.shapes[first..first + count].iter().enumerate()
                            {
                                prims += 1;
                                if let Some(t) = scene.geom.hit(s, &r, 0.0, tm) {
                                    tm = t;
                                    hitp = Some(first + k);
                                    tbest = t;
                                }
                            }
                            tm
                        });
                    let Some(hp) = hitp else { continue };
                    let h = Hit {
                        t: tbest,
                        prim: hp as u32,
                        instance: Hit::NO_INSTANCE,
                    };
                    let su = scene.surface(&h, &r);
                    let n = if su.ng.dot(r.dir) < 0.0 {
                        su.ng
                    } else {
                        -su.ng
                    };
                    for l in &scene.lights {
                        let to = l.position - su.p;
                        let d = to.length();
                        if n.dot(to) <= 0.0 {
                            continue;
                        }
                        let sr = Ray::new(su.p + n * scene.epsilon, to / d);
                        rays += 1;
                        scene
                            .bvh
                            .traverse::<false>(&sr, d, &mut sc, |first, count, tmax| {
                                let (first, count) = scene.tri_blocks.prims(first, count);
                                for s in &scene.geom.shapes[first..first + count] {
                                    prims += 1;
                                    if scene.geom.hit(s, &sr, 0.0, tmax).is_some() {
                                        return -1.0;
                                    }
                                }
                                tmax
                            });
                    }
                }
            }
            let nodes = probe::NODES.with(|c| c.get());
            line += &format!(
                " {f} n{:.1}/p{:.1}",
                nodes as f64 / rays as f64,
                prims as f64 / rays as f64
            );
        }
        println!("{line}");
    }
}
