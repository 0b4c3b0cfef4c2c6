//! One receiver's walk through the scene hierarchy: instances below its horizon are culled by
//! their world boxes (top tree), then inside each instance's mesh tree a node is culled when
//! its box lies below the horizon, drawn through its proxy when its bounding sphere subtends
//! less than `lod` (radius / distance) as seen from the receiver, or when the proxy's
//! simplification error subtends less than `lod` x ERROR_SHARE (seen from the node's centre
//! when the receiver is outside its sphere, or, for masks, from the nearest point of the slab
//! holding its triangles), and opened otherwise; leaves
//! that are still close are drawn at full resolution. The receiver never leaves world space
//! for the tests: each instance gets one 3x4 matrix from mesh space straight into the
//! receiver's tangent frame, so instances share their geometry and nothing is copied.

use crate::disk_mask::Mask;
use crate::mesh::Vec3;
use crate::packets::{Packet, LANES};
use crate::plane_table::PlaneTable;
use crate::rasterizer::{dot, lanes_that_may_block, may_block, LocalCorners, TriangleBatch};
use crate::transfer::Receiver;

use super::affine::Affine;
use super::clusters::{Compact, MeshTree, NO_CHILD};
use super::top::TopTree;

/// A node the receiver is outside of is also drawn through its proxy, however large it looks,
/// when the proxy's error subtends less than this share of `lod` (flat floors, walls and
/// gentle terrain near the receiver cost a few proxy triangles instead of every triangle).
/// 0.4 x 0.15 is 0.06 radian, about one cell of the mask: a finer proxy changes only cells it
/// cannot resolve, and its small, distant triangles cover cells spuriously (plane_table.rs).
/// Measured on bench/scene.py's 100k scenes (PUSH 0.25): crowd 2.0 % median error and 6,600
/// blockers per receiver at 0.1, 2.0 % and 1,400 at 0.4, 3.6 % and 480 at 0.8; terrain 1.6 %
/// and 9,000, 1.7 % and 1,300, 3.2 % and 440.
pub const ERROR_SHARE: f32 = 0.4;

/// What a blocker triangle carries besides its corners.
#[derive(Clone, Copy, Debug)]
pub struct Tag {
    pub mesh: u32,
    pub instance: u32,
    /// -1 for an instance with a negative determinant: its winding is turned over.
    pub facing: f32,
}

/// Receives the blocker triangles of one receiver, in its tangent frame, corners above the
/// horizon only. `ids` are the corners' mesh vertex ids.
pub trait Sink {
    fn triangle(&mut self, a: Vec3, b: Vec3, c: Vec3, ids: [u32; 3], tag: Tag);
    /// Sinks that need neither vertex ids nor tags set this and take whole packets instead
    /// of single triangles (`packet`): the walk then reads the trees' `TreePackets`.
    const PACKETS: bool = false;
    /// The `lanes` of a packet (corners in the receiver's frame, each lane with a corner
    /// above the horizon) of an instance with `facing` (as `Tag::facing`). Called only when
    /// `PACKETS` is set.
    fn packet(&mut self, _corners: &LocalCorners, _lanes: u32, _facing: f32) {
        unreachable!("Sink::packet called on a sink without PACKETS")
    }
    /// True when nothing more can change the result (stops the walk early).
    fn done(&self) -> bool {
        false
    }
    /// Completes what the sink has queued; the walk calls it before it returns.
    fn flush(&mut self) {}
}

/// The parts of a prepared scene a walk reads.
pub struct Walk<'a> {
    pub trees: &'a [&'a MeshTree],
    pub positions: &'a [&'a [Vec3]],
    pub instances: &'a [(u32, Affine)],
    pub top: &'a TopTree,
    pub lod: f32,
    /// Instances left out (ascending ids): a solver's own object, which it shadows itself.
    pub exclude: &'a [u32],
    /// Also draw a node through its proxy when its error is small from the nearest point of
    /// its slab (see `instance`). For masks only: a proxy's few vertices would blur radiance.
    pub near_proxies: bool,
    /// The walk gathers radiance: a node is drawn through its proxy only when it is small
    /// in angle (`lod`), never for its small error alone. A proxy shows the radiance of its
    /// few vertices: a flat wall's proxy, exact in shape, showed only its corners' light, and
    /// the test room's floor took 18 % too little bounce light from a sun patch.
    pub radiance: bool,
}

