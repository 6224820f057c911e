//! The project's C harness over Embree 3 (`c/embree_side.c`), present when the build found
//! Debian's `libembree-dev` (`cfg(embree)`).

use ring_tracer_kernel::glam::Vec3A;

#[cfg(embree)]
mod ffi {
    use std::os::raw::{c_char, c_int};
    extern "C" {
        pub fn eb_version() -> *const c_char;
        pub fn eb_new(
            verts: *const f32,
            nverts: usize,
            idx: *const u32,
            ntris: usize,
            config: *const c_char,
        ) -> c_int;
        pub fn eb_cpu_seconds() -> f64;
        pub fn eb_free(h: c_int);
        pub fn eb_build_figures(
            verts: *const f32,
            nverts: usize,
            idx: *const u32,
            ntris: usize,
            config: *const c_char,
            commit_s: *mut f64,
            cpu_s: *mut f64,
            build_s: *mut f64,
            sah: *mut f64,
        ) -> c_int;
        pub fn eb_intersect1(h: c_int, rays: *const f32, n: usize) -> u64;
        pub fn eb_occluded1(h: c_int, rays: *const f32, n: usize) -> u64;
        pub fn eb_intersect16(h: c_int, rays: *const f32, n: usize, coherent: c_int) -> u64;
        pub fn eb_occluded16(h: c_int, rays: *const f32, n: usize, coherent: c_int) -> u64;
    }
}

/// An Embree scene over one triangle mesh (built once, traced from any number of threads).
pub struct Embree {
    #[cfg(embree)]
    handle: std::os::raw::c_int,
}

/// How a batch of rays is handed to Embree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Call {
    /// `rtcIntersect1` per ray.
    Intersect1,
    /// `rtcIntersect16` per 16 consecutive rays (coherent flag for tiles of primary rays).
    Intersect16 {
        /// Sets `RTC_INTERSECT_CONTEXT_FLAG_COHERENT`.
        coherent: bool,
    },
    /// `rtcOccluded1` per ray.
    Occluded1,
    /// `rtcOccluded16` per 16 consecutive rays.
    Occluded16 {
        /// Sets `RTC_INTERSECT_CONTEXT_FLAG_COHERENT`.
        coherent: bool,
    },
}

/// The instruction set Embree's device may use: by default the widest the CPU has (its
/// AVX-512 code on CPUs with AVX-512, 16 rays to a register in `rtcIntersect16`); the others
/// cap it, e.g. at AVX2, which our kernel uses for all but its packets' leaf tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Isa {
    /// The widest the CPU has.
    #[default]
    Best,
    /// `sse4.2`.
    Sse42,
    /// `avx`.
    Avx,
    /// `avx2`.
    Avx2,
    /// `avx512`.
    Avx512,
}

impl Isa {
    /// The names `--embree-isa` takes, with their values.
    pub const NAMES: [(&'static str, Isa); 5] = [
        ("best", Isa::Best),
        ("sse4.2", Isa::Sse42),
        ("avx", Isa::Avx),
        ("avx2", Isa::Avx2),
        ("avx512", Isa::Avx512),
    ];

    /// The ISA named `name` (one of [`Isa::NAMES`]).
    pub fn parse(name: &str) -> Result<Isa, String> {
        Isa::NAMES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, isa)| isa)
            .ok_or_else(|| {
                let names: Vec<&str> = Isa::NAMES.iter().map(|(n, _)| *n).collect();
                format!(
                    "--embree-isa {name:?}: expected one of {}",
                    names.join(", ")
                )
            })
    }

    /// The ISA an `--embree-isa` argument names; exits with status 2 and the list of names
    /// when it names none.
    pub fn from_arg(arg: Option<String>) -> Isa {
        Isa::parse(&arg.unwrap_or_default()).unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(2)
        })
    }

    /// Its name in [`Isa::NAMES`].
    pub fn name(self) -> &'static str {
        Isa::NAMES
            .iter()
            .find(|(_, i)| *i == self)
            .map_or("best", |(n, _)| n)
    }

    /// The device configuration: one build thread, the ISA cap (Embree's own names are
    /// those of [`Isa::NAMES`]), then `extra` (`",benchmark=1"` or nothing).
    #[cfg_attr(not(embree), allow(dead_code))]
    fn config(self, extra: &str) -> std::ffi::CString {
        let cap = match self {
            Isa::Best => String::new(),
            isa => format!(",isa={}", isa.name()),
        };
        // the names hold no NUL
        std::ffi::CString::new(format!("threads=1{cap}{extra}")).unwrap_or_default()
    }
}

