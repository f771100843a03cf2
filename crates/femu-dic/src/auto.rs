//! Options chosen from the images: what `femu dic` does when the user does not set the element
//! size or the regularization length.
//!
//! The statistics come from the images themselves:
//! - the **speckle size**: full width at half maximum of the normalized autocorrelation of the
//!   reference over the ROI, along x and y (B-mode speckle is longer laterally than axially);
//! - the **texture per element**: the eigenvalues of the mean structure tensor `⟨∇f ∇fᵀ⟩` of
//!   each element; their ratio (small / large) measures how one-directional the texture is
//!   (muscle fibres and fascia are lines: displacement along them is poorly determined, the
//!   aperture problem);
//! - the **grey-level noise of the pair**: the residual of the first correlation, per image
//!   (`RMS / √2`, both images being noisy).
//!
//! Choice. The element size is the smallest multiple of 4 px, at least 16, whose area holds
//! [`SPECKLES_PER_ELEMENT`] speckle cells `FWHM_x × FWHM_y` (an element must see more than one
//! independent speckle; B-mode speckle is some 25–31 x 4 px on the Logiq E9 frames, so
//! 16 px). The regularization length is the first rung of the ladder `off, 4h, 8h, 16h` (at
//! most the ROI's longer side) whose correlation converges with at least half of the elements
//! trusted (a rung whose accelerated iterations stall close to convergence is correlated again
//! with plain steps first, [`STALLED_INCREMENT_PX`]); when the median texture ratio is below [`LINE_TEXTURE`] (line-like texture, which
//! needs the support of more neighbours: muscle fibres, fascia) the ladder starts at `4h`,
//! without the unregularized rung. A longer regularization is a bias, not only a smoothing: on
//! simulated B-mode sequences of a compressed thigh (`bench/independent_us`), `8h` instead of `4h`
//! doubled the composed field's lateral error against the true field and biased the identified
//! compressibility of the muscle by 10–55 %. If no rung converges the element size is doubled once and the ladder walked
//! again. A rung that fails with the images not matching even on the coarsest pyramid level
//! ([`MIN_COARSE_MATCH`]) ends the ladder: images of different scenes do not correlate with any
//! option. When everything fails the error names what was tried and what to try next.

use crate::error::DicError;
use crate::image::GreyImage;
use crate::mesh::{Rect, Roi};
use crate::quality::{self, NodalCovariance, Trust, TrustCriteria};
use crate::solver::{correlate, DicOptions, DicResult};

/// Median texture ratio (small / large structure-tensor eigenvalue) below which the texture
/// counts as line-like.
pub const LINE_TEXTURE: f64 = 0.25;

/// Speckle cells (FWHM_x x FWHM_y) an element holds at least.
pub const SPECKLES_PER_ELEMENT: f64 = 2.0;

/// Minimum share of trusted elements for a rung to be accepted.
pub const MIN_TRUSTED: f64 = 0.5;

/// The match on the coarsest pyramid level ([`coarse_match`]) below which a rung that failed
/// ends the ladder: the images do not show the same scene. Measured: 0.96-0.99 between frames
/// 2 and 4 video frames apart of the Logiq E9 gastrocnemius sequence (ROI 110,60,580x460), 0.00
/// between independent speckle images and between unrelated B-mode and DIC Challenge frames.
pub const MIN_COARSE_MATCH: f64 = 0.3;

/// How the element size or the regularization length is set.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Setting {
    /// Chosen from the images.
    Auto,
    /// Off (regularization only).
    Off,
    /// Given by the user (pixels).
    Given(f64),
}

/// Statistics of the images that the choice reads.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ImageStatistics {
    /// Speckle size (FWHM of the autocorrelation) along x and y (pixels).
    pub speckle_fwhm_px: [f64; 2],
    /// Median over the element-sized blocks of the reference of the small / large
    /// structure-tensor eigenvalue.
    pub texture_ratio_median: f64,
    /// Median over the blocks of `sqrt(small eigenvalue)` (grey levels per pixel).
    pub texture_gradient_median: f64,
    /// Grey-level noise per image from the pair (residual RMS of the first correlation / √2).
    pub pair_noise_grey: f64,
}

