//! Per-mesh cluster hierarchy: a bounding-volume tree whose leaves are clusters of nearby
//! triangles and whose every node carries a simplified proxy of the triangles below it
//! (hierarchical level of detail in the manner of Nanite's cluster groups, kept as a plain
//! binary tree). Each node's proxy is simplified from its subtree's triangles with
//! meshoptimizer's simplifier (edge collapse with locked borders, so neighbouring proxies meet
//! without cracks; looser when a long border stops it), so their vertices are a subset of the
//! mesh's: when the mesh deforms (`Scene::set_vertices`) the proxies deform with it and only the
//! bounds are refitted, nothing is simplified again (the paper's coarse mesh, section 3.2).
//!
//! A simplified surface made of a vertex subset lies inside the convex parts it replaces (for
//! a sphere, an inscribed polyhedron), so a distant crowd of proxies would block too little.
//! Each proxy vertex is therefore pushed out along the proxy's normal by the simplification
//! error (meshoptimizer's, accumulated up the tree), recomputed at every refit.
//!
//! Everything is in the mesh's own space; instances share one tree.

use rayon::prelude::*;

use crate::mesh::Vec3;
use crate::packets::PacketLists;

/// Triangles per leaf cluster (at most).
pub const LEAF_TRIANGLES: usize = 64;
/// Target size of every node's proxy.
pub const PROXY_TRIANGLES: usize = 16;
/// Coarser stand-ins for a whole mesh than its root's proxy, simplified from it (finest first):
/// a distant object a cell or two wide costs a few triangles, not PROXY_TRIANGLES.
pub const COARSE_TRIANGLES: [usize; 2] = [8, 4];
/// A proxy may keep this many times PROXY_TRIANGLES to keep its borders closed.
pub const BORDER_LIMIT: usize = 4;
/// Proxy vertices move out by this fraction of the simplification error. meshoptimizer's error
/// is the largest deviation, most of the surface lies much closer: the whole error grew every
/// distant silhouette (against rays through the cells, masks had 10x more spurious cells than
/// missed ones). Measured on bench/scene.py's 100k scenes (median error of transfer): crowd
/// 3.2 % at 1, 2.2 % at 0.5, 2.0 % at 0.25, 2.6 % at 0; terrain 2.3, 1.9, 1.7, 1.6 %.
pub const PUSH: f32 = 0.25;

/// Triangles over a compact list of mesh vertices, so that a receiver transforms each vertex
/// once rather than once per corner.
#[derive(Default, Clone, Debug)]
pub struct Compact {
    /// Mesh vertex ids, each once.
    pub vertices: Vec<u32>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle, the mesh vertices whose radiance its corners show (`shown`); empty when
    /// each corner shows its own. A proxy simplified from a mesh split at sharp edges holds
    /// one copy of each position (`welded`): its corners show the copy of the faces they
    /// stand for (`SplitCopies`), not the first copy, which may be a face turned away.
    pub shown: Vec<[u32; 3]>,
}

impl Compact {
    pub fn new(triangles: impl Iterator<Item = [u32; 3]>) -> Self {
        let mut compact = Compact::default();
        let mut slot = std::collections::HashMap::new();
        for tri in triangles {
            let local = tri.map(|v| {
                *slot.entry(v).or_insert_with(|| {
                    compact.vertices.push(v);
                    (compact.vertices.len() - 1) as u32
                })
            });
            compact.triangles.push(local);
        }
        compact
    }

    /// The mesh vertices whose radiance triangle `t`'s corners show.
    #[inline(always)]
    pub fn shown(&self, t: usize) -> [u32; 3] {
        match self.shown.get(t) {
            Some(ids) => *ids,
            None => self.triangles[t].map(|k| self.vertices[k as usize]),
        }
    }

    /// The triangles over mesh vertex ids.
    pub fn mesh_triangles(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        self.triangles.iter().map(|t| t.map(|i| self.vertices[i as usize]))
    }
}

pub const NO_CHILD: u32 = u32::MAX;

#[derive(Clone, Copy, Debug)]
pub struct Node {
    /// Children (both NO_CHILD for a leaf).
    pub children: [u32; 2],
    /// For a leaf, its index in `leaves`.
    pub leaf: u32,
}

