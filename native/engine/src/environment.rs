//! Projection of equirectangular environment maps onto the SH basis.
//!
//! Pixels map to directions exactly as Blender's Environment Texture node maps them (Cycles,
//! `direction_to_equirectangular`): u = 0.5 - atan2(y, x) / (2 pi), v = 1 - acos(z) / pi, with
//! v = 1 the top row. Rows here are stored top row first, as image files store them. Each pixel
//! is weighted by its exact solid angle (cos theta_top - cos theta_bottom) 2 pi / width.

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::sh::{ShBasis, MAX_COEFFS};

/// An image of `height` x `width` pixels with `channels` interleaved floats (3 or 4; RGB used).
pub struct Image<'a> {
    pub pixels: &'a [f32],
    pub height: usize,
    pub width: usize,
    pub channels: usize,
}

/// Direction of the centre of pixel (row, col), row 0 at the top.
pub fn pixel_direction(row: usize, col: usize, height: usize, width: usize) -> [f32; 3] {
    use std::f64::consts::PI;
    let theta = PI * (row as f64 + 0.5) / height as f64;
    let phi = PI - 2.0 * PI * (col as f64 + 0.5) / width as f64;
    [(theta.sin() * phi.cos()) as f32, (theta.sin() * phi.sin()) as f32, theta.cos() as f32]
}

/// Lighting coefficients (bands^2 x 3, row-major) of the radiance in `image`; `rotation`
/// (row-major 3x3) is applied to each pixel direction before the basis is evaluated.
pub fn project(image: &Image, bands: usize, rotation: [[f32; 3]; 3]) -> Result<Vec<f32>> {
    check_image(image)?;
    let basis = ShBasis::new(bands)?;
    let k = basis.coeffs();
    let (h, w, ch) = (image.height, image.width, image.channels);
    let rows: Vec<Vec<f64>> = (0..h)
        .into_par_iter()
        .map(|row| {
            use std::f64::consts::PI;
            let (top, bottom) = (PI * row as f64 / h as f64, PI * (row + 1) as f64 / h as f64);
            let solid_angle = ((top.cos() - bottom.cos()) * 2.0 * PI / w as f64) as f32;
            let mut sums = vec![0.0f64; k * 3];
            let mut y = [0.0f32; MAX_COEFFS];
            for col in 0..w {
                let d = rotate(rotation, pixel_direction(row, col, h, w));
                basis.eval(d, &mut y);
                let px = &image.pixels[(row * w + col) * ch..(row * w + col) * ch + 3];
                for i in 0..k {
                    let wy = (y[i] * solid_angle) as f64;
                    for c in 0..3 {
                        sums[i * 3 + c] += wy * px[c] as f64;
                    }
                }
            }
            sums
        })
        .collect();
    let mut total = vec![0.0f64; k * 3];
    for sums in rows {
        total.iter_mut().zip(sums).for_each(|(t, s)| *t += s);
    }
    Ok(total.into_iter().map(|v| v as f32).collect())
}

fn check_image(image: &Image) -> Result<()> {
    if image.height == 0 || image.width == 0 {
        return Err(Error::invalid("the environment image is empty"));
    }
    if !(3..=4).contains(&image.channels) {
        return Err(Error::invalid(format!("the environment image needs 3 or 4 channels, got {}", image.channels)));
    }
    if image.pixels.len() != image.height * image.width * image.channels {
        return Err(Error::invalid("the environment image's pixel buffer does not match its shape"));
    }
    if let Some(i) = image.pixels.iter().position(|v| !v.is_finite()) {
        let px = i / image.channels;
        return Err(Error::invalid(format!(
            "the environment image has a non-finite value at row {}, column {}",
            px / image.width,
            px % image.width
        )));
    }
    Ok(())
}

#[inline]
pub fn rotate(m: [[f32; 3]; 3], d: [f32; 3]) -> [f32; 3] {
    [
        m[0][0] * d[0] + m[0][1] * d[1] + m[0][2] * d[2],
        m[1][0] * d[0] + m[1][1] * d[1] + m[1][2] * d[2],
        m[2][0] * d[0] + m[2][1] * d[1] + m[2][2] * d[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDENTITY: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

    #[test]
    fn constant_environment_projects_to_band_zero() {
        let (h, w) = (64, 128);
        let pixels = vec![1.0f32; h * w * 3];
        let image = Image { pixels: &pixels, height: h, width: w, channels: 3 };
        let l = project(&image, 3, IDENTITY).unwrap();
        // integral of Y_0 over the sphere = 4 pi * 0.282095 = 3.5449
        assert!((l[0] - 3.544_908).abs() < 1e-3, "{}", l[0]);
        assert!(l[3..].iter().all(|v| v.abs() < 1e-3));
    }

    #[test]
    fn centre_column_faces_plus_x() {
        let d = pixel_direction(32, 64, 64, 128);
        assert!(d[0] > 0.99, "{d:?}");
        let top = pixel_direction(0, 10, 64, 128);
        assert!(top[2] > 0.99);
    }

    #[test]
    fn rejects_non_finite_pixels() {
        let mut pixels = vec![1.0f32; 4 * 8 * 3];
        pixels[5] = f32::NAN;
        let image = Image { pixels: &pixels, height: 4, width: 8, channels: 3 };
        assert!(project(&image, 3, IDENTITY).is_err());
    }
}
