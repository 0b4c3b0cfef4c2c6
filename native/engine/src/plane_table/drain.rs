//! OR-ing triangles given by their edge codes into a mask: the inner loop of every pipelined
//! rasterization (`rasterizer::Pipeline::drain`), in AVX2 registers where the CPU has them.
//!
//! A code's mask is the stored mask XOR its flip (nothing, or the disk for a complemented
//! one). The AVX2 path XORs with all ones instead, derived from the code's top bit without a
//! load, keeps the drain's OR in four registers, and ANDs it with the disk once at the end:
//! the stored masks lie within the disk, so `(s ^ ones) & disk == s ^ disk` and the result is
//! the same bit for bit. The AVX-512 kernel's drain holds a mask in two 512-bit words and
//! folds the flips and the AND into ternary-logic operations: four operations per word where
//! the AVX2 drain takes six per 256-bit word. It measured no faster on a Xeon, and about 9 %
//! faster per solve on an AMD EPYC with Zen 5 (docs/solver_speed.md).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

use super::{Fetches, PlaneTable, MASK_BYTES};
use crate::disk_mask::Mask;

impl PlaneTable {
    /// ORs into `mask` the triangles of the `lanes` of `fetches` (`[edge][lane]`): for each,
    /// the AND of its three edges' masks.
    #[inline(always)]
    pub fn or_triangles(&self, fetches: &Fetches, lanes: u32, mask: &mut Mask) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2.
            return unsafe { self.or_triangles_avx2(fetches, lanes, mask) };
        }
        self.or_triangles_portable(fetches, lanes, mask)
    }

    fn or_triangles_portable(&self, fetches: &Fetches, lanes: u32, mask: &mut Mask) {
        let mut bits = lanes;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let edge = |e: usize| self.flipped(&self.masks[fetches.offsets[e][i] as usize / MASK_BYTES], (fetches.flips[e][i] & 1) as usize);
            mask.or_assign(&Mask::and3(&edge(0), &edge(1), &edge(2)));
        }
    }

    /// `or_triangles` in AVX2 registers, for callers compiled for AVX2 (where it inlines).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn or_triangles_avx2(&self, fetches: &Fetches, lanes: u32, mask: &mut Mask) {
        self.or_triangles_avx2_inlined(fetches, lanes, mask)
    }

    /// `or_triangles_avx2` for kernels compiled for AVX2, into which it inlines (no closures:
    /// those would be compiled without AVX2 and keep the intrinsics as calls).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn or_triangles_avx2_inlined(&self, fetches: &Fetches, lanes: u32, mask: &mut Mask) {
        const WORDS: usize = MASK_BYTES / 32;
        let base = self.masks.as_ptr() as *const u8;
        let mut acc = [_mm256_setzero_si256(); WORDS];
        let mut bits = lanes;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            // SAFETY: `fetches` clamps every offset to the last stored mask.
            let [a, b, c] = [0, 1, 2].map(|e| base.add(fetches.offsets[e][i] as usize) as *const __m256i);
            let (fa, fb, fc) = (_mm256_set1_epi32(fetches.flips[0][i]), _mm256_set1_epi32(fetches.flips[1][i]), _mm256_set1_epi32(fetches.flips[2][i]));
            for (w, acc) in acc.iter_mut().enumerate() {
                let x = _mm256_xor_si256(_mm256_load_si256(a.add(w)), fa);
                let y = _mm256_xor_si256(_mm256_load_si256(b.add(w)), fb);
                let z = _mm256_xor_si256(_mm256_load_si256(c.add(w)), fc);
                *acc = _mm256_or_si256(*acc, _mm256_and_si256(_mm256_and_si256(x, y), z));
            }
        }
        let (disk, out) = (self.disk().0.as_ptr() as *const __m256i, mask.0.as_mut_ptr() as *mut __m256i);
        for (w, acc) in acc.into_iter().enumerate() {
            let inside = _mm256_and_si256(acc, _mm256_load_si256(disk.add(w)));
            _mm256_store_si256(out.add(w), _mm256_or_si256(_mm256_load_si256(out.add(w)), inside));
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl PlaneTable {
    /// `or_triangles_avx2` in 512-bit registers (the AVX-512 kernel's drain, as the tests call
    /// it).
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(test)]
    #[target_feature(enable = "avx512f")]
    unsafe fn or_triangles_avx512<const N: usize>(&self, fetches: &Fetches<N>, lanes: u32, mask: &mut Mask) {
        let mut acc = [_mm512_setzero_si512(); 2];
        self.accumulate_avx512(fetches, lanes, &mut acc);
        self.finish_avx512(acc, mask);
    }

    /// ORs into `acc` (a mask in two 512-bit words, not yet AND-ed with the disk) the
    /// triangles of the `lanes` of `fetches`, for kernels compiled for AVX-512F, into which it
    /// inlines. The kernel keeps `acc` in registers across its packets (`finish_avx512`).
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[inline(always)]
    pub(crate) unsafe fn accumulate_avx512<const N: usize>(&self, fetches: &Fetches<N>, lanes: u32, acc: &mut [__m512i; 2]) {
        let base = self.masks.as_ptr() as *const u8;
        let mut bits = lanes;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            // SAFETY: `fetches` clamps every offset to the last stored mask.
            let [a, b, c] = [0, 1, 2].map(|e| base.add(fetches.offsets[e][i] as usize) as *const __m512i);
            let (fa, fb, fc) = (_mm512_set1_epi32(fetches.flips[0][i]), _mm512_set1_epi32(fetches.flips[1][i]), _mm512_set1_epi32(fetches.flips[2][i]));
            for (w, acc) in acc.iter_mut().enumerate() {
                let x = _mm512_xor_si512(_mm512_load_si512(a.add(w)), fa);
                // x & (fb ^ b): ternary-logic table 0x60 for (x, fb, b).
                let t = _mm512_ternarylogic_epi32::<0x60>(x, fb, _mm512_load_si512(b.add(w)));
                let u = _mm512_xor_si512(_mm512_load_si512(c.add(w)), fc);
                // acc | (t & u): table 0xF8.
                *acc = _mm512_ternarylogic_epi32::<0xF8>(*acc, t, u);
            }
        }
    }

    /// ORs `acc` (`accumulate_avx512`), AND-ed with the disk, into `mask`.
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[inline(always)]
    pub(crate) unsafe fn finish_avx512(&self, acc: [__m512i; 2], mask: &mut Mask) {
        let (disk, out) = (self.disk().0.as_ptr() as *const __m512i, mask.0.as_mut_ptr() as *mut __m512i);
        for (w, acc) in acc.into_iter().enumerate() {
            // out | (acc & disk): table 0xF8.
            let v = _mm512_ternarylogic_epi32::<0xF8>(_mm512_load_si512(out.add(w)), acc, _mm512_load_si512(disk.add(w)));
            _mm512_store_si512(out.add(w), v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::disk_mask::disk;
    use crate::packets::LANES;
    use crate::test_random::xorshift32 as next;

    #[test]
    fn stored_masks_lie_within_the_disk() {
        for resolution in [12, 32, 128] {
            let table = PlaneTable::shared(resolution).unwrap();
            assert!(table.masks.iter().all(|m| m.and_not(&disk()) == Mask::EMPTY), "resolution {resolution}");
        }
    }

    #[test]
    fn every_path_ors_the_masks_of_its_codes() {
        let mut state = 0x2545_f491;
        for resolution in [12, 96, 128] {
            let table = PlaneTable::shared(resolution).unwrap();
            let texels = 6 * (resolution * resolution) as u32;
            for round in 0..20_000 {
                let codes: [[u32; LANES]; 3] =
                    std::array::from_fn(|_| std::array::from_fn(|_| table.code(next(&mut state) % texels)));
                let lanes = next(&mut state) & 0xff;
                let start = if round % 3 == 0 { Mask::EMPTY } else { table.mask_at(next(&mut state) % texels) };
                let mut expected = start;
                for i in (0..LANES).filter(|i| lanes >> i & 1 == 1) {
                    expected.or_assign(&table.triangle_of_codes([codes[0][i], codes[1][i], codes[2][i]]));
                }
                let mut portable = start;
                table.or_triangles_portable(&table.fetches(&codes), lanes, &mut portable);
                assert_eq!(portable, expected, "portable, resolution {resolution}, round {round}");
                #[cfg(target_arch = "x86_64")]
                if std::is_x86_feature_detected!("avx2") {
                    let mut simd = start;
                    // SAFETY: the CPU supports AVX2.
                    unsafe { table.or_triangles_avx2(&table.fetches(&codes), lanes, &mut simd) };
                    assert_eq!(simd, expected, "AVX2, resolution {resolution}, round {round}");
                }
                #[cfg(target_arch = "x86_64")]
                if std::is_x86_feature_detected!("avx512f") {
                    let mut wide = start;
                    // SAFETY: the CPU supports AVX-512F.
                    unsafe { table.or_triangles_avx512(&table.fetches(&codes), lanes, &mut wide) };
                    assert_eq!(wide, expected, "AVX-512, resolution {resolution}, round {round}");
                }
            }
        }
    }
}
