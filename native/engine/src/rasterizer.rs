//! Hemispherical rasterization of blocker triangles (Kautz et al. 2004, section 3.1.1).
//!
//! Seen from the receiver at the origin, a triangle (a, b, c) covers the cone of directions
//! alpha a + beta b + gamma c with non-negative weights: the directions on the inner side of the
//! three planes through the origin and an edge. Its mask is the AND of those three half-space
//! masks; triangles are OR-ed into the visibility mask in any order (occluder fusion, no depth).

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;

use crate::disk_mask::Mask;
use crate::integrate::Frame;
use crate::packets::{Packet, LANES};
use crate::plane_table::{Fetches, PlaneTable};

#[inline(always)]
pub fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline(always)]
pub fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
fn negate(a: [f32; 3]) -> [f32; 3] {
    [-a[0], -a[1], -a[2]]
}

/// Below this |det| / (|a| |b| |c|) the receiver lies (almost) in the triangle's plane: the
/// cone has no solid angle, and its edge planes would be numerical noise. Compared squared.
pub(crate) const FLAT_CONE_SQUARED: f32 = 1e-12;

/// Height (z of a unit direction in the receiver's frame) under every cell's sample: the
/// lowest samples, rim cells' centroids, lie at z = 0.0860 (`disk_mask`; a test keeps this
/// within 1 % below). A triangle whose directions all stay under it blocks no cell, whatever
/// bits the table's rounded planes would set there; on the 8k Suzanne one drawn triangle in
/// six lies there, thin triangles just above the horizon.
pub(crate) const LOW_BAND_Z: f32 = 0.0855;

