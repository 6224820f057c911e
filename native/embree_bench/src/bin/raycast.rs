//! Ray casting with the kernel alone, for profiling (`perf stat` / `perf record`) and for
//! checking that a kernel change keeps every hit:
//! `cargo run --release -p ring_tracer_embree_bench --bin raycast -- [--stream] MESH.obj [KIND] [REPEAT] [DUMP]`
//!
//! KIND: `primary`, `incoherent` (default) or `any` (the incoherent rays as shadow queries),
//! the rays of [`ring_tracer_kernel::raysets`] (1024 x 1024). Prints the load time, the rate
//! and a checksum of the answers; with DUMP, writes each ray's answer (primitive and `t` bits,
//! or the any-hit flag) to that file, one per line, so two builds can be compared with `cmp`.
//! With `--stream`, the rays go through the stream queries (`Scene::intersect_stream` /
//! `occluded_stream`, all of them one stream) instead of one query per ray: the checksum must
//! be the one-ray queries'.

use ring_tracer_embree_bench::cpu_seconds;
use ring_tracer_kernel::{raysets, Hit, Ray, Scene, Scratch, StreamScratch};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

fn main() -> std::io::Result<()> {
    let all: Vec<String> = std::env::args().skip(1).collect();
    let stream = all.iter().any(|a| a == "--stream");
    let args: Vec<String> = all.into_iter().filter(|a| a != "--stream").collect();
    let Some(mesh) = args.first() else {
        eprintln!("usage: raycast [--stream] MESH.obj [primary|incoherent|any] [REPEAT] [DUMP]");
        std::process::exit(2);
    };
    let kind = args.get(1).map(String::as_str).unwrap_or("incoherent");
    let repeat: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(1);
    let t0 = Instant::now();
    let scene = match Scene::load(Path::new(mesh)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    println!("load + BVH {:.3} s", t0.elapsed().as_secs_f64());
    let b = scene.bounds();
    let rays = match kind {
        "primary" => raysets::primary(b, 1024),
        _ => raysets::incoherent(b, 1024 * 1024),
    };
    // a hit names its triangle by its corners (the primitive index depends on the BVH's order)
    let tris = scene.triangles();
    let name = |p: u32| -> u64 {
        tris.get(p as usize).map_or(p as u64, |t| {
            t.iter().flat_map(|v| v.to_array()).fold(0u64, |h, x| {
                (h ^ x.to_bits() as u64).wrapping_mul(0x100_0000_01b3)
            })
        })
    };
    let t1 = Instant::now();
    let c1 = cpu_seconds();
    let mut answers = Vec::new();
    for _ in 0..repeat {
        answers = if stream {
            streamed(&scene, &rays, kind == "any")
        } else {
            one_by_one(&scene, &rays, kind == "any")
        };
    }
    let secs = t1.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - c1;
    let named: Vec<(u64, u32)> = answers
        .iter()
        .map(|&(p, t)| match kind {
            "any" => (p as u64, t),
            _ if p == u32::MAX => (u64::MAX, t),
            _ => (name(p), t),
        })
        .collect();
    let sum = named
        .iter()
        .fold(0u64, |acc, &(p, t)| acc.rotate_left(5) ^ p ^ t as u64);
    let hits = answers.iter().filter(|a| {
        if kind == "any" {
            a.0 == 1
        } else {
            a.0 != u32::MAX
        }
    });
    let m = (rays.len() * repeat) as f64 / 1e6;
    println!(
        "{kind}: {:.2} Mrays/s, {:.2} per CPU second, {} hits, checksum {sum:016x}",
        m / secs,
        if cpu > 0.0 { m / cpu } else { 0.0 },
        hits.count()
    );
    if let Some(dump) = args.get(3) {
        let mut f = std::io::BufWriter::new(std::fs::File::create(dump)?);
        for (p, t) in &named {
            writeln!(f, "{p:016x} {t:08x}")?;
        }
    }
    Ok(())
}

/// (primitive or `u32::MAX`, `t` bits) of each closest hit, or (occluded, 0), one query a ray.
fn one_by_one(scene: &Scene, rays: &[Ray], any: bool) -> Vec<(u32, u32)> {
    let mut s = Scratch::new();
    rays.iter()
        .map(|r| {
            if any {
                (scene.occluded_with(r, f32::INFINITY, &mut s) as u32, 0)
            } else {
                answer(scene.intersect_with(r, f32::INFINITY, &mut s))
            }
        })
        .collect()
}

/// [`one_by_one`]'s answers, from one stream query over all the rays.
fn streamed(scene: &Scene, rays: &[Ray], any: bool) -> Vec<(u32, u32)> {
    let mut s = StreamScratch::new();
    let tmax = vec![f32::INFINITY; rays.len()];
    let done = if any {
        let mut out = vec![false; rays.len()];
        scene
            .occluded_stream(rays, &tmax, &mut out, &mut s)
            .map(|()| out.iter().map(|&o| (o as u32, 0)).collect())
    } else {
        let mut out = vec![None; rays.len()];
        scene
            .intersect_stream(rays, &tmax, &mut out, &mut s)
            .map(|()| out.into_iter().map(answer).collect())
    };
    done.unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    })
}

/// A closest hit as (primitive, `t` bits), a miss as (`u32::MAX`, 0).
fn answer(h: Option<Hit>) -> (u32, u32) {
    h.map_or((u32::MAX, 0), |h| (h.prim, h.t.to_bits()))
}
