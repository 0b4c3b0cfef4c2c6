//! The two-level mesh hierarchy of Kautz et al. 2004, section 3.2 ("Mesh Hierarchy").
//!
//! Blockers near a receiver come from the full-resolution mesh, the rest from a coarse mesh
//! whose vertices are a subset of the fine ones (meshoptimizer's edge-collapse simplifier), so
//! the coarse mesh deforms with the animation at no cost. Each fine triangle is owned by the
//! coarse triangle nearest to it at rest; a coarse triangle and the fine triangles it owns form
//! a cluster. A receiver sees the clusters owning its k-ring as their fine triangles and every
//! other cluster as its coarse triangle: the coarse surface that stands in for the receiver's
//! own neighbourhood (and would cut through it, falsely shadowing concave spots) is replaced
//! by the real one, and no region is left without blockers.

use crate::mesh::Vec3;

/// A list of triangles and the distinct vertices they use (for bounds and for finding what
/// moved); the solver rasterizes them from packets (`packets.rs`).
#[derive(Default)]
pub struct Compact {
    /// Welded vertex ids, each once.
    pub vertices: Vec<u32>,
    /// The triangles over welded ids.
    pub welded: Vec<[u32; 3]>,
}

impl Compact {
    fn new(triangles: impl Iterator<Item = [u32; 3]>) -> Self {
        let mut compact = Compact::default();
        let mut seen = std::collections::HashSet::new();
        for tri in triangles {
            compact.vertices.extend(tri.iter().filter(|&&v| seen.insert(v)));
            compact.welded.push(tri);
        }
        compact
    }
}

/// Clusters per group: groups are culled as a whole before their clusters are looked at.
pub const GROUP: usize = 16;

/// Topology-only structure built once per mesh at its rest pose.
pub struct Hierarchy {
    /// Coarse triangles over welded vertex indices; one per cluster, ordered by recursive
    /// bisection of their rest centroids (`bisection_order`), so that every group and every
    /// node of the group tree is a compact region.
    pub coarse: Vec<[u32; 3]>,
    /// Per group of `GROUP` consecutive clusters, its coarse triangles as a compact list.
    pub group_compact: Vec<Compact>,
    /// Fine triangles owned by each cluster (CSR: `owned[owned_start[c]..owned_start[c + 1]]`).
    pub owned_start: Vec<u32>,
    pub owned: Vec<u32>,
    /// Each cluster's fine triangles as a compact list.
    pub cluster_compact: Vec<Compact>,
    /// Clusters each welded vertex sees at full resolution, ascending (CSR like `owned`).
    pub near_start: Vec<u32>,
    pub near: Vec<u32>,
}

/// Default coarse size: a sixteenth of the fine mesh, at least 192 triangles (the paper used
/// 160 to 444; larger coarse meshes cut the false shadowing of concave spots). Receivers see
/// the clusters near them at full resolution, so clusters keep about 16 fine triangles however
/// large the mesh; the group tree (`group_tree.rs`) keeps the distant coarse triangles cheap.
/// Capped at 4096 without it, the 126k-vertex Suzanne rasterized 2,600 triangles per receiver
/// against 1,500 for the 32k one.
pub fn default_coarse_triangles(fine_triangles: usize) -> usize {
    (fine_triangles / 16).max(192).min(fine_triangles)
}

impl Hierarchy {
    /// `coarse_triangles`: target size of the coarse mesh (the simplifier may stop above it).
    /// `ring`: 1 or 2, the k-ring of fine triangles every receiver sees at full resolution.
    pub fn build(positions: &[Vec3], fine: &[[u32; 3]], coarse_triangles: usize, ring: usize) -> Self {
        let coarse = bisection_order(positions, simplify(positions, fine, coarse_triangles));
        let owner = assign_owners(positions, fine, &coarse);
        let (owned_start, owned) = group_by(&owner, coarse.len());
        let (near_start, near) = near_clusters(positions.len(), fine, &owner, ring);
        let group_compact = coarse.chunks(GROUP).map(|group| Compact::new(group.iter().copied())).collect();
        let cluster_compact: Vec<Compact> = (0..coarse.len())
            .map(|c| Compact::new(owned[owned_start[c] as usize..owned_start[c + 1] as usize].iter().map(|&t| fine[t as usize])))
            .collect();
        Hierarchy { coarse, group_compact, owned_start, owned, cluster_compact, near_start, near }
    }