/// Whether any corner of a triangle (local coordinates) is above the receiver's horizon.
#[inline(always)]
pub fn above_horizon(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> bool {
    a[2] > 0.0 || b[2] > 0.0 || c[2] > 0.0
}

/// Whether every direction of triangle (a, b, c) stays under `LOW_BAND_Z`. Each is the
/// direction of a point q of the flat triangle: q's height is at most the highest corner's,
/// and for s = a + b + c, |q| >= q . s / |s| >= min_k (p_k . s) / |s|. So q_z / |q| <
/// LOW_BAND_Z whenever top / near < LOW_BAND_Z / |s|, compared squared (no roots; false for
/// NaN and infinite corners). The same operations in the same order as the AVX2 packets'.
#[inline(always)]
pub fn below_low_band(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> bool {
    let s = [a[0] + b[0] + c[0], a[1] + b[1] + c[1], a[2] + b[2] + c[2]];
    let near = dot(a, s).min(dot(b, s)).min(dot(c, s));
    let top = a[2].max(b[2]).max(c[2]);
    near > 0.0 && top * top * dot(s, s) < LOW_BAND_Z * LOW_BAND_Z * (near * near)
}

/// Whether a triangle (local coordinates) may block a cell: a corner above the horizon and
/// not wholly under the lowest samples.
#[inline(always)]
pub fn may_block(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> bool {
    above_horizon(a, b, c) && !below_low_band(a, b, c)
}

/// Bit i set when lane i of `corners` may block a cell: `may_block` for every lane,
/// branch-free (`lane_above_horizon`, `below_low_band`).
#[inline(always)]
pub fn lanes_that_may_block(corners: &LocalCorners) -> u32 {
    lane_bits(&std::array::from_fn(|i| lane_may_block(corners, i)))
}

#[inline(always)]
fn lane_may_block(corners: &LocalCorners, i: usize) -> bool {
    let corner = |k: usize| [corners[k][0][i], corners[k][1][i], corners[k][2][i]];
    lane_above_horizon(corners, i) & !below_low_band(corner(0), corner(1), corner(2))
}

/// Whether lane i of `corners` has a corner above the horizon, by the highest corner (a max
/// compiles to one vector instruction where three compares and two ORs did not; a NaN corner
/// is skipped by `max`, as by the compares).
#[inline(always)]
fn lane_above_horizon(corners: &LocalCorners, i: usize) -> bool {
    corners[0][2][i].max(corners[1][2][i]).max(corners[2][2][i]) > 0.0
}

/// Mask of the cells covered by triangle (a, b, c) given relative to the receiver in its tangent
/// frame (+Z = normal). None when it covers nothing: entirely below the horizon, degenerate,
/// or touching the receiver.
#[inline(always)]
pub fn triangle_mask(table: &PlaneTable, a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Option<Mask> {
    let [ab, bc, ca] = triangle_texels(table, a, b, c)?;
    Some(Mask::and3(&table.mask_at(ab), &table.mask_at(bc), &table.mask_at(ca)))
}

/// The table texels of the three edge planes whose masks `triangle_mask` ANDs (None when it
/// covers nothing), for callers that prefetch them before use.
#[inline(always)]
pub fn triangle_texels(table: &PlaneTable, a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Option<[u32; 3]> {
    if !may_block(a, b, c) {
        return None;
    }
    let (ab, bc, ca) = (cross(a, b), cross(b, c), cross(c, a));
    let det = dot(ab, c);
    if !(det * det > FLAT_CONE_SQUARED * (dot(a, a) * dot(b, b) * dot(c, c))) {
        return None; // also rejects NaN
    }
    // Orient the edge planes so that the opposite vertex is on their positive side.
    let (ab, bc, ca) = if det > 0.0 { (ab, bc, ca) } else { (negate(ab), negate(bc), negate(ca)) };
    Some([table.texel(ab), table.texel(bc), table.texel(ca)])
}

/// Corners of `LANES` triangles relative to a receiver, in its tangent frame: corner k,
/// axis j, lane i is `[k][j][i]`.
pub type LocalCorners = [[[f32; LANES]; 3]; 3];

/// Table codes (`PlaneTable::code`; edge ab, bc, ca) of every lane's three edge planes, and
/// the bit set of lanes whose cone has a solid angle. In AVX2 registers where the CPU has
/// them (`avx2`, the same codes bit for bit).
#[inline(always)]
pub fn edge_codes(table: &PlaneTable, corners: &LocalCorners, codes: &mut [[u32; LANES]; 3]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2.
        return unsafe { avx2::edge_codes(table, corners, codes) };
    }
    edge_codes_portable(table, corners, codes)
}

/// `edge_codes` in portable lane loops, written branch-free so that they vectorise.
#[inline(always)]
fn edge_codes_portable(table: &PlaneTable, corners: &LocalCorners, codes: &mut [[u32; LANES]; 3]) -> u32 {
    let [a, b, c] = corners;
    let mut planes = [[[0.0f32; LANES]; 3]; 3]; // edge ab, bc, ca; component; lane
    let mut solid = [false; LANES];
    for i in 0..LANES {
        let (pa, pb, pc) = ([a[0][i], a[1][i], a[2][i]], [b[0][i], b[1][i], b[2][i]], [c[0][i], c[1][i], c[2][i]]);
        let (ab, bc, ca) = (cross(pa, pb), cross(pb, pc), cross(pc, pa));
        let det = dot(ab, pc);
        // Orient the edge planes so that the opposite vertex is on their positive side.
        let flip = if det < 0.0 { -1.0 } else { 1.0 };
        solid[i] = det * det > FLAT_CONE_SQUARED * (dot(pa, pa) * dot(pb, pb) * dot(pc, pc)); // false for NaN
        for j in 0..3 {
            planes[0][j][i] = flip * ab[j];
            planes[1][j][i] = flip * bc[j];
            planes[2][j][i] = flip * ca[j];
        }
    }
    for e in 0..3 {
        table.codes(&planes[e][0], &planes[e][1], &planes[e][2], &mut codes[e]);
    }
    lane_bits(&solid)
}

/// Bit i set when lane i is. The eight bools read as one little-endian word have bit 0 of
/// byte i at bit 8i; multiplying by 0x0102040810204080 moves it to bit 56 + i (the partial
/// products that reach the top byte are exactly these, and none carry into it), so the top
/// byte is the lanes' bits: a move-mask without intrinsics, where folding the bools one by one
/// compiled to a chain of scalar shifts.
#[inline(always)]
fn lane_bits(lanes: &[bool; LANES]) -> u32 {
    const _: () = assert!(LANES == 8, "lane_bits gathers eight bytes");
    let bytes = lanes.map(|on| on as u8);
    (u64::from_le_bytes(bytes).wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32
}

/// ORs triangles into a mask with the table fetches pipelined: the masks of one packet are
/// prefetched when its texels are known and OR-ed only when the next packet's texels are (or
/// at `drain`), by which time they have arrived. On an AMD EPYC the fetches were what the
/// kernel waited on; on a Xeon with 2 MiB of L2 per core, the instructions of the drain are
/// (docs/solver_speed.md). The AVX-512 kernel pipelines its own fetches, without prefetches.
#[derive(Default)]
pub struct Pipeline {
    /// Where the masks of the packets' edge codes lie: the previous packet's, prefetched and
    /// not yet OR-ed, in `fetches[pending]`; the next packet's are written into the other,
    /// so that neither is copied.
    fetches: [Fetches; 2],
    pending: usize,
    /// The previous packet's kept lanes.
    pending_lanes: u32,
    /// Every mask drawn so far, OR-ed at once rather than a packet late (`census`).
    #[cfg(feature = "census")]
    seen: Mask,
}

impl Pipeline {
    /// Prefetches the masks of the `lanes` of `codes`, ORs the pending ones into `mask` and
    /// makes these pending.
    ///
    /// # Safety
    /// With `AVX2`, the CPU must support AVX2.
    #[inline(always)]
    unsafe fn advance<const AVX2: bool>(&mut self, table: &PlaneTable, codes: &[[u32; LANES]; 3], lanes: u32, mask: &mut Mask) {
        let next = 1 - self.pending;
        self.fetches[next] = table.fetches(codes);
        table.prefetch(&self.fetches[next], lanes);
        self.drain_pending::<AVX2>(table, mask);
        self.pending = next;
        self.pending_lanes = lanes;
    }

    /// ORs every pending triangle into `mask`.
    #[inline(always)]
    pub fn drain(&mut self, table: &PlaneTable, mask: &mut Mask) {
        // SAFETY: the portable drain dispatches at run time.
        unsafe { self.drain_pending::<false>(table, mask) }
    }

    /// `drain`, with `AVX2` straight into the AVX2 drain, which inlines into AVX2 kernels.
    ///
    /// # Safety
    /// With `AVX2`, the CPU must support AVX2.
    #[inline(always)]
    unsafe fn drain_pending<const AVX2: bool>(&mut self, table: &PlaneTable, mask: &mut Mask) {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            table.or_triangles_avx2_inlined(&self.fetches[self.pending], self.pending_lanes, mask);
            self.pending_lanes = 0;
            return;
        }
        table.or_triangles(&self.fetches[self.pending], self.pending_lanes, mask);
        self.pending_lanes = 0;
    }

    /// Rasterizes the lanes of `packet` set in `lanes` for a receiver at `origin` with tangent
    /// frame `frame`, except triangles with a corner `exclude` (the receiver's own vertex) and
    /// triangles that cannot block a cell (`may_block`: below the horizon or the samples). Returns how many were rasterized. Call `drain`
    /// before reading `mask`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn rasterize_packet(
        &mut self,
        table: &PlaneTable,
        origin: [f32; 3],
        frame: &Frame,
        packet: &Packet,
        lanes: u32,
        exclude: u32,
        mask: &mut Mask,
    ) -> u32 {
        // SAFETY: the portable kernel dispatches at run time.
        unsafe { self.rasterize_viewed::<false>(table, &Viewer { origin, frame, exclude }, packet, lanes, mask) }
    }

    /// `rasterize_packet` for every packet of `batch`, each with the lanes given beside it,
    /// seen from `viewer`. In one call, so that the AVX2 and AVX-512 kernels
    /// (`avx2::rasterize_batch`, `avx512::rasterize_batch`) run the batch with their packet
    /// arithmetic and drain inlined: a call per packet, each making the viewer's broadcasts
    /// again, cost about 5 % of the solver's instructions. The AVX-512 kernel draws the whole
    /// batch into `mask`; the others may leave their last packet pending until `drain`.
    #[inline(always)]
    pub(crate) fn rasterize_batch(&mut self, table: &PlaneTable, viewer: &Viewer, batch: &[(&Packet, u32)], mask: &mut Mask) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // The census counts packet by packet, in `rasterize_viewed`.
            if !cfg!(feature = "census") && avx512_kernel() {
                // SAFETY: the CPU supports the AVX-512 subsets the kernel is compiled for.
                return unsafe { avx512::rasterize_batch(table, viewer, batch, mask) };
            }
            // SAFETY: the CPU supports AVX2.
            return unsafe { avx2::rasterize_batch(self, table, viewer, batch, mask) };
        }
        // SAFETY: the portable kernel dispatches at run time.
        batch.iter().map(|&(packet, lanes)| unsafe { self.rasterize_viewed::<false>(table, viewer, packet, lanes, mask) }).sum()
    }

    /// `rasterize_packet` seen from `viewer`; with `AVX2`, through the AVX2 kernels directly.
    ///
    /// # Safety
    /// With `AVX2`, the CPU must support AVX2.
    #[inline(always)]
    unsafe fn rasterize_viewed<const AVX2: bool>(&mut self, table: &PlaneTable, viewer: &Viewer, packet: &Packet, lanes: u32, mask: &mut Mask) -> u32 {
        let mut codes = [[0u32; LANES]; 3];
        let lanes = lanes & packet.lanes;
        #[cfg(target_arch = "x86_64")]
        let (candidates, solid) =
            if AVX2 { avx2::packet_codes_inlined(table, viewer, packet, lanes, &mut codes) } else { packet_codes(table, viewer, packet, lanes, &mut codes) };
        #[cfg(not(target_arch = "x86_64"))]
        let (candidates, solid) = packet_codes(table, viewer, packet, lanes, &mut codes);
        #[cfg(feature = "census")]
        census::packet(lanes, candidates);
        if candidates == 0 {
            return 0;
        }
        #[cfg(feature = "census")]
        census::count(table, &local_corners(viewer.origin, viewer.frame, packet), &codes, candidates & solid, &mut self.seen);
        self.advance::<AVX2>(table, &codes, candidates & solid, mask);
        candidates.count_ones()
    }
}

/// Whether `rasterize_batch` runs the AVX-512 kernel: where the CPU has AVX-512 F, VL, BW and
/// DQ, unless the environment variable `HEMISHADOW_NO_AVX512` is set (to time or rule out the
/// kernel; its masks are the AVX2 kernel's bit for bit).
#[cfg(target_arch = "x86_64")]
fn avx512_kernel() -> bool {
    static CHOICE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *CHOICE.get_or_init(|| std::env::var_os("HEMISHADOW_NO_AVX512").is_none() && has_avx512())
}

/// Whether the CPU has the AVX-512 subsets the AVX-512 kernel is compiled for.
#[cfg(target_arch = "x86_64")]
fn has_avx512() -> bool {
    std::is_x86_feature_detected!("avx512f")
        && std::is_x86_feature_detected!("avx512vl")
        && std::is_x86_feature_detected!("avx512bw")
        && std::is_x86_feature_detected!("avx512dq")
}

/// Where a packet is seen from: a receiver's origin and tangent frame, and its vertex, whose
/// own triangles are not drawn.
pub(crate) struct Viewer<'a> {
    pub origin: [f32; 3],
    pub frame: &'a Frame,
    pub exclude: u32,
}

