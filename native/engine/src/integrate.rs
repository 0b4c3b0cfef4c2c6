//! Integration of a visibility mask against the SH basis and the BRDF (Kautz et al. 2004,
//! equation 3 and section 3.2, "Downsampling the visibility mask").
//!
//! The mask is downsampled in B x B blocks into a grey occlusion term. In the disk
//! parameterisation cosine-weighted solid angle is area, so a block's contribution is its grey
//! value times the integral of the basis over the block's part of the disk.
//!
//! Diffuse transfer is integrated in the receiver's tangent frame, where those block integrals
//! are constants computed once: the blocked part is subtracted from the exact unoccluded
//! transfer (zonal, A_l Y_l0(+Z)), so an unoccluded receiver is exact and only blocked blocks
//! cost anything; one SH rotation then takes the vector to world space.
//! Glossy (normalised Phong) transfer depends on the view, so it is integrated in world space:
//! each block is a quadrature point at the centroid of its visible cells.

use crate::disk_mask::{cell_centre, cell_samples, disk, is_full, lift, Mask, CELL_SIZE, MASK_SIDE};
use crate::sh::{clamped_cosine_zonal, ShBasis, MAX_COEFFS};
use crate::sh_rotation::ShRotator;

/// The BRDF of the receivers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Brdf {
    /// Lambertian, without albedo and without 1/pi (the project's transfer convention).
    Diffuse,
    /// Normalised Phong: (e + 2) / (2 pi) max(0, r.s)^e, r the view direction mirrored about n.
    Phong { exponent: f32 },
}

/// A receiver's tangent frame in world space: tangent, bitangent, normal.
#[derive(Clone, Copy)]
pub struct Frame {
    pub t: [f32; 3],
    pub b: [f32; 3],
    pub n: [f32; 3],
}

impl Frame {
    #[inline(always)]
    fn to_world(self, l: [f32; 3]) -> [f32; 3] {
        let (t, b, n) = (self.t, self.b, self.n);
        [
            l[0] * t[0] + l[1] * b[0] + l[2] * n[0],
            l[0] * t[1] + l[1] * b[1] + l[2] * n[1],
            l[0] * t[2] + l[1] * b[2] + l[2] * n[2],
        ]
    }
}

struct Block {
    row0: usize,
    col0: usize,
    in_disk: u64,
    /// Every cell wholly inside the disk: counting bits measures area and centroid.
    full: bool,
    /// The block's area of the disk.
    area: f32,
}

/// Quadrature over B x B blocks of the mask.
pub struct Quadrature {
    block: usize,
    basis: ShBasis,
    rotator: ShRotator,
    blocks: Vec<Block>,
    /// Per block, the integral of each local-frame basis function over the block's disk area.
    local_weights: Vec<f32>,
    /// Diffuse transfer of an unoccluded receiver in its own frame.
    local_open: [f32; MAX_COEFFS],
    /// `local_open` less every block's weights (what a wholly blocked receiver keeps: the
    /// quadrature's residual), and the disk's cells.
    local_closed: [f32; MAX_COEFFS],
    disk: Mask,
    col_masks: Vec<u64>,
    row_masks: Vec<u64>,
    /// With one cell per block: per mask row and column c (0 to 32), the sum of the weights of
    /// the row's cells left of c (zero outside the disk), each padded with zeros to a multiple
    /// of 8 floats. A run of consecutive cells then costs two reads, whatever its length,
    /// and the loop over runs holds its sums in registers.
    row_sums: Vec<f32>,
}

