//! Mesh instancing: a mesh read once, drawn many times.
//!
//! A `Mesh` holds the triangles of one mesh file in its own (object) space, with their
//! shading data and their own BVH (the bottom level). An `Instance` is one reference to it:
//! the shared mesh, an affine transform (kept with its inverse), and an optional material that
//! replaces the mesh's own. The scene keeps a second BVH over the instances' world bounds (the
//! top level, next to the BVH of its own primitives); a ray that enters an instance's box is
//! taken into object space by the inverse transform and traced through the mesh's BVH.
//!
//! - The direction is not renormalised in object space, so `t` names the same point on both
//!   rays and hits compare with the scene's other primitives directly. The triangle test
//!   (Möller–Trumbore) and the box test are linear in the direction and need no unit length.
//! - The geometric normal is the cross product of the transformed edges, as a flattened copy of
//!   the mesh would have it (this keeps the orientation under mirroring transforms); vertex
//!   normals go to world space with the inverse transpose, are normalised, then interpolated,
//!   again as in a flattened copy.
//! - An instance's world box bounds its transformed vertices (not the transformed box of the
//!   mesh), so rotated instances get tight boxes; that costs O(vertices of the mesh) once per
//!   instance at load time.
//!
//! Memory: one copy of each mesh's triangles and BVH, plus O(1) per instance (two matrices, a
//! transform, a box and a BVH reference). Which references are instanced is the scene format's
//! choice (see [`crate::toml_scene`]).

use crate::bvh::Bvh;
use crate::geometry::Aabb;
use crate::ray::Ray;
use crate::scene::PrimInfo;
use glam::{Affine3A, Mat3A, Vec3A};

/// No material override: the mesh's own materials are used.
pub(crate) const OWN_MATERIAL: u32 = u32::MAX;

/// A triangle as the intersection test takes it: first vertex and the two edges from it.
pub(crate) type Tri = [Vec3A; 3];

/// One mesh file's triangles in object space, in the order of their BVH.
#[derive(Clone, Debug)]
pub(crate) struct Mesh {
    pub tris: Vec<Tri>,
    pub info: Vec<PrimInfo>,
    pub patch_normals: Vec<[Vec3A; 3]>,
    pub bvh: Bvh,
    /// The distinct vertices of the triangles (as the test sees them: `v0`, `v0 + e1`,
    /// `v0 + e2`), for instance bounds.
    pub vertices: Vec<Vec3A>,
}

impl Mesh {
    /// A mesh from triangles and their shading data, already in BVH order.
    pub fn new(
        tris: Vec<Tri>,
        info: Vec<PrimInfo>,
        patch_normals: Vec<[Vec3A; 3]>,
        bvh: Bvh,
    ) -> Mesh {
        let mut keys: Vec<[u32; 3]> = tris
            .iter()
            .flat_map(|t| [t[0], t[0] + t[1], t[0] + t[2]])
            .map(|v| v.to_array().map(f32::to_bits))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        let vertices = keys
            .iter()
            .map(|k| Vec3A::from_array(k.map(f32::from_bits)))
            .collect();
        Mesh {
            tris,
            info,
            patch_normals,
            bvh,
            vertices,
        }
    }

    /// World bounds of the mesh under `xf`: the box of its transformed vertices, widened by a
    /// few units in the last place so that rounding in the transform never cuts off a hit.
    pub fn bounds_under(&self, xf: &Affine3A) -> Aabb {
        let b = self
            .vertices
            .iter()
            .fold(Aabb::EMPTY, |b, v| b.grow(xf.transform_point3a(*v)));
        if b.is_empty() {
            return b;
        }
        let pad = Vec3A::splat(b.min.abs().max(b.max.abs()).max_element() * 4.0 * f32::EPSILON);
        Aabb {
            min: b.min - pad,
            max: b.max + pad,
        }
    }
}

/// One reference to a shared mesh.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Instance {
    /// Index of the mesh in the scene's meshes.
    pub mesh: u32,
    /// Material for every triangle, or [`OWN_MATERIAL`].
    pub material: u32,
    /// World to object space (the inverse of the reference's transform).
    pub to_object: Affine3A,
    /// The linear part of the transform (object to world), for edges.
    pub to_world: Mat3A,
    /// Its inverse transpose, for normals.
    pub normal_to_world: Mat3A,
}

