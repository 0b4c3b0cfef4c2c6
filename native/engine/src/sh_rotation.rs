//! Rotation of SH coefficient vectors into another frame.
//!
//! A band-l function is fixed by its values at 2l+1 generic directions d_k, so coefficients in
//! a rotated frame follow from evaluating the function there and solving with the
//! precomputed inverse of A_l[k][m] = Y_lm(d_k). Cost per rotation: 2 bands - 1 basis
//! evaluations and two small matrix products per band, with no recursion on rotation
//! matrices (compare Ivanic and Ruedenberg 1996, which is faster but far longer).

use crate::sh::{ShBasis, MAX_COEFFS};

pub struct ShRotator {
    basis: ShBasis,
    directions: Vec<[f32; 3]>,
    /// Per band l, the (2l+1)^2 row-major inverse of A_l.
    inverses: Vec<Vec<f32>>,
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
        let inverses = (0..bands)
            .map(|l| {
                let n = 2 * l + 1;
                let a: Vec<f64> = (0..n * n).map(|e| values[e / n][l * l + e % n] as f64).collect();
                invert(&a, n).expect("generic directions make every band's matrix invertible").into_iter().map(|v| v as f32).collect()
            })
            .collect();
        ShRotator { basis, directions, inverses }
    }

    /// Coefficients in world space of a function given by `local` coefficients in the frame
    /// whose axes (in world space) are `axes` = [x, y, z] (tangent, bitangent, normal).
    pub fn to_world(&self, axes: [[f32; 3]; 3], local: &[f32], out: &mut [f32]) {
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