/// The tree of one mesh: node 0 is the root, parents come before their children.
pub struct MeshTree {
    pub nodes: Vec<Node>,
    pub leaves: Vec<Compact>,
    /// One proxy per node.
    pub proxies: Vec<Compact>,
    /// Per node, how far its proxy may lie from the surface it stands for (mesh units): the
    /// simplifier's error, which selects the level of detail; proxies are pushed out by PUSH x it.
    pub proxy_error: Vec<f32>,
    /// Per node, its proxy's vertices (in `proxies[n].vertices` order) pushed out by the error.
    pub proxy_positions: Vec<Vec<Vec3>>,
    /// Whole-mesh stand-ins coarser than the root's proxy (COARSE_TRIANGLES), their errors
    /// (the root proxy's plus their own) and their pushed-out vertices, as for proxies.
    pub coarse: Vec<Compact>,
    pub coarse_error: Vec<f32>,
    pub coarse_positions: Vec<Vec<Vec3>>,
    /// Per node, its box in mesh space (refitted by `refit`).
    pub bounds: Vec<[Vec3; 2]>,
    /// Per node, the centre of its box and half its diagonal.
    pub spheres: Vec<[f32; 4]>,
    /// Per node, a slab holding its triangles: a unit normal (its proxy's mean), the offset
    /// of its mid-plane along it, and half its thickness (infinite where no normal exists).
    /// Rigid motions keep it, so distances to it do not depend on how a mesh is placed.
    pub slabs: Vec<[f32; 5]>,
    /// Per node, the range of `leaves` below it (a pre-order tree keeps them contiguous).
    leaf_span: Vec<(u32, u32)>,
    pub largest_compact: usize,
    /// The leaves, proxies and coarse stand-ins again, in packets for the mask walk.
    pub packets: TreePackets,
}

/// A mesh tree's triangles in packets of `LANES` (`packets.rs`), for walks that only need
/// masks (`traverse::MaskSink`): a receiver then transforms and tests eight triangles at a
/// time, as the solver does with its own, instead of gathering them one by one from the
/// compact vertex lists. Corners in mesh space, refreshed by `MeshTree::refit`.
#[derive(Default)]
pub struct TreePackets {
    /// List l: leaf l's triangles, over the mesh's vertices.
    pub leaves: PacketLists,
    /// List n: node n's proxy; list k: coarse stand-in k; both over `pushed`.
    pub proxies: PacketLists,
    pub coarse: PacketLists,
    /// Every proxy's pushed-out vertices, then every coarse stand-in's, one after another.
    pushed: Vec<Vec3>,
}

impl TreePackets {
    fn new(leaves: &[Compact], proxies: &[Compact], coarse: &[Compact]) -> Self {
        let leaf_lists: Vec<Vec<[u32; 3]>> = leaves.iter().map(|l| l.mesh_triangles().collect()).collect();
        let mut first = 0u32;
        let mut numbered = |c: &Compact| {
            let list: Vec<[u32; 3]> = c.triangles.iter().map(|t| t.map(|k| first + k)).collect();
            first += c.vertices.len() as u32;
            list
        };
        let proxy_lists: Vec<_> = proxies.iter().map(&mut numbered).collect();
        let coarse_lists: Vec<_> = coarse.iter().map(&mut numbered).collect();
        let packets = |lists: &[Vec<[u32; 3]>]| PacketLists::new(lists.iter().map(|l| &l[..]));
        TreePackets { leaves: packets(&leaf_lists), proxies: packets(&proxy_lists), coarse: packets(&coarse_lists), pushed: Vec::new() }
    }

    fn update(&mut self, positions: &[Vec3], proxy_positions: &[Vec<Vec3>], coarse_positions: &[Vec<Vec3>]) {
        self.leaves.update(positions);
        self.pushed.clear();
        self.pushed.extend(proxy_positions.iter().chain(coarse_positions).flatten());
        self.proxies.update(&self.pushed);
        self.coarse.update(&self.pushed);
    }
}