/// For the `lanes` of `packet` seen from `viewer`: the bit set of those to draw (`may_block`,
/// no corner the viewer's own vertex) and, when there are any, the bit set
/// of those whose cone has a solid angle, with every lane's edge codes in `codes`
/// (`edge_codes`); `(0, 0)` and `codes` untouched when none is to be drawn. In AVX2 registers
/// where the CPU has them (`avx2`, the same results bit for bit).
#[inline(always)]
fn packet_codes(table: &PlaneTable, viewer: &Viewer, packet: &Packet, lanes: u32, codes: &mut [[u32; LANES]; 3]) -> (u32, u32) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2.
        return unsafe { avx2::packet_codes(table, viewer, packet, lanes, codes) };
    }
    packet_codes_portable(table, viewer, packet, lanes, codes)
}

/// `packet_codes` in portable lane loops.
#[inline(always)]
fn packet_codes_portable(table: &PlaneTable, viewer: &Viewer, packet: &Packet, lanes: u32, codes: &mut [[u32; LANES]; 3]) -> (u32, u32) {
    let (local, exclude) = (local_corners(viewer.origin, viewer.frame, packet), viewer.exclude);
    // May block a cell and not the receiver's own (one lane loop, one bit gather).
    let mut keep = [false; LANES];
    for (i, keep) in keep.iter_mut().enumerate() {
        let own = (packet.ids[0][i] == exclude) | (packet.ids[1][i] == exclude) | (packet.ids[2][i] == exclude);
        *keep = lane_may_block(&local, i) & !own;
    }
    let candidates = lane_bits(&keep) & lanes;
    if candidates == 0 {
        return (0, 0);
    }
    (candidates, edge_codes_portable(table, &local, codes))
}