/// One build of Embree's BVH, timed ([`Embree::build_figures`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildFigures {
    /// Wall time of `rtcCommitScene`, seconds.
    pub commit_seconds: f64,
    /// The process's CPU time over `rtcCommitScene` (all its threads), seconds.
    pub cpu_seconds: f64,
    /// Embree's own clock around the BVH build (from the triangles to the finished tree,
    /// primitive references and leaf blocks included), seconds.
    pub build_seconds: f64,
    /// The SAH of its BVH statistics (node traversal 1, a leaf block 1, half areas relative to
    /// the root's).
    pub sah: f64,
}

/// The mesh as the harness takes it: 3 floats a vertex, 3 vertices a triangle, and the
/// indices 0, 1, 2, ...
#[cfg_attr(not(embree), allow(dead_code))]
fn mesh_arrays(tris: &[[Vec3A; 3]]) -> (Vec<f32>, Vec<u32>) {
    let verts: Vec<f32> = tris
        .iter()
        .flat_map(|t| t.iter().flat_map(|v| [v.x, v.y, v.z]))
        .collect();
    let idx: Vec<u32> = (0..(3 * tris.len()) as u32).collect();
    (verts, idx)
}

/// Rays as the harness takes them: origin and direction, 6 floats each.
pub fn flat(rays: &[ring_tracer_kernel::Ray]) -> Vec<f32> {
    rays.iter()
        .flat_map(|r| {
            let (o, d) = (r.origin, r.dir);
            [o.x, o.y, o.z, d.x, d.y, d.z]
        })
        .collect()
}

impl Embree {
    /// Embree's version, or why it is not there.
    pub fn version() -> Result<String, String> {
        #[cfg(embree)]
        {
            // SAFETY: eb_version returns a pointer to a static NUL-terminated string literal.
            let v = unsafe { std::ffi::CStr::from_ptr(ffi::eb_version()) };
            Ok(v.to_string_lossy().into_owned())
        }
        #[cfg(not(embree))]
        {
            Err(
                "Embree 3 was not found when this bench was built (Debian: apt-get install \
                 libembree-dev, then rebuild)"
                    .into(),
            )
        }
    }

    /// Builds Embree's BVH over the triangles (each given by its three corners), on a device
    /// capped at `isa`.
    pub fn new(tris: &[[Vec3A; 3]], isa: Isa) -> Result<Embree, String> {
        #[cfg(embree)]
        {
            let (verts, idx) = mesh_arrays(tris);
            // SAFETY: `verts` holds 3 floats per vertex for 3 * tris.len() vertices and `idx`
            // 3 indices per triangle, all below the vertex count; eb_new copies both before
            // returning and keeps no pointer to them; `config` is a NUL-terminated string that
            // outlives the call. Calls on several threads at once are sound: each claims its
            // slot of the C side's table with one atomic exchange, so no two live values share
            // a handle (`scenes_built_on_several_threads_at_once_stay_apart`).
            let config = isa.config("");
            let handle = unsafe {
                ffi::eb_new(
                    verts.as_ptr(),
                    idx.len(),
                    idx.as_ptr(),
                    tris.len(),
                    config.as_ptr(),
                )
            };
            if handle < 0 {
                return Err("Embree refused the device or the scene".into());
            }
            Ok(Embree { handle })
        }
        #[cfg(not(embree))]
        {
            let _ = (tris, isa);
            Err(Embree::version().unwrap_err())
        }
    }

