//! The lateral motion of B-mode speckle under shear, in the measurement model.
//!
//! A delay-and-sum image focused on receive at every pixel has a point-spread function whose
//! phase curves across the beam like a lens's focal plane, `h(dx, dz) ≈ A exp(i k₂ dz + i α dx²)`
//! with `α = -k/(2z)` at depth `z` (`k = 2π f / c` the one-way wavenumber, `k₂ = 2k`). Under a
//! shear `g = ∂u_axial/∂x_lateral` the scatterers' axial shifts grow across the beam, the
//! speckle sees `h(dx, dz + g dx)`, and its envelope moves sideways while the tissue does not:
//!
//! ```text
//!   shift = c(z) g,    c(z) = k₂ (-α) / (2 (α² + 1/(4σ⁴)))     (mm per unit shear)
//! ```
//!
//! for a Gaussian lateral amplitude of standard deviation `σ` (the lateral resolution's FWHM
//! over `2√(2 ln 2)`). A DIC field of such frames therefore measures
//! `u_lateral + κ c(z) g` instead of `u_lateral`; `κ = 1` for a point-spread function that is
//! exactly this Gaussian lens. The closed form is 6-15 % above the shift of a measured
//! point-spread function with apodization (`bench/independent_us/psf_phase.py`), and the fat's
//! bulk modulus reacts strongly to the lateral field, so by default [`ShiftScale::Fitted`]: the
//! identification estimates `κ` with the material parameters (variable projection,
//! [`crate::fit::Problem::with_speckle_shift`]), and the intervals carry its uncertainty.

use serde::Serialize;

/// How the shift's scale `κ` is set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum ShiftScale {
    /// Estimated from the field with the parameters: a nuisance parameter, profiled out of the
    /// least-squares problem (its uncertainty in the parameters' intervals).
    Fitted,
    /// Held at the given value (1: the closed form as it is).
    Fixed(f64),
}

/// The imaging of a measured field's frames, for the speckle's shift under shear.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SpeckleShift {
    /// Centre frequency of the echo (MHz).
    pub frequency_mhz: f64,
    /// Lateral resolution: FWHM of the point-spread function's lateral amplitude (mm).
    pub resolution_mm: f64,
    /// Speed of sound (m/s).
    pub sound_speed_m_s: f64,
    /// A point of the probe face (model frame, mm): depth is measured from it along `axial`.
    pub face: [f64; 2],
    /// Unit model directions of the image's lateral (+x, across the beam) and axial (+y, into
    /// the tissue) axes.
    pub lateral: [f64; 2],
    pub axial: [f64; 2],
    pub scale: ShiftScale,
}

impl SpeckleShift {
    /// `c(z)`: the speckle's lateral shift per unit shear at depth `depth_mm` below the face
    /// (mm); 0 at and above the face.
    pub fn per_shear(&self, depth_mm: f64) -> f64 {
        if !(depth_mm > 0.0) {
            return 0.0;
        }
        let k =
            2.0 * std::f64::consts::PI * self.frequency_mhz * 1e6 / (self.sound_speed_m_s * 1e3);
        let k2 = 2.0 * k;
        let alpha = -k / (2.0 * depth_mm);
        let sigma = self.resolution_mm / (2.0 * (2.0 * std::f64::consts::LN_2).sqrt());
        k2 * (-alpha) / (2.0 * (alpha * alpha + 1.0 / (4.0 * sigma.powi(4))))
    }

    /// The depth of the model point `x` below the face (mm).
    pub fn depth(&self, x: [f64; 2]) -> f64 {
        (x[0] - self.face[0]) * self.axial[0] + (x[1] - self.face[1]) * self.axial[1]
    }

    /// Checks the numbers (finite, positive) and the axes (unit, perpendicular).
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [
            ("frequency", self.frequency_mhz),
            ("lateral resolution", self.resolution_mm),
            ("sound speed", self.sound_speed_m_s),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(format!(
                    "the speckle shift's {name} must be positive, got {v}"
                ));
            }
        }
        let unit = |a: [f64; 2]| ((a[0] * a[0] + a[1] * a[1]).sqrt() - 1.0).abs() < 1e-6;
        let dot = self.lateral[0] * self.axial[0] + self.lateral[1] * self.axial[1];
        if !(unit(self.lateral) && unit(self.axial) && dot.abs() < 1e-6) {
            return Err(format!(
                "the image axes {:?}, {:?} are not perpendicular unit vectors",
                self.lateral, self.axial
            ));
        }
        if let ShiftScale::Fixed(k) = self.scale {
            if !k.is_finite() {
                return Err(format!("the speckle shift's scale must be finite, got {k}"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed form at the pymust Hann frames' settings (9 MHz, FWHM 0.907 mm) against
    /// `psf_phase.closed_form_shift` written out (under g = 0.05: 2.71, 2.29, 1.38 px of
    /// 0.1 mm at 5, 10 and 20 mm), and no shift at or above the face.
    #[test]
    fn closed_form_matches_the_lens_formula() {
        let s = SpeckleShift {
            frequency_mhz: 9.0,
            resolution_mm: 0.907,
            sound_speed_m_s: 1540.0,
            face: [0.0, 0.0],
            lateral: [1.0, 0.0],
            axial: [0.0, -1.0],
            scale: ShiftScale::Fitted,
        };
        let k = 2.0 * std::f64::consts::PI * 9e6 / 1.54e6;
        let sigma = 0.907 / (2.0 * (2.0 * 2f64.ln()).sqrt());
        for z in [5.0, 10.0, 20.0] {
            let alpha = -k / (2.0 * z);
            let beta = -2.0 * k * 0.05;
            let want = beta * alpha / (2.0 * (alpha * alpha + 1.0 / (4.0 * sigma.powi(4))));
            let got = 0.05 * s.per_shear(z);
            assert!(
                (got - want).abs() < 1e-12 * want.abs(),
                "{z}: {got} vs {want}"
            );
            assert!(got > 0.0);
        }
        assert!((0.05 * s.per_shear(10.0) / 0.1 - 2.2885).abs() < 1e-3);
        assert_eq!(s.per_shear(0.0), 0.0);
        assert_eq!(s.per_shear(-1.0), 0.0);
        assert!((s.depth([3.0, -7.5]) - 7.5).abs() < 1e-15);
        assert!(s.check().is_ok());
        let bad = SpeckleShift {
            axial: [0.0, -0.5],
            ..s
        };
        assert!(bad.check().unwrap_err().contains("unit"));
    }
}
