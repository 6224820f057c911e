//! Instructions, branches and cache misses per ray of RingTracer's kernel and of Embree, counted
//! by Valgrind's callgrind (Debian `valgrind`) rather than timed:
//! `cargo run --release -p ring_tracer_embree_bench --bin counts -- [--rays N] [--ll BYTES]
//! [--embree-isa ISA] [--kernels LIST] MESH.obj...` (ISA as for `embree_bench`, default `avx2`:
//! Valgrind runs no AVX-512; LIST: some of
//! `ours,ours-stream,embree,ours16,embree16`, default all five).
//!
//! On a shared virtual machine, rates move by 10-30% between runs, more than most kernel
//! changes are worth; these counts are the same on every run. For each mesh and ray kind
//! (primary rays in tiles, incoherent ones, the incoherent ones as any-hit queries, the
//! primary hits' shadow rays as any-hit queries) this program runs itself under callgrind once
//! per kernel: one ray at a time (`ours`: `Scene::intersect_with` / `occluded_with`; `embree`:
//! `rtcIntersect1` / `rtcOccluded1`), all the rays as one stream (`ours-stream`:
//! `Scene::intersect_stream` / `occluded_stream`, the sort included, its arrays sized for the
//! stream before the warm-up) and in packets of sixteen consecutive rays (`ours16`:
//! `Scene::intersect_packet` / `occluded_packet`; `embree16`: `rtcIntersect16` /
//! `rtcOccluded16`, with the coherent flag on primary and shadow rays, as the bench), with the branch
//! predictor and a two-level cache simulated (the last level `--ll` bytes, 16-way, default
//! 32 MiB), and counts only the traced rays: a warm-up eighth of them first, then `N` inside
//! [`counted`] (default 65,536, rounded down to the square of a multiple of 4: the primary
//! rays are an image of that many pixels over the whole view, in tiles; for the packet kernels,
//! whose packets are as coherent as their tiles are small, as many tiles of the bench's
//! 1024 x 1024 image, in runs of sixteen neighbours). Simulated
//! mispredictions and misses are not the hardware's, but they compare two kernels on the same
//! rays.

use ring_tracer_embree_bench::embree::{flat, Call, Embree, Isa};
use ring_tracer_embree_bench::{packet_hits, shadow_rays, single_hits, RaySets, Streams};
use ring_tracer_kernel::{raysets, Aabb, Ray, Scene};
use std::path::Path;
use std::process::Command;

const KINDS: [&str; 4] = ["primary", "incoherent", "any", "shadow"];

/// The kernels and ways of calling them, in the table's order.
const KERNELS: [&str; 5] = ["ours", "ours-stream", "embree", "ours16", "embree16"];

/// The part callgrind counts (`--toggle-collect`): what `f` does, callees included.
#[inline(never)]
fn counted(f: impl FnOnce() -> u64) -> u64 {
    f()
}

/// The side of the square image of about `n` primary rays (a multiple of 4, for the tiles):
/// every kind traces `side(n)^2` rays.
fn side(n: usize) -> u32 {
    (((n as f64).sqrt() as u32) / 4 * 4).max(4)
}

/// The side of the bench's image: its 4 x 4 pixel tiles are the packets of primary rays, and
/// their coherence (their shadow rays' too) depends on it.
const BENCH_SIDE: u32 = 1024;

/// Tiles taken in a row by [`sampled_tiles`].
const RUN: usize = 16;

/// About `n` primary rays for the packet kernels: tiles of the bench's image, [`RUN`] in a row
/// (in tile order) out of every k x RUN, so that each packet is as coherent as the bench's,
/// and so are the sixteens of their shadow rays, which straddle neighbouring tiles. The runs
/// taken move along each row of tiles from the one above, so that they cover the image.
fn sampled_tiles(b: Aabb, n: usize) -> Vec<Ray> {
    let primary = raysets::primary(b, BENCH_SIDE);
    let order = raysets::tile_order(BENCH_SIDE);
    let stride = (order.len() / n.max(16 * RUN)).max(1);
    let per_row = (BENCH_SIDE as usize / 4 / RUN).max(1);
    order
        .chunks(16 * RUN)
        .enumerate()
        .filter(|(c, _)| c % stride == (c / per_row) % stride)
        .flat_map(|(_, run)| run)
        .filter_map(|&i| primary.get(i as usize).copied())
        .collect()
}