    /// Builds Embree's BVH over the triangles once more, on a device capped at `isa` in
    /// benchmark mode, and gives its build time and SAH figure (which Embree prints to the
    /// standard output: the harness captures file descriptor 1 for the build, so nothing else
    /// may print meanwhile; this flushes Rust's buffer first).
    pub fn build_figures(tris: &[[Vec3A; 3]], isa: Isa) -> Result<BuildFigures, String> {
        #[cfg(embree)]
        {
            use std::io::Write;
            let (verts, idx) = mesh_arrays(tris);
            let config = isa.config(",benchmark=1");
            let mut f = BuildFigures {
                commit_seconds: 0.0,
                cpu_seconds: 0.0,
                build_seconds: 0.0,
                sah: 0.0,
            };
            let _ = std::io::stdout().flush();
            // SAFETY: the arrays are as for eb_new (copied before the call returns, no pointer
            // kept), `config` is NUL-terminated and outlives the call, and the three outputs
            // are valid, distinct f64s. The call claims no slot and frees all it makes.
            let status = unsafe {
                ffi::eb_build_figures(
                    verts.as_ptr(),
                    idx.len(),
                    idx.as_ptr(),
                    tris.len(),
                    config.as_ptr(),
                    &mut f.commit_seconds,
                    &mut f.cpu_seconds,
                    &mut f.build_seconds,
                    &mut f.sah,
                )
            };
            match status {
                0 => Ok(f),
                -1 => Err("Embree refused the device or the scene".into()),
                -2 => Err("the standard output could not be captured for Embree's build".into()),
                -3 => Err("Embree's build printed no BENCHMARK_BUILD line".into()),
                e => Err(format!(
                    "Embree's build failed with device error {}",
                    -100 - e
                )),
            }
        }
        #[cfg(not(embree))]
        {
            let _ = (tris, isa);
            Err(Embree::version().unwrap_err())
        }
    }

    /// The process's CPU time in seconds (all its threads, nanosecond resolution), or `None`
    /// without the harness.
    pub fn cpu_seconds() -> Option<f64> {
        #[cfg(embree)]
        {
            // SAFETY: reads a clock; no arguments, no state.
            Some(unsafe { ffi::eb_cpu_seconds() })
        }
        #[cfg(not(embree))]
        {
            None
        }
    }

    /// Traces `rays` (6 floats each, see [`flat`]); returns how many hit.
    pub fn trace(&self, call: Call, rays: &[f32]) -> u64 {
        #[cfg(embree)]
        {
            let n = rays.len() / 6;
            let p = rays.as_ptr();
            let h = self.handle;
            // SAFETY: `p` points to `n` complete rays of 6 floats that stay borrowed for the
            // call; `h` is a live handle (freed only in Drop) that no other value holds; the
            // harness only reads the rays, its packet calls hand Embree the 64-byte aligned
            // masks it requires, and Embree's scenes may be traced from several threads at once.
            unsafe {
                match call {
                    Call::Intersect1 => ffi::eb_intersect1(h, p, n),
                    Call::Occluded1 => ffi::eb_occluded1(h, p, n),
                    Call::Intersect16 { coherent } => ffi::eb_intersect16(h, p, n, coherent as _),
                    Call::Occluded16 { coherent } => ffi::eb_occluded16(h, p, n, coherent as _),
                }
            }
        }
        #[cfg(not(embree))]
        {
            let _ = (call, rays);
            0
        }
    }
}

impl Drop for Embree {
    fn drop(&mut self) {
        #[cfg(embree)]
        // SAFETY: the handle came from eb_new and is freed once, here.
        unsafe {
            ffi::eb_free(self.handle)
        };
    }
}

#[cfg(all(test, embree))]
mod tests {
    use super::*;
    use ring_tracer_kernel::Ray;

    #[test]
    fn embree_counts_hits_like_the_geometry_says() {
        // a unit square in z = 0 as two triangles; rays down -z over a 4 x 4 grid, half inside
        let q = [
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(1.0, 1.0, 0.0),
            Vec3A::new(0.0, 1.0, 0.0),
        ];
        assert!(!Embree::version().unwrap().is_empty());
        // every ISA cap the CPU can run (Embree refuses a device above what the CPU has)
        let caps = [Isa::Best, Isa::Sse42, Isa::Avx, Isa::Avx2, Isa::Avx512];
        let tris = [[q[0], q[1], q[2]], [q[0], q[2], q[3]]];
        let devices: Vec<Embree> = caps
            .iter()
            .filter_map(|&i| Embree::new(&tris, i).ok())
            .collect();
        assert!(devices.len() >= 2, "{} devices", devices.len());
        let rays: Vec<Ray> = (0..17)
            .map(|i| {
                let x = (i % 4) as f32 * 0.5 + 0.1;
                let y = (i / 4 % 4) as f32 * 0.5 + 0.1;
                Ray::new(Vec3A::new(x, y, 1.0), -Vec3A::Z)
            })
            .collect();
        // x, y in {0.1, 0.6, 1.1, 1.6}: 4 of each 16 are inside; the 17th ray is (0.1, 0.1)
        let f = flat(&rays);
        for call in [
            Call::Intersect1,
            Call::Occluded1,
            Call::Intersect16 { coherent: true },
            Call::Occluded16 { coherent: false },
        ] {
            for e in &devices {
                assert_eq!(e.trace(call, &f), 5, "{call:?}");
            }
        }
    }

