//! A per-mesh transfer solver for deforming meshes (Kautz et al. 2004, section 3.2).
//!
//! Built once from the topology and a rest pose, it keeps what does not change while the mesh
//! deforms: the weld map, the two-level hierarchy (`hierarchy.rs`), the default offset and the
//! quadrature. Each `solve` takes the frame's positions and refreshes cluster bounds, culls
//! clusters below each receiver's horizon, and reuses the previous result of receivers whose
//! blockers did not move.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use rayon::prelude::*;

use crate::disk_mask::{disk, Mask};
use crate::error::{Error, Result};
use crate::group_tree::{centre_distance2, GroupTree, FAR_LOD, LEAF};
use crate::hierarchy::{default_coarse_triangles, morton_permutation, Hierarchy, GROUP};
use crate::integrate::{Brdf, Quadrature};
use crate::mesh::{box_centre, box_of, check_finite, half_diagonal2, weld, welded_normals, Normalization, Vec3};
use crate::progress::{par_rows, par_rows_with, Progress};
use crate::pvs::{contributing, node_unit, Pvs};
use crate::plane_table::PlaneTable;
use crate::packets::{Packet, PacketLists, LANES};
use crate::rasterizer::{Pipeline, Source, Viewer};
use crate::caster_reuse::{CasterCache, CasterPlan, Kept};
use crate::scene::casters::Casters;
use crate::sh::ShBasis;
use crate::transfer::{check_brdf, checked_downsample, checked_offset, welded_views, Receiver, Settings, View, HORIZON_MARGIN};

/// How the solver picks blockers.
#[derive(Clone, Debug)]
pub struct Blockers {
    /// Use the two-level hierarchy; without it every fine triangle is a blocker.
    pub hierarchy: bool,
    /// Target size of the coarse mesh; None: `default_coarse_triangles`.
    pub coarse_triangles: Option<usize>,
    /// The k-ring (1 or 2) of fine triangles every receiver sees at full resolution.
    pub ring: usize,
    /// Skip clusters whose bounds lie below the receiver's horizon.
    pub cull: bool,
    /// Reuse the last result of receivers whose blockers did not move.
    pub reuse: bool,
    /// Clusters whose centre lies within this many of their radii of a receiver are seen at
    /// full resolution too: a coarse triangle that close cuts through the real surface. 2.5
    /// keeps every vertex of the shared meshes and characters, in every frame, within 0.1 AO
    /// of the exact path (bench/solver_trust.py); 1.5 left receivers inside folds 0.13 off.
    pub near_scale: f32,
    /// Groups of coarse triangles whose bounds' radius is below this fraction of their
    /// distance are drawn through a coarser proxy (`group_tree.rs`); 0 draws every coarse
    /// triangle, as the paper's two levels do.
    pub far_lod: f32,
}

impl Default for Blockers {
    fn default() -> Self {
        Blockers { hierarchy: true, coarse_triangles: None, ring: 2, cull: true, reuse: true, near_scale: 2.5, far_lod: FAR_LOD }
    }
}

/// Counters of the last solve.
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    /// Triangles above the horizon handed to the rasterizer per computed receiver (after
    /// the hierarchy and culling).
    pub blockers_per_receiver: f64,
    pub computed: usize,
    pub reused: usize,
    /// Whether the frame was close enough to the sampled poses to use the PVS.
    pub used_pvs: bool,
}

struct LastFrame {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    views: Option<Vec<Vec3>>,
    node_bounds: Vec<[Vec3; 2]>,
    used_pvs: bool,
    casters: Option<CasterCache>,
    transfer: Vec<f32>,
}

pub struct Solver {
    remap: Vec<u32>,
    first_copy: Vec<u32>,
    /// The rest pose's: every frame is moved and scaled by the same map.
    normalization: Normalization,
    fine: Vec<[u32; 3]>,
    hierarchy: Hierarchy,
    /// Per group, its clusters' coarse triangles (lane i of packet p: cluster p * LANES + i).
    coarse_packets: PacketLists,
    /// Per cluster, the fine triangles it owns.
    fine_packets: PacketLists,
    /// The groups' tree, with proxies for distant ones.
    group_tree: GroupTree,
    /// Welded receivers in the order they are computed: along a Morton curve of the rest
    /// pose, so that a thread's consecutive receivers read the same clusters from cache
    /// (Blender's subdivided meshes number vertices far apart from their neighbours).
    receiver_order: Vec<u32>,
    /// Per input vertex, the row of its welded receiver in that order: the output is copied
    /// from the computed rows in one pass.
    output_rows: Vec<u32>,
    blockers: Blockers,
    brdf: Brdf,
    offset: f32,
    table: Arc<PlaneTable>,
    quadrature: Quadrature,
    disk: Mask,
    last: Option<LastFrame>,
    /// The caster masks' second buffer (`solve_with_casters`).
    spare_masks: Vec<Kept>,
    pvs: Option<Pvs>,
    stats: Stats,
}

/// One frame's data shared by the receivers (welded, normalised).
struct Frame {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    views: Option<Vec<Vec3>>,
    /// Bounding boxes of clusters.
    bounds: Vec<[Vec3; 2]>,
    /// Per group, its clusters' spheres (`ClusterSpheres`).
    spheres: Vec<ClusterSpheres>,
    group_bounds: Vec<[Vec3; 2]>,
    /// Per node of the group tree, its box.
    node_bounds: Vec<[Vec3; 2]>,
    /// Whether receivers see through their potentially visible sets.
    use_pvs: bool,
}

