//! B-mode image formation: echoes → envelope → time-gain compensation → log compression →
//! gain and dynamic range → 8-bit pixels, the chain of a scanner's image (Szabo, *Diagnostic
//! ultrasound imaging: inside out*, 2014, ch. 10).
//!
//! For pixel `P` (lateral `l_P`, depth `d_P`) the demodulated (complex baseband, IQ) echo is
//!
//! ```text
//!   s(P) = Σ_s A_s 10^(−Att(s)/20) h(d_P − d_s, l_P − l_s) + n(P)
//! ```
//!
//! with `h` the Gaussian PSF of [`crate::probe`] (carrier phase `2 k (d_P − d_s)`), `A_s` the
//! scatterer amplitude, `Att(s) = Σ 2 α f Δd` the round-trip attenuation (dB) accumulated
//! along the beam line from the probe face to the scatterer through the tissues it crosses in
//! the **current** configuration (α per tissue in dB/cm/MHz; the bone's 20 dB/cm/MHz makes the
//! shadow below the cortex), and `n` the receiver's electronic noise (complex Gaussian,
//! band-limited by the same Gaussian receive filter, RMS `10^(noise_db/20)`). Amplitudes are
//! normalized so that the tissue's speckle has RMS envelope `10^(echo_db/20)`: for diffuse
//! scatterers of density `ρ`, `E|s|² = ρ E[A²] ∫∫|h|²`, hence `E[A²] = 10^(echo_db/10) /
//! (ρ π σ_ax σ_lat)`; line scatterers (density `ρ_l` per mm) use `ρ_l √π σ_lat` and a
//! specular factor `0.1 + 0.9 |cos θ|⁴` of the angle θ between the interface normal and the
//! beam. Only the pixels within 3.5 σ of a scatterer receive its echo (the Gaussian is below
//! 2e-3 there).
//!
//! Then the envelope `E = |s|` is amplified by the time-gain compensation
//! `TGC(d) = min(2 α_TGC f d, TGC_max)` (dB), which assumes a mean attenuation and is limited
//! like a scanner's sliders, log-compressed, `L = 20 log10(E) + TGC(d)` (dB), and mapped to
//! grey levels by the user's two knobs:
//!
//! ```text
//!   grey = clamp(255 (L + G − L₀) / DR, 0, 255)      G: gain (dB), DR: dynamic range (dB)
//! ```
//!
//! `L₀` is the fixed black level (15 dB by default): raising the gain shifts the histogram up,
//! widening the dynamic range narrows it and darkens it (the gain must follow, as the seed
//! found, §2.2 and Figs. 5–6).

use crate::error::UsError;
use crate::phantom::{Phantom, PhantomState, ScattererKind};
use crate::probe::{Probe, Transducer};
use femu_dic::GreyImage;
use femu_mesh::locate::PointLocator;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rayon::prelude::*;

/// Support of the Gaussian PSF in standard deviations.
const SUPPORT_SIGMAS: f64 = 3.5;

/// The scanner's image settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scanner {
    /// Gain G (dB), in [-20, 100].
    pub gain_db: f64,
    /// Dynamic range DR (dB), in [10, 120].
    pub dynamic_db: f64,
    /// Black level L₀ (dB).
    pub black_level_db: f64,
    /// TGC slope (dB/cm/MHz, one way; the compensation is `2 α_TGC f d`).
    pub tgc_db_per_cm_mhz: f64,
    /// Largest TGC (dB).
    pub tgc_max_db: f64,
    /// RMS of the electronic noise (dB, same scale as the tissue levels); `None`: none.
    pub noise_db: Option<f64>,
}

impl Default for Scanner {
    /// The seed's chosen couple (gain 34 dB, dynamic 42 dB), TGC 0.6 dB/cm/MHz up to 45 dB,
    /// noise at −65 dB.
    fn default() -> Self {
        Scanner {
            gain_db: 34.0,
            dynamic_db: 42.0,
            black_level_db: 15.0,
            tgc_db_per_cm_mhz: 0.6,
            tgc_max_db: 45.0,
            noise_db: Some(-65.0),
        }
    }
}

