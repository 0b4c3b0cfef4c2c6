//! A third level above the paper's two (`hierarchy.rs`): a binary tree over the groups of
//! coarse triangles, each inner node carrying a simplified proxy of the coarse triangles below
//! it. A receiver draws a node through its proxy when the node subtends a small angle, so the
//! distant part of a large mesh costs a few dozen triangles instead of every coarse triangle;
//! the coarse mesh may then grow with the mesh, and clusters (the full-resolution patches
//! around each receiver) keep their size. Without it the cost per receiver grew with the mesh:
//! the 126k-vertex Suzanne took 5.9x the 32k one's time per frame for 4x the vertices.
//!
//! Groups are consecutive in the hierarchy's bisection order, so a range of groups the tree
//! cuts is a compact region; a node covers a range, its leaves are single groups. Proxies
//! keep a subset of the coarse vertices (meshoptimizer's simplifier with locked borders,
//! `scene::clusters::simplify`), so they deform with the mesh at no cost, as the coarse mesh
//! does.

use crate::hierarchy::{Hierarchy, GROUP};
use crate::mesh::{box_centre, half_diagonal2, Vec3, EMPTY_BOX};
use crate::packets::PacketLists;
use crate::scene::clusters::{simplify, union};

/// A node is drawn through its proxy when its bounding sphere's radius is below this fraction
/// of its distance. Measured by bench/group_tree.py (docs/benchmarks_group_tree.md): against
/// the exact path, the median error of transfer grows by a tenth to a fifth of a point at 0.5
/// and about twice that at 0.7, while the 126k-vertex Suzanne's frame takes a third less at 0.5.
pub const FAR_LOD: f32 = 0.5;

/// Target size of a node's proxy. The simplifier keeps a node's border, so proxies come out
/// larger (17 triangles on average at 8, 27 at 16 on the subdivided Suzannes); 8 drew 900
/// instead of 1,040 and 1,170 blockers per receiver on the 32k and 126k ones, for +0.03
/// points of median error.
pub const PROXY_TRIANGLES: usize = 8;

/// A node is drawn through its proxy only while the proxy's error (how far the simplifier let
/// it stray from the node's coarse triangles, at rest) subtends less than this angle, in
/// radians, from the receiver: about one cell of the mask. The radius rule alone let coarse
/// proxies of bumpy scans leak (the armadillo's turned copies 0.106 AO above the exact path);
/// with it, 0.086, for 1-2 % more blockers on the 8k Suzanne and 8 % on the 126k one
/// (docs/solver_speed.md).
pub const PROXY_ERROR_ANGLE: f32 = 0.08;

#[derive(Clone, Copy, Debug)]
pub struct GroupNode {
    /// The groups below it: `first..end`.
    pub first: u32,
    pub end: u32,
    /// Children, or `LEAF` for a single group.
    pub children: [u32; 2],
    /// The nodes below it are `id + 1..subtree_end` (pre-order).
    pub subtree_end: u32,
}

pub const LEAF: [u32; 2] = [u32::MAX; 2];

impl GroupNode {
    /// The clusters of its groups, of `clusters` in all.
    pub fn clusters(&self, clusters: usize) -> std::ops::Range<usize> {
        self.first as usize * GROUP..(self.end as usize * GROUP).min(clusters)
    }
}

pub struct GroupTree {
    /// Node 0 is the root; parents come before their children.
    pub nodes: Vec<GroupNode>,
    /// Per node, its proxy's triangles (welded ids) in packets; empty for leaves.
    pub proxies: PacketLists,
    /// Per node, (its proxy's error at rest / PROXY_ERROR_ANGLE)^2: the squared distance from
    /// the receiver beyond which the proxy is accurate enough (0 for leaves).
    near_limit2: Vec<f32>,
}

impl GroupTree {
    pub fn build(positions: &[Vec3], hierarchy: &Hierarchy) -> GroupTree {
        let mut nodes = Vec::new();
        if hierarchy.groups() > 0 {
            split(0, hierarchy.groups() as u32, &mut nodes);
        }
        let (proxies, proxy_error): (Vec<Vec<[u32; 3]>>, Vec<f32>) = nodes
            .iter()
            .map(|n| {
                if n.children == LEAF {
                    return (Vec::new(), 0.0);
                }
                simplify(positions, &hierarchy.coarse[n.clusters(hierarchy.clusters())], PROXY_TRIANGLES)
            })
            .unzip();
        let near_limit2 = proxy_error.iter().map(|e| (e / PROXY_ERROR_ANGLE).powi(2)).collect();
        GroupTree { nodes, proxies: PacketLists::new(proxies.iter().map(|p| &p[..])), near_limit2 }
    }

    /// Whether inner node `n` with box `b` is drawn through its proxy from `origin`: its radius
    /// is below `far_lod` (given squared) x its distance, and its proxy's error subtends less
    /// than PROXY_ERROR_ANGLE.
    #[inline(always)]
    pub fn is_far(&self, n: usize, b: &[Vec3; 2], origin: Vec3, lod2: f32) -> bool {
        let d2 = centre_distance2(b, origin);
        half_diagonal2(b) < lod2 * d2 && self.near_limit2[n] <= d2
    }

