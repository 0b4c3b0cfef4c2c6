//! Real SH (bands 0..4, the binding convention with the Condon-Shortley phase) of 8 unit
//! directions at once, as straight-line per-lane code: inside an AVX2 function the compiler
//! vectorizes it, in the portable path it does not, and both give the same bits (the same
//! IEEE operations per lane, no fused multiply-add).

pub const LANES: usize = 8;
pub type Lanes = [f32; LANES];

const C0: f32 = 0.282_094_79;
const C1: f32 = 0.488_602_51;
const C2A: f32 = 1.092_548_4;
const C2B: f32 = 0.315_391_57;
const C2C: f32 = 0.546_274_2;
const C3A: f32 = 0.590_043_6;
const C3B: f32 = 2.890_611_4;
const C3C: f32 = 0.457_045_8;
const C3D: f32 = 0.373_176_33;
const C3E: f32 = 1.445_305_7;
const C4A: f32 = 2.503_343;
const C4B: f32 = 1.770_130_8;
const C4C: f32 = 0.946_174_7;
const C4D: f32 = 0.669_046_5;
const C4E: f32 = 0.105_785_55;
const C4F: f32 = 0.473_087_35;
const C4G: f32 = 0.625_835_7;

/// Y_i of the directions (x, y, z) (unit) for i < coeffs (1, 4, 9, 16 or 25; bands 0..2 are
/// always written), lane j = direction j.
#[inline(always)]
pub fn eval(x: &Lanes, y: &Lanes, z: &Lanes, coeffs: usize, out: &mut [Lanes; 25]) {
    for j in 0..LANES {
        let (x, y, z) = (x[j], y[j], z[j]);
        let (x2, y2, z2) = (x * x, y * y, z * z);
        out[0][j] = C0;
        out[1][j] = -C1 * y;
        out[2][j] = C1 * z;
        out[3][j] = -C1 * x;
        out[4][j] = C2A * x * y;
        out[5][j] = -C2A * y * z;
        out[6][j] = C2B * (3.0 * z2 - 1.0);
        out[7][j] = -C2A * x * z;
        out[8][j] = C2C * (x2 - y2);
    }
    if coeffs <= 9 {
        return;
    }
    for j in 0..LANES {
        let (x, y, z) = (x[j], y[j], z[j]);
        let (x2, y2, z2) = (x * x, y * y, z * z);
        out[9][j] = -C3A * y * (3.0 * x2 - y2);
        out[10][j] = C3B * x * y * z;
        out[11][j] = -C3C * y * (5.0 * z2 - 1.0);
        out[12][j] = C3D * z * (5.0 * z2 - 3.0);
        out[13][j] = -C3C * x * (5.0 * z2 - 1.0);
        out[14][j] = C3E * z * (x2 - y2);
        out[15][j] = -C3A * x * (x2 - 3.0 * y2);
    }
    if coeffs <= 16 {
        return;
    }
    for j in 0..LANES {
        let (x, y, z) = (x[j], y[j], z[j]);
        let (x2, y2, z2) = (x * x, y * y, z * z);
        out[16][j] = C4A * x * y * (x2 - y2);
        out[17][j] = -C4B * y * z * (3.0 * x2 - y2);
        out[18][j] = C4C * x * y * (7.0 * z2 - 1.0);
        out[19][j] = -C4D * y * z * (7.0 * z2 - 3.0);
        out[20][j] = C4E * (35.0 * z2 * z2 - 30.0 * z2 + 3.0);
        out[21][j] = -C4D * x * z * (7.0 * z2 - 3.0);
        out[22][j] = C4F * (x2 - y2) * (7.0 * z2 - 1.0);
        out[23][j] = -C4B * x * z * (x2 - 3.0 * y2);
        out[24][j] = C4G * (x2 * x2 - 6.0 * x2 * y2 + y2 * y2);
    }
}

#[cfg(test)]
mod tests {
    use crate::sh::ShBasis;

    #[test]
    fn matches_the_engine_basis() {
        let basis = ShBasis::new(5).unwrap();
        let dirs: Vec<[f32; 3]> = (0..64)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 64.0;
                let phi = i as f32 * 2.399_963;
                let r = (1.0 - z * z).sqrt();
                [r * phi.cos(), r * phi.sin(), z]
            })
            .collect();
        for chunk in dirs.chunks(8) {
            let x = std::array::from_fn(|j| chunk[j][0]);
            let y = std::array::from_fn(|j| chunk[j][1]);
            let z = std::array::from_fn(|j| chunk[j][2]);
            let mut out = [[0.0; 8]; 25];
            super::eval(&x, &y, &z, 25, &mut out);
            for (j, d) in chunk.iter().enumerate() {
                let mut expect = [0.0; 25];
                basis.eval(*d, &mut expect);
                for i in 0..25 {
                    assert!((out[i][j] - expect[i]).abs() < 2e-6, "Y_{i}({d:?}): {} vs {}", out[i][j], expect[i]);
                }
            }
        }
    }
}
