//! `Pipeline::rasterize_packet`'s arithmetic for one packet in AVX2 registers: the corners
//! moved into the receiver's frame, the horizon, low-band and own-triangle tests, and the
//! table codes of the edge planes (`edge_codes`, also for the scene's batches). The compiler's vectorisation
//! of the portable loops spilled lanes to the stack and rebuilt the lane bits from scalar
//! compares; this is the same sequence of operations lane by lane (multiplies and adds, never
//! fused), so the codes and lanes are bit-identical to the portable path's.

use std::arch::x86_64::*;

use crate::disk_mask::Mask;
use crate::packets::{Packet, LANES};
use crate::plane_table::PlaneTable;

use super::{LocalCorners, Pipeline, Viewer, FLAT_CONE_SQUARED, LOW_BAND_Z};

type V3 = [__m256; 3];

#[inline(always)]
unsafe fn dot(a: V3, b: V3) -> __m256 {
    _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])), _mm256_mul_ps(a[2], b[2]))
}

#[inline(always)]
unsafe fn cross(a: V3, b: V3) -> V3 {
    [
        _mm256_sub_ps(_mm256_mul_ps(a[1], b[2]), _mm256_mul_ps(a[2], b[1])),
        _mm256_sub_ps(_mm256_mul_ps(a[2], b[0]), _mm256_mul_ps(a[0], b[2])),
        _mm256_sub_ps(_mm256_mul_ps(a[0], b[1]), _mm256_mul_ps(a[1], b[0])),
    ]
}

#[inline(always)]
unsafe fn splat(v: [f32; 3]) -> V3 {
    [_mm256_set1_ps(v[0]), _mm256_set1_ps(v[1]), _mm256_set1_ps(v[2])]
}

/// Corner `k` of every lane of `packet` in the frame (t, b, n) at `o`.
#[inline(always)]
unsafe fn local_corner(packet: &Packet, k: usize, o: V3, [t, b, n]: [V3; 3]) -> V3 {
    let c = &packet.corners[k];
    let d = [
        _mm256_sub_ps(_mm256_loadu_ps(c[0].as_ptr()), o[0]),
        _mm256_sub_ps(_mm256_loadu_ps(c[1].as_ptr()), o[1]),
        _mm256_sub_ps(_mm256_loadu_ps(c[2].as_ptr()), o[2]),
    ];
    [dot(d, t), dot(d, b), dot(d, n)]
}

/// Lanes of `packet` with corner `k` the vertex `exclude`, as a lane mask.
#[inline(always)]
unsafe fn is_vertex(packet: &Packet, k: usize, exclude: __m256i) -> __m256i {
    _mm256_cmpeq_epi32(_mm256_loadu_si256(packet.ids[k].as_ptr() as *const __m256i), exclude)
}

/// `Pipeline::rasterize_batch` in AVX2 registers: one function compiled for AVX2, into which
/// the packet arithmetic and the drain inline.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn rasterize_batch(pipeline: &mut Pipeline, table: &PlaneTable, viewer: &Viewer, batch: &[(&Packet, u32)], mask: &mut Mask) -> u32 {
    let mut drawn = 0;
    for &(packet, lanes) in batch {
        drawn += pipeline.rasterize_viewed::<true>(table, viewer, packet, lanes, mask);
    }
    drawn
}

/// `super::packet_codes` in AVX2 registers.
#[inline]
#[target_feature(enable = "avx2")]
pub unsafe fn packet_codes(table: &PlaneTable, viewer: &Viewer, packet: &Packet, lanes: u32, codes: &mut [[u32; LANES]; 3]) -> (u32, u32) {
    packet_codes_inlined(table, viewer, packet, lanes, codes)
}

