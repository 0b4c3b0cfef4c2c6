//! Mesh preparation: input checks, welding by position, normalisation, vertex normals and
//! tangent frames.
//!
//! Imported meshes are split at UV seams and hard edges (glTF's Fox is an unindexed triangle
//! soup). Transfer is computed on the mesh welded by exact position, so splits never change
//! the result and a receiver's own incident triangles are known.
//!
//! Transfer depends on directions only, so the engine works on positions moved to the mesh's
//! centre and divided by its size (`Normalization`): a mesh of 1 mm and one of 1 km, or one
//! far from the origin, see the same numbers, and no tolerance in the engine is absolute.

use std::collections::HashMap;

use crate::error::{Error, Result};
use crate::rasterizer::{cross, dot};

pub type Vec3 = [f32; 3];

/// A mesh welded by position, with the map from input vertices to welded ones.
pub struct WeldedMesh {
    pub positions: Vec<Vec3>,
    /// Triangles over welded vertices; triangles that repeat a welded vertex are dropped.
    pub triangles: Vec<[u32; 3]>,
    /// Input vertex -> welded vertex.
    pub remap: Vec<u32>,
}

pub fn check_finite(values: &[Vec3], what: &str) -> Result<()> {
    match values.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        Some(i) => Err(Error::invalid(format!("{what} {i} is not finite: {:?}", values[i]))),
        None => Ok(()),
    }
}

fn check_indices(triangles: &[[u32; 3]], vertex_count: usize) -> Result<()> {
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&i) = tri.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(Error::invalid(format!(
                "triangle {t} uses vertex index {i}, but the mesh has {vertex_count} vertices"
            )));
        }
    }
    Ok(())
}

/// Checks the input and welds vertices that share a position exactly (+0.0 and -0.0 alike).
pub fn weld(vertices: &[Vec3], triangles: &[[u32; 3]]) -> Result<WeldedMesh> {
    if vertices.is_empty() {
        return Err(Error::invalid("the mesh has no vertices"));
    }
    if triangles.is_empty() {
        return Err(Error::invalid("the mesh has no triangles"));
    }
    check_finite(vertices, "vertex")?;
    check_indices(triangles, vertices.len())?;
    let key = |v: &Vec3| v.map(|c| (c + 0.0).to_bits()); // + 0.0 turns -0.0 into +0.0
    let mut first_of: HashMap<[u32; 3], u32> = HashMap::with_capacity(vertices.len());
    let mut positions = Vec::new();
    let remap: Vec<u32> = vertices
        .iter()
        .map(|v| {
            *first_of.entry(key(v)).or_insert_with(|| {
                positions.push(*v);
                (positions.len() - 1) as u32
            })
        })
        .collect();
    let triangles = triangles
        .iter()
        .map(|t| t.map(|i| remap[i as usize]))
        .filter(|[a, b, c]| a != b && b != c && c != a)
        .collect();
    Ok(WeldedMesh { positions, triangles, remap })
}

/// The similarity that maps a mesh into the unit box around the origin: `(p - centre) * scale`.
/// Computed in f64 from the vertices used by triangles (loose vertices do not count).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalization {
    centre: [f64; 3],
    scale: f64,
}

impl Normalization {
    pub fn of(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for &i in triangles.iter().flatten() {
            let p = positions[i as usize];
            for a in 0..3 {
                lo[a] = lo[a].min(p[a] as f64);
                hi[a] = hi[a].max(p[a] as f64);
            }
        }
        let half_extent = (0..3).map(|a| 0.5 * (hi[a] - lo[a])).fold(0.0, f64::max);
        let scale = if half_extent > 0.0 && half_extent.is_finite() { 1.0 / half_extent } else { 1.0 };
        let centre = if lo[0].is_finite() { [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a])) } else { [0.0; 3] };
        Normalization { centre, scale }
    }

    /// Lengths in mesh units -> normalised units.
    pub fn scale(&self) -> f32 {
        self.scale as f32
    }

    #[inline]
    pub fn apply(&self, p: Vec3) -> Vec3 {
        [0, 1, 2].map(|a| ((p[a] as f64 - self.centre[a]) * self.scale) as f32)
    }

    /// Normalised -> mesh units, in double precision.
    #[inline]
    pub fn invert(&self, p: Vec3) -> [f64; 3] {
        [0, 1, 2].map(|a| p[a] as f64 / self.scale + self.centre[a])
    }

    pub fn apply_all(&self, points: impl Iterator<Item = Vec3>) -> Vec<Vec3> {
        points.map(|p| self.apply(p)).collect()
    }
}

impl WeldedMesh {
    /// The mesh moved and scaled into the unit box (see `Normalization`), and the map used.
    pub fn normalized(mut self) -> (Self, Normalization) {
        let normalization = Normalization::of(&self.positions, &self.triangles);
        for p in &mut self.positions {
            *p = normalization.apply(*p);
        }
        (self, normalization)
    }

    /// For every welded vertex, the first input vertex that welded into it.
    pub fn first_copies(&self) -> Vec<u32> {
        let mut first = vec![u32::MAX; self.positions.len()];
        for (i, &w) in self.remap.iter().enumerate().rev() {
            first[w as usize] = i as u32;
        }
        first
    }
}

/// The box that holds nothing: any point widens it.
pub const EMPTY_BOX: [Vec3; 2] = [[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]];

/// The centre of box `b`.
#[inline(always)]
pub fn box_centre(b: &[Vec3; 2]) -> Vec3 {
    [0, 1, 2].map(|a| 0.5 * (b[0][a] + b[1][a]))
}

/// Half the diagonal of box `b`, squared: the squared radius of the sphere around it.
#[inline(always)]
pub fn half_diagonal2(b: &[Vec3; 2]) -> f32 {
    [0, 1, 2].map(|a| 0.5 * (b[1][a] - b[0][a])).iter().map(|d| d * d).sum()
}

