//! # ring_tracer_kernel
//!
//! RingTracer's ray-tracing kernel: scene parsing (NFF, native TOML, OBJ), a binned-SAH BVH,
//! Whitted-style recursive ray tracing, and PNG/EXR output. Plain Rust; the Erlang NIF lives
//! in a separate crate.
//!
//! ```no_run
//! use ring_tracer_kernel::{render_image, write_image, Scene, Settings};
//! let scene = Scene::load(std::path::Path::new("balls_s1.nff"))?;
//! let settings = Settings::for_scene(&scene);
//! let (rgb, stats) = render_image(&scene, &settings, 2)?;
//! write_image(std::path::Path::new("balls.png"), settings.width, settings.height, &rgb)?;
//! println!("{} eye rays, {} shadow rays", stats.eye, stats.shadow);
//! # Ok::<(), ring_tracer_kernel::Error>(())
//! ```
//!
//! Determinism: [`trace_span`] is a pure function of (scene, settings, pixel index), so any split
//! of the image into spans, on any number of threads or machines, gives the same bits.
//!
//! ## Map of the crate
//! - [`nff`], [`toml_scene`], [`obj`]: scene formats (all errors are `file:line: problem`;
//!   text of the file is echoed only escaped and cut short); [`limits`]: bounds checked before
//!   allocating; [`memory`]: input-sized arrays allocated fallibly, checked against the
//!   address space left; [`warning`]: what parses but may not render as meant
//!   ([`Scene::warnings`]); [`files`]: the files a scene may read (regular files only, size-checked, and
//!   referenced files confined to the scene's folder by [`files::Confinement`]).
//! - [`animation`]: the clock of each frame (POV-Ray's) and key lists (linear, Catmull-Rom);
//!   [`animated`]: [`AnimatedScene`], a TOML scene's `[animation]` and the [`Scene`] of each
//!   frame (camera, light and colour changes share the first frame's BVH).
//! - [`scene`]: [`Scene`] (camera, lights, materials, primitives, BVH) and its queries
//!   ([`Scene::intersect`], [`Scene::occluded`]); [`geometry`]: spheres, triangles (smooth
//!   patches keep vertex normals), polygons, cones/cylinders, infinite planes; [`polygon`]:
//!   polygons are ear-clipped into triangles, or kept whole with an edge BVH that answers the
//!   crossing rule in O(log n) per ray; [`bvh`]: binned-SAH BVH with 8-wide SIMD nodes (AVX2, else
//!   portable code);
//!   `packet` (private): coherent rays through it sixteen at a time
//!   ([`Scene::intersect_packet`], [`Scene::occluded_packet`], the same answers as one ray at a
//!   time), its leaf tests eight or sixteen rays to a vector (`lanes`, private); [`stream`]:
//!   long streams of incoherent rays reordered for coherence and traced one by one
//!   ([`Scene::intersect_stream`], [`Scene::occluded_stream`], the same answers);
//!   [`instance`]: a mesh referenced many times is stored once (triangles and BVH) and drawn
//!   by instances (transform, inverse, material) under a top-level BVH.
//! - [`raysets`]: the fixed ray sets of the ray-casting benchmarks.
//! - [`camera`], [`ray`], [`material`], [`light`]: the Whitted model's ingredients;
//!   [`integrator`]: the [`Integrator`] trait and [`Whitted`] (shading rules documented there).
//! - [`render`]: [`Settings`], [`trace_span`], [`render_image`] (SPD corner mode, stratified
//!   jittered sampling, adaptive cut-off); [`stats`]: [`RayStats`]; [`film`]: PNG/EXR output.
//!
//! ## Speed
//! f32 throughout with `glam::Vec3A`/`Vec4` (SSE2); primitives are an enum (no dynamic
//! dispatch); per-primitive data is precomputed (triangle edges, cone frames); BVH traversal
//! tests eight boxes at once; shadow rays are any-hit with a per-light shadow cache (the last
//! occluder is tried first, and dropped once it has let a few rays in a row through; the answer
//! does not depend on it), and test a leaf's spheres and triangles before its cones; no
//! allocation per ray.
#![deny(missing_docs)]

pub mod animated;
pub mod animation;
pub mod bvh;
pub mod camera;
pub mod error;
pub mod files;
pub mod film;
pub mod geometry;
pub mod instance;
pub mod integrator;
mod lanes;
pub mod light;
pub mod limits;
pub mod material;
pub mod memory;
pub mod nff;
pub mod obj;
mod packet;
pub mod polygon;
pub mod ray;
pub mod raysets;
pub mod render;
pub mod safe_fs;
pub mod scene;
pub mod stats;
pub mod stream;
#[cfg(test)]
mod test_support;
pub mod toml_scene;
mod tri4;
pub mod warning;

pub use animated::AnimatedScene;
pub use animation::{Animation, Interpolation, Track};
pub use bvh::Scratch;
pub use camera::Camera;
pub use error::Error;
pub use film::{
    encode_png, encode_png8, to_srgb8, write_image, write_image_in, write_image_mode, write_png8_in,
};
pub use geometry::Aabb;
pub use glam;
pub use integrator::{Integrator, Whitted};
pub use light::Light;
pub use material::{Checker, Material};
pub use ray::Ray;
pub use render::{
    render_image, render_image_into, trace_span, trace_span_into, work_by_row, Region, Settings,
};
pub use scene::{Format, Hit, Scene};
pub use stats::{Counter, RayStats};
pub use stream::StreamScratch;
pub use warning::{Warning, Warnings};
