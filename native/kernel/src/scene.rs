//! The scene: camera, background, lights, materials, primitives and their BVH, and instances
//! of shared meshes with theirs ([`crate::instance`]).

use crate::bvh::{Bvh, Scratch};
use crate::camera::Camera;
use crate::files::Unreadable;
use crate::geometry::{hit_triangle, make_cone, Aabb, Geometry, Shape};
use crate::instance::{Instance, Mesh, Tri, OWN_MATERIAL};
use crate::light::Light;
use crate::limits;
use crate::material::Material;
use crate::memory;
use crate::polygon::{self, ear_clip};
use crate::ray::Ray;
use crate::tri4::{RayLanes, TriBlocks};
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

/// No shadow-cache entry.
const NO_CACHE: (u32, u32) = (u32::MAX, u32::MAX);

/// Shadow-cache slots a [`Scratch`] may hold ([`Scene::occluded_cached`]).
const CACHE_SLOTS: usize = 1 << 19;

/// A cached occluder is dropped once it has let this many shadow rays of its slot in a row
/// through: where few rays are blocked (most of a scene's shadow rays reach their light), a
/// stale entry costs a test per ray and saves nothing.
const CACHE_PATIENCE: u32 = 4;

/// Stores `occluder` and its count of rays let through at shadow-cache `entry` (see
/// [`Scene::occluded_cached`]), growing the cache as needed.
#[inline]
fn set_cache(scratch: &mut Scratch, entry: Option<usize>, occluder: (u32, u32), misses: u32) {
    let Some(e) = entry else { return };
    if scratch.shadow_cache.len() < e + 2 {
        scratch.shadow_cache.resize(e + 2, NO_CACHE);
    }
    if let Some([c, m]) = scratch.shadow_cache.get_mut(e..e + 2) {
        *c = occluder;
        *m = (misses, 0);
    }
}

