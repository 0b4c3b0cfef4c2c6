//! The look-up table of half-space masks (Kautz et al. 2004, section 3.1.1).
//!
//! A plane through the receiver is given by its normal m; its mask has the cells whose sample
//! direction d satisfies m.d >= 0. Normals are quantised by a cube map of 6 x R x R texels
//! (the paper's R = 128 gives 12 MiB); each texel stores the mask of the plane through its
//! centre direction. Opposite normals map to mirrored texels, so two triangles sharing an edge
//! get complementary masks along it (no crack, no overlap); at power-of-two resolutions a
//! mirrored texel's mask is the complement bit for bit, so only the three positive faces are
//! stored (6 MiB at 128) and a negative face's mask is its mirror's complement, made at each
//! fetch. The lookup rounds a normal and its opposite apart only when a coordinate lands
//! within an ulp of a texel boundary (u s + R/2 and R/2 - u s round on grids of different
//! steps): 287 of 20 million random normals at 128, each leaving a sliver of cells open or
//! covered twice along that edge. Around a shared vertex the rounded planes of different
//! edges need not meet in one point, which can leave a sliver open: finely tessellated
//! blockers seen at grazing angles leak a little light (see docs/algorithm.md). Widening every
//! mask by the quantisation angle closes those slivers but was measured to over-occlude real
//! meshes far more (spot: median error 2 % -> 8 %). Tables are built once per resolution and
//! shared by all threads.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use crate::disk_mask::{cell_direction, Mask, MASK_SIDE, MASK_WORDS};
use crate::error::{Error, Result};
use crate::large_pages::LargePageVec;
use crate::packets::LANES;

mod drain;

/// The paper's 6 x 128 x 128 texels (12 MiB, of which 6 are stored). 64 (a quarter of the
/// memory) measured 1.06-1.7x faster for +0.03 to +0.33 percentage points of median error
/// (docs/benchmarks.md), but its coarser planes double the worst per-vertex change under
/// rounding (AO 0.011 where the scale-invariance bound of tests/test_solver_trust.py is
/// 0.005): an option, not the default.
pub const DEFAULT_RESOLUTION: usize = 128;

pub struct PlaneTable {
    resolution: usize,
    /// Every face, or only the positive ones (see `Codes`).
    masks: LargePageVec<Mask>,
    codes: Codes,
    /// What a code's mask is XOR-ed with, by its `COMPLEMENT` bit: nothing, or the disk's
    /// cells (a negative face's mask is its mirror's complement within the disk).
    flips: [Mask; 2],
}

/// Where the mask of a texel (face 2a or 2a + 1 for axis a, index `within` its face of F =
/// R^2 texels) is stored. Every face stored: at texel order. Only the positive faces (at
/// power-of-two resolutions): texel (2a + 1, R - 1 - i, R - 1 - j) is the mirror of
/// (2a, i, j), whose index within the face is the mirror's XOR (F - 1), and its mask the
/// complement. One mapping for the lane-parallel `codes` and the single `code`.
#[derive(Clone, Copy)]
struct Codes {
    axis_stride: u32,
    /// Added for a negative face (0 when it is mirrored onto the positive one).
    negative_offset: u32,
    /// XOR-ed into a negative face's index within its face.
    flip: u32,
    /// OR-ed into a negative face's code.
    complement: u32,
}

impl Codes {
    fn new(resolution: usize, mirrored: bool) -> Self {
        let face = (resolution * resolution) as u32;
        match mirrored {
            true => Codes { axis_stride: face, negative_offset: 0, flip: face - 1, complement: COMPLEMENT },
            false => Codes { axis_stride: 2 * face, negative_offset: face, flip: 0, complement: 0 },
        }
    }

    /// The code of the texel `within` the face of `axis` (`negative`: all ones for the
    /// negative face, else 0), written with selects so that it vectorises.
    #[inline(always)]
    fn of(self, axis: u32, negative: u32, within: u32) -> u32 {
        (axis * self.axis_stride + (negative & self.negative_offset) + (within ^ (negative & self.flip)))
            | (negative & self.complement)
    }
}

