//! Closing the rasterizer's pinholes. Edge planes are rounded to the plane table's texels, so
//! around a vertex shared by several triangles the rounded planes need not meet in one point
//! and a sliver stays open (plane_table.rs); seen from a scene receiver, finely tessellated
//! floors and walls, and the seams where meshes meet, show such slivers as single open cells
//! inside blocked regions. An open cell whose four neighbours are blocked (at least
//! `neighbours` of them) is one of those: a real gap one cell (about 3.6 degrees) wide and
//! closed on every side is rare, and a leak costs more than the gap it may close.

use crate::disk_mask::{Mask, MASK_SIDE};

/// `mask` with the open cells of `disk` that have at least `neighbours` (3 or 4) blocked
/// 4-neighbours set. Cells outside the disk count as open.
pub fn close(mask: &Mask, disk: &Mask, neighbours: u32) -> Mask {
    let mut out = *mask;
    let row = |r: usize| if r < MASK_SIDE { mask.row_bits(r) } else { 0 };
    for r in 0..MASK_SIDE {
        let open = disk.row_bits(r) & !mask.row_bits(r);
        if open == 0 {
            continue;
        }
        let here = mask.row_bits(r);
        let (up, down, left, right) = (row(r.wrapping_sub(1)), row(r + 1), here << 1, here >> 1);
        // Bit-sliced count of the four neighbour bits per column: at least 3 is (two pairs
        // both set) or (one pair set and one of the other pair).
        let (a, b) = (up & down, up ^ down);
        let (c, d) = (left & right, left ^ right);
        let at_least = match neighbours {
            4 => a & c,
            _ => (a & c) | (a & d) | (b & c),
        };
        let fill = open & at_least;
        if fill != 0 {
            for col in 0..MASK_SIDE {
                if fill >> col & 1 != 0 {
                    out.set(r, col);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::disk_mask::disk;

    #[test]
    fn single_holes_close_and_edges_stay() {
        let full = disk();
        let mut m = full;
        // open a pinhole at (10, 10), a two-cell crack at (20, 8..10) and the right half of row 16
        for (r, c) in [(10, 10), (20, 8), (20, 9)] {
            m.0[(r * MASK_SIDE + c) / 64] &= !(1u64 << ((r * MASK_SIDE + c) % 64));
        }
        let mut half = Mask::EMPTY;
        for r in 0..MASK_SIDE {
            for c in 0..16 {
                if full.get(r, c) {
                    half.set(r, c);
                }
            }
        }
        let closed = close(&m, &full, 3);
        assert!(closed.get(10, 10) && closed.get(20, 8) && closed.get(20, 9));
        assert!(!close(&m, &full, 4).get(20, 8), "a two-cell crack has three blocked neighbours per cell");
        assert!(close(&m, &full, 4).get(10, 10));
        assert_eq!(close(&half, &full, 3), half, "a straight edge has no open cell with 3 blocked neighbours");
    }
}