impl Solver {
    pub fn new(rest: &[Vec3], triangles: &[[u32; 3]], settings: &Settings, blockers: Blockers) -> Result<Self> {
        let basis = ShBasis::new(settings.bands)?;
        check_brdf(settings.brdf)?;
        let downsample = checked_downsample(settings)?;
        if !matches!(blockers.ring, 1 | 2) {
            return Err(Error::invalid(format!("ring must be 1 or 2, got {}", blockers.ring)));
        }
        let (mesh, normalization) = weld(rest, triangles)?.normalized();
        if mesh.triangles.is_empty() {
            return Err(Error::invalid("every triangle of the mesh is degenerate: each has two corners at the same position (or the same vertex twice)"));
        }
        let offset = checked_offset(settings.offset, &mesh, normalization.scale())?;
        let coarse_target = blockers.coarse_triangles.unwrap_or(default_coarse_triangles(mesh.triangles.len()));
        let layout = snapped(&mesh.positions, &mesh.triangles);
        let hierarchy = Hierarchy::build(&layout, &mesh.triangles, coarse_target.max(1), blockers.ring);
        let first_copy = mesh.first_copies();
        let coarse_packets = PacketLists::new(hierarchy.coarse.chunks(GROUP));
        let fine_packets = PacketLists::new(hierarchy.cluster_compact.iter().map(|c| &c.welded[..]));
        let group_tree = GroupTree::build(&layout, &hierarchy);
        let receiver_order = morton_permutation(&layout);
        let output_rows = output_rows(&receiver_order, &mesh.remap);
        Ok(Solver {
            remap: mesh.remap,
            first_copy,
            normalization,
            fine: mesh.triangles,
            hierarchy,
            coarse_packets,
            fine_packets,
            group_tree,
            receiver_order,
            output_rows,
            blockers,
            brdf: settings.brdf,
            offset,
            table: PlaneTable::shared(settings.table_resolution)?,
            quadrature: Quadrature::new(downsample, basis),
            disk: disk(),
            last: None,
            spare_masks: Vec::new(),
            pvs: None,
            stats: Stats::default(),
        })
    }

    pub fn vertex_count(&self) -> usize {
        self.remap.len()
    }

    pub fn coarse_triangles(&self) -> usize {
        self.hierarchy.clusters()
    }

