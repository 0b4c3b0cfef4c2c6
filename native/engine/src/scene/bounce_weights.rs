//! Gathering once for many bounce passes. A receiver's gathered irradiance along its normal is
//! linear in the vertex radiance the scene shows (each covered cell takes its nearest
//! blocker's radiance, interpolated barycentrically), and which blocker a cell sees does not
//! change between passes. So one ordered walk per receiver records, per vertex it sees, the
//! weight that vertex's radiance carries; every pass after that is a sparse product instead
//! of a walk through the scene (the bakers' vertex bounce passes were most of a bake).
//!
//! The weights are those of `gather` with 3 bands followed by the lobe evaluation along the
//! normal (irradiance / pi, SH-filtered with A = pi, 2pi/3, pi/4), so both give the same
//! values up to rounding.

use crate::disk_mask::{Mask, MASK_CELLS};
use crate::error::{Error, Result};
use crate::sh::{ShBasis, MAX_COEFFS};

use super::gather::Projector;
use super::ordered::{DepthSink, Hit, Rgb};

/// Row-compressed weights: receiver r's vertices and weights are the entries
/// `rows[r]..rows[r + 1]`; a vertex is a slot, `first_slot[instance] + vertex id`.
pub struct BounceWeights {
    /// Each receiver's visibility mask from the same walk (covered cells, pinholes closed),
    /// the one `Scene::visibility` gives: the bounce surfaces' direct light needs it too.
    pub masks: Vec<Mask>,
    /// Whether each receiver is outside solid geometry, as `Scene::valid` decides it, from
    /// the same walk (`receivers::is_valid` of its back faces).
    pub valid: Vec<bool>,
    rows: Vec<usize>,
    slots: Vec<u32>,
    weights: Vec<f32>,
    first_slot: Vec<u32>,
    /// The scene's instance stamps when recorded: any change to its blockers renews one.
    stamps: Vec<u64>,
}

/// The vertex slot of each instance's first vertex, and the total after the last.
pub fn first_slots(vertex_counts: impl Iterator<Item = usize>) -> Result<Vec<u32>> {
    let mut first = vec![0u32];
    for count in vertex_counts {
        let next = *first.last().expect("non-empty") as u64 + count as u64;
        let next = u32::try_from(next).map_err(|_| Error::invalid("bounce weights: the instances hold more than 4 billion vertices"))?;
        first.push(next);
    }
    Ok(first)
}

/// Per cell, the irradiance / pi along the receiver's normal (its local +Z) that unit
/// radiance over the cell gives, filtered through 3 SH bands as `gather` + lobe evaluation
/// (computed once: a few milliseconds, which every call paid).
pub fn normal_cell_weights() -> &'static [f32] {
    static WEIGHTS: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    WEIGHTS.get_or_init(cell_weights_along_z)
}

fn cell_weights_along_z() -> Vec<f32> {
    let basis = ShBasis::new(3).expect("3 bands");
    let projector = Projector::new(basis.clone());
    let mut y = [0.0f32; MAX_COEFFS];
    basis.eval([0.0, 0.0, 1.0], &mut y);
    let band = |i: usize| match i {
        0 => 1.0,
        1..=3 => 2.0 / 3.0,
        _ => 0.25,
    };
    (0..MASK_CELLS).map(|cell| projector.cell_weights(cell).iter().enumerate().map(|(i, w)| band(i) * y[i] * w).sum()).collect()
}

/// Per thread: the walk's stack and a dense accumulator over every vertex slot.
pub struct Scratch {
    pub stack: Vec<crate::mesh::Vec3>,
    sums: Vec<f32>,
    seen: Vec<bool>,
    touched: Vec<u32>,
}

impl Scratch {
    pub fn new(slots: usize) -> Self {
        Scratch { stack: Vec::new(), sums: vec![0.0; slots], seen: vec![false; slots], touched: Vec::new() }
    }
}

/// One receiver's vertex slots and their weights, in slot order.
pub type Row = (Vec<u32>, Vec<f32>);