impl MeshTree {
    pub fn build(positions: &[Vec3], triangles: &[[u32; 3]]) -> MeshTree {
        let centroids: Vec<Vec3> = triangles.iter().map(|t| centroid(positions, t)).collect();
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        let mut nodes = Vec::new();
        let mut leaf_ranges = Vec::new();
        let mut ranges = Vec::new();
        split(&centroids, &mut order, 0, &mut nodes, &mut leaf_ranges, &mut ranges);
        let leaves: Vec<Compact> =
            leaf_ranges.iter().map(|&(s, e)| Compact::new(order[s..e].iter().map(|&t| triangles[t as usize]))).collect();
        // Proxies are simplified over welded positions (`SplitCopies::welded`), leaves keep the
        // mesh's ids.
        let copies = SplitCopies::new(positions, triangles);
        let by_position = copies.as_ref().map_or_else(|| triangles.to_vec(), |c| c.welded(positions, triangles));
        let subtree = |n: usize| order[ranges[n].0..ranges[n].1].iter().map(|&t| by_position[t as usize]).collect::<Vec<_>>();
        let (mut proxies, proxy_error): (Vec<Compact>, Vec<f32>) = (0..nodes.len())
            .into_par_iter()
            .map(|n| {
                let (tris, error) = simplify(positions, &subtree(n), PROXY_TRIANGLES);
                (Compact::new(tris.into_iter()), error)
            })
            .unzip();
        if let Some(copies) = &copies {
            proxies.par_iter_mut().for_each(|p| copies.choose(positions, p));
        }
        let (mut coarse, mut coarse_error) = (Vec::new(), Vec::new());
        let (mut from, mut error) = (proxies[0].mesh_triangles().collect::<Vec<_>>(), proxy_error[0]);
        for target in COARSE_TRIANGLES {
            let (tris, step) = simplify(positions, &from, target);
            if tris.len() >= from.len() {
                break;
            }
            error += step;
            let mut stand_in = Compact::new(tris.iter().copied());
            if let Some(copies) = &copies {
                copies.choose(positions, &mut stand_in);
            }
            coarse.push(stand_in);
            coarse_error.push(error);
            from = tris;
        }
        let largest_compact = leaves.iter().chain(&proxies).map(|c| c.vertices.len()).max().unwrap_or(0);
        let leaf_span = leaf_spans(&nodes);
        let packets = TreePackets::new(&leaves, &proxies, &coarse);
        let mut tree = MeshTree {
            nodes,
            leaves,
            proxies,
            proxy_error,
            proxy_positions: Vec::new(),
            coarse,
            coarse_error,
            coarse_positions: Vec::new(),
            bounds: Vec::new(),
            spheres: Vec::new(),
            slabs: Vec::new(),
            leaf_span,
            largest_compact,
            packets,
        };
        tree.refit(positions);
        tree
    }

    /// Recomputes every node's box and pushed-out proxy from this frame's positions.
    pub fn refit(&mut self, positions: &[Vec3]) {
        self.proxy_positions =
            self.proxies.par_iter().zip(&self.proxy_error).map(|(p, &e)| pushed_out(positions, p, PUSH * e)).collect();
        let mut bounds = vec![EMPTY_BOX; self.nodes.len()];
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            bounds[n] = if node.children[0] == NO_CHILD {
                box_of(self.leaves[node.leaf as usize].vertices.iter().map(|&v| positions[v as usize]))
            } else {
                union(&bounds[node.children[0] as usize], &bounds[node.children[1] as usize])
            };
            bounds[n] = union(&bounds[n], &box_of(self.proxy_positions[n].iter().copied()));
        }
        self.coarse_positions = self.coarse.iter().zip(&self.coarse_error).map(|(c, &e)| pushed_out(positions, c, PUSH * e)).collect();
        for c in &self.coarse_positions {
            bounds[0] = union(&bounds[0], &box_of(c.iter().copied()));
        }
        self.spheres = bounds.iter().map(sphere_of).collect();
        self.bounds = bounds;
        self.slabs = (0..self.nodes.len()).into_par_iter().map(|n| self.slab(n, positions)).collect();
        self.packets.update(positions, &self.proxy_positions, &self.coarse_positions);
    }

    /// Node `n`'s slab (see `slabs`) around the vertices of the leaves below it.
    fn slab(&self, n: usize, positions: &[Vec3]) -> [f32; 5] {
        let proxy = &self.proxies[n];
        let mut sum = [0.0f32; 3];
        for t in &proxy.triangles {
            let [a, b, c] = t.map(|k| positions[proxy.vertices[k as usize] as usize]);
            sum = crate::mesh::add(sum, crate::rasterizer::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a)));
        }
        let Some(normal) = crate::mesh::normalize(sum) else {
            return [0.0, 0.0, 1.0, 0.0, f32::INFINITY];
        };
        let (first, end) = self.leaf_span[n];
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for leaf in &self.leaves[first as usize..end as usize] {
            for &v in &leaf.vertices {
                let h = crate::rasterizer::dot(normal, positions[v as usize]);
                (lo, hi) = (lo.min(h), hi.max(h));
            }
        }
        [normal[0], normal[1], normal[2], 0.5 * (lo + hi), 0.5 * (hi - lo)]
    }

    pub fn triangle_count(&self) -> usize {
        self.leaves.iter().map(|l| l.triangles.len()).sum()
    }
}