impl Instance {
    /// An instance of `mesh` under `xf`; `None` unless `xf` and its inverse are finite and
    /// invertible.
    pub fn new(mesh: u32, xf: Affine3A, material: u32) -> Option<Instance> {
        let to_object = xf.inverse();
        let normal_to_world = xf.matrix3.inverse().transpose();
        (xf.is_finite()
            && xf.matrix3.determinant() != 0.0
            && to_object.is_finite()
            && normal_to_world.is_finite())
        .then_some(Instance {
            mesh,
            material,
            to_object,
            to_world: xf.matrix3,
            normal_to_world,
        })
    }

    /// The ray in object space, its direction not renormalised (same `t` for the same point).
    #[inline(always)]
    pub fn object_ray(&self, ray: &Ray) -> Ray {
        Ray::scaled(
            self.to_object.transform_point3a(ray.origin),
            self.to_object.transform_vector3a(ray.dir),
        )
    }

    /// World geometric normal of an object-space triangle (edges transformed, then crossed).
    #[inline]
    pub fn geometric_normal(&self, t: &Tri) -> Vec3A {
        (self.to_world * t[1])
            .cross(self.to_world * t[2])
            .normalize_or(Vec3A::Z)
    }

    /// A vertex normal taken to world space and normalised (zero if it vanishes).
    #[inline]
    pub fn normal(&self, n: Vec3A) -> Vec3A {
        (self.normal_to_world * n).normalize_or_zero()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::{Instance, OWN_MATERIAL};
    use crate::files::Unreadable;
    use crate::scene::{Hit, Scene, SceneBuilder};
    use crate::{render_image, to_srgb8, Material, Ray, Settings};
    use glam::{Affine3A, Vec3A};
    use std::cell::Cell;

    /// A UV sphere of radius 1 with vertex normals, `2 * lon * (lat - 1)` triangles (the
    /// poles' fans included), the upper half in material `red`, the lower in `blue` of
    /// `m.mtl`.
    pub(crate) fn sphere_obj(lon: usize, lat: usize) -> String {
        use std::fmt::Write;
        let mut s = String::from("mtllib m.mtl\nv 0 1 0\nvn 0 1 0\n");
        for i in 1..lat {
            let th = std::f64::consts::PI * i as f64 / lat as f64;
            for j in 0..lon {
                let ph = std::f64::consts::TAU * j as f64 / lon as f64;
                let (x, y, z) = (th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
                let _ = writeln!(s, "v {x:.6} {y:.6} {z:.6}\nvn {x:.5} {y:.5} {z:.5}");
            }
        }
        s += "v 0 -1 0\nvn 0 -1 0\n";
        let idx = |i: usize, j: usize| 2 + (i - 1) * lon + j % lon;
        let last = 2 + (lat - 1) * lon;
        let mut faces = Vec::new();
        for j in 0..lon {
            faces.push([1, idx(1, j + 1), idx(1, j)]);
        }
        for i in 1..lat - 1 {
            for j in 0..lon {
                faces.push([idx(i, j), idx(i, j + 1), idx(i + 1, j + 1)]);
                faces.push([idx(i, j), idx(i + 1, j + 1), idx(i + 1, j)]);
            }
        }
        for j in 0..lon {
            faces.push([last, idx(lat - 1, j), idx(lat - 1, j + 1)]);
        }
        let half = faces.len() / 2;
        for (k, [a, b, c]) in faces.iter().enumerate() {
            if k == 0 || k == half {
                s += if k == 0 {
                    "usemtl red\n"
                } else {
                    "usemtl blue\n"
                };
            }
            let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
        }
        s
    }

    const MTL: &str = "newmtl red\nKd 0.9 0.2 0.1\nKs 0.3 0.3 0.3\nNs 40\n\
                       newmtl blue\nKd 0.1 0.3 0.9\n";

    /// A scene with `sphere.obj` referenced `refs` times under the transform keys `xf`
    /// (TOML), over a floor plane, and how often each file was read.
    fn scene(xf: &str, extra: &str, refs: usize) -> (Scene, usize) {
        let mut src = String::from(
            "[camera]\nfrom = [0.1, 0.6, 6]\nat = [0, 0, 0]\nwidth = 48\nheight = 36\n\
             [[lights]]\nposition = [4, 5, 6]\n\
             [materials.gold]\ncolor = [0.9, 0.7, 0.2]\nks = 0.4\n\
             [[objects]]\ntype = \"plane\"\npoint = [0, -3, 0]\nnormal = [0, 1, 0]\n",
        );
        for _ in 0..refs {
            src += &format!("[[objects]]\ntype = \"mesh\"\nfile = \"sphere.obj\"\n{xf}\n{extra}\n");
        }
        let obj = sphere_obj(24, 12);
        let reads = Cell::new(0);
        let resolve = |p: &str| -> Result<Vec<u8>, Unreadable> {
            reads.set(reads.get() + 1);
            match p {
                "sphere.obj" => Ok(obj.as_bytes().to_vec()),
                "m.mtl" => Ok(MTL.as_bytes().to_vec()),
                _ => Err(Unreadable::Missing(format!("no {p}"))),
            }
        };
        let s = crate::toml_scene::parse(src.as_bytes(), "i.toml", &resolve).unwrap();
        (s, reads.get())
    }

    const TRANSFORMS: [&str; 6] = [
        "translate = [0.5, -0.25, 1.0]",
        "rotate_y_degrees = 37",
        "scale = [2.0, 0.5, 1.25]",
        "translate = [-0.3, 0.2, 0.4]\nrotate_y_degrees = -60\nscale = [0.7, 1.8, 1.1]",
        // shear, and a mirror (negative determinant)
        "matrix = [[1, 0.4, 0, 0.2], [0, 0.8, 0.3, -0.1], [0.2, 0, -1.3, 0.5]]",
        "scale = [-1.5, 1, 1]",
    ];

    /// The object-space ray keeps the world ray's `t`: the triangle test and the box test take
    /// a direction of any length.
    #[test]
    fn tests_take_unnormalised_directions() {
        let (v0, e1, e2) = (Vec3A::new(-1.0, -1.0, 0.0), Vec3A::X * 2.0, Vec3A::Y * 2.0);
        let o = Vec3A::new(-0.3, -0.2, 4.0);
        let d = Vec3A::new(0.05, -0.1, -1.0).normalize();
        let unit = crate::geometry::hit_triangle(v0, e1, e2, &Ray::from_unit(o, d), 0.0, 1e30);
        let (t, u, v) = unit.unwrap();
        for k in [1e-3f32, 0.37, 3.0, 250.0] {
            let (tk, uk, vk) =
                crate::geometry::hit_triangle(v0, e1, e2, &Ray::scaled(o, d * k), 0.0, 1e30)
                    .unwrap();
            assert!((tk * k - t).abs() <= 1e-5 * t, "{k}: {tk}");
            assert!((uk - u).abs() < 1e-6 && (vk - v).abs() < 1e-6, "{k}");
        }
        // through an instance scaled by 3 (the object ray's direction has length 1/3): the
        // same t as the world ray's
        let inst = Instance::new(
            0,
            Affine3A::from_scale(glam::Vec3::splat(3.0)),
            OWN_MATERIAL,
        );
        let oray = inst.unwrap().object_ray(&Ray::from_unit(o * 3.0, d));
        assert!((oray.dir.length() - 1.0 / 3.0).abs() < 1e-6);
        let (ti, _, _) = crate::geometry::hit_triangle(v0, e1, e2, &oray, 0.0, 1e30).unwrap();
        assert!((ti - 3.0 * t).abs() <= 1e-5 * ti, "{ti} vs {}", 3.0 * t);
        let boxes = crate::bvh::Bvh::build(&[crate::Aabb {
            min: Vec3A::new(-1.0, -1.0, -0.1),
            max: Vec3A::new(1.0, 1.0, 0.1),
        }])
        .0;
        // the box is entered at z = 0.1, t = 3 * 3.9 / |d.z| on the world ray
        let entry = 3.0 * 3.9 / d.z.abs();
        let mut scratch = crate::Scratch::new();
        for (tmax, want) in [(entry * 0.999, false), (entry * 1.001, true)] {
            let mut seen = false;
            boxes.traverse::<true>(&oray, tmax, &mut scratch, |_, _, t| {
                seen = true;
                t
            });
            assert_eq!(seen, want, "tmax {tmax}, entry {entry}");
        }
    }

    fn close(a: Vec3A, b: Vec3A) -> bool {
        (a - b).abs().max_element() <= 1e-4
    }

    /// Two references of a mesh under one transform are instanced and coincide; one reference
    /// is flattened. The instance gives the flattened mesh's hits: same t (to 1e-4 relative;
    /// in practice below 1e-6 but for a few grazing rays, at most 3e-5), the same geometric
    /// and shading normals (to 1e-4; at most 2e-5), the same material, the same shadows.
    #[test]
    fn an_instance_hits_like_the_flattened_mesh() {
        for xf in TRANSFORMS {
            for extra in ["", "smooth = false", "material = \"gold\""] {
                let (flat, _) = scene(xf, extra, 1);
                let (inst, _) = scene(xf, extra, 2);
                assert_eq!((flat.instance_count(), flat.mesh_count()), (0, 0));
                assert_eq!((inst.instance_count(), inst.mesh_count()), (2, 1));
                assert_eq!(inst.primitive_count(), 2 * flat.primitive_count() - 1);
                assert_eq!(inst.stored_primitive_count(), flat.stored_primitive_count());
                let b = flat.bounds();
                let mut hits = 0;
                for from in [
                    [0.1, 0.6, 6.0],
                    [5.0, 2.1, 3.0],
                    [-4.0, -1.1, 2.0],
                    [0.5, 6.0, -0.5],
                ] {
                    let from = Vec3A::from_array(from);
                    for i in 0..=24 {
                        for j in 0..=24 {
                            // off the grid of the mesh's vertices, which a ray along an edge could slip
                            // between (the triangle test is not watertight, flattened or not)
                            let f =
                                Vec3A::new((i as f32 + 0.37) / 25.0, (j as f32 + 0.61) / 25.0, 0.5);
                            let at = b.min + (b.max - b.min) * Vec3A::new(f.x, f.y, f.z);
                            let at = at + Vec3A::new(0.0, 0.0, (f.x - f.y) * 0.3);
                            let ray = Ray::new(from, at - from);
                            let (hf, hi) = (flat.intersect(&ray, 1e30), inst.intersect(&ray, 1e30));
                            let what = format!("{xf} / {extra}: ray {ray:?}: {hf:?} vs {hi:?}");
                            assert_eq!(hf.is_some(), hi.is_some(), "{what}");
                            let (Some(hf), Some(hi)) = (hf, hi) else {
                                continue;
                            };
                            assert!((hf.t - hi.t).abs() <= 1e-4 * hf.t.max(1.0), "{what}");
                            assert_eq!(
                                hf.prim as usize >= flat.geom.shapes.len(),
                                hi.instance == Hit::NO_INSTANCE,
                                "plane in one only: {what}"
                            );
                            let (sf, si) = (flat.surface(&hf, &ray), inst.surface(&hi, &ray));
                            assert!(close(sf.ng, si.ng), "ng {:?} {:?} {what}", sf.ng, si.ng);
                            assert!(close(sf.ns, si.ns), "ns {:?} {:?} {what}", sf.ns, si.ns);
                            assert_eq!(
                                flat.material(sf.material),
                                inst.material(si.material),
                                "{what}"
                            );
                            assert_eq!(flat.occluded(&ray, 1e30), inst.occluded(&ray, 1e30));
                            let short = hf.t * 0.999;
                            assert_eq!(flat.occluded(&ray, short), inst.occluded(&ray, short));
                            hits += (hi.instance != Hit::NO_INSTANCE) as usize;
                        }
                    }
                }
                assert!(hits > 300, "{xf}: only {hits} rays hit the mesh");
            }
        }
    }

    /// The images agree too: the 8-bit pixels are the same for every transform tested, and the
    /// linear values within 1e-4 (they differ in their last bits, 1e-6 to 2e-5 here: normals are
    /// rounded differently, and the scene epsilon comes from bounds a few units in the last
    /// place apart); so do the ray counts.
    #[test]
    fn an_instance_renders_like_the_flattened_mesh() {
        for xf in TRANSFORMS {
            let (flat, _) = scene(xf, "", 1);
            let (inst, _) = scene(xf, "", 2);
            let settings = Settings::for_scene(&flat);
            let (a, sa) = render_image(&flat, &settings, 1).unwrap();
            let (b, sb) = render_image(&inst, &settings, 1).unwrap();
            let far = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f32::max);
            assert!(to_srgb8(&a) == to_srgb8(&b), "{xf}");
            assert!(far < 1e-4, "{xf}: {far}");
            assert_eq!(sa.eye_hits, sb.eye_hits, "{xf}");
            assert_eq!((sa.shadow, sa.reflected), (sb.shadow, sb.reflected), "{xf}");
        }
    }

    /// 3000 references of one OBJ: read once, stored once, 3000 instances; the primitive count
    /// says what the image holds, the stored count what memory holds.
    #[test]
    fn a_mesh_referenced_3000_times_is_read_and_stored_once() {
        let (one, reads_one) = scene("", "", 1);
        let tris = one.primitive_count() - 1;
        assert_eq!(tris, 2 * 24 * 11);
        assert_eq!(reads_one, 2, "the OBJ and its mtllib");
        let xf = "translate = [1, 2, 3]\nrotate_y_degrees = 10";
        let (s, reads) = scene(xf, "", 3000);
        assert_eq!(reads, 2, "the OBJ and its mtllib, once");
        assert_eq!(s.mesh_count(), 1);
        assert_eq!(s.instance_count(), 3000);
        assert_eq!(s.internal_primitive_count(), 1, "the plane");
        assert_eq!(s.stored_primitive_count(), 1 + tris);
        assert_eq!(s.primitive_count(), 1 + 3000 * tris);
        assert_eq!(s.meshes[0].tris.len(), tris);
        // materials: the scene's default and gold, the OBJ's grey, red and blue once
        assert_eq!(s.materials.len(), one.materials.len());
        assert_eq!(s.instance_bvh.nodes.len(), {
            let (b, _) = crate::bvh::Bvh::build(&vec![crate::Aabb::EMPTY.grow(Vec3A::ZERO); 3000]);
            b.nodes.len()
        });
    }

    /// A mesh referenced with `smooth = false` once and `smooth = true` twice: the first is
    /// flattened, the others share one mesh.
    #[test]
    fn references_group_by_file_and_smooth_flag() {
        let src = "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n\
                   [[objects]]\ntype = \"mesh\"\nfile = \"s.obj\"\nsmooth = false\n\
                   [[objects]]\ntype = \"mesh\"\nfile = \"s.obj\"\n\
                   [[objects]]\ntype = \"mesh\"\nfile = \"s.obj\"\ntranslate = [3, 0, 0]\n";
        let obj = sphere_obj(8, 4);
        let resolve = |p: &str| -> Result<Vec<u8>, Unreadable> {
            match p {
                "s.obj" => Ok(obj.as_bytes().to_vec()),
                _ => Err(Unreadable::Missing(format!("no {p}"))),
            }
        };
        let s = crate::toml_scene::parse(src.as_bytes(), "g.toml", &resolve).unwrap();
        let tris = 2 * 8 * 3;
        assert_eq!((s.mesh_count(), s.instance_count()), (1, 2));
        assert_eq!(s.internal_primitive_count(), tris);
        assert_eq!(s.stored_primitive_count(), 2 * tris);
        assert_eq!(s.primitive_count(), 3 * tris);
    }

    fn unit_mesh(b: &mut SceneBuilder, n: usize) -> Result<u32, crate::Error> {
        let mut mb = b.for_mesh();
        let m = mb.material(Material::default());
        for i in 0..n {
            let x = i as f32;
            mb.triangle(
                [
                    Vec3A::new(x, 0.0, 0.0),
                    Vec3A::new(x + 1.0, 0.0, 0.0),
                    Vec3A::Y,
                ],
                None,
                m,
            )?;
        }
        b.add_mesh(mb, "mesh")
    }

    /// The primitive bound counts a shared mesh's triangles once, however many instances; the
    /// instance bound is checked before each instance is added.
    #[test]
    fn limits_count_stored_triangles_and_instances() {
        let mut b = SceneBuilder::new();
        b.max_primitives = 10;
        b.max_instances = 100;
        let m = b.material(Material::default());
        b.sphere(Vec3A::ZERO, 1.0, m).unwrap();
        let mesh = unit_mesh(&mut b, 8).unwrap();
        for i in 0..100 {
            let xf = Affine3A::from_translation(glam::Vec3::new(0.0, 0.0, i as f32));
            assert!(b.instance(mesh, xf, None).unwrap());
        }
        assert_eq!(
            b.instance(mesh, Affine3A::IDENTITY, None).unwrap_err().to_string(),
            "mesh instance count is 101, more than the limit of 100 (limits::MAX_MESH_REFERENCES); \
             raise the constant in native/kernel/src/limits.rs and rebuild"
        );
        // 1 sphere + 8 shared triangles stored; 1 more fits, 2 more do not
        b.sphere(Vec3A::ONE, 1.0, m).unwrap();
        assert_eq!(
            unit_mesh(&mut b, 2).unwrap_err().to_string(),
            "primitive count is 11, more than the limit of 10 (limits::MAX_PRIMITIVES); \
             raise the constant in native/kernel/src/limits.rs and rebuild"
        );
        assert_eq!(
            b.sphere(Vec3A::ONE, 1.0, m).unwrap_err().to_string(),
            "primitive count is 11, more than the limit of 10 (limits::MAX_PRIMITIVES); \
             raise the constant in native/kernel/src/limits.rs and rebuild"
        );
        assert_eq!(b.primitive_count(), 2 + 800);
        let s = b.build("scene").unwrap();
        assert_eq!((s.stored_primitive_count(), s.instance_count()), (10, 100));
        // a singular transform makes no instance
        let mut b = SceneBuilder::new();
        let mesh = unit_mesh(&mut b, 1).unwrap();
        assert!(!b
            .instance(mesh, Affine3A::from_scale(glam::Vec3::ZERO), None)
            .unwrap());
    }
}
