//! Hemispherical rasterization of blocker triangles (Kautz et al. 2004, section 3.1.1).
//!
//! Seen from the receiver at the origin, a triangle (a, b, c) covers the cone of directions
//! alpha a + beta b + gamma c with non-negative weights: the directions on the inner side of the
//! three planes through the origin and an edge. Its mask is the AND of those three half-space
//! masks; triangles are OR-ed into the visibility mask in any order (occluder fusion, no depth).

use crate::disk_mask::Mask;
use crate::plane_table::PlaneTable;

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
const FLAT_CONE_SQUARED: f32 = 1e-12;

/// Whether any corner of a triangle (local coordinates) is above the receiver's horizon.
#[inline(always)]
pub fn above_horizon(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> bool {
    a[2] > 0.0 || b[2] > 0.0 || c[2] > 0.0
}

/// Mask of the cells covered by triangle (a, b, c) given relative to the receiver in its tangent
/// frame (+Z = normal). None when it covers nothing: entirely below the horizon, degenerate,
/// or touching the receiver.
#[inline(always)]
pub fn triangle_mask(table: &PlaneTable, a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Option<Mask> {
    if !above_horizon(a, b, c) {
        return None;
    }
    let (ab, bc, ca) = (cross(a, b), cross(b, c), cross(c, a));
    let det = dot(ab, c);
    if !(det * det > FLAT_CONE_SQUARED * (dot(a, a) * dot(b, b) * dot(c, c))) {
        return None; // also rejects NaN
    }
    // Orient the edge planes so that the opposite vertex is on their positive side.
    let (ab, bc, ca) = if det > 0.0 { (ab, bc, ca) } else { (negate(ab), negate(bc), negate(ca)) };
    Some(Mask::and3(table.lookup(ab), table.lookup(bc), table.lookup(ca)))
}

/// Blocker triangles queued in structure-of-arrays form, rasterized `LANES` at a time so that
/// the edge planes, the flat-cone test and the table indices of a batch are computed with
/// vector instructions (Embree-style SoA packets); only the table fetches stay scalar.
///
/// The fetches are what the kernel waits on (the 12 MiB table does not stay in cache), so
/// they are pipelined: a full batch computes its texels and prefetches their masks, then ORs
/// the previous batch's masks, which have arrived meanwhile. `finish` ORs what is left.
pub struct TriangleBatch {
    /// Corner k, component j, lane i: `corners[k][j][i]`.
    corners: [[[f32; LANES]; 3]; 3],
    len: usize,
    /// Texels (edge ab, bc, ca) of the previous batch's kept triangles, prefetched, not OR-ed.
    pending: [[u32; 3]; LANES],
    pending_len: usize,
}

pub const LANES: usize = 8;

impl Default for TriangleBatch {
    fn default() -> Self {
        TriangleBatch { corners: [[[0.0; LANES]; 3]; 3], len: 0, pending: [[0; 3]; LANES], pending_len: 0 }
    }
}

impl TriangleBatch {
    /// Queues a triangle (local coordinates, at least one corner above the horizon); full
    /// batches go through the pipeline into `mask`.
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

    /// Rasterizes everything queued into `mask` and empties the batch and the pipeline.
    #[inline(always)]
    pub fn finish(&mut self, table: &PlaneTable, mask: &mut Mask) {
        self.flush(table, mask);
        self.or_pending(table, mask);
    }

    /// Texels of the queued triangles are computed and prefetched, the previous batch is OR-ed
    /// into `mask`, and the queued ones become the pending batch.
    #[inline(always)]
    fn flush(&mut self, table: &PlaneTable, mask: &mut Mask) {
        let [a, b, c] = &self.corners;
        let mut planes = [[[0.0f32; LANES]; 3]; 3]; // edge ab, bc, ca; component; lane
        let mut keep = [false; LANES];
        for i in 0..LANES {
            let (pa, pb, pc) = ([a[0][i], a[1][i], a[2][i]], [b[0][i], b[1][i], b[2][i]], [c[0][i], c[1][i], c[2][i]]);
            let (ab, bc, ca) = (cross(pa, pb), cross(pb, pc), cross(pc, pa));
            let det = dot(ab, pc);
            let flip = if det < 0.0 { -1.0 } else { 1.0 };
            keep[i] = det * det > FLAT_CONE_SQUARED * (dot(pa, pa) * dot(pb, pb) * dot(pc, pc));
            for j in 0..3 {
                planes[0][j][i] = flip * ab[j];
                planes[1][j][i] = flip * bc[j];
                planes[2][j][i] = flip * ca[j];
            }
        }
        let mut texels = [[0u32; LANES]; 3];
        for e in 0..3 {
            table.texels(&planes[e][0], &planes[e][1], &planes[e][2], &mut texels[e]);
        }
        let mut next = [[0u32; 3]; LANES];
        let mut next_len = 0;
        for i in 0..self.len {
            if keep[i] {
                next[next_len] = [texels[0][i], texels[1][i], texels[2][i]];
                next[next_len].iter().for_each(|&t| table.prefetch(t));
                next_len += 1;
            }
        }
        self.or_pending(table, mask);
        self.pending = next;
        self.pending_len = next_len;
        self.len = 0;
    }

    #[inline(always)]
    fn or_pending(&mut self, table: &PlaneTable, mask: &mut Mask) {
        for [ab, bc, ca] in &self.pending[..self.pending_len] {
            mask.or_assign(&Mask::and3(table.mask_at(*ab), table.mask_at(*bc), table.mask_at(*ca)));
        }
        self.pending_len = 0;
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
    fn triangle_below_horizon_covers_nothing() {
        let t = table();
        assert!(triangle_mask(&t, [1.0, 0.0, -0.1], [0.0, 1.0, -0.2], [-1.0, -1.0, -0.3]).is_none());
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
