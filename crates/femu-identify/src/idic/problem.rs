//! The integrated-DIC least-squares problem: grey-level residuals of an image sequence as a
//! function of the material parameters, with the exact Jacobian ([`LeastSquares`]).
//!
//! Frame 0 is the unloaded (reference) image `f`; frame `i ≥ 1` was taken at load step `i`,
//! whose model `models[i − 1]` carries that step's load. A reference pixel `x_p` (in the
//! tissue, see [`super::pixels`]) is the material point `X_p` of the model; at step `i` it is
//! imaged at `x_p + d_i(x_p; θ)`, `d_i = P u_i(X_p; θ)` (`P` the frame's map from mm to pixels,
//! `u_i` the finite-element displacement of step `i`; `d_0 = 0`). A frame pair `(a, b)` gives
//! the residuals
//!
//! ```text
//!   r_p = √w_πb [ g_a(x_p + d_a) − s_πb g_b(x_p + d_b) − o_πb ]                         (1)
//! ```
//!
//! (`g_0 = f`; contrast and offset per brightness band by variable projection, see
//! [`super::brightness`]; `w` the band's weight), and their derivatives along the
//! log-parameters `φ_j = ln θ_j` follow from the exact sensitivities of each step
//! ([`DirectSensitivity`], one back-substitution per parameter):
//!
//! ```text
//!   ∂r_p/∂φ_j = √w [ ∇g_a · ∂d_a/∂φ_j − s ∇g_b · ∂d_b/∂φ_j ] + (projection term),
//!   ∂d_i/∂φ_j = Σ_{m tied in j} θ_m P ∂u_i/∂θ_m                                           (2)
//! ```
//!
//! The pairs are every frame against the reference (`Pairing::Reference`, Leclerc et al.
//! 2009), each frame against the one before it (`Pairing::Consecutive`: both frames warped by
//! the model, small increments of strain decorrelate the speckle less), or both
//! (`Pairing::Both`: the two comparisons of a frame see its renewed scatterers against two
//! different frames, and their errors partly average out), or every frame against every
//! earlier one (`Pairing::All`, the default of a study). Each step is solved
//! from its own last converged state (warm start), the steps in parallel.

use super::brightness::{BandFit, BandSums};
use super::frame::ImageFrame;
use super::pixels::{PixelOptions, PixelSet};
use crate::fit::{Columns, FitError, FreeParameter, LeastSquares};
use femu_dic::bspline::BSpline;
use femu_dic::GreyImage;
use femu_mech::sensitivity::{DirectSensitivity, Parameter};
use femu_mech::{Model, SolverOptions, StaticSolver};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Most free parameters (directions) a Jacobian evaluation handles: 32 (five tissues of a
/// three-parameter law, tied or not, is 15).
pub const MAX_DIRECTIONS: usize = 32;

/// Pixels whose displaced position comes closer than this to an image edge (px) are left out
/// (see [`IdicProblem::freeze_mask`]): 8 px leaves the B-spline's 2-px support and 6 px of
/// motion during one minimization.
pub const FROZEN_MARGIN_PX: f64 = 8.0;

/// Which frames are compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pairing {
    /// Every loaded frame against the unloaded one: pairs `(0, i)`.
    Reference,
    /// Each frame against the previous one: pairs `(i − 1, i)`.
    Consecutive,
    /// Both: `(i − 1, i)` for every frame and `(0, i)` for the frames after the first loaded one.
    Both,
    /// Every frame against every earlier one: pairs `(a, b)`, `a < b` — more comparisons of
    /// each frame's renewed scatterers against different frames (the guide's integrated-DIC
    /// page, docs/guide/src/explanation/idic.md).
    All,
}

impl Pairing {
    /// The names a study or a command line gives (`[identification] image_pairing`).
    pub const NAMES: &'static str = "all, both, consecutive, reference";
}

impl std::str::FromStr for Pairing {
    type Err = String;

    /// `"all" | "both" | "consecutive" | "reference"`.
    fn from_str(name: &str) -> Result<Pairing, String> {
        match name {
            "all" => Ok(Pairing::All),
            "both" => Ok(Pairing::Both),
            "consecutive" => Ok(Pairing::Consecutive),
            "reference" => Ok(Pairing::Reference),
            other => Err(format!("unknown choice '{other}' ({})", Pairing::NAMES)),
        }
    }
}

/// How the grey levels are compared.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct IdicOptions {
    pub pairing: Pairing,
    /// Contrast and offset per band and pair (variable projection); `false`: grey levels
    /// conserved.
    pub brightness: bool,
    pub pixels: PixelOptions,
    /// The forward solves' Newton settings.
    pub solver: SolverOptions,
    /// Window (px, a Gaussian's standard deviation) of the local normalization of every frame
    /// after its smoothing (`GreyImage::locally_normalized`): the frames are compared as their
    /// local patterns, not their local brightness. `None`: as recorded. The echo of an
    /// interface (skin, fascia) whose scatterers are renewed between load steps changes its
    /// brightness along the line, which a warp would otherwise follow by moving the line
    /// (the guide's integrated-DIC page, docs/guide/src/explanation/idic.md).
    #[serde(default)]
    pub local_normalization_px: Option<f64>,
}