    /// Per node, the box around its groups' boxes (`group_bounds`) and its proxy.
    pub fn bounds(&self, group_bounds: &[[Vec3; 2]]) -> Vec<[Vec3; 2]> {
        let mut bounds = vec![EMPTY_BOX; self.nodes.len()];
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            bounds[n] = if node.children == LEAF {
                group_bounds[node.first as usize]
            } else {
                union(&bounds[node.children[0] as usize], &bounds[node.children[1] as usize])
            };
            for packet in self.proxies.of(n) {
                bounds[n] = union(&bounds[n], &packet.bounds);
            }
        }
        bounds
    }
}

/// The squared distance from `origin` to the centre of box `b`.
#[inline(always)]
pub fn centre_distance2(b: &[Vec3; 2], origin: Vec3) -> f32 {
    let centre = box_centre(b);
    (0..3).map(|a| (centre[a] - origin[a]).powi(2)).sum()
}

/// Halves `first..end` down to single groups; appends nodes in pre-order, returns the root.
fn split(first: u32, end: u32, nodes: &mut Vec<GroupNode>) -> u32 {
    let id = nodes.len() as u32;
    nodes.push(GroupNode { first, end, children: LEAF, subtree_end: id + 1 });
    if end - first > 1 {
        let mid = first + (end - first) / 2;
        let left = split(first, mid, nodes);
        let right = split(mid, end, nodes);
        nodes[id as usize].children = [left, right];
        nodes[id as usize].subtree_end = nodes.len() as u32;
    }
    id
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::clusters::tests_support::sphere;

    #[test]
    fn nodes_cover_every_group_once_and_proxies_are_small() {
        let (v, t) = sphere(40);
        let h = Hierarchy::build(&v, &t, 400, 1);
        let mut tree = GroupTree::build(&v, &h);
        let leaves: Vec<u32> = tree.nodes.iter().filter(|n| n.children == LEAF).map(|n| n.first).collect();
        assert_eq!(leaves, (0..h.groups() as u32).collect::<Vec<_>>());
        for (n, node) in tree.nodes.iter().enumerate() {
            let below = &tree.nodes[n + 1..node.subtree_end as usize];
            assert!(below.iter().all(|b| node.first <= b.first && b.end <= node.end));
            assert_eq!(below.len(), if node.children == LEAF { 0 } else { 2 * (node.end - node.first) as usize - 2 });
            let proxy: u32 = tree.proxies.of(n).iter().map(|p| p.lanes.count_ones()).sum();
            if node.children == LEAF {
                assert_eq!(proxy, 0);
            } else {
                assert!(proxy > 0 && proxy as usize <= 4 * PROXY_TRIANGLES, "node {n}: {proxy}");
            }
        }
        tree.proxies.update(&v);
        let groups: Vec<[Vec3; 2]> = (0..h.groups()).map(|g| crate::mesh::box_of(h.group_compact[g].vertices.iter().map(|&i| v[i as usize]))).collect();
        let bounds = tree.bounds(&groups);
        assert!((0..3).all(|a| bounds[0][0][a] <= -0.8 && bounds[0][1][a] >= 0.8));
    }

    #[test]
    fn a_proxy_is_drawn_only_where_its_error_is_small_from_the_receiver() {
        // A bumpy sphere: proxies of 8 triangles stray from its coarse triangles.
        let (mut v, t) = sphere(40);
        for p in &mut v {
            let bump = 1.0 + 0.15 * (7.0 * p[0]).sin() * (9.0 * p[1]).sin() * (5.0 * p[2]).cos();
            *p = p.map(|c| c * bump);
        }
        let h = Hierarchy::build(&v, &t, 400, 1);
        let mut tree = GroupTree::build(&v, &h);
        tree.proxies.update(&v);
        let groups: Vec<[Vec3; 2]> = (0..h.groups()).map(|g| crate::mesh::box_of(h.group_compact[g].vertices.iter().map(|&i| v[i as usize]))).collect();
        let bounds = tree.bounds(&groups);
        let lod2 = FAR_LOD * FAR_LOD;
        let mut error_decided = 0;
        for (n, b) in bounds.iter().enumerate().filter(|(n, _)| tree.nodes[*n].children != LEAF) {
            let (centre, radius) = (box_centre(b), half_diagonal2(b).sqrt());
            let (by_radius, by_error) = (radius / FAR_LOD, tree.near_limit2[n].sqrt());
            assert!(by_error.is_finite(), "node {n}");
            let seen_from = |d: f32| tree.is_far(n, b, [centre[0] + d, centre[1], centre[2]], lod2);
            assert!(seen_from(1.01 * by_radius.max(by_error)), "node {n}: far from both rules");
            assert!(!seen_from(0.99 * by_radius), "node {n}: within the radius rule");
            if by_error > 1.02 * by_radius {
                error_decided += 1;
                assert!(!seen_from(0.99 * by_error), "node {n}: far by its radius, its proxy too coarse");
            }
        }
        assert!(error_decided > 0, "no proxy was coarse enough for the error rule to decide");
    }
}
