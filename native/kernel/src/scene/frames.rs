//! Scenes derived from a built one for an animation's frames: another view, or mesh
//! instances moved, sharing what did not change.

use super::{epsilon_for, Placement, Scene};
use crate::bvh::Bvh;
use crate::camera::Camera;
use crate::instance::Instance;
use crate::light::Light;
use crate::material::Material;
use crate::Error;
use glam::Affine3A;
use std::sync::Arc;

impl Scene {
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
}