impl Default for IdicOptions {
    fn default() -> Self {
        IdicOptions {
            pairing: Pairing::Reference,
            brightness: true,
            pixels: PixelOptions::default(),
            solver: SolverOptions::default(),
            local_normalization_px: None,
        }
    }
}

/// One load step: its model (with that step's load), solver and last state.
struct Step {
    model: Model,
    solver: StaticSolver,
    sensitivity: DirectSensitivity,
    /// Last converged state (warm start of the next solve).
    state: Option<Vec<f64>>,
    /// `∂state/∂θ_m` for every member parameter, of the last Jacobian evaluation.
    dstate: Vec<Vec<f64>>,
}

/// One load step solved on a refined mesh, at the problem's pixels (px; `None` where that
/// mesh does not cover a pixel).
struct RefinedStep {
    displacement: Vec<Option<[f64; 2]>>,
    /// Per free parameter, `∂d/∂ln θ_j` (empty unless asked for).
    sensitivity: Vec<Vec<Option<[f64; 2]>>>,
}

/// Buffers of the Jacobian evaluation, kept from one evaluation to the next (their sizes
/// depend only on the pixels, the pairs and the number of directions): the fresh pages of a
/// new allocation of this size cost more to clear than the arithmetic that fills them.
#[derive(Debug, Default)]
struct Scratch {
    /// Per frame `i ≥ 1`, `∂d_i/∂t_j` at each pixel, row-major (`p * n_dir + j`).
    directions: Vec<Vec<[f64; 2]>>,
    /// `v_pj = ∇F·∂d_a − s ∇G·∂d_b` and `∇G·∂d_b` of one pair, row-major.
    rows: Vec<f64>,
    dgs: Vec<f64>,
    /// Jacobian columns handed back by the optimizer ([`LeastSquares::recycle`]).
    columns: Vec<Vec<f64>>,
}

/// `dir(i, p, out)`: the pixel displacement derivatives of frame `i` at pixel `p`, one per
/// direction ([`IdicProblem::directional`]).
type PixelDirections<'a> = dyn Fn(usize, usize, &mut [[f64; 2]]) + Sync + 'a;

/// The integrated-DIC problem (module documentation).
pub struct IdicProblem {
    steps: Vec<Step>,
    free: Vec<FreeParameter>,
    members: Vec<Parameter>,
    frame: ImageFrame,
    pixels: PixelSet,
    /// The pixels of each brightness band, in order.
    band_pixels: Vec<Vec<usize>>,
    /// Frame 0 is the reference; frame `i` was taken at step `i` (`models[i − 1]`).
    images: Vec<GreyImage>,
    splines: Vec<BSpline>,
    /// `[g, ∂g/∂x, ∂g/∂y]` of each frame's interpolant at its displaced pixels `x_p + d_i`
    /// (frame 0, which never moves, sampled once per scale).
    frame_samples: Vec<Vec<[f64; 3]>>,
    scale_px: f64,
    options: IdicOptions,
    /// `√w` per (pair, band).
    sqrt_w: Vec<f64>,
    /// 1 for the pixels in use, 0 for those the model moves out of a frame (see
    /// [`IdicProblem::freeze_mask`]).
    active: Vec<f64>,
    /// The frame pairs `(a, b)`.
    pairs: Vec<(usize, usize)>,
    /// Pixel displacements `d_i` (px) of each frame `i ≥ 1` at the last evaluation.
    displacement: Vec<Vec<[f64; 2]>>,
    /// A displacement held fixed and added to each step's model displacement (px, per step
    /// and pixel): the discretization correction (see [`IdicProblem::set_correction`]).
    correction: Option<Vec<Vec<[f64; 2]>>>,
    /// The brightness fit of each (pair, band) at the last evaluation.
    fits: Vec<Vec<BandFit>>,
    scratch: Mutex<Scratch>,
    stop: Option<Arc<AtomicBool>>,
    forward_solves: usize,
    jacobians: usize,
    /// Wall time in the forward solves and sensitivities, and in the image work (s).
    solve_s: f64,
    image_s: f64,
}

