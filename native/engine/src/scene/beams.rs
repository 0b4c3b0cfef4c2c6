//! Beam clearance: whether nothing at all lies between a point and a lamp's whole polygon,
//! the pyramid with the point as apex and the polygon as base. Where it is clear, every
//! segment from the point to a sample on the lamp is clear too, and a soft shadow needs no
//! segment tests there (most of a room's floor sees an area lamp whole). The test is
//! conservative: a triangle or node box counts as inside unless one face plane of the pyramid
//! has all its corners outside, so "not clear" only means "test the segments".

use crate::mesh::Vec3;
use crate::rasterizer::{cross, dot};

use super::affine::Affine;
use super::segments::{Segments, Shape};

/// Most corners a lamp polygon may have.
pub const MAX_CORNERS: usize = 8;

/// Planes n . x <= d bounding the pyramid: one per polygon edge, the base pulled towards the
/// apex by `offset` (the lamp's own surface is left out, as segments leave it out), the six
/// of its bounding box, and the receiver's tangent plane through the apex. That last one cuts
/// off only what lies below the receiver's horizon, whose segments carry no light. A triangle
/// is separated only when all its corners lie outside one plane: without the tangent plane
/// the surface the apex sits on, and without the box the walls of a room (a face's corners
/// outside different planes of the pyramid), were never separated, and no beam was clear.
struct Pyramid {
    planes: [(Vec3, f32); PLANES],
    count: usize,
    /// The apex and the polygon's corners: a triangle whose plane has them all on one side
    /// is separated too.
    corners: [Vec3; MAX_CORNERS + 1],
    corner_count: usize,
}

const PLANES: usize = MAX_CORNERS + 8;

impl Pyramid {
    /// None when the apex lies in the polygon's plane or the polygon is degenerate.
    fn new(apex: Vec3, normal: Vec3, polygon: &[Vec3], offset: f32) -> Option<Pyramid> {
        let k = polygon.len();
        if !(3..=MAX_CORNERS).contains(&k) {
            return None;
        }
        let centroid = polygon.iter().fold([0.0f32; 3], |s, q| add(s, *q)).map(|c| c / k as f32);
        let inside = add(apex, centroid).map(|c| c / 2.0);
        let mut planes = [([0.0f32; 3], 0.0f32); PLANES];
        for i in 0..k {
            planes[i] = facing_away(cross(sub(polygon[i], apex), sub(polygon[(i + 1) % k], apex)), apex, inside)?;
        }
        let (n, d) = facing_away(cross(sub(polygon[1], polygon[0]), sub(polygon[2], polygon[0])), polygon[0], inside)?;
        let length = dot(n, n).sqrt();
        planes[k] = (n, d - offset * length);
        planes[k + 1] = (normal.map(|c| -c), -dot(normal, apex)); // below the horizon is outside
        for a in 0..3 {
            let (lo, hi) = polygon.iter().fold((apex[a], apex[a]), |(lo, hi), q| (lo.min(q[a]), hi.max(q[a])));
            let mut axis = [0.0f32; 3];
            axis[a] = 1.0;
            planes[k + 2 + 2 * a] = (axis, hi);
            planes[k + 3 + 2 * a] = (axis.map(|c| -c), -lo);
        }
        let mut corners = [apex; MAX_CORNERS + 1];
        corners[1..=k].copy_from_slice(polygon);
        Some(Pyramid { planes, count: k + 8, corners, corner_count: k + 1 })
    }

    /// Whether a triangle lies strictly outside one of the pyramid's planes, or the pyramid
    /// strictly on one side of the triangle's plane.
    #[inline(always)]
    fn separates(&self, points: &[Vec3; 3]) -> bool {
        if self.planes[..self.count].iter().any(|&(n, d)| points.iter().all(|&p| dot(n, p) > d)) {
            return true;
        }
        let n = cross(sub(points[1], points[0]), sub(points[2], points[0]));
        let d = dot(n, points[0]);
        let corners = &self.corners[..self.corner_count];
        corners.iter().all(|&c| dot(n, c) > d) || corners.iter().all(|&c| dot(n, c) < d)
    }

    /// Whether a box lies strictly outside one plane (its corner least outside, per plane).
    #[inline(always)]
    fn separates_box(&self, b: &[Vec3; 2]) -> bool {
        self.planes[..self.count].iter().any(|&(n, d)| {
            let nearest = [0, 1, 2].map(|a| if n[a] > 0.0 { b[0][a] } else { b[1][a] });
            dot(n, nearest) > d
        })
    }

    /// The pyramid in an instance's mesh space, given world = linear * local + shift and
    /// local = inverse * (world - shift).
    fn to_mesh(&self, linear: &[Vec3; 3], inverse: &[Vec3; 3], shift: Vec3) -> Pyramid {
        let mut planes = self.planes;
        for plane in planes[..self.count].iter_mut() {
            let (n, d) = *plane;
            let local = [0, 1, 2].map(|j| n[0] * linear[0][j] + n[1] * linear[1][j] + n[2] * linear[2][j]);
            *plane = (local, d - dot(n, shift));
        }
        let corners = self.corners.map(|c| {
            let v = sub(c, shift);
            [dot(inverse[0], v), dot(inverse[1], v), dot(inverse[2], v)]
        });
        Pyramid { planes, corners, ..*self }
    }
}