/// One correlation tried.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Attempt {
    pub element_size_px: usize,
    pub regularization_px: Option<f64>,
    pub converged: bool,
    pub iterations: usize,
    pub last_increment_px: f64,
    pub residual_rms: f64,
    /// Share of the elements trusted; NaN (null in JSON) for a rung of the automatic choice
    /// that did not converge (rejected without computing its quality).
    pub trusted_fraction: f64,
    /// 90th percentile of the larger nodal standard deviation (pixels); NaN as above.
    pub sd_p90_px: f64,
    /// Why it failed or was not kept.
    pub note: Option<String>,
    /// Wall time of the correlation (seconds; its quality not included).
    pub correlation_s: f64,
}

/// The choice and how it was reached.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Choice {
    pub statistics: ImageStatistics,
    pub attempts: Vec<Attempt>,
    pub element_size_px: usize,
    pub regularization_px: Option<f64>,
    pub reason: String,
}

/// A correlation with its quality.
pub struct Measured {
    pub res: DicResult,
    pub cov: NodalCovariance,
    pub trust: Vec<Trust>,
}

/// Half-width of the box filter removed before the autocorrelation (pixels).
const DETREND_RADIUS: usize = 8;

/// FWHM of the normalized autocorrelation of the speckle of `img` over `r` along x and y
/// (pixels; twice the lag at which it falls to ½, linearly interpolated; capped at 64 px). The
/// local mean over a `17 x 17` box is removed first, so that fascia and other long structures
/// (and the depth-dependent brightness) do not count as speckle.
pub fn speckle_fwhm(img: &GreyImage, r: &Rect) -> [f64; 2] {
    let (w, h) = (r.w, r.h);
    // Box mean by a summed-area table over the rectangle (clamped at its edges).
    let mut sat = vec![0.0; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            sat[(y + 1) * (w + 1) + x + 1] =
                img.at(r.x + x, r.y + y) + sat[y * (w + 1) + x + 1] + sat[(y + 1) * (w + 1) + x]
                    - sat[y * (w + 1) + x];
        }
    }
    let d = DETREND_RADIUS;
    let hp: Vec<f64> = (0..w * h)
        .map(|k| {
            let (x, y) = (k % w, k / w);
            let (x0, x1, y0, y1) = (
                x.saturating_sub(d),
                (x + d + 1).min(w),
                y.saturating_sub(d),
                (y + d + 1).min(h),
            );
            let s = sat[y1 * (w + 1) + x1] - sat[y0 * (w + 1) + x1] - sat[y1 * (w + 1) + x0]
                + sat[y0 * (w + 1) + x0];
            img.at(r.x + x, r.y + y) - s / ((x1 - x0) * (y1 - y0)) as f64
        })
        .collect();
    let rho = |dx: usize, dy: usize| {
        let (mut s, mut s0) = (0.0, 0.0);
        for y in 0..h - dy {
            for x in 0..w - dx {
                let a = hp[y * w + x];
                s += a * hp[(y + dy) * w + x + dx];
                s0 += a * a;
            }
        }
        if s0 > 0.0 {
            s / s0
        } else {
            0.0
        }
    };
    let half = |axis: usize| {
        let mut prev = 1.0;
        for k in 1..=32usize.min(if axis == 0 { w } else { h } - 1) {
            let v = if axis == 0 { rho(k, 0) } else { rho(0, k) };
            if v <= 0.5 {
                return 2.0 * ((k - 1) as f64 + (prev - 0.5) / (prev - v));
            }
            prev = v;
        }
        64.0
    };
    [half(0), half(1)]
}

