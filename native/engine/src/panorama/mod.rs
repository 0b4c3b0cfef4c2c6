//! Relightable panoramas (Wong, Or, Fu 2003): primary visibility from a viewpoint (`hits`,
//! through a `bvh` of the scene's world triangles) and the native relighting of baked SH maps
//! by suns, point lights and environments (`relight`, SIMD kernels in `relight_avx2`).

pub mod bvh;
pub mod directions;
pub mod half;
pub mod hits;
pub mod relight;
#[cfg(target_arch = "x86_64")]
mod relight_avx2;
pub mod sh_lanes;