/// Local surface description at a hit.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Surface {
    pub p: Vec3A,
    /// Geometric normal, primitive's own orientation.
    pub ng: Vec3A,
    /// Shading normal, in the same hemisphere as `ng`.
    pub ns: Vec3A,
    pub material: u32,
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

    /// Closest hit along `ray` with `0 < t < tmax`. Convenience form; loops should keep one
    /// [`Scratch`] per thread and call [`Scene::intersect_with`].
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<Hit> {
        self.intersect_with(ray, tmax, &mut Scratch::new())
    }

    /// [`Scene::intersect`] reusing a traversal stack (for hot loops: one `Scratch` per thread).
    ///
    /// Among hits at the same distance the lowest primitive index wins (whatever the order the
    /// leaves are visited in), so [`Scene::intersect_packet`] finds the same hits.
    #[inline]
    pub fn intersect_with(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> Option<Hit> {
        let mut prim = u32::MAX;
        let mut mailbox = Mailbox::default();
        let lanes = RayLanes::new(ray);
        let best = self
            .bvh
            // inlined into the traversal: a call there would spill the ray's vectors per node
            .traverse_prefetching::<true>(
                ray,
                tmax,
                &mut scratch.stack,
                &mut scratch.work,
                #[inline(always)]
                |first, count, tm| {
                    self.leaf_closest(first, count, ray, &lanes, &mut mailbox, tm, &mut prim)
                },
                |first, count| self.tri_blocks.prefetch(first, count),
            );
        self.finish_closest(ray, best, prim, scratch)
    }

    /// The closest-hit test of one BVH leaf `(first, count)` for `ray`, whose best hit so far is
    /// `prim` at `tm` (`prim == u32::MAX`: none, `tm` the bound). Returns the new bound and
    /// updates `prim`: a hit replaces it when nearer, or at the same distance with a lower index,
    /// so the result over several leaves does not depend on their order.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn leaf_closest(
        &self,
        first: usize,
        count: usize,
        ray: &Ray,
        lanes: &RayLanes,
        mailbox: &mut Mailbox,
        mut tm: f32,
        prim: &mut u32,
    ) -> f32 {
        // a hit at exactly `tm` is taken only if it has a lower index than the hit there
        let limit = |tm: f32, prim: u32| if prim == u32::MAX { tm } else { tm.next_up() };
        if let Some(leaf) = self.tri_blocks.leaf(first, count) {
            for b in leaf {
                if let Some((i, t)) = b.closest(lanes, 0.0, limit(tm, *prim)) {
                    let p = b.prim(i);
                    if t < tm || p < *prim {
                        tm = t;
                        *prim = p;
                    }
                }
            }
            return tm;
        }
        if let Some(range) = self.geom.shapes.get(first..first + count) {
            for (k, s) in range.iter().enumerate() {
                if mailbox.seen(s) {
                    continue;
                }
                if let Some(t) = self.geom.hit(s, ray, 0.0, limit(tm, *prim)) {
                    let p = (first + k) as u32;
                    if t < tm || p < *prim {
                        tm = t;
                        *prim = p;
                    }
                }
            }
        }
        tm
    }

    /// The rest of a closest-hit query after the scene's own BVH gave `prim` at `best`
    /// (`u32::MAX`: nothing before `best`): the mesh instances, then the planes.
    #[inline]
    pub(crate) fn finish_closest(
        &self,
        ray: &Ray,
        mut best: f32,
        mut prim: u32,
        scratch: &mut Scratch,
    ) -> Option<Hit> {
        let shapes = &self.geom.shapes;
        let mut instance = Hit::NO_INSTANCE;
        if !self.instances.is_empty() {
            if let Some((t, i, p)) = self.intersect_instances(ray, best, scratch) {
                best = t;
                instance = i;
                prim = p;
            }
        }
        scratch.work += self.planes.len() as u64;
        for (k, pl) in self.planes.iter().enumerate() {
            let dn = pl.normal.dot(ray.dir);
            if dn != 0.0 {
                let t = (pl.d - pl.normal.dot(ray.origin)) / dn;
                if t > 0.0 && t < best {
                    best = t;
                    prim = (shapes.len() + k) as u32;
                    instance = Hit::NO_INSTANCE;
                }
            }
        }
        if prim == u32::MAX {
            None
        } else {
            Some(Hit {
                t: best,
                prim,
                instance,
            })
        }
    }

    /// Closest hit on a mesh instance before `tmax`: (t, instance, triangle). Without
    /// `ORDERED`, the first hit found (any-hit, for shadow rays; then t is negative).
    #[inline]
    fn instances_hit<const ORDERED: bool>(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(f32, u32, u32)> {
        let instances = &self.instances;
        let meshes = &self.meshes;
        let inner = &mut scratch.inner_stack;
        let mut inner_work = 0u64;
        let mut found = None;
        let t = self.instance_bvh.traverse_in::<ORDERED>(
            ray,
            tmax,
            &mut scratch.stack,
            &mut scratch.work,
            |first, count, tmax| {
                let mut tm = tmax;
                let Some(range) = instances.get(first..first + count) else {
                    return tm;
                };
                for (k, inst) in range.iter().enumerate() {
                    let Some(mesh) = meshes.get(inst.mesh as usize) else {
                        continue;
                    };
                    let oray = inst.object_ray(ray);
                    let r = mesh.bvh.traverse_in::<ORDERED>(
                        &oray,
                        tm,
                        inner,
                        &mut inner_work,
                        |f, c, tm2| {
                            let mut t2 = tm2;
                            if let Some(tris) = mesh.tris.get(f..f + c) {
                                for (j, tri) in tris.iter().enumerate() {
                                    if let Some((t, _, _)) =
                                        hit_triangle(tri[0], tri[1], tri[2], &oray, 0.0, t2)
                                    {
                                        found = Some(((first + k) as u32, (f + j) as u32));
                                        if !ORDERED {
                                            return -1.0;
                                        }
                                        t2 = t;
                                    }
                                }
                            }
                            t2
                        },
                    );
                    if !ORDERED && r < 0.0 {
                        return -1.0;
                    }
                    tm = r;
                }
                tm
            },
        );
        scratch.work += inner_work;
        found.map(|(i, p)| (t, i, p))
    }

    /// [`Scene::instances_hit`] for closest-hit queries.
    #[inline]
    fn intersect_instances(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(f32, u32, u32)> {
        self.instances_hit::<true>(ray, tmax, scratch)
    }

    /// Whether `ray` hits triangle `prim` of instance `instance` before `tmax`.
    #[inline]
    fn hits_instance_triangle(&self, instance: u32, prim: u32, ray: &Ray, tmax: f32) -> bool {
        let Some(inst) = self.instances.get(instance as usize) else {
            return false;
        };
        let Some(tri) = self
            .meshes
            .get(inst.mesh as usize)
            .and_then(|m| m.tris.get(prim as usize))
        else {
            return false;
        };
        hit_triangle(tri[0], tri[1], tri[2], &inst.object_ray(ray), 0.0, tmax).is_some()
    }

    /// Closest hits of a packet of rays (such as a 4 x 4 pixel tile of primary rays):
    /// `out[i]` gets what [`Scene::intersect_with`] returns for `rays[i]`, bit for bit, for
    /// `i < min(rays.len(), out.len())`. Coherent rays go through the BVH together, sixteen at
    /// a time (`packet.rs`).
    pub fn intersect_packet(
        &self,
        rays: &[Ray],
        tmax: f32,
        scratch: &mut Scratch,
        out: &mut [Option<Hit>],
    ) {
        crate::packet::trace(self, rays, |_| tmax, scratch, out, false);
    }

    /// [`Scene::intersect_packet`] for coherent rays (a tile of eye rays): every ray goes
    /// through the packet traversal, so the work it adds to `scratch` does not depend on the
    /// other rays of the packet (the renderer's work counts stay additive over any split).
    pub(crate) fn intersect_tile(
        &self,
        rays: &[Ray],
        scratch: &mut Scratch,
        out: &mut [Option<Hit>],
    ) {
        crate::packet::trace(self, rays, |_| f32::INFINITY, scratch, out, true);
    }

    /// Any-hit queries of a packet of rays (such as the shadow rays of a tile): `out[i]` gets
    /// what [`Scene::occluded_with`] returns for `rays[i]`. Coherent rays go through the BVH
    /// together, sixteen at a time, each done at its first hit (`packet.rs`).
    pub fn occluded_packet(
        &self,
        rays: &[Ray],
        tmax: f32,
        scratch: &mut Scratch,
        out: &mut [bool],
    ) {
        crate::packet::trace(self, rays, |_| tmax, scratch, out, false);
    }

    /// True if anything blocks `ray` before `tmax` (any-hit, early exit).
    pub fn occluded(&self, ray: &Ray, tmax: f32) -> bool {
        self.occluded_with(ray, tmax, &mut Scratch::new())
    }

    /// [`Scene::occluded`] reusing a traversal stack.
    #[inline]
    pub fn occluded_with(&self, ray: &Ray, tmax: f32, scratch: &mut Scratch) -> bool {
        self.occluded_cached(ray, tmax, scratch, usize::MAX)
    }

    /// Any-hit query with a shadow cache: `slot` (e.g. light and tree depth) remembers the last
    /// occluder found, which is tested first. The answer does not depend on the cache.
    pub(crate) fn occluded_cached(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
        slot: usize,
    ) -> bool {
        let shapes = &self.geom.shapes;
        let geom = &self.geom;
        // the slot's occluder at 2 slot, and at 2 slot + 1 how many rays in a row it let through
        let entry = (slot < CACHE_SLOTS).then_some(2 * slot);
        let (cached, misses) = match entry.map(|e| scratch.shadow_cache.get(e..e + 2)) {
            Some(Some(&[c, (m, _)])) => (c, m),
            _ => (NO_CACHE, 0),
        };
        if cached != NO_CACHE {
            let (ci, c) = cached;
            scratch.work += 1;
            let blocked = if ci == Hit::NO_INSTANCE {
                shapes
                    .get(c as usize)
                    .is_some_and(|s| geom.hit(s, ray, 0.0, tmax).is_some())
            } else {
                self.hits_instance_triangle(ci, c, ray, tmax)
            };
            if blocked {
                if misses != 0 {
                    self::set_cache(scratch, entry, cached, 0);
                }
                return true;
            }
        }
        let mut found = NO_CACHE;
        let mut mailbox = Mailbox::default();
        let blocks = &self.tri_blocks;
        // made at the first triangle leaf: most shadow rays of an analytic scene meet none
        let mut lanes = None;
        let r = self.bvh.traverse_prefetching::<false>(
            ray,
            tmax,
            &mut scratch.stack,
            &mut scratch.work,
            #[inline(always)]
            |first, count, tmax| {
                if let Some(leaf) = blocks.leaf(first, count) {
                    let lanes = lanes.get_or_insert_with(|| RayLanes::new(ray));
                    for b in leaf {
                        if let Some(i) = b.any(lanes, 0.0, tmax) {
                            found = (Hit::NO_INSTANCE, b.prim(i));
                            return -1.0;
                        }
                    }
                    return tmax;
                }
                if let Some(range) = shapes.get(first..first + count) {
                    // any hit will do: the cheap tests first, the cones (dearer) after
                    for (k, s) in range.iter().enumerate() {
                        if !matches!(s, Shape::Cone(_)) && geom.hit(s, ray, 0.0, tmax).is_some() {
                            found = (Hit::NO_INSTANCE, (first + k) as u32);
                            return -1.0;
                        }
                    }
                    for (k, s) in range.iter().enumerate() {
                        if !matches!(s, Shape::Cone(_)) || mailbox.seen(s) {
                            continue;
                        }
                        if geom.hit(s, ray, 0.0, tmax).is_some() {
                            found = (Hit::NO_INSTANCE, (first + k) as u32);
                            return -1.0;
                        }
                    }
                }
                tmax
            },
            |first, count| blocks.prefetch(first, count),
        );
        if r < 0.0 {
            self::set_cache(scratch, entry, found, 0);
            return true;
        }
        let beyond = self.occluded_beyond_bvh(ray, tmax, scratch);
        if let Some(f) = beyond.filter(|&f| f != NO_CACHE) {
            self::set_cache(scratch, entry, f, 0);
            return true;
        }
        if cached != NO_CACHE {
            // a cached occluder that keeps letting rays through is tested no more
            if misses + 1 >= CACHE_PATIENCE {
                self::set_cache(scratch, entry, NO_CACHE, 0);
            } else {
                self::set_cache(scratch, entry, cached, misses + 1);
            }
        }
        beyond.is_some()
    }

    /// The rest of an any-hit query once the scene's own BVH let `ray` through: the mesh
    /// instances, then the planes. `Some((instance, triangle))` for an instance's triangle,
    /// `Some(NO_CACHE)` for a plane, `None` when nothing blocks the ray before `tmax`.
    #[inline]
    pub(crate) fn occluded_beyond_bvh(
        &self,
        ray: &Ray,
        tmax: f32,
        scratch: &mut Scratch,
    ) -> Option<(u32, u32)> {
        if !self.instances.is_empty() {
            if let Some((_, i, p)) = self.instances_hit::<false>(ray, tmax, scratch) {
                return Some((i, p));
            }
        }
        scratch.work += self.planes.len() as u64;
        self.planes
            .iter()
            .any(|pl| {
                let dn = pl.normal.dot(ray.dir);
                dn != 0.0 && {
                    let t = (pl.d - pl.normal.dot(ray.origin)) / dn;
                    t > 0.0 && t < tmax
                }
            })
            .then_some(NO_CACHE)
    }

    /// Surface data at a hit.
    #[inline]
    pub(crate) fn surface(&self, hit: &Hit, ray: &Ray) -> Surface {
        let p = ray.at(hit.t);
        if hit.instance != Hit::NO_INSTANCE {
            return self.instance_surface(hit, ray, p);
        }
        let i = hit.prim as usize;
        if let Some(shape) = self.geom.shapes.get(i) {
            let ng = self.geom.geometric_normal(shape, p);
            let info = self.info.get(i).copied().unwrap_or(PrimInfo {
                material: 0,
                normals: NO_NORMALS,
            });
            let mut ns = ng;
            if info.normals != NO_NORMALS {
                if let (Shape::Triangle { v0, e1, e2 }, Some(nn)) =
                    (shape, self.patch_normals.get(info.normals as usize))
                {
                    let (u, v) = hit_triangle(*v0, *e1, *e2, ray, f32::NEG_INFINITY, f32::INFINITY)
                        .map_or((1.0 / 3.0, 1.0 / 3.0), |h| (h.1, h.2));
                    let n = nn[0] * (1.0 - u - v) + nn[1] * u + nn[2] * v;
                    if let Some(n) = n.try_normalize() {
                        ns = if n.dot(ng) < 0.0 { -n } else { n };
                    }
                }
            }
            Surface {
                p,
                ng,
                ns,
                material: info.material,
            }
        } else {
            let k = i.saturating_sub(self.geom.shapes.len());
            let (ng, material) = self
                .planes
                .get(k)
                .map_or((Vec3A::Z, 0), |pl| (pl.normal, pl.material));
            Surface {
                p,
                ng,
                ns: ng,
                material,
            }
        }
    }

    /// [`Scene::surface`] of a hit on a mesh instance: the geometric normal from the
    /// transformed edges, vertex normals through the inverse transpose (each normalised, then
    /// interpolated), as a flattened copy of the mesh would give them.
    fn instance_surface(&self, hit: &Hit, ray: &Ray, p: Vec3A) -> Surface {
        let none = Surface {
            p,
            ng: Vec3A::Z,
            ns: Vec3A::Z,
            material: 0,
        };
        let Some(inst) = self.instances.get(hit.instance as usize) else {
            return none;
        };
        let Some(mesh) = self.meshes.get(inst.mesh as usize) else {
            return none;
        };
        let i = hit.prim as usize;
        let (Some(tri), Some(info)) = (mesh.tris.get(i), mesh.info.get(i)) else {
            return none;
        };
        let ng = inst.geometric_normal(tri);
        let mut ns = ng;
        if let Some(nn) = mesh.patch_normals.get(info.normals as usize) {
            let oray = inst.object_ray(ray);
            let (u, v) = hit_triangle(
                tri[0],
                tri[1],
                tri[2],
                &oray,
                f32::NEG_INFINITY,
                f32::INFINITY,
            )
            .map_or((1.0 / 3.0, 1.0 / 3.0), |h| (h.1, h.2));
            let n = inst.normal(nn[0]) * (1.0 - u - v)
                + inst.normal(nn[1]) * u
                + inst.normal(nn[2]) * v;
            if let Some(n) = n.try_normalize() {
                ns = if n.dot(ng) < 0.0 { -n } else { n };
            }
        }
        Surface {
            p,
            ng,
            ns,
            material: if inst.material == OWN_MATERIAL {
                info.material
            } else {
                inst.material
            },
        }
    }

    /// Whether `self` and `other` draw the same built geometry (primitives, meshes and their
    /// BVHs, shared and not copied): true for two frames of an animation in which only the
    /// camera, the lights or material colours change ([`crate::AnimatedScene`]).
    pub fn shares_geometry_with(&self, other: &Scene) -> bool {
        Arc::ptr_eq(&self.bvh, &other.bvh)
            && Arc::ptr_eq(&self.geom, &other.geom)
            && Arc::ptr_eq(&self.instance_bvh, &other.instance_bvh)
    }

    /// Whether `self` and `other` draw the same primitives and meshes with the same BVHs
    /// below the top level (shared, not copied): true also for two frames of an animation in
    /// which only mesh instances move, whose top-level BVH is rebuilt.
    pub fn shares_primitives_with(&self, other: &Scene) -> bool {
        Arc::ptr_eq(&self.bvh, &other.bvh)
            && Arc::ptr_eq(&self.geom, &other.geom)
            && Arc::ptr_eq(&self.meshes, &other.meshes)
    }

    /// This scene seen by `camera`, lit by `lights`, with `materials`: the geometry and its
    /// BVH are shared, not rebuilt. The ray offset follows the camera as [`SceneBuilder::build`]
    /// makes it, so the result is the scene that building with these values would give.
    pub(crate) fn with_view(
        &self,
        camera: Camera,
        lights: Vec<Light>,
        materials: Vec<Material>,
    ) -> Scene {
        let mut s = self.clone();
        s.camera = camera;
        s.epsilon = epsilon_for(s.bounds, &camera);
        s.lights = lights;
        s.materials = materials;
        s
    }

    /// This scene with some mesh instances moved: `moved` gives (index in the order the scene
    /// placed them, new transform). Only the top-level BVH over the instances is built again;
    /// the meshes, their BVHs and the scene's own primitives are shared. `Ok(None)` names the
    /// first move whose transform is not invertible; `name` (the scene's file) is in an
    /// [`Error::Memory`].
    pub(crate) fn with_moved_instances(
        &self,
        moved: &[(usize, Affine3A)],
        name: &str,
    ) -> Result<Result<Scene, usize>, Error> {
        let mut placements: Vec<Placement> = self.placements.as_ref().clone();
        for (k, (i, xf)) in moved.iter().enumerate() {
            match placements.get_mut(*i) {
                Some(p) => p.xf = *xf,
                None => return Ok(Err(k)),
            }
        }
        let mut list = Vec::with_capacity(placements.len());
        let mut boxes = Vec::with_capacity(placements.len());
        for (i, p) in placements.iter().enumerate() {
            let (Some(inst), Some(mesh)) = (
                Instance::new(p.mesh, p.xf, p.material),
                self.meshes.get(p.mesh as usize),
            ) else {
                return Ok(Err(moved.iter().position(|m| m.0 == i).unwrap_or(0)));
            };
            list.push(inst);
            boxes.push(mesh.bounds_under(&p.xf));
        }
        let (instance_bvh, order) = Bvh::try_build_with(&boxes, crate::bvh::LEAF_MIN, &|| {
            format!("{name}: the BVH of the mesh instances")
        })?;
        let mut s = self.clone();
        s.instances = Arc::new(
            order
                .iter()
                .filter_map(|&i| list.get(i as usize).copied())
                .collect(),
        );
        s.instance_bvh = Arc::new(instance_bvh);
        s.placements = Arc::new(placements);
        s.bounds = boxes.iter().fold(self.own_bounds, |a, b| a.union(*b));
        s.epsilon = epsilon_for(s.bounds, &s.camera);
        Ok(Ok(s))
    }

    pub(crate) fn material(&self, index: u32) -> Material {
        self.materials
            .get(index as usize)
            .copied()
            .unwrap_or_default()
    }
}

/// Remembers the last cones tested along one ray: long oblique cones are referenced by several
/// BVH leaves, and a repeated test can never find anything new (the search interval only
/// shrinks).
#[derive(Clone, Copy, Default)]
pub(crate) struct Mailbox {
    recent: [u32; 2],
    used: bool,
}

impl Mailbox {
    #[inline(always)]
    fn seen(&mut self, s: &Shape) -> bool {
        let Shape::Cone(k) = *s else { return false };
        let key = k.wrapping_add(1);
        if self.used && (self.recent[0] == key || self.recent[1] == key) {
            return true;
        }
        self.used = true;
        self.recent[1] = self.recent[0];
        self.recent[0] = key;
        false
    }
}

/// Collects scene contents, then builds the BVH.
#[derive(Debug)]
pub(crate) struct SceneBuilder {
    pub camera: Option<Camera>,
    pub resolution: (u32, u32),
    pub background: Vec3A,
    /// Ambient intensity; `None` = SPD formula from the light count.
    pub ambient: Option<Vec3A>,
    pub lights: Vec<Light>,
    pub materials: Vec<Material>,
    geom: Geometry,
    info: Vec<PrimInfo>,
    patch_normals: Vec<[Vec3A; 3]>,
    planes: Vec<Plane>,
    poly_bounds: Vec<Aabb>,
    /// Primitives as the scene file counts them (a triangulated polygon is one; an instanced
    /// mesh counts its triangles once per instance).
    source_count: usize,
    /// Shared meshes, built by [`SceneBuilder::add_mesh`].
    meshes: Vec<Mesh>,
    /// Instances of them, and their world boxes.
    instances: Vec<Instance>,
    instance_bounds: Vec<Aabb>,
    /// How each instance was placed, in the same order.
    placements: Vec<Placement>,
    /// Primitives stored elsewhere that count towards the bound: the triangles of the shared
    /// meshes (and, in a builder from [`SceneBuilder::for_mesh`], the scene's primitives).
    stored_elsewhere: usize,
    /// [`limits::MAX_PRIMITIVES`]; a field only so tests can reach the bound cheaply.
    pub(crate) max_primitives: usize,
    /// [`limits::MAX_MESH_REFERENCES`], likewise.
    pub(crate) max_instances: usize,
    /// [`limits::MAX_MESH_TRIANGLES`], likewise (checked by [`crate::obj::load_mesh`]).
    pub(crate) max_mesh_triangles: usize,
    pub display_referred: bool,
    /// Warnings found so far (the parsers add them; [`Scene::warnings`]).
    pub warnings: Warnings,
}

/// A BVH over a geometry's shapes, with the shapes and their data put in its order, and the
/// bounds of it all. `blocks`: the leaves' triangles will be met four at a time
/// ([`TriBlocks`]), so an all-triangle geometry gets leaves of up to four. Every array whose
/// size the scene decides is checked against the memory left and allocated fallibly
/// ([`memory`]); `name` (the scene's file) is in the error.
fn ordered_bvh(
    geom: &Geometry,
    info: &[PrimInfo],
    poly_bounds: &[Aabb],
    blocks: bool,
    name: &str,
) -> Result<(Bvh, Vec<Shape>, Vec<PrimInfo>, Aabb), Error> {
    let n = geom.shapes.len();
    // BVH references: (shape index, box); oblique cones get several tight boxes
    let what =
        |array: &'static str| move || format!("{name}: the BVH's {array} for {n} primitives");
    let mut boxes: Vec<Aabb> = memory::try_with_capacity(n, what("boxes"))?;
    let mut owner: Vec<u32> = memory::try_with_capacity(n, what("box owners"))?;
    let mut tmp = Vec::new();
    for (i, s) in geom.shapes.iter().enumerate() {
        geom.split_bounds(s, poly_bounds, &mut tmp);
        memory::try_reserve(&mut boxes, tmp.len(), what("boxes"))?;
        memory::try_reserve(&mut owner, tmp.len(), what("box owners"))?;
        for b in &tmp {
            boxes.push(*b);
            owner.push(i as u32);
        }
    }
    // triangles are met four at a time: leaves of up to four are as cheap as one
    let all_triangles = blocks
        && geom
            .shapes
            .iter()
            .all(|s| matches!(s, Shape::Triangle { .. }));
    let leaf_min = if all_triangles {
        crate::bvh::LEAF_MIN_TRIANGLES
    } else {
        crate::bvh::LEAF_MIN
    };
    let (bvh, order) = Bvh::try_build_with(&boxes, leaf_min, &|| format!("{name}: the BVH"))?;
    let bounds = boxes.iter().fold(Aabb::EMPTY, |a, b| a.union(*b));
    // the boxes go before the ordered arrays are made: a parse's peak memory
    drop(boxes);
    let src = |r: &u32| owner.get(*r as usize).copied();
    // exactly sized: collected from a filter they would grow by doubling
    let mut shapes: Vec<Shape> = memory::try_with_capacity(order.len(), what("ordered shapes"))?;
    shapes.extend(
        order
            .iter()
            .filter_map(|r| src(r).and_then(|i| geom.shapes.get(i as usize).copied())),
    );
    let mut ordered_info: Vec<PrimInfo> =
        memory::try_with_capacity(order.len(), what("ordered shading data"))?;
    ordered_info.extend(
        order
            .iter()
            .filter_map(|r| src(r).and_then(|i| info.get(i as usize).copied())),
    );
    Ok((bvh, shapes, ordered_info, bounds))
}

/// The offset of secondary rays' origins: a fraction of the extent of the scene and the eye.
fn epsilon_for(bounds: Aabb, camera: &Camera) -> f32 {
    let extent = bounds.grow(camera.from).diagonal();
    (extent * 1e-5).max(1e-6)
}

impl SceneBuilder {
    pub fn new() -> SceneBuilder {
        SceneBuilder {
            camera: None,
            resolution: (512, 512),
            background: Vec3A::ZERO,
            ambient: None,
            display_referred: false,
            lights: Vec::new(),
            materials: Vec::new(),
            geom: Geometry::default(),
            info: Vec::new(),
            patch_normals: Vec::new(),
            planes: Vec::new(),
            poly_bounds: Vec::new(),
            source_count: 0,
            meshes: Vec::new(),
            instances: Vec::new(),
            instance_bounds: Vec::new(),
            placements: Vec::new(),
            stored_elsewhere: 0,
            max_primitives: limits::MAX_PRIMITIVES,
            max_instances: limits::MAX_MESH_REFERENCES,
            max_mesh_triangles: limits::MAX_MESH_TRIANGLES,
            warnings: Warnings::default(),
        }
    }

    /// Primitives stored so far, what [`limits::MAX_PRIMITIVES`] bounds: this builder's own,
    /// plus the shared meshes' triangles once each.
    fn stored(&self) -> usize {
        self.geom.shapes.len() + self.planes.len() + self.stored_elsewhere
    }

    /// A builder to load a shared mesh into (in object space, e.g. with
    /// [`crate::obj::load_mesh`] under the identity), whose primitives count towards this
    /// builder's bound; hand it to [`SceneBuilder::add_mesh`].
    pub fn for_mesh(&self) -> SceneBuilder {
        let mut b = SceneBuilder::new();
        b.max_primitives = self.max_primitives;
        b.max_mesh_triangles = self.max_mesh_triangles;
        b.stored_elsewhere = self.stored();
        b
    }

    /// Adds a shared mesh from a builder made by [`SceneBuilder::for_mesh`] holding only
    /// triangles (others are ignored): builds its BVH and takes over its materials. Returns
    /// the mesh's index for [`SceneBuilder::instance`]. `name` (the mesh's file) is named in
    /// an [`Error::Memory`].
    pub fn add_mesh(&mut self, mut mesh: SceneBuilder, name: &str) -> Result<u32, Error> {
        // the mesh file's warnings are the scene's (read once, they are said once)
        self.warnings.absorb(std::mem::take(&mut mesh.warnings));
        let base = self.materials.len() as u32;
        self.materials.extend(mesh.materials.iter().copied());
        let (bvh, shapes, info, _) =
            ordered_bvh(&mesh.geom, &mesh.info, &mesh.poly_bounds, false, name)?;
        let n = shapes.len();
        let mut tris: Vec<Tri> =
            memory::try_with_capacity(n, || format!("{name}: the {n} triangles of the mesh"))?;
        let mut infos =
            memory::try_with_capacity(n, || format!("{name}: the shading data of {n} triangles"))?;
        for (s, i) in shapes.iter().zip(&info) {
            // only triangles are expected; anything else would break the BVH order, so the
            // mesh is then dropped whole rather than drawn wrong
            let Shape::Triangle { v0, e1, e2 } = *s else {
                return Ok(self.add_empty_mesh());
            };
            tris.push([v0, e1, e2]);
            infos.push(PrimInfo {
                material: i.material.saturating_add(base),
                normals: i.normals,
            });
        }
        self.stored_elsewhere += tris.len();
        self.meshes
            .push(Mesh::new(tris, infos, mesh.patch_normals, bvh));
        Ok((self.meshes.len() - 1) as u32)
    }

    fn add_empty_mesh(&mut self) -> u32 {
        self.meshes.push(Mesh::new(
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Bvh::default(),
        ));
        (self.meshes.len() - 1) as u32
    }

    /// Adds an instance of shared mesh `mesh` under `xf`, with `material` for all its
    /// triangles or its own materials. The mesh's triangles count towards
    /// [`SceneBuilder::primitive_count`] again, but not towards the stored primitives. An
    /// instance of an empty mesh is not kept. `Ok(false)` if `xf` or its inverse is not
    /// finite.
    pub fn instance(
        &mut self,
        mesh: u32,
        xf: Affine3A,
        material: Option<u32>,
    ) -> Result<bool, Error> {
        limits::check(
            "mesh instance count",
            self.instances.len() as u64 + 1,
            self.max_instances as u64,
            "MAX_MESH_REFERENCES",
        )?;
        let Some(m) = self.meshes.get(mesh as usize) else {
            return Err(Error::InvalidArgument(format!("no shared mesh {mesh}")));
        };
        let Some(inst) = Instance::new(mesh, xf, material.unwrap_or(OWN_MATERIAL)) else {
            return Ok(false);
        };
        if m.tris.is_empty() {
            return Ok(true);
        }
        let bounds = m.bounds_under(&xf);
        self.source_count = self.source_count.saturating_add(m.tris.len());
        self.instances.push(inst);
        self.instance_bounds.push(bounds);
        self.placements.push(Placement {
            mesh,
            xf,
            material: material.unwrap_or(OWN_MATERIAL),
        });
        Ok(true)
    }

    /// Instances placed so far: the next one placed gets this index in
    /// [`Scene::with_moved_instances`]'s list.
    pub fn placed_instances(&self) -> usize {
        self.placements.len()
    }

    /// Adds a material, reusing the last one if identical; returns its index.
    pub fn material(&mut self, m: Material) -> u32 {
        if self.materials.last() == Some(&m) {
            return (self.materials.len() - 1) as u32;
        }
        self.materials.push(m);
        (self.materials.len() - 1) as u32
    }

    /// Primitives added so far, as the file counts them; a parser compares it before and after
    /// adding one to learn that a degenerate one was left out.
    pub fn primitive_count(&self) -> usize {
        self.source_count
    }

    /// Room for one more primitive: under [`limits::MAX_PRIMITIVES`], and in the primitive
    /// arrays, reserved fallibly ([`memory::try_reserve`]) so that [`SceneBuilder::push`]
    /// never allocates.
    fn room(&mut self) -> Result<(), Error> {
        limits::check(
            "primitive count",
            self.stored() as u64 + 1,
            self.max_primitives as u64,
            "MAX_PRIMITIVES",
        )?;
        let n = self.geom.shapes.len();
        let what = || format!("growing the array of {n} primitives");
        memory::try_reserve(&mut self.geom.shapes, 1, what)?;
        memory::try_reserve(&mut self.info, 1, what)
    }

    fn push(&mut self, s: Shape, material: u32, normals: u32) {
        self.geom.shapes.push(s);
        self.info.push(PrimInfo { material, normals });
    }

    pub fn sphere(&mut self, c: Vec3A, r: f32, material: u32) -> Result<(), Error> {
        self.room()?;
        if r != 0.0 {
            self.push(
                Shape::Sphere {
                    center: c,
                    radius: r.abs(),
                    inside: r < 0.0,
                },
                material,
                NO_NORMALS,
            );
            self.source_count += 1;
        }
        Ok(())
    }

    /// Adds a triangle (dropped if degenerate); `normals` are per-vertex shading normals.
    pub fn triangle(
        &mut self,
        v: [Vec3A; 3],
        normals: Option<[Vec3A; 3]>,
        material: u32,
    ) -> Result<(), Error> {
        let before = self.geom.shapes.len();
        self.triangle_inner(v, normals, material)?;
        if self.geom.shapes.len() > before {
            self.source_count += 1;
        }
        Ok(())
    }

    fn triangle_inner(
        &mut self,
        v: [Vec3A; 3],
        normals: Option<[Vec3A; 3]>,
        material: u32,
    ) -> Result<(), Error> {
        self.room()?;
        let e1 = v[1] - v[0];
        let e2 = v[2] - v[0];
        if e1.cross(e2).length_squared() == 0.0 {
            return Ok(());
        }
        let ni = match normals {
            Some(n) => {
                let k = self.patch_normals.len();
                memory::try_reserve(&mut self.patch_normals, 1, || {
                    format!("growing the array of {k} vertex normals")
                })?;
                self.patch_normals.push(n);
                (self.patch_normals.len() - 1) as u32
            }
            None => NO_NORMALS,
        };
        self.push(Shape::Triangle { v0: v[0], e1, e2 }, material, ni);
        Ok(())
    }

    /// Adds a polygon (triangles become [`Shape::Triangle`]); degenerate polygons are dropped.
    pub fn polygon(&mut self, verts: &[Vec3A], material: u32) -> Result<(), Error> {
        if let [a, b, c] = verts {
            return self.triangle([*a, *b, *c], None, material);
        }
        self.room()?;
        let Some(plane) = polygon::plane(verts) else {
            return Ok(());
        };
        // triangulate: triangles are much cheaper to test and bound than large polygons
        if let Some(tris) = ear_clip(verts, plane.normal) {
            let before = self.geom.shapes.len();
            for t in tris {
                let (Some(a), Some(b), Some(c)) =
                    (verts.get(t[0]), verts.get(t[1]), verts.get(t[2]))
                else {
                    continue;
                };
                self.triangle_inner([*a, *b, *c], None, material)?;
            }
            if self.geom.shapes.len() > before {
                self.source_count += 1;
            }
            return Ok(());
        }
        if let Some(k) = self.geom.polygons.add(verts, plane) {
            self.poly_bounds
                .push(verts.iter().fold(Aabb::EMPTY, |b, v| b.grow(*v)));
            self.push(Shape::Polygon(k), material, NO_NORMALS);
            self.source_count += 1;
        }
        Ok(())
    }

    pub fn cone(
        &mut self,
        base: Vec3A,
        r0: f32,
        apex: Vec3A,
        r1: f32,
        material: u32,
    ) -> Result<(), Error> {
        self.room()?;
        if let Some(mut c) = make_cone(base, r0, apex, r1) {
            // inside-only when a radius is negative and none positive (`0` and `-1` too)
            c.inside = (r0 < 0.0 || r1 < 0.0) && r0 <= 0.0 && r1 <= 0.0;
            let k = self.geom.cones.len() as u32;
            memory::try_reserve(&mut self.geom.cones, 1, || {
                format!("growing the array of {k} cones")
            })?;
            self.geom.cones.push(c);
            self.push(Shape::Cone(k), material, NO_NORMALS);
            self.source_count += 1;
        }
        Ok(())
    }

    /// Adds an infinite plane; `None` if the normal is zero.
    pub fn plane(
        &mut self,
        point: Vec3A,
        normal: Vec3A,
        material: u32,
    ) -> Result<Option<()>, Error> {
        self.room()?;
        let Some(n) = normal.try_normalize() else {
            return Ok(None);
        };
        let k = self.planes.len();
        memory::try_reserve(&mut self.planes, 1, || {
            format!("growing the array of {k} planes")
        })?;
        self.planes.push(Plane {
            normal: n,
            d: n.dot(point),
            material,
        });
        self.source_count += 1;
        Ok(Some(()))
    }

    /// Builds the BVH and the final scene. `camera` must be set. `name` (the scene's file) is
    /// named in an [`Error::Memory`], the one error: the memory the build needs is checked
    /// before it is allocated ([`memory`]).
    pub fn build(mut self, name: &str) -> Result<Scene, Error> {
        // the growth slack of the primitive arrays goes before the BVH's arrays are made
        self.geom.shapes.shrink_to_fit();
        self.info.shrink_to_fit();
        self.patch_normals.shrink_to_fit();
        let (bvh, shapes, info, bounds) =
            ordered_bvh(&self.geom, &self.info, &self.poly_bounds, true, name)?;
        self.geom.shapes = shapes;
        self.geom.cones_in_shape_order();
        self.geom.polygons.shrink_to_fit();
        let mut bvh = bvh;
        // at most a block per triangle (leaves of one), and its growth's slack
        let triangles = (self.geom.shapes.iter())
            .filter(|s| matches!(s, Shape::Triangle { .. }))
            .count();
        memory::check(
            || format!("{name}: the BVH's table of blocks for {triangles} triangles"),
            (triangles as u64).saturating_mul(std::mem::size_of::<crate::tri4::Tri4>() as u64),
        )?;
        let tri_blocks = TriBlocks::build(&mut bvh, &self.geom.shapes);
        let (instance_bvh, order) =
            Bvh::try_build_with(&self.instance_bounds, crate::bvh::LEAF_MIN, &|| {
                format!("{name}: the BVH of the mesh instances")
            })?;
        let instances: Vec<Instance> = order
            .iter()
            .filter_map(|&i| self.instances.get(i as usize).copied())
            .collect();
        let own_bounds = bounds;
        let bounds = self.instance_bounds.iter().fold(bounds, |a, b| a.union(*b));
        let camera = self.camera.unwrap_or_else(|| {
            Camera::new(Vec3A::Z * 5.0, Vec3A::ZERO, Vec3A::Y, 45.0).unwrap_or(Camera {
                from: Vec3A::Z,
                forward: -Vec3A::Z,
                right: Vec3A::X,
                up: Vec3A::Y,
                tan_half: 0.5,
            })
        });
        let epsilon = epsilon_for(bounds, &camera);
        let ambient = self
            .ambient
            .unwrap_or(Vec3A::splat(crate::light::spd_intensity(self.lights.len())));
        if self.materials.is_empty() {
            self.materials.push(Material::default());
        }
        Ok(Scene {
            camera,
            resolution: self.resolution,
            background: self.background,
            ambient,
            lights: self.lights,
            materials: self.materials,
            geom: Arc::new(self.geom),
            info: Arc::new(info),
            patch_normals: Arc::new(self.patch_normals),
            planes: Arc::new(self.planes),
            bvh: Arc::new(bvh),
            tri_blocks: Arc::new(tri_blocks),
            meshes: Arc::new(self.meshes),
            instances: Arc::new(instances),
            instance_bvh: Arc::new(instance_bvh),
            placements: Arc::new(self.placements),
            own_bounds,
            epsilon,
            bounds,
            source_count: self.source_count,
            display_referred: self.display_referred,
            warnings: self.warnings,
        })
    }
}

#[cfg(test)]
mod tuning {
    use super::*;
    use crate::bvh::probe;

    /// Deterministic traversal cost (node visits / primitive tests per ray) on the SPD scenes,
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
                        scene.bvh.traverse::<true>(
                            &r,
                            f32::INFINITY,
                            &mut sc,
                            |first, count, tmax| {
                                let (first, count) = scene.tri_blocks.prims(first, count);
                                let mut tm = tmax;
                                for (k, s) in
                                    scene.geom.shapes[first..first + count].iter().enumerate()
                                {
                                    prims += 1;
                                    if let Some(t) = scene.geom.hit(s, &r, 0.0, tm) {
                                        tm = t;
                                        hitp = Some(first + k);
                                        tbest = t;
                                    }
                                }
                                tm
                            },
                        );
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
}

#[cfg(test)]
mod limit_tests {
    use super::*;

    /// Every way of adding a primitive checks the bound before storing anything.
    #[test]
    fn primitive_limit_checked_before_adding() {
        let mut b = SceneBuilder::new();
        b.max_primitives = 3;
        let m = b.material(Material::default());
        b.sphere(Vec3A::ZERO, 1.0, m).unwrap();
        b.cone(Vec3A::ZERO, 1.0, Vec3A::Y, 0.5, m).unwrap();
        b.plane(Vec3A::ZERO, Vec3A::Y, m).unwrap();
        let tri = [Vec3A::ZERO, Vec3A::X, Vec3A::Y];
        let square = [Vec3A::ZERO, Vec3A::X, Vec3A::ONE, Vec3A::Y];
        let errors = [
            b.sphere(Vec3A::ONE, 1.0, m).unwrap_err(),
            b.triangle(tri, None, m).unwrap_err(),
            b.polygon(&square, m).unwrap_err(),
            b.cone(Vec3A::ZERO, 1.0, Vec3A::Y, 0.5, m).unwrap_err(),
            b.plane(Vec3A::ZERO, Vec3A::X, m).unwrap_err(),
        ];
        for e in errors {
            assert_eq!(
                e.to_string(),
                "primitive count is 4, more than the limit of 3 (limits::MAX_PRIMITIVES); \
                 raise the constant in native/kernel/src/limits.rs and rebuild"
            );
        }
        assert_eq!(b.geom.shapes.len() + b.planes.len(), 3);
        assert_eq!(b.primitive_count(), 3);
    }
}

#[cfg(test)]
mod shadow_cache_tests {
    use super::*;

    /// Spheres, cones (oblique ones split over several leaves), triangles and a plane, laid
    /// out on a grid so that shadow rays are blocked in runs and let through in runs.
    fn scene() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.material(Material::default());
        for i in 0..12 {
            for j in 0..12 {
                let p = Vec3A::new(i as f32, j as f32, 0.0);
                match (i + j) % 3 {
                    0 => b.sphere(p, 0.3, m).unwrap(),
                    1 => b
                        .cone(p, 0.2, p + Vec3A::new(0.7, 0.5, 1.5), 0.1, m)
                        .unwrap(),
                    _ => b
                        .triangle(
                            [
                                p,
                                p + Vec3A::new(0.6, 0.0, 0.2),
                                p + Vec3A::new(0.0, 0.6, 0.4),
                            ],
                            None,
                            m,
                        )
                        .unwrap(),
                }
            }
        }
        b.plane(Vec3A::new(0.0, 0.0, -3.0), Vec3A::Z, m).unwrap();
        b.build("test").unwrap()
    }

    /// Every primitive tested, no cache, no BVH.
    fn brute(s: &Scene, ray: &Ray, tmax: f32) -> bool {
        s.geom
            .shapes
            .iter()
            .any(|sh| s.geom.hit(sh, ray, 0.0, tmax).is_some())
            || s.planes.iter().any(|pl| {
                let dn = pl.normal.dot(ray.dir);
                dn != 0.0 && {
                    let t = (pl.d - pl.normal.dot(ray.origin)) / dn;
                    t > 0.0 && t < tmax
                }
            })
    }

    #[test]
    fn the_cache_changes_no_answer() {
        let s = scene();
        let mut scratch = Scratch::new();
        let lights = [
            Vec3A::new(5.0, 5.0, 8.0),
            Vec3A::new(-4.0, 14.0, 3.0),
            Vec3A::new(20.0, -3.0, 1.0),
        ];
        let (mut blocked, mut free) = (0, 0);
        // shading points in scanline order, as a renderer meets them
        for y in 0..60 {
            for x in 0..60 {
                let p = Vec3A::new(x as f32 * 0.2 - 0.5, y as f32 * 0.2 - 0.5, -0.6);
                for (li, l) in lights.iter().enumerate() {
                    let to = *l - p;
                    let dist = to.length();
                    let ray = Ray::from_unit(p, to / dist);
                    let want = brute(&s, &ray, dist);
                    for slot in [li * 8 + 1, usize::MAX, 1 << 30] {
                        assert_eq!(
                            s.occluded_cached(&ray, dist, &mut scratch, slot),
                            want,
                            "point {p:?} light {li} slot {slot}"
                        );
                    }
                    if want {
                        blocked += 1;
                    } else {
                        free += 1;
                    }
                }
            }
        }
        assert!(
            blocked > 1000 && free > 1000,
            "{blocked} blocked, {free} free"
        );
        // slots far apart: the cache grows, and the bound on slots holds
        assert!(scratch.shadow_cache.len() <= 2 * CACHE_SLOTS);
    }
}
