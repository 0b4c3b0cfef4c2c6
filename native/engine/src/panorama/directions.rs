//! Blender's equirectangular mapping (World HDRIs; a panoramic camera rotated (90, 0, -90)
//! degrees): pixel (row r, column c) of a W x H panorama, row 0 at the top, has centre
//! u = (c + 0.5) / W, v = 1 - (r + 0.5) / H and looks along
//! phi = (0.5 - u) 2 pi, theta = (v - 0.5) pi, d = (cos theta cos phi, cos theta sin phi, sin theta)
//! in the viewpoint's frame; `rotation` (rows of a 3x3 matrix whose columns are the frame's
//! axes in world) takes it to world.

pub type Rotation = [[f64; 3]; 3];

pub const IDENTITY: Rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Per column (cos phi, sin phi).
pub fn columns(width: usize) -> Vec<(f64, f64)> {
    (0..width)
        .map(|c| {
            let u = (c as f64 + 0.5) / width as f64;
            let phi = (0.5 - u) * 2.0 * std::f64::consts::PI;
            (phi.cos(), phi.sin())
        })
        .collect()
}

/// Per row (cos theta, sin theta).
pub fn rows(height: usize) -> Vec<(f64, f64)> {
    (0..height)
        .map(|r| {
            let v = 1.0 - (r as f64 + 0.5) / height as f64;
            let theta = (v - 0.5) * std::f64::consts::PI;
            (theta.cos(), theta.sin())
        })
        .collect()
}

/// The world direction of a pixel from its row and column terms.
#[inline]
pub fn direction(rotation: &Rotation, (ct, st): (f64, f64), (cp, sp): (f64, f64)) -> [f64; 3] {
    let local = [ct * cp, ct * sp, st];
    rotation.map(|row| row[0] * local[0] + row[1] * local[1] + row[2] * local[2])
}