/// Cube-map face and texel of a direction; the major axis picks the face.
#[inline(always)]
fn texel_of(m: [f32; 3], resolution: usize) -> usize {
    let [x, y, z] = m;
    let (ax, ay, az) = (x.abs(), y.abs(), z.abs());
    // Selects rather than branches: plane normals are random, so branches would mispredict.
    let x_major = ax >= ay && ax >= az;
    let y_major = !x_major && ay >= az;
    let axis = if x_major { 0 } else if y_major { 1 } else { 2 };
    let major = if x_major { ax } else if y_major { ay } else { az };
    let sign_negative = (if x_major { x } else if y_major { y } else { z }) < 0.0;
    let u = if x_major { y } else { x };
    let v = if x_major || y_major { z } else { y };
    let face = 2 * axis + sign_negative as usize;
    let half = 0.5 * resolution as f32;
    let scale = half / major;
    // Float-to-int casts saturate, so a zero or NaN normal still lands inside the table.
    let i = ((u * scale + half) as usize).min(resolution - 1);
    let j = ((v * scale + half) as usize).min(resolution - 1);
    (face * resolution + j) * resolution + i
}

/// Centre direction (not normalised) of a texel.
#[inline(always)]
fn texel_direction(face: usize, i: usize, j: usize, resolution: usize) -> [f32; 3] {
    let u = -1.0 + (i as f32 + 0.5) * 2.0 / resolution as f32;
    let v = -1.0 + (j as f32 + 0.5) * 2.0 / resolution as f32;
    let sign = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    match face / 2 {
        0 => [sign, u, v],
        1 => [u, sign, v],
        _ => [u, v, sign],
    }
}

/// The disk's cell directions by mask word: bit k of word w is cell 64 w + k (row-major),
/// with its direction in lane k (zero outside the disk, where `inside` clears the bit).
struct CellWords {
    x: [[f32; 64]; MASK_WORDS],
    y: [[f32; 64]; MASK_WORDS],
    z: [[f32; 64]; MASK_WORDS],
    inside: [u64; MASK_WORDS],
}

impl CellWords {
    fn new() -> Self {
        let mut words = CellWords { x: [[0.0; 64]; MASK_WORDS], y: [[0.0; 64]; MASK_WORDS], z: [[0.0; 64]; MASK_WORDS], inside: [0; MASK_WORDS] };
        for row in 0..MASK_SIDE {
            for col in 0..MASK_SIDE {
                if let Some(d) = cell_direction(row, col) {
                    let (w, k) = ((row * MASK_SIDE + col) / 64, (row * MASK_SIDE + col) % 64);
                    (words.x[w][k], words.y[w][k], words.z[w][k]) = (d[0], d[1], d[2]);
                    words.inside[w] |= 1 << k;
                }
            }
        }
        words
    }

    /// The cells on the positive side of the plane with normal m: the same sums, in the same
    /// order, as a cell-by-cell test, written lane-parallel so that the table (393,216 masks
    /// at resolution 256, built at every process's first scene query) builds in vector code.
    #[inline(always)]
    fn half_space(&self, m: [f32; 3]) -> Mask {
        let mut mask = Mask::EMPTY;
        for w in 0..MASK_WORDS {
            let (x, y, z) = (&self.x[w], &self.y[w], &self.z[w]);
            let mut dots = [0.0f32; 64];
            for k in 0..64 {
                dots[k] = m[0] * x[k] + m[1] * y[k] + m[2] * z[k];
            }
            // Eight lanes to a byte: a compare and a move-mask each.
            let mut bits = 0u64;
            for (b, lanes) in dots.chunks_exact(8).enumerate() {
                let byte = lanes.iter().enumerate().fold(0u64, |byte, (j, &d)| byte | ((d >= 0.0) as u64) << j);
                bits |= byte << (8 * b);
            }
            mask.0[w] = bits & self.inside[w];
        }
        mask
    }

