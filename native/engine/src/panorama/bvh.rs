//! A bounding volume hierarchy over world triangles for closest-hit ray casting (panorama
//! primary visibility). Binned surface-area heuristic build, stack traversal nearest child
//! first, Moller-Trumbore tests in f64 so that hits at pixel centres are exact to rounding.

use crate::mesh::{box_centre, Vec3, EMPTY_BOX};

const LEAF_SIZE: usize = 4;
const BINS: usize = 16;

#[derive(Clone, Copy)]
struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Inner node: index of the left child (the right one follows it), `count` = 0.
    /// Leaf: first triangle in `order`, `count` triangles.
    start: u32,
    count: u32,
}

pub struct Bvh {
    nodes: Vec<Node>,
    /// Triangle indices in leaf order.
    order: Vec<u32>,
    corners: Vec<[Vec3; 3]>,
}

/// The closest hit of a ray: distance along the (unit) direction, triangle, barycentrics of
/// corners b and c.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub triangle: u32,
    pub u: f64,
    pub v: f64,
}

fn bounds(tri: &[Vec3; 3]) -> [Vec3; 2] {
    let lo = [0, 1, 2].map(|a| tri[0][a].min(tri[1][a]).min(tri[2][a]));
    let hi = [0, 1, 2].map(|a| tri[0][a].max(tri[1][a]).max(tri[2][a]));
    [lo, hi]
}

fn grow(b: &mut [Vec3; 2], o: &[Vec3; 2]) {
    for a in 0..3 {
        b[0][a] = b[0][a].min(o[0][a]);
        b[1][a] = b[1][a].max(o[1][a]);
    }
}

fn area(b: &[Vec3; 2]) -> f32 {
    let e = [0, 1, 2].map(|a| (b[1][a] - b[0][a]).max(0.0));
    e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
}

impl Bvh {
    pub fn build(corners: Vec<[Vec3; 3]>) -> Bvh {
        let boxes: Vec<[Vec3; 2]> = corners.iter().map(bounds).collect();
        let centres: Vec<Vec3> = boxes.iter().map(box_centre).collect();
        let mut order: Vec<u32> = (0..corners.len() as u32).collect();
        let mut nodes = vec![Node { lo: [0.0; 3], hi: [0.0; 3], start: 0, count: 0 }];
        // (node index, first, end) still to split.
        let mut work = vec![(0usize, 0usize, order.len())];
        while let Some((node, first, end)) = work.pop() {
            let mut b = EMPTY_BOX;
            order[first..end].iter().for_each(|&t| grow(&mut b, &boxes[t as usize]));
            nodes[node].lo = b[0];
            nodes[node].hi = b[1];
            let split = if end - first > LEAF_SIZE { split(&mut order[first..end], &boxes, &centres) } else { None };
            match split {
                Some(mid) => {
                    let left = nodes.len();
                    nodes.push(nodes[node]);
                    nodes.push(nodes[node]);
                    nodes[node].start = left as u32;
                    nodes[node].count = 0;
                    work.push((left, first, first + mid));
                    work.push((left + 1, first + mid, end));
                }
                None => {
                    nodes[node].start = first as u32;
                    nodes[node].count = (end - first) as u32;
                }
            }
        }
        Bvh { nodes, order, corners }
    }

    pub fn is_empty(&self) -> bool {
        self.corners.is_empty()
    }

    /// The closest hit along origin + t * direction, t > 0.
    pub fn closest(&self, origin: [f64; 3], direction: [f64; 3], stack: &mut Vec<u32>) -> Option<Hit> {
        if self.corners.is_empty() {
            return None;
        }
        let inv = direction.map(|d| 1.0 / d);
        let mut best: Option<Hit> = None;
        let mut best_t = f64::INFINITY;
        stack.clear();
        stack.push(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            if slab(node, origin, inv) >= best_t {
                continue;
            }
            if node.count > 0 {
                let range = node.start as usize..(node.start + node.count) as usize;
                for &t in &self.order[range] {
                    if let Some((dist, u, v)) = intersect(&self.corners[t as usize], origin, direction) {
                        if dist < best_t {
                            best_t = dist;
                            best = Some(Hit { t: dist, triangle: t, u, v });
                        }
                    }
                }
                continue;
            }
            let (a, b) = (node.start, node.start + 1);
            let (ta, tb) = (slab(&self.nodes[a as usize], origin, inv), slab(&self.nodes[b as usize], origin, inv));
            // Push the farther child first so the nearer is visited first.
            let (near, far, tn, tf) = if ta <= tb { (a, b, ta, tb) } else { (b, a, tb, ta) };
            if tf < best_t {
                stack.push(far);
            }
            if tn < best_t {
                stack.push(near);
            }
        }
        best
    }
}