/// The plane through `point` with normal `n` oriented so that `inside` is inside; None when
/// `n` is zero or `inside` lies on it (a flat pyramid).
fn facing_away(n: Vec3, point: Vec3, inside: Vec3) -> Option<(Vec3, f32)> {
    let d = dot(n, point);
    let side = dot(n, inside) - d;
    if side == 0.0 || !side.is_finite() {
        return None;
    }
    Some(if side < 0.0 { (n, d) } else { (n.map(|c| -c), -d) })
}

#[inline(always)]
fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline(always)]
fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl Segments<'_> {
    /// Whether no triangle can reach into the pyramid from `apex` to the convex `polygon`
    /// (corners in order) above the plane through `apex` with normal `normal`, leaving out
    /// `offset` (world units) at the lamp's end; false for a degenerate pyramid.
    /// Conservative: false may still be clear.
    pub fn beam_clear(&self, apex: Vec3, normal: Vec3, polygon: &[Vec3], offset: f32, stack: &mut Vec<u32>, inner: &mut Vec<u32>) -> bool {
        let Some(world) = Pyramid::new(apex, normal, polygon, offset) else { return false };
        !self.any_touches(&world, stack, inner)
    }
}

impl Shape for Pyramid {
    fn in_mesh(&self, place: &Affine, _: &([Vec3; 3], Vec3)) -> Self {
        self.to_mesh(&place.linear, &place.inverse, place.translation)
    }

    #[inline(always)]
    fn may_touch_box(&self, b: &[Vec3; 2]) -> bool {
        !self.separates_box(b)
    }

    #[inline(always)]
    fn touches(&self, corners: [Vec3; 3]) -> bool {
        !self.separates(&corners)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const UP: Vec3 = [0.0, 0.0, 1.0];

    fn square(z: f32) -> [Vec3; 4] {
        [[-1.0, -1.0, z], [1.0, -1.0, z], [1.0, 1.0, z], [-1.0, 1.0, z]]
    }

    #[test]
    fn pyramid_separates_what_lies_outside_and_keeps_what_lies_inside() {
        let p = Pyramid::new([0.0, 0.0, 0.0], UP, &square(2.0), 0.0).unwrap();
        assert!(!p.separates(&[[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0]])); // on the axis
        assert!(p.separates(&[[3.0, 0.0, 1.0], [3.1, 0.0, 1.0], [3.0, 0.1, 1.0]])); // beside
        assert!(p.separates(&[[0.0, 0.0, 2.5], [0.1, 0.0, 2.5], [0.0, 0.1, 2.5]])); // beyond the lamp
        assert!(p.separates(&[[0.0, 0.0, -0.5], [0.1, 0.0, -0.5], [0.0, 0.1, -0.5]])); // behind the apex
        // a large triangle crossing the pyramid with no corner inside
        assert!(!p.separates(&[[-10.0, -10.0, 1.0], [10.0, -10.0, 1.0], [0.0, 10.0, 1.0]]));
        assert!(p.separates_box(&[[2.5, -1.0, 0.0], [3.0, 1.0, 1.0]]));
        assert!(!p.separates_box(&[[-5.0, -5.0, 0.9], [5.0, 5.0, 1.1]]));
        // the surface under the apex, corners all around it
        assert!(p.separates(&[[-10.0, -10.0, -1e-3], [10.0, -10.0, -1e-3], [0.0, 10.0, -1e-3]]));
        // a slanted sheet beside the pyramid, its corners outside different planes
        assert!(p.separates(&[[1.5, -10.0, 0.0], [1.5, 10.0, 0.0], [4.0, 0.0, 3.0]]));
    }

    #[test]
    fn the_lamp_end_is_left_out_by_offset() {
        let near_lamp = [[0.0, 0.0, 1.995], [0.1, 0.0, 1.995], [0.0, 0.1, 1.995]];
        assert!(!Pyramid::new([0.0; 3], UP, &square(2.0), 0.0).unwrap().separates(&near_lamp));
        assert!(Pyramid::new([0.0; 3], UP, &square(2.0), 0.01).unwrap().separates(&near_lamp));
    }

    #[test]
    fn a_flat_pyramid_is_refused() {
        assert!(Pyramid::new([0.0, 0.0, 2.0], UP, &square(2.0), 0.0).is_none());
        assert!(Pyramid::new([0.0; 3], UP, &square(2.0)[..2], 0.0).is_none());
    }

    #[test]
    fn mesh_space_planes_agree_with_world_ones() {
        let p = Pyramid::new([0.3, -0.2, 0.1], [0.0, 0.6, 0.8], &square(2.0), 0.0).unwrap();
        let linear = [[0.0, -2.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.5]]; // rows: world = linear * local
        let shift = [0.5, 1.0, -0.25];
        let inverse = [[0.0, 1.0, 0.0], [-0.5, 0.0, 0.0], [0.0, 0.0, 2.0]];
        let local = p.to_mesh(&linear, &inverse, shift);
        for x in [[0.0f32, 0.0, 1.0], [3.0, 0.5, 0.2], [-0.7, 0.4, 2.0], [0.1, 0.1, 4.0]] {
            let world = [0, 1, 2].map(|r| dot(linear[r], x) + shift[r]);
            for k in 0..p.count {
                let (nw, dw) = p.planes[k];
                let (nl, dl) = local.planes[k];
                assert_eq!(dot(nw, world) > dw, dot(nl, x) > dl, "{x:?} plane {k}");
            }
        }
        for k in 0..p.corner_count {
            let back = [0, 1, 2].map(|r| dot(linear[r], local.corners[k]) + shift[r]);
            assert!((0..3).all(|a| (back[a] - p.corners[k][a]).abs() < 1e-5), "corner {k}");
        }
    }
}
