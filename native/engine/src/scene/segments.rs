//! Segment occlusion: whether anything lies between a point and a target point (a lamp's
//! sample), for lamps at a finite distance, which a mask cannot serve (it has no depth: a
//! blocker behind the lamp would shadow it). Any hit ends the test (no nearest-first). The
//! segment walks the same hierarchy as masks (top tree of instance boxes, then each mesh's
//! node boxes in mesh space) and is tested exactly against every leaf triangle, never against
//! proxies: a proxy is pushed out of its surface and casts false shadows near edges.

use crate::mesh::Vec3;
use crate::rasterizer::{cross, dot};

use super::affine::Affine;
use super::clusters::{MeshTree, NO_CHILD};
use super::top::TopTree;

/// A segment origin + t * delta, t in [t0, t1] (ends trimmed by the offset).
#[derive(Clone, Copy)]
struct Segment {
    origin: Vec3,
    delta: Vec3,
    t0: f32,
    t1: f32,
}

impl Segment {
    /// Whether the segment crosses a box (slab test; a zero component of delta works through
    /// infinities, the NaN of 0 x inf is dropped by min/max).
    #[inline(always)]
    fn hits_box(&self, b: &[Vec3; 2]) -> bool {
        let (mut lo, mut hi) = (self.t0, self.t1);
        for a in 0..3 {
            let inv = 1.0 / self.delta[a];
            let (u, v) = ((b[0][a] - self.origin[a]) * inv, (b[1][a] - self.origin[a]) * inv);
            let (u, v) = if u <= v { (u, v) } else { (v, u) };
            lo = if u > lo { u } else { lo };
            hi = if v < hi { v } else { hi };
            if lo > hi {
                return false;
            }
        }
        true
    }

    /// Möller-Trumbore, both faces; a hit with t inside [t0, t1].
    #[inline(always)]
    fn hits_triangle(&self, a: Vec3, b: Vec3, c: Vec3) -> bool {
        let e1 = sub(b, a);
        let e2 = sub(c, a);
        let p = cross(self.delta, e2);
        let det = dot(e1, p);
        if det == 0.0 || !det.is_finite() {
            return false;
        }
        let inv = 1.0 / det;
        let s = sub(self.origin, a);
        let u = dot(s, p) * inv;
        if !(0.0..=1.0).contains(&u) {
            return false;
        }
        let q = cross(s, e1);
        let v = dot(self.delta, q) * inv;
        if v < 0.0 || u + v > 1.0 {
            return false;
        }
        let t = dot(e2, q) * inv;
        t >= self.t0 && t <= self.t1
    }
}

#[inline(always)]
fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// World to mesh space of one instance: the inverse of its affine map (t is unchanged).
fn inverse(t: &Affine) -> ([Vec3; 3], Vec3) {
    let m = t.linear.map(|r| r.map(f64::from));
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let c = |r: usize, k: usize| {
        let (r1, r2, k1, k2) = ((r + 1) % 3, (r + 2) % 3, (k + 1) % 3, (k + 2) % 3);
        m[r1][k1] * m[r2][k2] - m[r1][k2] * m[r2][k1]
    };
    // inverse[i][j] = cofactor(j, i) / det
    let inv: [Vec3; 3] = std::array::from_fn(|i| std::array::from_fn(|j| (c(j, i) / det) as f32));
    (inv, t.translation)
}

fn apply(inv: &[Vec3; 3], v: Vec3) -> Vec3 {
    [dot(inv[0], v), dot(inv[1], v), dot(inv[2], v)]
}

/// The parts of a prepared scene a segment test reads.
pub struct Segments<'a> {
    pub trees: &'a [&'a MeshTree],
    pub positions: &'a [&'a [Vec3]],
    pub instances: &'a [(u32, Affine)],
    pub inverses: Vec<([Vec3; 3], Vec3)>,
    pub top: &'a TopTree,
    pub top_bounds: &'a [[Vec3; 2]],
}

impl<'a> Segments<'a> {
    pub fn new(trees: &'a [&'a MeshTree], positions: &'a [&'a [Vec3]], instances: &'a [(u32, Affine)], top: &'a TopTree) -> Self {
        Segments { trees, positions, instances, inverses: instances.iter().map(|(_, t)| inverse(t)).collect(), top, top_bounds: &top.bounds }
    }

    /// Whether any triangle crosses the segment from `point` to `target`, leaving out `offset`
    /// (world units) at both ends: the surface the point lies on, and the lamp's own surface.
    pub fn occluded(&self, point: Vec3, target: Vec3, offset: f32, stack: &mut Vec<u32>) -> bool {
        let delta = sub(target, point);
        let length = dot(delta, delta).sqrt();
        if !(length > 2.0 * offset) {
            return false;
        }
        let trim = offset / length;
        self.any_touches(&Segment { origin: point, delta, t0: trim, t1: 1.0 - trim }, stack, &mut Vec::new())
    }

    /// Whether any triangle of the scene touches `world` (top tree of instance boxes, then each
    /// mesh's node boxes in mesh space, then its leaf triangles); stops at the first.
    pub(super) fn any_touches<S: Shape>(&self, world: &S, stack: &mut Vec<u32>, inner: &mut Vec<u32>) -> bool {
        if self.top.nodes.is_empty() {
            return false;
        }
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            if !world.may_touch_box(&self.top_bounds[n as usize]) {
                continue;
            }
            let node = self.top.nodes[n as usize];
            if node.children[0] != NO_CHILD {
                stack.extend_from_slice(&node.children);
            } else if self.instance_touches(&world.in_mesh(&self.instances[node.instance as usize].1, &self.inverses[node.instance as usize]), node.instance as usize, inner) {
                return true;
            }
        }
        false
    }

    fn instance_touches<S: Shape>(&self, local: &S, i: usize, stack: &mut Vec<u32>) -> bool {
        let mesh = self.instances[i].0 as usize;
        let (tree, positions) = (self.trees[mesh], self.positions[mesh]);
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            let n = n as usize;
            if !local.may_touch_box(&tree.bounds[n]) {
                continue;
            }
            let node = tree.nodes[n];
            if node.children[0] != NO_CHILD {
                stack.extend_from_slice(&node.children);
                continue;
            }
            let leaf = &tree.leaves[node.leaf as usize];
            for tri in &leaf.triangles {
                if local.touches(tri.map(|k| positions[leaf.vertices[k as usize] as usize])) {
                    return true;
                }
            }
        }
        false
    }
}

/// What `Segments::any_touches` looks for: a shape in world space, movable into a mesh's.
pub(super) trait Shape {
    /// The shape in an instance's mesh space (`place`: mesh to world; `inverse`: its inverse
    /// linear part, rows, and the translation).
    fn in_mesh(&self, place: &Affine, inverse: &([Vec3; 3], Vec3)) -> Self;
    /// False only where the shape surely misses the box.
    fn may_touch_box(&self, b: &[Vec3; 2]) -> bool;
    fn touches(&self, corners: [Vec3; 3]) -> bool;
}

impl Shape for Segment {
    fn in_mesh(&self, _: &Affine, (inv, shift): &([Vec3; 3], Vec3)) -> Self {
        Segment { origin: apply(inv, sub(self.origin, *shift)), delta: apply(inv, self.delta), ..*self }
    }

    #[inline(always)]
    fn may_touch_box(&self, b: &[Vec3; 2]) -> bool {
        self.hits_box(b)
    }

    #[inline(always)]
    fn touches(&self, [a, b, c]: [Vec3; 3]) -> bool {
        self.hits_triangle(a, b, c)
    }
}
