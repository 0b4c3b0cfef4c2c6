//! Real orthonormal spherical harmonics in the project's binding convention.
//!
//! Wong, Or, Fu, "Real-time relighting of compressed panoramas" (2003), appendix:
//! theta from +Z, phi from +X towards +Y, Condon-Shortley phase included, index i = l(l+1)+m.
//! Evaluated without trigonometry: sin^m(theta) cos(m phi) = Re((x+iy)^m) and
//! sin^m(theta) sin(m phi) = Im((x+iy)^m), so only the Legendre part Q_lm / sin^m is recursive.

use std::ops::{Add, Div, Mul, Sub};

use crate::error::{Error, Result};

/// Largest number of bands the engine evaluates (l = 0..MAX_BANDS-1).
pub const MAX_BANDS: usize = 8;
/// Coefficients for `MAX_BANDS` bands.
pub const MAX_COEFFS: usize = MAX_BANDS * MAX_BANDS;

/// What `ShBasis::eval5` computes on: one value (f32) or `Lanes16`.
pub trait Real: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> {
    fn splat(v: f32) -> Self;
}

impl Real for f32 {
    #[inline(always)]
    fn splat(v: f32) -> f32 {
        v
    }
}

/// 16 values with element-wise IEEE operations (no fused multiply-add): the compiler
/// vectorizes them, and each lane has the bits the scalar code gives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lanes16(pub [f32; 16]);

impl Real for Lanes16 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Lanes16([v; 16])
    }
}

macro_rules! lanes16_op {
    ($trait:ident, $method:ident, $op:tt) => {
        impl $trait for Lanes16 {
            type Output = Lanes16;
            #[inline(always)]
            fn $method(self, other: Lanes16) -> Lanes16 {
                Lanes16(std::array::from_fn(|j| self.0[j] $op other.0[j]))
            }
        }
    };
}
lanes16_op!(Add, add, +);
lanes16_op!(Sub, sub, -);
lanes16_op!(Mul, mul, *);
lanes16_op!(Div, div, /);

/// Rejects band counts outside 1..=MAX_BANDS.
pub fn check_bands(bands: usize) -> Result<usize> {
    if (1..=MAX_BANDS).contains(&bands) {
        Ok(bands * bands)
    } else {
        Err(Error::invalid(format!(
            "bands must be between 1 and {MAX_BANDS} (9, 16 and 25 coefficients are bands 3, 4, 5), got {bands}"
        )))
    }
}

/// Precomputed normalisation constants N_lm (sqrt 2 folded in for m != 0).
#[derive(Clone)]
pub struct ShBasis {
    bands: usize,
    norm: [f32; MAX_COEFFS],
}

fn factorial_ratio(l: usize, m: usize) -> f64 {
    // (l-m)! / (l+m)!
    ((l - m + 1)..=(l + m)).fold(1.0, |acc, k| acc / k as f64)
}

impl ShBasis {
    pub fn new(bands: usize) -> Result<Self> {
        check_bands(bands)?;
        let mut norm = [0.0f32; MAX_COEFFS];
        for l in 0..bands {
            for m in 0..=l {
                // N_lm of the appendix; m = 0 carries the extra 1/sqrt(2).
                let mut n = ((2 * l + 1) as f64 / (2.0 * std::f64::consts::PI) * factorial_ratio(l, m)).sqrt();
                if m == 0 {
                    n /= std::f64::consts::SQRT_2;
                }
                norm[l * (l + 1) + m] = n as f32;
                norm[l * (l + 1) - m] = n as f32;
            }
        }
        Ok(ShBasis { bands, norm })
    }

    pub fn bands(&self) -> usize {
        self.bands
    }

    pub fn coeffs(&self) -> usize {
        self.bands * self.bands
    }

    /// Writes Y_i(d) for a unit direction d into `out[..coeffs]`.
    #[inline]
    pub fn eval(&self, d: [f32; 3], out: &mut [f32]) {
        if self.bands <= 5 {
            // The hot case (the kernel evaluates 25 coefficients): straight-line code.
            let mut all = [0.0f32; 25];
            self.eval5(d, &mut all);
            let k = self.bands * self.bands;
            out[..k].copy_from_slice(&all[..k]);
        } else {
            self.eval_any(d, out, self.bands);
        }
    }