pub use crate::mesh::{box_of, EMPTY_BOX};
use crate::mesh::{box_centre, half_diagonal2};

pub fn union(a: &[Vec3; 2], b: &[Vec3; 2]) -> [Vec3; 2] {
    [[0, 1, 2].map(|i| a[0][i].min(b[0][i])), [0, 1, 2].map(|i| a[1][i].max(b[1][i]))]
}

pub fn sphere_of(b: &[Vec3; 2]) -> [f32; 4] {
    let c = box_centre(b);
    [c[0], c[1], c[2], half_diagonal2(b).sqrt()]
}

fn centroid(positions: &[Vec3], t: &[u32; 3]) -> Vec3 {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0)
}

/// Median split of `order` along the longest axis of its centroids' box, down to leaves of at
/// most LEAF_TRIANGLES; appends nodes in pre-order and returns the subtree's root.
fn split(
    centroids: &[Vec3],
    order: &mut [u32],
    offset: usize,
    nodes: &mut Vec<Node>,
    leaves: &mut Vec<(usize, usize)>,
    ranges: &mut Vec<(usize, usize)>,
) -> u32 {
    let id = nodes.len() as u32;
    nodes.push(Node { children: [NO_CHILD; 2], leaf: NO_CHILD });
    ranges.push((offset, offset + order.len()));
    if order.len() <= LEAF_TRIANGLES {
        nodes[id as usize].leaf = leaves.len() as u32;
        leaves.push((offset, offset + order.len()));
        return id;
    }
    let b = box_of(order.iter().map(|&t| centroids[t as usize]));
    let axis = (0..3).max_by(|&i, &j| (b[1][i] - b[0][i]).total_cmp(&(b[1][j] - b[0][j]))).unwrap_or(0);
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&x, &y| centroids[x as usize][axis].total_cmp(&centroids[y as usize][axis]));
    let (left, right) = order.split_at_mut(mid);
    let l = split(centroids, left, offset, nodes, leaves, ranges);
    let r = split(centroids, right, offset + mid, nodes, leaves, ranges);
    nodes[id as usize].children = [l, r];
    id
}

/// Per node, the range of leaf indices below it (nodes in pre-order, parents first).
fn leaf_spans(nodes: &[Node]) -> Vec<(u32, u32)> {
    let mut span = vec![(0u32, 0u32); nodes.len()];
    for n in (0..nodes.len()).rev() {
        let node = nodes[n];
        span[n] = if node.children[0] == NO_CHILD {
            (node.leaf, node.leaf + 1)
        } else {
            (span[node.children[0] as usize].0, span[node.children[1] as usize].1)
        };
    }
    span
}

/// A proxy's vertices moved `error` along the area-weighted normals of the proxy's triangles.
fn pushed_out(positions: &[Vec3], proxy: &Compact, error: f32) -> Vec<Vec3> {
    let mut normals = vec![[0.0f32; 3]; proxy.vertices.len()];
    for t in &proxy.triangles {
        let [a, b, c] = t.map(|k| positions[proxy.vertices[k as usize] as usize]);
        let n = crate::rasterizer::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a));
        for &k in t {
            normals[k as usize] = crate::mesh::add(normals[k as usize], n);
        }
    }
    proxy
        .vertices
        .iter()
        .zip(normals)
        .map(|(&v, n)| {
            let p = positions[v as usize];
            match crate::mesh::normalize(n) {
                Some(n) if error > 0.0 => [0, 1, 2].map(|a| p[a] + error * n[a]),
                _ => p,
            }
        })
        .collect()
}

