//! The linear probe and its point-spread function.
//!
//! **Geometry.** A linear array of width `W` lies on the skin with its face centred at `c`
//! (model frame, mm) and fires parallel beams along the unit direction `n` (into the tissue).
//! The lateral axis is `t = (−n_y, n_x)` (for a probe on the anterior skin firing along −y,
//! `t = +x`, so the image is not mirrored). Pixel `(i, j)` (column, row; centres at integer
//! coordinates as in `femu_dic::GreyImage`) images the point
//!
//! ```text
//!   X(i, j) = c + l t + d n,    l = (i + ½)/p − W/2   (lateral, mm),   d = (j + ½)/p   (depth, mm)
//! ```
//!
//! with `p` pixels per mm: rows are depth, the probe face is the top edge of the image.
//!
//! **Point-spread function** (pulse-echo, complex baseband). With `c = 1540 m/s` the
//! wavelength is `λ = c / f` (`λ = 1.54 / f[MHz]` mm: 0.171 mm at 9 MHz). A pulse of `N_c`
//! cycles is `N_c λ` long; the echo of a point resolves over half of it (round trip), so the
//! axial full width at half maximum is `FWHM_ax = N_c λ / 2`. The lateral beam width of an
//! aperture focused with f-number `F#` is `FWHM_lat = F# λ` (diffraction limit). Both are
//! Gaussian, `σ = FWHM / (2 √(2 ln 2))`, and the demodulated echo of a scatterer at axial
//! offset `a` and lateral offset `l` from the pixel is
//!
//! ```text
//!   h(a, l) = exp(−a²/2σ_ax²) exp(−l²/2σ_lat²) exp(2 i k a),    k = 2π/λ
//! ```
//!
//! whose phase `2 k a` (round trip) makes the speckle: the envelope `|Σ_s A_s h(x − x_s)|`
//! of many random scatterers per resolution cell is Rayleigh distributed (Goodman, *Speckle
//! phenomena in optics*, 2007; Wagner et al., IEEE Trans. Sonics Ultrason. 30, 1983).

use crate::error::UsError;

/// Speed of sound in soft tissue (mm/µs = km/s), the scanners' calibration value.
pub const SOUND_SPEED_MM_PER_US: f64 = 1.540;

/// `2 √(2 ln 2)`: FWHM of a Gaussian over its standard deviation.
pub const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

/// A linear probe on the skin (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Probe {
    /// Centre of the probe face in the model frame (mm).
    pub centre_mm: [f64; 2],
    /// Unit beam direction (into the tissue) in the model frame.
    pub direction: [f64; 2],
    /// Field of view: width (mm) and depth (mm).
    pub width_mm: f64,
    pub depth_mm: f64,
    /// Pixels per mm of the image.
    pub px_per_mm: f64,
}

impl Probe {
    /// A probe with its ranges checked: width and depth in (0, 200] mm, 1–40 px/mm, a
    /// non-zero direction (normalized here).
    pub fn new(
        centre_mm: [f64; 2],
        direction: [f64; 2],
        width_mm: f64,
        depth_mm: f64,
        px_per_mm: f64,
    ) -> Result<Self, UsError> {
        if !(centre_mm[0].is_finite() && centre_mm[1].is_finite()) {
            return Err(UsError::param("probe centre", "must be finite"));
        }
        let n = direction[0].hypot(direction[1]);
        if !(n > 1e-12 && n.is_finite()) {
            return Err(UsError::param(
                "probe direction",
                format!("{direction:?} is not a direction"),
            ));
        }
        for (name, v, lo, hi) in [
            ("probe width_mm", width_mm, 0.0, 200.0),
            ("probe depth_mm", depth_mm, 0.0, 200.0),
            ("probe px_per_mm", px_per_mm, 1.0, 40.0),
        ] {
            if !(v > lo && v <= hi) {
                return Err(UsError::param(name, format!("{v} is outside ({lo}, {hi}]")));
            }
        }
        let p = Probe {
            centre_mm,
            direction: [direction[0] / n, direction[1] / n],
            width_mm,
            depth_mm,
            px_per_mm,
        };
        let (w, h) = p.size_px();
        if w < 8 || h < 8 || w * h > 16_000_000 {
            return Err(UsError::param(
                "probe",
                format!("{w} x {h} px image: between 8 x 8 and 16 Mpx"),
            ));
        }
        Ok(p)
    }

    /// Image size (columns, rows).
    pub fn size_px(&self) -> (usize, usize) {
        (
            (self.width_mm * self.px_per_mm).round().max(1.0) as usize,
            (self.depth_mm * self.px_per_mm).round().max(1.0) as usize,
        )
    }

    /// The lateral unit vector `t = (−n_y, n_x)`.
    pub fn lateral(&self) -> [f64; 2] {
        [-self.direction[1], self.direction[0]]
    }

