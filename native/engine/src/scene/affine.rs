//! World transforms of instances: a 4x4 matrix (row-major, column vectors, last row 0 0 0 1)
//! kept as a 3x3 linear part and a translation, with what the hierarchy needs from it: the
//! sign of the determinant (a mirrored instance flips facing) and the largest stretch (how
//! much a bounding sphere can grow).

use crate::error::{Error, Result};
use crate::mesh::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Affine {
    /// Rows of the linear part: world = linear * p + translation.
    pub linear: [Vec3; 3],
    pub translation: Vec3,
    /// +1 or -1: a negative determinant turns the winding of every triangle over.
    pub facing: f32,
    /// Largest singular value of `linear` (a sphere of radius r maps into one of radius r * stretch).
    pub stretch: f32,
    /// Rows of the inverse of `linear` (world to mesh space, less the translation).
    pub inverse: [Vec3; 3],
    /// A lower bound of the smallest singular value of `linear`: mesh-space distances times
    /// `shrink` bound world distances from below.
    pub shrink: f32,
}

impl Affine {
    pub const IDENTITY: Affine = Affine {
        linear: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
        facing: 1.0,
        stretch: 1.0,
        inverse: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        shrink: 1.0,
    };

    /// From 16 row-major values; the last row must be (0, 0, 0, 1) and the linear part invertible.
    pub fn from_rows(m: &[f64; 16]) -> Result<Self> {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("matrix must be finite"));
        }
        let last = [m[12], m[13], m[14], m[15]];
        if (last[0].abs() + last[1].abs() + last[2].abs()) > 1e-6 || (last[3] - 1.0).abs() > 1e-6 {
            return Err(Error::invalid(format!("matrix must be affine (last row 0 0 0 1), got last row {last:?}")));
        }
        let l = [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];
        let det = l[0][0] * (l[1][1] * l[2][2] - l[1][2] * l[2][1]) - l[0][1] * (l[1][0] * l[2][2] - l[1][2] * l[2][0])
            + l[0][2] * (l[1][0] * l[2][1] - l[1][1] * l[2][0]);
        let scale = l.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
        if !(det.abs() > 1e-12 * scale.powi(3)) {
            return Err(Error::invalid("matrix must be invertible (its 3x3 part has a zero determinant)"));
        }
        let inverse = invert(&l, det);
        Ok(Affine {
            linear: l.map(|r| r.map(|v| v as f32)),
            translation: [m[3] as f32, m[7] as f32, m[11] as f32],
            facing: if det < 0.0 { -1.0 } else { 1.0 },
            stretch: largest_singular_value(&l) as f32,
            inverse: inverse.map(|r| r.map(|v| v as f32)),
            shrink: (1.0 / largest_singular_value(&inverse)) as f32,
        })
    }

    /// A world point in mesh space.
    #[inline(always)]
    pub fn unapply(&self, p: Vec3) -> Vec3 {
        let d = crate::mesh::sub(p, self.translation);
        self.inverse.map(|r| r[0] * d[0] + r[1] * d[1] + r[2] * d[2])
    }

    #[inline(always)]
    pub fn apply(&self, p: Vec3) -> Vec3 {
        let l = &self.linear;
        [0, 1, 2].map(|r| l[r][0] * p[0] + l[r][1] * p[1] + l[r][2] * p[2] + self.translation[r])
    }

    /// The world box around a local box (Arvo's method: per axis, the extreme of each term).
    pub fn apply_box(&self, b: &[Vec3; 2]) -> [Vec3; 2] {
        let mut out = [self.translation, self.translation];
        for r in 0..3 {
            for c in 0..3 {
                let (e, f) = (self.linear[r][c] * b[0][c], self.linear[r][c] * b[1][c]);
                out[0][r] += e.min(f);
                out[1][r] += e.max(f);
            }
        }
        out
    }
}