/// At most about `target` triangles over a subset of the given triangles' vertices: edge
/// collapse first (keeps the surface), sloppy vertex clustering when that stalls, and the
/// largest triangles when even that returns nothing (tiny or degenerate sets). Also returns
/// the simplifier's error in mesh units.
pub fn simplify(positions: &[Vec3], triangles: &[[u32; 3]], target: usize) -> (Vec<[u32; 3]>, f32) {
    if triangles.len() <= target {
        return (triangles.to_vec(), 0.0);
    }
    let compact = Compact::new(triangles.iter().copied());
    let local: Vec<Vec3> = compact.vertices.iter().map(|&v| positions[v as usize]).collect();
    let indices: Vec<u32> = compact.triangles.iter().flatten().copied().collect();
    let mut error = 0.0f32;
    // Locked borders keep neighbouring proxies (and a proxy next to full-resolution triangles)
    // closed along their seams: free borders shrink apart and leave cracks that leak light.
    // Long borders stop the reduction; then the free-border result, then sloppy clustering.
    let mut kept = meshopt::simplify_decoder(&indices, &local, target * 3, 1.0, meshopt::SimplifyOptions::LockBorder, Some(&mut error));
    if kept.len() > BORDER_LIMIT * target * 3 {
        kept = meshopt::simplify_decoder(&indices, &local, target * 3, 1.0, meshopt::SimplifyOptions::None, Some(&mut error));
    }
    if kept.len() > BORDER_LIMIT * target * 3 {
        kept = meshopt::simplify_sloppy_decoder(&indices, &local, target * 3, 1.0, Some(&mut error));
    }
    // meshoptimizer reports errors relative to the largest side of the points' box.
    let b = box_of(local.iter().copied());
    let extent = (0..3).map(|a| b[1][a] - b[0][a]).fold(0.0f32, f32::max);
    let error = error * extent;
    let mut result: Vec<[u32; 3]> = kept.chunks_exact(3).map(|t| [0, 1, 2].map(|k| compact.vertices[t[k] as usize])).collect();
    if result.is_empty() {
        let area = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            crate::mesh::length(crate::rasterizer::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a)))
        };
        result = triangles.to_vec();
        result.sort_by(|x, y| area(y).total_cmp(&area(x)));
        result.truncate(target);
    }
    (result, error)
}

/// The vertices of a mesh that repeats positions (split at sharp edges or seams), by position
/// in the order the triangles first use them, with their unit area-weighted normals at rest.
///
/// Meshes split at sharp edges or UV seams (flat shading, most imported files) repeat a
/// position under several ids: to the simplifier those edges are borders, which stop the
/// reduction or, left free, shrink apart, and each copy's proxy normal (`pushed_out`) moves it
/// its own way; both opened cracks in closed rooms (a room of boxes split at every edge let the
/// sky onto the floor through their proxies: 7 % fewer blocked cells). Positions are compared
/// exactly (-0.0 as 0.0), as a split copies them.
struct SplitCopies {
    by_position: std::collections::HashMap<[u32; 3], Vec<u32>>,
    normals: Vec<Vec3>,
}

