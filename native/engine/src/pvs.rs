//! Potentially visible sets (Kautz et al. 2004, section 3.2, "Potentially Visible Sets"):
//! from a few sampled poses, keep per receiver the units that ever contribute to its mask, so
//! later frames rasterize only those (the paper reports about 75 % fewer triangles). A unit is
//! what the walk draws as one: a cluster (id `c`), or a node of the group tree drawn through
//! its proxy (id `clusters + n`), so that the sets keep the tree's distant proxies.
//!
//! A unit contributes in a pose when, taken nearest first, its own mask adds cells that the
//! nearer units have not covered; dropping the others leaves that pose's mask unchanged.
//! A frame uses the sets only while its pose stays within `tolerance` of a sampled pose (the
//! largest vertex displacement, in the solver's normalised units where the rest pose spans
//! [-1, 1]); farther poses fall back to the full hierarchy.

use crate::disk_mask::{Mask, MASK_SIDE};
use crate::mesh::Vec3;

pub struct Pvs {
    /// Units each welded vertex keeps, ascending (CSR).
    start: Vec<u32>,
    units: Vec<u32>,
    /// Units below this id are clusters; the rest are nodes of the group tree.
    clusters: u32,
    /// The sampled poses, welded and normalised.
    poses: Vec<Vec<Vec3>>,
    pub tolerance: f32,
}

impl Pvs {
    /// `per_pose[p][v]`: units vertex v needs in pose p (any order), of a hierarchy with
    /// `clusters` clusters.
    pub fn new(per_pose: Vec<Vec<Vec<u32>>>, poses: Vec<Vec<Vec3>>, clusters: u32, tolerance: f32) -> Self {
        let vertices = per_pose.first().map_or(0, Vec::len);
        let mut start = Vec::with_capacity(vertices + 1);
        let mut units = Vec::new();
        start.push(0);
        let mut merged = Vec::new();
        for v in 0..vertices {
            merged.clear();
            per_pose.iter().for_each(|pose| merged.extend_from_slice(&pose[v]));
            merged.sort_unstable();
            merged.dedup();
            units.extend_from_slice(&merged);
            start.push(units.len() as u32);
        }
        Pvs { start, units, clusters, poses, tolerance }
    }

    /// The units `vertex` keeps, ascending: its clusters first.
    #[inline(always)]
    pub fn of(&self, vertex: usize) -> &[u32] {
        &self.units[self.start[vertex] as usize..self.start[vertex + 1] as usize]
    }

    /// The unit id of the group tree's node `n`.
    #[inline(always)]
    pub fn node_unit(&self, n: usize) -> u32 {
        node_unit(self.clusters as usize, n)
    }

    /// Whether `vertex` keeps a unit with an id in `ids`.
    #[inline(always)]
    pub fn keeps_any(&self, vertex: usize, ids: std::ops::Range<u32>) -> bool {
        let units = self.of(vertex);
        units.get(units.partition_point(|&u| u < ids.start)).is_some_and(|&u| u < ids.end)
    }

    /// Clusters kept per vertex, on average (proxies not counted).
    pub fn clusters_per_vertex(&self) -> f64 {
        let clusters = self.units.iter().filter(|&&u| u < self.clusters).count();
        clusters as f64 / (self.start.len() - 1).max(1) as f64
    }

    pub fn poses(&self) -> usize {
        self.poses.len()
    }

    /// The largest vertex displacement from `positions` to the nearest sampled pose.
    pub fn distance(&self, positions: &[Vec3]) -> f32 {
        self.poses.iter().map(|pose| max_displacement(pose, positions)).fold(f32::INFINITY, f32::min)
    }

    pub fn covers(&self, positions: &[Vec3]) -> bool {
        self.distance(positions) <= self.tolerance
    }

    pub fn bytes(&self) -> usize {
        (self.start.len() + self.units.len()) * 4 + self.poses.iter().map(|p| p.len() * 12).sum::<usize>()
    }
}

/// The mask grown by one cell in the 8 directions.
fn grow(mask: &Mask) -> Mask {
    let mut out = Mask::EMPTY;
    for row in 0..MASK_SIDE {
        let bits = mask.row_bits(row);
        let spread = bits | bits << 1 | bits >> 1;
        for r in row.saturating_sub(1)..(row + 2).min(MASK_SIDE) {
            out.0[r / 2] |= (spread as u64) << (32 * (r % 2));
        }
    }
    out
}

fn max_displacement(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .fold(0.0, f32::max)
}

/// The unit id of node `n` of the group tree over a hierarchy of `clusters` clusters.
#[inline(always)]
pub fn node_unit(clusters: usize, n: usize) -> u32 {
    (clusters + n) as u32
}

/// Cells by which a unit's mask is grown before the coverage test: a unit is dropped
/// only when nearer ones cover it with this margin, so that a small motion does not reveal it.
pub const MARGIN_CELLS: usize = 2;

/// The units that contribute, given each candidate's squared distance, id and mask: nearest
/// first, those whose mask, grown by `MARGIN_CELLS`, adds cells to what the nearer ones cover.
pub fn contributing(mut candidates: Vec<(f32, u32, Mask)>) -> Vec<u32> {
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
    let disk = crate::disk_mask::disk();
    let mut covered = Mask::EMPTY;
    let mut kept = Vec::new();
    for (_, cluster, mask) in candidates {
        let grown = (0..MARGIN_CELLS).fold(mask, |m, _| grow(&m));
        let uncovered = grown.and_not(&covered);
        if uncovered.0.iter().zip(&disk.0).any(|(u, d)| u & d != 0) {
            covered.or_assign(&mask);
            kept.push(cluster);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(bits: &[(usize, usize)]) -> Mask {
        let mut m = Mask::EMPTY;
        bits.iter().for_each(|&(r, c)| m.set(r, c));
        m
    }

    #[test]
    fn hidden_clusters_are_dropped_and_sets_merge_over_poses() {
        let block: Vec<(usize, usize)> = (8..20).flat_map(|r| (8..20).map(move |c| (r, c))).collect();
        let near = mask(&block);
        let hidden = mask(&[(12, 12), (13, 14)]);
        let at_the_edge = mask(&[(12, 18)]); // within the margin of the block's border
        let beside = mask(&[(25, 5)]);
        let candidates = vec![(4.0, 7, hidden), (1.0, 3, near), (9.0, 5, beside), (5.0, 8, at_the_edge)];
        assert_eq!(contributing(candidates), vec![3, 8, 5]);
        let pvs = Pvs::new(vec![vec![vec![3, 5, 12]], vec![vec![7, 3]]], vec![vec![[0.0; 3]], vec![[1.0, 0.0, 0.0]]], 10, 0.1);
        assert_eq!(pvs.of(0), &[3, 5, 7, 12]);
        assert_eq!(pvs.clusters_per_vertex(), 3.0);
        assert!(pvs.keeps_any(0, pvs.node_unit(2)..pvs.node_unit(3)) && !pvs.keeps_any(0, pvs.node_unit(0)..pvs.node_unit(2)));
        assert!(pvs.keeps_any(0, 4..6) && !pvs.keeps_any(0, 8..10) && !pvs.keeps_any(0, 13..20));
        assert!(pvs.covers(&[[0.95, 0.0, 0.0]]) && !pvs.covers(&[[0.5, 0.0, 0.0]]));
    }
}
