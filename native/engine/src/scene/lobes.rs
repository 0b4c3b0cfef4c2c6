//! Lobe integrals over a receiver's open cells, for lightmaps: for a clamped-cosine lobe
//! around a unit direction v (in the receiver's frame) and per-cell values f_c,
//! sum over open cells of max(0, v . M_c) f_c, where M_c is the cell's first moment (the
//! integral of s over its solid angle), rescaled so that the open hemisphere gives the exact
//! integral pi (1 + v_z) / 2 of the lobe (the linear form is 0.07 % low where the lobe's edge
//! crosses a cell). The masks stay packed: 128 bytes a receiver instead of 1 KiB unpacked.
//!
//! Laid out for the hot loop: per receiver, the lobes' weights of every cell (the open ones
//! only) go to a scratch of `MAX_LOBES` x 1024, then one pass over the cells adds each cell's
//! values, two blocks of eight at a time, to every lobe's sums, which stay in vector
//! registers. The kernel is compiled for AVX2 + FMA as well and picked at run time.

use rayon::prelude::*;

use crate::disk_mask::{Mask, MASK_CELLS};
use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// Lobes per receiver: the HL2 basis and the normal make four.
pub const MAX_LOBES: usize = 4;

/// Values summed per pass over the cells (one vector register per lobe).
const WIDTH: usize = 8;

/// out[(p * lobe_count + l) * K + k] = scale x sum over open cells c of max(0, v.M_c) values[c * K + k],
/// with v = lobes[p * lobe_count + l], scale = pi (1 + v_z) / 2 / sum over all cells of max(0, v.M_c).
pub fn lobe_integrals(masks: &[Mask], lobes: &[Vec3], lobe_count: usize, moments: &[Vec3], values: &[f32]) -> Result<Vec<f32>> {
    if moments.len() != MASK_CELLS {
        return Err(Error::invalid(format!("moments must have {MASK_CELLS} rows, got {}", moments.len())));
    }
    if lobe_count == 0 || lobe_count > MAX_LOBES || lobes.len() != masks.len() * lobe_count {
        return Err(Error::invalid(format!(
            "lobes must have {} x {lobe_count} rows (1 to {MAX_LOBES} lobes per receiver), got {}",
            masks.len(),
            lobes.len()
        )));
    }
    if values.is_empty() || !values.len().is_multiple_of(MASK_CELLS) {
        return Err(Error::invalid(format!("values must have {MASK_CELLS} rows, got {} numbers", values.len())));
    }
    let k = values.len() / MASK_CELLS;
    let kernel = Kernel::new(moments, values, k);
    let mut out = vec![0.0f32; lobes.len() * k];
    out.par_chunks_mut(lobe_count * k).zip(masks.par_iter()).zip(lobes.par_chunks(lobe_count)).for_each_init(
        || vec![[0.0f32; MASK_CELLS]; MAX_LOBES],
        |weights, ((row, mask), vs)| kernel.receiver(mask, vs, weights, row),
    );
    Ok(out)
}

/// The cells' moments by component and their values in blocks of `WIDTH` (zero-padded).
struct Kernel {
    moments: [[f32; MASK_CELLS]; 3],
    /// Block j of cell c: values[c * k + j * WIDTH ..][..WIDTH], at blocks[j * MASK_CELLS + c].
    blocks: Vec<[f32; WIDTH]>,
    k: usize,
}

impl Kernel {
    fn new(moments: &[Vec3], values: &[f32], k: usize) -> Kernel {
        let mut soa = [[0.0f32; MASK_CELLS]; 3];
        for (c, m) in moments.iter().enumerate() {
            (0..3).for_each(|a| soa[a][c] = m[a]);
        }
        let block_count = k.div_ceil(WIDTH).next_multiple_of(2); // summed two at a time
        let mut blocks = vec![[0.0f32; WIDTH]; block_count * MASK_CELLS];
        for j in 0..block_count {
            for c in 0..MASK_CELLS {
                for (i, slot) in blocks[j * MASK_CELLS + c].iter_mut().enumerate() {
                    let value = j * WIDTH + i;
                    *slot = if value < k { values[c * k + value] } else { 0.0 };
                }
            }
        }
        Kernel { moments: soa, blocks, k }
    }