/// One receiver's row: the weight of every vertex its covered cells see.
pub fn row(sink: &DepthSink, cell_weights: &[f32], first_slot: &[u32], scratch: &mut Scratch) -> Row {
    let Scratch { sums, seen, touched, .. } = scratch;
    let mut sources = [(0, 0.0); 4];
    for (cell, &cell_weight) in cell_weights.iter().enumerate() {
        let count = sink.sources(cell, &mut sources);
        for &(source, share) in &sources[..count] {
            let Some(Hit { instance, ids, weights }) = sink.hit(source) else { continue };
            let base = first_slot[instance as usize];
            for (id, b) in ids.iter().zip(weights) {
                let slot = (base + id) as usize;
                if !seen[slot] {
                    seen[slot] = true;
                    touched.push(slot as u32);
                }
                sums[slot] += cell_weight * share * b;
            }
        }
    }
    touched.sort_unstable();
    let weights = touched.iter().map(|&s| std::mem::take(&mut sums[s as usize])).collect();
    touched.iter().for_each(|&s| seen[s as usize] = false);
    (std::mem::take(touched), weights)
}

impl BounceWeights {
    /// From each receiver's mask and row (`row`).
    pub fn new(receivers: Vec<(Mask, bool, Row)>, first_slot: Vec<u32>, stamps: Vec<u64>) -> Self {
        let mut masks = Vec::with_capacity(receivers.len());
        let mut valid = Vec::with_capacity(receivers.len());
        let mut rows = Vec::with_capacity(receivers.len());
        for (mask, ok, row) in receivers {
            masks.push(mask);
            valid.push(ok);
            rows.push(row);
        }
        let mut offsets = Vec::with_capacity(rows.len() + 1);
        offsets.push(0);
        let total = rows.iter().map(|r| r.0.len()).sum();
        let (mut slots, mut weights) = (Vec::with_capacity(total), Vec::with_capacity(total));
        for (s, w) in rows {
            slots.extend(s);
            weights.extend(w);
            offsets.push(slots.len());
        }
        BounceWeights { masks, valid, rows: offsets, slots, weights, first_slot, stamps }
    }

    pub fn receivers(&self) -> usize {
        self.rows.len() - 1
    }

    /// Stored (vertex, weight) pairs over all receivers.
    pub fn entries(&self) -> usize {
        self.slots.len()
    }

    /// Irradiance / pi (3 per receiver, unclamped) under per-instance vertex radiance (None:
    /// black) of the scene whose instance stamps are `stamps`: the scene they were recorded
    /// in, with its blockers as they were (else what the receivers see may have changed).
    pub fn apply(&self, radiance: &[Option<&[Rgb]>], stamps: &[u64]) -> Result<Vec<f32>> {
        if stamps != self.stamps {
            return Err(Error::invalid("the scene's geometry or instances changed since these bounce weights were recorded (or they belong to another scene): record them again"));
        }
        let mut flat = vec![[0.0f32; 3]; *self.first_slot.last().expect("non-empty") as usize];
        for (i, r) in radiance.iter().enumerate() {
            if let Some(r) = r {
                flat[self.first_slot[i] as usize..self.first_slot[i + 1] as usize].copy_from_slice(r);
            }
        }
        use rayon::prelude::*;
        Ok(self
            .rows
            .par_windows(2)
            .flat_map_iter(|w| {
                let mut sum = [0.0f32; 3];
                for (s, wt) in self.slots[w[0]..w[1]].iter().zip(&self.weights[w[0]..w[1]]) {
                    let rgb = flat[*s as usize];
                    (0..3).for_each(|c| sum[c] += wt * rgb[c]);
                }
                sum
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_weights_integrate_a_white_sky_to_one() {
        // irradiance / pi of unit radiance over the hemisphere is 1; the 3-band filter keeps
        // it (the hemisphere's clamped cosine is smooth), up to the rim cells' quadrature.
        let total: f32 = normal_cell_weights().iter().sum();
        assert!((total - 1.0).abs() < 0.02, "{total}");
    }

    #[test]
    fn apply_weighs_each_instances_vertices() {
        let first = first_slots([2usize, 1].into_iter()).unwrap();
        let rows = vec![(vec![0, 2], vec![0.5, 0.25]), (vec![], vec![]), (vec![1], vec![2.0])];
        let w = BounceWeights::new(rows.into_iter().map(|r| (Mask::EMPTY, true, r)).collect(), first, vec![7, 8]);
        let a: Vec<Rgb> = vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let b: Vec<Rgb> = vec![[8.0, 8.0, 8.0]];
        let out = w.apply(&[Some(&a), Some(&b)], &[7, 8]).unwrap();
        assert_eq!(out, vec![2.5, 3.0, 3.5, 0.0, 0.0, 0.0, 8.0, 10.0, 12.0]);
        let dark = w.apply(&[Some(&a), None], &[7, 8]).unwrap();
        assert_eq!(&dark[..3], &[0.5, 1.0, 1.5]);
        assert!(w.apply(&[Some(&a), Some(&b)], &[7, 9]).is_err());
    }
}
