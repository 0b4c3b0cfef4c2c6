//! `Pipeline::rasterize_batch` for CPUs with AVX-512: the packets' arithmetic two packets at a
//! time in 512-bit registers (sixteen lanes), and the masks OR-ed as two 512-bit words with
//! ternary logic (`PlaneTable::accumulate_avx512`), kept in registers over the whole batch.
//! The same operations lane by lane as the portable and AVX2 paths (multiplies and adds,
//! never fused; `max` and `min` with the bound second), so the codes, lanes and masks are the
//! same bit for bit.
//!
//! Like the `Pipeline`, the kernel ORs a pair's masks only once the next pair's codes are
//! known, but it does not prefetch them: on an AMD EPYC with Zen 5, the prefetches took 15 %
//! longer solves and saved nothing, even in the AVX2 kernel (docs/solver_speed.md).

use std::arch::x86_64::*;

use crate::disk_mask::Mask;
use crate::packets::{Packet, LANES};
use crate::plane_table::{Fetches, PlaneTable};

use super::{Viewer, FLAT_CONE_SQUARED, LOW_BAND_Z};

type V3 = [__m512; 3];

/// Two packets' lanes.
const WIDE: usize = 2 * LANES;

#[inline(always)]
unsafe fn dot(a: V3, b: V3) -> __m512 {
    _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(a[0], b[0]), _mm512_mul_ps(a[1], b[1])), _mm512_mul_ps(a[2], b[2]))
}

#[inline(always)]
unsafe fn cross(a: V3, b: V3) -> V3 {
    [
        _mm512_sub_ps(_mm512_mul_ps(a[1], b[2]), _mm512_mul_ps(a[2], b[1])),
        _mm512_sub_ps(_mm512_mul_ps(a[2], b[0]), _mm512_mul_ps(a[0], b[2])),
        _mm512_sub_ps(_mm512_mul_ps(a[0], b[1]), _mm512_mul_ps(a[1], b[0])),
    ]
}

#[inline(always)]
unsafe fn splat(v: [f32; 3]) -> V3 {
    [_mm512_set1_ps(v[0]), _mm512_set1_ps(v[1]), _mm512_set1_ps(v[2])]
}

/// Eight lanes of `low` and eight of `high` in one register.
#[inline(always)]
unsafe fn pair(low: &[f32; LANES], high: &[f32; LANES]) -> __m512 {
    _mm512_insertf32x8::<1>(_mm512_castps256_ps512(_mm256_loadu_ps(low.as_ptr())), _mm256_loadu_ps(high.as_ptr()))
}

/// Corner `k` of every lane of both packets in the frame (t, b, n) at `o`.
#[inline(always)]
unsafe fn local_corner([p, q]: [&Packet; 2], k: usize, o: V3, [t, b, n]: [V3; 3]) -> V3 {
    let d: V3 = std::array::from_fn(|j| _mm512_sub_ps(pair(&p.corners[k][j], &q.corners[k][j]), o[j]));
    [dot(d, t), dot(d, b), dot(d, n)]
}

/// Lanes of both packets with corner `k` the vertex `exclude`.
#[inline(always)]
unsafe fn is_vertex([p, q]: [&Packet; 2], k: usize, exclude: __m512i) -> __mmask16 {
    let ids = _mm512_inserti32x8::<1>(
        _mm512_castsi256_si512(_mm256_loadu_si256(p.ids[k].as_ptr() as *const __m256i)),
        _mm256_loadu_si256(q.ids[k].as_ptr() as *const __m256i),
    );
    _mm512_cmpeq_epi32_mask(ids, exclude)
}

