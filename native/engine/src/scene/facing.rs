//! Validity without depth for most receivers. A receiver is invalid when more than half of the
//! disk's cells see a back face first (`receivers`). Only the ordered mode knows what is seen
//! first, but the cells that some back-facing blocker covers bound those from above: a
//! receiver whose back-facing blockers cover at most half of the disk is valid, whatever lies
//! in front of them. One plain walk with the blockers split by facing settles that for almost
//! every receiver of a room (the back faces it sees are the far sides of furniture, hidden
//! behind their front sides) and gives its visibility mask too; only the others need the
//! ordered walk.

use crate::disk_mask::Mask;
use crate::mesh::{sub, Vec3};
use crate::packets::LANES;
use crate::plane_table::PlaneTable;
use crate::rasterizer::{cross, dot, LocalCorners, TriangleBatch};

use super::traverse::{Sink, Tag};

/// Whether the receiver, at the origin, sees the back of triangle (a, b, c) of an instance
/// with `facing` (-1 when its matrix mirrors): the ordered mode's test (`DepthSink::draw`),
/// operation for operation, so that both split the blockers alike.
#[inline(always)]
pub fn sees_back(a: Vec3, b: Vec3, c: Vec3, facing: f32) -> bool {
    let normal = cross(sub(b, a), sub(c, a));
    facing * dot(normal, a) > 0.0
}

/// The masks of a receiver's front- and back-facing blockers (occluder fusion within each).
pub struct FacingSink<'a> {
    table: &'a PlaneTable,
    front: TriangleBatch,
    back: TriangleBatch,
    front_mask: Mask,
    back_mask: Mask,
}

impl<'a> FacingSink<'a> {
    pub fn new(table: &'a PlaneTable) -> Self {
        FacingSink { table, front: TriangleBatch::default(), back: TriangleBatch::default(), front_mask: Mask::EMPTY, back_mask: Mask::EMPTY }
    }

    /// (front, back): the raw masks, pinholes not closed. Walks with this sink never stop
    /// early: every back-facing blocker counts.
    pub fn finish(mut self) -> (Mask, Mask) {
        self.front.finish(self.table, &mut self.front_mask);
        self.back.finish(self.table, &mut self.back_mask);
        (self.front_mask, self.back_mask)
    }
}

impl Sink for FacingSink<'_> {
    #[inline(always)]
    fn triangle(&mut self, a: Vec3, b: Vec3, c: Vec3, _: [u32; 3], tag: Tag) {
        if sees_back(a, b, c, tag.facing) {
            self.back.push(self.table, a, b, c, &mut self.back_mask);
        } else {
            self.front.push(self.table, a, b, c, &mut self.front_mask);
        }
    }

    const PACKETS: bool = true;

    #[inline(always)]
    fn packet(&mut self, corners: &LocalCorners, lanes: u32, facing: f32) {
        let mut back = 0u32;
        for i in 0..LANES {
            let corner = |k: usize| [corners[k][0][i], corners[k][1][i], corners[k][2][i]];
            back |= (sees_back(corner(0), corner(1), corner(2), facing) as u32) << i;
        }
        let (front_lanes, back_lanes) = (lanes & !back, lanes & back);
        if front_lanes != 0 {
            self.front.push_packet(self.table, corners, front_lanes, &mut self.front_mask);
        }
        if back_lanes != 0 {
            self.back.push_packet(self.table, corners, back_lanes, &mut self.back_mask);
        }
    }
}