/// The corners of `packet` relative to a receiver at `origin`, in its tangent frame.
#[inline(always)]
fn local_corners(origin: [f32; 3], frame: &Frame, packet: &Packet) -> LocalCorners {
    let mut local: LocalCorners = [[[0.0; LANES]; 3]; 3];
    for k in 0..3 {
        let [x, y, z] = &packet.corners[k];
        for i in 0..LANES {
            let d = [x[i] - origin[0], y[i] - origin[1], z[i] - origin[2]];
            local[k][0][i] = dot(d, frame.t);
            local[k][1][i] = dot(d, frame.b);
            local[k][2][i] = dot(d, frame.n);
        }
    }
    local
}

/// Where the solver's packets come from: a group tree node's proxy, a group's coarse
/// triangles, a cluster's fine triangles (the census counts packets by it).
#[derive(Clone, Copy)]
pub enum Source {
    Proxy,
    Coarse,
    Fine,
}

/// What the solver's triangles add to their receivers' masks (feature `census`, for profiling
/// only: it draws every mask twice). Counts by outcome (no cell, only cells already blocked,
/// new cells) and by the height of the highest corner's direction above the horizon
/// (z below 0.1, below 0.5, higher), and the packets the solver's walk hands over.
#[cfg(feature = "census")]
pub mod census {
    use std::sync::atomic::{AtomicU64, Ordering};

