//! Ray casting, RingTracer's kernel next to Intel Embree 3, same rays, same run.
//!
//! `cargo run --release -p ring_tracer_embree_bench -- [--rounds R] [--size N] [--builds B]
//! [--embree-isa ISA] MESH.obj...`
//!
//! `--embree-isa` caps the instruction set of Embree's device (`best`, the default: the widest
//! the CPU has; `sse4.2`, `avx`, `avx2`, `avx512`). On a CPU with AVX-512 Embree's packets of
//! 16 then run its AVX-512 code, sixteen rays to a register, where ours use AVX-512 only in the
//! leaves' tests across rays (AVX or AVX2 elsewhere); `--embree-isa avx2` shows how much of the
//! gap is the width.
//!
//! For each mesh, first the BVH builds: B times each (default 5), ours and Embree's
//! alternating, from the mesh's triangles (ours: [`ring_tracer_kernel::bvh::TriangleTree`], the
//! boxes, the binary SAH build, the collapse into 8-wide nodes and the leaves' blocks of four;
//! Embree: its own clock around its BVH build on a device with one build thread, from its
//! `BENCHMARK_BUILD` line, and the wall time of `rtcCommitScene`), the medians, and the SAH
//! figure of both trees by the definition of Embree's BVH statistics. Then both BVHs are
//! built once more for tracing, and R rounds (default 3) each time every
//! measurement below, ours and Embree's alternating, and the table gives each one's range
//! over the rounds (Mrays/s, the machine may be busy: compare columns of one run only).
//! Rays ([`ring_tracer_kernel::raysets`]): N x N primary rays (default 1024) of the default
//! OBJ view, and as many incoherent rays (random origins in the central half of the box,
//! directions on the sphere), closest hit; the incoherent ones also as any-hit shadow queries,
//! and the shadow rays of the primary hits towards a point light outside the box
//! ([`ring_tracer_embree_bench::shadow_rays`]), coherent any-hit queries.
//! Columns: single rays on 1 thread (`Scene::intersect_with` / `occluded_with` against
//! `rtcIntersect1` / `rtcOccluded1`), for the incoherent rows our stream queries on 1 thread
//! (`Scene::intersect_stream` / `occluded_stream`, all the rays as one stream, which the
//! query reorders; its arrays are kept between rounds and sized before the first) against the
//! same `rtcIntersect1` / `rtcOccluded1` over the rays in their own order, packets of 16 on 1 thread (ours: `Scene::intersect_packet`
//! and `occluded_packet` on 4 x 4 pixel tiles and their shadow rays; Embree: `rtcIntersect16` /
//! `rtcOccluded16` on the same sixteens, with the coherent flag for those two), and single
//! rays on 2 threads. Hit counts must agree (they are printed
//! when they differ by more than a few rays on triangle edges).
//!
//! Without Embree's headers at build time the bench says so and times ours only.

use ring_tracer_embree_bench::embree::{flat, BuildFigures, Call, Embree, Isa};
use ring_tracer_embree_bench::{packet_hits, shadow_rays, single_hits, RaySets, Streams};
use ring_tracer_kernel::bvh::TriangleTree;
use ring_tracer_kernel::glam::Vec3A;
use ring_tracer_kernel::{Ray, Scene};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// Runs `f` over `items` split in small chunks handed out to `threads` threads; returns
/// (seconds, sum of f's results).
fn timed<T: Sync>(
    threads: usize,
    items: &[T],
    chunk: usize,
    f: impl Fn(&[T]) -> u64 + Sync,
) -> (f64, u64) {
    let next = AtomicUsize::new(0);
    let t = Instant::now();
    let total = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut sum = 0;
                    loop {
                        let c = next.fetch_add(1, Ordering::Relaxed);
                        let Some(part) = items.chunks(chunk).nth(c) else {
                            break;
                        };
                        sum += f(part);
                    }
                    sum
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap_or(0)).sum()
    });
    (t.elapsed().as_secs_f64(), total)
}

/// One measured quantity: its rate in each round and its hit count.
#[derive(Default)]
struct Figure {
    rates: Vec<f64>,
    hits: u64,
}

impl Figure {
    fn add(&mut self, rays: usize, (secs, hits): (f64, u64)) {
        self.rates.push(rays as f64 / secs / 1e6);
        self.hits = hits;
    }
    fn range(&self) -> String {
        if self.rates.is_empty() {
            return "-".into();
        }
        let lo = self.rates.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = self.rates.iter().cloned().fold(0.0, f64::max);
        format!("{lo:.1}-{hi:.1}")
    }
    fn best(&self) -> f64 {
        self.rates.iter().cloned().fold(0.0, f64::max)
    }
}