/// Why an integrated-DIC problem cannot be set up.
#[derive(Debug, thiserror::Error)]
pub enum IdicError {
    #[error("{0} frames for {1} load steps: give the unloaded image and one image per step")]
    FrameCount(usize, usize),
    #[error("frame {index} is {w} x {h} px, the unloaded image {w0} x {h0} px")]
    FrameSize {
        index: usize,
        w: usize,
        h: usize,
        w0: usize,
        h0: usize,
    },
    #[error("the load steps' models must share the reference mesh ({0})")]
    Mesh(String),
    #[error("{0} free parameters: an integrated correlation handles at most {MAX_DIRECTIONS}")]
    TooManyParameters(usize),
    #[error("pixels: {0}")]
    Pixels(String),
    #[error(transparent)]
    Fit(#[from] FitError),
}

impl IdicProblem {
    /// Sets up the problem: `models[i]` carries load step `i + 1` (same mesh and materials),
    /// `images[0]` is the unloaded frame and `images[i]` the frame of step `i`, `frame` places
    /// the images in the model. Contact converges to 1e-8 of the element size so that the
    /// displacements are smooth functions of the parameters.
    pub fn new(
        models: Vec<Model>,
        images: Vec<GreyImage>,
        frame: ImageFrame,
        free: Vec<FreeParameter>,
        options: IdicOptions,
    ) -> Result<IdicProblem, IdicError> {
        if images.len() != models.len() + 1 || models.is_empty() {
            return Err(IdicError::FrameCount(images.len(), models.len()));
        }
        let (w0, h0) = (images[0].width, images[0].height);
        for (index, im) in images.iter().enumerate() {
            if (im.width, im.height) != (w0, h0) {
                return Err(IdicError::FrameSize {
                    index,
                    w: im.width,
                    h: im.height,
                    w0,
                    h0,
                });
            }
        }
        if free.len() > MAX_DIRECTIONS {
            return Err(IdicError::TooManyParameters(free.len()));
        }
        let n_nodes = models[0].node_count();
        if models.iter().any(|m| m.node_count() != n_nodes) {
            return Err(IdicError::Mesh("node counts differ".into()));
        }
        for f in &free {
            if !(f.lower > 0.0 && f.upper > f.lower && f.upper.is_finite()) {
                return Err(FitError::BadBounds {
                    name: f.name.clone(),
                    lower: f.lower,
                    upper: f.upper,
                }
                .into());
            }
        }
        let pixels = PixelSet::new(&models[0].mesh, &frame, w0, h0, &options.pixels)
            .map_err(IdicError::Pixels)?;
        let members = free
            .iter()
            .flat_map(|f| f.members.iter().copied())
            .collect();
        let steps = models
            .into_iter()
            .map(|mut model| {
                for c in &mut model.contacts {
                    c.penetration_tolerance = c.penetration_tolerance.min(1e-8);
                }
                let solver = StaticSolver::new(&model, options.solver)
                    .map_err(|e| FitError::Solve(e.to_string()))?;
                Ok(Step {
                    model,
                    solver,
                    sensitivity: DirectSensitivity::new(),
                    state: None,
                    dstate: Vec::new(),
                })
            })
            .collect::<Result<Vec<_>, FitError>>()?;
        let n = images.len();
        let consecutive = (1..n).map(|i| (i - 1, i));
        let reference = (1..n).map(|i| (0, i));
        let pairs: Vec<(usize, usize)> = match options.pairing {
            Pairing::Reference => reference.collect(),
            Pairing::Consecutive => consecutive.collect(),
            // (0, 1) is already the first consecutive pair.
            Pairing::Both => consecutive.chain(reference.skip(1)).collect(),
            // By the frames' distance, so that the last is (0, n − 1) as with `Reference` and
            // `Both` (the residual maps show the last pair).
            Pairing::All => (1..n)
                .flat_map(|gap| (gap..n).map(move |b| (b - gap, b)))
                .collect(),
        };
        let mut band_pixels = vec![Vec::new(); pixels.bands];
        for (p, &band) in pixels.band.iter().enumerate() {
            band_pixels[band].push(p);
        }
        let mut p = IdicProblem {
            band_pixels,
            sqrt_w: vec![1.0; pairs.len() * pixels.bands],
            active: vec![1.0; pixels.len()],
            fits: vec![Vec::new(); pairs.len()],
            frame_samples: vec![vec![[0.0; 3]; pixels.len()]; images.len()],
            scratch: Mutex::new(Scratch::default()),
            displacement: vec![vec![[0.0; 2]; pixels.len()]; images.len()],
            correction: None,
            splines: Vec::new(),
            scale_px: -1.0,
            steps,
            free,
            members,
            frame,
            pixels,
            images,
            options,
            pairs,
            stop: None,
            forward_solves: 0,
            jacobians: 0,
            solve_s: 0.0,
            image_s: 0.0,
        };
        p.set_scale(0.0);
        Ok(p)
    }

    /// Stops at the next evaluation with [`FitError::Interrupted`] once `flag` is set.
    pub fn with_stop(mut self, flag: Option<Arc<AtomicBool>>) -> Self {
        self.stop = flag;
        self
    }

