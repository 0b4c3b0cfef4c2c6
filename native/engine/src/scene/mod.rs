//! Scene visibility: many meshes, each placed by instances with a world transform, shadowing
//! each other and any receiver point (issue 10). Meshes are stored once and shared by their
//! instances; each mesh gets a cluster hierarchy with simplified proxies (`clusters`), the
//! instances a tree of world boxes (`top`); a receiver walks both (`traverse`), culling what
//! lies below its horizon and drawing distant parts through their proxies, into the paper's
//! visibility mask (Kautz et al. 2004, section 3) or, in the ordered mode (`ordered`), into a
//! per-cell depth buffer that knows which surface is seen (validity, `gather`).
//!
//! Meshes whose vertices change (`set_vertices`) keep their hierarchy and proxies and only
//! refit bounds; moved instances (`set_matrix`) only refit the top tree. Adding meshes or
//! instances builds what is new (and rebuilds the top tree, which is cheap).

pub mod affine;
pub mod beams;
pub mod bounce_weights;
pub mod casters;
pub mod clusters;
pub mod facing;
pub mod gather;
pub mod lobes;
pub mod ordered;
pub mod pinholes;
pub mod receivers;
pub mod segments;
pub mod top;
pub mod traverse;
pub mod world;

use std::sync::atomic::{AtomicU64, Ordering};

/// Source of instance stamps, unique across every scene of the process.
static VERSIONS: AtomicU64 = AtomicU64::new(1);

fn next_stamp() -> u64 {
    VERSIONS.fetch_add(1, Ordering::Relaxed)
}
use std::sync::Arc;

use rayon::prelude::*;

use crate::disk_mask::{disk, Mask};
use crate::error::{Error, Result};
use crate::integrate::Quadrature;
use crate::mesh::{check_finite, Vec3};
use crate::plane_table::PlaneTable;
use crate::progress::{par_collect, par_rows, Progress};
use crate::sh::ShBasis;
use crate::transfer::{check_brdf, checked_downsample, Settings};

use affine::Affine;
use bounce_weights::BounceWeights;
use clusters::{union, MeshTree, EMPTY_BOX};
use facing::FacingSink;
use ordered::{DepthSink, Rgb};
use top::TopTree;
use traverse::{MaskSink, Walk};

/// Default level of detail: a node whose bounding sphere's radius is below this fraction of its
/// distance to the receiver (about 9 degrees) is drawn through its proxy. Measured against ray
/// casting (tests/test_scene.py's room; bench/scene.py's 1M crowd), 0.15 is more accurate than
/// 0.1 or 0.05 as well as cheaper: far blockers made of triangles smaller than the plane
/// table's quantisation cover cells spuriously, and proxies have fewer, larger triangles.
pub const DEFAULT_LOD: f32 = 0.15;

/// Plane table of scenes: 6 x 256 x 256 texels (24 MiB stored, built once per process). Scene
/// receivers see far more small, distant triangles than mesh vertices do, and a texel's
/// rounding of an edge plane (about 1/128 radian at 256) blows a triangle smaller than that
/// up to a random size: measured against ray casting (bench/scene.py, 100k scenes), 256
/// lowers the median error from 4.5-4.7 % to 3.1-3.8 % (terrain 3.7 -> 2.3 %) for about 1.35x
/// the time, far less than the 1.9-3x more rays Embree needs for that error.
pub const TABLE_RESOLUTION: usize = 256;

struct SceneMesh {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    tree: Option<MeshTree>,
    /// Vertices changed since the tree was refitted.
    moved: bool,
    radiance: Option<Vec<Rgb>>,
}

/// Counters of the last query.
#[derive(Clone, Copy, Debug, Default)]
pub struct SceneStats {
    /// Triangles above the horizon handed to the rasterizer per receiver (hemisphere).
    pub blockers_per_receiver: f64,
}

