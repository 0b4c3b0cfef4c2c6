//! Native relighting of a baked panorama (Wong et al. 2003): outgoing radiance per pixel =
//! sum_i c_i L_i, with c_i the pixel's SH maps (albedo and 1/pi included) and L_i the SH of
//! the incident light. Suns and environments give the same L_i for every pixel, so all of
//! them fold into one weight per map and channel (a linear combination of maps); a point
//! light gives L_i = I f(d) Y_i(l) with l and d from the pixel's position, evaluated per pixel.
//!
//! Maps come as k planes of H x W x 3 values and are kept row by row (row r of every map
//! together: one relight reads memory front to back), 8-bit (value = offset + scale * byte / 255, the
//! scale and offset folded into the weights) or float16. Rows run in parallel; within a row,
//! blocks of 8 pixels (24 interleaved values) go through AVX2 when the CPU has it, else the
//! portable code, which performs the same IEEE operations in the same order (same bits).

use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use super::directions::{self, Rotation};
use super::half;
use super::sh_lanes::{self, Lanes, LANES};
use crate::error::{Error, Result};

pub enum Maps {
    U8(Vec<u8>),
    /// IEEE half bits.
    F16(Vec<u16>),
}

pub struct Relighter {
    pub width: usize,
    pub height: usize,
    pub coeffs: usize,
    maps: Maps,
    /// Per map, per channel: value = offset + scale * byte / 255 (8-bit maps only).
    scale: Vec<[f32; 3]>,
    offset: Vec<[f32; 3]>,
    /// Position planes (x, y, z), H x W each, for point lights.
    position: [Vec<f32>; 3],
    hit: Vec<bool>,
    rotation: Rotation,
    /// The background of the last environment (its SH and H*W*3 values): dragging a sun under
    /// a fixed environment does not evaluate it again.
    background_cache: Mutex<Option<Background>>,
}

/// An environment's SH (k) and the H*W*3 values its background shows.
type Background = (Vec<[f32; 3]>, Arc<Vec<f32>>);

#[derive(Clone, Copy, Debug)]
pub struct PointLight {
    pub position: [f32; 3],
    /// Radiant intensity (W/sr) per channel: power / (4 pi) x colour.
    pub intensity: [f32; 3],
    /// 1/d^2 falloff; false: the paper's constant falloff (as if every pixel were 1 m away).
    pub inverse_square: bool,
}

pub struct Lighting<'a> {
    /// (k) per-channel SH weights shared by every pixel: suns (E Y_i(l)) plus environments (L_i).
    pub uniform: &'a [[f32; 3]],
    pub points: &'a [PointLight],
    /// Radiance SH (k) that background pixels show in their direction; None: black.
    pub background: Option<&'a [[f32; 3]]>,
}

/// Weights folded for one relight; shared by both code paths so they agree to the bit.
pub(crate) struct Folded {
    /// Per map, per channel: weight of the raw value (byte or half).
    pub uniform: Vec<[f32; 3]>,
    pub base: [f32; 3],
    /// Per point light: (light, per-map raw-value scale x intensity, per-map offset x intensity).
    pub points: Vec<FoldedPoint>,
    /// The same weights repeated over a block's 24 interleaved values (the portable code).
    pub uniform_block: Vec<[f32; 3 * LANES]>,
    pub base_block: [f32; 3 * LANES],
    pub points_block: Vec<Vec<[f32; 3 * LANES]>>,
}

/// A point light with its per-map raw-value scale and offset, both times its intensity.
pub(crate) type FoldedPoint = (PointLight, Vec<[f32; 3]>, Vec<[f32; 3]>);

fn spread(w: &[f32; 3]) -> [f32; 3 * LANES] {
    std::array::from_fn(|e| w[e % 3])
}