    pub fn coeffs(&self) -> usize {
        self.quadrature.basis().coeffs()
    }

    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Bytes the solver keeps between frames, the shared plane table excepted.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        let h = &self.hierarchy;
        let compact = |c: &crate::hierarchy::Compact| c.vertices.len() * 4 + c.welded.len() * 12;
        let last = self.last.as_ref().map_or(0, |l| {
            (l.positions.len() + l.normals.len() + l.views.as_ref().map_or(0, Vec::len)) * size_of::<Vec3>()
                + l.node_bounds.len() * 24
                + l.transfer.len() * 4
                + l.casters.as_ref().map_or(0, CasterCache::bytes)
        }) + self.spare_masks.capacity() * size_of::<Kept>();
        (self.remap.len() + self.first_copy.len() + self.receiver_order.len() + self.output_rows.len()) * 4
            + self.fine.len() * 12
            + h.coarse.len() * 12
            + (h.owned_start.len() + h.owned.len() + h.near_start.len() + h.near.len()) * 4
            + h.group_compact.iter().map(compact).sum::<usize>()
            + h.cluster_compact.iter().map(compact).sum::<usize>()
            + self.coarse_packets.bytes()
            + self.fine_packets.bytes()
            + self.group_tree.proxies.bytes()
            + self.group_tree.nodes.len() * std::mem::size_of::<crate::group_tree::GroupNode>()
            + self.pvs.as_ref().map_or(0, Pvs::bytes)
            + last
    }

    /// Transfer vectors (bands^2 per input vertex) for this frame's positions.
    pub fn solve(&mut self, vertices: &[Vec3], normals: Option<&[Vec3]>, view: Option<&View>) -> Result<Vec<f32>> {
        self.solve_with_progress(vertices, normals, view, &mut |_| true)
    }

    /// `solve`, reporting the fraction done to `progress` (on this thread) and stopping with
    /// `Error::Cancelled` when it returns false; a cancelled solve leaves the solver as it was.
    pub fn solve_with_progress(
        &mut self,
        vertices: &[Vec3],
        normals: Option<&[Vec3]>,
        view: Option<&View>,
        progress: Progress,
    ) -> Result<Vec<f32>> {
        self.solve_with_casters(vertices, normals, view, None, progress)
    }

    /// `solve_with_progress` with a scene's blockers (`casters`) rasterized into each
    /// receiver's mask after the mesh's own: shadows cast by other objects. Receivers whose
    /// own blockers kept still rasterize only the casters that moved (`caster_reuse`).
    pub fn solve_with_casters(
        &mut self,
        vertices: &[Vec3],
        normals: Option<&[Vec3]>,
        view: Option<&View>,
        casters: Option<&Casters>,
        progress: Progress,
    ) -> Result<Vec<f32>> {
        let frame = self.prepare(vertices, normals, view)?;
        let still = self.reusable_receivers(&frame, casters.is_some());
        let cache = self.last.as_ref().and_then(|l| l.casters.as_ref());
        let plan = casters.map(|c| CasterPlan::new(cache, c));
        // This frame's masks go to the buffer the frame before last used (no allocation, no
        // zeroing); the last frame's stay readable, and stay the cache if this solve is cancelled.
        let keep_masks = casters.is_some() && self.blockers.reuse;
        let mut masks = std::mem::take(&mut self.spare_masks);
        masks.resize(if keep_masks { frame.positions.len() } else { 0 }, Kept::default());
        let k = self.coeffs();
        let mut ordered = vec![0.0f32; frame.positions.len() * k];
        let (blockers, reused) = (AtomicU64::new(0), AtomicU64::new(0));
        let solved = par_rows_with(&mut ordered, k, &mut masks, progress, Scratch::default, |i, scratch, out, slot| {
            let r = self.receiver_order[i] as usize;
            let copy = still[r] && plan.as_ref().is_none_or(|p| p.unchanged);
            let step = match (&self.last, copy) {
                (Some(last), true) => {
                    out.copy_from_slice(&last.transfer[r * k..(r + 1) * k]);
                    reused.fetch_add(1, Ordering::Relaxed);
                    Step { base: cache.map(|c| c.masks[i]), count: 0 }
                }
                _ => {
                    let cached = cache.zip(self.last.as_ref()).filter(|_| still[r] && plan.as_ref().is_some_and(|p| p.masks_valid));
                    let cached = cached.map(|(c, last)| (c.masks[i], &last.transfer[r * k..(r + 1) * k]));
                    self.receiver(r, &frame, casters.zip(plan.as_ref()), cached, scratch, out)
                }
            };
            blockers.fetch_add(step.count, Ordering::Relaxed);
            if let (Some(slot), Some(base)) = (slot, step.base) {
                *slot = base;
            }
        });
        if let Err(error) = solved {
            self.spare_masks = masks;
            return Err(error);
        }
        let reused = reused.into_inner() as usize;
        let computed = frame.positions.len() - reused;
        self.stats = Stats {
            blockers_per_receiver: blockers.into_inner() as f64 / computed.max(1) as f64,
            computed,
            reused,
            used_pvs: frame.use_pvs,
        };
        let mut result = Vec::with_capacity(self.output_rows.len() * k);
        for &row in &self.output_rows {
            result.extend_from_slice(&ordered[row as usize * k..(row as usize + 1) * k]);
        }
        if self.blockers.reuse {
            let mut welded = vec![0.0f32; ordered.len()];
            for (row, &r) in ordered.chunks_exact(k).zip(&self.receiver_order) {
                welded[r as usize * k..(r as usize + 1) * k].copy_from_slice(row);
            }
            let last_masks = self.last.as_mut().and_then(|l| l.casters.as_mut()).map(|c| std::mem::take(&mut c.masks));
            self.spare_masks = last_masks.unwrap_or_default();
            let casters = casters.zip(plan).map(|(c, p)| p.into_cache(c, masks));
            let Frame { positions, normals, views, node_bounds, use_pvs, .. } = frame;
            self.last = Some(LastFrame { positions, normals, views, node_bounds, used_pvs: use_pvs, casters, transfer: welded });
        }
        Ok(result)
    }

    /// Checks a frame's input and computes what its receivers share; fills the packets.
    fn prepare(&mut self, vertices: &[Vec3], normals: Option<&[Vec3]>, view: Option<&View>) -> Result<Frame> {
        if vertices.len() != self.remap.len() {
            return Err(Error::invalid(format!(
                "the solver was built for {} vertices, got {}: the topology changed, build a new solver",
                self.remap.len(),
                vertices.len()
            )));
        }
        check_finite(vertices, "vertex")?;
        let positions = self.normalization.apply_all(self.first_copy.iter().map(|&i| vertices[i as usize]));
        let normals = welded_normals(&positions, &self.fine, &self.remap, normals)?;
        let views = welded_views(&self.first_copy, self.remap.len(), self.brdf, view)?;
        self.coarse_packets.update(&positions);
        self.fine_packets.update(&positions);
        self.group_tree.proxies.update(&positions);
        let bounds = self.cluster_bounds(&positions);
        let group_bounds = self.group_bounds(&positions, &bounds);
        let node_bounds = self.group_tree.bounds(&group_bounds);
        let spheres = self.cluster_spheres(&bounds);
        let use_pvs = self.pvs.as_ref().is_some_and(|pvs| pvs.covers(&positions));
        Ok(Frame { positions, normals, views, bounds, spheres, group_bounds, node_bounds, use_pvs })
    }

    /// Samples `poses` (input vertices per pose) for potentially visible sets (`pvs.rs`):
    /// later frames within `tolerance` of one of them rasterize only the clusters that
    /// contributed to a receiver in some sampled pose. Replaces any earlier sets.
    /// `normals`: per pose, as `solve` takes them (None: the mesh's own).
    pub fn build_pvs(&mut self, poses: &[&[Vec3]], normals: Option<&[&[Vec3]]>, tolerance: f32, progress: Progress) -> Result<()> {
        if normals.is_some_and(|n| n.len() != poses.len()) {
            return Err(Error::invalid("build_pvs needs one set of normals per pose"));
        }
        if poses.is_empty() {
            return Err(Error::invalid("build_pvs needs at least one pose"));
        }
        if !(tolerance.is_finite() && tolerance >= 0.0) {
            return Err(Error::invalid(format!("the PVS tolerance must be finite and non-negative, got {tolerance}")));
        }
        let (mut per_pose, mut welded_poses) = (Vec::new(), Vec::new());
        for (p, pose) in poses.iter().enumerate() {
            let frame = self.prepare(pose, normals.map(|n| n[p]), None)?;
            let mut needed: Vec<Vec<u32>> = vec![Vec::new(); frame.positions.len()];
            let mut fraction = |f: f32| progress((p as f32 + f) / poses.len() as f32);
            let mut rows = vec![0.0f32; frame.positions.len()];
            let slots: Vec<std::sync::Mutex<Vec<u32>>> = needed.iter_mut().map(|v| std::sync::Mutex::new(std::mem::take(v))).collect();
            par_rows(&mut rows, 1, &mut fraction, || (), |r, _, _| {
                *slots[r].lock().unwrap_or_else(|e| e.into_inner()) = self.contributing_units(r, &frame);
            })?;
            per_pose.push(slots.into_iter().map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner())).collect());
            welded_poses.push(frame.positions);
        }
        self.pvs = Some(Pvs::new(per_pose, welded_poses, self.hierarchy.clusters() as u32, tolerance));
        self.last = None;
        Ok(())
    }

    pub fn clear_pvs(&mut self) {
        self.pvs = None;
        self.last = None;
    }

    pub fn pvs(&self) -> Option<&Pvs> {
        self.pvs.as_ref()
    }

    /// The units (clusters and proxies, `pvs.rs`) that contribute to receiver `r`'s mask in
    /// this frame, its ring always included: the walk of `own_mask`, each unit's mask apart.
    fn contributing_units(&self, r: usize, frame: &Frame) -> Vec<u32> {
        let mut kept = self.hierarchy.near_of(r).to_vec();
        let Some(receiver) = Receiver::new(frame.positions[r], frame.normals[r], self.offset) else { return kept };
        let (tree, origin) = (&self.group_tree, receiver.origin);
        let lod2 = self.far_lod2();
        let mut candidates = Vec::new();
        let mut stack: Vec<u32> = if tree.nodes.is_empty() { Vec::new() } else { vec![0] };
        while let Some(n) = stack.pop() {
            let (n, bounds) = (n as usize, &frame.node_bounds[n as usize]);
            if self.culled(&receiver, bounds) {
                continue;
            }
            match self.turn(n, bounds, origin, lod2) {
                Turn::Group(g) => self.cluster_candidates(g, r, &receiver, frame, &mut candidates),
                Turn::Proxy => {
                    let mask = self.unit_mask(r, &receiver, tree.proxies.of(n), u32::MAX);
                    if mask != Mask::EMPTY {
                        candidates.push((centre_distance2(bounds, origin), node_unit(self.hierarchy.clusters(), n), mask));
                    }
                }
                Turn::Open(children) => stack.extend_from_slice(&children),
            }
        }
        kept.extend(contributing(candidates));
        kept
    }

    /// Each cluster of group `g` that draws anything for receiver `r`, as a candidate unit.
    fn cluster_candidates(&self, g: usize, r: usize, receiver: &Receiver, frame: &Frame, candidates: &mut Vec<(f32, u32, Mask)>) {
        let first = g * GROUP;
        let clusters = (first + GROUP).min(self.hierarchy.clusters()) - first;
        let (near, _) = frame.spheres[g].sides(receiver.origin, receiver.frame.n);
        let expanded = self.expanded_clusters(r, first, clusters, near);
        for i in 0..clusters {
            let c = first + i;
            let mask = if expanded >> i & 1 == 1 {
                self.unit_mask(r, receiver, self.fine_packets.of(c), u32::MAX)
            } else {
                self.unit_mask(r, receiver, [&self.coarse_packets.of(g)[i / LANES]], 1 << (i % LANES))
            };
            if mask != Mask::EMPTY {
                candidates.push((centre_distance2(&frame.bounds[c], receiver.origin), c as u32, mask));
            }
        }
    }

    /// The mask the `lanes` of `packets` draw alone for receiver `r`: the sets judge each unit
    /// apart.
    fn unit_mask<'a>(&self, r: usize, receiver: &Receiver, packets: impl IntoIterator<Item = &'a Packet>, lanes: u32) -> Mask {
        let (table, mut mask, mut pipeline) = (&*self.table, Mask::EMPTY, Pipeline::default());
        for packet in packets {
            pipeline.rasterize_packet(table, receiver.origin, &receiver.frame, packet, lanes, r as u32, &mut mask);
        }
        pipeline.drain(table, &mut mask);
        mask
    }

    /// Bits of the clusters `first..first + clusters` that receiver `r` sees at full
    /// resolution: its ring, the clusters close to it (`near`, `ClusterSpheres::sides`), or
    /// all without the hierarchy.
    #[inline(always)]
    fn expanded_clusters(&self, r: usize, first: usize, clusters: usize, near: u32) -> u32 {
        if !self.blockers.hierarchy {
            return (1 << clusters) - 1;
        }
        bits_of(self.hierarchy.near_of(r), first, clusters) | near
    }

    /// Per cluster, the bounding box of its coarse triangle and the fine triangles it owns in
    /// this frame. The coarse triangle counts: it can reach beyond the fine triangles (they are
    /// owned by nearest centroid), and a receiver close to it must see the real surface.
    fn cluster_bounds(&self, positions: &[Vec3]) -> Vec<[Vec3; 2]> {
        (0..self.hierarchy.clusters())
            .map(|c| {
                let fine = self.hierarchy.cluster_compact[c].vertices.iter().map(|&v| positions[v as usize]);
                box_of(fine.chain(self.hierarchy.coarse[c].iter().map(|&v| positions[v as usize])))
            })
            .collect()
    }

    fn cluster_spheres(&self, bounds: &[[Vec3; 2]]) -> Vec<ClusterSpheres> {
        bounds.chunks(GROUP).map(|group| ClusterSpheres::new(group, self.blockers.near_scale)).collect()
    }

    /// Per group, the box around its clusters' boxes and its coarse triangles.
    fn group_bounds(&self, positions: &[Vec3], clusters: &[[Vec3; 2]]) -> Vec<[Vec3; 2]> {
        (0..self.hierarchy.groups())
            .map(|g| {
                let range = g * GROUP..((g + 1) * GROUP).min(clusters.len());
                let corners = clusters[range].iter().flat_map(|b| [b[0], b[1]]);
                let coarse = self.hierarchy.group_compact[g].vertices.iter().map(|&v| positions[v as usize]);
                box_of(corners.filter(|p| p[0].is_finite()).chain(coarse))
            })
            .collect()
    }

    /// Receivers whose result cannot differ from the last frame's: same position, normal and
    /// view, and the same walk down the group tree in both frames (`same_walk`).
    /// `casters`: whether this frame has casters; a last frame with (or without) them leaves
    /// nothing to reuse for a frame without (or with): the masks differ.
    fn reusable_receivers(&self, frame: &Frame, casters: bool) -> Vec<bool> {
        let n = frame.positions.len();
        let Some(last) = self.last.as_ref().filter(|_| self.blockers.reuse) else { return vec![false; n] };
        if last.views != frame.views || last.used_pvs != frame.use_pvs || last.casters.is_some() != casters {
            return vec![false; n];
        }
        let moved: Vec<bool> = (0..n).map(|v| frame.positions[v] != last.positions[v] || frame.normals[v] != last.normals[v]).collect();
        let h = &self.hierarchy;
        let group_moved: Vec<bool> = (0..h.groups())
            .map(|g| {
                let clusters = g * GROUP..((g + 1) * GROUP).min(h.clusters());
                h.group_compact[g].vertices.iter().any(|&v| moved[v as usize])
                    || clusters.flat_map(|c| h.cluster_compact[c].vertices.iter()).any(|&v| moved[v as usize])
            })
            .collect();
        let tree = &self.group_tree;
        let node_moved: Vec<bool> = (0..tree.nodes.len())
            .map(|n| tree.proxies.of(n).iter().flat_map(|p| p.ids.iter().flatten()).any(|&v| v != u32::MAX && moved[v as usize]))
            .collect();
        (0..n)
            .into_par_iter()
            .map(|r| {
                if moved[r] {
                    return false;
                }
                let Some(receiver) = Receiver::new(frame.positions[r], frame.normals[r], self.offset) else { return true };
                self.same_walk(&receiver, frame, last, &group_moved, &node_moved)
            })
            .collect()
    }

    /// Whether the receiver's walk down the group tree takes the same turns in this frame as
    /// in the last (every node it culls, draws through its proxy or opens) and meets nothing
    /// that moved except below its horizon in both frames: then its blockers are the same.
    fn same_walk(&self, receiver: &Receiver, frame: &Frame, last: &LastFrame, group_moved: &[bool], node_moved: &[bool]) -> bool {
        let (lod2, origin) = (self.far_lod2(), receiver.origin);
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let n = n as usize;
            let (now, then) = (&frame.node_bounds[n], &last.node_bounds[n]);
            // Below the horizon in both frames: nothing in it is drawn, culled or not.
            if receiver.below_horizon(now) && receiver.below_horizon(then) {
                continue;
            }
            match (self.turn(n, now, origin, lod2), self.turn(n, then, origin, lod2)) {
                (Turn::Group(g), _) if group_moved[g] => return false,
                (Turn::Group(_), _) => {}
                (Turn::Proxy, Turn::Proxy) if !node_moved[n] => {}
                (Turn::Open(children), Turn::Open(_)) => stack.extend_from_slice(&children),
                _ => return false,
            }
        }
        true
    }

    /// Transfer of welded receiver `r` into `out`: its own blockers and the still casters'
    /// (or `cached`, their masks from the last frame with the result then), then the moving
    /// casters, per `plan`. A mask equal to the last frame's takes the last result as it is.
    #[allow(clippy::too_many_arguments)]
    fn receiver<'a>(
        &'a self,
        r: usize,
        frame: &Frame,
        casters: Option<(&Casters, &CasterPlan)>,
        cached: Option<(Kept, &[f32])>,
        scratch: &mut Scratch<'a>,
        out: &mut [f32],
    ) -> Step {
        let Some(receiver) = Receiver::new(frame.positions[r], frame.normals[r], self.offset) else {
            out.fill(0.0);
            return Step { base: Some(Kept::default()), count: 0 };
        };
        // Each walk stops once the cells it has not drawn are blocked already (`occlude`).
        let occlude = |skip: &[u32], known: Mask, corners: &mut Vec<Vec3>| match casters {
            Some((c, _)) => c.occlude(&self.table, &self.normalization, &receiver, skip, known, corners),
            None => (Mask::EMPTY, 0),
        };
        let ((own, still), mut count) = match cached {
            Some((kept, _)) => ((kept.own, kept.still), 0),
            None => {
                let (own, count) = self.own_mask(r, frame, &receiver, scratch);
                let (still, more) = match casters.filter(|_| own != self.disk) {
                    Some((_, plan)) => occlude(&plan.skip_moving, own, &mut scratch.corners),
                    None => (Mask::EMPTY, 0),
                };
                ((own, still), count + more)
            }
        };
        let mut total = own;
        if let Some((c, plan)) = casters.filter(|_| own != self.disk) {
            let mut known = own;
            known.or_assign(&still);
            let (mut cast, more) = occlude(&plan.skip_still, known, &mut scratch.corners);
            cast.or_assign(&still);
            total.or_assign(&c.close_pinholes(&cast));
            count += more;
        }
        match cached {
            Some((kept, last)) if kept.total == total => out.copy_from_slice(last),
            _ => {
                let view = frame.views.as_ref().map_or(receiver.frame.n, |v| v[r]);
                self.quadrature.integrate(&total, &receiver.frame, self.brdf, view, out);
            }
        }
        Step { base: Some(Kept { own, still, total }), count }
    }

    /// The mask of receiver `r`'s own blockers and their count. The hot loop is compiled
    /// twice, for AVX2 + FMA and for the baseline, and picked at run time.
    fn own_mask<'a>(&'a self, r: usize, frame: &Frame, receiver: &Receiver, scratch: &mut Scratch<'a>) -> (Mask, u64) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { self.own_mask_avx2(r, frame, receiver, scratch) };
        }
        self.own_mask_portable(r, frame, receiver, scratch)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn own_mask_avx2<'a>(&'a self, r: usize, frame: &Frame, receiver: &Receiver, scratch: &mut Scratch<'a>) -> (Mask, u64) {
        self.own_mask_portable(r, frame, receiver, scratch)
    }

    /// Down the group tree (`group_tree.rs`), nodes below the horizon skipped and distant
    /// ones drawn through their proxies; per group reached: the coarse triangles of the
    /// clusters seen from afar, then the fine packets of the clusters seen at full resolution
    /// (the receiver's ring and clusters close to it), each packet skipped when its box is
    /// below the horizon. With potentially visible sets, also skipped: every node that holds
    /// no unit the receiver keeps (`pvs.rs`), unless a node above it is kept whole.
    #[inline(always)]
    fn own_mask_portable<'a>(&'a self, r: usize, frame: &Frame, receiver: &Receiver, scratch: &mut Scratch<'a>) -> (Mask, u64) {
        let (tree, table, origin) = (&self.group_tree, &*self.table, receiver.origin);
        let pvs = self.pvs.as_ref().filter(|_| frame.use_pvs);
        let Scratch { packets, stack, .. } = scratch;
        let mut drawing = Drawing::new(Viewer { origin, frame: &receiver.frame, exclude: r as u32 }, packets);
        let lod2 = self.far_lod2();
        stack.clear();
        if !tree.nodes.is_empty() {
            stack.push(0);
        }
        while let Some(entry) = stack.pop() {
            let (n, whole) = ((entry & !WHOLE) as usize, entry & WHOLE);
            let bounds = &frame.node_bounds[n];
            if self.culled(receiver, bounds) {
                continue;
            }
            let sets = pvs.filter(|_| whole == 0);
            if sets.is_some_and(|pvs| !self.keeps_below(pvs, r, n)) {
                continue;
            }
            match self.turn(n, bounds, origin, lod2) {
                Turn::Group(g) => self.group_blockers(g, r, sets, frame, receiver, &mut drawing),
                Turn::Proxy => {
                    for packet in tree.proxies.of(n) {
                        push_if(drawing.packets, (packet, u32::MAX), !self.packet_culled(receiver, packet));
                    }
                    drawing.end_source(table, Source::Proxy);
                }
                Turn::Open([first, second]) => {
                    let proxy_kept = sets.is_some_and(|pvs| pvs.keeps_any(r, pvs.node_unit(n)..pvs.node_unit(n + 1)));
                    let whole = if proxy_kept { WHOLE } else { whole };
                    stack.extend_from_slice(&[second | whole, first | whole]); // in group order
                }
            }
            // A full batch is drawn (in census builds, every source's packets at once, by
            // `end_source`); the walk stops once the drawn ones block every cell.
            if drawing.packets.len() >= Drawing::BATCH || cfg!(feature = "census") {
                drawing.draw(table);
                if drawing.mask == self.disk {
                    break;
                }
            }
        }
        drawing.finish(table)
    }

    /// Whether receiver `r` keeps a unit of node `n` or below it: its proxy, a node's below
    /// it, or one of its clusters.
    #[inline(always)]
    fn keeps_below(&self, pvs: &Pvs, r: usize, n: usize) -> bool {
        let node = self.group_tree.nodes[n];
        let clusters = node.clusters(self.hierarchy.clusters());
        pvs.keeps_any(r, pvs.node_unit(n)..pvs.node_unit(node.subtree_end as usize))
            || pvs.keeps_any(r, clusters.start as u32..clusters.end as u32)
    }

    /// How the walks down the group tree (`own_mask`, the sets' `contributing_units`, reuse's
    /// `same_walk`) meet node `n` with box `bounds` seen from `origin`: one rule for all three,
    /// since the sets and reuse are exact only while their walks take the solve's turns.
    #[inline(always)]
    fn turn(&self, n: usize, bounds: &[Vec3; 2], origin: Vec3, lod2: f32) -> Turn {
        let node = self.group_tree.nodes[n];
        if node.children == LEAF {
            Turn::Group(node.first as usize)
        } else if self.group_tree.is_far(n, bounds, origin, lod2) {
            Turn::Proxy
        } else {
            Turn::Open(node.children)
        }
    }

    /// Whether the walks skip a box: culling is on and the box is below the receiver's horizon.
    #[inline(always)]
    fn culled(&self, receiver: &Receiver, bounds: &[Vec3; 2]) -> bool {
        self.blockers.cull && receiver.below_horizon(bounds)
    }

    /// Whether the walks drop a packet by its box: culling is on and the box is clearly below
    /// the receiver's horizon. Without `&&`'s branch: the hand-over of packets is branch-free
    /// (`push_if`).
    #[inline(always)]
    fn packet_culled(&self, receiver: &Receiver, packet: &Packet) -> bool {
        self.blockers.cull & receiver.clearly_below_horizon(&packet.bounds)
    }

    /// The square of the group tree's `far_lod`; 0 (every group opened) without the
    /// hierarchy. One place for the walk, the potentially visible sets' walk and `same_walk`,
    /// whose reuse is only sound when they agree.
    #[inline(always)]
    fn far_lod2(&self) -> f32 {
        if !self.blockers.hierarchy { 0.0 } else { self.blockers.far_lod.powi(2) }
    }

    /// Group `g`'s blockers for receiver `r`: see `own_mask_portable`.
    /// `sets`: the potentially visible sets, when they choose the group's clusters.
    #[inline(always)]
    fn group_blockers<'a>(&'a self, g: usize, r: usize, sets: Option<&Pvs>, frame: &Frame, receiver: &Receiver, drawing: &mut Drawing<'_, '_, 'a>) {
        let (h, table) = (&self.hierarchy, &*self.table);
        let first = g * GROUP;
        let clusters = (first + GROUP).min(h.clusters()) - first;
        let seen = sets.map_or(u32::MAX, |pvs| bits_of(pvs.of(r), first, clusters));
        if seen == 0 || self.culled(receiver, &frame.group_bounds[g]) {
            return;
        }
        let (near, below) = frame.spheres[g].sides(receiver.origin, receiver.frame.n);
        let expanded = self.expanded_clusters(r, first, clusters, near);
        // With culling on, clusters wholly below the horizon are dropped before their packets
        // are handed over.
        let above = if self.blockers.cull { !below } else { u32::MAX };
        if self.blockers.hierarchy {
            let far = !expanded & seen & above;
            for (p, packet) in self.coarse_packets.of(g).iter().enumerate() {
                let lanes = far >> (p * LANES) & packet.lanes;
                push_if(drawing.packets, (packet, lanes), lanes != 0);
            }
            drawing.end_source(table, Source::Coarse);
        }
        let mut bits = expanded & seen & above;
        while bits != 0 {
            let c = first + bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let cluster_seen = !self.culled(receiver, &frame.bounds[c]);
            for packet in self.fine_packets.of(c) {
                push_if(drawing.packets, (packet, u32::MAX), cluster_seen & !self.packet_culled(receiver, packet));
            }
        }
        drawing.end_source(table, Source::Fine);
    }
}