/// Median over the `h x h` blocks of `r` of the structure-tensor eigenvalues of the reference
/// (central differences): `(median of small / large, median of sqrt(small))`.
pub fn texture(img: &GreyImage, r: &Rect, h: usize) -> (f64, f64) {
    let mut ratio = Vec::new();
    let mut small = Vec::new();
    for by in 0..r.h / h {
        for bx in 0..r.w / h {
            let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
            for y in r.y + by * h..r.y + (by + 1) * h {
                for x in r.x + bx * h..r.x + (bx + 1) * h {
                    let gx = 0.5
                        * (img.at((x + 1).min(img.width - 1), y) - img.at(x.saturating_sub(1), y));
                    let gy = 0.5
                        * (img.at(x, (y + 1).min(img.height - 1)) - img.at(x, y.saturating_sub(1)));
                    sxx += gx * gx;
                    syy += gy * gy;
                    sxy += gx * gy;
                }
            }
            let n = (h * h) as f64;
            let (sxx, syy, sxy) = (sxx / n, syy / n, sxy / n);
            let half = 0.5 * (sxx + syy);
            let disc = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
            let (lo, hi) = ((half - disc).max(0.0), half + disc);
            ratio.push(if hi > 0.0 { lo / hi } else { 0.0 });
            small.push(lo.sqrt());
        }
    }
    (median(ratio), median(small))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The nodal covariance and the trust of the elements of a correlation.
fn quality_of(
    res: &DicResult,
    criteria: &TrustCriteria,
) -> Result<(NodalCovariance, Vec<Trust>), DicError> {
    let cov = quality::covariance(res)?;
    let trust = quality::element_trust(res, &cov, criteria);
    Ok((cov, trust))
}

/// The attempt of a correlation, with its quality when it was computed (else no trusted
/// fraction and no standard deviation: NaN).
fn attempt_of(
    res: &DicResult,
    quality: Option<&(NodalCovariance, Vec<Trust>)>,
    opts: &DicOptions,
) -> Attempt {
    let (trusted_fraction, sd_p90_px) = match quality {
        None => (f64::NAN, f64::NAN),
        Some((cov, trust)) => {
            let trusted = trust.iter().filter(|&&t| t == Trust::Trusted).count();
            let mut sd: Vec<f64> = cov
                .node
                .iter()
                .map(|n| n.sd_ux_px.max(n.sd_uy_px))
                .collect();
            sd.sort_by(|a, b| a.total_cmp(b));
            (
                trusted as f64 / trust.len().max(1) as f64,
                sd.get(sd.len() * 9 / 10).copied().unwrap_or(f64::NAN),
            )
        }
    };
    Attempt {
        element_size_px: opts.element_size,
        regularization_px: opts.regularization_length,
        converged: res.converged,
        iterations: res.iterations,
        last_increment_px: res.last_increment_px,
        residual_rms: res.residual_rms,
        trusted_fraction,
        sd_p90_px,
        note: None,
        correlation_s: res.timings.total_s,
    }
}

/// The match of the images on the coarsest pyramid level a correlation solved: its level and
/// `sqrt(1 − (r / s)²)`, with `r` the level's grey-level residual RMS (after the brightness
/// correction) and `s` the reference's grey-level standard deviation over the region at that
/// level — the ZNCC of the two images for a least-squares brightness fit: about 0 for images
/// that show different scenes, whatever the regularization or the element size.
pub fn coarse_match(f: &GreyImage, bb: &Rect, res: &DicResult) -> Option<(usize, f64)> {
    let lv = res
        .levels
        .iter()
        .filter(|l| l.level > 0 && l.skipped.is_none() && l.residual_rms.is_finite())
        .max_by_key(|l| l.level)?;
    let mut img = f.half();
    for _ in 1..lv.level {
        img = img.half();
    }
    let s = 1usize << lv.level;
    let (x0, y0) = (
        (bb.x / s).min(img.width - 1),
        (bb.y / s).min(img.height - 1),
    );
    let (x1, y1) = (
        ((bb.x + bb.w) / s).clamp(x0 + 1, img.width),
        ((bb.y + bb.h) / s).clamp(y0 + 1, img.height),
    );
    let (mut sum, mut sum2, mut n) = (0.0, 0.0, 0.0);
    for y in y0..y1 {
        for x in x0..x1 {
            let v = img.at(x, y);
            sum += v;
            sum2 += v * v;
            n += 1.0;
        }
    }
    let var = (sum2 / n - (sum / n).powi(2)).max(0.0);
    if !(var > 0.0) {
        return None;
    }
    let ratio = lv.residual_rms / var.sqrt();
    Some((lv.level, (1.0 - ratio * ratio).max(0.0).sqrt()))
}

/// Correlates `f` → `g` with the element size and regularization length chosen as the module
/// documentation says (or as given), returning the field with its quality and the choice.
pub fn correlate_auto(
    f: &GreyImage,
    g: &GreyImage,
    roi: &Roi,
    base: &DicOptions,
    element: Setting,
    regularization: Setting,
    criteria: &TrustCriteria,
) -> Result<(Measured, Choice), DicError> {
    correlate_ladder(f, g, roi, base, element, regularization, criteria, true)
}

/// [`correlate_auto`], with `stop_on_mismatch` false for frames known to show the same
/// tissue (consecutive frames of a sequence): there a rung whose correlation ends far from the
/// match on the coarsest level failed, it does not prove different scenes, and the longer
/// regularizations and larger elements of the ladder are still tried.
///
/// When no rung succeeds with Anderson acceleration (`base.acceleration_depth > 0`), the ladder
/// is run again with plain modified Gauss–Newton steps and [`PLAIN_ITERATION_FACTOR`] times the
/// iterations: on fine speckle under strain the accelerated steps can cycle a few hundredths of
/// a pixel from the fixed point that the plain iteration reaches, slowly (femu's own B-mode
/// frames of a compression: 126 plain iterations where the accelerated ones stalled at
/// 0.04 px).
#[allow(clippy::too_many_arguments)]
pub fn correlate_ladder(
    f: &GreyImage,
    g: &GreyImage,
    roi: &Roi,
    base: &DicOptions,
    element: Setting,
    regularization: Setting,
    criteria: &TrustCriteria,
    stop_on_mismatch: bool,
) -> Result<(Measured, Choice), DicError> {
    let run = |opts: &DicOptions| {
        ladder(
            f,
            g,
            roi,
            opts,
            element,
            regularization,
            criteria,
            stop_on_mismatch,
        )
    };
    let (first_error, accelerated_attempts) = match run(base) {
        Ok(r) => return Ok(r),
        Err(LadderFailure {
            error,
            attempts: Some(attempts),
        }) if base.acceleration_depth > 0 => (error, attempts),
        Err(LadderFailure { error, .. }) => return Err(error),
    };
    let plain = DicOptions {
        acceleration_depth: 0,
        max_iterations: PLAIN_ITERATION_FACTOR * base.max_iterations,
        ..base.clone()
    };
    match run(&plain) {
        Ok((m, mut c)) => {
            let mut attempts = accelerated_attempts;
            attempts.append(&mut c.attempts);
            c.attempts = attempts;
            c.reason = format!(
                "{}; with plain Gauss-Newton steps ({} iterations at most): no rung converged with Anderson acceleration",
                c.reason, plain.max_iterations
            );
            Ok((m, c))
        }
        Err(LadderFailure {
            attempts: Some(_), ..
        }) => Err(match first_error {
            DicError::Diverged(m) => DicError::Diverged(format!(
                "{m} (tried with Anderson acceleration, then again with plain Gauss-Newton steps)"
            )),
            e => e,
        }),
        Err(LadderFailure { error, .. }) => Err(error),
    }
}

/// How many times the iterations of an accelerated rung a plain one gets ([`correlate_ladder`]).
pub const PLAIN_ITERATION_FACTOR: usize = 3;

/// A rung whose accelerated iterations end without converging but with a last increment below
/// this (pixels) is correlated again with plain Gauss–Newton steps ([`PLAIN_ITERATION_FACTOR`]
/// times the iterations) before the ladder moves on. Anderson acceleration can cycle a few
/// hundredths of a pixel from a fixed point that the plain iteration reaches: on simulated
/// B-mode sequences of a compressed thigh (`bench/independent_us`) the `4h` rung of the first
/// pair stalled at 0.008–0.05 px on half of the sequences, the ladder then kept `8h` or `16h`,
/// and the longer regularization biased the identified compressibility of the muscle.
pub const STALLED_INCREMENT_PX: f64 = 0.1;

/// One pass of the ladder of [`correlate_ladder`] with `base`'s options; a ladder whose every
/// rung failed returns a [`LadderFailure`] with its attempts.
#[allow(clippy::too_many_arguments)]
fn ladder(
    f: &GreyImage,
    g: &GreyImage,
    roi: &Roi,
    base: &DicOptions,
    element: Setting,
    regularization: Setting,
    criteria: &TrustCriteria,
    stop_on_mismatch: bool,
) -> Result<(Measured, Choice), LadderFailure> {
    let fatal = |e: DicError| LadderFailure {
        error: e,
        attempts: None,
    };
    let bb = roi.bounding_box(f.width, f.height).map_err(fatal)?;
    let fwhm = speckle_fwhm(f, &bb);
    // An explicit element size is used as given (the mesh reports a size that does not fit);
    // the automatic one is kept within half the ROI.
    let h0 = match element {
        Setting::Given(h) => h as usize,
        _ => ((16.0f64.max((SPECKLES_PER_ELEMENT * fwhm[0] * fwhm[1]).sqrt()) / 4.0).ceil()
            as usize
            * 4)
        .min(bb.w.min(bb.h) / 2)
        .max(4),
    };
    // Element size and ROI errors (an element larger than the ROI, an empty mask) at once.
    crate::mesh::DicMesh::new(roi, f.width, f.height, h0).map_err(fatal)?;
    // Options out of their range (tolerance, iterations, flag factor, levels, a given
    // regularization shorter than two elements) would fail every rung alike: refused once,
    // before the ladder.
    DicOptions {
        element_size: h0,
        regularization_length: match regularization {
            Setting::Given(l) => Some(l),
            _ => None,
        },
        ..base.clone()
    }
    .validate()
    .map_err(fatal)?;
    let (ratio, gradient) = texture(f, &bb, h0);
    let mut stats = ImageStatistics {
        speckle_fwhm_px: fwhm,
        texture_ratio_median: ratio,
        texture_gradient_median: gradient,
        pair_noise_grey: f64::NAN,
    };
    let mut attempts = Vec::new();
    let sizes: Vec<usize> = match element {
        Setting::Given(_) => vec![h0],
        _ => vec![h0, 2 * h0],
    };
    let longest = bb.w.max(bb.h) as f64;
    for &h in &sizes {
        let ladder: Vec<Option<f64>> = match regularization {
            Setting::Off => vec![None],
            Setting::Given(l) => vec![Some(l)],
            Setting::Auto => {
                // Isotropic texture: first without regularization (full resolution); line-like
                // texture needs the support of neighbours along the lines, so it starts at 4h.
                let line_like = stats.texture_ratio_median < LINE_TEXTURE;
                let off = (!line_like).then_some(None);
                off.into_iter()
                    .chain(
                        [4.0, 8.0, 16.0]
                            .iter()
                            .map(|k| Some((k * h as f64).min(longest).max(2.0 * h as f64))),
                    )
                    .collect()
            }
        };
        let mut k = 0;
        while k < ladder.len() {
            let opts = DicOptions {
                element_size: h,
                regularization_length: ladder[k],
                ..base.clone()
            };
            // Options given in full: the result is returned whatever it is (the caller writes
            // it and reports a non-convergence with [`advice`]).
            let forced = element != Setting::Auto && regularization != Setting::Auto;
            let started = std::time::Instant::now();
            let failed = |e: DicError| Attempt {
                element_size_px: h,
                regularization_px: ladder[k],
                converged: false,
                iterations: 0,
                last_increment_px: f64::NAN,
                residual_rms: f64::NAN,
                trusted_fraction: 0.0,
                sd_p90_px: f64::NAN,
                note: Some(e.to_string()),
                correlation_s: started.elapsed().as_secs_f64(),
            };
            let is_fatal = |e: &DicError| {
                matches!(
                    e,
                    DicError::Roi(_) | DicError::SizeMismatch { .. } | DicError::Interrupted(_)
                )
            };
            let mut opts = opts;
            let mut correlated = if forced {
                correlate(f, g, roi, &opts)
            } else {
                crate::solver::correlate_rung(f, g, roi, &opts)
            };
            // Accelerated steps that stalled close to the fixed point: the same rung again with
            // plain steps, before a longer regularization (a bias) or a larger element is tried.
            if let Some(res) = correlated.as_ref().ok().filter(|res| {
                !forced
                    && !res.converged
                    && opts.acceleration_depth > 0
                    && res.last_increment_px < STALLED_INCREMENT_PX
            }) {
                let mut stalled = attempt_of(res, None, &opts);
                stalled.note = Some(format!(
                    "stalled {:.3} px from convergence with Anderson acceleration; the same rung again with plain Gauss-Newton steps",
                    res.last_increment_px
                ));
                attempts.push(stalled);
                opts = DicOptions {
                    acceleration_depth: 0,
                    max_iterations: PLAIN_ITERATION_FACTOR * opts.max_iterations,
                    ..opts
                };
                correlated = crate::solver::correlate_rung(f, g, roi, &opts);
            }
            let res = match correlated {
                Ok(res) => res,
                Err(e) if is_fatal(&e) => return Err(fatal(e)),
                Err(e) => {
                    attempts.push(failed(e));
                    k += 1;
                    continue;
                }
            };
            // A rung that did not converge is rejected whatever its quality: the covariance
            // and the trust (the costliest part of a rung after the iterations) are computed
            // only for a field that may be kept; such a rung's attempt has no trusted fraction
            // and no standard deviation.
            let quality = if forced || res.converged {
                match quality_of(&res, criteria) {
                    Ok(q) => Some(q),
                    Err(e) if is_fatal(&e) => return Err(fatal(e)),
                    Err(e) => {
                        attempts.push(failed(e));
                        k += 1;
                        continue;
                    }
                }
            } else {
                None
            };
            if stats.pair_noise_grey.is_nan() {
                stats.pair_noise_grey = res.residual_rms / std::f64::consts::SQRT_2;
            }
            let mut a = attempt_of(&res, quality.as_ref(), &opts);
            let ok = forced || (a.converged && a.trusted_fraction >= MIN_TRUSTED);
            if !a.converged {
                a.note = Some("not converged".into());
            } else if !ok {
                a.note = Some(format!(
                    "only {:.0} % of the elements trusted",
                    100.0 * a.trusted_fraction
                ));
            }
            // Frames that do not match even on the coarsest level (different scenes, or a
            // motion far beyond the capture range): no longer regularization or larger element
            // makes them correlate; the ladder stops here instead of trying every rung.
            let mismatch = (!ok && stop_on_mismatch)
                .then(|| coarse_match(f, &bb, &res))
                .flatten()
                .filter(|&(_, z)| z < MIN_COARSE_MATCH);
            if let Some((level, z)) = mismatch {
                a.note = Some(format!(
                    "{}; the images do not match on the coarsest level (1/{} resolution, ZNCC {z:.2} < {MIN_COARSE_MATCH})",
                    a.note.take().unwrap_or_else(|| "rejected".into()),
                    1usize << level
                ));
                attempts.push(a);
                return Err(fatal(DicError::Diverged(format!(
                    "the images do not correlate: on the coarsest pyramid level (1/{} resolution) they match with a ZNCC of {z:.2} (< {MIN_COARSE_MATCH}) after the correlation (element {h} px, regularization {}); they may not show the same scene, or move farther than the correlation can follow. The rest of the ladder (longer regularizations, larger elements) was not tried",
                    1usize << level,
                    ladder[k].map_or("off".to_string(), |l| format!("{l} px")),
                ))));
            }
            attempts.push(a);
            if ok {
                let reason = match (element, regularization) {
                    (Setting::Given(_), Setting::Given(_) | Setting::Off) => {
                        "as given".to_string()
                    }
                    _ => format!(
                        "the first rung of the ladder (element {h} px, regularization {}) that converged with at least {:.0} % of the elements trusted; speckle FWHM {:.1} x {:.1} px, texture ratio {:.2} ({})",
                        ladder[k].map_or("off".to_string(), |l| format!("{l} px")),
                        100.0 * MIN_TRUSTED,
                        fwhm[0],
                        fwhm[1],
                        stats.texture_ratio_median,
                        if stats.texture_ratio_median < LINE_TEXTURE {
                            "line-like: ladder from 4 elements"
                        } else {
                            "ladder from no regularization"
                        }
                    ),
                };
                let choice = Choice {
                    statistics: stats,
                    attempts,
                    element_size_px: h,
                    regularization_px: ladder[k],
                    reason,
                };
                let (cov, trust) = quality.expect("a kept rung is forced or converged");
                return Ok((Measured { res, cov, trust }, choice));
            }
            k += 1;
        }
    }
    Err(LadderFailure {
        error: DicError::Diverged(failure_advice(f, &bb, &attempts, sizes[0])),
        attempts: Some(attempts),
    })
}

/// Why a ladder returned no field: the error, and the attempts when every rung was tried and
/// failed (another pass may succeed); `None` when nothing more is worth trying.
struct LadderFailure {
    error: DicError,
    attempts: Option<Vec<Attempt>>,
}

/// What failed, for [`suggestions`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// A correlation with the element size and regularization given did not converge.
    GivenOptions,
    /// No rung of the automatic choice converged with enough elements trusted.
    NothingConverged,
}

