//! The ordered mode: which blocker is seen in each cell, not only whether one is. The paper's
//! rasterizer has no depth (occluder fusion, section 3.1); here each covered cell also keeps the
//! distance along its own sample direction to the blocker's plane, and a nearer blocker
//! replaces a farther one (a per-cell depth test). That is the "nearest first" rule made
//! exact per cell: sorting whole triangles by distance would let a large floor win over an
//! object standing on it. A cell keeps the facing of its nearest blocker (for `valid`) and
//! that blocker's radiance interpolated barycentrically at the cell's direction (for `gather`).

use crate::disk_mask::{cell_direction, Mask, MASK_CELLS, MASK_SIDE};
use crate::mesh::{sub, Vec3};
use crate::plane_table::PlaneTable;
use crate::packets::LANES;
use crate::rasterizer::{cross, dot, edge_codes, LocalCorners};

use super::traverse::{Sink, Tag};

/// The sample direction of every cell in the receiver's frame (zero outside the disk).
pub fn cell_directions() -> &'static [Vec3; MASK_CELLS] {
    static DIRECTIONS: std::sync::OnceLock<[Vec3; MASK_CELLS]> = std::sync::OnceLock::new();
    DIRECTIONS.get_or_init(|| std::array::from_fn(|i| cell_direction(i / MASK_SIDE, i % MASK_SIDE).unwrap_or([0.0; 3])))
}

pub type Rgb = [f32; 3];

/// Relative depth difference under which two blockers count as coincident.
const TIE: f32 = 1e-4;

/// The nearest blocker of a cell: its instance, its corners' vertex ids and the cell
/// direction's barycentric weights on them.
#[derive(Clone, Copy)]
pub struct Hit {
    pub instance: u32,
    pub ids: [u32; 3],
    pub weights: [f32; 3],
}

/// A triangle whose table codes are known and whose masks are on their way.
#[derive(Clone, Copy)]
struct Pending {
    corners: [Vec3; 3],
    ids: [u32; 3],
    tag: Tag,
    codes: [u32; 3],
}

/// A triangle that won some cell: what its barycentric weights need.
#[derive(Clone, Copy)]
struct Winner {
    a: Vec3,
    e1: Vec3,
    e2: Vec3,
    normal: Vec3,
    nn: f32,
    ids: [u32; 3],
    instance: u32,
}

const NO_TAG: Tag = Tag { mesh: 0, instance: 0, facing: 1.0 };
const NO_PENDING: Pending = Pending { corners: [[0.0; 3]; 3], ids: [0; 3], tag: NO_TAG, codes: [0; 3] };

pub struct DepthSink<'a> {
    table: &'a PlaneTable,
    /// Per instance, its per-vertex radiance (None: black).
    radiance: &'a [Option<&'a [Rgb]>],
    pub depth: [f32; MASK_CELLS],
    /// Cells whose nearest blocker shows its back.
    pub back: Mask,
    /// Every blocker's table mask OR-ed, as the plain mask walk draws them (`covered` leaves
    /// out cells whose ray misses a blocker's plane).
    pub raw: Mask,
    pub colour: [Rgb; MASK_CELLS],
    pub triangles: u64,
    /// Triangles that won a cell, and per cell the index of its winner: barycentric weights
    /// are taken once per cell (`hit`), not at every win (a cell is won a few times over as
    /// nearer blockers arrive).
    winners: Vec<Winner>,
    winner: [u32; MASK_CELLS],
    /// Whether winners are kept: for colours, or for `hit` (else depth and facing are all
    /// there is).
    keeps_winners: bool,
    /// Triangles in arrival order, a batch at a time: their texels are computed lane-parallel
    /// when the batch is full (`edge_codes`, as the mask rasterizer does) and prefetched;
    /// the batch before is drawn then, by when its masks are in cache (the 256 table is 48
    /// MiB; one triangle at a time, texels and fetches were most of a gather's time).
    batch: LocalCorners,
    batch_ids: [[u32; 3]; LANES],
    batch_tags: [Tag; LANES],
    batch_len: usize,
    pending: [Pending; LANES],
    pending_len: usize,
}