    fn receiver(&self, mask: &Mask, lobes: &[Vec3], weights: &mut [[f32; MASK_CELLS]], out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { self.receiver_avx2(mask, lobes, weights, out) };
        }
        self.receiver_portable::<Portable>(mask, lobes, weights, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn receiver_avx2(&self, mask: &Mask, lobes: &[Vec3], weights: &mut [[f32; MASK_CELLS]], out: &mut [f32]) {
        self.receiver_portable::<Avx2>(mask, lobes, weights, out)
    }

    /// Weights of every lobe (open cells only), then the sums, block by block of values.
    #[inline(always)]
    fn receiver_portable<A: BlockSums>(&self, mask: &Mask, lobes: &[Vec3], weights: &mut [[f32; MASK_CELLS]], out: &mut [f32]) {
        let mut scales = [0.0f32; MAX_LOBES];
        for (l, v) in lobes.iter().enumerate() {
            scales[l] = self.lobe_weights(mask, *v, &mut weights[l]);
        }
        match lobes.len() {
            1 => self.sums::<A, 1>(weights, &scales, out),
            2 => self.sums::<A, 2>(weights, &scales, out),
            3 => self.sums::<A, 3>(weights, &scales, out),
            _ => self.sums::<A, 4>(weights, &scales, out),
        }
    }

    /// out[l * k + j] = scales[l] x sum over cells of weights[l][c] values[c][j], for `L` lobes.
    #[inline(always)]
    fn sums<A: BlockSums, const L: usize>(&self, weights: &[[f32; MASK_CELLS]], scales: &[f32; MAX_LOBES], out: &mut [f32]) {
        let weights: &[[f32; MASK_CELLS]; L] = weights[..L].try_into().expect("L lobes of weights");
        for (pair, blocks) in self.blocks.chunks_exact(2 * MASK_CELLS).enumerate() {
            let sums = A::block_sums::<L>(blocks.split_at(MASK_CELLS), weights);
            for (half, sums) in sums.iter().enumerate() {
                let first = (2 * pair + half) * WIDTH;
                if first >= self.k {
                    break; // the padding block
                }
                let width = WIDTH.min(self.k - first);
                for l in 0..L {
                    for (o, s) in out[l * self.k + first..][..width].iter_mut().zip(&sums[l]) {
                        *o = s * scales[l];
                    }
                }
            }
        }
    }

    /// max(0, v.M_c) of the open cells into `weights` (zero where blocked); returns the scale
    /// that makes the whole hemisphere's sum the exact integral.
    #[inline(always)]
    fn lobe_weights(&self, mask: &Mask, v: Vec3, weights: &mut [f32; MASK_CELLS]) -> f32 {
        let [mx, my, mz] = &self.moments;
        let mut total = [0.0f32; 8];
        for byte in 0..MASK_CELLS / 8 {
            let open = &OPEN[(mask.0[byte / 8] >> (8 * (byte % 8)) & 0xff) as usize];
            let cells = byte * 8..(byte + 1) * 8;
            let (x, y, z, w) = (&mx[cells.clone()], &my[cells.clone()], &mz[cells.clone()], &mut weights[cells]);
            for i in 0..8 {
                let d = (v[0] * x[i] + v[1] * y[i] + v[2] * z[i]).max(0.0);
                total[i] += d;
                w[i] = d * open[i];
            }
        }
        let total: f32 = total.iter().sum();
        let exact = std::f32::consts::PI * (1.0 + v[2].clamp(-1.0, 1.0)) / 2.0;
        if total > 0.0 {
            exact / total
        } else {
            0.0
        }
    }
}

/// Each cell's first moment M_c (the integral of s over its solid angle, in the receiver's
/// frame) and its solid angle: (x, y, z, solid angle) per cell, row-major. A midpoint rule in
/// (theta, phi) on 1024 x 2048 points, which has no 1/z singularity at the rim; each point
/// goes to the cell its direction projects into (the z components add up to pi to 1e-6).
pub fn cell_moments() -> Vec<[f64; 4]> {
    const THETA: usize = 1024;
    const PHI: usize = 2048;
    const ROWS: usize = 64;
    let side = crate::disk_mask::MASK_SIDE;
    let (dt, dp) = (std::f64::consts::FRAC_PI_2 / THETA as f64, 2.0 * std::f64::consts::PI / PHI as f64);
    let cell = |v: f64| (((v + 1.0) * (side as f64 / 2.0)) as usize).min(side - 1);
    let phis: Vec<(f64, f64)> = (0..PHI).map(|j| ((j as f64 + 0.5) * dp).sin_cos()).collect();
    // Fixed bands of rows, summed in a fixed order: the same bits in every run.
    let bands: Vec<Vec<[f64; 4]>> = (0..THETA / ROWS)
        .into_par_iter()
        .map(|band| {
            let mut sums = vec![[0.0f64; 4]; MASK_CELLS];
            for i in band * ROWS..(band + 1) * ROWS {
                let theta = (i as f64 + 0.5) * dt;
                let (st, ct) = theta.sin_cos();
                let weight = st * dt * dp;
                for &(sp, cp) in &phis {
                    let s = [st * cp, st * sp, ct];
                    let sum = &mut sums[cell(s[1]) * side + cell(s[0])];
                    for (total, v) in sum.iter_mut().zip([s[0], s[1], s[2], 1.0]) {
                        *total += v * weight;
                    }
                }
            }
            sums
        })
        .collect();
    bands.into_iter().reduce(|mut a, b| {
        a.iter_mut().zip(&b).for_each(|(x, y)| (0..4).for_each(|k| x[k] += y[k]));
        a
    })
    .expect("at least one band")
}

/// Per lobe, the `WIDTH` sums over the cells of weight x block, for two columns of blocks
/// (one block per cell in each).
trait BlockSums {
    fn block_sums<const L: usize>(blocks: (&[[f32; WIDTH]], &[[f32; WIDTH]]), weights: &[[f32; MASK_CELLS]; L]) -> [[[f32; WIDTH]; L]; 2];
}

struct Portable;

impl BlockSums for Portable {
    #[inline(always)]
    fn block_sums<const L: usize>(blocks: (&[[f32; WIDTH]], &[[f32; WIDTH]]), weights: &[[f32; MASK_CELLS]; L]) -> [[[f32; WIDTH]; L]; 2] {
        [blocks.0, blocks.1].map(|blocks| {
            let mut sums = [[0.0f32; WIDTH]; L];
            for (c, block) in blocks.iter().enumerate() {
                for (sum, w) in sums.iter_mut().zip(weights) {
                    for i in 0..WIDTH {
                        sum[i] += w[c] * block[i];
                    }
                }
            }
            sums
        })
    }
}

/// Fused multiply-adds in vector registers, two columns of blocks at a time: each cell's
/// weight is broadcast once for both, and 2 L chains of adds are in flight (one chain per
/// lobe would wait on each add's latency).
#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl BlockSums for Avx2 {
    #[inline(always)]
    fn block_sums<const L: usize>(blocks: (&[[f32; WIDTH]], &[[f32; WIDTH]]), weights: &[[f32; MASK_CELLS]; L]) -> [[[f32; WIDTH]; L]; 2] {
        use std::arch::x86_64::*;
        // SAFETY: only called from `receiver_avx2`, compiled for AVX2 + FMA on a CPU that has
        // them; loads and stores are unaligned, of whole [f32; 8] blocks.
        unsafe {
            let mut first = [_mm256_setzero_ps(); L];
            let mut second = [_mm256_setzero_ps(); L];
            for (c, (a, b)) in blocks.0.iter().zip(blocks.1).enumerate() {
                let (a, b) = (_mm256_loadu_ps(a.as_ptr()), _mm256_loadu_ps(b.as_ptr()));
                for l in 0..L {
                    let w = _mm256_set1_ps(weights[l][c]);
                    first[l] = _mm256_fmadd_ps(w, a, first[l]);
                    second[l] = _mm256_fmadd_ps(w, b, second[l]);
                }
            }
            let mut sums = [[[0.0f32; WIDTH]; L]; 2];
            for l in 0..L {
                _mm256_storeu_ps(sums[0][l].as_mut_ptr(), first[l]);
                _mm256_storeu_ps(sums[1][l].as_mut_ptr(), second[l]);
            }
            sums
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
type Avx2 = Portable;

/// Per byte of a mask, 1.0 for each of its 8 cells that is open (bit clear), else 0.0.
static OPEN: [[f32; 8]; 256] = {
    let mut table = [[0.0f32; 8]; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut i = 0;
        while i < 8 {
            table[byte][i] = if byte >> i & 1 == 0 { 1.0 } else { 0.0 };
            i += 1;
        }
        byte += 1;
    }
    table
};

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic stream of values in [0, 1).
    fn stream(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn sums_match_a_double_precision_reference_for_every_lobe_count_and_width() {
        let mut next = stream(7);
        let moments: Vec<Vec3> = (0..MASK_CELLS).map(|_| [0, 1, 2].map(|_| (next() - 0.5) as f32 * 0.01)).collect();
        let masks: Vec<Mask> = (0..40).map(|_| Mask([0; 16].map(|_| ((next() * 2f64.powi(53)) as u64) << 11 & ((next() * 2f64.powi(53)) as u64) << 11))).collect();
        for k in [1, 5, 8, 9, 17, 26, 40] {
            let values: Vec<f32> = (0..MASK_CELLS * k).map(|_| (next() * 2.0 - 1.0) as f32).collect();
            for count in 1..=MAX_LOBES {
                let lobes: Vec<Vec3> = (0..masks.len() * count)
                    .map(|_| crate::mesh::normalize([0, 1, 2].map(|_| (next() - 0.5) as f32)).unwrap())
                    .collect();
                let fast = lobe_integrals(&masks, &lobes, count, &moments, &values).unwrap();
                let kernel = Kernel::new(&moments, &values, k);
                let mut weights = vec![[0.0f32; MASK_CELLS]; MAX_LOBES];
                for (p, mask) in masks.iter().enumerate() {
                    let vs = &lobes[p * count..(p + 1) * count];
                    let mut portable = vec![0.0f32; count * k];
                    kernel.receiver_portable::<Portable>(mask, vs, &mut weights, &mut portable);
                    for (l, v) in vs.iter().enumerate() {
                        let weight = |c: usize| (v.iter().zip(&moments[c]).map(|(a, b)| f64::from(*a) * f64::from(*b)).sum::<f64>()).max(0.0);
                        let total: f64 = (0..MASK_CELLS).map(weight).sum();
                        let scale = if total > 0.0 { std::f64::consts::PI * (1.0 + f64::from(v[2])) / 2.0 / total } else { 0.0 };
                        for j in 0..k {
                            let open = (0..MASK_CELLS).filter(|&c| mask.0[c / 64] >> (c % 64) & 1 == 0);
                            let exact: f64 = open.map(|c| weight(c) * f64::from(values[c * k + j])).sum::<f64>() * scale;
                            let bound = 1e-4 * (scale * total).max(1e-3);
                            let i = (p * count + l) * k + j;
                            assert!((f64::from(fast[i]) - exact).abs() < bound, "k {k}, lobes {count}: {} vs {exact}", fast[i]);
                            assert!((f64::from(portable[l * k + j]) - exact).abs() < bound, "portable k {k}, lobes {count}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn more_lobes_than_the_kernel_holds_are_refused() {
        let moments = vec![[0.0, 0.0, 1.0]; MASK_CELLS];
        let lobes = vec![[0.0, 0.0, 1.0]; MAX_LOBES + 1];
        assert!(lobe_integrals(&[Mask::EMPTY], &lobes, MAX_LOBES + 1, &moments, &[1.0; MASK_CELLS]).is_err());
    }
}
