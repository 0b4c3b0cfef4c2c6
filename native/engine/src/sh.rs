//! Real orthonormal spherical harmonics in the project's binding convention.
//!
//! Wong, Or, Fu, "Real-time relighting of compressed panoramas" (2003), appendix:
//! theta from +Z, phi from +X towards +Y, Condon-Shortley phase included, index i = l(l+1)+m.
//! Evaluated without trigonometry: sin^m(theta) cos(m phi) = Re((x+iy)^m) and
//! sin^m(theta) sin(m phi) = Im((x+iy)^m), so only the Legendre part Q_lm / sin^m is recursive.

use crate::error::{Error, Result};

/// Largest number of bands the engine evaluates (l = 0..MAX_BANDS-1).
pub const MAX_BANDS: usize = 8;
/// Coefficients for `MAX_BANDS` bands.
pub const MAX_COEFFS: usize = MAX_BANDS * MAX_BANDS;

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

    /// Bands 0..4 with the recursion of `eval_any` expanded: Q_lm(z) / sin^m for l <= 4.
    #[inline(always)]
    fn eval5(&self, [x, y, z]: [f32; 3], out: &mut [f32; 25]) {
        let n = &self.norm;
        let (c1, s1) = (x, y);
        let (c2, s2) = (x * c1 - y * s1, x * s1 + y * c1);
        let (c3, s3) = (x * c2 - y * s2, x * s2 + y * c2);
        let (c4, s4) = (x * c3 - y * s3, x * s3 + y * c3);
        let z2 = z * z;
        // (l, m, Q_lm / sin^m): from the appendix's recursion, (1 - 2m) factors included.
        let q = [
            (0, 0, 1.0),
            (1, 0, z),
            (1, 1, -1.0),
            (2, 0, 1.5 * z2 - 0.5),
            (2, 1, -3.0 * z),
            (2, 2, 3.0),
            (3, 0, z * (2.5 * z2 - 1.5)),
            (3, 1, 1.5 - 7.5 * z2),
            (3, 2, 15.0 * z),
            (3, 3, -15.0),
            (4, 0, (35.0 * z2 * z2 - 30.0 * z2 + 3.0) / 8.0),
            (4, 1, z * (7.5 - 17.5 * z2)),
            (4, 2, 52.5 * z2 - 7.5),
            (4, 3, -105.0 * z),
            (4, 4, 105.0),
        ];
        let cos_m = [1.0, c1, c2, c3, c4];
        let sin_m = [0.0, s1, s2, s3, s4];
        for (l, m, qlm) in q {
            let centre = l * (l + 1);
            out[centre + m] = n[centre + m] * qlm * cos_m[m];
            if m > 0 {
                out[centre - m] = n[centre - m] * qlm * sin_m[m];
            }
        }
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
            let sign = if (half - 1) % 2 == 0 { 1.0 } else { -1.0 };
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
    fn rejects_bad_band_counts() {
        assert!(ShBasis::new(0).is_err());
        assert!(ShBasis::new(MAX_BANDS + 1).is_err());
    }
}