impl Scanner {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), UsError> {
        let checks = [
            ("gain_db", self.gain_db, -20.0, 100.0),
            ("dynamic_db", self.dynamic_db, 10.0, 120.0),
            ("black_level_db", self.black_level_db, -100.0, 100.0),
            ("tgc_db_per_cm_mhz", self.tgc_db_per_cm_mhz, 0.0, 10.0),
            ("tgc_max_db", self.tgc_max_db, 0.0, 120.0),
            ("noise_db", self.noise_db.unwrap_or(-100.0), -200.0, 40.0),
        ];
        for (name, v, lo, hi) in checks {
            if !(v >= lo && v <= hi) {
                return Err(UsError::param(name, format!("{v} is outside [{lo}, {hi}]")));
            }
        }
        Ok(())
    }

    /// Time-gain compensation at depth `d_mm` (dB).
    pub fn tgc_db(&self, frequency_mhz: f64, d_mm: f64) -> f64 {
        (2.0 * self.tgc_db_per_cm_mhz * frequency_mhz * d_mm.max(0.0) / 10.0).min(self.tgc_max_db)
    }

    /// Grey level (0–255, not rounded) of a compressed level `L` (dB).
    pub fn grey(&self, level_db: f64) -> f64 {
        (255.0 * (level_db + self.gain_db - self.black_level_db) / self.dynamic_db)
            .clamp(0.0, 255.0)
    }
}

/// One simulated frame.
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    /// Envelope `|s|` before TGC and log compression (row-major).
    pub envelope: Vec<f64>,
    /// The displayed 8-bit image (grey levels 0–255, integers).
    pub image: GreyImage,
    /// Tissue index seen at each pixel (`usize::MAX`: no tissue, `usize::MAX − 1`: bone).
    pub tissue: Vec<usize>,
    /// Round-trip attenuation at each pixel (dB).
    pub attenuation_db: Vec<f64>,
    /// Scatterers that contributed.
    pub scatterers: usize,
    pub seconds: f64,
}

/// Pixel marker: no tissue (gel above the skin, or outside the mesh).
pub const NO_TISSUE: usize = usize::MAX;
/// Pixel marker: inside the bone outline.
pub const BONE: usize = usize::MAX - 1;