    use super::{LocalCorners, Mask, PlaneTable, Source, LANES};

    static COUNTS: [[AtomicU64; 3]; 3] = [const { [const { AtomicU64::new(0) }; 3] }; 3];

    /// `[outcome][height]` counts since the start (outcome: empty, hidden, adding).
    pub fn counts() -> [[u64; 3]; 3] {
        std::array::from_fn(|o| std::array::from_fn(|h| COUNTS[o][h].load(Ordering::Relaxed)))
    }

    pub const SOURCES: [&str; 3] = ["proxies", "coarse", "fine"];

    thread_local! {
        static SOURCE: std::cell::Cell<Source> = const { std::cell::Cell::new(Source::Fine) };
    }

    pub fn set_source(source: Source) {
        SOURCE.with(|s| s.set(source));
    }

    /// Per source, packets with lanes to draw, their lanes, the lanes drawn (may block a
    /// cell, not the receiver's own), and the packets with none drawn.
    static PACKETS: [[AtomicU64; 4]; 3] = [const { [const { AtomicU64::new(0) }; 4] }; 3];

    /// Per source (`SOURCES`), `[packets, lanes offered, lanes drawn, packets with none drawn]`
    /// since the start.
    pub fn packets() -> [[u64; 4]; 3] {
        std::array::from_fn(|k| std::array::from_fn(|i| PACKETS[k][i].load(Ordering::Relaxed)))
    }

    pub(super) fn packet(offered: u32, drawn: u32) {
        if offered != 0 {
            let counts = &PACKETS[SOURCE.with(|s| s.get()) as usize];
            counts[0].fetch_add(1, Ordering::Relaxed);
            counts[1].fetch_add(offered.count_ones() as u64, Ordering::Relaxed);
            counts[2].fetch_add(drawn.count_ones() as u64, Ordering::Relaxed);
            counts[3].fetch_add((drawn == 0) as u64, Ordering::Relaxed);
        }
    }