/// The child's work: `n` rays of `kind` through one kernel, after a warm-up eighth (for
/// `shadow`, one per primary hit); returns (rays counted, hits).
fn one_side(
    mesh: &str,
    kernel: &str,
    kind: &str,
    n: usize,
    isa: Isa,
) -> Result<(usize, u64), String> {
    let scene = Scene::load(Path::new(mesh)).map_err(|e| e.to_string())?;
    // primary rays over the whole view, in tiles: an image of `n` pixels
    let RaySets {
        mut tiled,
        incoherent,
    } = RaySets::new(scene.bounds(), side(n));
    if kernel.ends_with("16") {
        tiled = sampled_tiles(scene.bounds(), tiled.len());
    }
    let rays = match kind {
        "primary" => tiled,
        // the primary hits' shadow rays (fewer than `n` where primary rays miss)
        "shadow" => shadow_rays(&scene, &tiled),
        _ => incoherent,
    };
    let warm = &rays[..rays.len() / 8];
    let any = kind == "any" || kind == "shadow";
    // the rays themselves are read once before the count (as Embree's copy of them is made)
    std::hint::black_box(rays.iter().map(|r| r.origin.x).sum::<f32>());
    let coherent = kind == "primary" || kind == "shadow";
    let call = match (kernel, any) {
        ("embree", false) => Some(Call::Intersect1),
        ("embree", true) => Some(Call::Occluded1),
        ("embree16", false) => Some(Call::Intersect16 { coherent }),
        ("embree16", true) => Some(Call::Occluded16 { coherent }),
        _ => None,
    };
    if let Some(call) = call {
        let e = Embree::new(&scene.triangles(), isa)?;
        // the warm-up: a whole number of packets
        e.trace(call, &flat(&warm[..warm.len() / 16 * 16]));
        let f = flat(&rays);
        Ok((rays.len(), counted(|| e.trace(call, &f))))
    } else if kernel == "ours-stream" {
        // arrays sized for the whole stream first (as a renderer's stay allocated), so that
        // the counted call copies none of them to grow them; the warm-up as the others'
        let mut streams = Streams::default();
        streams.reserve(rays.len());
        streams.hits(&scene, warm, any);
        Ok((rays.len(), counted(|| streams.hits(&scene, &rays, any))))
    } else if kernel == "ours16" {
        packet_hits(&scene, &warm[..warm.len() / 16 * 16], any);
        Ok((rays.len(), counted(|| packet_hits(&scene, &rays, any))))
    } else {
        single_hits(&scene, warm, any);
        Ok((rays.len(), counted(|| single_hits(&scene, &rays, any))))
    }
}