    /// Compares the images smoothed by a Gaussian of `sigma_px` (coarse-to-fine: a wider
    /// capture range, see `GreyImage::gaussian_blur`), then locally normalized if asked
    /// ([`IdicOptions::local_normalization_px`]); the weights return to one per pixel
    /// scaled by the reference's grey-level spread, the same for every start.
    pub fn set_scale(&mut self, sigma_px: f64) {
        if sigma_px == self.scale_px {
            return;
        }
        self.scale_px = sigma_px;
        self.splines = self
            .images
            .par_iter()
            .map(|im| {
                let b = im.gaussian_blur(sigma_px);
                let b = match self.options.local_normalization_px {
                    Some(window) => b.locally_normalized(window),
                    None => b,
                };
                BSpline::new(&b.data, b.width, b.height)
            })
            .collect();
        self.sample_frame(0);
        let f: Vec<f64> = self
            .pixels
            .px
            .iter()
            .map(|p| self.splines[0].eval(p[0] as f64, p[1] as f64))
            .collect();
        let n = f.len() as f64;
        let mean = f.iter().sum::<f64>() / n;
        let sd = (f.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        self.sqrt_w.fill(1.0 / sd.max(1e-9));
    }

    /// The current smoothing (px).
    pub fn scale_px(&self) -> f64 {
        self.scale_px
    }

    /// Weights each (pair, band) by the inverse variance of its residual at `phi` (grey
    /// levels², with the brightness fit's two degrees of freedom removed), so that noisier
    /// pairs (more decorrelated frames) and darker bands count less.
    pub fn reweight(&mut self, phi: &[f64]) -> Result<Vec<f64>, FitError> {
        self.freeze_mask(phi)?;
        self.sqrt_w.fill(1.0);
        let r = self.residual_vector();
        let n_pix = self.pixels.len();
        let nb = self.pixels.bands;
        let mut ss = vec![(0.0f64, 0.0f64); self.sqrt_w.len()];
        for (k, ri) in r.iter().enumerate() {
            let (pair, p) = (k / n_pix, k % n_pix);
            if self.active[p] == 0.0 {
                continue;
            }
            let e = &mut ss[pair * nb + self.pixels.band[p]];
            e.0 += ri * ri;
            e.1 += 1.0;
        }
        let sd: Vec<f64> = ss
            .iter()
            .map(|&(s, n)| (s / (n - 2.0).max(1.0)).sqrt())
            .collect();
        for (w, s) in self.sqrt_w.iter_mut().zip(&sd) {
            *w = if *s > 0.0 { 1.0 / s } else { 1.0 };
        }
        Ok(sd)
    }

    /// Solves at `phi` and keeps the pixels that every frame's displacement leaves at least
    /// [`FROZEN_MARGIN_PX`] px inside the image (beyond, the interpolation reads the mirror
    /// image); the others are left out until the next call. The set is frozen so that the cost
    /// stays a smooth function of the parameters during one minimization; the driver calls
    /// this at the start of each. Returns the pixels kept.
    pub fn freeze_mask(&mut self, phi: &[f64]) -> Result<usize, FitError> {
        self.active.fill(1.0);
        self.evaluate(phi, false)?;
        let (w, h) = (self.pixels.width as f64, self.pixels.height as f64);
        let m = (self.options.pixels.border_px as f64).max(FROZEN_MARGIN_PX);
        for (p, a) in self.active.iter_mut().enumerate() {
            let x = [self.pixels.px[p][0] as f64, self.pixels.px[p][1] as f64];
            let inside = self.displacement.iter().all(|d| {
                let (u, v) = (x[0] + d[p][0], x[1] + d[p][1]);
                u >= m && v >= m && u <= w - 1.0 - m && v <= h - 1.0 - m
            });
            *a = if inside { 1.0 } else { 0.0 };
        }
        // The brightness fits of the evaluation above counted every pixel: redo them.
        self.fit_brightness();
        Ok(self.active.iter().filter(|a| **a > 0.0).count())
    }

    /// Pixels in use (see [`IdicProblem::freeze_mask`]).
    pub fn active_pixels(&self) -> usize {
        self.active.iter().filter(|a| **a > 0.0).count()
    }

    /// Wall time spent in the forward solves with their sensitivities, and in the image work
    /// (sampling, brightness, residuals, Jacobian columns), since the problem was built (s).
    pub fn timings(&self) -> (f64, f64) {
        (self.solve_s, self.image_s)
    }

    pub fn pixels(&self) -> &PixelSet {
        &self.pixels
    }

    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// How the grey levels are compared.
    pub fn options(&self) -> &IdicOptions {
        &self.options
    }

    pub fn frame(&self) -> &ImageFrame {
        &self.frame
    }

    pub fn images(&self) -> &[GreyImage] {
        &self.images
    }

    /// The model of load step `i` (0-based).
    pub fn model(&self, i: usize) -> &Model {
        &self.steps[i].model
    }

    pub fn steps(&self) -> usize {
        self.steps.len()
    }

    /// Pixel displacements of frame `i` (`0` is the reference: zero) at the last evaluation.
    pub fn displacement(&self, i: usize) -> &[[f64; 2]] {
        &self.displacement[i]
    }

    /// `√w` per (pair, band), pair-major.
    pub fn sqrt_weights(&self) -> &[f64] {
        &self.sqrt_w
    }

    /// The contrast and offset of each (pair, band) at the last evaluation.
    pub fn brightness(&self) -> Vec<Vec<(f64, f64)>> {
        self.fits
            .iter()
            .map(|fits| fits.iter().map(|f| (f.contrast, f.offset)).collect())
            .collect()
    }

    /// The last converged state of every step (None before the first evaluation).
    pub fn states(&self) -> Option<Vec<Vec<f64>>> {
        self.steps.iter().map(|s| s.state.clone()).collect()
    }

    fn check_stop(&self) -> Result<(), FitError> {
        match &self.stop {
            Some(f) if f.load(Ordering::Relaxed) => Err(FitError::Interrupted),
            _ => Ok(()),
        }
    }

    /// Solves every step at `phi` (and their sensitivities when `jacobian`), in parallel.
    fn solve_steps(&mut self, phi: &[f64], jacobian: bool) -> Result<(), FitError> {
        let free = &self.free;
        let members = &self.members;
        let results: Vec<Result<(), FitError>> = self
            .steps
            .par_iter_mut()
            .enumerate()
            .map(|(i, st)| {
                for (f, &p) in free.iter().zip(phi) {
                    for m in &f.members {
                        m.set(&mut st.model, p.exp());
                    }
                }
                let sol = st
                    .solver
                    .solve_with(&st.model, st.state.as_deref(), &mut |_| {})
                    .map_err(|e| FitError::from_solve_at(e, &format!("load step {}", i + 1)))?;
                if jacobian {
                    st.sensitivity
                        .compute(
                            &mut st.solver,
                            &st.model,
                            &sol.state,
                            members,
                            &mut st.dstate,
                        )
                        .map_err(|e| FitError::Sensitivity(format!("load step {}: {e}", i + 1)))?;
                }
                st.state = Some(sol.state);
                Ok(())
            })
            .collect();
        self.forward_solves += self.steps.len();
        if jacobian {
            self.jacobians += 1;
        }
        results.into_iter().collect()
    }

    /// The pixel displacements of every frame from the steps' last states.
    fn update_displacements(&mut self) {
        let (pixels, frame) = (&self.pixels, &self.frame);
        for (i, st) in self.steps.iter().enumerate() {
            let u = st.state.as_deref().expect("solved");
            let c = self.correction.as_ref().map(|c| &c[i]);
            self.displacement[i + 1]
                .par_iter_mut()
                .zip(pixels.loc.par_iter())
                .enumerate()
                .for_each(|(p, (d, l))| {
                    *d = frame.field_to_pixels(l, u);
                    if let Some(c) = c {
                        d[0] += c[p][0];
                        d[1] += c[p][1];
                    }
                });
        }
    }

    /// Adds `correction[i][p]` (px) to the model displacement of load step `i + 1` at pixel
    /// `p` in every later evaluation, held fixed (its parameter derivative is left out of the
    /// Jacobian): the approximation-error treatment of the mesh (Kaipio & Somersalo 2007), the
    /// correction being the discretization error of the model's displacement estimated at an
    /// earlier estimate. `None` removes it.
    pub fn set_correction(
        &mut self,
        correction: Option<Vec<Vec<[f64; 2]>>>,
    ) -> Result<(), FitError> {
        if let Some(c) = &correction {
            if c.len() != self.steps.len() || c.iter().any(|c| c.len() != self.pixels.len()) {
                return Err(FitError::Solve(format!(
                    "a displacement correction needs {} load steps of {} pixels",
                    self.steps.len(),
                    self.pixels.len()
                )));
            }
        }
        self.correction = correction;
        Ok(())
    }

    /// The model's own pixel displacement of frame `i ≥ 1` at the last evaluation, without
    /// the correction.
    pub fn model_displacement(&self, i: usize) -> Vec<[f64; 2]> {
        let d = &self.displacement[i];
        match &self.correction {
            Some(c) => d
                .iter()
                .zip(&c[i - 1])
                .map(|(d, c)| [d[0] - c[0], d[1] - c[1]])
                .collect(),
            None => d.clone(),
        }
    }

    /// Samples frame `i`'s interpolant at its displaced pixels `x_p + d_i` (`d_0 = 0`).
    fn sample_frame(&mut self, i: usize) {
        let (spline, d, px) = (&self.splines[i], &self.displacement[i], &self.pixels.px);
        self.frame_samples[i]
            .par_iter_mut()
            .enumerate()
            .with_min_len(1024)
            .for_each(|(p, out)| {
                let (g, gx, gy) =
                    spline.eval_grad(px[p][0] as f64 + d[p][0], px[p][1] as f64 + d[p][1]);
                *out = [g, gx, gy];
            });
    }

    /// Samples every loaded frame at its displaced pixels (each frame once, whatever the
    /// pairs it is in) and fits the brightness of every pair.
    fn sample_pairs(&mut self) {
        for i in 1..self.images.len() {
            self.sample_frame(i);
        }
        self.fit_brightness();
    }

    /// The brightness fit of every (pair, band) from the frames' samples, over the active
    /// pixels.
    fn fit_brightness(&mut self) {
        let nb = self.pixels.bands;
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            let (fa, fb) = (&self.frame_samples[a], &self.frame_samples[b]);
            let mut sums = vec![BandSums::default(); nb];
            for (((f, g), &band), &active) in
                fa.iter().zip(fb).zip(&self.pixels.band).zip(&self.active)
            {
                if active > 0.0 {
                    sums[band].add(f[0], g[0]);
                }
            }
            self.fits[k] = sums
                .iter()
                .map(|s| s.fit(self.options.brightness))
                .collect();
        }
    }