    pub fn clusters(&self) -> usize {
        self.coarse.len()
    }

    pub fn groups(&self) -> usize {
        self.group_compact.len()
    }

    #[inline(always)]
    pub fn owned_by(&self, cluster: usize) -> &[u32] {
        &self.owned[self.owned_start[cluster] as usize..self.owned_start[cluster + 1] as usize]
    }

    #[inline(always)]
    pub fn near_of(&self, vertex: usize) -> &[u32] {
        &self.near[self.near_start[vertex] as usize..self.near_start[vertex + 1] as usize]
    }
}

/// Coarse triangles whose vertices are fine vertices (meshoptimizer keeps a vertex subset).
fn simplify(positions: &[Vec3], fine: &[[u32; 3]], target_triangles: usize) -> Vec<[u32; 3]> {
    let indices: Vec<u32> = fine.iter().flatten().copied().collect();
    // No error limit: the target size decides; borders may move so open meshes simplify too.
    let simplified = meshopt::simplify_decoder(&indices, positions, target_triangles * 3, 1.0, meshopt::SimplifyOptions::None, None);
    let mut coarse: Vec<[u32; 3]> = simplified.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    if coarse.is_empty() {
        coarse = fine.to_vec(); // nothing to simplify (tiny meshes): the fine mesh is its own coarse mesh
    }
    coarse
}

/// Sorts triangles by recursive bisection of their centroids across the longest axis, cut
/// where the group tree (`group_tree.rs`) cuts its ranges, so that every group and every
/// node of the tree is a compact box. Morton order did not cut there: a node's range could
/// straddle two distant regions, whose box was then never far enough to draw through a
/// proxy (the 126k-vertex Suzanne drew 1,870 blockers per receiver against 1,300 now).
fn bisection_order(positions: &[Vec3], triangles: Vec<[u32; 3]>) -> Vec<[u32; 3]> {
    let centres: Vec<Vec3> = triangles.iter().map(|t| centroid(positions, t)).collect();
    let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
    bisect(&centres, &mut order);
    order.into_iter().map(|i| triangles[i as usize]).collect()
}

/// Orders `items` so that the first `GROUP * (groups / 2)` lie on one side of a plane across
/// the longest axis of their box, then each half likewise, down to single groups.
fn bisect(centres: &[Vec3], items: &mut [u32]) {
    let groups = items.len().div_ceil(GROUP);
    if groups <= 1 {
        return;
    }
    let b = crate::mesh::box_of(items.iter().map(|&i| centres[i as usize]));
    let axis = (0..3).max_by(|&a, &c| (b[1][a] - b[0][a]).total_cmp(&(b[1][c] - b[0][c]))).unwrap_or(0);
    let left = GROUP * (groups / 2);
    items.select_nth_unstable_by(left, |&i, &j| centres[i as usize][axis].total_cmp(&centres[j as usize][axis]).then(i.cmp(&j)));
    let (l, r) = items.split_at_mut(left);
    bisect(centres, l);
    bisect(centres, r);
}

/// The indices of `points` in the order of a Morton (Z-order) curve through them: nearby
/// points come close together (equal codes keep their order).
pub fn morton_permutation(points: &[Vec3]) -> Vec<u32> {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for c in points {
        for a in 0..3 {
            lo[a] = lo[a].min(c[a]);
            hi[a] = hi[a].max(c[a]);
        }
    }
    let code = |c: &Vec3| {
        let q = |a: usize| (((c[a] - lo[a]) / (hi[a] - lo[a]).max(1e-20)) * 1023.0) as u32;
        (0..10).fold(0u32, |m, bit| m | ((q(0) >> bit) & 1) << (3 * bit) | ((q(1) >> bit) & 1) << (3 * bit + 1) | ((q(2) >> bit) & 1) << (3 * bit + 2))
    };
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_by_key(|&i| code(&points[i as usize]));
    order
}