    /// `eval5` of several directions at once, lane j holding direction j: the same
    /// operations in the same order per lane, so each lane has the bits `eval` gives.
    #[inline(always)]
    pub fn eval5_lanes(&self, d: [Lanes16; 3], out: &mut [Lanes16; 25]) {
        self.eval5(d, out);
    }

    /// Bands 0..4 with the recursion of `eval_any` expanded: Q_lm(z) / sin^m for l <= 4, of
    /// one direction (f32) or of 16 (`Lanes16`).
    #[inline(always)]
    fn eval5<T: Real>(&self, [x, y, z]: [T; 3], out: &mut [T; 25]) {
        let norm = &self.norm;
        let n = |i: usize| T::splat(norm[i]);
        let k = T::splat;
        let (c1, s1) = (x, y);
        let (c2, s2) = (x * c1 - y * s1, x * s1 + y * c1);
        let (c3, s3) = (x * c2 - y * s2, x * s2 + y * c2);
        let (c4, s4) = (x * c3 - y * s3, x * s3 + y * c3);
        let z2 = z * z;
        let cos_m = [k(1.0), c1, c2, c3, c4];
        let sin_m = [k(0.0), s1, s2, s3, s4];
        // A macro rather than a closure: inlined into the callers' AVX2 copies.
        macro_rules! put {
            ($l:expr, $m:expr, $qlm:expr) => {{
                let (centre, m, qlm): (usize, usize, T) = ($l * ($l + 1), $m, $qlm);
                out[centre + m] = n(centre + m) * qlm * cos_m[m];
                if m > 0 {
                    out[centre - m] = n(centre - m) * qlm * sin_m[m];
                }
            }};
        }
        put!(0, 0, k(1.0));
        put!(1, 0, z);
        put!(1, 1, k(-1.0));
        put!(2, 0, k(1.5) * z2 - k(0.5));
        put!(2, 1, k(-3.0) * z);
        put!(2, 2, k(3.0));
        put!(3, 0, z * (k(2.5) * z2 - k(1.5)));
        put!(3, 1, k(1.5) - k(7.5) * z2);
        put!(3, 2, k(15.0) * z);
        put!(3, 3, k(-15.0));
        put!(4, 0, (k(35.0) * z2 * z2 - k(30.0) * z2 + k(3.0)) / k(8.0));
        put!(4, 1, z * (k(7.5) - k(17.5) * z2));
        put!(4, 2, k(52.5) * z2 - k(7.5));
        put!(4, 3, k(-105.0) * z);
        put!(4, 4, k(105.0));
    }

    #[inline(always)]
    fn eval_any(&self, d: [f32; 3], out: &mut [f32], bands: usize) {
        let out = &mut out[..bands * bands];
        let [x, y, z] = d;
        // (cm, sm) = (Re, Im) of (x + iy)^m; qmm = Q_mm / sin^m = prod (1 - 2k).
        let (mut cm, mut sm) = (1.0f32, 0.0f32);
        let mut qmm = 1.0f32;
        for m in 0..bands {
            if m > 0 {
                let (c, s) = (cm * x - sm * y, cm * y + sm * x);
                cm = c;
                sm = s;
                qmm *= (1 - 2 * m as i32) as f32;
            }
            // Legendre recursion in l for this m.
            let mut q_prev = 0.0f32;
            let mut q = qmm;
            for l in m..bands {
                if l == m + 1 {
                    q_prev = q;
                    q = (2 * m + 1) as f32 * z * qmm;
                } else if l > m + 1 {
                    let next = ((2 * l - 1) as f32 * z * q - (l + m - 1) as f32 * q_prev) / (l - m) as f32;
                    q_prev = q;
                    q = next;
                }
                let centre = l * (l + 1);
                if m == 0 {
                    out[centre] = self.norm[centre] * q;
                } else {
                    out[centre + m] = self.norm[centre + m] * q * cm;
                    out[centre - m] = self.norm[centre - m] * q * sm;
                }
            }
        }
    }
}