impl<'a> DepthSink<'a> {
    pub fn new(table: &'a PlaneTable, radiance: &'a [Option<&'a [Rgb]>]) -> Self {
        DepthSink {
            table,
            radiance,
            depth: [f32::INFINITY; MASK_CELLS],
            back: Mask::EMPTY,
            raw: Mask::EMPTY,
            colour: [[0.0; 3]; MASK_CELLS],
            triangles: 0,
            winners: Vec::new(),
            winner: [0; MASK_CELLS],
            keeps_winners: radiance.iter().any(Option::is_some),
            batch: [[[0.0; LANES]; 3]; 3],
            batch_ids: [[0; 3]; LANES],
            batch_tags: [NO_TAG; LANES],
            batch_len: 0,
            pending: [NO_PENDING; LANES],
            pending_len: 0,
        }
    }

    /// A sink that keeps each cell's nearest blocker for `hit`, whatever the radiance.
    pub fn recording(table: &'a PlaneTable, radiance: &'a [Option<&'a [Rgb]>]) -> Self {
        DepthSink { keeps_winners: true, ..DepthSink::new(table, radiance) }
    }

    /// The nearest blocker of a covered cell once the walk is over (None where nothing is
    /// seen, or when winners are not kept).
    pub fn hit(&self, cell: usize) -> Option<Hit> {
        let t = self.depth[cell];
        if !(self.keeps_winners && t.is_finite()) {
            return None;
        }
        let w = &self.winners[self.winner[cell] as usize];
        let d = cell_directions()[cell];
        let q = sub([d[0] * t, d[1] * t, d[2] * t], w.a);
        Some(Hit { instance: w.instance, ids: w.ids, weights: barycentric(q, w.e1, w.e2, w.normal, w.nn) })
    }

    /// The cells whose nearest blockers show their light in `cell`, with their shares; returns
    /// how many of `out` it set. A cell whose nearest blocker faces the receiver shows its own.
    /// A back face, or nothing, in a cell whose neighbours (left, right, up, down) show front
    /// faces all round, is a pinhole between two triangles of a surface (the plane table's
    /// cells on a shared edge can fall to neither): the cell shows its front neighbours'
    /// light. It showed the inside of the solid behind, lit as the other side of the wall: a
    /// room lit through its window by the sky alone gathered 1.6x Cycles' bounce light on its
    /// floor. Other back faces (the inside of a solid, a sheet seen from behind) show none.
    pub fn sources(&self, cell: usize, out: &mut [(usize, f32); 4]) -> usize {
        let covered = self.depth[cell].is_finite();
        if covered && !self.back.get(cell / MASK_SIDE, cell % MASK_SIDE) {
            out[0] = (cell, 1.0);
            return 1;
        }
        let (row, col) = ((cell / MASK_SIDE) as i32, (cell % MASK_SIDE) as i32);
        let mut count = 0;
        for (dr, dc) in [(0, -1), (0, 1), (-1, 0), (1, 0)] {
            let (r, c) = (row + dr, col + dc);
            if !(0..MASK_SIDE as i32).contains(&r) || !(0..MASK_SIDE as i32).contains(&c) || cell_direction(r as usize, c as usize).is_none() {
                continue; // off the disk
            }
            let n = r as usize * MASK_SIDE + c as usize;
            if !self.depth[n].is_finite() || self.back.get(r as usize, c as usize) {
                return 0; // not a pinhole
            }
            out[count] = (n, 0.0);
            count += 1;
        }
        out[..count].iter_mut().for_each(|s| s.1 = 1.0 / count as f32);
        count
    }

    /// Cells some blocker covers.
    pub fn covered(&self) -> Mask {
        let mut mask = Mask::EMPTY;
        for (i, d) in self.depth.iter().enumerate() {
            if d.is_finite() {
                mask.set(i / MASK_SIDE, i % MASK_SIDE);
            }
        }
        mask
    }
}

impl Sink for DepthSink<'_> {
    /// Queues the triangle; a full batch gets its texels and the batch before is drawn.
    /// Triangles are drawn in arrival order, so ties resolve as one at a time.
    #[inline(always)]
    fn triangle(&mut self, a: Vec3, b: Vec3, c: Vec3, ids: [u32; 3], tag: Tag) {
        let i = self.batch_len;
        for j in 0..3 {
            self.batch[0][j][i] = a[j];
            self.batch[1][j][i] = b[j];
            self.batch[2][j][i] = c[j];
        }
        self.batch_ids[i] = ids;
        self.batch_tags[i] = tag;
        self.batch_len += 1;
        if self.batch_len == LANES {
            self.advance();
        }
    }

    fn flush(&mut self) {
        self.advance();
        self.draw_pending();
        self.resolve();
    }
}

impl DepthSink<'_> {
    /// Texels of the queued batch, prefetched; draws the pending batch and makes this one pending.
    #[inline(always)]
    fn advance(&mut self) {
        let mut codes = [[0u32; LANES]; 3];
        let solid = edge_codes(self.table, &self.batch, &mut codes) & ((1u32 << self.batch_len) - 1);
        let mut next = [NO_PENDING; LANES];
        let mut next_len = 0;
        let mut bits = solid;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let t = [0, 1, 2].map(|e| codes[e][i]);
            t.iter().for_each(|&t| self.table.prefetch_code(t));
            let corner = |k: usize| [self.batch[k][0][i], self.batch[k][1][i], self.batch[k][2][i]];
            next[next_len] = Pending { corners: [corner(0), corner(1), corner(2)], ids: self.batch_ids[i], tag: self.batch_tags[i], codes: t };
            next_len += 1;
        }
        self.batch_len = 0;
        self.draw_pending();
        self.pending = next;
        self.pending_len = next_len;
    }

    #[inline(always)]
    fn draw_pending(&mut self) {
        let t = self.table;
        for k in 0..self.pending_len {
            let Pending { corners: [a, b, c], ids, tag, codes } = self.pending[k];
            let covered = t.triangle_of_codes(codes);
            self.raw.or_assign(&covered);
            self.draw(covered, a, b, c, ids, tag);
        }
        self.pending_len = 0;
    }

    /// The per-cell depth test of a triangle covering `covered`.
    #[inline(always)]
    fn draw(&mut self, covered: Mask, a: Vec3, b: Vec3, c: Vec3, ids: [u32; 3], tag: Tag) {
        self.triangles += 1;
        let (e1, e2) = (sub(b, a), sub(c, a));
        let normal = cross(e1, e2);
        let (nn, na) = (dot(normal, normal), dot(normal, a));
        // Receiver at the origin: it sees the winding's back when the plane's normal points away
        // (`facing::sees_back`, which must agree with this bit for bit).
        let back = tag.facing * na > 0.0;
        let index = self.winners.len() as u32;
        let mut won = false;
        let directions = cell_directions();
        for (w, &word) in covered.0.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let cell = w * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let d = directions[cell];
                let t = na / dot(normal, d);
                // Coincident faces (a box standing on a floor) tie: the back face wins, so a
                // receiver inside the box is not let out through the floor.
                let nearer = t < self.depth[cell] || (back && t <= self.depth[cell] * (1.0 + TIE));
                if !(t > 0.0 && nearer) {
                    continue; // farther, or a quantised edge cell whose ray misses the plane
                }
                self.depth[cell] = t;
                let bit = 1u64 << (cell % 64);
                self.back.0[w] = if back { self.back.0[w] | bit } else { self.back.0[w] & !bit };
                self.winner[cell] = index;
                won = true;
            }
        }
        if won && self.keeps_winners {
            self.winners.push(Winner { a, e1, e2, normal, nn, ids, instance: tag.instance });
        }
    }

    /// Colour of every covered cell from its winner, once the walk is over: the radiance
    /// interpolated barycentrically at the cell's direction on its nearest blocker (black when
    /// that blocker's instance shows none); pinholes show their neighbours' (`sources`).
    fn resolve(&mut self) {
        if !self.keeps_winners || self.radiance.iter().all(Option::is_none) {
            return; // colours stay black
        }
        let mut sources = [(0, 0.0); 4];
        for cell in 0..MASK_CELLS {
            let count = self.sources(cell, &mut sources);
            let mut colour = [0.0f32; 3];
            for &(source, share) in &sources[..count] {
                let Some(r) = self.radiance[self.winners[self.winner[source] as usize].instance as usize] else { continue };
                let Hit { ids, weights, .. } = self.hit(source).expect("a covered cell with its winner kept");
                let [ra, rb, rc] = ids.map(|v| r[v as usize]);
                (0..3).for_each(|k| colour[k] += share * (weights[0] * ra[k] + weights[1] * rb[k] + weights[2] * rc[k]));
            }
            self.colour[cell] = colour;
        }
    }
}

