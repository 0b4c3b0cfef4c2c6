//! The 32x32 one-bit visibility mask over the unit disk (Kautz et al. 2004, section 3.1).
//!
//! The hemisphere around a receiver's normal (+Z of its tangent frame) is projected onto the
//! unit disk by dropping z (Nusselt analog), so every in-disk cell carries the same
//! cosine-weighted solid angle. Cell (row, col) covers x in [-1 + col/16, -1 + (col+1)/16] and
//! y likewise with row. Every cell that overlaps the disk belongs to the mask: it stands for its
//! part of the disk, with that part's area as weight and the direction through that part's
//! centroid as its sample (the cell centre for cells wholly inside). Counting rim cells by
//! their centre alone would leave slivers of the horizon always visible. Bit `row * 32 + col`
//! of the mask is set when the cell's sample direction is blocked.

pub const MASK_SIDE: usize = 32;
pub const MASK_CELLS: usize = MASK_SIDE * MASK_SIDE;
pub const MASK_WORDS: usize = MASK_CELLS / 64;

/// 1024 bits, two mask rows per 64-bit word; aligned to a cache line, so a mask is exactly
/// two lines (one prefetch each).
#[derive(Clone, Copy, PartialEq, Eq, Default, Debug)]
#[repr(C, align(64))]
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

/// Side length of a cell in disk coordinates.
pub const CELL_SIZE: f32 = 2.0 / MASK_SIDE as f32;

/// A cell's part of the disk: its area and the disk point at its centroid.
#[derive(Clone, Copy, Debug, Default)]
pub struct CellSample {
    pub area: f32,
    pub x: f32,
    pub y: f32,
}

/// Samples per cell side used to measure rim cells.
const RIM_SUBSAMPLES: usize = 16;

fn measure_cell(row: usize, col: usize) -> CellSample {
    let (x0, y0) = (cell_centre(col), cell_centre(row));
    let corner = (x0.abs() + CELL_SIZE / 2.0).powi(2) + (y0.abs() + CELL_SIZE / 2.0).powi(2);
    if corner <= 1.0 {
        return CellSample { area: CELL_SIZE * CELL_SIZE, x: x0, y: y0 };
    }
    let step = CELL_SIZE as f64 / RIM_SUBSAMPLES as f64;
    let (mut count, mut sx, mut sy) = (0usize, 0.0f64, 0.0f64);
    for j in 0..RIM_SUBSAMPLES {
        for i in 0..RIM_SUBSAMPLES {
            let x = x0 as f64 - CELL_SIZE as f64 / 2.0 + (i as f64 + 0.5) * step;
            let y = y0 as f64 - CELL_SIZE as f64 / 2.0 + (j as f64 + 0.5) * step;
            if x * x + y * y < 1.0 {
                count += 1;
                sx += x;
                sy += y;
            }
        }
    }
    if count == 0 {
        return CellSample::default();
    }
    let area = (count as f64 * step * step) as f32;
    CellSample { area, x: (sx / count as f64) as f32, y: (sy / count as f64) as f32 }
}

/// Area and centroid of every cell's part of the disk, row-major (zero area outside).
pub fn cell_samples() -> &'static [CellSample; MASK_CELLS] {
    static SAMPLES: std::sync::OnceLock<[CellSample; MASK_CELLS]> = std::sync::OnceLock::new();
    SAMPLES.get_or_init(|| std::array::from_fn(|i| measure_cell(i / MASK_SIDE, i % MASK_SIDE)))
}

/// The sample direction of cell (row, col), or None when the cell misses the disk.
pub fn cell_direction(row: usize, col: usize) -> Option<[f32; 3]> {
    let sample = cell_samples()[row * MASK_SIDE + col];
    (sample.area > 0.0).then(|| lift(sample.x, sample.y))
}

/// Whether a cell lies wholly inside the disk (its sample is its centre, its area a full cell).
pub fn is_full(row: usize, col: usize) -> bool {
    cell_samples()[row * MASK_SIDE + col].area == CELL_SIZE * CELL_SIZE
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
    fn cell_areas_add_up_to_pi() {
        let area: f32 = cell_samples().iter().map(|c| c.area).sum();
        assert!((area - std::f32::consts::PI).abs() < 2e-3, "{area}");
        assert_eq!(disk().count() as usize, cell_samples().iter().filter(|c| c.area > 0.0).count());
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