    /// `half_space` of every texel of `masks` (table index `first` on), compiled for AVX2 as
    /// well and picked at run time.
    fn fill(&self, masks: &mut [Mask], first: usize, resolution: usize) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports the feature the function is compiled for.
            return unsafe { self.fill_avx2(masks, first, resolution) };
        }
        self.fill_portable(masks, first, resolution)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn fill_avx2(&self, masks: &mut [Mask], first: usize, resolution: usize) {
        for (offset, mask) in masks.iter_mut().enumerate() {
            let (face, i, j) = texel_coordinates(first + offset, resolution);
            *mask = self.half_space_avx2(texel_direction(face, i, j, resolution));
        }
    }

    /// `half_space` in AVX2 registers: the same products and sums in the same order (no fused
    /// multiply-add), so the same bits, with a compare and a move-mask per eight cells. The
    /// compiler's version of the portable loop packed the bits one at a time: the table (a
    /// fresh process's first solve or scene query) took about 0.15 s of CPU at 128.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn half_space_avx2(&self, m: [f32; 3]) -> Mask {
        use std::arch::x86_64::*;
        let (mx, my, mz) = (_mm256_set1_ps(m[0]), _mm256_set1_ps(m[1]), _mm256_set1_ps(m[2]));
        let zero = _mm256_setzero_ps();
        let mut mask = Mask::EMPTY;
        for w in 0..MASK_WORDS {
            let mut bits = 0u64;
            for b in 0..8 {
                // SAFETY: lanes 8 b .. 8 b + 8 lie inside each 64-lane row.
                let (x, y, z) = (
                    _mm256_loadu_ps(self.x[w].as_ptr().add(8 * b)),
                    _mm256_loadu_ps(self.y[w].as_ptr().add(8 * b)),
                    _mm256_loadu_ps(self.z[w].as_ptr().add(8 * b)),
                );
                let dots = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(mx, x), _mm256_mul_ps(my, y)), _mm256_mul_ps(mz, z));
                let byte = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(dots, zero)) as u32 as u64;
                bits |= byte << (8 * b);
            }
            mask.0[w] = bits & self.inside[w];
        }
        mask
    }

    fn fill_portable(&self, masks: &mut [Mask], first: usize, resolution: usize) {
        for (offset, mask) in masks.iter_mut().enumerate() {
            let (face, i, j) = texel_coordinates(first + offset, resolution);
            *mask = self.half_space(texel_direction(face, i, j, resolution));
        }
    }
}

/// Face and texel (i, j) of table index `index`.
#[inline(always)]
fn texel_coordinates(index: usize, resolution: usize) -> (usize, usize, usize) {
    let (face, rest) = (index / (resolution * resolution), index % (resolution * resolution));
    (face, rest % resolution, rest / resolution)
}

const CHUNK: usize = 1024;

fn fill_every_texel(cells: &CellWords, masks: &mut [Mask], first: usize, resolution: usize) {
    masks.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| cells.fill(chunk, first + c * CHUNK, resolution));
}

/// The positive faces 0, 2, 4 of the whole table, stored one after the other.
fn fill_positive_faces(cells: &CellWords, masks: &mut [Mask], resolution: usize) {
    let face = resolution * resolution;
    for (pair, positive) in masks.chunks_mut(face).enumerate() {
        fill_every_texel(cells, positive, 2 * pair * face, resolution);
    }
}

impl PlaneTable {
    pub fn build(resolution: usize) -> Result<Self> {
        if !(4..=512).contains(&resolution) {
            return Err(Error::invalid(format!(
                "plane table resolution must be between 4 and 512, got {resolution}"
            )));
        }
        let cells = CellWords::new();
        let disk = Mask(cells.inside);
        let texels = 6 * resolution * resolution;
        if resolution.is_power_of_two() {
            // The mirror's exact complement: each dot product is exactly negated, since the
            // centre coordinates -1 + (i + 0.5) 2 / R are exact, and no cell lies exactly on a
            // texel's plane (tested at every power-of-two resolution up to 256).
            let mut masks = LargePageVec::filled(Mask::EMPTY, texels / 2);
            fill_positive_faces(&cells, &mut masks, resolution);
            let codes = Codes::new(resolution, true);
            return Ok(PlaneTable { resolution, masks, codes, flips: [Mask::EMPTY, disk] });
        }
        let mut masks = LargePageVec::filled(Mask::EMPTY, texels);
        fill_every_texel(&cells, &mut masks, 0, resolution);
        Ok(PlaneTable { resolution, masks, codes: Codes::new(resolution, false), flips: [Mask::EMPTY, disk] })
    }

    /// The shared table of a resolution, built on first use.
    pub fn shared(resolution: usize) -> Result<Arc<PlaneTable>> {
        static TABLES: Mutex<Vec<Arc<PlaneTable>>> = Mutex::new(Vec::new());
        let mut tables = TABLES.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(table) = tables.iter().find(|t| t.resolution == resolution) {
            return Ok(table.clone());
        }
        let table = Arc::new(PlaneTable::build(resolution)?);
        tables.push(table.clone());
        Ok(table)
    }

    pub fn resolution(&self) -> usize {
        self.resolution
    }

    pub fn bytes(&self) -> usize {
        self.masks.len() * std::mem::size_of::<Mask>()
    }

