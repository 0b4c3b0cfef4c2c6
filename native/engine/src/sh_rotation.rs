//! Rotation of SH coefficient vectors into another frame.
//!
//! A band-l function is fixed by its values at 2l+1 generic directions d_k, so coefficients in
//! a rotated frame follow from evaluating the function there and solving with the
//! precomputed inverse of A_l[k][m] = Y_lm(d_k). Cost per rotation: 2 bands - 1 basis
//! evaluations and two small matrix products per band, with no recursion on rotation
//! matrices (compare Ivanic and Ruedenberg 1996, which is faster but far longer).

use rayon::prelude::*;

use crate::sh::{Lanes16, Real, ShBasis, MAX_COEFFS};

pub struct ShRotator {
    basis: ShBasis,
    directions: Vec<[f32; 3]>,
    /// Per band l, the (2l+1)^2 row-major inverse of A_l.
    inverses: Vec<Vec<f32>>,
    /// The same, column k of band l as lanes over the rows m (for `to_world_lanes`).
    inverse_columns: Vec<Vec<Lanes16>>,
}

/// Fixed, well-spread directions that are generic for every band (no symmetry makes A_l singular).
fn generic_directions(count: usize) -> Vec<[f32; 3]> {
    // Fibonacci spiral with an irrational twist; tests check the conditioning of every A_l.
    (0..count)
        .map(|k| {
            let z = 1.0 - (2.0 * k as f64 + 1.0) / count as f64 * 0.97;
            let phi = k as f64 * 2.399_963_229_728_653 + 0.4;
            let s = (1.0 - z * z).sqrt();
            [(s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32]
        })
        .collect()
}

/// Inverse of a small square matrix by Gauss-Jordan elimination with partial pivoting
/// (run once per band at construction; a linear-algebra crate would be heavier than this).
fn invert(matrix: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut a = matrix.to_vec();
    let mut inv: Vec<f64> = (0..n * n).map(|i| if i / n == i % n { 1.0 } else { 0.0 }).collect();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs()))?;
        if a[pivot * n + col].abs() < 1e-9 {
            return None;
        }
        for k in 0..n {
            a.swap(col * n + k, pivot * n + k);
            inv.swap(col * n + k, pivot * n + k);
        }
        let p = a[col * n + col];
        for k in 0..n {
            a[col * n + k] /= p;
            inv[col * n + k] /= p;
        }
        for row in (0..n).filter(|&r| r != col) {
            let f = a[row * n + col];
            for k in 0..n {
                a[row * n + k] -= f * a[col * n + k];
                inv[row * n + k] -= f * inv[col * n + k];
            }
        }
    }
    Some(inv)
}

impl ShRotator {
    pub fn new(basis: ShBasis) -> Self {
        let bands = basis.bands();
        let directions = generic_directions(2 * bands - 1);
        let mut y = [0.0f32; MAX_COEFFS];
        let values: Vec<[f32; MAX_COEFFS]> = directions
            .iter()
            .map(|d| {
                basis.eval(*d, &mut y);
                y
            })
            .collect();
        let inverses: Vec<Vec<f32>> = (0..bands)
            .map(|l| {
                let n = 2 * l + 1;
                let a: Vec<f64> = (0..n * n).map(|e| values[e / n][l * l + e % n] as f64).collect();
                invert(&a, n).expect("generic directions make every band's matrix invertible").into_iter().map(|v| v as f32).collect()
            })
            .collect();
        let inverse_columns = inverses
            .iter()
            .enumerate()
            .map(|(l, inv)| {
                let n = 2 * l + 1;
                (0..n).map(|k| Lanes16(std::array::from_fn(|m| if m < n { inv[m * n + k] } else { 0.0 }))).collect()
            })
            .collect();
        ShRotator { basis, directions, inverses, inverse_columns }
    }

