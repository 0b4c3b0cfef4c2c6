//! The 32x32 one-bit visibility mask over the unit disk (Kautz et al. 2004, section 3.1).
//!
//! The hemisphere around a receiver's normal (+Z of its tangent frame) is projected onto the
//! unit disk by dropping z (Nusselt analog), so every in-disk cell carries the same
//! cosine-weighted solid angle. Cell (row, col) covers x in [-1 + col/16, -1 + (col+1)/16] and
//! y likewise with row; it belongs to the disk when its centre does. Bit `row * 32 + col` of the
//! mask is set when the direction through the cell centre is blocked.

pub const MASK_SIDE: usize = 32;
pub const MASK_CELLS: usize = MASK_SIDE * MASK_SIDE;
pub const MASK_WORDS: usize = MASK_CELLS / 64;

/// 1024 bits, two mask rows per 64-bit word; aligned for 256-bit loads.
#[derive(Clone, Copy, PartialEq, Eq, Default, Debug)]
#[repr(C, align(32))]
pub struct Mask(pub [u64; MASK_WORDS]);

impl Mask {
    pub const EMPTY: Mask = Mask([0; MASK_WORDS]);

    #[inline(always)]
    pub fn and3(a: &Mask, b: &Mask, c: &Mask) -> Mask {
        let mut out = Mask::EMPTY;
        for i in 0..MASK_WORDS {
            out.0[i] = a.0[i] & b.0[i] & c.0[i];
        }
        out
    }

    #[inline(always)]
    pub fn or_assign(&mut self, other: &Mask) {
        for i in 0..MASK_WORDS {
            self.0[i] |= other.0[i];
        }
    }

    #[inline(always)]
    pub fn and_not(&self, other: &Mask) -> Mask {
        let mut out = Mask::EMPTY;
        for i in 0..MASK_WORDS {
            out.0[i] = self.0[i] & !other.0[i];
        }
        out
    }

    pub fn count(&self) -> u32 {
        self.0.iter().map(|w| w.count_ones()).sum()
    }

    #[inline(always)]
    pub fn get(&self, row: usize, col: usize) -> bool {
        let bit = row * MASK_SIDE + col;
        (self.0[bit / 64] >> (bit % 64)) & 1 == 1
    }

    #[inline(always)]
    pub fn set(&mut self, row: usize, col: usize) {
        let bit = row * MASK_SIDE + col;
        self.0[bit / 64] |= 1u64 << (bit % 64);
    }

    /// The 32 bits of one mask row, bit `col` for column `col`.
    #[inline(always)]
    pub fn row_bits(&self, row: usize) -> u32 {
        (self.0[row / 2] >> (32 * (row % 2))) as u32
    }
}

/// Disk coordinate of the centre of cell `index` along one axis.
#[inline]
pub fn cell_centre(index: usize) -> f32 {
    -1.0 + (index as f32 + 0.5) * (2.0 / MASK_SIDE as f32)
}

/// The hemisphere direction through the centre of cell (row, col), or None outside the disk.
pub fn cell_direction(row: usize, col: usize) -> Option<[f32; 3]> {
    let (x, y) = (cell_centre(col), cell_centre(row));
    let r2 = x * x + y * y;
    (r2 < 1.0).then(|| [x, y, (1.0 - r2).sqrt()])
}

/// Lifts a point of the unit disk to the hemisphere.
#[inline(always)]
pub fn lift(x: f32, y: f32) -> [f32; 3] {
    [x, y, (1.0 - x * x - y * y).max(0.0).sqrt()]
}

/// The cells that belong to the disk.
pub fn disk() -> Mask {
    let mut mask = Mask::EMPTY;
    for row in 0..MASK_SIDE {
        for col in 0..MASK_SIDE {
            if cell_direction(row, col).is_some() {
                mask.set(row, col);
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_area_is_close_to_pi() {
        let cells = disk().count() as f32;
        let area = cells * (2.0 / MASK_SIDE as f32).powi(2);
        assert!((area - std::f32::consts::PI).abs() < 0.05, "{area}");
    }

    #[test]
    fn row_bits_match_get() {
        let mut mask = Mask::EMPTY;
        mask.set(5, 7);
        mask.set(6, 31);
        assert_eq!(mask.row_bits(5), 1 << 7);
        assert_eq!(mask.row_bits(6), 1 << 31);
        assert!(mask.get(6, 31) && !mask.get(6, 30));
    }
}
