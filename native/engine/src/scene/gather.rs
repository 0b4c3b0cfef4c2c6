//! Gathering: the SH projection of the radiance arriving from the blockers (the ordered mode's
//! per-cell radiance), integral of L(s) Y_i(s) ds over the receiver's hemisphere, or over the
//! whole sphere for probes (two hemispheres, +Z and -Z). Cells carry cosine-weighted solid
//! angle (the disk's area), so each cell's basis integral is taken over solid angle once, in
//! the receiver's frame, by supersampling (ds = dA / z); one SH rotation per colour channel
//! takes the sum to world space. Cells where nothing is seen add nothing: the environment is
//! the caller's (transfer).

use crate::disk_mask::{cell_direction, lift, MASK_CELLS, MASK_SIDE};
use crate::sh::{ShBasis, MAX_COEFFS};
use crate::sh_rotation::ShRotator;
use crate::transfer::Receiver;

use super::ordered::DepthSink;

/// Subsamples per cell side for the basis integrals.
const SUB: usize = 8;

pub struct Projector {
    basis: ShBasis,
    rotator: ShRotator,
    /// Per cell, the integral of each local basis function over the cell's solid angle.
    weights: Vec<f32>,
}

impl Projector {
    pub fn new(basis: ShBasis) -> Self {
        let k = basis.coeffs();
        let mut weights = vec![0.0f32; MASK_CELLS * k];
        let mut y = [0.0f32; MAX_COEFFS];
        let cell = 2.0 / MASK_SIDE as f64;
        for i in 0..MASK_CELLS {
            let (row, col) = (i / MASK_SIDE, i % MASK_SIDE);
            if cell_direction(row, col).is_none() {
                continue;
            }
            let mut sums = [0.0f64; MAX_COEFFS];
            for sy in 0..SUB {
                for sx in 0..SUB {
                    let x = -1.0 + cell * (col as f64 + (sx as f64 + 0.5) / SUB as f64);
                    let yy = -1.0 + cell * (row as f64 + (sy as f64 + 0.5) / SUB as f64);
                    let z2 = 1.0 - x * x - yy * yy;
                    if z2 <= 0.0 {
                        continue;
                    }
                    basis.eval(lift(x as f32, yy as f32), &mut y);
                    let w = (cell / SUB as f64).powi(2) / z2.sqrt();
                    sums[..k].iter_mut().zip(&y[..k]).for_each(|(s, v)| *s += *v as f64 * w);
                }
            }
            weights[i * k..(i + 1) * k].iter_mut().zip(&sums[..k]).for_each(|(w, s)| *w = *s as f32);
        }
        Projector { rotator: ShRotator::new(basis.clone()), basis, weights }
    }

    pub fn coeffs(&self) -> usize {
        self.basis.coeffs()
    }

    /// The integral of each local basis function over one cell's solid angle.
    pub fn cell_weights(&self, cell: usize) -> &[f32] {
        let k = self.coeffs();
        &self.weights[cell * k..(cell + 1) * k]
    }

    /// Adds the SH projection (k x 3, coefficient-major) of what `sink` saw to `out`.
    pub fn add(&self, sink: &DepthSink, receiver: &Receiver, out: &mut [f32]) {
        let k = self.coeffs();
        let mut local = [[0.0f32; MAX_COEFFS]; 3];
        for cell in 0..MASK_CELLS {
            let rgb = sink.colour[cell]; // a pinhole shows its neighbours' light (`DepthSink::sources`)
            if rgb == [0.0; 3] {
                continue;
            }
            let w = self.cell_weights(cell);
            for ch in 0..3 {
                if rgb[ch] != 0.0 {
                    local[ch][..k].iter_mut().zip(w).for_each(|(l, w)| *l += rgb[ch] * w);
                }
            }
        }
        let f = receiver.frame;
        let mut world = [0.0f32; MAX_COEFFS];
        for ch in 0..3 {
            self.rotator.to_world([f.t, f.b, f.n], &local[ch][..k], &mut world[..k]);
            for i in 0..k {
                out[i * 3 + ch] += world[i];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_weights_add_up_to_the_hemisphere() {
        let p = Projector::new(ShBasis::new(3).unwrap());
        let y00: f32 = (0..MASK_CELLS).map(|c| p.weights[c * 9]).sum();
        // integral of Y_00 over a hemisphere: 2 pi x 0.282095; the disk's rim cells are
        // sampled at midpoints, which miss a little of the 1/z singularity there.
        let exact = 2.0 * std::f32::consts::PI * 0.282_095;
        assert!((y00 - exact).abs() < 0.02 * exact, "{y00} vs {exact}");
    }
}