/// Zonal coefficients of the clamped cosine: integral of Y_lm(s) max(0, n.s) ds = A_l Y_lm(n).
pub fn clamped_cosine_zonal(l: usize) -> f32 {
    use std::f64::consts::PI;
    let a = match l {
        0 => PI,
        1 => 2.0 * PI / 3.0,
        _ if l % 2 == 1 => 0.0,
        _ => {
            // 2 pi (-1)^(l/2 - 1) / ((l+2)(l-1)) * l! / (2^l ((l/2)!)^2)
            let half = l / 2;
            let sign = if (half - 1).is_multiple_of(2) { 1.0 } else { -1.0 };
            let fact = |n: usize| (1..=n).fold(1.0f64, |acc, k| acc * k as f64);
            2.0 * PI * sign / ((l + 2) as f64 * (l - 1) as f64) * fact(l) / (2f64.powi(l as i32) * fact(half).powi(2))
        }
    };
    a as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convention_signs() {
        let basis = ShBasis::new(2).unwrap();
        let mut y = [0.0f32; 4];
        basis.eval([1.0, 0.0, 0.0], &mut y);
        assert!((y[0] - 0.282_095).abs() < 1e-6);
        assert!((y[3] + 0.488_603).abs() < 1e-6);
        basis.eval([0.0, 1.0, 0.0], &mut y);
        assert!((y[1] + 0.488_603).abs() < 1e-6);
        basis.eval([0.0, 0.0, 1.0], &mut y);
        assert!((y[2] - 0.488_603).abs() < 1e-6);
    }

    #[test]
    fn zonal_clamped_cosine_values() {
        use std::f32::consts::PI;
        let expected = [PI, 2.0 * PI / 3.0, PI / 4.0, 0.0, -PI / 24.0];
        for (l, e) in expected.iter().enumerate() {
            assert!((clamped_cosine_zonal(l) - e).abs() < 1e-6, "l={l}");
        }
    }

    #[test]
    fn expanded_bands_match_the_recursion() {
        let basis = ShBasis::new(5).unwrap();
        for k in 0..50 {
            let t = k as f32 * 0.37;
            let d = crate::mesh::normalize([t.sin(), (1.3 * t).cos(), (0.7 * t).sin() - 0.2]).unwrap();
            let (mut fast, mut slow) = ([0.0f32; 25], [0.0f32; 25]);
            basis.eval(d, &mut fast);
            basis.eval_any(d, &mut slow, 5);
            for i in 0..25 {
                assert!((fast[i] - slow[i]).abs() < 1e-5, "{i}: {} vs {}", fast[i], slow[i]);
            }
        }
    }

    #[test]
    fn lanes_give_the_bits_of_single_directions() {
        let basis = ShBasis::new(5).unwrap();
        let dirs: Vec<[f32; 3]> = (0..64)
            .map(|k| {
                let t = k as f32 * 0.61;
                crate::mesh::normalize([t.cos(), (2.1 * t).sin(), (0.9 * t).cos() - 0.3]).unwrap()
            })
            .collect();
        for chunk in dirs.chunks(16) {
            let lanes = [0, 1, 2].map(|a| Lanes16(std::array::from_fn(|j| chunk[j][a])));
            let mut out = [Lanes16([0.0; 16]); 25];
            basis.eval5_lanes(lanes, &mut out);
            for (j, d) in chunk.iter().enumerate() {
                let mut one = [0.0f32; 25];
                basis.eval(*d, &mut one);
                for i in 0..25 {
                    assert_eq!(out[i].0[j].to_bits(), one[i].to_bits(), "Y_{i}({d:?})");
                }
            }
        }
    }

    #[test]
    fn rejects_bad_band_counts() {
        assert!(ShBasis::new(0).is_err());
        assert!(ShBasis::new(MAX_BANDS + 1).is_err());
    }
}