    /// The weighted residuals (1), pair-major.
    fn residual_vector(&self) -> Vec<f64> {
        let n = self.pixels.len();
        let nb = self.pixels.bands;
        let mut r = vec![0.0; n * self.pairs.len()];
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            let (fa, fb, fits) = (
                &self.frame_samples[a],
                &self.frame_samples[b],
                &self.fits[k],
            );
            r[k * n..(k + 1) * n]
                .par_iter_mut()
                .enumerate()
                .with_min_len(1024)
                .for_each(|(p, out)| {
                    let band = self.pixels.band[p];
                    *out = self.active[p]
                        * self.sqrt_w[k * nb + band]
                        * fits[band].residual(fa[p][0], fb[p][0]);
                });
        }
        r
    }

    /// Derivatives of the weighted residuals along `n_dir` directions of the pixel
    /// displacements: `dir(i, p, out)` writes `∂d_i/∂t_j` at pixel `p` of frame `i ≥ 1` for
    /// every direction `j` (frame 0 never moves). Returns one column per direction, pair-major,
    /// with the projection term of the brightness fit (module [`super::brightness`]). Each
    /// frame's directions are computed once (a frame is in several pairs), and the buffers are
    /// those of the last call ([`Scratch`]).
    pub(crate) fn directional(&self, n_dir: usize, dir: &PixelDirections) -> Columns {
        debug_assert!(
            n_dir <= MAX_DIRECTIONS,
            "{n_dir} directions, at most {MAX_DIRECTIONS}"
        );
        let n = self.pixels.len();
        let nb = self.pixels.bands;
        let len = n * self.pairs.len();
        let mut guard = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        let Scratch {
            directions,
            rows,
            dgs,
            columns,
        } = &mut *guard;
        directions.resize_with(self.images.len() - 1, Vec::new);
        for (i, d) in directions.iter_mut().enumerate() {
            // Every entry is written below: the old contents need no clearing.
            d.resize(n * n_dir, [0.0; 2]);
            d.par_chunks_mut(n_dir)
                .enumerate()
                .with_min_len(256)
                .for_each(|(p, out)| dir(i + 1, p, out));
        }
        // Every entry of every column is written by the last loop below.
        let mut cols: Columns = (0..n_dir)
            .map(|_| {
                let mut c = columns.pop().unwrap_or_default();
                c.resize(len, 0.0);
                c
            })
            .collect();
        rows.resize(n * n_dir, 0.0);
        dgs.resize(n * n_dir, 0.0);
        // Frame 0 never moves: its directions are zero (multiplied out as the others are,
        // so that the sums are those of any frame).
        let zero = vec![[0.0; 2]; n_dir];
        for (k, &(a, b)) in self.pairs.iter().enumerate() {
            let (fa, fb, fits) = (
                &self.frame_samples[a],
                &self.frame_samples[b],
                &self.fits[k],
            );
            let dir_a = (a > 0).then(|| &directions[a - 1]);
            let dir_b = &directions[b - 1];
            // v_pj = ∇F·∂d_a − s ∇G·∂d_b and ∇G·∂d_b, row-major.
            rows.par_chunks_mut(n_dir)
                .zip(dgs.par_chunks_mut(n_dir))
                .enumerate()
                .with_min_len(256)
                .for_each(|(p, (rv, dv))| {
                    let da = dir_a.map_or(&zero[..], |d| &d[p * n_dir..(p + 1) * n_dir]);
                    let db = &dir_b[p * n_dir..(p + 1) * n_dir];
                    let (f, g) = (&fa[p], &fb[p]);
                    let c = fits[self.pixels.band[p]].contrast;
                    for j in 0..n_dir {
                        let dg = g[1] * db[j][0] + g[2] * db[j][1];
                        rv[j] = f[1] * da[j][0] + f[2] * da[j][1] - c * dg;
                        dv[j] = dg;
                    }
                });
            // Band sums Σ G v, Σ v, Σ δG r per direction, each band's pixels in order (the
            // bands in parallel), and the projection term's coefficients of each.
            let (rows, dgs) = (&*rows, &*dgs);
            let q: Vec<[f64; 2]> = self
                .band_pixels
                .par_iter()
                .enumerate()
                .flat_map_iter(|(band, members)| {
                    let mut sums = vec![[0.0; 3]; n_dir];
                    for &p in members {
                        if self.active[p] == 0.0 {
                            continue;
                        }
                        let g = fb[p][0];
                        let r = fits[band].residual(fa[p][0], g);
                        for (j, e) in sums.iter_mut().enumerate() {
                            let vj = rows[p * n_dir + j];
                            e[0] += g * vj;
                            e[1] += vj;
                            e[2] += dgs[p * n_dir + j] * r;
                        }
                    }
                    sums.into_iter()
                        .map(move |e| fits[band].correction(e[0], e[1], e[2]))
                })
                .collect();
            for (j, col) in cols.iter_mut().enumerate() {
                col[k * n..(k + 1) * n]
                    .par_iter_mut()
                    .enumerate()
                    .with_min_len(1024)
                    .for_each(|(p, out)| {
                        let band = self.pixels.band[p];
                        let qj = q[band * n_dir + j];
                        let g = fb[p][0];
                        *out = self.active[p]
                            * self.sqrt_w[k * nb + band]
                            * (rows[p * n_dir + j] - (g * qj[0] + qj[1]));
                    });
            }
        }
        cols
    }

