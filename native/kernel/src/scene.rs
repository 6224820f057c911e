//! The scene: camera, background, lights, materials, primitives and their BVH, and instances
//! of shared meshes with theirs ([`crate::instance`]).
//!
//! A file per concept: this one holds the [`Scene`] type, its parts and its accessors;
//! `queries` its closest-hit and any-hit queries, `shadow_cache` the any-hit query that
//! remembers the last occluder, `surface` what a hit sees, `frames` the scenes derived from
//! one for an animation's frames, and `builder` the [`SceneBuilder`] the parsers fill.

mod builder;
mod frames;
mod queries;
mod shadow_cache;
mod stream;
mod surface;
#[cfg(test)]
mod tuning;

pub(crate) use builder::SceneBuilder;
pub(crate) use queries::Mailbox;

use crate::bvh::Bvh;
use crate::camera::Camera;
use crate::files::Unreadable;
use crate::geometry::{Aabb, Geometry, Shape};
use crate::instance::{Instance, Mesh};
use crate::light::Light;
use crate::limits;
use crate::material::Material;
use crate::tri4::TriBlocks;
use crate::warning::Warnings;
use crate::Error;
use glam::{Affine3A, Vec3A};
use std::path::Path;
use std::sync::Arc;

/// Scene file formats, chosen by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Eric Haines' Neutral File Format (`.nff`), see [`crate::nff`].
    Nff,
    /// RingTracer's native TOML scene format (`.toml`), see [`crate::toml_scene`].
    Toml,
    /// A Wavefront OBJ mesh (`.obj`) shown with a default camera and light, see [`crate::obj`].
    Obj,
}

impl Format {
    /// Picks the format from the file extension (case-insensitive).
    pub fn from_path(path: &str) -> Result<Format, Error> {
        let ext = Path::new(path)
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("nff") => Ok(Format::Nff),
            Some("toml") => Ok(Format::Toml),
            Some("obj") => Ok(Format::Obj),
            _ => Err(Error::Unsupported(format!(
                "{path}: unknown scene format (expected a .nff, .toml or .obj file)"
            ))),
        }
    }
}

/// A mesh instance as the scene placed it: which mesh, where, with what material.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Placement {
    pub mesh: u32,
    pub xf: Affine3A,
    pub material: u32,
}

/// Per-primitive shading data, in BVH order.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PrimInfo {
    pub material: u32,
    /// Index into `patch_normals`, or `u32::MAX`.
    pub normals: u32,
}

const NO_NORMALS: u32 = u32::MAX;

/// An infinite two-sided plane (native format only; kept outside the BVH).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Plane {
    pub normal: Vec3A,
    pub d: f32,
    pub material: u32,
}

/// The closest intersection found by [`Scene::intersect`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit-direction) ray.
    pub t: f32,
    /// With `instance == Hit::NO_INSTANCE`: internal primitive index,
    /// `0..internal_primitive_count()`: bounded primitives first (in BVH order), then planes.
    /// Otherwise the triangle's index in the instance's mesh (in the mesh's BVH order).
    pub prim: u32,
    /// Index of the mesh instance hit, `0..instance_count()`, or [`Hit::NO_INSTANCE`].
    pub instance: u32,
}

impl Hit {
    /// [`Hit::instance`] of a hit on one of the scene's own primitives.
    pub const NO_INSTANCE: u32 = u32::MAX;
}

/// A ready-to-render scene. Immutable, `Send + Sync`.
#[derive(Clone, Debug)]
pub struct Scene {
    pub(crate) camera: Camera,
    pub(crate) resolution: (u32, u32),
    pub(crate) background: Vec3A,
    pub(crate) ambient: Vec3A,
    pub(crate) lights: Vec<Light>,
    pub(crate) materials: Vec<Material>,
    pub(crate) geom: Arc<Geometry>,
    pub(crate) info: Arc<Vec<PrimInfo>>,
    pub(crate) patch_normals: Arc<Vec<[Vec3A; 3]>>,
    pub(crate) planes: Arc<Vec<Plane>>,
    pub(crate) bvh: Arc<Bvh>,
    /// The triangles of `bvh`'s all-triangle leaves, four to a SIMD block.
    pub(crate) tri_blocks: Arc<TriBlocks>,
    /// Shared meshes, each stored once.
    pub(crate) meshes: Arc<Vec<Mesh>>,
    /// References to them, in the order of `instance_bvh`'s leaves.
    pub(crate) instances: Arc<Vec<Instance>>,
    /// The top-level BVH, over the instances' world boxes.
    pub(crate) instance_bvh: Arc<Bvh>,
    /// The instances as the scene placed them, in its order (not the BVH's), for
    /// [`Scene::with_moved_instances`].
    pub(crate) placements: Arc<Vec<Placement>>,
    /// Bounds of the scene's own primitives (planes excluded), without the instances.
    pub(crate) own_bounds: Aabb,
    pub(crate) epsilon: f32,
    pub(crate) bounds: Aabb,
    pub(crate) source_count: usize,
    /// Colours in the file are display values, as in the SPD (see [`Scene::display_referred`]).
    pub(crate) display_referred: bool,
    /// What parsed but may not render as meant ([`Scene::warnings`]).
    pub(crate) warnings: Warnings,
}