    /// Three scenes built at once on three threads, each a square of its own size: every one
    /// answers for its own square, so no two share a slot. (Three: the test beside it may hold
    /// five of the C side's eight slots meanwhile.)
    #[test]
    fn scenes_built_on_several_threads_at_once_stay_apart() {
        let rays: Vec<Ray> = (0..64)
            .map(|i| {
                let x = (i % 8) as f32 + 0.5;
                let y = (i / 8) as f32 + 0.5;
                Ray::new(Vec3A::new(x, y, 1.0), -Vec3A::Z)
            })
            .collect();
        let f = flat(&rays);
        for _round in 0..5 {
            let start = std::sync::Barrier::new(3);
            let built = std::sync::Barrier::new(3);
            std::thread::scope(|s| {
                let handles: Vec<_> = (1..=3u32)
                    .map(|k| {
                        let (start, built, f) = (&start, &built, &f);
                        s.spawn(move || {
                            // a k x k square from the origin: k * k of the 8 x 8 rays hit it
                            let side = k as f32;
                            let q = [
                                Vec3A::ZERO,
                                Vec3A::new(side, 0.0, 0.0),
                                Vec3A::new(side, side, 0.0),
                                Vec3A::new(0.0, side, 0.0),
                            ];
                            let tris = [[q[0], q[1], q[2]], [q[0], q[2], q[3]]];
                            start.wait();
                            let e = Embree::new(&tris, Isa::Best);
                            // every scene lives until all are built
                            built.wait();
                            let e = e.expect("a free slot for each scene");
                            (k, e.handle, e.trace(Call::Intersect1, f))
                        })
                    })
                    .collect();
                let mut seen = std::collections::HashSet::new();
                for h in handles {
                    let (k, handle, hits) = h.join().unwrap();
                    assert_eq!(hits, (k * k) as u64, "scene {k}");
                    assert!(seen.insert(handle), "handle {handle} twice");
                }
            });
        }
    }

    /// Forty unit squares in a row, a triangle pair each: Embree's build reports a time and
    /// an SAH of at least the root's own 1, as our figure of the same triangles does.
    #[test]
    fn build_figures_report_time_and_sah() {
        let mut tris = Vec::new();
        for k in 0..40 {
            let x = k as f32;
            let q = [
                Vec3A::new(x, 0.0, 0.0),
                Vec3A::new(x + 1.0, 0.0, 0.0),
                Vec3A::new(x + 1.0, 1.0, 0.0),
                Vec3A::new(x, 1.0, 0.0),
            ];
            tris.push([q[0], q[1], q[2]]);
            tris.push([q[0], q[2], q[3]]);
        }
        let f = Embree::build_figures(&tris, Isa::Best).unwrap();
        assert!((1.0..100.0).contains(&f.sah), "{f:?}");
        assert!(
            f.build_seconds > 0.0 && f.commit_seconds >= f.build_seconds,
            "{f:?}"
        );
        let ours = ring_tracer_kernel::bvh::TriangleTree::build(&tris)
            .unwrap()
            .sah();
        assert!((1.0..100.0).contains(&ours), "{ours}");
    }

    #[test]
    fn isa_names_round_trip() {
        for (name, isa) in Isa::NAMES {
            assert_eq!(Isa::parse(name), Ok(isa));
            assert_eq!(isa.name(), name);
        }
        let e = Isa::parse("avx2,threads=64").unwrap_err();
        assert!(e.contains("expected one of best, sse4.2"), "{e}");
    }
}