pub struct Scene {
    meshes: Vec<SceneMesh>,
    instances: Vec<(u32, Affine)>,
    /// Per instance, radiance that overrides its mesh's (`set_instance_radiance`).
    instance_radiance: Vec<Option<Vec<Rgb>>>,
    instance_bounds: Vec<[Vec3; 2]>,
    top: Option<TopTree>,
    refit_top: bool,
    lod: f32,
    table_resolution: usize,
    stats: SceneStats,
    /// Per instance, a stamp renewed whenever its blockers change (moved, mesh deformed).
    stamps: Vec<u64>,
    /// Which walk `visibility_valid` takes next (speed only: both give the same values).
    validity_walk: ValidityWalk,
}

/// Whether the facing walk decided at least half of `visibility_valid`'s last chunk, and how
/// many chunks have passed; kept between calls, since a baker asks chunk after chunk.
#[derive(Clone, Copy)]
struct ValidityWalk {
    facing_pays: bool,
    chunks: usize,
}

impl Default for Scene {
    fn default() -> Self {
        Scene::new()
    }
}

impl Scene {
    pub fn new() -> Self {
        Scene {
            meshes: Vec::new(),
            instances: Vec::new(),
            instance_radiance: Vec::new(),
            instance_bounds: Vec::new(),
            top: None,
            refit_top: false,
            lod: DEFAULT_LOD,
            table_resolution: TABLE_RESOLUTION,
            stats: SceneStats::default(),
            stamps: Vec::new(),
            validity_walk: ValidityWalk { facing_pays: true, chunks: 0 },
        }
    }

    /// Adds a mesh (not yet in the scene: place it with `add_instance`); returns its id.
    pub fn add_mesh(&mut self, vertices: &[Vec3], triangles: &[[u32; 3]]) -> Result<u32> {
        check_finite(vertices, "vertex")?;
        if triangles.is_empty() {
            return Err(Error::invalid("the mesh has no triangles"));
        }
        if let Some(t) = triangles.iter().find(|t| t.iter().any(|&v| v as usize >= vertices.len())) {
            return Err(Error::invalid(format!("triangle {t:?} uses a vertex beyond the mesh's {} vertices", vertices.len())));
        }
        self.meshes.push(SceneMesh { positions: vertices.to_vec(), triangles: triangles.to_vec(), tree: None, moved: false, radiance: None });
        Ok((self.meshes.len() - 1) as u32)
    }

    /// Places mesh `mesh` with a 4x4 world matrix (row-major, column vectors); returns the
    /// instance's id. Instances share the mesh's geometry and hierarchy.
    pub fn add_instance(&mut self, mesh: u32, matrix: &[f64; 16]) -> Result<u32> {
        self.mesh_index(mesh)?;
        self.instances.push((mesh, Affine::from_rows(matrix)?));
        self.instance_radiance.push(None);
        self.stamps.push(next_stamp());
        self.top = None;
        Ok((self.instances.len() - 1) as u32)
    }

    /// New positions for a mesh that moves (same vertex count and triangles); its hierarchy is
    /// refitted, not rebuilt, and nothing else is touched. The same positions change nothing.
    pub fn set_vertices(&mut self, mesh: u32, vertices: &[Vec3]) -> Result<()> {
        let m = self.mesh_index(mesh)?;
        let count = self.meshes[m].positions.len();
        if vertices.len() != count {
            return Err(Error::invalid(format!("mesh {mesh} has {count} vertices, got {}: add a new mesh to change topology", vertices.len())));
        }
        check_finite(vertices, "vertex")?;
        if self.meshes[m].positions == vertices {
            return Ok(());
        }
        self.meshes[m].positions.copy_from_slice(vertices);
        self.meshes[m].moved = true;
        self.refit_top = true;
        for (stamp, _) in self.stamps.iter_mut().zip(&self.instances).filter(|(_, (im, _))| *im as usize == m) {
            *stamp = next_stamp();
        }
        Ok(())
    }

    /// A new world matrix for an instance; the same matrix changes nothing.
    pub fn set_matrix(&mut self, instance: u32, matrix: &[f64; 16]) -> Result<()> {
        let i = self.instance_index(instance)?;
        let transform = Affine::from_rows(matrix)?;
        if self.instances[i].1 == transform {
            return Ok(());
        }
        self.instances[i].1 = transform;
        self.refit_top = true;
        self.stamps[i] = next_stamp();
        Ok(())
    }