impl Relighter {
    /// `maps`: k planes of H*W*3; `scale`/`offset`: k per-channel triples (8-bit maps; ignored
    /// for float16); `position`: H*W; `hit`: H*W; `rotation`: the viewpoint's frame.
    #[allow(clippy::too_many_arguments)]
    pub fn new(width: usize, height: usize, coeffs: usize, maps: Maps, scale: Vec<[f32; 3]>, offset: Vec<[f32; 3]>,
               position: &[[f32; 3]], hit: Vec<bool>, rotation: Rotation) -> Result<Relighter> {
        let n = width * height;
        if width == 0 || height == 0 {
            return Err(Error::invalid("the panorama is empty"));
        }
        if !matches!(coeffs, 1 | 4 | 9 | 16 | 25) {
            return Err(Error::invalid(format!("relighting takes 1, 4, 9, 16 or 25 coefficients, got {coeffs}")));
        }
        let len = match &maps {
            Maps::U8(m) => m.len(),
            Maps::F16(m) => m.len(),
        };
        if len != coeffs * n * 3 || position.len() != n || hit.len() != n {
            return Err(Error::invalid("maps, positions and mask do not match the panorama's size"));
        }
        if matches!(maps, Maps::U8(_)) && (scale.len() != coeffs || offset.len() != coeffs) {
            return Err(Error::invalid(format!("8-bit maps need {coeffs} scales and offsets")));
        }
        let plane = |a: usize| position.iter().map(|p| p[a]).collect::<Vec<f32>>();
        let maps = match maps {
            Maps::U8(m) => Maps::U8(by_rows(&m, coeffs, height, width * 3)),
            Maps::F16(m) => Maps::F16(by_rows(&m, coeffs, height, width * 3)),
        };
        Ok(Relighter { width, height, coeffs, maps, scale, offset, position: [plane(0), plane(1), plane(2)], hit, rotation,
                       background_cache: Mutex::new(None) })
    }

    /// Bytes the kernel reads per relight (maps, plus positions when point lights are on).
    pub fn bytes_read(&self, points: bool) -> usize {
        let maps = match &self.maps {
            Maps::U8(m) => m.len(),
            Maps::F16(m) => 2 * m.len(),
        };
        maps + if points { 12 * self.width * self.height } else { 0 }
    }

