//! Where an image lies in the model: the affine map from pixels to the model frame.
//!
//! Pixel `(x, y)` (column, row; centres at integer coordinates as in `femu_dic::GreyImage`)
//! images the model point
//!
//! ```text
//!   X(x, y) = O + s (x e_x + y e_y)                 (mm)
//! ```
//!
//! with `O` the model point of pixel (0, 0), `s` the pixel size (mm/px) and `e_x`, `e_y`
//! orthonormal model directions of the image's columns and rows. A linear ultrasound probe on
//! the skin is one such frame (`e_y` the beam, into the tissue; `e_x` along the array); so is
//! any calibrated camera looking at a plane. A model displacement `U` (mm) moves the image of
//! a material point by `d = (U·e_x, U·e_y) / s` pixels.

use serde::{Deserialize, Serialize};

/// The pose and pixel size of an image in the model frame (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageFrame {
    /// Model point (mm) of the centre of pixel (0, 0).
    pub origin_mm: [f64; 2],
    /// Pixel size (mm/px).
    pub mm_per_px: f64,
    /// Unit model direction of increasing column `x`.
    pub x_axis: [f64; 2],
    /// Unit model direction of increasing row `y` (perpendicular to `x_axis`).
    pub y_axis: [f64; 2],
}

impl ImageFrame {
    /// A frame with its axes checked orthonormal (to 1e-6) and a positive finite pixel size.
    pub fn new(
        origin_mm: [f64; 2],
        mm_per_px: f64,
        x_axis: [f64; 2],
        y_axis: [f64; 2],
    ) -> Result<ImageFrame, String> {
        if !(mm_per_px > 0.0 && mm_per_px.is_finite()) {
            return Err(format!("pixel size {mm_per_px} mm must be positive"));
        }
        if !(origin_mm[0].is_finite() && origin_mm[1].is_finite()) {
            return Err(format!("origin {origin_mm:?} mm must be finite"));
        }
        let unit = |v: [f64; 2]| (v[0].hypot(v[1]) - 1.0).abs() < 1e-6;
        if !(unit(x_axis) && unit(y_axis)) {
            return Err(format!("axes {x_axis:?}, {y_axis:?} must be unit vectors"));
        }
        if (x_axis[0] * y_axis[0] + x_axis[1] * y_axis[1]).abs() > 1e-6 {
            return Err(format!("axes {x_axis:?}, {y_axis:?} must be perpendicular"));
        }
        Ok(ImageFrame {
            origin_mm,
            mm_per_px,
            x_axis,
            y_axis,
        })
    }

    /// Model point (mm) of a pixel position.
    pub fn pixel_to_model(&self, p: [f64; 2]) -> [f64; 2] {
        let s = self.mm_per_px;
        [
            self.origin_mm[0] + s * (p[0] * self.x_axis[0] + p[1] * self.y_axis[0]),
            self.origin_mm[1] + s * (p[0] * self.x_axis[1] + p[1] * self.y_axis[1]),
        ]
    }

    /// Pixel position of a model point.
    pub fn model_to_pixel(&self, x: [f64; 2]) -> [f64; 2] {
        let d = [x[0] - self.origin_mm[0], x[1] - self.origin_mm[1]];
        self.displacement_to_pixels(d)
    }

    /// A model displacement (mm) in pixels: `(U·e_x, U·e_y) / s`.
    #[inline]
    pub fn displacement_to_pixels(&self, u: [f64; 2]) -> [f64; 2] {
        let k = 1.0 / self.mm_per_px;
        [
            k * (u[0] * self.x_axis[0] + u[1] * self.x_axis[1]),
            k * (u[0] * self.y_axis[0] + u[1] * self.y_axis[1]),
        ]
    }

    /// The nodal displacement field `u` (2 components per node, mm) at location `l`, in pixels.
    #[inline]
    pub fn field_to_pixels(&self, l: &femu_mesh::locate::PointLocation, u: &[f64]) -> [f64; 2] {
        self.displacement_to_pixels([l.interpolate(u, 2, 0), l.interpolate(u, 2, 1)])
    }

    /// A displacement in pixels as a model displacement (mm).
    pub fn displacement_to_model(&self, d: [f64; 2]) -> [f64; 2] {
        let s = self.mm_per_px;
        [
            s * (d[0] * self.x_axis[0] + d[1] * self.y_axis[0]),
            s * (d[0] * self.x_axis[1] + d[1] * self.y_axis[1]),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_refuses_bad_axes() {
        let f = ImageFrame::new([-19.95, 59.95], 0.1, [1.0, 0.0], [0.0, -1.0]).unwrap();
        let x = f.pixel_to_model([12.5, 40.0]);
        assert!((x[0] - (-19.95 + 1.25)).abs() < 1e-12 && (x[1] - (59.95 - 4.0)).abs() < 1e-12);
        let p = f.model_to_pixel(x);
        assert!((p[0] - 12.5).abs() < 1e-9 && (p[1] - 40.0).abs() < 1e-9);
        let d = f.displacement_to_pixels([0.3, -0.7]);
        assert!((d[0] - 3.0).abs() < 1e-12 && (d[1] - 7.0).abs() < 1e-12);
        let u = f.displacement_to_model(d);
        assert!((u[0] - 0.3).abs() < 1e-12 && (u[1] + 0.7).abs() < 1e-12);
        assert!(ImageFrame::new([0.0; 2], 0.1, [1.0, 0.0], [1.0, 0.0]).is_err());
        assert!(ImageFrame::new([0.0; 2], 0.1, [2.0, 0.0], [0.0, 1.0]).is_err());
        assert!(ImageFrame::new([0.0; 2], -0.1, [1.0, 0.0], [0.0, 1.0]).is_err());
    }
}