    /// Outgoing radiance per vertex of a mesh, (V, 3), for `gather`.
    pub fn set_radiance(&mut self, mesh: u32, rgb: &[Rgb]) -> Result<()> {
        let m = self.mesh_index(mesh)?;
        let count = self.meshes[m].positions.len();
        if rgb.len() != count {
            return Err(Error::invalid(format!("mesh {mesh} has {count} vertices, got {} radiance rows", rgb.len())));
        }
        if let Some(i) = rgb.iter().position(|c| !c.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(format!("radiance {i} is not finite: {:?}", rgb[i])));
        }
        self.meshes[m].radiance = Some(rgb.to_vec());
        Ok(())
    }

    /// Outgoing radiance per vertex of one instance's mesh, (V, 3), for `gather`: instances
    /// of one mesh that are lit differently. Replaces the mesh's radiance for this instance.
    pub fn set_instance_radiance(&mut self, instance: u32, rgb: &[Rgb]) -> Result<()> {
        let i = self.instance_index(instance)?;
        let count = self.meshes[self.instances[i].0 as usize].positions.len();
        if rgb.len() != count {
            return Err(Error::invalid(format!("instance {instance}'s mesh has {count} vertices, got {} radiance rows", rgb.len())));
        }
        if let Some(v) = rgb.iter().position(|c| !c.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(format!("radiance {v} is not finite: {:?}", rgb[v])));
        }
        self.instance_radiance[i] = Some(rgb.to_vec());
        Ok(())
    }

    /// Per instance, the radiance its blockers show: its own, else its mesh's, else none.
    fn radiance_by_instance(&self) -> Vec<Option<&[Rgb]>> {
        self.instances
            .iter()
            .zip(&self.instance_radiance)
            .map(|((m, _), own)| own.as_deref().or(self.meshes[*m as usize].radiance.as_deref()))
            .collect()
    }

    /// Level of detail (see DEFAULT_LOD); 0 draws every triangle at full resolution.
    pub fn set_lod(&mut self, lod: f32) -> Result<()> {
        if !(lod.is_finite() && (0.0..=1.0).contains(&lod)) {
            return Err(Error::invalid(format!("lod must be between 0 and 1, got {lod}")));
        }
        self.lod = lod;
        Ok(())
    }

    pub fn lod(&self) -> f32 {
        self.lod
    }

    /// The plane table resolution `visibility`, `valid` and `gather` use, and `transfer`'s default.
    pub fn table_resolution(&self) -> usize {
        self.table_resolution
    }

    pub fn mesh_count(&self) -> usize {
        self.meshes.len()
    }

    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    /// Triangles in the scene, counting each instance.
    pub fn triangle_count(&self) -> usize {
        self.instances.iter().map(|(m, _)| self.meshes[*m as usize].triangles.len()).sum()
    }

    pub fn stats(&self) -> SceneStats {
        self.stats
    }

    fn mesh_index(&self, mesh: u32) -> Result<usize> {
        if (mesh as usize) < self.meshes.len() {
            Ok(mesh as usize)
        } else {
            Err(Error::invalid(format!("mesh id {mesh} is out of range: the scene has {} meshes", self.meshes.len())))
        }
    }

    fn instance_index(&self, instance: u32) -> Result<usize> {
        if (instance as usize) < self.instances.len() {
            Ok(instance as usize)
        } else {
            Err(Error::invalid(format!("instance id {instance} is out of range: the scene has {} instances", self.instances.len())))
        }
    }

    /// Builds what is missing and refits what moved, and the scene's plane table (once per
    /// process, 24 MiB) so that the first query does not pay for it.
    pub fn prepare(&mut self) {
        let _ = PlaneTable::shared(self.table_resolution);
        self.meshes.par_iter_mut().for_each(|m| match &mut m.tree {
            None => {
                m.tree = Some(MeshTree::build(&m.positions, &m.triangles));
                m.moved = false;
            }
            Some(tree) if m.moved => {
                tree.refit(&m.positions);
                m.moved = false;
            }
            Some(_) => {}
        });
        if self.top.is_none() || self.refit_top {
            self.instance_bounds = self
                .instances
                .iter()
                .map(|(m, t)| t.apply_box(&self.meshes[*m as usize].tree.as_ref().expect("built above").bounds[0]))
                .collect();
            match &mut self.top {
                Some(top) => top.refit(&self.instance_bounds),
                None => self.top = Some(TopTree::build(&self.instance_bounds)),
            }
            self.refit_top = false;
        }
    }

    /// Whether every mesh has its tree and nothing moved since `prepare`.
    pub fn prepared(&self) -> bool {
        self.top.is_some() && !self.refit_top && self.meshes.iter().all(|m| m.tree.is_some() && !m.moved)
    }

    /// The diagonal of the scene's world bounding box (0 when empty); from the geometry
    /// only, so that it does not depend on how the hierarchy was built.
    pub fn size(&mut self) -> f32 {
        self.prepare();
        let boxes: Vec<[Vec3; 2]> = self.meshes.par_iter().map(|m| clusters::box_of(m.positions.iter().copied())).collect();
        let b = self.instances.iter().fold(EMPTY_BOX, |acc, (m, t)| union(&acc, &t.apply_box(&boxes[*m as usize])));
        let d = [0, 1, 2].map(|a| (b[1][a] - b[0][a]).max(0.0));
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }

    /// A walk over every instance of the prepared scene.
    fn scene_walk<'a>(&'a self, trees: &'a [&'a MeshTree], positions: &'a [&'a [Vec3]]) -> Walk<'a> {
        Walk { trees, positions, instances: &self.instances, top: self.top.as_ref().expect("prepared"), lod: self.lod, exclude: &[], near_proxies: false, radiance: false }
    }

    fn walk_parts(&self) -> (Vec<&MeshTree>, Vec<&[Vec3]>) {
        let trees = self.meshes.iter().map(|m| m.tree.as_ref().expect("prepared")).collect();
        let positions = self.meshes.iter().map(|m| m.positions.as_slice()).collect();
        (trees, positions)
    }

    /// SH transfer vectors (bands^2 per point) of receivers at `points` with `normals`, the
    /// same definition as `crate::transfer` (`settings.offset` is a fraction of `size()`).
    pub fn transfer(&mut self, points: &[Vec3], normals: &[Vec3], settings: &Settings, progress: Progress) -> Result<Vec<f32>> {
        receivers::check(points, Some(normals))?;
        let basis = ShBasis::new(settings.bands)?;
        check_brdf(settings.brdf)?;
        let downsample = checked_downsample(&Settings { downsample: settings.downsample.or(scene_downsample(settings.brdf)), ..settings.clone() })?;
        let views = per_receiver_views(settings, points.len())?;
        let offset = receivers::offset(settings.offset, self.size())?;
        let table = PlaneTable::shared(settings.table_resolution)?;
        let quadrature = Quadrature::new(downsample, basis);
        let k = quadrature.basis().coeffs();
        let (trees, positions) = self.walk_parts();
        let walk = self.scene_walk(&trees, &positions);
        let full = disk();
        let counted = AtomicU64::new(0);
        let mut out = vec![0.0f32; points.len() * k];
        par_rows(&mut out, k, progress, Vec::new, |r, scratch, row| {
            let receiver = receivers::receiver(points[r], normals[r], offset);
            let mut sink = MaskSink::new(&table, full);
            walk.run(&receiver, scratch, &mut sink);
            let (mask, count) = sink.finish();
            counted.fetch_add(count, Ordering::Relaxed);
            let view = views.as_ref().map_or(receiver.frame.n, |v| v[r]);
            quadrature.integrate(&mask, &receiver.frame, settings.brdf, view, row);
        })?;
        self.stats.blockers_per_receiver = counted.into_inner() as f64 / points.len().max(1) as f64;
        Ok(out)
    }

    /// The raw visibility masks of the receivers (bit row * 32 + col set when blocked), in the
    /// tangent frame `crate::mesh::tangent_frame` builds from each normal.
    pub fn visibility(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>) -> Result<Vec<Mask>> {
        receivers::check(points, Some(normals))?;
        let offset = receivers::offset(offset, self.size())?;
        let table = PlaneTable::shared(self.table_resolution)?;
        let (trees, positions) = self.walk_parts();
        let walk = self.scene_walk(&trees, &positions);
        let full = disk();
        Ok(points
            .par_iter()
            .zip(normals)
            .map_init(Vec::new, |scratch, (p, n)| {
                let receiver = receivers::receiver(*p, *n, offset);
                let mut sink = MaskSink::new(&table, full);
                walk.run(&receiver, scratch, &mut sink);
                sink.finish().0
            })
            .collect())
    }

    /// Whether each receiver is outside solid geometry (see `receivers`).
    pub fn valid(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>) -> Result<Vec<bool>> {
        Ok(self.visibility_valid(points, normals, offset)?.1)
    }

    /// Per segment from `points[i]` to `targets[i]`, whether any triangle of the scene crosses
    /// it (exact tests on every triangle, no proxies); `offset` (a fraction of `size()`, as for
    /// receivers) is left out at both ends. For lamps at a finite distance (`segments`).
    pub fn occluded(&mut self, points: &[Vec3], targets: &[Vec3], offset: Option<f32>) -> Result<Vec<bool>> {
        receivers::check(points, None)?;
        if targets.len() != points.len() {
            return Err(Error::invalid(format!("targets has {} rows but points has {}", targets.len(), points.len())));
        }
        receivers::check(targets, None)?;
        let offset = receivers::offset(offset, self.size())?;
        let (trees, positions) = self.walk_parts();
        let segments = segments::Segments::new(&trees, &positions, &self.instances, self.top.as_ref().expect("prepared"));
        Ok(points
            .par_iter()
            .zip(targets)
            .map_init(Vec::new, |stack, (p, t)| segments.occluded(*p, *t, offset, stack))
            .collect())
    }

    /// Per point, whether no triangle can reach into the pyramid from it to a convex polygon
    /// of `corners` corners (in order), above the point's tangent plane (`normals`): one
    /// polygon for every point, or one per point, flat in `polygons`. `offset` (a fraction of
    /// `size()`) is left out at the polygon's end, as `occluded` leaves it out. Conservative
    /// (`beams`): where it says clear, every segment to a point of the polygon above the
    /// tangent plane is; elsewhere, test the segments.
    pub fn beams_clear(&mut self, points: &[Vec3], normals: &[Vec3], polygons: &[Vec3], corners: usize, offset: Option<f32>) -> Result<Vec<bool>> {
        receivers::check(points, Some(normals))?;
        receivers::check(polygons, None)?;
        if !(3..=beams::MAX_CORNERS).contains(&corners) {
            return Err(Error::invalid(format!("a polygon has 3 to {} corners, got {corners}", beams::MAX_CORNERS)));
        }
        let shared = polygons.len() == corners;
        if !shared && polygons.len() != points.len() * corners {
            return Err(Error::invalid(format!("polygons holds {} corners: {corners} (one polygon) or {corners} per point ({})", polygons.len(), points.len() * corners)));
        }
        let offset = receivers::offset(offset, self.size())?;
        let (trees, positions) = self.walk_parts();
        let segments = segments::Segments::new(&trees, &positions, &self.instances, self.top.as_ref().expect("prepared"));
        Ok(points
            .par_iter()
            .enumerate()
            .map_init(|| (Vec::new(), Vec::new()), |(stack, inner), (i, p)| {
                let polygon = if shared { polygons } else { &polygons[i * corners..(i + 1) * corners] };
                let n = crate::mesh::normalize(normals[i]).expect("checked");
                segments.beam_clear(*p, n, polygon, offset, stack, inner)
            })
            .collect())
    }

    /// `visibility` and `valid`, the same values. A plain walk with the blockers split by
    /// facing (`facing`) decides most receivers of open scenes and of rooms of single-sided
    /// walls; the ordered walk decides the rest. Where it decides few (thick walls, whose outer
    /// faces lie behind their inner ones), receivers take the ordered walk alone: chunk by
    /// chunk, the facing walk is kept while it decided at least half of the last chunk (of
    /// this call or the last), and tried again every `RETRY` chunks.
    pub fn visibility_valid(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>) -> Result<MasksAndValidity> {
        Ok(self.visibility_valid_in(points, normals, offset, VALIDITY_CHUNK)?.0)
    }

    /// `visibility_valid` in chunks of `chunk`, and how many chunks took the facing walk.
    fn visibility_valid_in(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>, chunk: usize) -> Result<(MasksAndValidity, usize)> {
        receivers::check(points, Some(normals))?;
        receivers::offset(offset, self.size())?; // refused even with no points
        const RETRY: usize = 8;
        let (mut masks, mut valid) = (Vec::with_capacity(points.len()), Vec::with_capacity(points.len()));
        let mut by_facing = 0;
        for start in (0..points.len()).step_by(chunk.max(1)) {
            let range = start..(start + chunk).min(points.len());
            let (p, n) = (&points[range.clone()], &normals[range]);
            let walk = self.validity_walk;
            self.validity_walk.chunks += 1;
            let (m, v) = if walk.facing_pays || walk.chunks.is_multiple_of(RETRY) {
                by_facing += 1;
                let (m, v, undecided) = self.by_facing(p, n, offset)?;
                self.validity_walk.facing_pays = 2 * undecided <= p.len();
                (m, v)
            } else {
                let full = disk();
                let both = self.depth_buffers(p, n, offset, |sink| (pinholes::close(&sink.raw, &full, traverse::PINHOLE_NEIGHBOURS), receivers::is_valid(&sink.back)))?;
                both.into_iter().unzip()
            };
            masks.extend(m);
            valid.extend(v);
        }
        Ok(((masks, valid), by_facing))
    }

    /// Masks and validity by the facing walk, the ordered walk where it cannot decide, and
    /// how many could not be decided.
    fn by_facing(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>) -> Result<(Vec<Mask>, Vec<bool>, usize)> {
        let split = self.facing_masks(points, normals, offset)?;
        let full = disk();
        let masks = split.iter().map(|(front, back)| {
            let mut mask = *front;
            mask.or_assign(back);
            pinholes::close(&mask, &full, traverse::PINHOLE_NEIGHBOURS)
        });
        let undecided: Vec<usize> = (0..split.len()).filter(|&i| !receivers::is_valid(&split[i].1)).collect();
        let mut valid = vec![true; split.len()];
        if !undecided.is_empty() {
            let (p, n): (Vec<Vec3>, Vec<Vec3>) = undecided.iter().map(|&i| (points[i], normals[i])).unzip();
            let exact = self.depth_buffers(&p, &n, offset, |sink| receivers::is_valid(&sink.back))?;
            undecided.iter().zip(exact).for_each(|(&i, v)| valid[i] = v);
        }
        Ok((masks.collect(), valid, undecided.len()))
    }

    /// Per receiver, the raw masks of its front- and back-facing blockers.
    fn facing_masks(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>) -> Result<Vec<(Mask, Mask)>> {
        receivers::check(points, Some(normals))?;
        let offset = receivers::offset(offset, self.size())?;
        let table = PlaneTable::shared(self.table_resolution)?;
        let (trees, positions) = self.walk_parts();
        let walk = self.scene_walk(&trees, &positions);
        Ok(points
            .par_iter()
            .zip(normals)
            .map_init(Vec::new, |scratch, (p, n)| {
                let mut sink = FacingSink::new(&table);
                walk.run(&receivers::receiver(*p, *n, offset), scratch, &mut sink);
                sink.finish()
            })
            .collect())
    }

    /// `read` of each receiver's depth buffer (the ordered mode without radiance).
    fn depth_buffers<T: Send>(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>, read: impl Fn(&DepthSink) -> T + Sync + Send) -> Result<Vec<T>> {
        receivers::check(points, Some(normals))?;
        let offset = receivers::offset(offset, self.size())?;
        let table = PlaneTable::shared(self.table_resolution)?;
        let (trees, positions) = self.walk_parts();
        let walk = self.scene_walk(&trees, &positions);
        let radiance: Vec<Option<&[Rgb]>> = vec![None; self.instances.len()];
        Ok(points
            .par_iter()
            .zip(normals)
            .map_init(Vec::new, |scratch, (p, n)| {
                let receiver = receivers::receiver(*p, *n, offset);
                let mut sink = DepthSink::new(&table, &radiance);
                walk.run(&receiver, scratch, &mut sink);
                read(&sink)
            })
            .collect())
    }

    /// Ordered mode: the SH projection (bands^2 x 3 per point, coefficient-major) of the
    /// radiance of the nearest blocker in every direction, over the receiver's hemisphere, or
    /// over the whole sphere when `normals` is None.
    pub fn gather(&mut self, points: &[Vec3], normals: Option<&[Vec3]>, bands: usize, offset: Option<f32>, progress: Progress) -> Result<Vec<f32>> {
        Ok(self.ordered_gather(points, normals, bands, offset, false, progress)?.0)
    }

    /// `gather`, with each walked hemisphere's view (its normal's, or +Z then -Z without
    /// normals; receiver-major): probes get their masks and validity from the same walks.
    pub fn gather_views(&mut self, points: &[Vec3], normals: Option<&[Vec3]>, bands: usize, offset: Option<f32>, progress: Progress) -> Result<(Vec<f32>, Vec<HemisphereView>)> {
        self.ordered_gather(points, normals, bands, offset, true, progress)
    }

    /// `gather`, and the views when `views` (else none: plain gathers skip that work).
    fn ordered_gather(&mut self, points: &[Vec3], normals: Option<&[Vec3]>, bands: usize, offset: Option<f32>, views: bool, progress: Progress) -> Result<(Vec<f32>, Vec<HemisphereView>)> {
        receivers::check(points, normals)?;
        let projector = gather::Projector::new(ShBasis::new(bands)?);
        let offset = receivers::offset(offset, self.size())?;
        let table = PlaneTable::shared(self.table_resolution)?;
        let (trees, positions) = self.walk_parts();
        let walk = Walk { radiance: true, ..self.scene_walk(&trees, &positions) };
        let radiance = self.radiance_by_instance();
        let k = projector.coeffs();
        let full = disk();
        let rows = par_collect(points.len(), progress, Vec::new, |r, scratch| {
            let hemispheres: &[Vec3] = match normals {
                Some(n) => std::slice::from_ref(&n[r]),
                None => &[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]],
            };
            let mut row = vec![0.0f32; k * 3];
            let mut seen = Vec::new();
            for n in hemispheres {
                let receiver = receivers::receiver(points[r], *n, offset);
                let mut sink = DepthSink::new(&table, &radiance);
                walk.run(&receiver, scratch, &mut sink);
                projector.add(&sink, &receiver, &mut row);
                if views {
                    seen.push(hemisphere_view(&sink, &full));
                }
            }
            (row, seen)
        })?;
        let (rows, views): (Vec<Vec<f32>>, Vec<Vec<HemisphereView>>) = rows.into_iter().unzip();
        Ok((rows.concat(), views.concat()))
    }

    /// What `gather` (3 bands) then the lobe along each normal would give, recorded as weights
    /// on the vertices each receiver sees (`bounce_weights`), for bounce passes that change
    /// only the radiance, with the receivers' `visibility` masks and validity (`valid`) from
    /// the same walk.
    pub fn bounce_weights(&mut self, points: &[Vec3], normals: &[Vec3], offset: Option<f32>, progress: Progress) -> Result<BounceWeights> {
        receivers::check(points, Some(normals))?;
        let offset = receivers::offset(offset, self.size())?;
        let table = PlaneTable::shared(self.table_resolution)?;
        let first_slot = bounce_weights::first_slots(self.instances.iter().map(|(m, _)| self.meshes[*m as usize].positions.len()))?;
        let slots = *first_slot.last().expect("non-empty") as usize;
        let cell_weights = bounce_weights::normal_cell_weights();
        let (trees, positions) = self.walk_parts();
        let walk = Walk { radiance: true, ..self.scene_walk(&trees, &positions) };
        let black: Vec<Option<&[Rgb]>> = vec![None; self.instances.len()];
        let full = disk();
        let rows = par_collect(points.len(), progress, || bounce_weights::Scratch::new(slots), |r, scratch| {
            let receiver = receivers::receiver(points[r], normals[r], offset);
            let mut sink = DepthSink::recording(&table, &black);
            walk.run(&receiver, &mut scratch.stack, &mut sink);
            let row = bounce_weights::row(&sink, cell_weights, &first_slot, scratch);
            (closed_mask(&sink, &full), receivers::is_valid(&sink.back), row)
        })?;
        Ok(BounceWeights::new(rows, first_slot, self.stamps.clone()))
    }

    /// Irradiance / pi (3 per receiver, unclamped) that `weights` give under the radiance the
    /// scene shows now (`set_radiance`, `set_instance_radiance`).
    pub fn apply_bounce_weights(&self, weights: &BounceWeights) -> Result<Vec<f32>> {
        weights.apply(&self.radiance_by_instance(), &self.stamps)
    }
}