/// Every [`Failure`], for a caller (a test) that checks each piece of advice.
pub const FAILURES: [Failure; 2] = [Failure::GivenOptions, Failure::NothingConverged];

/// One thing to try next: what it is, and the options of `femu dic` that do it (none: leave
/// options out).
#[derive(Debug, Clone, PartialEq)]
pub struct Suggestion {
    pub what: &'static str,
    pub args: Vec<String>,
}

/// What to try after `failure` with element `h`: a larger element, a longer regularization,
/// and, when `tissue` (the bright part of the ROI, [`tissue_box`]) is given, a ROI over it.
pub fn suggestions(failure: Failure, h: usize, tissue: Option<Rect>) -> Vec<Suggestion> {
    let (element, length) = match failure {
        Failure::GivenOptions => (2 * h, 16 * h),
        Failure::NothingConverged => (4 * h, 32 * h),
    };
    let mut out = Vec::new();
    if failure == Failure::GivenOptions {
        out.push(Suggestion {
            what: "the automatic choice (no --element, no --regularization)",
            args: Vec::new(),
        });
    }
    out.push(Suggestion {
        what: "a larger element",
        args: vec!["--element".into(), element.to_string()],
    });
    out.push(Suggestion {
        what: "a longer regularization",
        args: vec!["--regularization".into(), length.to_string()],
    });
    if let Some(t) = tissue {
        out.push(Suggestion {
            what: "a smaller ROI away from the dark bands",
            args: vec!["--roi".into(), format!("{},{},{}x{}", t.x, t.y, t.w, t.h)],
        });
    }
    out
}