/// Renders the phantom in `state` as seen by `probe` (see the module documentation).
/// `noise_seed` draws the electronic noise (a new acquisition: a new seed).
pub fn render(
    phantom: &Phantom,
    state: &PhantomState,
    probe: &Probe,
    transducer: &Transducer,
    scanner: &Scanner,
    noise_seed: u64,
) -> Result<Frame, UsError> {
    let t0 = std::time::Instant::now();
    transducer.validate()?;
    scanner.validate()?;
    if state.positions.len() != phantom.scatterers.len() {
        return Err(UsError::param(
            "state",
            format!(
                "{} positions for {} scatterers",
                state.positions.len(),
                phantom.scatterers.len()
            ),
        ));
    }
    let (w, h) = probe.size_px();
    let ppm = probe.px_per_mm;
    let f = transducer.frequency_mhz;
    let psf = transducer.psf();
    let (tissue, attenuation_db) = attenuation_map(phantom, state, probe, f);

    // Scatterer amplitudes and image positions.
    let area_norm = 1.0 / psf.energy_area_mm2().sqrt();
    let line_norm = 1.0 / (std::f64::consts::PI.sqrt() * psf.sigma_lateral_mm).sqrt();
    let beam = probe.direction;
    let sup_ax = SUPPORT_SIGMAS * psf.sigma_axial_mm * ppm;
    let sup_lat = SUPPORT_SIGMAS * psf.sigma_lateral_mm * ppm;
    let mut pts: Vec<(f64, f64, f64)> = phantom
        .scatterers
        .par_iter()
        .zip(state.positions.par_iter())
        .filter_map(|(s, &x)| {
            let p = probe.model_to_pixel(x);
            if p[0] < -sup_lat - 1.0
                || p[0] > w as f64 + sup_lat
                || p[1] < -sup_ax - 1.0
                || p[1] > h as f64 + sup_ax
            {
                return None;
            }
            let level = match s.kind {
                ScattererKind::Tissue(k) => {
                    let t = phantom.acoustics.tissue(k);
                    10f64.powf(t.echo_db / 20.0) * area_norm / t.density_per_mm2.sqrt()
                }
                ScattererKind::Line { normal, echo_db } => {
                    let c = (normal[0] * beam[0] + normal[1] * beam[1]).abs();
                    10f64.powf(echo_db / 20.0) * line_norm
                        / phantom.acoustics.line_density_per_mm.sqrt()
                        * (0.1 + 0.9 * c.powi(4)).sqrt()
                }
            };
            let (i, j) = (
                p[0].round().clamp(0.0, (w - 1) as f64) as usize,
                p[1].round().clamp(0.0, (h - 1) as f64) as usize,
            );
            let att = if p[1] < 0.0 {
                0.0
            } else {
                attenuation_db[j * w + i]
            };
            let a = s.z * level * 10f64.powf(-att / 20.0);
            (a != 0.0).then_some((p[0], p[1], a))
        })
        .collect();
    pts.sort_unstable_by(|a, b| a.1.total_cmp(&b.1));
    let n_used = pts.len();

    // Coherent sum, bands of rows in parallel.
    let two_k = 2.0 * psf.wavenumber_per_mm;
    let inv2_ax = 1.0 / (2.0 * (psf.sigma_axial_mm * ppm).powi(2));
    let inv2_lat = 1.0 / (2.0 * (psf.sigma_lateral_mm * ppm).powi(2));
    let band = 8usize;
    let mut iq = vec![[0.0f64; 2]; w * h];
    iq.par_chunks_mut(band * w)
        .enumerate()
        .for_each(|(b, out)| {
            let r0 = b * band;
            let r1 = r0 + out.len() / w;
            let lo = pts.partition_point(|p| p.1 < r0 as f64 - sup_ax);
            let hi = pts.partition_point(|p| p.1 <= r1 as f64 + sup_ax);
            let mut lat = Vec::new();
            for &(px, py, a) in &pts[lo..hi] {
                let j0 = ((py - sup_ax).ceil().max(r0 as f64)) as usize;
                let j1 = ((py + sup_ax).floor().min((r1 - 1) as f64)) as isize;
                if (j1 as f64) < j0 as f64 {
                    continue;
                }
                let i0 = (px - sup_lat).ceil().max(0.0) as usize;
                let i1 = (px + sup_lat).floor().min((w - 1) as f64);
                if i1 < i0 as f64 {
                    continue;
                }
                let i1 = i1 as usize;
                lat.clear();
                lat.extend((i0..=i1).map(|i| {
                    let dx = i as f64 - px;
                    a * (-dx * dx * inv2_lat).exp()
                }));
                for j in j0..=(j1 as usize) {
                    let dy = j as f64 - py;
                    let g = (-dy * dy * inv2_ax).exp();
                    let phase = two_k * dy / ppm;
                    let (c, s) = (g * phase.cos(), g * phase.sin());
                    let row = &mut out[(j - r0) * w..(j - r0 + 1) * w];
                    for (k, &lv) in lat.iter().enumerate() {
                        let o = &mut row[i0 + k];
                        o[0] += lv * c;
                        o[1] += lv * s;
                    }
                }
            }
        });

    // Electronic noise: white complex Gaussian through the Gaussian receive filter.
    if let Some(noise_db) = scanner.noise_db {
        let noise = filtered_noise(
            w,
            h,
            psf.sigma_lateral_mm * ppm,
            psf.sigma_axial_mm * ppm,
            10f64.powf(noise_db / 20.0),
            noise_seed,
        );
        for (o, n) in iq.iter_mut().zip(noise) {
            o[0] += n[0];
            o[1] += n[1];
        }
    }
    let envelope: Vec<f64> = iq.iter().map(|c| c[0].hypot(c[1])).collect();
    let grey: Vec<f64> = envelope
        .par_iter()
        .enumerate()
        .map(|(k, &e)| {
            let d = ((k / w) as f64 + 0.5) / ppm;
            let level = 20.0 * e.max(1e-30).log10() + scanner.tgc_db(f, d);
            scanner.grey(level).round()
        })
        .collect();
    let image = GreyImage::new(w, h, grey)?;
    Ok(Frame {
        width: w,
        height: h,
        envelope,
        image,
        tissue,
        attenuation_db,
        scatterers: n_used,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Tissue at each pixel (current configuration) and the round-trip attenuation accumulated
/// from the probe face down each beam line (midpoint rule over the pixel rows).
fn attenuation_map(
    phantom: &Phantom,
    state: &PhantomState,
    probe: &Probe,
    f: f64,
) -> (Vec<usize>, Vec<f64>) {
    let (w, h) = probe.size_px();
    let dz_cm = 0.1 / probe.px_per_mm;
    let locator = PointLocator::new(&state.mesh);
    let columns: Vec<(Vec<usize>, Vec<f64>)> = (0..w)
        .into_par_iter()
        .map(|i| {
            // Where this beam line crosses the bone outline (even-odd rule along the line).
            let a = probe.pixel_to_model([i as f64, -0.5]);
            let b = probe.pixel_to_model([i as f64, h as f64 - 0.5]);
            let mut hits: Vec<f64> = phantom
                .bone
                .iter()
                .filter_map(|s| segment_hit(a, b, s[0], s[1]))
                .collect();
            hits.sort_unstable_by(f64::total_cmp);
            let mut tissue = vec![NO_TISSUE; h];
            let mut att = vec![0.0; h];
            let mut acc = 0.0;
            for j in 0..h {
                let t = (j as f64 + 0.5) / h as f64;
                let x = probe.pixel_to_model([i as f64, j as f64]);
                let alpha = match locator.locate(x) {
                    Some(loc) => {
                        let k = phantom.tissue_of_element[loc.element];
                        tissue[j] = k;
                        phantom.acoustics.tissue(k).attenuation_db_per_cm_mhz
                    }
                    None => {
                        if hits.iter().filter(|&&s| s < t).count() % 2 == 1 {
                            tissue[j] = BONE;
                            phantom.acoustics.bone_attenuation_db_per_cm_mhz
                        } else {
                            0.0
                        }
                    }
                };
                let step = 2.0 * alpha * f * dz_cm;
                att[j] = acc + 0.5 * step;
                acc += step;
            }
            (tissue, att)
        })
        .collect();
    let mut tissue = vec![NO_TISSUE; w * h];
    let mut att = vec![0.0; w * h];
    for (i, (tc, ac)) in columns.into_iter().enumerate() {
        for j in 0..h {
            tissue[j * w + i] = tc[j];
            att[j * w + i] = ac[j];
        }
    }
    (tissue, att)
}

/// Parameter `t ∈ [0, 1]` along `a → b` where it crosses the segment `p → q`, if it does.
fn segment_hit(a: [f64; 2], b: [f64; 2], p: [f64; 2], q: [f64; 2]) -> Option<f64> {
    let r = [b[0] - a[0], b[1] - a[1]];
    let s = [q[0] - p[0], q[1] - p[1]];
    let den = r[0] * s[1] - r[1] * s[0];
    if den.abs() < 1e-300 {
        return None;
    }
    let ap = [p[0] - a[0], p[1] - a[1]];
    let t = (ap[0] * s[1] - ap[1] * s[0]) / den;
    let u = (ap[0] * r[1] - ap[1] * r[0]) / den;
    // Half-open on the segment so a line through a shared vertex counts once.
    ((0.0..=1.0).contains(&t) && (0.0..1.0).contains(&u)).then_some(t)
}

/// Complex white Gaussian noise filtered by a separable Gaussian (standard deviations in px),
/// scaled to the RMS magnitude `rms`.
fn filtered_noise(w: usize, h: usize, sx: f64, sy: f64, rms: f64, seed: u64) -> Vec<[f64; 2]> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut v: Vec<[f64; 2]> = (0..w * h)
        .map(|_| [rng.sample(StandardNormal), rng.sample(StandardNormal)])
        .collect();
    let kernel = |s: f64| -> Vec<f64> {
        let r = (SUPPORT_SIGMAS * s).ceil().max(1.0) as isize;
        (-r..=r)
            .map(|k| (-(k as f64).powi(2) / (2.0 * s * s)).exp())
            .collect()
    };
    let (kx, ky) = (kernel(sx.max(0.3)), kernel(sy.max(0.3)));
    let conv =
        |src: &[[f64; 2]], n: usize, stride: usize, count: usize, cstride: usize, k: &[f64]| {
            let r = (k.len() / 2) as isize;
            let mut out = vec![[0.0; 2]; src.len()];
            for c in 0..count {
                for i in 0..n as isize {
                    let mut acc = [0.0; 2];
                    for (m, &kv) in k.iter().enumerate() {
                        let j = i + m as isize - r;
                        if j >= 0 && j < n as isize {
                            let s = src[c * cstride + j as usize * stride];
                            acc[0] += kv * s[0];
                            acc[1] += kv * s[1];
                        }
                    }
                    out[c * cstride + i as usize * stride] = acc;
                }
            }
            out
        };
    v = conv(&v, w, 1, h, w, &kx);
    v = conv(&v, h, w, w, 1, &ky);
    // White noise of variance 2 (two components) through k: variance 2 Σkx² Σky².
    let gain: f64 = kx.iter().map(|k| k * k).sum::<f64>() * ky.iter().map(|k| k * k).sum::<f64>();
    let scale = rms / (2.0 * gain).sqrt();
    for c in v.iter_mut() {
        c[0] *= scale;
        c[1] *= scale;
    }
    v
}