/// What a receiver's depth buffer says of its hemisphere.
#[derive(Clone, Copy, Debug)]
pub struct HemisphereView {
    /// The visibility mask: covered cells, pinholes closed as `visibility` closes them.
    pub mask: Mask,
    /// The fraction of its cells that show back faces (`valid` when at most
    /// receivers::BACK_FACE_LIMIT).
    pub back: f32,
    /// The harmonic mean distance to what its cells see, over the cells that see something
    /// (irradiance caching's R: the cells are equal areas of the projected disk, so the mean
    /// is cosine-weighted); infinite when it sees nothing.
    pub distance: f32,
}

fn hemisphere_view(sink: &DepthSink, full: &Mask) -> HemisphereView {
    HemisphereView { mask: closed_mask(sink, full), back: receivers::back_fraction(&sink.back), distance: harmonic_distance(sink) }
}

/// The area of the cells that see something over the sum of each one's area / its depth
/// (rim cells count for the part of the disk they hold: equal weights would overweigh the
/// horizon); infinite when nothing is seen.
fn harmonic_distance(sink: &DepthSink) -> f32 {
    let samples = crate::disk_mask::cell_samples();
    let (mut seen, mut near) = (0.0f32, 0.0f32);
    for (t, s) in sink.depth.iter().zip(samples).filter(|(t, _)| t.is_finite()) {
        seen += s.area;
        near += s.area / t.max(f32::MIN_POSITIVE);
    }
    if near > 0.0 { seen / near } else { f32::INFINITY }
}