/// A mesh-space to receiver-space map: rows of (frame x linear), and the translation.
struct Local {
    rows: [Vec3; 3],
    shift: Vec3,
    /// The receiver in mesh space, and the square of the instance's `shrink`.
    at: Vec3,
    shrink2: f32,
}

impl Local {
    fn new(receiver: &Receiver, t: &Affine) -> Local {
        let f = [receiver.frame.t, receiver.frame.b, receiver.frame.n];
        let l = &t.linear;
        let rows = f.map(|fr| [0, 1, 2].map(|c| fr[0] * l[0][c] + fr[1] * l[1][c] + fr[2] * l[2][c]));
        let d = crate::mesh::sub(t.translation, receiver.origin);
        Local { rows, shift: f.map(|fr| dot(fr, d)), at: t.unapply(receiver.origin), shrink2: t.shrink * t.shrink }
    }

    #[inline(always)]
    fn apply(&self, p: Vec3) -> Vec3 {
        [0, 1, 2].map(|r| dot(self.rows[r], p) + self.shift[r])
    }

    /// `apply` to every corner of a packet, lane by lane: the same products in the same order,
    /// so packets and single triangles give the same corners bit for bit.
    #[inline(always)]
    fn apply_packet(&self, packet: &Packet) -> LocalCorners {
        let mut corners: LocalCorners = [[[0.0; LANES]; 3]; 3];
        for (k, corner) in packet.corners.iter().enumerate() {
            for (r, row) in self.rows.iter().enumerate() {
                for i in 0..LANES {
                    corners[k][r][i] = row[0] * corner[0][i] + row[1] * corner[1][i] + row[2] * corner[2][i] + self.shift[r];
                }
            }
        }
        corners
    }

    /// A lower bound of the squared distance from the receiver to anything in a node's slab.
    #[inline(always)]
    fn slab_distance2(&self, slab: &[f32; 5]) -> f32 {
        let gap = (dot([slab[0], slab[1], slab[2]], self.at) - slab[3]).abs() - slab[4];
        gap.max(0.0).powi(2) * self.shrink2
    }

    /// Whether a mesh-space box lies on or below the receiver's horizon.
    #[inline(always)]
    fn below(&self, b: &[Vec3; 2]) -> bool {
        let z = self.rows[2];
        let top: f32 = (0..3).map(|c| (z[c] * b[0][c]).max(z[c] * b[1][c])).sum();
        top + self.shift[2] <= 0.0
    }
}

/// Whether a world box lies on or below the receiver's tangent plane.
#[inline(always)]
pub fn below_horizon(receiver: &Receiver, b: &[Vec3; 2]) -> bool {
    let n = receiver.frame.n;
    let top = [0, 1, 2].map(|a| if n[a] >= 0.0 { b[1][a] } else { b[0][a] });
    dot(n, top) <= dot(n, receiver.origin)
}

