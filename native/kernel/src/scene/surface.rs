//! What a hit sees: the point, its geometric and shading normals, its material.

use super::{Hit, PrimInfo, Scene, NO_NORMALS};
use crate::geometry::{hit_triangle, Shape};
use crate::instance::OWN_MATERIAL;
use crate::ray::Ray;
use glam::Vec3A;

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

impl Scene {
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
}