/// Entry distance of the ray into the node's box, infinity on a miss.
#[inline]
fn slab(node: &Node, origin: [f64; 3], inv: [f64; 3]) -> f64 {
    let mut near = 0.0f64;
    let mut far = f64::INFINITY;
    for a in 0..3 {
        let t0 = (node.lo[a] as f64 - origin[a]) * inv[a];
        let t1 = (node.hi[a] as f64 - origin[a]) * inv[a];
        let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        // NaN (0 * inf on a box face) compares false and leaves the interval as it was.
        if t0 > near {
            near = t0;
        }
        if t1 < far {
            far = t1;
        }
    }
    if near <= far * (1.0 + 4.0 * f64::EPSILON) {
        near
    } else {
        f64::INFINITY
    }
}

/// Moller-Trumbore in f64: (t, u, v) of a hit with t > 0, either side of the triangle.
#[inline]
fn intersect(tri: &[Vec3; 3], o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64, f64)> {
    let p = tri.map(|c| c.map(|x| x as f64));
    let e1 = sub(p[1], p[0]);
    let e2 = sub(p[2], p[0]);
    let h = cross(d, e2);
    let det = dot(e1, h);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let f = 1.0 / det;
    let s = sub(o, p[0]);
    let u = f * dot(s, h);
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = cross(s, e1);
    let v = f * dot(d, q);
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = f * dot(e2, q);
    (t > 0.0).then_some((t, u, v))
}

/// Splits `order` (a node's triangles) by the binned SAH; the left part's length, or None
/// when a leaf is cheaper or the centroids cannot be told apart.
fn split(order: &mut [u32], boxes: &[[Vec3; 2]], centres: &[Vec3]) -> Option<usize> {
    let mut cb = EMPTY_BOX;
    for &t in order.iter() {
        let c = centres[t as usize];
        grow(&mut cb, &[c, c]);
    }
    let mut parent = EMPTY_BOX;
    order.iter().for_each(|&t| grow(&mut parent, &boxes[t as usize]));
    let leaf_cost = order.len() as f32 * area(&parent);
    let mut best: Option<(f32, usize, f32)> = None; // (cost, axis, position)
    for axis in 0..3 {
        let (lo, hi) = (cb[0][axis], cb[1][axis]);
        if !(hi > lo) {
            continue;
        }
        let scale = BINS as f32 / (hi - lo);
        let bin = |t: u32| (((centres[t as usize][axis] - lo) * scale) as usize).min(BINS - 1);
        let mut counts = [0usize; BINS];
        let mut bb = [EMPTY_BOX; BINS];
        for &t in order.iter() {
            let i = bin(t);
            counts[i] += 1;
            grow(&mut bb[i], &boxes[t as usize]);
        }
        let mut right_area = [0.0f32; BINS];
        let mut right_count = [0usize; BINS];
        let (mut acc, mut n) = (EMPTY_BOX, 0);
        for i in (1..BINS).rev() {
            grow(&mut acc, &bb[i]);
            n += counts[i];
            right_area[i] = area(&acc);
            right_count[i] = n;
        }
        let (mut acc, mut n) = (EMPTY_BOX, 0);
        for i in 0..BINS - 1 {
            grow(&mut acc, &bb[i]);
            n += counts[i];
            if n == 0 || right_count[i + 1] == 0 {
                continue;
            }
            let cost = n as f32 * area(&acc) + right_count[i + 1] as f32 * right_area[i + 1];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, lo + (i + 1) as f32 / scale));
            }
        }
    }
    let (cost, axis, position) = best?;
    if order.len() <= 2 * LEAF_SIZE && cost >= leaf_cost {
        return None;
    }
    // Partition by the chosen plane (the same binning as the cost used).
    let mut mid = 0;
    for i in 0..order.len() {
        if centres[order[i] as usize][axis] < position {
            order.swap(i, mid);
            mid += 1;
        }
    }
    if mid == 0 || mid == order.len() {
        mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |a, b| centres[*a as usize][axis].total_cmp(&centres[*b as usize][axis]));
    }
    Some(mid)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(corners: &[[Vec3; 3]], o: [f64; 3], d: [f64; 3]) -> Option<(f64, u32)> {
        corners
            .iter()
            .enumerate()
            .filter_map(|(i, c)| intersect(c, o, d).map(|(t, _, _)| (t, i as u32)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }

    #[test]
    fn matches_brute_force() {
        // A pseudo-random soup of small triangles in a box.
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 33) as f32) / (1u64 << 31) as f32
        };
        let corners: Vec<[Vec3; 3]> = (0..2000)
            .map(|_| {
                let c = [rnd() * 4.0 - 2.0, rnd() * 4.0 - 2.0, rnd() * 4.0 - 2.0];
                [0, 1, 2].map(|_| [c[0] + rnd() * 0.4, c[1] + rnd() * 0.4, c[2] + rnd() * 0.4])
            })
            .collect();
        let bvh = Bvh::build(corners.clone());
        let mut stack = Vec::new();
        for _ in 0..3000 {
            let d = [rnd() as f64 - 0.5, rnd() as f64 - 0.5, rnd() as f64 - 0.5];
            let n = dot(d, d).sqrt();
            let d = d.map(|x| x / n);
            let o = [0.1, -0.2, 0.05];
            let got = bvh.closest(o, d, &mut stack).map(|h| (h.t, h.triangle));
            assert_eq!(got, brute(&corners, o, d));
        }
    }
}