const CHUNK: usize = 4096;

/// The median of `v` (0 when empty).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Builds both BVHs over `tris` `builds` times, ours and Embree's alternating, and prints the
/// median times (wall and CPU) and both SAH figures.
fn build_figures(tris: &[[Vec3A; 3]], builds: usize, isa: Isa) {
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    let mut theirs = Vec::<BuildFigures>::new();
    let (mut sah, mut refused) = (0.0, None);
    for _ in 0..builds {
        let (t, c) = (Instant::now(), Embree::cpu_seconds());
        match TriangleTree::build(tris) {
            Ok(tree) => {
                wall.push(t.elapsed().as_secs_f64());
                if let (Some(c), Some(now)) = (c, Embree::cpu_seconds()) {
                    cpu.push(now - c);
                }
                sah = tree.sah();
            }
            Err(e) => {
                println!("  our BVH: {e}");
                return;
            }
        }
        match Embree::build_figures(tris, isa) {
            Ok(f) => theirs.push(f),
            Err(e) => refused = Some(e),
        }
    }
    let cpu = if cpu.is_empty() {
        String::new()
    } else {
        format!(" (CPU {:.4} s)", median(cpu))
    };
    println!(
        "BVH build, median of {builds}, 1 thread: ours {:.4} s{cpu}, SAH {sah:.3}",
        median(wall)
    );
    let of = |f: fn(&BuildFigures) -> f64| median(theirs.iter().map(f).collect());
    match (theirs.last(), refused) {
        (Some(last), _) => println!(
            "  Embree {:.4} s by its own clock (rtcCommitScene {:.4} s, CPU {:.4} s), SAH {:.3}",
            of(|f| f.build_seconds),
            of(|f| f.commit_seconds),
            of(|f| f.cpu_seconds),
            last.sah
        ),
        (None, Some(e)) => println!("  Embree: {e}"),
        (None, None) => {}
    }
}

/// A table row: label, our rays, Embree's (flat), coherent, any-hit.
type Row<'a> = (&'static str, &'a [Ray], &'a [f32], bool, bool);

/// The cells of a row, in the order they are timed: ours 1, Embree 1, ours 16, Embree 16,
/// ours 2 threads, Embree 2 threads, ours as a stream (incoherent rows only).
const CELLS: usize = 7;

/// The cell of our stream queries.
const STREAM: usize = 6;