    /// Half the imaged width as the image holds it (whole pixels), mm.
    fn half_width(&self) -> f64 {
        0.5 * self.size_px().0 as f64 / self.px_per_mm
    }

    /// Probe coordinates `(lateral, depth)` (mm) of a pixel position.
    pub fn pixel_to_probe(&self, p: [f64; 2]) -> [f64; 2] {
        [
            (p[0] + 0.5) / self.px_per_mm - self.half_width(),
            (p[1] + 0.5) / self.px_per_mm,
        ]
    }

    /// Pixel position of probe coordinates `(lateral, depth)` (mm).
    pub fn probe_to_pixel(&self, q: [f64; 2]) -> [f64; 2] {
        [
            (q[0] + self.half_width()) * self.px_per_mm - 0.5,
            q[1] * self.px_per_mm - 0.5,
        ]
    }

    /// Model point of probe coordinates `(lateral, depth)`.
    pub fn probe_to_model(&self, q: [f64; 2]) -> [f64; 2] {
        let (t, n, c) = (self.lateral(), self.direction, self.centre_mm);
        [
            c[0] + q[0] * t[0] + q[1] * n[0],
            c[1] + q[0] * t[1] + q[1] * n[1],
        ]
    }

    /// Probe coordinates `(lateral, depth)` of a model point.
    pub fn model_to_probe(&self, x: [f64; 2]) -> [f64; 2] {
        let (t, n, c) = (self.lateral(), self.direction, self.centre_mm);
        let d = [x[0] - c[0], x[1] - c[1]];
        [d[0] * t[0] + d[1] * t[1], d[0] * n[0] + d[1] * n[1]]
    }

    /// Model point (mm) of a pixel position.
    pub fn pixel_to_model(&self, p: [f64; 2]) -> [f64; 2] {
        self.probe_to_model(self.pixel_to_probe(p))
    }

    /// Pixel position of a model point.
    pub fn model_to_pixel(&self, x: [f64; 2]) -> [f64; 2] {
        self.probe_to_pixel(self.model_to_probe(x))
    }

    /// A displacement in pixels expressed in the model frame (mm).
    pub fn displacement_to_model(&self, u_px: [f64; 2]) -> [f64; 2] {
        let (t, n) = (self.lateral(), self.direction);
        let s = 1.0 / self.px_per_mm;
        [
            s * (u_px[0] * t[0] + u_px[1] * n[0]),
            s * (u_px[0] * t[1] + u_px[1] * n[1]),
        ]
    }

    /// A model displacement (mm) in image pixels.
    pub fn displacement_to_pixels(&self, u_mm: [f64; 2]) -> [f64; 2] {
        let (t, n) = (self.lateral(), self.direction);
        [
            self.px_per_mm * (u_mm[0] * t[0] + u_mm[1] * t[1]),
            self.px_per_mm * (u_mm[0] * n[0] + u_mm[1] * n[1]),
        ]
    }
}

/// The transducer: centre frequency and the pulse and aperture that set the resolution.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transducer {
    /// Centre frequency (MHz), in [1, 30] (the seed: 9, 11, 13 MHz on an ML6-15 probe).
    pub frequency_mhz: f64,
    /// Cycles in the transmitted pulse, in [1, 10] (2: a broadband imaging pulse).
    pub cycles: f64,
    /// f-number of the focused aperture, in [0.5, 10].
    pub f_number: f64,
}

impl Default for Transducer {
    fn default() -> Self {
        Transducer {
            frequency_mhz: 9.0,
            cycles: 2.0,
            f_number: 3.0,
        }
    }
}

impl Transducer {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), UsError> {
        for (name, v, lo, hi) in [
            ("frequency_mhz", self.frequency_mhz, 1.0, 30.0),
            ("cycles", self.cycles, 1.0, 10.0),
            ("f_number", self.f_number, 0.5, 10.0),
        ] {
            if !(v >= lo && v <= hi) {
                return Err(UsError::param(name, format!("{v} is outside [{lo}, {hi}]")));
            }
        }
        Ok(())
    }

    /// Wavelength `λ = c / f` (mm).
    pub fn wavelength_mm(&self) -> f64 {
        SOUND_SPEED_MM_PER_US / self.frequency_mhz
    }

    /// The Gaussian pulse-echo PSF (module documentation).
    pub fn psf(&self) -> Psf {
        let lambda = self.wavelength_mm();
        let fwhm_axial = self.cycles * lambda / 2.0;
        let fwhm_lateral = self.f_number * lambda;
        Psf {
            sigma_axial_mm: fwhm_axial / FWHM_PER_SIGMA,
            sigma_lateral_mm: fwhm_lateral / FWHM_PER_SIGMA,
            wavenumber_per_mm: 2.0 * std::f64::consts::PI / lambda,
        }
    }
}

/// Gaussian pulse-echo point-spread function (standard deviations, carrier wavenumber).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Psf {
    pub sigma_axial_mm: f64,
    pub sigma_lateral_mm: f64,
    /// `k = 2π / λ` (rad/mm); the echo phase is `2 k a`.
    pub wavenumber_per_mm: f64,
}