    /// Coefficients in world space of a function given by `local` coefficients in the frame
    /// whose axes (in world space) are `axes` = [x, y, z] (tangent, bitangent, normal).
    pub fn to_world(&self, axes: [[f32; 3]; 3], local: &[f32], out: &mut [f32]) {
        if self.basis.bands() <= 5 {
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports the feature the function is compiled for.
                return unsafe { self.to_world_avx2(axes, local, out) };
            }
            return self.to_world_lanes(axes, local, out);
        }
        self.to_world_each(axes, local, out);
    }

    /// `to_world_each` for up to 5 bands with the basis evaluated at all directions at once
    /// (`ShBasis::eval5_lanes`) and the bands' sums taken for all rows at once: the same
    /// operations in the same order, so the same bits, with 1,800 instructions a call
    /// instead of 9,800 (cachegrind on `examples/profile_rotation.rs`).
    #[inline(always)]
    fn to_world_lanes(&self, axes: [[f32; 3]; 3], local: &[f32], out: &mut [f32]) {
        let bands = self.basis.bands();
        let mut dirs = [Lanes16([0.0; 16]); 3];
        for (k, d) in self.directions.iter().enumerate() {
            for (axis, lanes) in axes.iter().zip(&mut dirs) {
                lanes.0[k] = dot(*axis, *d);
            }
        }
        let mut y = [Lanes16([0.0; 16]); 25];
        self.basis.eval5_lanes(dirs, &mut y);
        for l in 0..bands {
            // Band l's part of the function at each direction, summed in the order `sum` does.
            let band = l * l..(l + 1) * (l + 1);
            let mut values = Lanes16::splat(local[band.start]) * y[band.start];
            for i in band.start + 1..band.end {
                values = values + Lanes16::splat(local[i]) * y[i];
            }
            // out_m = sum over k of inv[m][k] values_k, k in order, for all m at once.
            let columns = &self.inverse_columns[l];
            let mut sums = columns[0] * Lanes16::splat(values.0[0]);
            for (column, &v) in columns.iter().zip(&values.0).skip(1) {
                sums = sums + *column * Lanes16::splat(v);
            }
            out[l * l..(l + 1) * (l + 1)].copy_from_slice(&sums.0[..2 * l + 1]);
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn to_world_avx2(&self, axes: [[f32; 3]; 3], local: &[f32], out: &mut [f32]) {
        self.to_world_lanes(axes, local, out)
    }

    /// The coefficients, in each of `frames` (rows: its x, y, z axes in world space,
    /// orthonormal: a rotation or a mirror), of `channels` functions given in world space
    /// (`world`: K rows of `channels`): K x `channels` per frame, frame after frame. Each is
    /// `to_world` with the world's axes seen from the frame (the transposed rows), one call
    /// per channel.
    pub fn to_frames(&self, world: &[f32], channels: usize, frames: &[[[f32; 3]; 3]]) -> Vec<f32> {
        let k = self.basis.coeffs();
        if channels == 0 {
            return Vec::new();
        }
        let per_channel: Vec<Vec<f32>> = (0..channels).map(|c| (0..k).map(|i| world[i * channels + c]).collect()).collect();
        let mut out = vec![0.0f32; frames.len() * k * channels];
        out.par_chunks_mut(k * channels).zip(frames).for_each(|(out, f)| {
            let world_axes = [0, 1, 2].map(|j| [f[0][j], f[1][j], f[2][j]]);
            let mut rotated = [0.0f32; MAX_COEFFS];
            for (c, function) in per_channel.iter().enumerate() {
                self.to_world(world_axes, function, &mut rotated[..k]);
                for (i, v) in rotated[..k].iter().enumerate() {
                    out[i * channels + c] = *v;
                }
            }
        });
        out
    }

    fn to_world_each(&self, axes: [[f32; 3]; 3], local: &[f32], out: &mut [f32]) {
        let bands = self.basis.bands();
        let mut y = [0.0f32; MAX_COEFFS];
        // f_k^l = band-l part of the function at direction d_k, evaluated in local coordinates.
        let mut values = [[0.0f32; 2 * crate::sh::MAX_BANDS - 1]; crate::sh::MAX_BANDS];
        for (k, d) in self.directions.iter().enumerate() {
            let l_dir = [dot(axes[0], *d), dot(axes[1], *d), dot(axes[2], *d)];
            self.basis.eval(l_dir, &mut y);
            for l in 0..bands {
                if k < 2 * l + 1 {
                    values[l][k] = (l * l..(l + 1) * (l + 1)).map(|i| local[i] * y[i]).sum();
                }
            }
        }
        for l in 0..bands {
            let n = 2 * l + 1;
            let inv = &self.inverses[l];
            for m in 0..n {
                out[l * l + m] = (0..n).map(|k| inv[m * n + k] * values[l][k]).sum();
            }
        }
    }
}

#[inline(always)]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_directions_at_once_give_the_bits_of_one_at_a_time() {
        for bands in 1..=5 {
            let rotator = ShRotator::new(ShBasis::new(bands).unwrap());
            let k = bands * bands;
            let (mut fast, mut each) = ([0.0f32; 25], [0.0f32; 25]);
            for case in 0..2000 {
                let t = case as f32 * 0.731;
                let n = crate::mesh::normalize([t.sin(), (1.7 * t).cos(), (0.3 * t).sin() - 0.1]).unwrap();
                let (tx, bx) = crate::mesh::tangent_frame(n);
                let axes = if case % 3 == 0 { [bx, tx, n] } else { [tx, bx, n] }; // mirrored frames too
                let local: Vec<f32> = (0..k).map(|i| ((i * 13 + case * 7) % 17) as f32 / 8.0 - 1.0).collect();
                rotator.to_world(axes, &local, &mut fast[..k]);
                rotator.to_world_each(axes, &local, &mut each[..k]);
                assert!(fast[..k].iter().zip(&each[..k]).all(|(a, b)| a.to_bits() == b.to_bits()), "bands {bands}, case {case}: {fast:?} vs {each:?}");
            }
        }
    }

    /// In every frame (mirrored ones too), the frame's coefficients at a local direction give
    /// the world function's value at that direction in world space, channel by channel.
    #[test]
    fn functions_seen_from_frames_take_the_same_values() {
        for bands in [1, 3, 5] {
            let basis = ShBasis::new(bands).unwrap();
            let k = bands * bands;
            let world: Vec<f32> = (0..k * 3).map(|i| ((i * 7 % 11) as f32 - 5.0) / 5.0).collect();
            let frames: Vec<[[f32; 3]; 3]> = (0..50)
                .map(|case| {
                    let t = case as f32 * 0.917;
                    let n = crate::mesh::normalize([t.cos(), (2.3 * t).sin(), (0.7 * t).cos() - 0.2]).unwrap();
                    let (tx, bx) = crate::mesh::tangent_frame(n);
                    if case % 2 == 0 { [tx, bx, n] } else { [bx, tx, n] }
                })
                .collect();
            let local = ShRotator::new(basis.clone()).to_frames(&world, 3, &frames);
            let (mut yw, mut yl) = ([0.0f32; 25], [0.0f32; 25]);
            for (f, frame) in frames.iter().enumerate() {
                for d in generic_directions(30) {
                    basis.eval(d, &mut yw);
                    basis.eval([dot(frame[0], d), dot(frame[1], d), dot(frame[2], d)], &mut yl);
                    for c in 0..3 {
                        let fw: f32 = (0..k).map(|i| world[i * 3 + c] * yw[i]).sum();
                        let fl: f32 = (0..k).map(|i| local[(f * k + i) * 3 + c] * yl[i]).sum();
                        assert!((fw - fl).abs() < 1e-4 * (1.0 + fw.abs()), "bands {bands}, frame {f}, channel {c}: {fw} vs {fl}");
                    }
                }
            }
        }
    }

    #[test]
    fn rotated_function_matches_direct_evaluation() {
        let basis = ShBasis::new(5).unwrap();
        let rotator = ShRotator::new(basis.clone());
        let local: Vec<f32> = (0..25).map(|i| ((i * 7 % 11) as f32 - 5.0) / 5.0).collect();
        let n = crate::mesh::normalize([0.3, -0.5, 0.8]).unwrap();
        let (t, b) = crate::mesh::tangent_frame(n);
        let mut world = [0.0f32; 25];
        rotator.to_world([t, b, n], &local, &mut world);
        let (mut yw, mut yl) = ([0.0f32; 25], [0.0f32; 25]);
        for d in generic_directions(40) {
            basis.eval(d, &mut yw);
            basis.eval([dot(t, d), dot(b, d), dot(n, d)], &mut yl);
            let fw: f32 = world.iter().zip(&yw).map(|(a, b)| a * b).sum();
            let fl: f32 = local.iter().zip(&yl).map(|(a, b)| a * b).sum();
            assert!((fw - fl).abs() < 1e-3, "{fw} vs {fl}");
        }
    }
}