impl Quadrature {
    /// `block` cells per block side: 1, 2, 4 or 8.
    pub fn new(block: usize, basis: ShBasis) -> Self {
        assert!(matches!(block, 1 | 2 | 4 | 8), "block size must divide 32 and fit 64 bits");
        let disk = disk();
        let per_side = MASK_SIDE / block;
        let mut local_open = [0.0f32; MAX_COEFFS];
        unoccluded_diffuse(&basis, [0.0, 0.0, 1.0], &mut local_open);
        let k = basis.coeffs();
        let mut cell_weights = vec![0.0f32; if block == 1 { MASK_SIDE * MASK_SIDE * k } else { 0 }];
        let mut quadrature = Quadrature {
            block,
            rotator: ShRotator::new(basis.clone()),
            basis,
            blocks: Vec::new(),
            local_weights: Vec::new(),
            local_open,
            local_closed: local_open,
            disk,
            col_masks: (0..block).map(|k| (0..block).fold(0, |m, j| m | 1u64 << (j * block + k))).collect(),
            row_masks: (0..block).map(|j| ((1u64 << block) - 1) << (j * block)).collect(),
            row_sums: Vec::new(),
        };
        for br in 0..per_side {
            for bc in 0..per_side {
                let (row0, col0) = (br * block, bc * block);
                let in_disk = quadrature.pattern(&disk, row0, col0);
                if in_disk != 0 {
                    let full = (row0..row0 + block).all(|r| (col0..col0 + block).all(|c| is_full(r, c)));
                    let mut b = Block { row0, col0, in_disk, full, area: 0.0 };
                    b.area = quadrature.measure(&b, in_disk).0;
                    quadrature.blocks.push(b);
                    let weights = block_integral(&quadrature.basis, row0, col0, block);
                    if block == 1 {
                        cell_weights[(row0 * MASK_SIDE + col0) * k..][..k].copy_from_slice(&weights);
                    }
                    quadrature.local_weights.extend_from_slice(&weights);
                }
            }
        }
        if block == 1 {
            quadrature.row_sums = row_sums(&cell_weights, k);
        }
        for (i, closed) in quadrature.local_closed[..k].iter_mut().enumerate() {
            let all: f64 = quadrature.local_weights.chunks_exact(k).map(|w| w[i] as f64).sum();
            *closed = (local_open[i] as f64 - all) as f32;
        }
        quadrature
    }

    /// The cells of one block as B*B bits, row-major within the block.
    #[inline(always)]
    fn pattern(&self, mask: &Mask, row0: usize, col0: usize) -> u64 {
        let b = self.block;
        let low = (1u32 << b) - 1;
        (0..b).fold(0u64, |p, j| p | (((mask.row_bits(row0 + j) >> col0) & low) as u64) << (j * b))
    }

    /// Disk area of the cells of `pattern` in `block` and the local direction through their
    /// centroid: by bit counts inside the disk, by each cell's measured part on the rim.
    #[inline(always)]
    fn measure(&self, block: &Block, pattern: u64) -> (f32, [f32; 3]) {
        let (x, y, area);
        if block.full {
            let count = pattern.count_ones() as f32;
            let (mut sum_col, mut sum_row) = (0u32, 0u32);
            for k in 1..self.block {
                sum_col += k as u32 * (pattern & self.col_masks[k]).count_ones();
                sum_row += k as u32 * (pattern & self.row_masks[k]).count_ones();
            }
            x = cell_centre(block.col0) + CELL_SIZE * sum_col as f32 / count;
            y = cell_centre(block.row0) + CELL_SIZE * sum_row as f32 / count;
            area = count * CELL_SIZE * CELL_SIZE;
        } else {
            let (mut a, mut sx, mut sy) = (0.0f32, 0.0f32, 0.0f32);
            let mut bits = pattern;
            while bits != 0 {
                let bit = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let cell = cell_samples()[(block.row0 + bit / self.block) * MASK_SIDE + block.col0 + bit % self.block];
                a += cell.area;
                sx += cell.area * cell.x;
                sy += cell.area * cell.y;
            }
            (x, y, area) = (sx / a, sy / a, a);
        }
        (area, lift(x, y))
    }

    pub fn basis(&self) -> &ShBasis {
        &self.basis
    }

    /// Transfer vector of a receiver with visibility `blocked` into `out[..coeffs]`.
    /// `view` (unit, towards the viewer) is used by glossy BRDFs only.
    pub fn integrate(&self, blocked: &Mask, frame: &Frame, brdf: Brdf, view: [f32; 3], out: &mut [f32]) {
        match brdf {
            Brdf::Diffuse => self.integrate_diffuse(blocked, frame, out),
            Brdf::Phong { exponent } => self.integrate_phong(blocked, frame, exponent, view, out),
        }
    }

    fn integrate_diffuse(&self, blocked: &Mask, frame: &Frame, out: &mut [f32]) {
        let k = self.basis.coeffs();
        if *blocked == Mask::EMPTY {
            unoccluded_diffuse(&self.basis, frame.n, out); // exact, and no rotation needed
            return;
        }
        let mut local = self.local_open;
        if self.block == 1 {
            self.subtract_blocked_cells(blocked, &mut local[..k]);
        } else {
            self.subtract_blocked_blocks(blocked, &mut local[..k]);
        }
        self.rotator.to_world([frame.t, frame.b, frame.n], &local[..k], out);
    }

