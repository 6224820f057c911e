//! Single-ray rates of RingTracer's kernel and Embree per CPU second, for a busy machine:
//! `cargo run --release -p ring_tracer_embree_bench --bin cpu_ratio -- [--rounds R]
//! [--embree-isa ISA] [--packets] MESH.obj...` (ISA as for `embree_bench`).
//!
//! The same rays as `embree_bench` (1024 x 1024 primary rays in tiles, as many incoherent ones,
//! closest hit and any hit), one thread, ours and Embree alternating; the incoherent rows also
//! through our stream queries (`Scene::intersect_stream` / `occluded_stream`, all the rays as
//! one stream, its arrays sized before the rounds) against the same `rtcIntersect1` /
//! `rtcOccluded1` over the rays in their own order. With `--packets`, the
//! bench's packet cells instead (`Scene::intersect_packet` / `occluded_packet` against
//! `rtcIntersect16` / `rtcOccluded16`, coherent flag on primary and shadow rays), the shadow
//! rays of the primary hits too, each timing over eight passes of its rays (a packet pass of
//! the teapot takes a few 10 ms ticks). Each cell is timed by the
//! process's CPU time (`/proc/self/stat`, 10 ms ticks) as well as by the clock: when other
//! programs share the cores, wall-clock rates swing with their load, while CPU-second rates
//! only feel what they do to the caches. The ratio compares the best rounds.

use ring_tracer_embree_bench::embree::{flat, Call, Embree, Isa};
use ring_tracer_embree_bench::{
    packet_hits, shadow_rays, single_hits, timed_cpu as timed, RaySets, Streams,
};
use ring_tracer_kernel::{Ray, Scene};
use std::path::Path;

/// Passes over a cell's rays per timing with `--packets`.
const PACKET_PASSES: usize = 8;

fn bench(path: &str, rounds: usize, isa: Isa, packets: bool) {
    let (lw, lc, scene) = timed(|| Scene::load(Path::new(path)));
    let scene = match scene {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return;
        }
    };
    let tris = scene.triangles();
    let (ew, ec, embree) = timed(|| Embree::new(&tris, isa));
    let embree = match embree {
        Ok(e) => e,
        Err(e) => {
            eprintln!("Embree: {e}");
            return;
        }
    };
    println!(
        "\n{path}: {} triangles; ours load + BVH {lw:.2} s ({lc:.2} CPU s), Embree BVH {ew:.2} s ({ec:.2} CPU s)",
        tris.len()
    );
    let b = scene.bounds();
    let RaySets { tiled, incoherent } = RaySets::new(b, 1024);
    let shadow = if packets {
        shadow_rays(&scene, &tiled)
    } else {
        Vec::new()
    };
    let (ft, fi, fs) = (flat(&tiled), flat(&incoherent), flat(&shadow));
    let mut rows: Vec<(&str, &[Ray], &[f32], bool)> = vec![
        ("primary", &tiled, &ft, false),
        ("incoherent", &incoherent, &fi, false),
        ("incoherent, any hit", &incoherent, &fi, true),
    ];
    let (passes, e, ours) = if packets {
        rows.push(("shadow rays of primary hits", &shadow, &fs, true));
        (PACKET_PASSES, "16", "ours, packets of 16")
    } else {
        (1, "1", "ours")
    };
    let mut streams = Streams::default();
    if !packets {
        streams.hits(&scene, &incoherent, false);
        streams.hits(&scene, &incoherent, true);
        println!(
            "| rays | {ours}, Mrays/CPU s | Embree rtcIntersect{e} | ours / E{e} (CPU) | ours / E{e} (wall) | ours, stream | stream / E{e} (CPU) | stream / E{e} (wall) |"
        );
        println!("|---|---|---|---|---|---|---|---|");
    } else {
        println!(
            "| rays | {ours}, Mrays/CPU s | Embree rtcIntersect{e} | ours / E{e} (CPU) | ours / E{e} (wall) |"
        );
        println!("|---|---|---|---|---|");
    }
    for (label, rays, fr, any) in rows {
        let n = (rays.len() * passes) as f64 / 1e6;
        let call = match (packets, any) {
            (false, false) => Call::Intersect1,
            (false, true) => Call::Occluded1,
            (true, false) => Call::Intersect16 {
                coherent: label != "incoherent",
            },
            (true, true) => Call::Occluded16 {
                coherent: label != "incoherent, any hit",
            },
        };
        let (mut o, mut e, mut st) = (Vec::new(), Vec::new(), Vec::new());
        let stream = !packets && label != "primary";
        let mut hits = (0, 0, None);
        for _ in 0..rounds {
            let r = timed(|| {
                let mut h = 0;
                for _ in 0..passes {
                    h = match packets {
                        true => packet_hits(&scene, rays, any),
                        false => single_hits(&scene, rays, any),
                    };
                }
                h
            });
            hits.0 = r.2;
            o.push((n / r.0, n / r.1.max(0.01)));
            let r = timed(|| {
                let mut h = 0;
                for _ in 0..passes {
                    h = embree.trace(call, fr);
                }
                h
            });
            hits.1 = r.2;
            e.push((n / r.0, n / r.1.max(0.01)));
            if stream {
                let r = timed(|| streams.hits(&scene, rays, any));
                hits.2 = Some(r.2);
                st.push((n / r.0, n / r.1.max(0.01)));
            }
        }
        let best = |v: &[(f64, f64)], k: usize| {
            v.iter()
                .map(|x| if k == 0 { x.0 } else { x.1 })
                .fold(0.0, f64::max)
        };
        let range = |v: &[(f64, f64)]| {
            let lo = v.iter().map(|x| x.1).fold(f64::INFINITY, f64::min);
            format!("{lo:.2}-{:.2}", best(v, 1))
        };
        let streamed = if packets {
            String::new()
        } else if stream {
            format!(
                " {} | {:.2} | {:.2} |",
                range(&st),
                best(&st, 1) / best(&e, 1),
                best(&st, 0) / best(&e, 0)
            )
        } else {
            " - | - | - |".to_string()
        };
        println!(
            "| {label} | {} | {} | {:.2} | {:.2} |{streamed}",
            range(&o),
            range(&e),
            best(&o, 1) / best(&e, 1),
            best(&o, 0) / best(&e, 0)
        );
        if hits.0.abs_diff(hits.1) > rays.len() as u64 / 10_000 + 2 {
            println!("  (hit counts differ: ours {}, Embree {})", hits.0, hits.1);
        }
        if let Some(h) = hits.2.filter(|&h| h != hits.0) {
            println!("  (our stream's hit count differs from our single rays': {h})");
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut rounds = 3;
    let mut isa = Isa::Best;
    let mut packets = false;
    let mut meshes = Vec::new();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--rounds" => rounds = args.next().and_then(|v| v.parse().ok()).unwrap_or(rounds),
            "--embree-isa" => isa = Isa::from_arg(args.next()),
            "--packets" => packets = true,
            _ => meshes.push(a),
        }
    }
    if meshes.is_empty() {
        eprintln!("usage: cpu_ratio [--rounds R] [--embree-isa ISA] [--packets] MESH.obj...");
        std::process::exit(2);
    }
    if let Err(e) = Embree::version() {
        eprintln!("{e}");
        std::process::exit(1);
    }
    for m in &meshes {
        bench(m, rounds.max(1), isa, packets);
    }
}
