//! BVH builds alone, for counting them under Valgrind's callgrind rather than timing them:
//! `cargo run --release -p ring_tracer_embree_bench --bin builds -- [--kernel ours|embree]
//! [--times N] [--embree-isa ISA] [--clock] MESH.obj`.
//!
//! Loads the mesh, then builds its hierarchy `N` times (default 1) inside [`counted`]: ours
//! ([`TriangleTree::build`], what `bench rays` times) or Embree's (a device with one build
//! thread and a committed scene, [`Embree::new`], ISA default `avx2`: Valgrind runs no
//! AVX-512), and prints the last tree's figures. Under
//! `valgrind --tool=callgrind --toggle-collect='*counted*'` only the builds are counted, so
//! `callgrind_annotate` splits a build's instructions by function. Embree's count includes the
//! set-up of its device and scene; a run over a one-triangle mesh gives that part. Ours also
//! prints the least and median CPU time of a build; `--clock` builds Embree's in benchmark
//! mode instead and prints the least and median of its own clock (`BENCHMARK_BUILD`).

use ring_tracer_embree_bench::embree::{Embree, Isa};
use ring_tracer_kernel::bvh::TriangleTree;
use ring_tracer_kernel::glam::Vec3A;
use ring_tracer_kernel::Scene;
use std::path::Path;

/// The part callgrind counts (`--toggle-collect`): what `f` does, callees included.
#[inline(never)]
fn counted<T>(f: impl FnOnce() -> T) -> T {
    f()
}

/// Builds ours `times` times; the last tree's SAH and sizes, or the error, and the least and
/// median CPU time of a build.
fn ours(tris: &[[Vec3A; 3]], times: usize) -> String {
    let mut last = String::new();
    let mut cpu = Vec::with_capacity(times);
    for _ in 0..times {
        let c = Embree::cpu_seconds();
        let tree = counted(|| TriangleTree::build(tris));
        if let (Some(c), Some(now)) = (c, Embree::cpu_seconds()) {
            cpu.push(now - c);
        }
        last = match tree {
            Ok(t) => format!(
                "ours: SAH {:.3}, {} nodes, {} blocks",
                t.sah(),
                t.node_count(),
                t.block_count()
            ),
            Err(e) => format!("ours: {e}"),
        };
    }
    cpu.sort_by(f64::total_cmp);
    match (cpu.first(), cpu.get(cpu.len() / 2)) {
        (Some(least), Some(median)) => format!(
            "{last}; CPU a build: least {:.3} ms, median {:.3} ms",
            least * 1e3,
            median * 1e3
        ),
        _ => last,
    }
}

/// Builds Embree's `times` times; whether it did. Outside callgrind (`--clock`), in
/// benchmark mode instead, for the least and median of its own clock.
fn embree(tris: &[[Vec3A; 3]], times: usize, isa: Isa, clock: bool) -> String {
    if clock {
        let mut own: Vec<f64> = (0..times)
            .filter_map(|_| Embree::build_figures(tris, isa).ok())
            .map(|f| f.build_seconds)
            .collect();
        own.sort_by(f64::total_cmp);
        return match (own.first(), own.get(own.len() / 2)) {
            (Some(least), Some(median)) => format!(
                "embree ({}), its own clock: least {:.3} ms, median {:.3} ms",
                isa.name(),
                least * 1e3,
                median * 1e3
            ),
            _ => "embree: no figures".into(),
        };
    }
    let mut last = String::new();
    for _ in 0..times {
        last = match counted(|| Embree::new(tris, isa)) {
            Ok(_) => format!("embree ({}): built", isa.name()),
            Err(e) => format!("embree: {e}"),
        };
    }
    last
}

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut kernel, mut times, mut isa, mut mesh) = ("ours".to_string(), 1, Isa::Avx2, None);
    let mut clock = false;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--kernel" => kernel = args.next().unwrap_or(kernel),
            "--times" => times = args.next().and_then(|v| v.parse().ok()).unwrap_or(times),
            "--embree-isa" => isa = Isa::from_arg(args.next()),
            "--clock" => clock = true,
            _ => mesh = Some(a),
        }
    }
    let Some(mesh) = mesh else {
        eprintln!(
            "usage: builds [--kernel ours|embree] [--times N] [--embree-isa ISA] [--clock] MESH.obj"
        );
        std::process::exit(2);
    };
    let scene = match Scene::load(Path::new(&mesh)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let tris = scene.triangles();
    let line = match kernel.as_str() {
        "ours" => ours(&tris, times.max(1)),
        "embree" => embree(&tris, times.max(1), isa, clock),
        k => {
            eprintln!("unknown kernel {k}: ours or embree");
            std::process::exit(2);
        }
    };
    println!("{mesh}: {} triangles, {times} builds; {line}", tris.len());
}