    /// Per free parameter, the nodal field `Σ_m θ_m ∂u/∂θ_m` (the derivative along `ln θ`)
    /// from the members' derivatives `dstate` of a step solved on `model`.
    fn free_fields(&self, model: &Model, dstate: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let mut k = 0;
        self.free
            .iter()
            .map(|f| {
                let mut sum = vec![0.0; dstate[0].len()];
                for m in &f.members {
                    let theta = m.value(model);
                    for (s, d) in sum.iter_mut().zip(&dstate[k]) {
                        *s += theta * d;
                    }
                    k += 1;
                }
                sum
            })
            .collect()
    }

    /// Per load step, [`Self::free_fields`] of its last Jacobian evaluation.
    fn step_free_fields(&self) -> Vec<Vec<Vec<f64>>> {
        self.steps
            .iter()
            .map(|st| self.free_fields(&st.model, &st.dstate))
            .collect()
    }

    /// The Jacobian columns `∂r/∂φ_j` (2) at the last solved state.
    fn jacobian_columns(&self) -> Columns {
        let fields = self.step_free_fields();
        let (pixels, frame) = (&self.pixels, &self.frame);
        let dir = |i: usize, p: usize, out: &mut [[f64; 2]]| {
            for (o, field) in out.iter_mut().zip(&fields[i - 1]) {
                *o = frame.field_to_pixels(&pixels.loc[p], field);
            }
        };
        self.directional(self.free.len(), &dir)
    }