/// The suggestions as one sentence: `try A (--x 1), B (--y 2); or C (--roi ...)`.
pub fn advice_text(suggestions: &[Suggestion]) -> String {
    let item = |s: &Suggestion| {
        if s.args.is_empty() {
            s.what.to_string()
        } else {
            format!("{} ({})", s.what, s.args.join(" "))
        }
    };
    let (roi, rest): (Vec<&Suggestion>, Vec<&Suggestion>) = suggestions
        .iter()
        .partition(|s| s.args.first().is_some_and(|a| a == "--roi"));
    let mut text = format!(
        "try {}",
        rest.iter().map(|s| item(s)).collect::<Vec<_>>().join(", ")
    );
    for s in roi {
        text.push_str(&format!("; or {}", item(s)));
    }
    text
}

/// The bright part of `bb` when it is smaller than `bb` (a ROI worth suggesting).
fn tissue_hint(f: &GreyImage, bb: &Rect, h: usize) -> Option<Rect> {
    tissue_box(f, bb, h).filter(|t| t != bb)
}

/// What to try when a correlation with element `h` did not converge: a larger element, a
/// longer regularization, a ROI away from the dark bands (computed from the image).
pub fn advice(f: &GreyImage, bb: &Rect, h: usize) -> String {
    advice_text(&suggestions(
        Failure::GivenOptions,
        h,
        tissue_hint(f, bb, h),
    ))
}

