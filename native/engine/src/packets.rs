//! Blocker triangles in structure-of-arrays packets of `LANES`, the unit the rasterizer works
//! on (Embree-style SoA): a receiver transforms, tests and rasterizes a packet with vector
//! instructions, and skips a whole packet whose box lies below its horizon.
//!
//! The topology (which triangles, and their vertex ids for the receiver's own-triangle test)
//! is fixed when the packets are made; `update` writes one frame's corners and boxes.

use rayon::prelude::*;

use crate::mesh::Vec3;

/// Triangles per packet: eight f32 lanes fill an AVX2 register.
pub const LANES: usize = 8;

/// Up to `LANES` triangles: corner k, axis j, lane i is `corners[k][j][i]`.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
pub struct Packet {
    pub corners: [[[f32; LANES]; 3]; 3],
    /// Vertex ids of the corners (lanes past `lanes` repeat u32::MAX).
    pub ids: [[u32; LANES]; 3],
    /// Bit i set when lane i holds a triangle.
    pub lanes: u32,
    /// Box around this frame's corners.
    pub bounds: [Vec3; 2],
}

impl Packet {
    fn new(triangles: &[[u32; 3]]) -> Self {
        debug_assert!(triangles.len() <= LANES);
        let mut ids = [[u32::MAX; LANES]; 3];
        for (i, tri) in triangles.iter().enumerate() {
            (0..3).for_each(|k| ids[k][i] = tri[k]);
        }
        let lanes = (1u32 << triangles.len()) - 1;
        Packet { corners: [[[0.0; LANES]; 3]; 3], ids, lanes, bounds: [[0.0; 3]; 2] }
    }

    /// This frame's corners and box.
    fn update(&mut self, positions: &[Vec3]) {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for i in 0..(32 - self.lanes.leading_zeros()) as usize {
            for k in 0..3 {
                let p = positions[self.ids[k][i] as usize];
                for a in 0..3 {
                    self.corners[k][a][i] = p[a];
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
        }
        self.bounds = [lo, hi];
    }
}

/// Lists of triangles, each list cut into packets (CSR: list l owns packets
/// `start[l]..start[l + 1]`).
#[derive(Clone, Default)]
pub struct PacketLists {
    pub packets: Vec<Packet>,
    pub start: Vec<u32>,
}

impl PacketLists {
    pub fn new<'a>(lists: impl Iterator<Item = &'a [[u32; 3]]>) -> Self {
        let mut out = PacketLists { packets: Vec::new(), start: vec![0] };
        for list in lists {
            out.packets.extend(list.chunks(LANES).map(Packet::new));
            out.start.push(out.packets.len() as u32);
        }
        out
    }

    /// One list per `LANES` triangles, lane i of packet p holding triangle p * LANES + i.
    pub fn strided(triangles: &[[u32; 3]]) -> Self {
        PacketLists::new(triangles.chunks(LANES))
    }

    #[inline(always)]
    pub fn of(&self, list: usize) -> &[Packet] {
        &self.packets[self.start[list] as usize..self.start[list + 1] as usize]
    }

    /// Writes this frame's corners and boxes.
    pub fn update(&mut self, positions: &[Vec3]) {
        self.packets.par_iter_mut().with_min_len(256).for_each(|p| p.update(positions));
    }

    pub fn bytes(&self) -> usize {
        self.packets.len() * std::mem::size_of::<Packet>() + self.start.len() * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_are_cut_into_full_packets_and_a_remainder() {
        let tris: Vec<[u32; 3]> = (0..11).map(|t| [t, t + 1, t + 2]).collect();
        let mut lists = PacketLists::new([&tris[..], &tris[..3]].into_iter());
        assert_eq!(lists.start, vec![0, 2, 3]);
        assert_eq!(lists.of(0)[1].lanes, 0b111);
        let positions: Vec<Vec3> = (0..13).map(|v| [v as f32, 0.0, -(v as f32)]).collect();
        lists.update(&positions);
        let p = &lists.of(0)[1];
        assert_eq!([p.corners[2][0][2], p.corners[2][2][2]], [12.0, -12.0]); // triangle 10, corner 2
        assert_eq!(p.bounds, [[8.0, 0.0, -12.0], [12.0, 0.0, -8.0]]);
        assert_eq!(p.ids[0][3], u32::MAX);
    }
}