    /// Subtracts every block's weights times its grey value (blocked share of its disk area).
    fn subtract_blocked_blocks(&self, blocked: &Mask, local: &mut [f32]) {
        let k = local.len();
        for (block, weights) in self.blocks.iter().zip(self.local_weights.chunks_exact(k)) {
            let pattern = self.pattern(blocked, block.row0, block.col0);
            if pattern == 0 {
                continue;
            }
            let grey = if block.full {
                pattern.count_ones() as f32 / block.in_disk.count_ones() as f32
            } else {
                self.measure(block, pattern).0 / block.area
            };
            local.iter_mut().zip(weights).for_each(|(t, w)| *t -= grey * w);
        }
    }

    /// One cell per block: every blocked disk cell has grey value 1, so its weights are
    /// subtracted as they are, a run of blocked cells in a row at a time (the difference of
    /// two of the row's prefix sums): the general loop's result up to rounding, without
    /// visiting open cells or each blocked one. A mostly blocked receiver starts from
    /// `local_closed` and adds its runs of open cells instead. Each coefficient sees the same
    /// operations in the same order in the AVX2 build, which holds the sums in registers, so
    /// both builds give the same bits.
    fn subtract_blocked_cells(&self, blocked: &Mask, local: &mut [f32]) {
        let open = self.disk.and_not(blocked);
        if blocked.count() > open.count() {
            local.copy_from_slice(&self.local_closed[..local.len()]);
            self.add_cells::<true>(&open, local);
        } else {
            self.add_cells::<false>(blocked, local);
        }
    }

    /// Adds (ADD) or subtracts the weights of `cells` to or from `local`.
    fn add_cells<const ADD: bool>(&self, cells: &Mask, local: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports the feature the functions are compiled for.
            return unsafe {
                match padded(local.len()) / LANE {
                    1 => self.add_cells_avx2::<1, ADD>(cells, local),
                    2 => self.add_cells_avx2::<2, ADD>(cells, local),
                    3 => self.add_cells_avx2::<3, ADD>(cells, local),
                    4 => self.add_cells_avx2::<4, ADD>(cells, local),
                    5 => self.add_cells_avx2::<5, ADD>(cells, local),
                    6 => self.add_cells_avx2::<6, ADD>(cells, local),
                    7 => self.add_cells_avx2::<7, ADD>(cells, local),
                    _ => self.add_cells_avx2::<8, ADD>(cells, local),
                }
            };
        }
        self.add_cells_portable::<ADD>(cells, local);
    }

    fn add_cells_portable<const ADD: bool>(&self, cells: &Mask, local: &mut [f32]) {
        let (k, row) = (local.len(), padded(local.len()));
        for (start, end) in runs(cells) {
            let (before, through) = (&self.row_sums[start * row..][..k], &self.row_sums[end * row..][..k]);
            for (t, (b, e)) in local.iter_mut().zip(before.iter().zip(through)) {
                *t = if ADD { *t + (e - b) } else { *t - (e - b) };
            }
        }
    }

    /// The sums in N registers of 8 (LLVM scalarises the same loop written on arrays).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn add_cells_avx2<const N: usize, const ADD: bool>(&self, cells: &Mask, local: &mut [f32]) {
        use std::arch::x86_64::{_mm256_add_ps, _mm256_loadu_ps, _mm256_storeu_ps, _mm256_sub_ps};
        let mut padded_local = [[0.0f32; LANE]; N];
        padded_local.as_flattened_mut()[..local.len()].copy_from_slice(local);
        let mut sums = padded_local.map(|lane| _mm256_loadu_ps(lane.as_ptr()));
        for (start, end) in runs(cells) {
            let before = self.row_sums[start * N * LANE..][..N * LANE].as_ptr();
            let through = self.row_sums[end * N * LANE..][..N * LANE].as_ptr();
            for (i, sum) in sums.iter_mut().enumerate() {
                let w = _mm256_sub_ps(_mm256_loadu_ps(through.add(i * LANE)), _mm256_loadu_ps(before.add(i * LANE)));
                *sum = if ADD { _mm256_add_ps(*sum, w) } else { _mm256_sub_ps(*sum, w) };
            }
        }
        for (lane, sum) in padded_local.iter_mut().zip(sums) {
            _mm256_storeu_ps(lane.as_mut_ptr(), sum);
        }
        local.copy_from_slice(&padded_local.as_flattened()[..local.len()]);
    }

    fn integrate_phong(&self, blocked: &Mask, frame: &Frame, exponent: f32, view: [f32; 3], out: &mut [f32]) {
        let k = self.basis.coeffs();
        let out = &mut out[..k];
        let mut y = [0.0f32; MAX_COEFFS];
        out.fill(0.0);
        let n = frame.n;
        let nv = crate::rasterizer::dot(n, view);
        let r = [2.0 * nv * n[0] - view[0], 2.0 * nv * n[1] - view[1], 2.0 * nv * n[2] - view[2]];
        let norm = (exponent + 2.0) / (2.0 * std::f32::consts::PI);
        for block in &self.blocks {
            let pattern = block.in_disk & !self.pattern(blocked, block.row0, block.col0);
            if pattern == 0 {
                continue;
            }
            let (area, local) = self.measure(block, pattern);
            let s = frame.to_world(local);
            let rs = crate::rasterizer::dot(r, s);
            if rs <= 0.0 {
                continue;
            }
            self.basis.eval(s, &mut y);
            let w = area * norm * rs.powf(exponent);
            out.iter_mut().zip(&y[..k]).for_each(|(o, yi)| *o += w * yi);
        }
    }
}