fn centroid(positions: &[Vec3], t: &[u32; 3]) -> Vec3 {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0]
}

/// The coarse triangle with the nearest centroid, for every fine triangle (the first on ties).
fn assign_owners(positions: &[Vec3], fine: &[[u32; 3]], coarse: &[[u32; 3]]) -> Vec<u32> {
    use rayon::prelude::*;
    let coarse_centres: Vec<Vec3> = coarse.iter().map(|t| centroid(positions, t)).collect();
    let grid = CentreGrid::new(&coarse_centres);
    fine.par_iter().map(|t| grid.nearest(&coarse_centres, centroid(positions, t))).collect()
}

/// Squared distance, written once so that every search compares the same values.
#[inline(always)]
fn distance2(c: &Vec3, p: &Vec3) -> f32 {
    (c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2) + (c[2] - p[2]).powi(2)
}

/// Centres bucketed in a uniform grid of cells about as wide as their spacing, for nearest
/// queries that look at a few cells instead of every centre (a million fine triangles against
/// 63,000 coarse ones took minutes by brute force).
struct CentreGrid {
    lo: Vec3,
    cell: f32,
    cells: std::collections::HashMap<[i32; 3], Vec<u32>>,
    /// The grid's extent in cells (inclusive), to know when every cell has been searched.
    extent: [[i32; 3]; 2],
}

impl CentreGrid {
    fn new(centres: &[Vec3]) -> Self {
        let b = crate::mesh::box_of(centres.iter().copied());
        let size = (0..3).map(|a| b[1][a] - b[0][a]).fold(0.0f32, f32::max);
        // Centres lie on a surface: about one per cell of a grid over the box's largest face.
        let cell = (size / (centres.len() as f32).sqrt()).max(size * 1e-6).max(f32::MIN_POSITIVE);
        let mut grid = CentreGrid { lo: b[0], cell, cells: Default::default(), extent: [[0; 3]; 2] };
        for (i, c) in centres.iter().enumerate() {
            grid.cells.entry(grid.key(c)).or_default().push(i as u32);
        }
        let keys: Vec<[i32; 3]> = grid.cells.keys().copied().collect();
        grid.extent = [[0, 1, 2].map(|a| keys.iter().map(|k| k[a]).min().unwrap_or(0)), [0, 1, 2].map(|a| keys.iter().map(|k| k[a]).max().unwrap_or(0))];
        grid
    }

    fn key(&self, p: &Vec3) -> [i32; 3] {
        [0, 1, 2].map(|a| ((p[a] - self.lo[a]) / self.cell).floor().clamp(-1e9, 1e9) as i32)
    }

    /// The index of the centre nearest to p, the lowest on ties (as a scan in order gives).
    fn nearest(&self, centres: &[Vec3], p: Vec3) -> u32 {
        let k = self.key(&p);
        let reach = (0..3).map(|a| (k[a] - self.extent[0][a]).abs().max((self.extent[1][a] - k[a]).abs())).max().unwrap_or(0);
        let mut best: Option<(f32, u32)> = None;
        for r in 0..=reach {
            for key in shell(k, r) {
                for &i in self.cells.get(&key).into_iter().flatten() {
                    let d = distance2(&centres[i as usize], &p);
                    if best.is_none_or(|(bd, bi)| d < bd || (d == bd && i < bi)) {
                        best = Some((d, i));
                    }
                }
            }
            // Every centre beyond shell r lies at least r cells away along some axis (less a
            // margin for the rounding of the cell keys).
            if best.is_some_and(|(bd, _)| bd < ((r as f32 - 1e-3) * self.cell).max(0.0).powi(2)) {
                break;
            }
        }
        best.map_or(0, |(_, i)| i)
    }
}

/// The cells at Chebyshev distance exactly r from k.
fn shell(k: [i32; 3], r: i32) -> impl Iterator<Item = [i32; 3]> {
    (-r..=r).flat_map(move |x| (-r..=r).flat_map(move |y| (-r..=r).map(move |z| [x, y, z])))
        .filter(move |d| d.iter().map(|v| v.abs()).max() == Some(r))
        .map(move |d| [k[0] + d[0], k[1] + d[1], k[2] + d[2]])
}