/// Where a receiver's blockers are drawn: the packets its walk gathers, handed to the
/// rasterizer in batches of about `BATCH` (`Pipeline::rasterize_batch`), and the mask they
/// draw. Batches across groups rather than one call per group and source (each re-reading
/// the viewer and ending in a loop exit): the 8k Suzanne solved about 4 % faster.
struct Drawing<'v, 'p, 'a> {
    viewer: Viewer<'v>,
    pipeline: Pipeline,
    packets: &'p mut Vec<(&'a Packet, u32)>,
    mask: Mask,
    rasterized: u32,
}

impl<'v, 'p, 'a> Drawing<'v, 'p, 'a> {
    const BATCH: usize = 64;

    /// Gathers into `packets` (a thread's, reused from receiver to receiver).
    fn new(viewer: Viewer<'v>, packets: &'p mut Vec<(&'a Packet, u32)>) -> Self {
        packets.clear();
        Drawing { viewer, pipeline: Pipeline::default(), packets, mask: Mask::EMPTY, rasterized: 0 }
    }

    /// Rasterizes the gathered packets.
    #[inline(always)]
    fn draw(&mut self, table: &PlaneTable) {
        self.rasterized += self.pipeline.rasterize_batch(table, &self.viewer, self.packets, &mut self.mask);
        self.packets.clear();
    }

    /// The packets gathered since the last call came from `source`: the census draws them
    /// at once, to count them by source; other builds wait for a full batch.
    #[inline(always)]
    fn end_source(&mut self, _table: &PlaneTable, _source: Source) {
        #[cfg(feature = "census")]
        {
            crate::rasterizer::census::set_source(_source);
            self.draw(_table);
        }
    }

    /// The mask of everything gathered, and how many triangles were rasterized.
    #[inline(always)]
    fn finish(mut self, table: &PlaneTable) -> (Mask, u64) {
        self.draw(table);
        self.pipeline.drain(table, &mut self.mask);
        (self.mask, self.rasterized as u64)
    }
}

/// What a thread reuses from receiver to receiver, so that computing one allocates nothing.
#[derive(Default)]
struct Scratch<'a> {
    /// The corners of the casters' blockers (`Casters::occlude`).
    corners: Vec<Vec3>,
    /// The packets the walk gathers (`Drawing`) and its stack of nodes (`own_mask`).
    packets: Vec<(&'a Packet, u32)>,
    stack: Vec<u32>,
}

/// What computing (or reusing) one receiver left: the masks of its own and of the still
/// casters' blockers (for the next frame), and how many blockers it rasterized.
struct Step {
    base: Option<Kept>,
    count: u64,
}

/// Normalised positions rounded to a grid of 1/1024: the hierarchy is built from these, so that
/// the rounding of a scaled or moved copy of a mesh (a few ulps) almost never changes the
/// simplifier's choices, and results do not depend on the mesh's size. Loose vertices go to
/// the centre: the simplifier scales its metric by the bounds of every vertex it is given.
fn snapped(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut used = vec![false; positions.len()];
    triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
    let snap = |p: &Vec3| p.map(|c| (c * 1024.0).round() / 1024.0);
    positions.iter().zip(used).map(|(p, used)| if used { snap(p) } else { [0.0; 3] }).collect()
}

/// Per input vertex (welded as `remap` says), the position of its welded vertex in `order`.
fn output_rows(order: &[u32], remap: &[u32]) -> Vec<u32> {
    let mut row_of = vec![0u32; order.len()];
    for (row, &w) in order.iter().enumerate() {
        row_of[w as usize] = row as u32;
    }
    remap.iter().map(|&w| row_of[w as usize]).collect()
}

/// A walk's turn at a node of the group tree (`Solver::turn`): a leaf's group, a node drawn
/// through its proxy, or a node opened into its two children.
enum Turn {
    Group(usize),
    Proxy,
    Open([u32; 2]),
}

/// Marks a node of the walk's stack kept whole by the potentially visible sets: its proxy was
/// kept in a sampled pose where it was drawn from afar, so all below it is drawn here.
const WHOLE: u32 = 1 << 31;

/// Bits (relative to `first`) of the entries of the ascending `list` in `first..first + count`.
#[inline(always)]
fn bits_of(list: &[u32], first: usize, count: usize) -> u32 {
    let start = list.partition_point(|&c| (c as usize) < first);
    list[start..].iter().take_while(|&&c| (c as usize) < first + count).fold(0, |bits, &c| bits | 1 << (c as usize - first))
}

/// A group's clusters as spheres around their boxes (centre, half the diagonal), in
/// structure-of-arrays form: a receiver is tested against all sixteen in a few vector
/// instructions, where an array of spheres was tested one sphere at a time. Lanes past the
/// group's clusters never contain a receiver and never lie below a horizon.
#[derive(Clone, Copy)]
struct ClusterSpheres {
    centres: [[f32; GROUP]; 3],
    /// (near_scale x the radius)^2: the near test's (`sides`).
    near2: [f32; GROUP],
    /// The radius, rounded up.
    radii: [f32; GROUP],
}

impl ClusterSpheres {
    /// The spheres around `boxes` (at most `GROUP`).
    fn new(boxes: &[[Vec3; 2]], near_scale: f32) -> Self {
        let mut out = ClusterSpheres { centres: [[0.0; GROUP]; 3], near2: [-1.0; GROUP], radii: [f32::INFINITY; GROUP] };
        for (i, b) in boxes.iter().enumerate() {
            let centre = box_centre(b);
            (0..3).for_each(|a| out.centres[a][i] = centre[a]);
            let r2 = half_diagonal2(b);
            if r2.is_finite() {
                out.near2[i] = r2 * near_scale.powi(2);
                out.radii[i] = r2.sqrt() * 1.0001;
            }
        }
        out
    }