    /// Mask of the cells on the positive side of the plane through the origin with normal m.
    #[inline(always)]
    pub fn lookup(&self, m: [f32; 3]) -> Mask {
        // texel_of always returns an index below 6 * resolution^2.
        self.mask_at(texel_of(m, self.resolution) as u32)
    }

    /// The texel `lookup` reads for normal m (pair with `mask_at`, or `code`).
    #[inline(always)]
    pub fn texel(&self, m: [f32; 3]) -> u32 {
        texel_of(m, self.resolution) as u32
    }

    /// Codes (`code`) of the texels `lookup` reads for `LANES` normals given as components
    /// (x, y, z), written so that the loop vectorises: the face by selects, the coordinates
    /// clamped in float (NaN to 0, as the saturating casts of `texel_of` do) before an unchecked
    /// conversion, and a negative face's mirror by integer selects. For the pipelined fetches
    /// (`prefetch_code`, `mask_of_code`).
    #[inline(always)]
    pub fn codes<const LANES: usize>(&self, x: &[f32; LANES], y: &[f32; LANES], z: &[f32; LANES], out: &mut [u32; LANES]) {
        let resolution = self.resolution as u32;
        let half = 0.5 * self.resolution as f32;
        let last = (self.resolution - 1) as f32;
        let codes = self.codes;
        for i in 0..LANES {
            let (ax, ay, az) = (x[i].abs(), y[i].abs(), z[i].abs());
            let x_major = ax >= ay && ax >= az;
            let y_major = !x_major && ay >= az;
            let major = if x_major { ax } else if y_major { ay } else { az };
            let along = if x_major { x[i] } else if y_major { y[i] } else { z[i] };
            let u = if x_major { y[i] } else { x[i] };
            let v = if x_major || y_major { z[i] } else { y[i] };
            let axis = if x_major { 0 } else if y_major { 1 } else { 2 };
            let negative = if along < 0.0 { u32::MAX } else { 0 };
            let scale = half / major;
            let texel = |w: f32| {
                let w = w * scale + half;
                let w = if w > 0.0 { w } else { 0.0 }; // also NaN
                let w = if w < last { w } else { last };
                // SAFETY: w is finite and in [0, resolution - 1].
                unsafe { w.to_int_unchecked::<u32>() }
            };
            let within = texel(v) * resolution + texel(u);
            out[i] = codes.of(axis, negative, within);
        }
    }