/// `rasterize_batch` with the packets' arithmetic done two packets at a time (an odd last
/// packet is paired with itself, its copy drawing no lane), and the masks of a pair OR-ed
/// while the next pair's codes are computed.
#[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq")]
pub(super) unsafe fn rasterize_batch(table: &PlaneTable, viewer: &Viewer, batch: &[(&Packet, u32)], mask: &mut Mask) -> u32 {
    let mut fetches = [Fetches::<WIDE>::default(); 2];
    let (mut pending, mut pending_lanes) = (0, 0);
    let mut acc = [_mm512_setzero_si512(); 2];
    let mut drawn = 0;
    for two in batch.chunks(2) {
        let (p, p_lanes) = two[0];
        let (q, q_lanes) = two.get(1).copied().unwrap_or((p, 0));
        let lanes = (p_lanes & p.lanes) | (q_lanes & q.lanes) << LANES;
        let (corners, keep) = kept_corners(viewer, [p, q], lanes);
        if keep == 0 {
            continue;
        }
        drawn += keep.count_ones();
        let (codes, solid) = solid_codes(table, corners);
        let next = 1 - pending;
        fetches[next] = table.fetches_avx512(codes);
        table.accumulate_avx512(&fetches[pending], pending_lanes, &mut acc);
        (pending, pending_lanes) = (next, keep as u32 & solid);
    }
    table.accumulate_avx512(&fetches[pending], pending_lanes, &mut acc);
    table.finish_avx512(acc, mask);
    drawn
}

/// Both packets' corners in the receiver's frame, and the bits of the lanes to draw
/// (`avx2::packet_codes_inlined`'s tests; packet `q` in bits 8 to 15).
#[inline(always)]
unsafe fn kept_corners(viewer: &Viewer, packets: [&Packet; 2], lanes: u32) -> ([V3; 3], __mmask16) {
    let Viewer { origin, frame, exclude } = *viewer;
    let (o, axes) = (splat(origin), [splat(frame.t), splat(frame.b), splat(frame.n)]);
    let corners = [0, 1, 2].map(|k| local_corner(packets, k, o, axes));
    let zero = _mm512_setzero_ps();
    let above = corners.iter().fold(0, |above, c| above | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(c[2], zero));
    let ex = _mm512_set1_epi32(exclude as i32);
    let own = is_vertex(packets, 0, ex) | is_vertex(packets, 1, ex) | is_vertex(packets, 2, ex);
    (corners, above & !below_low_band(corners) & !own & lanes as __mmask16)
}

/// `super::below_low_band` of every lane.
#[inline(always)]
unsafe fn below_low_band([pa, pb, pc]: [V3; 3]) -> __mmask16 {
    let s: V3 = std::array::from_fn(|j| _mm512_add_ps(_mm512_add_ps(pa[j], pb[j]), pc[j]));
    let near = _mm512_min_ps(_mm512_min_ps(dot(pa, s), dot(pb, s)), dot(pc, s));
    let top = _mm512_max_ps(_mm512_max_ps(pa[2], pb[2]), pc[2]);
    let height = _mm512_mul_ps(_mm512_mul_ps(top, top), dot(s, s));
    let bound = _mm512_mul_ps(_mm512_set1_ps(LOW_BAND_Z * LOW_BAND_Z), _mm512_mul_ps(near, near));
    _mm512_cmp_ps_mask::<_CMP_GT_OQ>(near, _mm512_setzero_ps()) & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(height, bound)
}

/// The codes of the three edge planes of every lane (`[edge]`), and the bits of the lanes
/// whose cone has a solid angle (`avx2::solid_codes`).
#[inline(always)]
unsafe fn solid_codes(table: &PlaneTable, [pa, pb, pc]: [V3; 3]) -> ([__m512i; 3], u32) {
    let (ab, bc, ca) = (cross(pa, pb), cross(pb, pc), cross(pc, pa));
    let det = dot(ab, pc);
    let scale = _mm512_mul_ps(_mm512_mul_ps(dot(pa, pa), dot(pb, pb)), dot(pc, pc));
    let solid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(_mm512_mul_ps(det, det), _mm512_mul_ps(_mm512_set1_ps(FLAT_CONE_SQUARED), scale));
    // Orient the edge planes so that the opposite vertex is on their positive side.
    let negative = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(det, _mm512_setzero_ps());
    let flip = _mm512_castsi512_ps(_mm512_maskz_mov_epi32(negative, _mm512_set1_epi32(i32::MIN)));
    let codes = [ab, bc, ca].map(|[x, y, z]| table.codes_avx512(_mm512_xor_ps(x, flip), _mm512_xor_ps(y, flip), _mm512_xor_ps(z, flip)));
    (codes, solid as u32)
}