impl Scene {
    /// Parse scene bytes. `name` is used in error messages (the file name). `resolve` loads files
    /// the scene references (OBJ meshes, MTL) by the relative path written in the scene; it
    /// returns their bytes or why it could not ([`Unreadable`]).
    pub fn parse(
        bytes: &[u8],
        format: Format,
        name: &str,
        resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    ) -> Result<Scene, Error> {
        limits::check_file_size(format!("the size of {name}"), bytes.len() as u64)?;
        let bytes = crate::files::without_bom(bytes);
        match format {
            Format::Nff => crate::nff::parse(bytes, name),
            Format::Toml => crate::toml_scene::parse(bytes, name, resolve),
            Format::Obj => crate::obj::parse_scene(bytes, name, resolve),
        }
    }

    /// Convenience: reads the file ([`files::open_scene`]) and the files it references,
    /// relative to the folder it was read in and confined to it ([`files::Confinement`]). An
    /// animated scene gives its first frame ([`crate::AnimatedScene::load`] gives them all).
    pub fn load(path: &Path) -> Result<Scene, Error> {
        Ok(crate::AnimatedScene::load(path)?.into_first_frame())
    }

    /// What parsed but may not render as meant (a degenerate primitive left out, a colour
    /// outside its useful range, an OBJ face whose material is missing), each with its file and
    /// line: the first [`limits::MAX_WARNINGS`] and a count of the rest. Empty for a clean file.
    pub fn warnings(&self) -> &Warnings {
        &self.warnings
    }

    /// Default image size from the scene.
    pub fn resolution(&self) -> (u32, u32) {
        self.resolution
    }

    /// Number of primitives as the scene describes them (a polygon counts once even though it
    /// is triangulated internally; mesh triangles count one each; degenerate ones are left out,
    /// each with a warning).
    /// A mesh counts its triangles once per reference, whether it is instanced or flattened:
    /// this is what the image holds, not what is stored (see
    /// [`Scene::stored_primitive_count`]).
    pub fn primitive_count(&self) -> usize {
        self.source_count
    }

    /// The scene's own triangles as corner triples (`v0, v0 + e1, v0 + e2`), in BVH order; other
    /// shapes and the triangles of instanced meshes are left out. For handing the same mesh to
    /// another kernel in comparisons (see [`crate::raysets`]).
    pub fn triangles(&self) -> Vec<[Vec3A; 3]> {
        self.geom
            .shapes
            .iter()
            .filter_map(|s| match *s {
                Shape::Triangle { v0, e1, e2 } => Some([v0, v0 + e1, v0 + e2]),
                _ => None,
            })
            .collect()
    }

    /// Number of the scene's own internal primitives (triangles after polygon triangulation,
    /// spheres, cones, planes; the triangles of shared meshes are not among them);
    /// [`Hit::prim`] indexes these when [`Hit::instance`] is [`Hit::NO_INSTANCE`].
    pub fn internal_primitive_count(&self) -> usize {
        self.geom.shapes.len() + self.planes.len()
    }

    /// Number of primitives held in memory: the internal ones plus each shared mesh's
    /// triangles once, however many instances draw it. [`limits::MAX_PRIMITIVES`] bounds this.
    pub fn stored_primitive_count(&self) -> usize {
        self.internal_primitive_count() + self.meshes.iter().map(|m| m.tris.len()).sum::<usize>()
    }

    /// Number of shared meshes (each mesh file instanced by the scene, stored once).
    pub fn mesh_count(&self) -> usize {
        self.meshes.len()
    }

    /// Number of mesh instances (references drawn from a shared mesh).
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    /// Whether the scene's colours are display values rather than linear light. NFF scenes are:
    /// the SPD's renderers wrote the computed values straight to the 8-bit frame buffer, so a
    /// colour of 0.5 meant code 128 on screen. Such a scene's traced pixels are decoded from
    /// sRGB at the end of [`crate::trace_span`] (clamped to [0, 1] first), so that the film's
    /// sRGB encoding gives back the SPD's values and OpenEXR holds the linear light they show.
    pub fn display_referred(&self) -> bool {
        self.display_referred
    }

    /// Replaces the lighting conventions: the ambient intensity, and the colour of every light.
    /// NFF leaves both to the renderer (we follow the SPD Readme by default); this lets a scene
    /// be rendered as another renderer lit it, e.g. the SPD's pictures (ambient 0, lights 1).
    pub fn relight(&mut self, ambient: Vec3A, light: Vec3A) {
        self.ambient = ambient;
        self.lights.iter_mut().for_each(|l| l.color = light);
    }

    /// Number of lights.
    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Bounding box of the bounded primitives and the mesh instances (planes excluded).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Material `index` (the default one if there is no such material), by reference: the
    /// shading of a hit reads a few of its fields, not all of it.
    pub(crate) fn material(&self, index: u32) -> &Material {
        self.materials
            .get(index as usize)
            .unwrap_or(&Material::DEFAULT)
    }
}

/// The offset of secondary rays' origins: a fraction of the extent of the scene and the eye.
fn epsilon_for(bounds: Aabb, camera: &Camera) -> f32 {
    let extent = bounds.grow(camera.from).diagonal();
    (extent * 1e-5).max(1e-6)
}