impl SplitCopies {
    /// None when no position repeats (nothing to choose).
    fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Option<Self> {
        let mut normals = vec![[0.0f32; 3]; positions.len()];
        let mut by_position: std::collections::HashMap<[u32; 3], Vec<u32>> = std::collections::HashMap::new();
        for t in triangles {
            let [a, b, c] = t.map(|v| positions[v as usize]);
            let n = crate::rasterizer::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a));
            for &v in t {
                normals[v as usize] = crate::mesh::add(normals[v as usize], n);
                let copies = by_position.entry(position_key(positions[v as usize])).or_default();
                if !copies.contains(&v) {
                    copies.push(v);
                }
            }
        }
        let normals = normals.into_iter().map(|n| crate::mesh::normalize(n).unwrap_or([0.0; 3])).collect();
        by_position.values().any(|c| c.len() > 1).then_some(SplitCopies { by_position, normals })
    }

    /// The triangles with every vertex replaced by the first copy of its position.
    fn welded(&self, positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
        triangles.iter().map(|t| t.map(|v| self.by_position[&position_key(positions[v as usize])][0])).collect()
    }

    /// Sets `compact.shown`: per corner, the copy of its position whose normal is closest to
    /// its triangle's.
    fn choose(&self, positions: &[Vec3], compact: &mut Compact) {
        compact.shown = compact
            .triangles
            .iter()
            .map(|t| {
                let ids = t.map(|k| compact.vertices[k as usize]);
                let [a, b, c] = ids.map(|v| positions[v as usize]);
                let n = crate::rasterizer::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a));
                ids.map(|v| {
                    let copies = &self.by_position[&position_key(positions[v as usize])];
                    let facing = |w: &u32| crate::rasterizer::dot(n, self.normals[*w as usize]);
                    *copies.iter().max_by(|x, y| facing(x).total_cmp(&facing(y))).unwrap_or(&v)
                })
            })
            .collect();
    }
}

/// A position as a hash key: its bits, -0.0 as 0.0.
fn position_key(p: Vec3) -> [u32; 3] {
    p.map(|x| (x + 0.0).to_bits())
}

#[cfg(test)]
pub mod tests_support {
    use crate::mesh::Vec3;

    /// UV sphere of radius 1: n rings x 2n segments, wound outwards.
    pub fn sphere(n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut v = vec![[0.0, 0.0, 1.0]];
        for i in 1..n {
            let th = std::f32::consts::PI * i as f32 / n as f32;
            for j in 0..2 * n {
                let ph = std::f32::consts::PI * j as f32 / n as f32;
                v.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
            }
        }
        v.push([0.0, 0.0, -1.0]);
        let ring = |i: usize, j: usize| (1 + (i - 1) * 2 * n + j % (2 * n)) as u32;
        let last = (v.len() - 1) as u32;
        let mut t = Vec::new();
        for j in 0..2 * n {
            t.push([0, ring(1, j), ring(1, j + 1)]);
            t.push([last, ring(n - 1, j + 1), ring(n - 1, j)]);
        }
        for i in 1..n - 1 {
            for j in 0..2 * n {
                t.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
                t.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
            }
        }
        (v, t)
    }
}

#[cfg(test)]
mod tests {
    use super::tests_support::sphere;
    use super::*;