impl Psf {
    /// `∫∫ |h|² = π σ_ax σ_lat` (mm²): the energy of one scatterer's echo, which sets the
    /// scatterer amplitude that gives a tissue its mean backscatter level.
    pub fn energy_area_mm2(&self) -> f64 {
        std::f64::consts::PI * self.sigma_axial_mm * self.sigma_lateral_mm
    }
}

/// Places a probe on the skin: along the ray from the centre of the skin nodes towards
/// `outward` (unit vector, e.g. anterior = +y), at the outermost crossing of the skin faces;
/// the beam points back along the ray (into the tissue). `skin` lists the `(element, face)`
/// pairs of the outline.
pub fn probe_on_skin(
    mesh: &femu_mesh::Mesh,
    skin: &[(usize, usize)],
    outward: [f64; 2],
    width_mm: f64,
    depth_mm: f64,
    px_per_mm: f64,
) -> Result<Probe, UsError> {
    if skin.is_empty() {
        return Err(UsError::Geometry(
            "the mesh has no skin surface to place the probe on".into(),
        ));
    }
    let mut c = [0.0, 0.0];
    let mut n = 0.0;
    for &(e, f) in skin {
        for k in mesh.elements[e].face_nodes(f) {
            c[0] += mesh.nodes[k][0];
            c[1] += mesh.nodes[k][1];
            n += 1.0;
        }
    }
    c = [c[0] / n, c[1] / n];
    let len = outward[0].hypot(outward[1]);
    if !(len > 0.0) {
        return Err(UsError::param("probe side", "the direction is zero"));
    }
    let d = [outward[0] / len, outward[1] / len];
    let mut best: Option<f64> = None;
    for &(e, f) in skin {
        let [a, b] = mesh.elements[e].face_nodes(f);
        let (p, q) = (mesh.nodes[a], mesh.nodes[b]);
        let s = [q[0] - p[0], q[1] - p[1]];
        let den = d[0] * s[1] - d[1] * s[0];
        if den.abs() < 1e-300 {
            continue;
        }
        let ap = [p[0] - c[0], p[1] - c[1]];
        let t = (ap[0] * s[1] - ap[1] * s[0]) / den;
        let u = (ap[0] * d[1] - ap[1] * d[0]) / den;
        if t > 0.0 && (0.0..=1.0).contains(&u) {
            best = Some(best.map_or(t, |b: f64| b.max(t)));
        }
    }
    let t = best.ok_or_else(|| {
        UsError::Geometry(format!(
            "no skin face along {d:?} from the section's centre {c:?}"
        ))
    })?;
    Probe::new(
        [c[0] + t * d[0], c[1] + t * d[1]],
        [-d[0], -d[1]],
        width_mm,
        depth_mm,
        px_per_mm,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_model_round_trip_and_orientation() {
        let p = Probe::new([1.0, 60.0], [0.0, -2.0], 40.0, 30.0, 10.0).unwrap();
        assert_eq!(p.size_px(), (400, 300));
        // Probe on the anterior skin firing down: lateral axis +x, rows go down in y.
        assert_eq!(p.lateral(), [1.0, 0.0]);
        let x = p.pixel_to_model([0.0, 0.0]);
        assert!((x[0] - (1.0 - 20.0 + 0.05)).abs() < 1e-12 && (x[1] - (60.0 - 0.05)).abs() < 1e-12);
        let q = p.model_to_pixel([3.3, 41.7]);
        let back = p.pixel_to_model(q);
        assert!((back[0] - 3.3).abs() < 1e-12 && (back[1] - 41.7).abs() < 1e-12);
        let u = p.displacement_to_model(p.displacement_to_pixels([0.3, -0.7]));
        assert!((u[0] - 0.3).abs() < 1e-12 && (u[1] + 0.7).abs() < 1e-12);
        assert!(Probe::new([0.0, 0.0], [0.0, 0.0], 40.0, 30.0, 10.0).is_err());
        assert!(Probe::new([0.0, 0.0], [0.0, 1.0], -4.0, 30.0, 10.0).is_err());
    }

    #[test]
    fn psf_sizes_follow_the_wavelength() {
        let t = Transducer::default();
        let psf = t.psf();
        let lambda = 1.54 / 9.0;
        assert!((psf.sigma_axial_mm * FWHM_PER_SIGMA - lambda).abs() < 1e-12);
        assert!((psf.sigma_lateral_mm * FWHM_PER_SIGMA - 3.0 * lambda).abs() < 1e-12);
        let hi = Transducer {
            frequency_mhz: 13.0,
            ..t
        }
        .psf();
        assert!(hi.sigma_axial_mm < psf.sigma_axial_mm);
        assert!(Transducer {
            frequency_mhz: 0.5,
            ..t
        }
        .validate()
        .is_err());
    }
}
