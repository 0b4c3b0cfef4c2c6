//! Primary visibility of a panorama: the first surface seen through each pixel centre, by
//! ray casting the scene's world triangles through a BVH. Exact at pixel centres (no
//! resampling, unlike a rasterized cube map), and fast enough: one ray per pixel.

use rayon::prelude::*;

use super::bvh::{cross, Bvh};
use super::directions::{self, Rotation};
use crate::error::{Error, Result};
use crate::scene::Scene;

/// A pixel's closest hit and the direction of its ray.
type RayHit = (super::bvh::Hit, [f64; 3]);

/// Per pixel, row 0 at the top; background pixels have `instance` = -1, t = inf, zeros elsewhere.
pub struct Hits {
    pub width: usize,
    pub height: usize,
    pub t: Vec<f32>,
    pub position: Vec<[f32; 3]>,
    /// The triangle's modelled front side (instance facing applied), unit.
    pub normal: Vec<[f32; 3]>,
    pub instance: Vec<i32>,
    pub mesh: Vec<i32>,
    /// The ray met the back of its triangle.
    pub back: Vec<bool>,
}

pub fn primary_hits(scene: &Scene, origin: [f64; 3], rotation: &Rotation, width: usize, height: usize) -> Result<Hits> {
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!("the panorama size must be positive, got {width} x {height}")));
    }
    if origin.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid("the viewpoint must be finite"));
    }
    let world = scene.world_triangles();
    if world.corners.is_empty() {
        return Err(Error::invalid("the scene is empty: add a mesh and an instance of it before baking a panorama"));
    }
    let bvh = Bvh::build(world.corners.clone());
    let (cols, rows) = (directions::columns(width), directions::rows(height));
    let n = width * height;
    let mut hits = Hits {
        width,
        height,
        t: vec![f32::INFINITY; n],
        position: vec![[0.0; 3]; n],
        normal: vec![[0.0; 3]; n],
        instance: vec![-1; n],
        mesh: vec![-1; n],
        back: vec![false; n],
    };
    let per_row: Vec<Vec<Option<RayHit>>> = rows
        .par_iter()
        .map_init(Vec::new, |stack, row| {
            cols.iter()
                .map(|col| {
                    let d = directions::direction(rotation, *row, *col);
                    bvh.closest(origin, d, stack).map(|h| (h, d))
                })
                .collect()
        })
        .collect();
    for (r, row) in per_row.into_iter().enumerate() {
        for (c, hit) in row.into_iter().enumerate() {
            let Some((h, d)) = hit else { continue };
            let i = r * width + c;
            let tri = world.corners[h.triangle as usize].map(|p| p.map(|x| x as f64));
            let w = 1.0 - h.u - h.v;
            hits.position[i] = [0, 1, 2].map(|a| (w * tri[0][a] + h.u * tri[1][a] + h.v * tri[2][a]) as f32);
            let e1 = [0, 1, 2].map(|a| tri[1][a] - tri[0][a]);
            let e2 = [0, 1, 2].map(|a| tri[2][a] - tri[0][a]);
            let g = cross(e1, e2);
            let len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let facing = world.facing[h.triangle as usize] as f64;
            let nrm = g.map(|x| facing * x / len);
            hits.normal[i] = nrm.map(|x| x as f32);
            hits.back[i] = nrm[0] * d[0] + nrm[1] * d[1] + nrm[2] * d[2] > 0.0;
            hits.t[i] = h.t as f32;
            hits.instance[i] = world.instance[h.triangle as usize] as i32;
            hits.mesh[i] = world.mesh[h.triangle as usize] as i32;
        }
    }
    Ok(hits)
}
