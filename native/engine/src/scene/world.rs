//! The scene's triangles in world space, one copy per instance: what a ray caster needs
//! (panorama primary visibility), with the instance, mesh and facing of each.

use super::Scene;
use crate::mesh::Vec3;

/// World-space triangles of every instance, in instance order.
pub struct WorldTriangles {
    pub corners: Vec<[Vec3; 3]>,
    /// Per triangle: the instance that places it and the mesh it comes from.
    pub instance: Vec<u32>,
    pub mesh: Vec<u32>,
    /// Per triangle: +1, or -1 where a mirrored instance turns its winding over, so that
    /// facing * (b - a) x (c - a) is the modelled front side.
    pub facing: Vec<f32>,
}

impl Scene {
    /// Every instance's triangles moved into world space (the current vertices and matrices).
    pub fn world_triangles(&self) -> WorldTriangles {
        let total: usize = self.instances.iter().map(|(m, _)| self.meshes[*m as usize].triangles.len()).sum();
        let mut out = WorldTriangles {
            corners: Vec::with_capacity(total),
            instance: Vec::with_capacity(total),
            mesh: Vec::with_capacity(total),
            facing: Vec::with_capacity(total),
        };
        for (index, (mesh_id, affine)) in self.instances.iter().enumerate() {
            let mesh = &self.meshes[*mesh_id as usize];
            let world: Vec<Vec3> = mesh.positions.iter().map(|p| affine.apply(*p)).collect();
            for t in &mesh.triangles {
                out.corners.push(t.map(|v| world[v as usize]));
                out.instance.push(index as u32);
                out.mesh.push(*mesh_id);
                out.facing.push(affine.facing);
            }
        }
        out
    }
}