fn bench(path: &str, rounds: usize, size: u32, builds: usize, isa: Isa) {
    let t0 = Instant::now();
    let scene = match Scene::load(Path::new(path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return;
        }
    };
    let ours_build = t0.elapsed().as_secs_f64();
    let tris = scene.triangles();
    let t1 = Instant::now();
    let embree = Embree::new(&tris, isa);
    let embree_build = t1.elapsed().as_secs_f64();
    let name = Path::new(path)
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    println!();
    match &embree {
        Ok(_) => println!(
            "{name}: {} triangles; load + BVH {ours_build:.2} s (ours), BVH {embree_build:.2} s (Embree {}, 1 build thread)",
            tris.len(),
            Embree::version().unwrap_or_default()
        ),
        Err(e) => println!(
            "{name}: {} triangles; load + BVH {ours_build:.2} s. Embree: {e}",
            tris.len()
        ),
    }
    build_figures(&tris, builds, isa);
    let b = scene.bounds();
    let RaySets { tiled, incoherent } = RaySets::new(b, size);
    let n = tiled.len();
    let flat_tiled = flat(&tiled);
    let flat_inc = flat(&incoherent);
    let shadow = shadow_rays(&scene, &tiled);
    let flat_shadow = flat(&shadow);

    let rows: [Row; 4] = [
        ("primary (coherent)", &tiled, &flat_tiled, true, false),
        ("incoherent", &incoherent, &flat_inc, false, false),
        ("incoherent, any hit", &incoherent, &flat_inc, false, true),
        (
            "shadow rays of primary hits",
            &shadow,
            &flat_shadow,
            true,
            true,
        ),
    ];
    let mut figs: Vec<[Figure; CELLS]> = rows.iter().map(|_| Default::default()).collect();
    // the stream's arrays sized once, before the rounds (as a renderer's stay allocated)
    let streams = Mutex::new(Streams::default());
    let stream_hits = |part: &[Ray], any: bool| match streams.lock() {
        Ok(mut s) => s.hits(&scene, part, any),
        Err(_) => 0,
    };
    stream_hits(&incoherent, false);
    stream_hits(&incoherent, true);
    for _ in 0..rounds {
        for (k, &(_, rays, fr, coherent, any)) in rows.iter().enumerate() {
            let ours_single = |part: &[Ray]| single_hits(&scene, part, any);
            let ours_packet = |part: &[Ray]| packet_hits(&scene, part, any);
            let (one, sixteen) = if any {
                (Call::Occluded1, Call::Occluded16 { coherent })
            } else {
                (Call::Intersect1, Call::Intersect16 { coherent })
            };
            let f = &mut figs[k];
            f[0].add(rays.len(), timed(1, rays, CHUNK, ours_single));
            if let Ok(e) = &embree {
                f[1].add(rays.len(), timed(1, fr, 6 * CHUNK, |p| e.trace(one, p)));
            }
            f[2].add(rays.len(), timed(1, rays, CHUNK, ours_packet));
            if let Ok(e) = &embree {
                f[3].add(rays.len(), timed(1, fr, 6 * CHUNK, |p| e.trace(sixteen, p)));
            }
            f[4].add(rays.len(), timed(2, rays, CHUNK, ours_single));
            if let Ok(e) = &embree {
                f[5].add(rays.len(), timed(2, fr, 6 * CHUNK, |p| e.trace(one, p)));
            }
            if !coherent {
                let all = rays.len().max(1);
                f[STREAM].add(rays.len(), timed(1, rays, all, |p| stream_hits(p, any)));
            }
        }
    }
    println!(
        "{} x {size} rays of each kind, {rounds} rounds alternating; Mrays/s (min-max); ours / Embree of the best rounds",
        size
    );
    println!(
        "| rays | ours, single | Embree rtcIntersect1 | ours / E1 | ours, stream | stream / E1 | ours, packets of 16 | Embree rtcIntersect16 | ours / E16 | ours, 2 threads | scaling | Embree 1, 2 threads |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (k, row) in rows.iter().enumerate() {
        let f = &figs[k];
        let ratio = |a: &Figure, b: &Figure| {
            if b.rates.is_empty() {
                "-".to_string()
            } else {
                format!("{:.2}", a.best() / b.best())
            }
        };
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
            row.0,
            f[0].range(),
            f[1].range(),
            ratio(&f[0], &f[1]),
            f[STREAM].range(),
            if f[STREAM].rates.is_empty() {
                "-".to_string()
            } else {
                ratio(&f[STREAM], &f[1])
            },
            f[2].range(),
            f[3].range(),
            ratio(&f[2], &f[3]),
            f[4].range(),
            f[4].best() / f[0].best(),
            f[5].range(),
        );
        let hits: Vec<u64> = f
            .iter()
            .filter(|x| !x.rates.is_empty())
            .map(|x| x.hits)
            .collect();
        let (lo, hi) = (
            hits.iter().min().copied().unwrap_or(0),
            hits.iter().max().copied().unwrap_or(0),
        );
        if hi - lo > (n as u64) / 10_000 + 2 {
            println!("  (hit counts differ: {hits:?})");
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut rounds = 3;
    let mut size = 1024;
    let mut builds = 5;
    let mut isa = Isa::Best;
    let mut meshes = Vec::new();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--rounds" => rounds = args.next().and_then(|v| v.parse().ok()).unwrap_or(rounds),
            "--size" => size = args.next().and_then(|v| v.parse().ok()).unwrap_or(size),
            "--builds" => builds = args.next().and_then(|v| v.parse().ok()).unwrap_or(builds),
            "--embree-isa" => isa = Isa::from_arg(args.next()),
            _ => meshes.push(a),
        }
    }
    if meshes.is_empty() {
        eprintln!(
            "usage: embree_bench [--rounds R] [--size N] [--builds B] [--embree-isa ISA] MESH.obj..."
        );
        std::process::exit(2);
    }
    match Embree::version() {
        Ok(v) => println!(
            "Embree {v} (the project's harness, native/embree_bench/c), ISA: {}",
            match isa {
                Isa::Best => "the widest the CPU has (--embree-isa caps it)".to_string(),
                i => format!("at most {} (--embree-isa)", i.name()),
            }
        ),
        Err(e) => println!("{e}"),
    }
    for m in &meshes {
        bench(m, rounds.max(1), size.max(4), builds.max(1), isa);
    }
}