impl Walk<'_> {
    /// Feeds `sink` every blocker of `receiver`; `scratch` holds transformed vertices. The
    /// walk with its transforms and the rasterizer's batches is compiled twice, for AVX2 +
    /// FMA and for the baseline, and picked at run time, as the solver's own kernel is (about
    /// 6 % faster on the demo cloth's casters; their blockers still cost about 1.5x one of the
    /// solver's own, which come from prepacked packets).
    pub fn run<S: Sink>(&self, receiver: &Receiver, scratch: &mut Vec<Vec3>, sink: &mut S) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { self.run_avx2(receiver, scratch, sink) };
        }
        self.run_portable(receiver, scratch, sink)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_avx2<S: Sink>(&self, receiver: &Receiver, scratch: &mut Vec<Vec3>, sink: &mut S) {
        self.run_portable(receiver, scratch, sink)
    }

    #[inline(always)]
    fn run_portable<S: Sink>(&self, receiver: &Receiver, scratch: &mut Vec<Vec3>, sink: &mut S) {
        self.walk(receiver, scratch, sink);
        sink.flush();
    }

    #[inline(always)]
    fn walk<S: Sink>(&self, receiver: &Receiver, scratch: &mut Vec<Vec3>, sink: &mut S) {
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        if self.top.nodes.is_empty() {
            return;
        }
        stack.push(0);
        while let Some(n) = stack.pop() {
            if below_horizon(receiver, &self.top.bounds[n as usize]) {
                continue;
            }
            let node = self.top.nodes[n as usize];
            if node.children[0] != NO_CHILD {
                stack.extend_from_slice(&node.children);
                continue;
            }
            if self.exclude.binary_search(&node.instance).is_ok() {
                continue;
            }
            self.instance(receiver, node.instance as usize, scratch, sink);
            if sink.done() {
                return;
            }
        }
    }

    #[inline(always)]
    fn instance<S: Sink>(&self, receiver: &Receiver, i: usize, scratch: &mut Vec<Vec3>, sink: &mut S) {
        let (mesh, transform) = self.instances[i];
        let (tree, positions) = (self.trees[mesh as usize], self.positions[mesh as usize]);
        let local = Local::new(receiver, &transform);
        let tag = Tag { mesh, instance: i as u32, facing: transform.facing };
        let lod2 = self.lod * self.lod;
        let error2 = (self.lod * ERROR_SHARE).powi(2);
        let stretch2 = transform.stretch * transform.stretch;
        if local.below(&tree.bounds[0]) {
            return;
        }
        // A distant object whose coarsest good-enough stand-in is coarser than the root's proxy.
        let s = tree.spheres[0];
        let q = local.apply([s[0], s[1], s[2]]);
        let d2 = dot(q, q);
        if s[3] * s[3] * stretch2 < d2 {
            let small_enough = !self.radiance || s[3] * s[3] * stretch2 < lod2 * d2;
            let coarse = (0..tree.coarse.len()).rev().find(|&k| small_enough && tree.coarse_error[k].powi(2) * stretch2 < error2 * d2);
            if let Some(k) = coarse {
                if S::PACKETS {
                    emit_packets(&local, tree.packets.coarse.of(k), tag.facing, sink);
                } else {
                    let pushed = &tree.coarse_positions[k];
                    emit(&local, |v| pushed[v], &tree.coarse[k], tag, scratch, sink);
                }
                return;
            }
        }
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(n) = stack.pop() {
            let n = n as usize;
            if local.below(&tree.bounds[n]) {
                continue;
            }
            let s = tree.spheres[n];
            let q = local.apply([s[0], s[1], s[2]]);
            let (d2, r2) = (dot(q, q), s[3] * s[3] * stretch2);
            let e = tree.proxy_error[n];
            // Near or inside the sphere, the slab's nearest point bounds the distance: flat
            // parts (a floor under a cloth) stay proxies however close the receiver is.
            let small = !self.radiance && e * e * stretch2 < error2 * d2;
            let far = (r2 < d2 && (r2 < lod2 * d2 || small))
                || (self.near_proxies && small && e * e * stretch2 < error2 * local.slab_distance2(&tree.slabs[n]));
            let node = tree.nodes[n];
            let leaf = node.children[0] == NO_CHILD;
            if far && S::PACKETS {
                emit_packets(&local, tree.packets.proxies.of(n), tag.facing, sink);
            } else if far {
                let pushed = &tree.proxy_positions[n];
                emit(&local, |k| pushed[k], &tree.proxies[n], tag, scratch, sink);
            } else if leaf && S::PACKETS {
                emit_packets(&local, tree.packets.leaves.of(node.leaf as usize), tag.facing, sink);
            } else if leaf {
                let compact = &tree.leaves[node.leaf as usize];
                emit(&local, |k| positions[compact.vertices[k] as usize], compact, tag, scratch, sink);
            }
            if far || leaf {
                if sink.done() {
                    return;
                }
            } else {
                stack.extend_from_slice(&node.children);
            }
        }
    }
}