/// CSR grouping of items by their key: (start offsets per key, items).
fn group_by(keys: &[u32], key_count: usize) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; key_count + 1];
    for &k in keys {
        start[k as usize + 1] += 1;
    }
    for i in 0..key_count {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; keys.len()];
    for (item, &k) in keys.iter().enumerate() {
        items[fill[k as usize] as usize] = item as u32;
        fill[k as usize] += 1;
    }
    (start, items)
}

/// Per vertex, the sorted distinct owners of the fine triangles in its k-ring.
fn near_clusters(vertex_count: usize, fine: &[[u32; 3]], owner: &[u32], ring: usize) -> (Vec<u32>, Vec<u32>) {
    let corner_keys: Vec<u32> = fine.iter().flatten().copied().collect();
    let (tri_start, corners) = group_by(&corner_keys, vertex_count); // corner index / 3 = triangle
    let triangles_of = |v: u32| corners[tri_start[v as usize] as usize..tri_start[v as usize + 1] as usize].iter().map(|c| c / 3);
    let mut near_start = Vec::with_capacity(vertex_count + 1);
    let mut near = Vec::new();
    near_start.push(0u32);
    let mut found: Vec<u32> = Vec::new();
    for v in 0..vertex_count as u32 {
        found.clear();
        let mut frontier: Vec<u32> = vec![v];
        for _ in 0..ring.max(1) {
            let mut next = Vec::new();
            for &u in &frontier {
                for t in triangles_of(u) {
                    found.push(owner[t as usize]);
                    next.extend_from_slice(&fine[t as usize]);
                }
            }
            next.sort_unstable();
            next.dedup();
            frontier = next;
        }
        found.sort_unstable();
        found.dedup();
        near.extend_from_slice(&found);
        near_start.push(near.len() as u32);
    }
    (near_start, near)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut positions = Vec::new();
        for j in 0..n {
            for i in 0..n {
                positions.push([i as f32, j as f32, ((i * j) as f32 * 0.1).sin()]);
            }
        }
        let mut tris = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = (j * n + i) as u32;
                tris.push([a, a + 1, a + n as u32 + 1]);
                tris.push([a, a + n as u32 + 1, a + n as u32]);
            }
        }
        (positions, tris)
    }

    #[test]
    fn every_fine_triangle_has_one_owner_and_every_vertex_sees_its_own_ring() {
        let (positions, fine) = grid(30);
        let h = Hierarchy::build(&positions, &fine, 100, 1);
        assert!(h.clusters() <= 120 && h.clusters() >= 50, "{}", h.clusters());
        assert_eq!(h.owned.len(), fine.len());
        for v in 0..positions.len() {
            let near = h.near_of(v);
            for (t, tri) in fine.iter().enumerate() {
                if tri.contains(&(v as u32)) {
                    let c = (0..h.clusters()).find(|&c| h.owned_by(c).contains(&(t as u32))).unwrap();
                    assert!(near.contains(&(c as u32)));
                }
            }
        }
    }

    #[test]
    fn the_grid_finds_the_same_nearest_centre_as_a_scan() {
        let (v, t) = crate::scene::clusters::tests_support::sphere(30);
        let coarse: Vec<[u32; 3]> = t.iter().step_by(7).copied().collect();
        let centres: Vec<Vec3> = coarse.iter().map(|c| centroid(&v, c)).collect();
        let grid = CentreGrid::new(&centres);
        let mut points: Vec<Vec3> = t.iter().map(|f| centroid(&v, f)).collect();
        points.extend([[5.0, -3.0, 0.5], [0.0, 0.0, 0.0], centres[3], [f32::NAN, 0.0, 0.0]]);
        for p in points {
            let scan = (0..centres.len()).min_by(|&i, &j| distance2(&centres[i], &p).total_cmp(&distance2(&centres[j], &p))).unwrap() as u32;
            let found = grid.nearest(&centres, p);
            assert!(found == scan || p[0].is_nan(), "{p:?}: grid {found}, scan {scan}");
        }
    }
}