/// The inverse of a 3x3 matrix of determinant `det` (the adjugate over the determinant).
fn invert(l: &[[f64; 3]; 3], det: f64) -> [[f64; 3]; 3] {
    let c = |r: usize, k: usize| {
        let (r1, r2, k1, k2) = ((r + 1) % 3, (r + 2) % 3, (k + 1) % 3, (k + 2) % 3);
        l[r1][k1] * l[r2][k2] - l[r1][k2] * l[r2][k1]
    };
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| c(j, i) / det))
}

/// sqrt of the largest eigenvalue of L^T L by power iteration (converges fast for 3x3).
fn largest_singular_value(l: &[[f64; 3]; 3]) -> f64 {
    let mut ata = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            ata[i][j] = (0..3).map(|k| l[k][i] * l[k][j]).sum();
        }
    }
    let mut v = [0.577_350_3, 0.577_350_3, 0.577_350_3];
    let mut lambda = 0.0;
    for _ in 0..64 {
        let w: [f64; 3] = [0, 1, 2].map(|i| (0..3).map(|j| ata[i][j] * v[j]).sum());
        let norm = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        if norm == 0.0 {
            break;
        }
        lambda = norm;
        v = w.map(|x| x / norm);
    }
    // The power iteration approaches from below: a little margin keeps the bound conservative.
    lambda.sqrt() * 1.001
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(linear: [[f64; 3]; 3], t: [f64; 3]) -> [f64; 16] {
        let l = linear;
        [l[0][0], l[0][1], l[0][2], t[0], l[1][0], l[1][1], l[1][2], t[1], l[2][0], l[2][1], l[2][2], t[2], 0.0, 0.0, 0.0, 1.0]
    }

    #[test]
    fn mirror_flips_facing_and_keeps_stretch() {
        let a = Affine::from_rows(&rows([[-2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [1.0, 2.0, 3.0])).unwrap();
        assert_eq!(a.facing, -1.0);
        assert!((a.stretch - 2.0).abs() < 0.01);
        assert_eq!(a.apply([1.0, 1.0, 1.0]), [-1.0, 3.0, 4.0]);
        assert!((a.shrink - 1.0).abs() < 0.01 && a.shrink <= 1.0);
    }

    #[test]
    fn unapply_inverts_apply_and_shrink_bounds_distances() {
        let a = Affine::from_rows(&rows([[0.0, -3.0, 0.0], [0.5, 0.0, 0.2], [0.0, 0.0, 2.0]], [1.0, -2.0, 0.5])).unwrap();
        for p in [[0.3f32, -1.0, 2.0], [5.0, 0.0, -4.0], [0.0, 0.0, 0.0]] {
            let q = a.unapply(a.apply(p));
            assert!((0..3).all(|k| (q[k] - p[k]).abs() < 1e-5), "{p:?} -> {q:?}");
        }
        // Unit mesh-space steps never map shorter than `shrink`.
        for d in [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [-0.2, 0.6, 0.77]] {
            let (o, w) = (a.apply([0.0; 3]), a.apply(d));
            let len = crate::mesh::length(crate::mesh::sub(w, o)) / crate::mesh::length(d);
            assert!(len >= a.shrink * 0.999, "{d:?}: {len} < {}", a.shrink);
        }
    }

    #[test]
    fn box_of_rotated_box_contains_the_corners() {
        let (c, s) = (0.6f64, 0.8f64);
        let a = Affine::from_rows(&rows([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], [0.0; 3])).unwrap();
        let b = a.apply_box(&[[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]);
        assert!((b[1][0] - 1.4).abs() < 1e-5 && (b[0][1] + 1.4).abs() < 1e-5);
    }

    #[test]
    fn singular_and_projective_matrices_are_refused() {
        assert!(Affine::from_rows(&rows([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [0.0; 3])).is_err());
        let mut m = rows([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [0.0; 3]);
        m[12] = 0.5;
        assert!(Affine::from_rows(&m).is_err());
        m[12] = f64::NAN;
        assert!(Affine::from_rows(&m).is_err());
    }
}
