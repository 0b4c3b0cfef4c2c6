//! A scene as extra blockers of a per-mesh solver's receivers: live shadow casters. The solver
//! computes in its own normalised space (`mesh::Normalization`), which a rigid placement
//! (`to_world`, as the add-on's object frame) maps into the scene's world; a receiver moved
//! there keeps its directions (rotations and mirrors keep angles), so the scene's blockers
//! rasterize into the same visibility mask as the solver's own triangles.

use crate::disk_mask::{disk, Mask};
use crate::error::{Error, Result};
use crate::mesh::{Normalization, Vec3};
use crate::plane_table::PlaneTable;
use crate::integrate::Frame;
use crate::transfer::Receiver;

use super::clusters::MeshTree;
use super::pinholes;
use super::traverse::{MaskSink, Walk, PINHOLE_NEIGHBOURS};
use super::Scene;

/// An orthogonal 3x3 part (a mirror allowed) and a translation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    rows: [[f64; 3]; 3],
    translation: [f64; 3],
}

impl Rigid {
    pub const IDENTITY: Rigid = Rigid { rows: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] };

    /// From 16 row-major values (column vectors); the 3x3 part must be orthogonal: a scale
    /// or shear belongs in the positions given to the solver, not here.
    pub fn from_rows(m: &[f64; 16]) -> Result<Self> {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("to_world must be finite"));
        }
        if m[12].abs() + m[13].abs() + m[14].abs() > 1e-6 || (m[15] - 1.0).abs() > 1e-6 {
            return Err(Error::invalid("to_world must be affine (last row 0 0 0 1)"));
        }
        let rows = [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| rows[k][i] * rows[k][j]).sum();
                if (d - f64::from(i == j)).abs() > 1e-4 {
                    return Err(Error::invalid(
                        "to_world must be rigid (an orthogonal 3x3 part, a mirror allowed): apply scale and shear to the vertices",
                    ));
                }
            }
        }
        Ok(Rigid { rows, translation: [m[3], m[7], m[11]] })
    }

    fn point(&self, p: [f64; 3]) -> Vec3 {
        [0, 1, 2].map(|r| (self.rows[r][0] * p[0] + self.rows[r][1] * p[1] + self.rows[r][2] * p[2] + self.translation[r]) as f32)
    }

    fn direction(&self, v: Vec3) -> Vec3 {
        let v = v.map(f64::from);
        [0, 1, 2].map(|r| (self.rows[r][0] * v[0] + self.rows[r][1] * v[1] + self.rows[r][2] * v[2]) as f32)
    }
}

/// How a solver sees the scene, besides its instances' stamps: results under one key differ
/// only where an instance's stamp changed.
#[derive(Clone, Debug, PartialEq)]
pub struct CastersKey {
    to_world: Rigid,
    exclude: Vec<u32>,
    lod: u32,
}

/// A prepared scene seen by a solver's receivers, minus the excluded instances.
pub struct Casters<'a> {
    trees: Vec<&'a MeshTree>,
    positions: Vec<&'a [Vec3]>,
    scene: &'a Scene,
    key: CastersKey,
    full: Mask,
}

impl Scene {
    /// The scene as casters for a solver whose positions `to_world` places in this scene's
    /// world, without the instances `exclude` (the solver's own object). Shared, so that
    /// solvers of several objects may read one scene at once: call `prepare` first.
    pub fn casters(&self, exclude: &[u32], to_world: Rigid) -> Result<Casters<'_>> {
        if let Some(&i) = exclude.iter().find(|&&i| i as usize >= self.instances.len()) {
            return Err(Error::invalid(format!("excluded instance {i} is out of range: the scene has {} instances", self.instances.len())));
        }
        if !self.prepared() {
            return Err(Error::invalid("the scene changed since it was prepared: call prepare() first"));
        }
        let mut exclude = exclude.to_vec();
        exclude.sort_unstable();
        exclude.dedup();
        let (trees, positions) = self.walk_parts();
        let key = CastersKey { to_world, exclude, lod: self.lod.to_bits() };
        Ok(Casters { trees, positions, scene: self, key, full: disk() })
    }
}

impl Casters<'_> {
    pub fn key(&self) -> &CastersKey {
        &self.key
    }

    /// Per instance, a stamp that changes whenever its blockers change (unique across scenes).
    pub fn stamps(&self) -> &[u64] {
        &self.scene.stamps
    }

    /// The instances a walk skips: the excluded ones and `also` (ascending).
    pub fn skipping(&self, also: &[u32]) -> Vec<u32> {
        let mut skip: Vec<u32> = self.key.exclude.iter().chain(also).copied().collect();
        skip.sort_unstable();
        skip.dedup();
        skip
    }

    /// The raw mask of the blockers of `receiver` (in the solver's normalised space, which
    /// `normalization` made from the solver's input), skipping the instances in `skip`
    /// (ascending, see `skipping`), and the triangle count. Finish the union of a receiver's
    /// raw masks with `close_pinholes`.
    ///
    /// `known`: cells the caller blocks anyway (its own and other blockers'). The walk stops
    /// once the mask and `known` cover the whole disk: the receiver is blocked everywhere
    /// whatever the rest would add, so the mask may lack cells of `known`, and its union
    /// with `known`, pinholes closed or not, is the whole disk either way.
    ///
    /// `table` is the solver's: the scene's finer one (`TABLE_RESOLUTION`) made the demo's
    /// cloth, lying on Suzanne, a third slower (63 against 48 ms per frame) for shadows the
    /// solver's own blockers are drawn with the coarser table anyway.
    #[allow(clippy::too_many_arguments)]
    pub fn occlude(&self, table: &PlaneTable, normalization: &Normalization, receiver: &Receiver, skip: &[u32], known: Mask, scratch: &mut Vec<Vec3>) -> (Mask, u64) {
        let place = &self.key.to_world;
        let Frame { t, b, n } = receiver.frame;
        let world = Receiver {
            frame: Frame { t: place.direction(t), b: place.direction(b), n: place.direction(n) },
            origin: place.point(normalization.invert(receiver.origin)),
        };
        let scene = self.scene;
        let top = scene.top.as_ref().expect("prepared by Scene::casters");
        let walk = Walk { trees: &self.trees, positions: &self.positions, instances: &scene.instances, top, lod: scene.lod, exclude: skip, near_proxies: true, radiance: false };
        let mut sink = MaskSink::knowing(table, self.full, known);
        walk.run(&world, scratch, &mut sink);
        sink.finish_raw()
    }

    /// The casters' mask with pinholes closed as in every scene query (`pinholes`); once, on
    /// the union of a receiver's raw masks, so that splitting the casters changes nothing.
    /// The solver's own blockers are not part of it: their seams are welded already.
    pub fn close_pinholes(&self, mask: &Mask) -> Mask {
        pinholes::close(mask, &self.full, PINHOLE_NEIGHBOURS)
    }
}