    /// Whether the AVX2 kernel runs on this CPU.
    pub fn simd_available() -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("f16c")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }

    /// Radiance (H*W*3, row 0 at the top) into `out`; `simd` false forces the portable code.
    pub fn relight(&self, lighting: &Lighting, out: &mut [f32], simd: bool) -> Result<()> {
        let k = self.coeffs;
        if out.len() != self.width * self.height * 3 {
            return Err(Error::invalid("the output does not match the panorama's size"));
        }
        if lighting.uniform.len() != k || lighting.background.is_some_and(|b| b.len() != k) {
            return Err(Error::invalid(format!("lighting must have {k} SH coefficients")));
        }
        let all = lighting.uniform.iter().chain(lighting.background.unwrap_or(&[])).flatten();
        let lamps = lighting.points.iter().flat_map(|p| p.position.iter().chain(&p.intensity));
        if all.chain(lamps).any(|v| !v.is_finite()) {
            return Err(Error::invalid("lighting must be finite"));
        }
        let folded = self.fold(lighting);
        let simd = simd && Self::simd_available();
        let background = lighting.background.map(|sh| self.background_image(sh));
        let w3 = self.width * 3;
        out.par_chunks_mut(w3).enumerate().for_each(|(r, row)| {
            self.row(r, &folded, row, simd);
            let hit = &self.hit[r * self.width..(r + 1) * self.width];
            for c in (0..self.width).filter(|&c| !hit[c]) {
                match &background {
                    Some(image) => row[c * 3..c * 3 + 3].copy_from_slice(&image[r * w3 + c * 3..r * w3 + c * 3 + 3]),
                    None => row[c * 3..c * 3 + 3].fill(0.0),
                }
            }
        });
        Ok(())
    }

    /// The radiance of environment `sh` at every background pixel (H*W*3), cached.
    fn background_image(&self, sh: &[[f32; 3]]) -> Arc<Vec<f32>> {
        let mut cache = self.background_cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((key, image)) = cache.as_ref() {
            if key.as_slice() == sh {
                return image.clone();
            }
        }
        let (cols, rows) = (directions::columns(self.width), directions::rows(self.height));
        let mut image = vec![0.0f32; self.width * self.height * 3];
        image.par_chunks_mut(self.width * 3).enumerate().for_each(|(r, row)| self.background(r, sh, &rows, &cols, row));
        let image = Arc::new(image);
        *cache = Some((sh.to_vec(), image.clone()));
        image
    }

    fn fold(&self, lighting: &Lighting) -> Folded {
        let k = self.coeffs;
        let (scale, offset): (Vec<[f32; 3]>, Vec<[f32; 3]>) = match self.maps {
            Maps::U8(_) => (self.scale.iter().map(|s| s.map(|v| v / 255.0)).collect(), self.offset.clone()),
            Maps::F16(_) => (vec![[1.0; 3]; k], vec![[0.0; 3]; k]),
        };
        let times = |a: &[f32; 3], b: &[f32; 3]| [a[0] * b[0], a[1] * b[1], a[2] * b[2]];
        let uniform: Vec<[f32; 3]> = (0..k).map(|i| times(&lighting.uniform[i], &scale[i])).collect();
        let mut base = [0.0f32; 3];
        for i in 0..k {
            for c in 0..3 {
                base[c] += lighting.uniform[i][c] * offset[i][c];
            }
        }
        let points: Vec<FoldedPoint> = lighting
            .points
            .iter()
            .map(|p| {
                (*p, scale.iter().map(|s| times(s, &p.intensity)).collect(), offset.iter().map(|o| times(o, &p.intensity)).collect())
            })
            .collect();
        let uniform_block = uniform.iter().map(spread).collect();
        let points_block = points.iter().map(|(_, ws, _)| ws.iter().map(spread).collect()).collect();
        Folded { uniform_block, base_block: spread(&base), points_block, uniform, base, points }
    }

    /// One row: AVX2 on whole blocks of 8 pixels when asked, the portable code elsewhere.
    fn row(&self, r: usize, folded: &Folded, row: &mut [f32], simd: bool) {
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if simd {
            let blocks = self.width / LANES;
            // SAFETY: `simd` is only true when the CPU has AVX2 and F16C (`simd_available`).
            unsafe { super::relight_avx2::row(self, r, folded, row, blocks) };
            done = blocks * LANES;
        }
        let _ = simd;
        let mut p = done;
        while p < self.width {
            let lanes = (self.width - p).min(LANES);
            self.block_portable(r, p, lanes, folded, &mut row[p * 3..(p + lanes) * 3]);
            p += lanes;
        }
    }

    /// Where row r of map i starts in `maps`.
    #[inline(always)]
    pub(crate) fn map_start(&self, r: usize, i: usize) -> usize {
        (r * self.coeffs + i) * self.width * 3
    }

    pub(crate) fn maps(&self) -> &Maps {
        &self.maps
    }

    /// The pixels p .. p + lanes of row r (out: their 3 * lanes values).
    fn block_portable(&self, r: usize, p: usize, lanes: usize, folded: &Folded, out: &mut [f32]) {
        let k = self.coeffs;
        let n = out.len();
        let mut raw = [[0.0f32; 3 * LANES]; 25];
        for (i, values) in raw.iter_mut().enumerate().take(k) {
            let start = self.map_start(r, i) + p * 3;
            match &self.maps {
                Maps::U8(m) => values[..n].iter_mut().zip(&m[start..start + n]).for_each(|(v, b)| *v = *b as f32),
                Maps::F16(m) => values[..n].iter_mut().zip(&m[start..start + n]).for_each(|(v, b)| *v = half::to_f32(*b)),
            }
        }
        // Whole blocks of 24 values with the weights spread over them: loops the compiler can
        // vectorize, each value still summed over the maps in order (the AVX2 code's bits).
        let mut acc = folded.base_block;
        for i in 0..k {
            let (w, x) = (&folded.uniform_block[i], &raw[i]);
            for e in 0..3 * LANES {
                acc[e] += w[e] * x[e];
            }
        }
        let mut t = [[0.0f32; LANES]; 25];
        let mut offsets = [0.0f32; 3 * LANES];
        for ((light, _, wo), ws) in folded.points.iter().zip(&folded.points_block) {
            self.point_lanes(r, p, lanes, light, wo, &mut t, &mut offsets);
            let mut sum = [0.0f32; 3 * LANES];
            for i in 0..k {
                let spread_t: [f32; 3 * LANES] = std::array::from_fn(|e| t[i][e / 3]);
                let (w, x) = (&ws[i], &raw[i]);
                for e in 0..3 * LANES {
                    sum[e] += (spread_t[e] * w[e]) * x[e];
                }
            }
            for e in 0..3 * LANES {
                acc[e] += sum[e] + offsets[e];
            }
        }
        out.copy_from_slice(&acc[..n]);
    }

    /// For a point light and up to 8 pixels: t[i][j] = f(d_j) Y_i(l_j) and the offsets' part,
    /// offsets[3 j + c] = sum_i t[i][j] wo[i][c]. Lanes past `lanes` repeat the last pixel.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn point_lanes(&self, r: usize, p: usize, lanes: usize, light: &PointLight, wo: &[[f32; 3]],
                              t: &mut [Lanes; 25], offsets: &mut [f32; 3 * LANES]) {
        let first = r * self.width + p;
        let (mut px, mut py, mut pz) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        if lanes == LANES {
            px.copy_from_slice(&self.position[0][first..first + LANES]);
            py.copy_from_slice(&self.position[1][first..first + LANES]);
            pz.copy_from_slice(&self.position[2][first..first + LANES]);
        } else {
            for j in 0..LANES {
                let q = first + j.min(lanes - 1);
                px[j] = self.position[0][q];
                py[j] = self.position[1][q];
                pz[j] = self.position[2][q];
            }
        }
        let (mut x, mut y, mut z, mut f) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        let inverse_square = if light.inverse_square { 1.0f32 } else { 0.0 };
        for j in 0..LANES {
            let (lx, ly, lz) = (light.position[0] - px[j], light.position[1] - py[j], light.position[2] - pz[j]);
            // A light on the surface itself would divide by zero: keep it a micrometre away.
            let d2 = (lx * lx + ly * ly + lz * lz).max(1e-12);
            let inv = 1.0 / d2.sqrt();
            x[j] = lx * inv;
            y[j] = ly * inv;
            z[j] = lz * inv;
            f[j] = if inverse_square != 0.0 { 1.0 / d2 } else { 1.0 };
        }
        let k = self.coeffs;
        sh_lanes::eval(&x, &y, &z, k, t);
        for ti in t.iter_mut().take(k) {
            for j in 0..LANES {
                ti[j] *= f[j];
            }
        }
        // The offsets' part per channel in lane order, then interleaved like the values.
        let mut per_channel = [[0.0f32; LANES]; 3];
        for (c, pc) in per_channel.iter_mut().enumerate() {
            for i in 0..k {
                let w = wo[i][c];
                for j in 0..LANES {
                    pc[j] += t[i][j] * w;
                }
            }
        }
        for j in 0..LANES {
            for c in 0..3 {
                offsets[3 * j + c] = per_channel[c][j];
            }
        }
    }

    /// Row r's background pixels: radiance SH `sh` in their direction, 8 at a time through the
    /// lane SH.
    fn background(&self, r: usize, sh: &[[f32; 3]], rows: &[(f64, f64)], cols: &[(f64, f64)], row: &mut [f32]) {
        let hit = &self.hit[r * self.width..(r + 1) * self.width];
        let mut pending = [0usize; LANES];
        let mut count = 0;
        for c in (0..self.width).filter(|&c| !hit[c]) {
            pending[count] = c;
            count += 1;
            if count == LANES {
                self.background_lanes(r, &pending, count, sh, rows, cols, row);
                count = 0;
            }
        }
        if count > 0 {
            self.background_lanes(r, &pending, count, sh, rows, cols, row);
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn background_lanes(&self, r: usize, columns: &[usize; LANES], count: usize, sh: &[[f32; 3]], rows: &[(f64, f64)],
                        cols: &[(f64, f64)], row: &mut [f32]) {
        let (mut x, mut y, mut z) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        for j in 0..count {
            let d = directions::direction(&self.rotation, rows[r], cols[columns[j]]);
            (x[j], y[j], z[j]) = (d[0] as f32, d[1] as f32, d[2] as f32);
        }
        let mut basis = [[0.0f32; LANES]; 25];
        sh_lanes::eval(&x, &y, &z, self.coeffs, &mut basis);
        for j in 0..count {
            let mut v = [0.0f32; 3];
            for (i, l) in sh.iter().enumerate() {
                for ch in 0..3 {
                    v[ch] += basis[i][j] * l[ch];
                }
            }
            row[columns[j] * 3..columns[j] * 3 + 3].copy_from_slice(&v);
        }
    }
}

/// (k, H, row) planes -> (H, k, row): each panorama row's maps side by side.
fn by_rows<T: Copy>(planes: &[T], k: usize, height: usize, row: usize) -> Vec<T> {
    let mut out = Vec::with_capacity(planes.len());
    for r in 0..height {
        for i in 0..k {
            let start = (i * height + r) * row;
            out.extend_from_slice(&planes[start..start + row]);
        }
    }
    out
}