/// The cells the depth buffer covers, pinholes closed as `visibility` closes them.
fn closed_mask(sink: &DepthSink, full: &Mask) -> Mask {
    pinholes::close(&sink.covered(), full, traverse::PINHOLE_NEIGHBOURS)
}

/// Per receiver, its visibility mask and whether it is valid.
type MasksAndValidity = (Vec<Mask>, Vec<bool>);

/// Receivers per chunk of `visibility_valid`, which picks its walk per chunk: a few times the
/// threads' work units, small beside a lightmap's samples.
const VALIDITY_CHUNK: usize = 2048;

/// Scene receivers see large blockers near their horizon (floors, walls) far more often than
/// mesh vertices do: diffuse transfer integrates single cells (`subtract_blocked_cells`, as
/// fast as 2 x 2 blocks). Measured against ray casting: the paper's 4 x 4 gave 4.4 % median
/// error on tests/test_scene.py's room, 2 x 2 3.2 %; on bench/scene.py's 100k scenes 1 x 1
/// lowers 2 x 2's median by 0.25-0.5 points at the same cost.
fn scene_downsample(brdf: crate::integrate::Brdf) -> Option<usize> {
    matches!(brdf, crate::integrate::Brdf::Diffuse).then_some(1)
}

fn per_receiver_views(settings: &Settings, count: usize) -> Result<Option<Arc<Vec<Vec3>>>> {
    let first: Vec<u32> = (0..count as u32).collect();
    Ok(crate::transfer::welded_views(&first, count, settings.brdf, settings.view.as_ref())?.map(Arc::new))
}

#[cfg(test)]
mod tests;