/// Callgrind's totals for the counted part: (instructions, data reads, last-level read
/// misses, conditional branches, of them mispredicted), and the rays counted.
fn measure(
    mesh: &str,
    kernel: &str,
    kind: &str,
    n: usize,
    ll: u64,
    isa: Isa,
) -> Option<([u64; 5], usize)> {
    let me = std::env::current_exe().ok()?;
    let out = Command::new("valgrind")
        .args([
            "--tool=callgrind",
            "--branch-sim=yes",
            "--cache-sim=yes",
            &format!("--LL={ll},16,64"),
            "--toggle-collect=*counts::counted*",
            "--callgrind-out-file=/dev/null",
        ])
        .arg(me)
        .args(["--one", mesh, kernel, kind, &n.to_string(), isa.name()])
        .output()
        .ok()?;
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        eprintln!(
            "{mesh} {kernel} {kind}: {}",
            err.lines().last().unwrap_or("")
        );
        return None;
    }
    // "==pid== Collected : Ir Dr Dw I1mr D1mr D1mw ILmr DLmr DLmw Bc Bcm Bi Bim"
    let line = err.lines().find(|l| l.contains("Collected :"))?;
    let v: Vec<u64> = line
        .split(':')
        .nth(1)?
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    // the child's "RAYS rays, HITS hits"
    let rays = String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    Some((
        [*v.first()?, *v.get(1)?, *v.get(7)?, *v.get(9)?, *v.get(10)?],
        rays,
    ))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--one") {
        let [mesh, kernel, kind, n, isa] = [1, 2, 3, 4, 5].map(|i| args.get(i).cloned());
        let n = n.and_then(|n| n.parse().ok()).unwrap_or(65_536);
        let isa = Isa::from_arg(isa);
        match one_side(
            &mesh.unwrap_or_default(),
            &kernel.unwrap_or_default(),
            &kind.unwrap_or_default(),
            n,
            isa,
        ) {
            Ok((rays, hits)) => println!("{rays} rays, {hits} hits"),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
        return;
    }
    let (mut n, mut ll, mut isa, mut meshes) = (65_536usize, 32u64 << 20, Isa::Avx2, Vec::new());
    let mut wanted: Vec<String> = KERNELS.iter().map(|k| k.to_string()).collect();
    let mut it = args.into_iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--kernels" => {
                wanted = it
                    .next()
                    .unwrap_or_default()
                    .split(',')
                    .map(str::to_string)
                    .collect();
                if let Some(bad) = wanted.iter().find(|k| !KERNELS.contains(&k.as_str())) {
                    eprintln!("--kernels {bad:?}: expected some of {}", KERNELS.join(","));
                    std::process::exit(2);
                }
            }
            "--rays" => n = it.next().and_then(|v| v.parse().ok()).unwrap_or(n),
            "--ll" => ll = it.next().and_then(|v| v.parse().ok()).unwrap_or(ll),
            "--embree-isa" => isa = Isa::from_arg(it.next()),
            _ => meshes.push(a),
        }
    }
    if meshes.is_empty() {
        eprintln!(
            "usage: counts [--rays N] [--ll BYTES] [--embree-isa ISA] [--kernels LIST] MESH.obj..."
        );
        std::process::exit(2);
    }
    if Command::new("valgrind").arg("--version").output().is_err() {
        eprintln!("counts needs Valgrind: apt-get install valgrind");
        std::process::exit(2);
    }
    let embree = Embree::version()
        .map_err(|e| println!("{e}: only our kernel is counted"))
        .is_ok();
    let kernels: Vec<&str> = KERNELS
        .into_iter()
        .filter(|k| wanted.iter().any(|w| w == k) && (embree || k.starts_with("ours")))
        .collect();
    let n = (side(n) as usize).pow(2);
    println!(
        "{n} rays of each kind (shadow: one per primary hit) after a warm-up eighth, one at a time or (16) in packets of 16; callgrind: simulated branch predictor, last-level cache {} MiB 16-way; Embree at most {}",
        ll >> 20,
        isa.name()
    );
    println!("| mesh | rays | kernel | instructions/ray | data reads/ray | LL read misses/ray | branches/ray | mispredicted/ray |");
    println!("|---|---|---|---|---|---|---|---|");
    for mesh in &meshes {
        let name = Path::new(mesh)
            .file_name()
            .map_or(mesh.clone(), |f| f.to_string_lossy().into_owned());
        for kind in KINDS {
            for &kernel in &kernels {
                let Some((c, rays)) = measure(mesh, kernel, kind, n, ll, isa) else {
                    continue;
                };
                let per = |x: u64| x as f64 / rays.max(1) as f64;
                println!(
                    "| {name} | {kind} | {kernel} | {:.1} | {:.1} | {:.3} | {:.2} | {:.3} |",
                    per(c[0]),
                    per(c[1]),
                    per(c[2]),
                    per(c[3]),
                    per(c[4])
                );
            }
        }
    }
}