/// `packet_codes` for kernels compiled for AVX2, into which it inlines (no closures: those
/// would be compiled without AVX2 and keep the intrinsics as calls).
#[inline(always)]
pub(super) unsafe fn packet_codes_inlined(table: &PlaneTable, viewer: &Viewer, packet: &Packet, lanes: u32, codes: &mut [[u32; LANES]; 3]) -> (u32, u32) {
    let Viewer { origin, frame, exclude } = *viewer;
    let (o, axes) = (splat(origin), [splat(frame.t), splat(frame.b), splat(frame.n)]);
    let (pa, pb, pc) = (local_corner(packet, 0, o, axes), local_corner(packet, 1, o, axes), local_corner(packet, 2, o, axes));
    let zero = _mm256_setzero_ps();
    let above = _mm256_or_ps(
        _mm256_or_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(pa[2], zero), _mm256_cmp_ps::<_CMP_GT_OQ>(pb[2], zero)),
        _mm256_cmp_ps::<_CMP_GT_OQ>(pc[2], zero),
    );
    let above = _mm256_andnot_ps(below_low_band([pa, pb, pc]), above);
    let ex = _mm256_set1_epi32(exclude as i32);
    let own = _mm256_or_si256(_mm256_or_si256(is_vertex(packet, 0, ex), is_vertex(packet, 1, ex)), is_vertex(packet, 2, ex));
    let own = _mm256_castsi256_ps(own);
    let keep = _mm256_movemask_ps(_mm256_andnot_ps(own, above)) as u32 & lanes;
    if keep == 0 {
        return (0, 0);
    }
    (keep, solid_codes(table, [pa, pb, pc], codes))
}

/// `super::below_low_band` of every lane, as a lane mask.
#[inline(always)]
unsafe fn below_low_band([pa, pb, pc]: [V3; 3]) -> __m256 {
    let s: V3 = [
        _mm256_add_ps(_mm256_add_ps(pa[0], pb[0]), pc[0]),
        _mm256_add_ps(_mm256_add_ps(pa[1], pb[1]), pc[1]),
        _mm256_add_ps(_mm256_add_ps(pa[2], pb[2]), pc[2]),
    ];
    let near = _mm256_min_ps(_mm256_min_ps(dot(pa, s), dot(pb, s)), dot(pc, s));
    let top = _mm256_max_ps(_mm256_max_ps(pa[2], pb[2]), pc[2]);
    let height = _mm256_mul_ps(_mm256_mul_ps(top, top), dot(s, s));
    let bound = _mm256_mul_ps(_mm256_set1_ps(LOW_BAND_Z * LOW_BAND_Z), _mm256_mul_ps(near, near));
    _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(near, _mm256_setzero_ps()), _mm256_cmp_ps::<_CMP_LT_OQ>(height, bound))
}

/// `edge_codes` in AVX2 registers, for batches of corners already in a receiver's frame (the
/// scene's walk).
#[inline]
#[target_feature(enable = "avx2")]
pub unsafe fn edge_codes(table: &PlaneTable, corners: &LocalCorners, codes: &mut [[u32; LANES]; 3]) -> u32 {
    let corner = |k: usize| -> V3 { std::array::from_fn(|j| _mm256_loadu_ps(corners[k][j].as_ptr())) };
    solid_codes(table, [corner(0), corner(1), corner(2)], codes)
}