    /// The residual change (first order) if every frame's pixel displacements moved by
    /// `delta[i − 1][p]` (px): the data of a one-step Gauss–Newton shift (see
    /// [`super::uncertainty`]).
    pub fn residual_change(&self, delta: &[Vec<[f64; 2]>]) -> Vec<f64> {
        let dir = |i: usize, p: usize, out: &mut [[f64; 2]]| {
            out[0] = delta[i - 1][p];
        };
        self.directional(1, &dir).pop().expect("one direction")
    }

    /// The pixel displacements (px) of every load step that the `refined` models (the same
    /// load steps on another mesh of the same geometry and materials) give at the parameters
    /// of the last evaluation, at the problem's pixels; `None` where that mesh does not cover
    /// a pixel. Each step warm-started from the one before.
    pub fn displacements_on(
        &self,
        refined: Vec<Model>,
    ) -> Result<Vec<Vec<Option<[f64; 2]>>>, FitError> {
        Ok(self
            .solve_refined(refined, false)?
            .into_iter()
            .map(|s| s.displacement)
            .collect())
    }

    /// Every load step solved on the `refined` models at the parameters of the last
    /// evaluation (see [`Self::displacements_on`]), with the pixel sensitivities
    /// `∂d/∂ln θ_j` of that mesh when `sensitivities` (empty otherwise).
    fn solve_refined(
        &self,
        refined: Vec<Model>,
        sensitivities: bool,
    ) -> Result<Vec<RefinedStep>, FitError> {
        if refined.len() != self.steps.len() {
            return Err(FitError::Solve(format!(
                "{} refined models for {} load steps",
                refined.len(),
                self.steps.len()
            )));
        }
        let theta: Vec<f64> = self
            .free
            .iter()
            .map(|f| f.members[0].value(&self.steps[0].model))
            .collect();
        let mut warm: Option<Vec<f64>> = None;
        let mut out = Vec::with_capacity(refined.len());
        for (i, mut model) in refined.into_iter().enumerate() {
            self.check_stop()?;
            for (f, &t) in self.free.iter().zip(&theta) {
                for m in &f.members {
                    if !m.belongs_to(&model) {
                        return Err(FitError::Solve(format!(
                            "the refined model has no material {} for {}",
                            m.material, f.name
                        )));
                    }
                    m.set(&mut model, t);
                }
            }
            for c in &mut model.contacts {
                c.penetration_tolerance = c.penetration_tolerance.min(1e-8);
            }
            let mut solver = StaticSolver::new(&model, self.options.solver)
                .map_err(|e| FitError::Solve(e.to_string()))?;
            let sol = solver
                .solve_with(&model, warm.as_deref(), &mut |_| {})
                .map_err(|e| {
                    FitError::from_solve_at(e, &format!("refined mesh, load step {}", i + 1))
                })?;
            let fields = if sensitivities {
                let mut dstate = Vec::new();
                DirectSensitivity::new()
                    .compute(&mut solver, &model, &sol.state, &self.members, &mut dstate)
                    .map_err(|e| {
                        FitError::Sensitivity(format!("refined mesh, load step {}: {e}", i + 1))
                    })?;
                self.free_fields(&model, &dstate)
            } else {
                Vec::new()
            };
            let locator = femu_mesh::locate::PointLocator::new(&model.mesh);
            let located: Vec<_> = self
                .pixels
                .px
                .par_iter()
                .map(|p| locator.locate(self.frame.pixel_to_model([p[0] as f64, p[1] as f64])))
                .collect();
            out.push(RefinedStep {
                displacement: located
                    .par_iter()
                    .map(|l| l.as_ref().map(|l| self.frame.field_to_pixels(l, &sol.u)))
                    .collect(),
                sensitivity: fields
                    .iter()
                    .map(|field| {
                        located
                            .par_iter()
                            .map(|l| l.as_ref().map(|l| self.frame.field_to_pixels(l, field)))
                            .collect()
                    })
                    .collect(),
            });
            warm = Some(sol.state);
        }
        Ok(out)
    }