    /// `codes` for eight normals in AVX2 registers: the same operations in the same order,
    /// so the same codes bit for bit (`max`/`min` with the bound second are the portable
    /// clamps, NaN included). For kernels compiled for AVX2, into which it inlines (no
    /// closures: those would be compiled without AVX2 and keep the intrinsics as calls).
    ///
    /// # Safety
    /// The CPU must support AVX2 (`is_x86_feature_detected!("avx2")`).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn codes_avx2(&self, x: __m256, y: __m256, z: __m256) -> __m256i {
        let sign = _mm256_set1_ps(-0.0);
        let (ax, ay, az) = (_mm256_andnot_ps(sign, x), _mm256_andnot_ps(sign, y), _mm256_andnot_ps(sign, z));
        let x_major = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(ax, ay), _mm256_cmp_ps::<_CMP_GE_OQ>(ax, az));
        let y_major = _mm256_andnot_ps(x_major, _mm256_cmp_ps::<_CMP_GE_OQ>(ay, az));
        let major = _mm256_blendv_ps(_mm256_blendv_ps(az, ay, y_major), ax, x_major);
        let along = _mm256_blendv_ps(_mm256_blendv_ps(z, y, y_major), x, x_major);
        let u = _mm256_blendv_ps(x, y, x_major);
        let v = _mm256_blendv_ps(y, z, _mm256_or_ps(x_major, y_major));
        let half = _mm256_set1_ps(0.5 * self.resolution as f32);
        let last = _mm256_set1_ps((self.resolution - 1) as f32);
        let scale = _mm256_div_ps(half, major);
        let texel_u = _mm256_cvttps_epi32(_mm256_min_ps(_mm256_max_ps(_mm256_add_ps(_mm256_mul_ps(u, scale), half), _mm256_setzero_ps()), last));
        let texel_v = _mm256_cvttps_epi32(_mm256_min_ps(_mm256_max_ps(_mm256_add_ps(_mm256_mul_ps(v, scale), half), _mm256_setzero_ps()), last));
        let within = _mm256_add_epi32(_mm256_mullo_epi32(texel_v, _mm256_set1_epi32(self.resolution as i32)), texel_u);
        let c = self.codes;
        let (stride_x, stride_y, stride_z) = (_mm256_setzero_si256(), _mm256_set1_epi32(c.axis_stride as i32), _mm256_set1_epi32((2 * c.axis_stride) as i32));
        let axis = _mm256_blendv_epi8(_mm256_blendv_epi8(stride_z, stride_y, _mm256_castps_si256(y_major)), stride_x, _mm256_castps_si256(x_major));
        let negative = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(along, _mm256_setzero_ps()));
        let negative_offset = _mm256_and_si256(negative, _mm256_set1_epi32(c.negative_offset as i32));
        let flip = _mm256_and_si256(negative, _mm256_set1_epi32(c.flip as i32));
        let complement = _mm256_and_si256(negative, _mm256_set1_epi32(c.complement as i32));
        let code = _mm256_add_epi32(_mm256_add_epi32(axis, negative_offset), _mm256_xor_si256(within, flip));
        _mm256_or_si256(code, complement)
    }

    /// `codes_avx2` for sixteen normals in AVX-512 registers, the same codes bit for bit.
    ///
    /// # Safety
    /// The CPU must support AVX-512F and AVX-512DQ.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn codes_avx512(&self, x: __m512, y: __m512, z: __m512) -> __m512i {
        let sign = _mm512_set1_ps(-0.0);
        let (ax, ay, az) = (_mm512_andnot_ps(sign, x), _mm512_andnot_ps(sign, y), _mm512_andnot_ps(sign, z));
        let x_major = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(ax, ay) & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(ax, az);
        let y_major = !x_major & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(ay, az);
        let major = _mm512_mask_blend_ps(x_major, _mm512_mask_blend_ps(y_major, az, ay), ax);
        let along = _mm512_mask_blend_ps(x_major, _mm512_mask_blend_ps(y_major, z, y), x);
        let u = _mm512_mask_blend_ps(x_major, x, y);
        let v = _mm512_mask_blend_ps(x_major | y_major, y, z);
        let half = _mm512_set1_ps(0.5 * self.resolution as f32);
        let last = _mm512_set1_ps((self.resolution - 1) as f32);
        let scale = _mm512_div_ps(half, major);
        let texel_u = _mm512_cvttps_epi32(_mm512_min_ps(_mm512_max_ps(_mm512_add_ps(_mm512_mul_ps(u, scale), half), _mm512_setzero_ps()), last));
        let texel_v = _mm512_cvttps_epi32(_mm512_min_ps(_mm512_max_ps(_mm512_add_ps(_mm512_mul_ps(v, scale), half), _mm512_setzero_ps()), last));
        let within = _mm512_add_epi32(_mm512_mullo_epi32(texel_v, _mm512_set1_epi32(self.resolution as i32)), texel_u);
        let c = self.codes;
        let axis = _mm512_mask_blend_epi32(y_major, _mm512_set1_epi32((2 * c.axis_stride) as i32), _mm512_set1_epi32(c.axis_stride as i32));
        let axis = _mm512_mask_blend_epi32(x_major, axis, _mm512_setzero_si512());
        let negative = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(along, _mm512_setzero_ps());
        let negative_offset = _mm512_maskz_mov_epi32(negative, _mm512_set1_epi32(c.negative_offset as i32));
        let flip = _mm512_maskz_mov_epi32(negative, _mm512_set1_epi32(c.flip as i32));
        let complement = _mm512_maskz_mov_epi32(negative, _mm512_set1_epi32(c.complement as i32));
        let code = _mm512_add_epi32(_mm512_add_epi32(axis, negative_offset), _mm512_xor_si512(within, flip));
        _mm512_or_si512(code, complement)
    }

    /// The mask of a texel of the whole table (`texel`).
    #[inline(always)]
    pub fn mask_at(&self, texel: u32) -> Mask {
        self.mask_of_code(self.code(texel))
    }

    /// The code of a texel (`texel`) for `prefetch_code` and `mask_of_code`: where
    /// its mask is stored, with `COMPLEMENT` set when it is the stored one's complement. One
    /// texel at a time (`mask_at`); the pipelined loops get their codes lane-parallel from
    /// `codes`, equal to these.
    #[inline(always)]
    pub fn code(&self, texel: u32) -> u32 {
        let face_texels = (self.resolution * self.resolution) as u32;
        let face = texel / face_texels;
        let negative = 0u32.wrapping_sub(face & 1);
        self.codes.of(face / 2, negative, texel % face_texels)
    }

    /// Asks the CPU to bring the mask of a code (`code`), two 64-byte lines, into cache ahead
    /// of its use.
    #[inline(always)]
    pub fn prefetch_code(&self, code: u32) {
        // No bounds check: the address is only a hint (a code's fetch checks it).
        self.prefetch_bytes((code & !COMPLEMENT) as usize * MASK_BYTES);
    }

    /// Where the masks of `codes` lie (`Fetches`), lane by lane; written so that it vectorises.
    #[inline(always)]
    pub fn fetches(&self, codes: &[[u32; LANES]; 3]) -> Fetches {
        let last = ((self.masks.len() - 1) * MASK_BYTES) as u32;
        let mut out = Fetches::default();
        for e in 0..3 {
            for i in 0..LANES {
                let code = codes[e][i];
                out.offsets[e][i] = ((code & !COMPLEMENT) << MASK_BYTES.trailing_zeros()).min(last);
                out.flips[e][i] = (code as i32) >> 31;
            }
        }
        out
    }

    /// `fetches` of sixteen lanes' codes in AVX-512 registers (`[edge]`), the same offsets and
    /// flips.
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn fetches_avx512(&self, codes: [__m512i; 3]) -> Fetches<{ 2 * LANES }> {
        let last = _mm512_set1_epi32(((self.masks.len() - 1) * MASK_BYTES) as i32);
        let mut out = Fetches::default();
        for (e, code) in codes.into_iter().enumerate() {
            let stored = _mm512_andnot_si512(_mm512_set1_epi32(COMPLEMENT as i32), code);
            let offset = _mm512_min_epu32(_mm512_slli_epi32::<{ MASK_BYTES.trailing_zeros() }>(stored), last);
            _mm512_storeu_si512(out.offsets[e].as_mut_ptr() as *mut __m512i, offset);
            _mm512_storeu_si512(out.flips[e].as_mut_ptr() as *mut __m512i, _mm512_srai_epi32::<31>(code));
        }
        out
    }

    /// Asks the CPU to bring the masks of the `lanes` of `fetches` into cache ahead of use.
    #[inline(always)]
    pub fn prefetch(&self, fetches: &Fetches, lanes: u32) {
        let mut bits = lanes;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            (0..3).for_each(|e| self.prefetch_bytes(fetches.offsets[e][i] as usize));
        }
    }

    #[inline(always)]
    fn prefetch_bytes(&self, offset: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let p = (self.masks.as_ptr() as *const i8).wrapping_add(offset);
            // SAFETY: prefetching is a hint and never faults, whatever the address.
            unsafe {
                _mm_prefetch(p, _MM_HINT_T0);
                _mm_prefetch(p.wrapping_add(64), _MM_HINT_T0);
            }
        }
    }

    /// The stored mask of a code (`code`), before its complement flip.
    #[inline(always)]
    fn stored(&self, code: u32) -> &Mask {
        &self.masks[(code & !COMPLEMENT) as usize]
    }

    /// The disk's cells: the flip of a complemented code.
    #[inline(always)]
    fn disk(&self) -> &Mask {
        &self.flips[1]
    }

    /// The mask of a triangle whose three edge planes have these codes: theirs AND-ed.
    #[inline(always)]
    pub fn triangle_of_codes(&self, [ab, bc, ca]: [u32; 3]) -> Mask {
        Mask::and3(&self.mask_of_code(ab), &self.mask_of_code(bc), &self.mask_of_code(ca))
    }

    /// The mask of a code (`code`): `mask_at` of its texel.
    #[inline(always)]
    pub fn mask_of_code(&self, code: u32) -> Mask {
        self.flipped(self.stored(code), (code >> COMPLEMENT.trailing_zeros()) as usize)
    }

    /// A stored mask XOR-ed with flip `flip` (0: nothing, 1: the disk).
    #[inline(always)]
    fn flipped(&self, stored: &Mask, flip: usize) -> Mask {
        let flip = &self.flips[flip];
        Mask(std::array::from_fn(|w| stored.0[w] ^ flip.0[w]))
    }
}