/// Floats per lane of the per-cell loop (one AVX2 register).
const LANE: usize = 8;

/// `len` rounded up to whole lanes.
fn padded(len: usize) -> usize {
    len.div_ceil(LANE) * LANE
}

/// `Quadrature::row_sums` from each cell's `k` weights (row-major): the prefix sums of every
/// row, accumulated in f64.
fn row_sums(cell_weights: &[f32], k: usize) -> Vec<f32> {
    let (per_row, row) = (MASK_SIDE + 1, padded(k));
    let mut sums = vec![0.0f32; MASK_SIDE * per_row * row];
    for (r, cells) in cell_weights.chunks_exact(MASK_SIDE * k).enumerate() {
        let mut acc = vec![0.0f64; k];
        let mut write = |c: usize, acc: &[f64]| {
            sums[(r * per_row + c) * row..][..k].iter_mut().zip(acc).for_each(|(o, a)| *o = *a as f32);
        };
        for (c, weights) in cells.chunks_exact(k).enumerate() {
            write(c, &acc);
            acc.iter_mut().zip(weights).for_each(|(a, w)| *a += *w as f64);
        }
        write(MASK_SIDE, &acc);
    }
    sums
}

/// Each run of consecutive set cells of `cells` within a row, in bit order, as the indices in
/// `Quadrature::row_sums` of the sums before its first cell and through its last.
#[inline(always)]
fn runs(cells: &Mask) -> impl Iterator<Item = (usize, usize)> + '_ {
    (0..MASK_SIDE).flat_map(move |row| {
        let bits = cells.row_bits(row) as u64;
        let (mut starts, mut lasts) = (bits & !(bits << 1), bits & !(bits >> 1));
        let base = row * (MASK_SIDE + 1);
        std::iter::from_fn(move || {
            (starts != 0).then(|| {
                let run = (base + starts.trailing_zeros() as usize, base + lasts.trailing_zeros() as usize + 1);
                starts &= starts - 1;
                lasts &= lasts - 1;
                run
            })
        })
    })
}

/// Integral of every basis function over the disk part of a block, in the local frame
/// (cosine-weighted solid angle = disk area), by 8 x 8 samples per cell.
fn block_integral(basis: &ShBasis, row0: usize, col0: usize, block: usize) -> Vec<f32> {
    const SUB: usize = 8;
    let k = basis.coeffs();
    let cell = 2.0 / MASK_SIDE as f64;
    let sample_area = (cell / SUB as f64).powi(2);
    let mut sums = vec![0.0f64; k];
    let mut y = [0.0f32; MAX_COEFFS];
    for row in row0..row0 + block {
        for col in col0..col0 + block {
            if crate::disk_mask::cell_direction(row, col).is_none() {
                continue; // never set in a mask: its sliver of the disk stays visible
            }
            for sy in 0..SUB {
                for sx in 0..SUB {
                    let x = -1.0 + cell * (col as f64 + (sx as f64 + 0.5) / SUB as f64);
                    let yy = -1.0 + cell * (row as f64 + (sy as f64 + 0.5) / SUB as f64);
                    if x * x + yy * yy >= 1.0 {
                        continue;
                    }
                    basis.eval(lift(x as f32, yy as f32), &mut y);
                    sums.iter_mut().zip(&y[..k]).for_each(|(s, v)| *s += *v as f64 * sample_area);
                }
            }
        }
    }
    sums.into_iter().map(|v| v as f32).collect()
}