/// The codes of the three edge planes of every lane of `[a, b, c]` into `codes`, and the bit
/// set of lanes whose cone has a solid angle (`edge_codes`).
#[inline(always)]
unsafe fn solid_codes(table: &PlaneTable, [pa, pb, pc]: [V3; 3], codes: &mut [[u32; LANES]; 3]) -> u32 {
    let (ab, bc, ca) = (cross(pa, pb), cross(pb, pc), cross(pc, pa));
    let det = dot(ab, pc);
    let scale = _mm256_mul_ps(_mm256_mul_ps(dot(pa, pa), dot(pb, pb)), dot(pc, pc));
    let solid = _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_mul_ps(det, det), _mm256_mul_ps(_mm256_set1_ps(FLAT_CONE_SQUARED), scale));
    // Orient the edge planes so that the opposite vertex is on their positive side: a sign
    // flip is the portable path's multiply by -1.
    let flip = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(det, _mm256_setzero_ps()), _mm256_set1_ps(-0.0));
    for (e, [x, y, z]) in [ab, bc, ca].into_iter().enumerate() {
        let code = table.codes_avx2(_mm256_xor_ps(x, flip), _mm256_xor_ps(y, flip), _mm256_xor_ps(z, flip));
        _mm256_storeu_si256(codes[e].as_mut_ptr() as *mut __m256i, code);
    }
    _mm256_movemask_ps(solid) as u32
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::{edge_codes_portable, packet_codes_portable};
    use super::*;
    use crate::integrate::Frame;

    /// Reproducible random corners (`test_random`).
    pub(in crate::rasterizer) struct Corners(pub u32);

    impl Corners {
        /// A packet of eight random lanes (`corner`); every fifth round, odd kinds of corners.
        pub(in crate::rasterizer) fn packet(&mut self, round: u32) -> Packet {
            let mut packet = Packet { corners: [[[0.0; LANES]; 3]; 3], ids: [[0; LANES]; 3], lanes: 0xff, bounds: [[0.0; 3]; 2] };
            for i in 0..LANES {
                let kind = if round.is_multiple_of(5) { self.0 >> 3 } else { 7 };
                for k in 0..3 {
                    let c = self.corner(if k == 0 { kind } else { 7 });
                    (0..3).for_each(|j| packet.corners[k][j][i] = c[j]);
                    packet.ids[k][i] = self.0 % 64;
                }
            }
            packet
        }

        /// A receiver's tangent frame, its normal mostly up, and its origin near zero.
        pub(in crate::rasterizer) fn frame(&mut self) -> (Frame, [f32; 3]) {
            let n = {
                let v = [self.next(), self.next(), self.next() + 2.0];
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                v.map(|c| c / l)
            };
            let (t, b) = crate::mesh::tangent_frame(n);
            (Frame { t, b, n }, [self.next() * 0.1, self.next() * 0.1, self.next() * 0.1])
        }

        pub(in crate::rasterizer) fn next(&mut self) -> f32 {
            crate::test_random::xorshift32(&mut self.0) as f32 / u32::MAX as f32 * 2.0 - 1.0
        }

        /// Lane i of a packet: mostly random triangles at every scale, some tiny, some
        /// degenerate, some through the receiver, some with a NaN or an infinite corner.
        fn corner(&mut self, lane_kind: u32) -> [f32; 3] {
            let p = [self.next(), self.next(), self.next()];
            match lane_kind % 8 {
                0 => p.map(|c| c * 1e-3 + 0.5),
                1 => [0.0; 3],
                2 => [p[0], f32::NAN, p[2]],
                3 => [f32::INFINITY, p[1], p[2]],
                4 => p.map(|c| c * 1e4),
                _ => p,
            }
        }
    }

    #[test]
    fn avx2_codes_equal_the_portable_ones() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = Corners(0x9e37_79b9);
        for resolution in [12, 96, 128, 512] {
            let table = PlaneTable::shared(resolution).unwrap();
            for round in 0..50_000u32 {
                let packet = rng.packet(round);
                let (frame, origin) = rng.frame();
                let viewer = Viewer { origin, frame: &frame, exclude: rng.0 % 64 };
                let lanes = rng.0 & 0xff;
                let (mut portable, mut simd) = ([[7u32; LANES]; 3], [[7u32; LANES]; 3]);
                let expected = packet_codes_portable(&table, &viewer, &packet, lanes, &mut portable);
                // SAFETY: the CPU supports AVX2 (checked above).
                let got = unsafe { packet_codes(&table, &viewer, &packet, lanes, &mut simd) };
                assert_eq!(got, expected, "resolution {resolution}, round {round}: lanes to draw, solid lanes");
                assert_eq!(simd, portable, "resolution {resolution}, round {round}: codes");
                // The same corners as a batch already in a receiver's frame (the scene's).
                let expected = edge_codes_portable(&table, &packet.corners, &mut portable);
                // SAFETY: as above.
                let got = unsafe { edge_codes(&table, &packet.corners, &mut simd) };
                assert_eq!((got, simd), (expected, portable), "resolution {resolution}, round {round}: edge codes");
            }
        }
    }
}