#[cfg(test)]
mod tests {
    use super::super::avx2::tests::Corners;
    use super::super::{avx2, has_avx512, packet_codes_portable, Pipeline};
    use super::*;

    /// `kept_corners` and `solid_codes` for a pair of packets, in a function compiled for them:
    /// the lanes to draw, the solid ones, and the codes `[packet][edge][lane]`.
    #[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq")]
    unsafe fn pair_codes(table: &PlaneTable, viewer: &Viewer, packets: [&Packet; 2], lanes: u32) -> (u32, u32, [[[u32; LANES]; 3]; 2]) {
        let (corners, keep) = kept_corners(viewer, packets, lanes);
        let (codes, solid) = solid_codes(table, corners);
        let mut out = [[[0; LANES]; 3]; 2];
        for (e, code) in codes.into_iter().enumerate() {
            let mut wide = [0u32; WIDE];
            _mm512_storeu_si512(wide.as_mut_ptr() as *mut __m512i, code);
            (out[0][e], out[1][e]) = (wide[..LANES].try_into().unwrap(), wide[LANES..].try_into().unwrap());
        }
        (keep as u32, solid, out)
    }

    #[test]
    fn pairs_give_the_portable_lanes_and_codes() {
        if !has_avx512() {
            return;
        }
        let mut rng = Corners(0x85eb_ca6b);
        for resolution in [12, 96, 128, 512] {
            let table = PlaneTable::shared(resolution).unwrap();
            for round in 0..25_000u32 {
                let packets = [rng.packet(round), rng.packet(round + 1)];
                let (frame, origin) = rng.frame();
                let viewer = Viewer { origin, frame: &frame, exclude: rng.0 % 64 };
                let lanes = rng.0 & 0xffff;
                // SAFETY: the CPU supports AVX-512 (checked above).
                let (keep, solid, codes) = unsafe { pair_codes(&table, &viewer, [&packets[0], &packets[1]], lanes) };
                for (h, packet) in packets.iter().enumerate() {
                    let mut portable = [[7u32; LANES]; 3];
                    let (candidates, portable_solid) = packet_codes_portable(&table, &viewer, packet, lanes >> (LANES * h) & 0xff, &mut portable);
                    assert_eq!(keep >> (LANES * h) & 0xff, candidates, "resolution {resolution}, round {round}, packet {h}: lanes to draw");
                    if candidates != 0 {
                        assert_eq!(solid >> (LANES * h) & 0xff, portable_solid, "resolution {resolution}, round {round}, packet {h}: solid lanes");
                        assert_eq!(codes[h], portable, "resolution {resolution}, round {round}, packet {h}: codes");
                    }
                }
            }
        }
    }

    #[test]
    fn batches_draw_the_avx2_masks() {
        if !has_avx512() {
            return;
        }
        let mut rng = Corners(0x27d4_eb2f);
        for resolution in [12, 128] {
            let table = PlaneTable::shared(resolution).unwrap();
            for round in 0..5_000u32 {
                let packets: Vec<Packet> = (0..1 + rng.0 % 5).map(|i| rng.packet(round + i)).collect();
                let batch: Vec<(&Packet, u32)> = packets.iter().map(|p| (p, crate::test_random::xorshift32(&mut rng.0) & 0xff)).collect();
                let (frame, origin) = rng.frame();
                let viewer = Viewer { origin, frame: &frame, exclude: rng.0 % 64 };
                let start = if round % 4 == 0 { Mask::EMPTY } else { table.mask_at(rng.0 % (6 * resolution * resolution) as u32) };
                let mut wide = start;
                // SAFETY: the CPU supports AVX2 and AVX-512 (checked above).
                let wide_drawn = unsafe { rasterize_batch(&table, &viewer, &batch, &mut wide) };
                let (mut pipeline, mut narrow) = (Pipeline::default(), start);
                // SAFETY: as above.
                let narrow_drawn = unsafe { avx2::rasterize_batch(&mut pipeline, &table, &viewer, &batch, &mut narrow) };
                pipeline.drain(&table, &mut narrow);
                assert_eq!((wide_drawn, wide), (narrow_drawn, narrow), "resolution {resolution}, round {round}, {} packets", batch.len());
            }
        }
    }
}