/// The axis-aligned box around `points` ([min, max]; `EMPTY_BOX` for none).
pub fn box_of(points: impl Iterator<Item = Vec3>) -> [Vec3; 2] {
    let mut b = EMPTY_BOX;
    for p in points {
        for a in 0..3 {
            b[0][a] = b[0][a].min(p[a]);
            b[1][a] = b[1][a].max(p[a]);
        }
    }
    b
}

#[inline]
pub fn normalize(v: Vec3) -> Option<Vec3> {
    let len = dot(v, v).sqrt();
    (len > 1e-20 && len.is_finite()).then(|| v.map(|c| c / len))
}

/// Area-weighted normals of a welded mesh (zero where no triangle touches a vertex).
pub fn area_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![[0.0f32; 3]; positions.len()];
    for tri in triangles {
        let [a, b, c] = tri.map(|i| positions[i as usize]);
        let face = cross(sub(b, a), sub(c, a)); // length = twice the area
        for &i in tri {
            let s = &mut sums[i as usize];
            *s = add(*s, face);
        }
    }
    sums.into_iter().map(|s| normalize(s).unwrap_or([0.0; 3])).collect()
}

/// Normals per welded vertex: the normalised mean of the given normals of its copies, or the
/// area-weighted normal where none are given or they cancel. A zero normal marks a vertex
/// that no triangle touches and that has no usable given normal.
pub fn welded_normals(positions: &[Vec3], triangles: &[[u32; 3]], remap: &[u32], given: Option<&[Vec3]>) -> Result<Vec<Vec3>> {
    let area = area_normals(positions, triangles);
    let Some(given) = given else { return Ok(area) };
    if given.len() != remap.len() {
        return Err(Error::invalid(format!("normals has {} rows but vertices has {}", given.len(), remap.len())));
    }
    check_finite(given, "normal")?;
    let mut sums = vec![[0.0f32; 3]; positions.len()];
    for (n, &w) in given.iter().zip(remap) {
        if let Some(unit) = normalize(*n) {
            sums[w as usize] = add(sums[w as usize], unit);
        }
    }
    Ok(sums.into_iter().zip(area).map(|(s, a)| normalize(s).unwrap_or(a)).collect())
}

/// Mean edge length of the welded mesh, the scale of the default self-occlusion offset.
pub fn mean_edge_length(mesh: &WeldedMesh) -> f32 {
    let mut total = 0.0f64;
    for tri in &mesh.triangles {
        let [a, b, c] = tri.map(|i| mesh.positions[i as usize]);
        total += (length(sub(b, a)) + length(sub(c, b)) + length(sub(a, c))) as f64;
    }
    (total / (3 * mesh.triangles.len().max(1)) as f64) as f32
}

/// Tangent and bitangent completing a unit normal to a right-handed frame
/// (Duff et al., "Building an orthonormal basis, revisited", 2017).
#[inline]
pub fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n[2]);
    let a = -1.0 / (sign + n[2]);
    let b = n[0] * n[1] * a;
    (
        [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]],
        [b, sign + n[1] * n[1] * a, -n[1]],
    )
}

#[inline(always)]
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline(always)]
pub fn length(a: Vec3) -> f32 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weld_merges_split_seams() {
        let vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-0.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let mesh = weld(&vertices, &[[0, 1, 2], [3, 4, 2]]).unwrap();
        assert_eq!(mesh.positions.len(), 4);
        assert_eq!(mesh.remap[3], mesh.remap[0]);
    }

    #[test]
    fn weld_drops_index_degenerate_triangles() {
        let vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let mesh = weld(&vertices, &[[0, 1, 2]]).unwrap();
        assert!(mesh.triangles.is_empty());
    }

    #[test]
    fn weld_rejects_bad_input() {
        assert!(weld(&[], &[[0, 0, 0]]).is_err());
        assert!(weld(&[[0.0; 3]], &[]).is_err());
        assert!(weld(&[[0.0; 3]], &[[0, 0, 1]]).is_err());
        assert!(weld(&[[f32::NAN, 0.0, 0.0]], &[[0, 0, 0]]).is_err());
    }

    #[test]
    fn normalization_ignores_loose_vertices_and_size() {
        let vertices = [[10.0, 0.0, 0.0], [12.0, 0.0, 0.0], [10.0, 4.0, 0.0], [1e6, 1e6, 1e6]];
        let n = Normalization::of(&vertices, &[[0, 1, 2]]);
        assert_eq!(n.apply([11.0, 2.0, 0.0]), [0.0, 0.0, 0.0]);
        assert_eq!(n.apply([10.0, 4.0, 0.0]), [-0.5, 1.0, 0.0]);
        let tiny: Vec<Vec3> = vertices.iter().map(|v| v.map(|c| c * 1e-3)).collect();
        let m = Normalization::of(&tiny, &[[0, 1, 2]]);
        let q = m.apply(tiny[2]);
        assert!((q[0] + 0.5).abs() < 1e-6 && (q[1] - 1.0).abs() < 1e-6, "{q:?}");
    }

    #[test]
    fn tangent_frame_is_orthonormal() {
        for n in [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, 0.0, 0.8], [0.0, -0.6, -0.8]] {
            let (t, b) = tangent_frame(n);
            assert!(dot(t, b).abs() < 1e-6 && dot(t, n).abs() < 1e-6 && dot(b, n).abs() < 1e-6);
            let c = cross(t, b);
            assert!((c[0] - n[0]).abs() < 1e-6 && (c[1] - n[1]).abs() < 1e-6 && (c[2] - n[2]).abs() < 1e-6);
        }
    }
}