    /// The sphere split into its triangles: every corner a vertex of its own.
    fn split_sphere(n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let (v, t) = sphere(n);
        let positions = t.iter().flat_map(|tri| tri.map(|i| v[i as usize])).collect();
        (positions, (0..t.len() as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect())
    }

    #[test]
    fn a_split_mesh_simplifies_as_the_welded_one() {
        let (v, t) = sphere(24);
        let (sv, st) = split_sphere(24);
        let (welded, split) = (MeshTree::build(&v, &t), MeshTree::build(&sv, &st));
        for (a, b) in welded.proxies.iter().zip(&split.proxies) {
            assert_eq!(a.triangles.len(), b.triangles.len());
            let shape = |c: &Compact, p: &[Vec3]| c.mesh_triangles().map(|t| t.map(|i| p[i as usize])).collect::<Vec<_>>();
            assert_eq!(shape(a, &v), shape(b, &sv));
        }
        assert_eq!(welded.proxy_positions, split.proxy_positions); // pushed out alike: no cracks
    }

    #[test]
    fn split_proxy_corners_show_the_copy_facing_their_way() {
        let (v, t) = split_sphere(24);
        let tree = MeshTree::build(&v, &t);
        let normal = |tri: [u32; 3]| {
            let [a, b, c] = tri.map(|i| v[i as usize]);
            crate::mesh::normalize(crate::rasterizer::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a))).unwrap()
        };
        let mut checked = 0;
        for proxy in tree.proxies.iter().chain(&tree.coarse) {
            assert_eq!(proxy.shown.len(), proxy.triangles.len());
            for (k, tri) in proxy.mesh_triangles().enumerate() {
                let n = normal(tri);
                for (corner, shown) in tri.iter().zip(proxy.shown(k)) {
                    assert_eq!(v[*corner as usize], v[shown as usize]);
                    // The copy's own triangle (each vertex belongs to one) faces the most like it.
                    let facing = |w: u32| crate::rasterizer::dot(n, normal(t[w as usize / 3]));
                    let best = (0..v.len() as u32).filter(|&w| v[w as usize] == v[shown as usize]).map(facing).fold(f32::MIN, f32::max);
                    assert!(facing(shown) >= best - 1e-6);
                    checked += 1;
                }
            }
        }
        assert!(checked > 100);
    }

    #[test]
    fn leaves_hold_every_triangle_once() {
        let (v, t) = sphere(40);
        let tree = MeshTree::build(&v, &t);
        assert_eq!(tree.triangle_count(), t.len());
        let mut seen: Vec<[u32; 3]> = tree.leaves.iter().flat_map(|l| l.mesh_triangles()).collect();
        let mut expected = t.clone();
        seen.sort();
        expected.sort();
        assert_eq!(seen, expected);
        assert!(tree.leaves.iter().all(|l| l.triangles.len() <= LEAF_TRIANGLES));
    }

    #[test]
    fn proxies_are_small_and_inside_their_node() {
        let (v, t) = sphere(40);
        let tree = MeshTree::build(&v, &t);
        for (n, proxy) in tree.proxies.iter().enumerate() {
            assert!(!proxy.triangles.is_empty() && proxy.triangles.len() <= BORDER_LIMIT * PROXY_TRIANGLES, "node {n}: {}", proxy.triangles.len());
            let b = tree.bounds[n];
            for p in &tree.proxy_positions[n] {
                assert!((0..3).all(|a| p[a] >= b[0][a] && p[a] <= b[1][a]));
            }
        }
        assert!(tree.proxies[0].triangles.len() <= PROXY_TRIANGLES * 3 / 2);
    }

    #[test]
    fn coarse_stand_ins_get_coarser_and_stay_in_the_root_box() {
        let (v, t) = sphere(40);
        let tree = MeshTree::build(&v, &t);
        assert_eq!(tree.coarse.len(), COARSE_TRIANGLES.len());
        let mut previous = (tree.proxies[0].triangles.len(), tree.proxy_error[0]);
        for (k, c) in tree.coarse.iter().enumerate() {
            assert!(!c.triangles.is_empty() && c.triangles.len() < previous.0, "level {k}: {}", c.triangles.len());
            let e = tree.coarse_error[k];
            // Measured: about 1.3 for the 4 triangles standing in for the unit sphere; never more
            // than its diameter, or the level could never be chosen usefully.
            assert!(e >= previous.1 && e <= 2.0, "level {k}: error {e}");
            previous = (c.triangles.len(), e);
            // Vertices of the sphere, pushed out by PUSH x the error, and inside the root's box.
            let b = tree.bounds[0];
            for p in &tree.coarse_positions[k] {
                let r = crate::mesh::length(*p);
                assert!(r >= 1.0 - 1e-4 && r <= 1.0 + PUSH * e + 1e-4, "level {k}: |p| {r}");
                assert!((0..3).all(|a| p[a] >= b[0][a] && p[a] <= b[1][a]));
            }
        }
    }

    #[test]
    fn refit_follows_moved_vertices() {
        let (mut v, t) = sphere(20);
        let mut tree = MeshTree::build(&v, &t);
        v.iter_mut().for_each(|p| p[0] += 5.0);
        tree.refit(&v);
        let leaf = tree.nodes.iter().position(|n| n.children[0] == NO_CHILD).unwrap();
        let expected = box_of(tree.leaves[tree.nodes[leaf].leaf as usize].vertices.iter().map(|&i| v[i as usize]));
        assert_eq!(tree.bounds[leaf], union(&expected, &box_of(tree.proxy_positions[leaf].iter().copied())));
        assert!(tree.bounds[0][0][0] > 3.0 && tree.bounds[0][1][0] > 5.99);
    }
}
