//! Arbitrary receivers: points with a normal anywhere in the scene (lightmap texels, probes,
//! panorama pixels), not mesh vertices. With no own triangles to leave out, a receiver is lifted
//! along its normal by an offset relative to the scene's size, which keeps the surface it lies
//! on below its horizon. A receiver is invalid when it sits inside solid geometry: more than
//! half of its hemisphere's cells see, as their nearest blocker, the back of a face (a point in
//! an open concave corner sees front faces only; one inside a closed mesh sees back faces all
//! around).

use crate::disk_mask::{disk, MASK_CELLS};
use crate::error::{Error, Result};
use crate::mesh::{normalize, Vec3};
use crate::transfer::Receiver;

/// Default offset along the normal, as a fraction of the scene's bounding-box diagonal.
pub const DEFAULT_OFFSET: f32 = 1e-4;

/// Fraction of the hemisphere's cells that may show back faces before a receiver is invalid.
pub const BACK_FACE_LIMIT: f32 = 0.5;

/// The receivers' offset in world units: `fraction` (default DEFAULT_OFFSET) of `scene_size`.
pub fn offset(fraction: Option<f32>, scene_size: f32) -> Result<f32> {
    match fraction {
        None => Ok(DEFAULT_OFFSET * scene_size),
        Some(f) if f.is_finite() && f >= 0.0 => Ok(f * scene_size),
        Some(f) => Err(Error::invalid(format!("offset must be a finite, non-negative fraction of the scene's size, got {f}"))),
    }
}

/// Checks points and normals (same count, finite, non-zero normals) before any work.
pub fn check(points: &[Vec3], normals: Option<&[Vec3]>) -> Result<()> {
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid(format!("point {i} is not finite: {:?}", points[i])));
    }
    let Some(normals) = normals else { return Ok(()) };
    if normals.len() != points.len() {
        return Err(Error::invalid(format!("normals has {} rows but points has {}", normals.len(), points.len())));
    }
    if let Some(i) = normals.iter().position(|n| normalize(*n).is_none()) {
        return Err(Error::invalid(format!("normal {i} must be a finite, non-zero direction, got {:?}", normals[i])));
    }
    Ok(())
}

/// A receiver at `point` looking along `normal` (normalised here), `offset` above the point.
pub fn receiver(point: Vec3, normal: Vec3, offset: f32) -> Receiver {
    let n = normalize(normal).unwrap_or([0.0, 0.0, 1.0]);
    Receiver::new(point, n, offset).expect("a unit normal is non-zero")
}

/// Whether the back faces seen are at most BACK_FACE_LIMIT of the hemisphere.
pub fn is_valid(back: &crate::disk_mask::Mask) -> bool {
    back_fraction(back) <= BACK_FACE_LIMIT
}

/// The fraction of the disk's cells whose nearest blocker shows its back.
pub fn back_fraction(back: &crate::disk_mask::Mask) -> f32 {
    let cells = disk().count() as f32;
    debug_assert!(cells as usize <= MASK_CELLS);
    back.count() as f32 / cells
}
