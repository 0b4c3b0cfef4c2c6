//! What a solver keeps between frames of the scene that shadows it (`scene::casters`). Per
//! receiver it keeps the mask of its own blockers and of the casters that stood still, so
//! that in a frame where only some casters moved (a character walking through a still room,
//! a cloth over a still head) a receiver that did not move rasterizes only the moving ones.
//! Casters are told apart by the scene's per-instance stamps, renewed on every change.

use crate::disk_mask::Mask;
use crate::scene::casters::{Casters, CastersKey};

/// One receiver's masks, kept from one frame to the next.
#[derive(Clone, Copy, Default)]
pub struct Kept {
    /// Its own blockers.
    pub own: Mask,
    /// The still casters' (raw).
    pub still: Mask,
    /// What its result was integrated from: the same mask again gives the same result.
    pub total: Mask,
}

pub struct CasterCache {
    key: CastersKey,
    /// Every instance's stamp at the last solve.
    stamps: Vec<u64>,
    /// The instances whose blockers are in `masks` (ascending), and their stamps then.
    still: Vec<u32>,
    still_stamps: Vec<u64>,
    /// Per welded receiver.
    pub masks: Vec<Kept>,
}

impl CasterCache {
    pub fn bytes(&self) -> usize {
        self.masks.len() * std::mem::size_of::<Kept>() + (self.stamps.len() + self.still_stamps.len()) * 8 + self.still.len() * 4
    }
}

/// How this frame's casters relate to the last frame's.
pub struct CasterPlan {
    /// No instance changed: a receiver whose own blockers kept still keeps its last result.
    pub unchanged: bool,
    /// The cached masks hold for receivers whose own blockers kept still.
    pub masks_valid: bool,
    /// What a walk over the still instances skips (the excluded and the moving ones).
    pub skip_moving: Vec<u32>,
    /// What a walk over the moving instances skips (the excluded and the still ones).
    pub skip_still: Vec<u32>,
    still: Vec<u32>,
}

impl CasterPlan {
    /// The still instances are those of the cache while none of them changed; otherwise
    /// those unchanged since the last solve (all of them at the first).
    pub fn new(cache: Option<&CasterCache>, casters: &Casters) -> Self {
        let stamps = casters.stamps();
        let same = cache.filter(|c| &c.key == casters.key() && c.stamps.len() == stamps.len());
        let unchanged = same.is_some_and(|c| c.stamps == stamps);
        let masks_valid = same.is_some_and(|c| c.still.iter().zip(&c.still_stamps).all(|(&i, &s)| stamps[i as usize] == s));
        let all = 0..stamps.len() as u32;
        let still: Vec<u32> = match same {
            Some(c) if masks_valid => c.still.clone(),
            Some(c) => all.filter(|&i| stamps[i as usize] == c.stamps[i as usize]).collect(),
            None => all.collect(),
        };
        let mut is_still = vec![false; stamps.len()];
        still.iter().for_each(|&i| is_still[i as usize] = true);
        let moving: Vec<u32> = (0..stamps.len() as u32).filter(|&i| !is_still[i as usize]).collect();
        CasterPlan { unchanged, masks_valid, skip_moving: casters.skipping(&moving), skip_still: casters.skipping(&still), still }
    }

    /// The cache for the next frame, with this frame's masks (own and still blockers).
    pub fn into_cache(self, casters: &Casters, masks: Vec<Kept>) -> CasterCache {
        let stamps = casters.stamps().to_vec();
        let still_stamps = self.still.iter().map(|&i| stamps[i as usize]).collect();
        CasterCache { key: casters.key().clone(), stamps, still: self.still, still_stamps, masks }
    }
}
