//! The AVX2 twin of `Relighter::block_portable`: 8 pixels (24 interleaved values, 3 vectors)
//! per step. Weights repeat every 3 values, so each map gets 3 weight vectors; a point
//! light's per-pixel factors are spread to the pixel's 3 values by a permutation. Same
//! operations in the same order as the portable code (no FMA), hence the same bits.

use std::arch::x86_64::*;

use super::relight::{Folded, Maps, Relighter};
use super::sh_lanes::LANES;

/// Lane l of vector v holds value v * 8 + l, i.e. pixel (v * 8 + l) / 3.
const SPREAD: [[i32; 8]; 3] = [[0, 0, 0, 1, 1, 1, 2, 2], [2, 3, 3, 3, 4, 4, 4, 5], [5, 5, 6, 6, 6, 7, 7, 7]];

#[inline(always)]
unsafe fn pattern(w: &[f32; 3]) -> [__m256; 3] {
    std::array::from_fn(|v| {
        let values: [f32; 8] = std::array::from_fn(|l| w[(v * 8 + l) % 3]);
        _mm256_loadu_ps(values.as_ptr())
    })
}

/// The 24 raw values of map i from value index e (bytes or halves) as floats.
#[inline(always)]
unsafe fn load24(maps: &Maps, start: usize) -> [__m256; 3] {
    match maps {
        Maps::U8(m) => {
            let p = m.as_ptr().add(start);
            std::array::from_fn(|v| _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(p.add(8 * v) as *const __m128i))))
        }
        Maps::F16(m) => {
            let p = m.as_ptr().add(start);
            std::array::from_fn(|v| _mm256_cvtph_ps(_mm_loadu_si128(p.add(8 * v) as *const __m128i)))
        }
    }
}

/// Blocks 0..blocks of row r (8 pixels each) into row[..blocks * 24].
#[target_feature(enable = "avx2,f16c")]
pub(crate) unsafe fn row(relighter: &Relighter, r: usize, folded: &Folded, row: &mut [f32], blocks: usize) {
    let k = relighter.coeffs;
    let plane = relighter.width * relighter.height * 3;
    let uniform: Vec<[__m256; 3]> = folded.uniform.iter().map(|w| pattern(w)).collect();
    let base = pattern(&folded.base);
    let points: Vec<Vec<[__m256; 3]>> = folded.points.iter().map(|(_, ws, _)| ws.iter().map(|w| pattern(w)).collect()).collect();
    let spread: [__m256i; 3] = std::array::from_fn(|v| _mm256_loadu_si256(SPREAD[v].as_ptr() as *const __m256i));
    let maps = relighter.maps();
    let mut raw = [[_mm256_setzero_ps(); 3]; 25];
    let mut t = [[0.0f32; LANES]; 25];
    let mut offsets = [0.0f32; 3 * LANES];
    for b in 0..blocks {
        let p = b * LANES;
        let first = (r * relighter.width + p) * 3;
        let mut acc = base;
        for i in 0..k {
            raw[i] = load24(maps, i * plane + first);
            for v in 0..3 {
                acc[v] = _mm256_add_ps(acc[v], _mm256_mul_ps(uniform[i][v], raw[i][v]));
            }
        }
        for ((light, _, wo), ws) in folded.points.iter().zip(&points) {
            relighter.point_lanes(r, p, LANES, light, wo, &mut t, &mut offsets);
            let mut sum = [_mm256_setzero_ps(); 3];
            for i in 0..k {
                let ti = _mm256_loadu_ps(t[i].as_ptr());
                for v in 0..3 {
                    let product = _mm256_mul_ps(_mm256_permutevar8x32_ps(ti, spread[v]), ws[i][v]);
                    sum[v] = _mm256_add_ps(sum[v], _mm256_mul_ps(product, raw[i][v]));
                }
            }
            for v in 0..3 {
                acc[v] = _mm256_add_ps(acc[v], _mm256_add_ps(sum[v], _mm256_loadu_ps(offsets.as_ptr().add(8 * v))));
            }
        }
        let out = row.as_mut_ptr().add(p * 3);
        for v in 0..3 {
            _mm256_storeu_ps(out.add(8 * v), acc[v]);
        }
    }
}