/// Exact diffuse transfer of an unoccluded receiver: A_l Y_lm(n).
pub fn unoccluded_diffuse(basis: &ShBasis, n: [f32; 3], out: &mut [f32]) {
    basis.eval(n, out);
    for l in 0..basis.bands() {
        let a = clamped_cosine_zonal(l);
        out[l * l..(l + 1) * (l + 1)].iter_mut().for_each(|v| *v *= a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn up() -> Frame {
        Frame { t: [1.0, 0.0, 0.0], b: [0.0, 1.0, 0.0], n: [0.0, 0.0, 1.0] }
    }

    #[test]
    fn fully_blocked_diffuse_is_nearly_zero() {
        let basis = ShBasis::new(5).unwrap();
        for block in [1, 2, 4] {
            let q = Quadrature::new(block, basis.clone());
            let mut t = [0.0f32; 25];
            q.integrate(&disk(), &up(), Brdf::Diffuse, [0.0, 0.0, 1.0], &mut t);
            let norm: f32 = t.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!(norm < 0.05, "block {block}: {norm}");
        }
    }

    #[test]
    fn blocked_cells_give_the_general_blocks_loop() {
        // Every band count (1 to 8 lanes of sums), in the dispatched (AVX2 where the CPU has
        // it) and the baseline build of the per-run loop; masks a quarter blocked (blocked
        // cells subtracted) and three quarters (open cells added to the closed transfer): the
        // general loop's result up to rounding, the two builds' to the bit.
        let mut state = 3u64;
        for bands in 1..=8 {
            let q = Quadrature::new(1, ShBasis::new(bands).unwrap());
            let k = q.basis.coeffs();
            for trial in 0..100 {
                let mut mask = Mask::EMPTY;
                for w in mask.0.iter_mut() {
                    state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    *w = if trial % 2 == 0 { state & (state >> 17) } else { state | (state >> 17) };
                }
                let mask = Mask::and3(&mask, &disk(), &disk());
                let (mut fast, mut general) = (q.local_open, q.local_open);
                q.subtract_blocked_cells(&mask, &mut fast[..k]);
                q.subtract_blocked_blocks(&mask, &mut general[..k]);
                let open = disk().and_not(&mask);
                let mut baseline = if trial % 2 == 0 { q.local_open } else { q.local_closed };
                if trial % 2 == 0 {
                    q.add_cells_portable::<false>(&mask, &mut baseline[..k]);
                } else {
                    q.add_cells_portable::<true>(&open, &mut baseline[..k]);
                }
                let worst = fast.iter().zip(&general).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
                assert!(worst < 2e-5, "bands {bands}, trial {trial}: {worst}");
                assert_eq!(fast, baseline, "bands {bands}");
            }
        }
    }

    #[test]
    fn blocked_runs_match_the_sum_in_f64() {
        // Shadow-like masks (discs of blocked cells, some with the lower half of the disk
        // too), both branches: within 1e-6 of the f64 sum of the blocked cells' weights. Cell
        // by cell in f32, as before the runs, the same masks ended 7.4e-6 away.
        let q = Quadrature::new(1, ShBasis::new(5).unwrap());
        let k = q.basis.coeffs();
        let mut state = 7u64;
        for trial in 0..400 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let (cx, cy, r) = ((state >> 8) % 32, (state >> 20) % 32, 3 + (state >> 32) % 14);
            let mut mask = Mask::EMPTY;
            for (row, col) in (0..MASK_SIDE).flat_map(|row| (0..MASK_SIDE).map(move |col| (row, col))) {
                let (dx, dy) = (col as i64 - cx as i64, row as i64 - cy as i64);
                if dx * dx + dy * dy <= (r * r) as i64 || (trial % 3 == 0 && row < 16) {
                    mask.set(row, col);
                }
            }
            let mask = Mask::and3(&mask, &disk(), &disk());
            let mut exact: Vec<f64> = q.local_open[..k].iter().map(|&v| v as f64).collect();
            for (b, w) in q.blocks.iter().zip(q.local_weights.chunks_exact(k)) {
                if q.pattern(&mask, b.row0, b.col0) != 0 {
                    exact.iter_mut().zip(w).for_each(|(e, w)| *e -= *w as f64);
                }
            }
            let mut got = q.local_open;
            q.subtract_blocked_cells(&mask, &mut got[..k]);
            let worst = got.iter().zip(&exact).map(|(g, e)| (*g as f64 - e).abs()).fold(0.0, f64::max);
            assert!(worst < 1e-6, "trial {trial}: {worst}");
        }
    }

    #[test]
    fn unblocked_phong_integrates_to_about_one() {
        // Normalised Phong with the mirror direction along n reflects all energy:
        // T_0 = Y_0 * integral f_r cos = 0.282095.
        let basis = ShBasis::new(3).unwrap();
        let q = Quadrature::new(2, basis);
        let mut t = [0.0f32; 9];
        q.integrate(&Mask::EMPTY, &up(), Brdf::Phong { exponent: 4.0 }, [0.0, 0.0, 1.0], &mut t);
        assert!((t[0] - 0.282_095).abs() < 0.01, "{}", t[0]);
    }
}
