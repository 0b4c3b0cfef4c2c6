//! hemishadow's engine: soft self-shadowing from environment lighting by hemispherical
//! rasterization (Kautz, Lehtinen, Aila, "Hemispherical Rasterization for Self-Shadowing of
//! Dynamic Objects", EGSR 2004). No Python here; `hemishadow-bindings` wraps it.
//!
//! Pipeline per receiver vertex: tangent frame -> blockers into the 32x32 disk mask
//! (`rasterizer`, `plane_table`, `disk_mask`) -> integration against SH and the BRDF
//! (`integrate`, `sh`) -> transfer vector (`transfer`). Lighting comes from `environment`.

// Two lints the engine's numeric code disagrees with on purpose: `!(a > b)` is how a test
// also rejects NaN, and loops over lanes and axes index several arrays at once (the portable
// kernels mirror their AVX2 twins lane by lane), which a zip of three or four iterators hides.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod caster_reuse;
pub mod disk_mask;
pub mod environment;
pub mod error;
pub mod group_tree;
pub mod hierarchy;
pub mod integrate;
pub mod large_pages;
pub mod mesh;
pub mod panorama;
pub mod packets;
pub mod plane_table;
pub mod progress;
pub mod pvs;
pub mod rasterizer;
pub mod scene;
pub mod sh;
pub mod sh_rotation;
pub mod solver;
pub mod transfer;

pub use error::{Error, Result};
pub use integrate::Brdf;
pub use progress::Progress;
pub use solver::{Blockers, Solver, Stats};
pub use transfer::{transfer, transfer_with_progress, Output, Settings, View};

/// Reproducible random numbers for tests, without a dependency.
#[cfg(test)]
pub(crate) mod test_random {
    /// One step of xorshift32 (Marsaglia 2003); `state` must not be 0.
    pub(crate) fn xorshift32(state: &mut u32) -> u32 {
        *state ^= *state << 13;
        *state ^= *state >> 17;
        *state ^= *state << 5;
        *state
    }
}