    /// The one-step Gauss–Newton shift of `ln θ` (eq. 3 of [`super::uncertainty`]) that moving
    /// every step's pixel displacements by `delta[i][p]` (px) implies at the last Jacobian
    /// evaluation, the parameters with `moving[k] == false` held (see
    /// [`super::uncertainty::gauss_newton_shift`]).
    pub fn shift_for(&self, delta: &[Vec<[f64; 2]>], moving: &[bool]) -> Vec<f64> {
        let dr = self.residual_change(delta);
        super::uncertainty::gauss_newton_shift(&self.jacobian_columns(), &dr, moving)
    }

    /// The one-step Gauss–Newton shift of `ln θ` (eq. 3 of [`super::uncertainty`]) that the
    /// `refined` models (the same load steps on a finer mesh of the same geometry and
    /// materials) imply at the parameters of the last Jacobian evaluation: each refined step
    /// solved and differentiated there, the residual with its pixel displacements (to first
    /// order) and its Jacobian with its sensitivities. Pixels the refined mesh does not cover
    /// keep the model's displacement and sensitivities. The parameters with
    /// `moving[k] == false` are held ([`super::uncertainty::gauss_newton_shift`]).
    pub fn discretization_shift(
        &self,
        refined: Vec<Model>,
        moving: &[bool],
    ) -> Result<Vec<f64>, FitError> {
        let fine = self.solve_refined(refined, true)?;
        let delta: Vec<Vec<[f64; 2]>> = fine
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let own = self.model_displacement(i + 1);
                f.displacement
                    .iter()
                    .zip(&own)
                    .map(|(f, d0)| f.map_or([0.0, 0.0], |f| [f[0] - d0[0], f[1] - d0[1]]))
                    .collect()
            })
            .collect();
        // The refined mesh's residual (first order in the displacement change) and its
        // Jacobian: the same image terms, the refined mesh's sensitivities (the model's own
        // where the refined mesh does not cover a pixel). With the whole residual, not only
        // its change: the model's residual is orthogonal to its own sensitivities at the
        // optimum, not to the refined mesh's (`crate::discretization`).
        let own = self.step_free_fields();
        let (pixels, frame) = (&self.pixels, &self.frame);
        let dir = |i: usize, p: usize, out: &mut [[f64; 2]]| {
            for (j, o) in out.iter_mut().enumerate() {
                *o = fine[i - 1].sensitivity[j][p]
                    .unwrap_or_else(|| frame.field_to_pixels(&pixels.loc[p], &own[i - 1][j]));
            }
        };
        let jacobian = self.directional(self.free.len(), &dir);
        let change = self.residual_change(&delta);
        let residual: Vec<f64> = self
            .residual_vector()
            .iter()
            .zip(&change)
            .map(|(r, c)| r + c)
            .collect();
        Ok(super::uncertainty::gauss_newton_shift(
            &jacobian, &residual, moving,
        ))
    }

    /// The unweighted residual maps of every pair at the last evaluation (grey levels, NaN out
    /// of the pixel set), `width x height` each.
    pub fn residual_maps(&self) -> Vec<Vec<f64>> {
        let (w, h) = (self.pixels.width, self.pixels.height);
        self.pairs
            .iter()
            .zip(&self.fits)
            .map(|(&(a, b), fits)| {
                let (fa, fb) = (&self.frame_samples[a], &self.frame_samples[b]);
                let mut m = vec![f64::NAN; w * h];
                for (p, px) in self.pixels.px.iter().enumerate() {
                    if self.active[p] == 0.0 {
                        continue;
                    }
                    m[px[1] * w + px[0]] = fits[self.pixels.band[p]].residual(fa[p][0], fb[p][0]);
                }
                m
            })
            .collect()
    }
}

impl LeastSquares for IdicProblem {
    fn free(&self) -> &[FreeParameter] {
        &self.free
    }

    fn evaluate(
        &mut self,
        phi: &[f64],
        jacobian: bool,
    ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
        self.check_stop()?;
        let t0 = std::time::Instant::now();
        let solved = self.solve_steps(phi, jacobian);
        self.solve_s += t0.elapsed().as_secs_f64();
        solved?;
        let t1 = std::time::Instant::now();
        self.update_displacements();
        self.sample_pairs();
        let r = self.residual_vector();
        let j = jacobian.then(|| self.jacobian_columns());
        self.image_s += t1.elapsed().as_secs_f64();
        Ok((r, j))
    }

    fn counts(&self) -> (usize, usize) {
        (self.forward_solves, self.jacobians)
    }

    /// Keeps the columns for the next Jacobian evaluation: at most two Jacobians' worth (the
    /// optimizer holds the accepted one while it evaluates a trial).
    fn recycle(&mut self, columns: Columns) {
        let keep = 2 * self.free.len();
        let pool = &mut self
            .scratch
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .columns;
        for c in columns {
            if pool.len() < keep && c.capacity() > 0 {
                pool.push(c);
            }
        }
    }
}