#[inline(always)]
fn emit<S: Sink>(local: &Local, position: impl Fn(usize) -> Vec3, compact: &Compact, tag: Tag, scratch: &mut Vec<Vec3>, sink: &mut S) {
    // A plain loop rather than `extend`, which is not inlined into the AVX2 copy of the walk.
    let count = compact.vertices.len();
    if scratch.len() < count {
        scratch.resize(count, [0.0; 3]);
    }
    for (k, out) in scratch[..count].iter_mut().enumerate() {
        *out = local.apply(position(k));
    }
    for (t, tri) in compact.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|k| scratch[k as usize]);
        if may_block(a, b, c) {
            sink.triangle(a, b, c, compact.shown(t), tag);
        }
    }
}

/// The packets' triangles that may block a cell (`may_block`), in the receiver's frame, to a
/// sink that takes packets; packets whose box lies below the horizon are skipped whole.
#[inline(always)]
fn emit_packets<S: Sink>(local: &Local, packets: &[Packet], facing: f32, sink: &mut S) {
    for packet in packets {
        if local.below(&packet.bounds) {
            continue;
        }
        let corners = local.apply_packet(packet);
        let lanes = lanes_that_may_block(&corners) & packet.lanes;
        if lanes != 0 {
            sink.packet(&corners, lanes, facing);
        }
    }
}

/// Open cells with this many blocked neighbours are closed (`pinholes`). Measured on
/// bench/scene.py's 100k scenes and tests/test_scene.py's room (median error of transfer): 4
/// lowers the room's 3.8 % to 3.3 % and the open-air receivers' 3.0 % to 2.7 %, the rest
/// unchanged within 0.15 points; 3 closes real gaps too (crowd 3.1 % -> 3.9 %).
pub const PINHOLE_NEIGHBOURS: u32 = 4;

/// The plain visibility mask (occluder fusion, any order), through the rasterizer's batches.
pub struct MaskSink<'a> {
    table: &'a PlaneTable,
    batch: TriangleBatch,
    pub mask: Mask,
    /// The walk stops once `mask` and `known` cover this.
    full: Mask,
    known: Mask,
    pub triangles: u64,
}

impl<'a> MaskSink<'a> {
    pub fn new(table: &'a PlaneTable, full: Mask) -> Self {
        Self::knowing(table, full, Mask::EMPTY)
    }

    /// A sink whose walk also stops once `mask` covers what `known` (cells the caller has
    /// blocked already) leaves open: what more it would draw falls inside `known`.
    pub fn knowing(table: &'a PlaneTable, full: Mask, known: Mask) -> Self {
        MaskSink { table, batch: TriangleBatch::default(), mask: Mask::EMPTY, full, known, triangles: 0 }
    }

    pub fn finish(self) -> (Mask, u64) {
        let full = self.full;
        let (mask, triangles) = self.finish_raw();
        (super::pinholes::close(&mask, &full, PINHOLE_NEIGHBOURS), triangles)
    }

    /// The mask without closing pinholes (for callers that add more blockers first).
    pub fn finish_raw(mut self) -> (Mask, u64) {
        self.batch.finish(self.table, &mut self.mask);
        (self.mask, self.triangles)
    }
}

impl Sink for MaskSink<'_> {
    #[inline(always)]
    fn triangle(&mut self, a: Vec3, b: Vec3, c: Vec3, _: [u32; 3], _: Tag) {
        self.batch.push(self.table, a, b, c, &mut self.mask);
        self.triangles += 1;
    }

    const PACKETS: bool = true;

    #[inline(always)]
    fn packet(&mut self, corners: &LocalCorners, lanes: u32, _facing: f32) {
        self.batch.push_packet(self.table, corners, lanes, &mut self.mask);
        self.triangles += lanes.count_ones() as u64;
    }

    fn done(&self) -> bool {
        let mut covered = self.mask;
        covered.or_assign(&self.known);
        covered == self.full
    }
}