/// The error message when nothing converged: what was tried and what to try.
fn failure_advice(f: &GreyImage, bb: &Rect, attempts: &[Attempt], h: usize) -> String {
    let tried: Vec<String> = attempts
        .iter()
        .map(|a| {
            format!(
                "element {} px, regularization {}: {}",
                a.element_size_px,
                a.regularization_px
                    .map_or("off".into(), |l| format!("{l} px")),
                a.note.clone().unwrap_or_else(|| "rejected".into())
            )
        })
        .collect();
    let hint = tissue_hint(f, bb, h);
    let text = advice_text(&suggestions(Failure::NothingConverged, h, hint));
    format!(
        "no correlation converged ({}). {}",
        tried.join("; "),
        capitalized(&text)
    )
}

fn capitalized(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map_or_else(String::new, |f| f.to_uppercase().chain(c).collect())
}

/// The run of rows and of columns of `bb`, around its middle, whose mean grey level exceeds a
/// fifth of the median row/column mean (the dark side bands and bottom of a B-mode frame fall
/// below), shrunk by one element.
pub fn tissue_box(f: &GreyImage, bb: &Rect, h: usize) -> Option<Rect> {
    let col: Vec<f64> = (bb.x..bb.x + bb.w)
        .map(|x| (bb.y..bb.y + bb.h).map(|y| f.at(x, y)).sum::<f64>() / bb.h as f64)
        .collect();
    let row: Vec<f64> = (bb.y..bb.y + bb.h)
        .map(|y| (bb.x..bb.x + bb.w).map(|x| f.at(x, y)).sum::<f64>() / bb.w as f64)
        .collect();
    // The run of bright enough lines around the middle of the ROI.
    let span = |v: &[f64]| {
        let thr = 0.2 * median(v.to_vec());
        let mid = v.len() / 2;
        if !(v[mid] > thr) {
            return None;
        }
        let a = (0..mid).rev().find(|&i| !(v[i] > thr)).map_or(0, |i| i + 1);
        let b = (mid..v.len()).find(|&i| !(v[i] > thr)).unwrap_or(v.len());
        Some((a, b))
    };
    let (x0, x1) = span(&col)?;
    let (y0, y1) = span(&row)?;
    let (x0, x1) = (x0 + h, x1.saturating_sub(h));
    let (y0, y1) = (y0 + h, y1.saturating_sub(h));
    (x1 > x0 + 2 * h && y1 > y0 + 2 * h).then(|| Rect {
        x: bb.x + x0,
        y: bb.y + y0,
        w: x1 - x0,
        h: y1 - y0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lab::{self, Speckle};

    /// The speckle of the virtual lab (Gaussian spots of σ = 2 px): the autocorrelation of a
    /// random sum of spots is the spot's own, `exp(−d²/(4σ²))`, whose FWHM is
    /// `4σ √(ln 2) = 6.66 px` before the detrending. And the automatic choice converges on a translated pair.
    #[test]
    fn speckle_size_and_automatic_choice() {
        let s = Speckle::new(160, 160, 2.0, 8);
        let f = s.reference();
        let r = Rect {
            x: 16,
            y: 16,
            w: 128,
            h: 128,
        };
        let w = speckle_fwhm(&f, &r);
        // Removing the 17 x 17 box mean also removes part of the spot's own low frequencies,
        // which narrows the autocorrelation (measured 5.4-5.5 px): the bound is 0.75-1.05 of
        // the theoretical 6.66 px.
        for v in w {
            assert!((0.75 * 6.66..1.05 * 6.66).contains(&v), "FWHM {w:?}");
        }
        let g = s.deformed(&lab::translation(0.3, 0.1));
        let (m, c) = correlate_auto(
            &f,
            &g,
            &Roi::Rect(r),
            &DicOptions::default(),
            Setting::Auto,
            Setting::Auto,
            &TrustCriteria::default(),
        )
        .unwrap();
        assert!(m.res.converged);
        assert_eq!(c.element_size_px, 16, "sqrt(2) x 5.5 px is below 16: {c:?}");
        assert_eq!(
            c.regularization_px, None,
            "isotropic speckle: no regularization needed {c:?}"
        );
        assert_eq!(c.attempts.len(), 1);
    }
}
