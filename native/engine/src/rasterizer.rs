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