/// The bit of a code (`PlaneTable::code`) that marks a complemented mask; tables have fewer
/// than 2^31 texels (at most 6 x 512 x 512).
const COMPLEMENT: u32 = 1 << 31;

const MASK_BYTES: usize = std::mem::size_of::<Mask>();

/// Where the masks of the three edge codes of `N` triangles lie (`PlaneTable::fetches`):
/// byte offsets of their stored masks, clamped to the table so that reading them needs no
/// check, and their flips (0, or all ones for a complemented code). Made once per packet in
/// vector code, where the drain computed them triangle by triangle.
#[derive(Clone, Copy)]
pub struct Fetches<const N: usize = LANES> {
    offsets: [[u32; N]; 3],
    flips: [[i32; N]; 3],
}

impl<const N: usize> Default for Fetches<N> {
    fn default() -> Self {
        Fetches { offsets: [[0; N]; 3], flips: [[0; N]; 3] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::disk_mask::disk;

    #[test]
    fn mirrored_faces_give_the_masks_of_their_own_directions() {
        let cells = CellWords::new();
        for resolution in [4, 8, 12, 64, 96, 128, 256] {
            let mut direct = vec![Mask::EMPTY; 6 * resolution * resolution];
            fill_every_texel(&cells, &mut direct, 0, resolution);
            let table = PlaneTable::build(resolution).unwrap();
            let differ = (0..direct.len()).filter(|&t| table.mask_at(t as u32) != direct[t]).count();
            assert_eq!(differ, 0, "resolution {resolution}");
        }
    }

    #[test]
    fn fetches_stay_within_the_table_whatever_the_codes() {
        let table = PlaneTable::shared(12).unwrap();
        let last = ((table.masks.len() - 1) * MASK_BYTES) as u32;
        let wild = [u32::MAX, COMPLEMENT, COMPLEMENT - 1, table.masks.len() as u32, 1 << 25, 0, 7, COMPLEMENT | 3];
        let fetches = table.fetches(&[wild, wild.map(|c| c.rotate_left(1)), wild.map(|c| c ^ COMPLEMENT)]);
        for e in 0..3 {
            for i in 0..LANES {
                let offset = fetches.offsets[e][i];
                assert!(offset <= last && (offset as usize).is_multiple_of(MASK_BYTES), "edge {e}, lane {i}: offset {offset}");
            }
        }
        assert_eq!(fetches.offsets[0][6], 7 * MASK_BYTES as u32);
        assert_eq!((fetches.flips[0][1], fetches.flips[0][5], fetches.flips[2][5]), (-1, 0, -1));
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx512_fetches_equal_the_portable_ones() {
        if !std::is_x86_feature_detected!("avx512f") {
            return;
        }
        let mut state = 0x1b87_3593;
        for resolution in [12, 128] {
            let table = PlaneTable::shared(resolution).unwrap();
            let wild = [u32::MAX, COMPLEMENT, COMPLEMENT - 1, table.masks.len() as u32, 1 << 25, 0, 7, COMPLEMENT | 3];
            for round in 0..2_000 {
                let codes: [[u32; 2 * LANES]; 3] = std::array::from_fn(|_| {
                    std::array::from_fn(|i| match round {
                        0 => wild[i % LANES] ^ (i as u32 / 8 * COMPLEMENT),
                        _ => crate::test_random::xorshift32(&mut state) >> (round % 8),
                    })
                });
                // SAFETY: the CPU supports AVX-512F (checked above); the loads read 16 lanes.
                let wide = unsafe { table.fetches_avx512(codes.map(|c| _mm512_loadu_si512(c.as_ptr() as *const __m512i))) };
                for half in 0..2 {
                    let narrow = table.fetches(&codes.map(|c| c[LANES * half..LANES * (half + 1)].try_into().unwrap()));
                    for e in 0..3 {
                        assert_eq!(wide.offsets[e][LANES * half..LANES * (half + 1)], narrow.offsets[e], "round {round}, half {half}, edge {e}");
                        assert_eq!(wide.flips[e][LANES * half..LANES * (half + 1)], narrow.flips[e], "round {round}, half {half}, edge {e}");
                    }
                }
            }
        }
    }

    #[test]
    fn codes_give_the_masks_of_their_texels() {
        for resolution in [12, 64, 128] {
            let table = PlaneTable::build(resolution).unwrap();
            for first in (0..6 * resolution * resolution).step_by(8) {
                for texel in first as u32..(first as u32 + 8).min(6 * (resolution * resolution) as u32) {
                    assert_eq!(table.mask_of_code(table.code(texel)), table.mask_at(texel), "resolution {resolution}, texel {texel}");
                }
            }
        }
    }

    #[test]
    fn word_parallel_half_spaces_equal_the_cell_by_cell_test() {
        let words = CellWords::new();
        let mut normals: Vec<[f32; 3]> = (0..6 * 24 * 24).map(|t| texel_direction(t / 576, t % 24, t / 24 % 24, 24)).collect();
        normals.extend([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 0.0], [f32::NAN, 1.0, 0.0], [1e-30, -1e-30, 0.0]]);
        for m in normals {
            let mut expected = Mask::EMPTY;
            for row in 0..MASK_SIDE {
                for col in 0..MASK_SIDE {
                    if let Some(d) = cell_direction(row, col) {
                        if m[0] * d[0] + m[1] * d[1] + m[2] * d[2] >= 0.0 {
                            expected.set(row, col);
                        }
                    }
                }
            }
            assert_eq!(words.half_space(m), expected, "{m:?}");
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports the feature.
                assert_eq!(unsafe { words.half_space_avx2(m) }, expected, "AVX2, {m:?}");
            }
        }
        // The run-time dispatched fill (AVX2 here) gives the same masks as the portable code,
        // over every texel of the default table (a fused multiply-add would differ there).
        let r = DEFAULT_RESOLUTION;
        let (mut filled, mut portable) = (vec![Mask::EMPTY; 6 * r * r], vec![Mask::EMPTY; 6 * r * r]);
        words.fill(&mut filled[100..], 100, r);
        words.fill_portable(&mut portable[100..], 100, r);
        assert!(filled == portable, "the dispatched fill differs from the portable one");
    }

    #[test]
    fn power_of_two_tables_keep_the_positive_faces_only() {
        assert_eq!(PlaneTable::shared(DEFAULT_RESOLUTION).unwrap().bytes(), 6 * 1024 * 1024);
        assert_eq!(PlaneTable::shared(64).unwrap().bytes(), 3 * 1024 * 1024 / 2);
        assert_eq!(PlaneTable::shared(12).unwrap().bytes(), 6 * 12 * 12 * 128);
    }

    #[test]
    fn up_facing_plane_keeps_the_whole_disk() {
        let table = PlaneTable::shared(DEFAULT_RESOLUTION).unwrap();
        assert_eq!(table.lookup([0.0, 0.0, 1.0]), disk());
        assert_eq!(table.lookup([0.0, 0.0, -1.0]), Mask::EMPTY);
    }

    #[test]
    fn degenerate_normals_do_not_panic() {
        let table = PlaneTable::shared(16).unwrap();
        let _ = table.lookup([0.0, 0.0, 0.0]);
        let _ = table.lookup([f32::NAN, 1.0, f32::INFINITY]);
    }

    #[test]
    fn lane_codes_match_lookup_everywhere() {
        let mut state = 7u64;
        let mut random = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * 3.0
        };
        let special = [0.0, -0.0, 1.0, -1.0, 1e-30, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.5, -0.5];
        let mut normals: Vec<[f32; 3]> = (0..4096).map(|_| [random(), random(), random()]).collect();
        for &a in &special {
            for &b in &special {
                normals.extend([[a, b, 1.0], [1.0, a, b], [a, 1.0, b], [a, b, a], [a, a, b]]);
            }
        }
        // Ties between axes and texel borders.
        normals.extend((0..64).map(|k| [k as f32 / 8.0 - 4.0, 1.0, k as f32 / 8.0 - 4.0]));
        // 16: the positive faces stored, negative ones mirrored; 12: every face stored.
        for resolution in [16, 12] {
            let table = PlaneTable::shared(resolution).unwrap();
            for chunk in normals.chunks(8) {
                let mut xyz = [[0.0f32; 8]; 3];
                for (i, n) in chunk.iter().enumerate() {
                    (0..3).for_each(|a| xyz[a][i] = n[a]);
                }
                let mut out = [0u32; 8];
                table.codes(&xyz[0], &xyz[1], &xyz[2], &mut out);
                for (i, n) in chunk.iter().enumerate() {
                    assert_eq!(out[i], table.code(texel_of(*n, resolution) as u32), "resolution {resolution}, {n:?}");
                }
            }
        }
    }

    #[test]
    fn every_texel_is_reachable_from_its_centre() {
        let resolution = 8;
        for face in 0..6 {
            for j in 0..resolution {
                for i in 0..resolution {
                    let d = texel_direction(face, i, j, resolution);
                    assert_eq!(texel_of(d, resolution), (face * resolution + j) * resolution + i);
                }
            }
        }
    }
}