/// Barycentric weights of the point `q` (relative to corner a) on the triangle with edges e1,
/// e2 and normal e1 x e2 (squared length nn), clamped onto the triangle (quantised edge cells
/// whose directions fall just outside it).
#[inline(always)]
fn barycentric(q: Vec3, e1: Vec3, e2: Vec3, normal: Vec3, nn: f32) -> [f32; 3] {
    let beta = (dot(cross(q, e2), normal) / nn).clamp(0.0, 1.0);
    let gamma = (dot(cross(e1, q), normal) / nn).clamp(0.0, 1.0);
    let sum = beta + gamma;
    let (beta, gamma) = if sum > 1.0 { (beta / sum, gamma / sum) } else { (beta, gamma) };
    [1.0 - beta - gamma, beta, gamma]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> std::sync::Arc<PlaneTable> {
        PlaneTable::shared(crate::plane_table::DEFAULT_RESOLUTION).unwrap()
    }

    const TAG: Tag = Tag { mesh: 0, instance: 0, facing: 1.0 };

    #[test]
    fn nearer_roof_wins_whatever_the_order() {
        let t = table();
        let radiance: Vec<Rgb> = vec![[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]];
        let meshes = [Some(radiance.as_slice())];
        // Wound to face the receiver below (a back face shows no light).
        let near = ([-5.0, -5.0, 1.0], [0.0, 5.0, 1.0], [5.0, -5.0, 1.0]);
        let far = ([-50.0, -50.0, 2.0], [0.0, 50.0, 2.0], [50.0, -50.0, 2.0]);
        for near_first in [true, false] {
            let mut sink = DepthSink::new(&t, &meshes);
            let order = if near_first { [(near, [0, 1, 2]), (far, [3, 4, 5])] } else { [(far, [3, 4, 5]), (near, [0, 1, 2])] };
            for ((a, b, c), ids) in order {
                sink.triangle(a, b, c, ids, TAG);
            }
            sink.flush();
            let zenith = 16 * MASK_SIDE + 16;
            assert!((sink.depth[zenith] - 1.0).abs() < 0.01, "{}", sink.depth[zenith]);
            assert_eq!(sink.colour[zenith], [1.0, 0.0, 0.0]);
        }
    }

    #[test]
    fn a_nearer_blocker_without_radiance_hides_a_glowing_one() {
        let t = table();
        let glow: Vec<Rgb> = vec![[1.0, 1.0, 1.0]; 3];
        let meshes = [None, Some(glow.as_slice())];
        let mut sink = DepthSink::new(&t, &meshes);
        let far = Tag { mesh: 1, instance: 1, facing: 1.0 };
        sink.triangle([-50.0, -50.0, 2.0], [0.0, 50.0, 2.0], [50.0, -50.0, 2.0], [0, 1, 2], far);
        sink.triangle([-5.0, -5.0, 1.0], [0.0, 5.0, 1.0], [5.0, -5.0, 1.0], [0, 1, 2], TAG);
        sink.flush();
        let zenith = 16 * MASK_SIDE + 16;
        assert!((sink.depth[zenith] - 1.0).abs() < 0.01);
        assert_eq!(sink.colour[zenith], [0.0; 3]); // black, not the farther glow
        let rim = (0..MASK_CELLS).find(|&c| sink.depth[c] > 1.5 && sink.depth[c].is_finite()).expect("a cell sees the far one");
        assert_eq!(sink.colour[rim], [1.0; 3]);
    }

    #[test]
    fn a_back_face_shows_no_light() {
        let t = table();
        let glow: Vec<Rgb> = vec![[1.0, 1.0, 1.0]; 3];
        let meshes = [Some(glow.as_slice())];
        for (b, c, lit) in [([0.0, 5.0, 1.0], [5.0, -5.0, 1.0], true), ([5.0, -5.0, 1.0], [0.0, 5.0, 1.0], false)] {
            let mut sink = DepthSink::new(&t, &meshes);
            sink.triangle([-5.0, -5.0, 1.0], b, c, [0, 1, 2], TAG);
            sink.flush();
            let zenith = 16 * MASK_SIDE + 16;
            assert!((sink.depth[zenith] - 1.0).abs() < 0.01); // seen either way: it blocks
            assert_eq!(sink.colour[zenith], if lit { [1.0; 3] } else { [0.0; 3] });
            assert_eq!(sink.sources(zenith, &mut [(0, 0.0); 4]), lit as usize);
        }
    }

    #[test]
    fn facing_follows_winding_and_mirroring() {
        let t = table();
        let meshes = [None];
        // Counter-clockwise seen from above: its normal points up, away from the receiver below.
        let (a, b, c) = ([-5.0, -5.0, 1.0], [5.0, -5.0, 1.0], [0.0, 5.0, 1.0]);
        let mut sink = DepthSink::new(&t, &meshes);
        sink.triangle(a, b, c, [0, 1, 2], TAG);
        sink.flush();
        assert!(sink.back.count() > 100);
        let mut sink = DepthSink::new(&t, &meshes);
        sink.triangle(a, b, c, [0, 1, 2], Tag { mesh: 0, instance: 0, facing: -1.0 });
        sink.flush();
        assert_eq!(sink.back.count(), 0);
        assert!(sink.covered().count() > 100);
    }
}
