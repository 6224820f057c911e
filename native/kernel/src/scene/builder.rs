//! [`SceneBuilder`]: collects a scene's contents as a parser reads them, then builds the BVH.

use super::{epsilon_for, Placement, Plane, PrimInfo, Scene, NO_NORMALS};
use crate::bvh::Bvh;
use crate::camera::Camera;
use crate::geometry::{make_cone, Aabb, Geometry, Shape};
use crate::instance::{Instance, Mesh, Tri, OWN_MATERIAL};
use crate::light::Light;
use crate::limits;
use crate::material::Material;
use crate::memory;
use crate::polygon::{self, ear_clip};
use crate::tri4::TriBlocks;
use crate::warning::Warnings;
use crate::Error;
use glam::{Affine3A, Vec3A};
use std::sync::Arc;

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
