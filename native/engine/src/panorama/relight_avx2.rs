//! The AVX2 twin of `Relighter::block_portable`: 8 pixels (24 interleaved values, 3 vectors)
//! per step. Weights repeat every 3 values, so each map gets 3 weight vectors; a point
//! light's per-pixel factors are spread to the pixel's 3 values by a permutation. Same
//! operations in the same order as the portable code (no FMA), hence the same bits.

use std::arch::x86_64::*;

use super::relight::{Folded, Maps, Relighter};
use super::sh_lanes::LANES;

/// Lane l of vector v holds value v * 8 + l, i.e. pixel (v * 8 + l) / 3.
const SPREAD: [[i32; 8]; 3] = [[0, 0, 0, 1, 1, 1, 2, 2], [2, 3, 3, 3, 4, 4, 4, 5], [5, 5, 6, 6, 6, 7, 7, 7]];

#[target_feature(enable = "avx2,f16c")]
#[inline]
unsafe fn pattern(w: &[f32; 3]) -> [__m256; 3] {
    let mut out = [_mm256_setzero_ps(); 3];
    for (v, o) in out.iter_mut().enumerate() {
        let mut values = [0.0f32; 8];
        for (l, x) in values.iter_mut().enumerate() {
            *x = w[(v * 8 + l) % 3];
        }
        *o = _mm256_loadu_ps(values.as_ptr());
    }
    out
}

/// 24 bytes from p as floats.
#[target_feature(enable = "avx2,f16c")]
#[inline]
unsafe fn load24_u8(p: *const u8) -> [__m256; 3] {
    [
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(p as *const __m128i))),
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(p.add(8) as *const __m128i))),
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(p.add(16) as *const __m128i))),
    ]
}

/// 24 halves from p as floats.
#[target_feature(enable = "avx2,f16c")]
#[inline]
unsafe fn load24_f16(p: *const u16) -> [__m256; 3] {
    [
        _mm256_cvtph_ps(_mm_loadu_si128(p as *const __m128i)),
        _mm256_cvtph_ps(_mm_loadu_si128(p.add(8) as *const __m128i)),
        _mm256_cvtph_ps(_mm_loadu_si128(p.add(16) as *const __m128i)),
    ]
}

/// Blocks 0..blocks of row r (8 pixels each) into row[..blocks * 24].
#[target_feature(enable = "avx2,f16c")]
pub(crate) unsafe fn row(relighter: &Relighter, r: usize, folded: &Folded, row: &mut [f32], blocks: usize) {
    let k = relighter.coeffs;
    let uniform: Vec<[__m256; 3]> = folded.uniform.iter().map(|w| pattern(w)).collect();
    let base = pattern(&folded.base);
    let points: Vec<Vec<[__m256; 3]>> = folded.points.iter().map(|(_, ws, _)| ws.iter().map(|w| pattern(w)).collect()).collect();
    let spread = [
        _mm256_loadu_si256(SPREAD[0].as_ptr() as *const __m256i),
        _mm256_loadu_si256(SPREAD[1].as_ptr() as *const __m256i),
        _mm256_loadu_si256(SPREAD[2].as_ptr() as *const __m256i),
    ];
    let maps = relighter.maps();
    let mut raw = [[_mm256_setzero_ps(); 3]; 25];
    let mut t = [[0.0f32; LANES]; 25];
    let mut offsets = [0.0f32; 3 * LANES];
    for b in 0..blocks {
        let p = b * LANES;
        let mut acc = base;
        for i in 0..k {
            raw[i] = match maps {
                Maps::U8(m) => load24_u8(m.as_ptr().add(relighter.map_start(r, i) + p * 3)),
                Maps::F16(m) => load24_f16(m.as_ptr().add(relighter.map_start(r, i) + p * 3)),
            };
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