    /// Which clusters a receiver at `origin` with normal `n` lies within the near sphere of
    /// (the first bits), and which lie below its horizon by a margin far above rounding (the
    /// second): every corner of such a cluster's coarse and fine triangles has a negative
    /// height in the receiver's frame, so the rasterizer would draw none of them
    /// (`Receiver::clearly_below_horizon`, with the sphere). One loop for both, which share
    /// the offsets from the centres.
    #[inline(always)]
    fn sides(&self, origin: Vec3, n: Vec3) -> (u32, u32) {
        let (mut inside, mut below) = ([false; GROUP], [false; GROUP]);
        for i in 0..GROUP {
            let d = [0, 1, 2].map(|a| self.centres[a][i] - origin[a]);
            inside[i] = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < self.near2[i];
            below[i] = d[0] * n[0] + d[1] * n[1] + d[2] * n[2] + self.radii[i] < -HORIZON_MARGIN;
        }
        (bits16(&inside), bits16(&below))
    }
}

/// Appends `item` to `batch` only when `keep`, without a branch on `keep`: the item is always
/// written and the length then grows by `keep`. A fine packet's horizon test has no pattern a
/// CPU can learn; handed over this way instead of through a branch on it, the cloth solved
/// about 3 % faster (docs/solver_speed.md).
#[inline(always)]
fn push_if<T: Copy>(batch: &mut Vec<T>, item: T, keep: bool) {
    batch.push(item);
    batch.truncate(batch.len() - !keep as usize);
}

/// Bit i set when `flags[i]`: one SSE2 move-mask on x86-64 (part of its baseline), where LLVM
/// took the bits of its own move-mask apart again one by one.
#[inline(always)]
fn bits16(flags: &[bool; 16]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cmpgt_epi8, _mm_loadu_si128, _mm_movemask_epi8, _mm_setzero_si128};
        // SAFETY: SSE2 is part of every x86-64 CPU; the load reads the 16 bytes of `flags`.
        unsafe { _mm_movemask_epi8(_mm_cmpgt_epi8(_mm_loadu_si128(flags.as_ptr().cast()), _mm_setzero_si128())) as u32 }
    }
    #[cfg(not(target_arch = "x86_64"))]
    flags.iter().rev().fold(0, |bits, &b| bits << 1 | b as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits16_gathers_every_combination() {
        for bits in 0u32..1 << 16 {
            let flags: [bool; 16] = std::array::from_fn(|i| bits >> i & 1 == 1);
            assert_eq!(bits16(&flags), bits);
        }
    }

    #[test]
    fn push_if_keeps_only_the_kept_items_in_order() {
        let mut batch = Vec::new();
        for (i, keep) in [true, false, false, true, true, false].into_iter().enumerate() {
            push_if(&mut batch, i, keep);
        }
        assert_eq!(batch, [0, 3, 4]);
    }

    const Z: Vec3 = [0.0, 0.0, 1.0];

    #[test]
    fn cluster_spheres_hold_the_receivers_within_their_near_radius_only() {
        let boxes = [[[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[3.0, 0.0, 0.0], [7.0, 0.0, 0.0]], [[f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]]];
        let spheres = ClusterSpheres::new(&boxes, 1.0);
        assert_eq!(spheres.sides([0.5, 0.0, 0.0], Z).0, 0b001);
        assert_eq!(spheres.sides([4.0, 0.0, 0.0], Z).0, 0b010);
        assert_eq!(spheres.sides([100.0, 0.0, 0.0], Z).0, 0);
        // The lanes past the three clusters are centred at the origin and still hold nothing.
        assert_eq!(spheres.sides([0.0; 3], Z).0, 0b001);
        assert_eq!(ClusterSpheres::new(&boxes, 2.0).sides([-1.5, 0.0, 0.0], Z).0, 0b001);
    }

    #[test]
    fn clusters_lie_clearly_below_only_with_their_whole_sphere() {
        let boxes = [[[-1.0, -1.0, -3.0], [1.0, 1.0, -1.0]], [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]], [[0.0, 0.0, f32::NAN], [1.0, 1.0, -5.0]]];
        let spheres = ClusterSpheres::new(&boxes, 2.5);
        // Seen from above the first box (radius sqrt(3), centre 2 below): below only while the
        // whole sphere is, not just the box.
        assert_eq!(spheres.sides([0.0, 0.0, 0.0], Z).1, 0b001);
        assert_eq!(spheres.sides([0.0, 0.0, -0.5], Z).1, 0);
        assert_eq!(spheres.sides([0.0, 0.0, 10.0], Z).1, 0b011);
        assert_eq!(spheres.sides([0.0, 0.0, 10.0], [0.0, 0.0, -1.0]).1, 0);
    }
}