    pub(super) fn count(table: &PlaneTable, local: &LocalCorners, codes: &[[u32; LANES]; 3], lanes: u32, seen: &mut Mask) {
        let mut bits = lanes;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let covered = table.triangle_of_codes(codes.map(|edge| edge[i]));
            let outcome = if covered == Mask::EMPTY { 0 } else if covered.and_not(seen) == Mask::EMPTY { 1 } else { 2 };
            seen.or_assign(&covered);
            let corner = |k: usize| [local[k][0][i], local[k][1][i], local[k][2][i]];
            let height = (0..3)
                .map(|k| local[k][2][i] / super::dot(corner(k), corner(k)).sqrt())
                .fold(f32::NEG_INFINITY, f32::max);
            let band = if height < 0.1 { 0 } else if height < 0.5 { 1 } else { 2 };
            COUNTS[outcome][band].fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Triangles given one at a time (local coordinates, at least one corner above the horizon),
/// queued into a lane group and rasterized through the pipeline `LANES` at a time.
#[derive(Default)]
pub struct TriangleBatch {
    corners: LocalCorners,
    len: usize,
    pipeline: Pipeline,
}

impl TriangleBatch {
    /// Queues a triangle; full batches go through the pipeline into `mask`.
    #[inline(always)]
    pub fn push(&mut self, table: &PlaneTable, a: [f32; 3], b: [f32; 3], c: [f32; 3], mask: &mut Mask) {
        let i = self.len;
        for j in 0..3 {
            self.corners[0][j][i] = a[j];
            self.corners[1][j][i] = b[j];
            self.corners[2][j][i] = c[j];
        }
        self.len += 1;
        if self.len == LANES {
            self.flush(table, mask);
        }
    }

    /// Rasterizes the `lanes` of `corners` (a whole packet, local coordinates) into `mask`
    /// through the pipeline, beside any triangles queued one at a time.
    #[inline(always)]
    pub fn push_packet(&mut self, table: &PlaneTable, corners: &LocalCorners, lanes: u32, mask: &mut Mask) {
        let mut codes = [[0u32; LANES]; 3];
        let solid = edge_codes(table, corners, &mut codes);
        // SAFETY: the portable drain dispatches at run time.
        unsafe { self.pipeline.advance::<false>(table, &codes, solid & lanes, mask) };
    }

    /// Rasterizes everything queued into `mask` and empties the batch and the pipeline.
    #[inline(always)]
    pub fn finish(&mut self, table: &PlaneTable, mask: &mut Mask) {
        self.flush(table, mask);
        self.pipeline.drain(table, mask);
    }

    #[inline(always)]
    fn flush(&mut self, table: &PlaneTable, mask: &mut Mask) {
        let mut codes = [[0u32; LANES]; 3];
        let solid = edge_codes(table, &self.corners, &mut codes);
        let queued = (1u32 << self.len) - 1;
        // SAFETY: the portable drain dispatches at run time.
        unsafe { self.pipeline.advance::<false>(table, &codes, solid & queued, mask) };
        self.len = 0;
    }
}

/// ORs every triangle of `triangles` (local coordinates) into `mask`.
pub fn rasterize(table: &PlaneTable, triangles: &[[[f32; 3]; 3]], mask: &mut Mask) {
    for [a, b, c] in triangles {
        if let Some(covered) = triangle_mask(table, *a, *b, *c) {
            mask.or_assign(&covered);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::disk_mask::{cell_direction, disk, MASK_SIDE};

    fn table() -> std::sync::Arc<PlaneTable> {
        PlaneTable::shared(crate::plane_table::DEFAULT_RESOLUTION).unwrap()
    }

    #[test]
    fn lane_bits_gathers_every_combination() {
        for bits in 0u32..256 {
            let lanes: [bool; LANES] = std::array::from_fn(|i| bits >> i & 1 == 1);
            assert_eq!(lane_bits(&lanes), bits);
        }
    }

    #[test]
    fn triangle_below_horizon_covers_nothing() {
        let t = table();
        assert!(triangle_mask(&t, [1.0, 0.0, -0.1], [0.0, 1.0, -0.2], [-1.0, -1.0, -0.3]).is_none());
    }

    #[test]
    fn the_low_band_lies_just_under_the_lowest_sample() {
        let lowest = (0..MASK_SIDE * MASK_SIDE)
            .filter_map(|i| cell_direction(i / MASK_SIDE, i % MASK_SIDE))
            .map(|d| d[2])
            .fold(f32::INFINITY, f32::min);
        assert!(LOW_BAND_Z < lowest && LOW_BAND_Z > 0.99 * lowest, "lowest sample z {lowest}");
    }

    /// Random triangles near the horizon, at every distance and size: each one that
    /// `below_low_band` rejects contains no cell's sample direction (its cone, tested in f64),
    /// and the test rejects a fair share of those that contain none.
    #[test]
    fn triangles_under_the_low_band_contain_no_sample() {
        let samples: Vec<[f64; 3]> = (0..MASK_SIDE * MASK_SIDE)
            .filter_map(|i| cell_direction(i / MASK_SIDE, i % MASK_SIDE))
            .map(|d| d.map(f64::from))
            .collect();
        let mut state = 0x2545_f491u32;
        let mut unit = || crate::test_random::xorshift32(&mut state) as f32 / u32::MAX as f32;
        let (mut rejected, mut empty) = (0, 0);
        for _ in 0..20_000 {
            let (distance, size, azimuth) = (0.05 + 10.0 * unit(), 0.02 + 2.0 * unit(), std::f32::consts::TAU * unit());
            let centre = [distance * azimuth.cos(), distance * azimuth.sin(), distance * (0.12 * unit() - 0.02)];
            let mut corner = || [0, 1, 2].map(|j| centre[j] + size * (unit() - 0.5) * if j == 2 { 0.1 } else { 1.0 });
            let (a, b, c) = (corner(), corner(), corner());
            let [a64, b64, c64] = [a, b, c].map(|p| p.map(f64::from));
            let edges = [cross64(a64, b64), cross64(b64, c64), cross64(c64, a64)];
            let det = dot64(edges[0], c64);
            let inside = |d: &[f64; 3]| edges.iter().all(|e| dot64(*e, *d) * det >= 0.0);
            let holds_a_sample = samples.iter().any(inside);
            if below_low_band(a, b, c) {
                assert!(!holds_a_sample, "rejected {a:?} {b:?} {c:?} holds a sample");
                rejected += 1;
            }
            empty += usize::from(!holds_a_sample && above_horizon(a, b, c));
        }
        assert!(rejected * 4 > empty, "rejected {rejected} of {empty} above the horizon and empty");
    }

    fn cross64(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    }

    fn dot64(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    #[test]
    fn triangle_touching_receiver_covers_nothing() {
        let t = table();
        assert!(triangle_mask(&t, [0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]).is_none());
    }

    #[test]
    fn big_roof_covers_almost_the_whole_disk() {
        let t = table();
        let mut mask = Mask::EMPTY;
        let roof = [
            [[-100.0, -100.0, 1.0], [100.0, -100.0, 1.0], [100.0, 100.0, 1.0]],
            [[-100.0, -100.0, 1.0], [100.0, 100.0, 1.0], [-100.0, 100.0, 1.0]],
        ];
        rasterize(&t, &roof, &mut mask);
        let covered = mask.count() as f32 / disk().count() as f32;
        assert!(covered > 0.97, "{covered}");
    }

    #[test]
    fn winding_does_not_matter() {
        let t = table();
        let (a, b, c) = ([0.3, 0.1, 1.0], [-0.2, 0.4, 0.8], [0.1, -0.5, 0.6]);
        assert_eq!(triangle_mask(&t, a, b, c), triangle_mask(&t, a, c, b));
    }

    #[test]
    fn cells_are_inside_the_disk_only() {
        let t = table();
        let mask = triangle_mask(&t, [5.0, -5.0, 0.01], [5.0, 5.0, 0.01], [-5.0, 0.0, 3.0]).unwrap();
        for row in 0..MASK_SIDE {
            for col in 0..MASK_SIDE {
                if mask.get(row, col) {
                    assert!(cell_direction(row, col).is_some());
                }
            }
        }
    }
}
