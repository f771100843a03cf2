//! Global finite-element DIC with Q4 elements (Besnard, Hild & Roux 2006, "Finite-element
//! displacement fields analysis from digital images: application to Portevin–Le Châtelier
//! bands"; the Correli-Q4 formulation used by the seed, §2.1.1).
//!
//! The displacement is the Q4 field `u(x) = Σ_n N_n(x) a_n` over the mesh of the ROI, and the
//! nodal values `a` minimize the sum of squared grey-level differences over the ROI pixels
//!
//! ```text
//! Φ(a) = Σ_x [ f(x) − g̃(x + u(x)) ]²                                                 (1)
//! ```
//!
//! with `f` the reference image, `g` the deformed one interpolated by cubic B-splines and
//! `g̃ = s g + o` optionally corrected for brightness `o` and contrast `s` (mean and standard
//! deviation of `g` matched to those of `f`, over the ROI or per element). Linearizing
//! `g(x + u + δu) ≈ g(x + u) + ∇f(x)·δu` (the *modified* Gauss–Newton scheme: the deformed
//! gradient is replaced by the reference one, valid at convergence where `g(x + u) ≈ f(x)`)
//! gives at each iteration
//!
//! ```text
//! M δa = b,   M_ij = Σ_x (N_i ∇f)·(N_j ∇f),   b_i = Σ_x (N_i ∇f) [f(x) − g̃(x + u(x))]    (2)
//! ```
//!
//! where `M` does not depend on `a`: it is assembled and factorized (sparse Cholesky) once per
//! pyramid level, and each iteration costs one pass over the pixels plus one sparse solve.
//!
//! **Regularization** (optional, Tikhonov): the penalty `λ aᵀ K a`, `K = Lᵀ L` with `L` the
//! 5-point Laplacian of each component at the nodes whose four neighbours exist (so rigid and
//! affine fields are not penalized), is added to (1), giving `(M + λK) δa = b − λ K a`. The
//! weight follows Tomičević, Hild & Roux (2013): `λ = vᵀMv / vᵀKv` for a plane wave `v` of the
//! regularization length `ℓ`, so that waves shorter than `ℓ` are damped (as `(ℓ/λ_w)⁴`) and
//! longer ones are left to the images. The penalty is a [`crate::regularize::Regularizer`]
//! ([`crate::regularize::Laplacian`] here), which gives the system `K` and `λ`.
//!
//! **Initialization**: an integer shift from FFT phase correlation on the coarsest level of a
//! 2x2 image pyramid, then Gauss–Newton on each level from coarse to fine, each level
//! starting from the field of the one above (doubled and interpolated).
//!
//! **Convergence**: the root mean square over the nodes of the nodal increment `|δa_n|` below
//! the tolerance (default 1e-3 px), or the iteration limit (the result says which). The RMS,
//! not the maximum, so that one weakly constrained corner node in a textureless spot does not
//! hold the whole field hostage; such a node's element keeps a high residual and is flagged.

use crate::anderson::Anderson;
use crate::bspline::BSpline;
use crate::error::DicError;
use crate::image::GreyImage;
use crate::mesh::{DicMesh, Roi};
use crate::sparse::{Cholesky, CscPattern};
use rayon::prelude::*;
use std::time::Instant;

/// Brightness and contrast correction of the deformed image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Brightness {
    /// None: grey levels are conserved.
    None,
    /// One offset and one scale over the whole ROI (the default: harmless when the lighting
    /// does not change, necessary when it does, as in DIC Challenge Sample 5).
    Global,
    /// One offset and one scale per element (ultrasound gain and attenuation vary with depth).
    PerElement,
}

/// Options of the correlation.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DicOptions {
    /// Element size (pixels).
    pub element_size: usize,
    /// Convergence: RMS over the nodes of the nodal displacement increment (pixels).
    pub tolerance: f64,
    /// Maximum number of Gauss–Newton iterations on the finest level.
    pub max_iterations: usize,
    pub brightness: Brightness,
    /// Tikhonov regularization length (pixels); `None`: no regularization.
    pub regularization_length: Option<f64>,
    /// Pyramid levels above the full-resolution image; `None`: automatic (up to 2 while the
    /// coarsest ROI still holds 2 x 2 elements).
    pub pyramid_levels: Option<usize>,
    /// Integer-shift initial guess by FFT cross-correlation.
    pub fft_init: bool,
    /// An element is flagged when its residual RMS exceeds this factor times the median.
    pub flag_factor: f64,
    /// Depth of the Anderson acceleration of the Gauss–Newton iterations (module
    /// [`crate::anderson`]; 0, the default here: plain modified Gauss–Newton steps, as the
    /// ultrasound simulator's incremental DIC was validated with; `femu dic` uses
    /// [`crate::anderson::DEFAULT_DEPTH`]).
    pub acceleration_depth: usize,
}

impl Default for DicOptions {
    fn default() -> Self {
        DicOptions {
            element_size: 16,
            tolerance: 1e-3,
            max_iterations: 100,
            brightness: Brightness::Global,
            regularization_length: None,
            pyramid_levels: None,
            fft_init: true,
            flag_factor: 3.0,
            acceleration_depth: 0,
        }
    }
}

impl DicOptions {
    /// The options' ranges, checked by [`correlate`] before any work (an error names the option).
    pub fn validate(&self) -> Result<(), DicError> {
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return Err(DicError::option(
                "tolerance",
                format!("{} must be positive", self.tolerance),
            ));
        }
        if self.max_iterations == 0 {
            return Err(DicError::option("max iterations", "must be at least 1"));
        }
        if let Some(l) = self.regularization_length {
            if !(l >= 2.0 * self.element_size as f64 && l.is_finite()) {
                return Err(DicError::option(
                    "regularization length",
                    format!(
                        "{l} px must be at least twice the element size ({} px): a shorter wave is not seen by the nodes",
                        self.element_size
                    ),
                ));
            }
        }
        if !(self.flag_factor > 1.0) {
            return Err(DicError::option(
                "flag factor",
                format!("{} must be above 1", self.flag_factor),
            ));
        }
        if matches!(self.pyramid_levels, Some(l) if l > 6) {
            return Err(DicError::option("pyramid levels", "at most 6"));
        }
        Ok(())
    }
}

/// What happened on one pyramid level.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LevelReport {
    /// 0: full resolution; `l`: images reduced `2^l` times.
    pub level: usize,
    pub elements: usize,
    pub nodes: usize,
    pub iterations: usize,
    pub converged: bool,
    pub last_increment_px: f64,
    pub residual_rms: f64,
    /// Why a coarse level was skipped (too small, no texture), if it was.
    pub skipped: Option<String>,
}

/// Wall-clock times (seconds).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Timings {
    /// Pyramid, B-spline coefficients, FFT initial guess.
    pub preparation_s: f64,
    /// Assembly and factorization of `M` (all levels).
    pub setup_s: f64,
    /// Gauss–Newton iterations (all levels).
    pub iterations_s: f64,
    pub total_s: f64,
}

/// The measured field and its diagnostics.
#[derive(Debug, Clone)]
pub struct DicResult {
    pub mesh: DicMesh,
    /// Nodal displacements `[ux, uy]` (pixels).
    pub displacement: Vec<[f64; 2]>,
    /// Gauss–Newton iterations on the finest level.
    pub iterations: usize,
    pub converged: bool,
    pub last_increment_px: f64,
    /// RMS of the grey-level residual `f − g̃(x + u)` over the ROI (grey levels, 0–255 scale).
    pub residual_rms: f64,
    /// The same as a percentage of the reference dynamic range over the ROI.
    pub residual_percent: f64,
    /// Residual RMS per element (grey levels).
    pub element_residual: Vec<f64>,
    /// Elements whose residual exceeds `flag_factor` times the median.
    pub flagged: Vec<bool>,
    /// Residual per image pixel (NaN outside the mesh), `width x height`.
    pub residual_image: Vec<f32>,
    /// Integer initial shift from the FFT (full-resolution pixels).
    pub initial_shift: (i64, i64),
    pub levels: Vec<LevelReport>,
    pub timings: Timings,
    pub image_size: (usize, usize),
    /// The Gauss–Newton system of the finest level, for the covariance ([`crate::quality`]).
    pub system: GaussNewtonSystem,
    /// Grey-level statistics of each element at convergence.
    pub element_texture: Vec<ElementTexture>,
}

/// What the reference image offers an element, and how well the corrected deformed image
/// matches it at convergence.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct ElementTexture {
    /// Mean and standard deviation of the reference grey levels over the element.
    pub mean: f64,
    pub std: f64,
    /// Eigenvalues (small, large) of the mean structure tensor `⟨∇f ∇fᵀ⟩` (grey levels² / px²):
    /// a small first one is the aperture problem (texture along one direction only).
    pub structure: [f64; 2],
    /// Zero-normalized cross-correlation of `f` and the corrected `g̃(x + u)` over the element
    /// (1: identical up to brightness and contrast; near 0: decorrelated speckle).
    pub zncc: f64,
    /// Fraction of the element's pixels whose warped position `x + u(x)` lies inside the
    /// deformed image (pixel centres `[0, W − 1] x [0, H − 1]`); the other pixels are left out
    /// of every sum (residual, brightness, these statistics, the covariance).
    pub inside: f64,
}

impl ElementTexture {
    /// Over the pixels where the corrected warped value `g` is finite (inside the deformed
    /// image). Without any such pixel every statistic is 0 (`inside` 0 makes it untrusted).
    fn of(f: &[f64], fx: &[f64], fy: &[f64], g: &[f64]) -> Self {
        let kept = || (0..f.len()).filter(|&k| !g[k].is_nan());
        let count = kept().count();
        if count == 0 {
            return ElementTexture {
                mean: 0.0,
                std: 0.0,
                structure: [0.0; 2],
                zncc: 0.0,
                inside: 0.0,
            };
        }
        let n = count as f64;
        let mean = kept().map(|k| f[k]).sum::<f64>() / n;
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for k in kept() {
            let (gx, gy) = (fx[k], fy[k]);
            sxx += gx * gx;
            syy += gy * gy;
            sxy += gx * gy;
        }
        let (sxx, syy, sxy) = (sxx / n, syy / n, sxy / n);
        let half_tr = 0.5 * (sxx + syy);
        let disc = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
        let gm = kept().map(|k| g[k]).sum::<f64>() / n;
        let (mut cfg, mut cff, mut cgg) = (0.0, 0.0, 0.0);
        for k in kept() {
            let (a, b) = (f[k], g[k]);
            cfg += (a - mean) * (b - gm);
            cff += (a - mean) * (a - mean);
            cgg += (b - gm) * (b - gm);
        }
        ElementTexture {
            mean,
            std: (cff / n).sqrt(),
            structure: [(half_tr - disc).max(0.0), half_tr + disc],
            zncc: if cff > 0.0 && cgg > 0.0 {
                cfg / (cff * cgg).sqrt()
            } else {
                0.0
            },
            inside: n / f.len() as f64,
        }
    }
}

/// The Gauss–Newton matrices of the finest level: `M` (eq. 2) assembled and per element, and the
/// regularization `λK` on the same pattern. The matrix of the iterations is `A = M + λK`.
#[derive(Debug, Clone)]
pub struct GaussNewtonSystem {
    /// Symmetric pattern over the equations `2 node + component`.
    pub pattern: CscPattern,
    pub m_values: Vec<f64>,
    /// `λK` on the pattern (`None` without regularization).
    pub reg_values: Option<Vec<f64>>,
    /// `λ` (dimensionless weight of eq. 3) when regularized.
    pub lambda: Option<f64>,
    /// Per element, `M_e` (row-major 8 x 8) over the equations of `dofs[e]`.
    pub elem_m: Vec<[f64; 64]>,
    /// Per element, the covariance of its right-hand side `b_e = Σ (N ∇f) r` under the
    /// residual's own noise: `σ_e² Σ_k Σ_l ρ(x_k − x_l) w_k w_lᵀ`, `w = N ∇f` (eq. 4 of
    /// [`crate::quality`]; `σ_e² M_e` for white noise).
    pub elem_m_noise: Vec<[f64; 64]>,
    /// The spatial correlation `ρ` of the residual used there.
    pub residual_correlation: ResidualCorrelation,
    pub dofs: Vec<[usize; 8]>,
}

impl GaussNewtonSystem {
    /// `A = M + λK` on the pattern.
    pub fn a_values(&self) -> Vec<f64> {
        match &self.reg_values {
            None => self.m_values.clone(),
            Some(k) => self.m_values.iter().zip(k).map(|(m, k)| m + k).collect(),
        }
    }
}

/// One pyramid level: pixels of the ROI ordered element by element, reference values and
/// gradients, the matrix `M (+ λK)` factorized once, and every buffer of the iterations.
struct Level {
    mesh: DicMesh,
    /// Shape function values at the `h²` pixels of an element (same for every element).
    ntab: Vec<[f64; 4]>,
    f: Vec<f64>,
    fx: Vec<f64>,
    fy: Vec<f64>,
    /// Equations of each element: `2 node + component`, nodes in element order.
    dofs: Vec<[usize; 8]>,
    pattern: CscPattern,
    /// `M` on the pattern, and per element (row-major 8 x 8), for the covariance of the result.
    m_values: Vec<f64>,
    elem_m: Vec<[f64; 64]>,
    /// The regularization `K` on the pattern, with its weight `λ`.
    reg: Option<(Vec<f64>, f64)>,
    chol: Cholesky,
    /// Reference mean and standard deviation per element and over the ROI.
    f_stats: Vec<[f64; 2]>,
    f_global: [f64; 2],
    // Iteration buffers (allocated once).
    gw: Vec<f64>,
    elem_b: Vec<[f64; 8]>,
    elem_g: Vec<[f64; 3]>,
    /// Per element, the pixels whose warped position leaves the deformed image (their `gw` is
    /// NaN): their count and their reference sums `Σf`, `Σf²` (left out of the statistics).
    elem_out: Vec<[f64; 3]>,
    corr: Vec<(f64, f64)>,
    rhs: Vec<f64>,
    work: Vec<f64>,
    /// Anderson acceleration of the fixed-point iteration (module [`crate::anderson`]).
    anderson: Anderson,
}

impl Level {
    /// Pixels, reference gradient, `M` (eq. 2) and its factorization.
    fn new(
        reference: &GreyImage,
        roi: &Roi,
        h: usize,
        reg_length: Option<f64>,
        acceleration: usize,
    ) -> Result<Self, DicError> {
        let mesh = DicMesh::new(roi, reference.width, reference.height, h)?;
        let spline = BSpline::new(&reference.data, reference.width, reference.height);
        let npx = h * h;
        let ntab: Vec<[f64; 4]> = (0..npx)
            .map(|k| {
                DicMesh::shape(
                    ((k % h) as f64 + 0.5) / h as f64,
                    ((k / h) as f64 + 0.5) / h as f64,
                )
            })
            .collect();
        let ne = mesh.n_elements();
        let mut f = vec![0.0; ne * npx];
        let mut fx = vec![0.0; ne * npx];
        let mut fy = vec![0.0; ne * npx];
        let mut elem_m = vec![[0.0f64; 64]; ne];
        let mut f_stats = vec![[0.0f64; 2]; ne];
        f.par_chunks_mut(npx)
            .zip(fx.par_chunks_mut(npx))
            .zip(fy.par_chunks_mut(npx))
            .zip(elem_m.par_iter_mut())
            .zip(f_stats.par_iter_mut())
            .enumerate()
            .for_each(|(e, ((((fe, fxe), fye), me), st))| {
                let (px, py) = mesh.element_origin(e);
                for k in 0..npx {
                    let (v, gx, gy) = spline.grad_at_pixel(px + k % h, py + k / h);
                    fe[k] = v;
                    fxe[k] = gx;
                    fye[k] = gy;
                    let n = &ntab[k];
                    // Row vector (N0 fx, N0 fy, N1 fx, ...) and its outer product.
                    let row = pixel_row(n, gx, gy);
                    for i in 0..8 {
                        for j in 0..=i {
                            me[i * 8 + j] += row[i] * row[j];
                        }
                    }
                }
                for i in 0..8 {
                    for j in 0..i {
                        me[j * 8 + i] = me[i * 8 + j];
                    }
                }
                let mean = fe.iter().sum::<f64>() / npx as f64;
                let var = fe.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / npx as f64;
                *st = [mean, var.sqrt()];
            });
        let n_all = (ne * npx) as f64;
        let mean = f.iter().sum::<f64>() / n_all;
        let std = (f.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n_all).sqrt();
        let grad_ms = fx.iter().zip(&fy).map(|(a, b)| a * a + b * b).sum::<f64>() / n_all;
        if !(std > 1e-6 && grad_ms > 1e-10) {
            return Err(DicError::NoTexture(format!(
                "the reference image is uniform over the region of interest (grey-level std {std:.3e}, gradient RMS {:.3e}): there is nothing to correlate",
                grad_ms.sqrt()
            )));
        }
        // Elements without texture make M singular (their corner nodes are unmeasurable).
        if reg_length.is_none() {
            for e in 0..ne {
                let g2: f64 = (0..npx)
                    .map(|k| fx[e * npx + k].powi(2) + fy[e * npx + k].powi(2))
                    .sum::<f64>()
                    / npx as f64;
                if g2 < 1e-6 * grad_ms {
                    let (px, py) = mesh.element_origin(e);
                    return Err(DicError::NoTexture(format!(
                        "element {e} (pixels x {px}..{}, y {py}..{}) has no grey-level texture (gradient RMS {:.2e} against {:.2e} over the ROI); exclude it with a mask or set a regularization length",
                        px + h,
                        py + h,
                        g2.sqrt(),
                        grad_ms.sqrt()
                    )));
                }
            }
        }
        let dofs: Vec<[usize; 8]> = mesh
            .conn
            .iter()
            .map(|c| {
                let mut d = [0usize; 8];
                for a in 0..4 {
                    d[2 * a] = 2 * c[a];
                    d[2 * a + 1] = 2 * c[a] + 1;
                }
                d
            })
            .collect();
        let n_eq = 2 * mesh.n_nodes();
        let mut pairs: Vec<(usize, usize)> = Vec::with_capacity(64 * ne);
        for d in &dofs {
            for &r in d {
                for &c in d {
                    pairs.push((r, c));
                }
            }
        }
        let regularizer = crate::regularize::regularizer_for(&mesh, reg_length);
        if let Some(r) = &regularizer {
            r.pattern_pairs(&mut pairs);
        }
        let pattern = femu_sparse::CscPattern::from_pairs(n_eq, &mut pairs);
        let mut m_values = vec![0.0; pattern.nnz()];
        for (d, me) in dofs.iter().zip(&elem_m) {
            add_element(&pattern, &mut m_values, d, me, 1.0);
        }
        let reg = regularizer.and_then(|r| {
            let k_values = r.k_values(&pattern);
            r.weight(&pattern, &m_values, &k_values)
                .map(|lambda| (k_values, lambda))
        });
        let a_values: Vec<f64> = match &reg {
            None => m_values.clone(),
            Some((kv, lambda)) => m_values
                .iter()
                .zip(kv)
                .map(|(m, k)| m + lambda * k)
                .collect(),
        };
        let chol = Cholesky::factorize(&pattern, &a_values).map_err(|e| match e {
            DicError::Linear(msg) => DicError::NoTexture(format!(
                "{msg}: some nodes are not measurable (too little texture around them); use a mask, larger elements or a regularization length"
            )),
            other => other,
        })?;
        Ok(Level {
            ntab,
            gw: vec![0.0; ne * npx],
            elem_b: vec![[0.0; 8]; ne],
            elem_g: vec![[0.0; 3]; ne],
            elem_out: vec![[0.0; 3]; ne],
            corr: vec![(1.0, 0.0); ne],
            rhs: vec![0.0; n_eq],
            work: vec![0.0; n_eq],
            anderson: Anderson::new(n_eq, acceleration),
            f,
            fx,
            fy,
            dofs,
            pattern,
            m_values,
            elem_m,
            reg,
            chol,
            f_stats,
            f_global: [mean, std],
            mesh,
        })
    }

    /// Evaluates `g(x + u(x))` at every ROI pixel into `gw`, with the sums `Σg`, `Σg²` per
    /// element. A pixel whose warped position falls outside the deformed image's pixel centres
    /// `[0, W − 1] x [0, H − 1]` (the border itself is inside) gets NaN: there the B-spline
    /// would return its mirror extension, which does not show the reference's content, so the
    /// pixel is left out of every sum (its count and reference sums go to `elem_out`).
    fn warp(&mut self, g: &BSpline, a: &[f64]) {
        let h = self.mesh.h;
        let npx = h * h;
        let mesh = &self.mesh;
        let ntab = &self.ntab;
        let f = &self.f;
        let (xmax, ymax) = (g.width as f64 - 1.0, g.height as f64 - 1.0);
        self.gw
            .par_chunks_mut(npx)
            .zip(self.elem_g.par_iter_mut())
            .zip(self.elem_out.par_iter_mut())
            .enumerate()
            .for_each(|(e, ((gwe, st), out))| {
                let fe = &f[e * npx..(e + 1) * npx];
                let mut o = [0.0; 3];
                let c = &mesh.conn[e];
                let ax = [a[2 * c[0]], a[2 * c[1]], a[2 * c[2]], a[2 * c[3]]];
                let ay = [
                    a[2 * c[0] + 1],
                    a[2 * c[1] + 1],
                    a[2 * c[2] + 1],
                    a[2 * c[3] + 1],
                ];
                let (px, py) = mesh.element_origin(e);
                let (mut s1, mut s2) = (0.0, 0.0);
                for j in 0..h {
                    for i in 0..h {
                        let k = j * h + i;
                        let n = &ntab[k];
                        let ux = n[0] * ax[0] + n[1] * ax[1] + n[2] * ax[2] + n[3] * ax[3];
                        let uy = n[0] * ay[0] + n[1] * ay[1] + n[2] * ay[2] + n[3] * ay[3];
                        let (sx, sy) = ((px + i) as f64 + ux, (py + j) as f64 + uy);
                        if !(sx >= 0.0 && sy >= 0.0 && sx <= xmax && sy <= ymax) {
                            gwe[k] = f64::NAN;
                            o[0] += 1.0;
                            o[1] += fe[k];
                            o[2] += fe[k] * fe[k];
                            continue;
                        }
                        let v = g.eval(sx, sy);
                        gwe[k] = v;
                        s1 += v;
                        s2 += v * v;
                    }
                }
                *st = [s1, s2, 0.0];
                *out = o;
            });
    }

    /// Brightness/contrast `(s, o)` of element `e` such that `s g + o` has the mean and the
    /// standard deviation of `f`.
    /// Both over the pixels inside the deformed image (all of them unless `warp` left some out).
    fn correction(&self, mode: Brightness, e: usize, global: [f64; 4]) -> (f64, f64) {
        let npx = (self.mesh.h * self.mesh.h) as f64;
        let (fm, fs, gm, gs) = match mode {
            Brightness::None => return (1.0, 0.0),
            Brightness::Global => (global[0], global[1], global[2], global[3]),
            Brightness::PerElement => {
                let [s1, s2, _] = self.elem_g[e];
                let [no, of1, of2] = self.elem_out[e];
                let n = npx - no;
                if n < 1.0 {
                    return (1.0, 0.0);
                }
                let gm = s1 / n;
                let gs = (s2 / n - gm * gm).max(0.0).sqrt();
                let [fm, fsd] = self.f_stats[e];
                if no == 0.0 {
                    (fm, fsd, gm, gs)
                } else {
                    let f1 = fm * npx - of1;
                    let f2 = (fsd * fsd + fm * fm) * npx - of2;
                    let m = f1 / n;
                    (m, (f2 / n - m * m).max(0.0).sqrt(), gm, gs)
                }
            }
        };
        if gs > 1e-9 * (1.0 + gm.abs()) {
            (fs / gs, fm - fs / gs * gm)
        } else {
            (1.0, fm - gm)
        }
    }

    /// Number of ROI pixels inside the deformed image (after [`Self::warp`]).
    fn kept(&self) -> f64 {
        self.gw.len() as f64 - self.elem_out.iter().map(|o| o[0]).sum::<f64>()
    }

    /// Global mean and std of the reference and of the warped image over the pixels inside
    /// the deformed image (for [`Brightness::Global`]): `[f mean, f std, g mean, g std]`.
    fn global_g(&self) -> [f64; 4] {
        let n = self.kept().max(1.0);
        let (s1, s2) = self
            .elem_g
            .iter()
            .fold((0.0, 0.0), |acc, v| (acc.0 + v[0], acc.1 + v[1]));
        let m = s1 / n;
        let (no, o1, o2) = self.elem_out.iter().fold((0.0, 0.0, 0.0), |acc, v| {
            (acc.0 + v[0], acc.1 + v[1], acc.2 + v[2])
        });
        let [fm, fsd] = if no == 0.0 {
            self.f_global
        } else {
            let nall = self.gw.len() as f64;
            let f1 = self.f_global[0] * nall - o1;
            let f2 = (self.f_global[1].powi(2) + self.f_global[0].powi(2)) * nall - o2;
            let fm = f1 / n;
            [fm, (f2 / n - fm * fm).max(0.0).sqrt()]
        };
        [fm, fsd, m, (s2 / n - m * m).max(0.0).sqrt()]
    }

    /// Residual `r = f − (s g + o)` and the element vectors `b_e = Σ (N ∇f) r` (eq. 2), with
    /// `Σ r²` per element in `elem_g[e][2]`.
    fn residual(&mut self, mode: Brightness) {
        let global = self.global_g();
        for e in 0..self.corr.len() {
            self.corr[e] = self.correction(mode, e, global);
        }
        let Level {
            ntab,
            f,
            fx,
            fy,
            gw,
            elem_b,
            elem_g,
            corr,
            mesh,
            ..
        } = self;
        let npx = mesh.h * mesh.h;
        elem_b
            .par_iter_mut()
            .zip(elem_g.par_iter_mut())
            .zip(f.par_chunks(npx))
            .zip(fx.par_chunks(npx))
            .zip(fy.par_chunks(npx))
            .zip(gw.par_chunks(npx))
            .zip(corr.par_iter())
            .for_each(|((((((b, st), fe), fxe), fye), gwe), &(s, o))| {
                let mut bb = [0.0; 8];
                let mut r2 = 0.0;
                for k in 0..npx {
                    if gwe[k].is_nan() {
                        // Outside the deformed image: no residual, no gradient term.
                        continue;
                    }
                    let r = fe[k] - (s * gwe[k] + o);
                    r2 += r * r;
                    let n = &ntab[k];
                    let (rx, ry) = (r * fxe[k], r * fye[k]);
                    for a in 0..4 {
                        bb[2 * a] += n[a] * rx;
                        bb[2 * a + 1] += n[a] * ry;
                    }
                }
                *b = bb;
                st[2] = r2;
            });
    }

    /// Gauss–Newton iterations (eq. 2) from the nodal values `a`, updated in place. Returns
    /// the iterations made, whether the increment fell below `tol`, and the last increment.
    /// Nothing is allocated here.
    fn iterate(
        &mut self,
        g: &BSpline,
        a: &mut [f64],
        mode: Brightness,
        tol: f64,
        max_iter: usize,
        limit: f64,
    ) -> Result<(usize, bool, f64), DicError> {
        let mut inc = f64::INFINITY;
        for it in 1..=max_iter {
            femu_mesh::stop::check()?;
            self.warp(g, a);
            self.residual(mode);
            self.rhs.fill(0.0);
            for (d, b) in self.dofs.iter().zip(&self.elem_b) {
                for i in 0..8 {
                    self.rhs[d[i]] += b[i];
                }
            }
            if let Some((kv, lambda)) = &self.reg {
                self.pattern.mul_vec(kv, a, &mut self.work);
                for (r, w) in self.rhs.iter_mut().zip(&self.work) {
                    *r -= lambda * w;
                }
            }
            self.chol.solve_in_place(&mut self.rhs);
            let sq: f64 = self.rhs.iter().map(|d| d * d).sum();
            // RMS over the nodes of the nodal increment |δa_n| (pixels).
            inc = (2.0 * sq / a.len() as f64).sqrt();
            if !inc.is_finite() {
                return Err(DicError::Diverged(format!(
                    "non-finite displacement increment at iteration {it}"
                )));
            }
            if inc < tol {
                // The last (plain) step: the fixed point itself, not an extrapolation.
                a.iter_mut().zip(&self.rhs).for_each(|(x, d)| *x += d);
                return Ok((it, true, inc));
            }
            self.anderson.update(a, &self.rhs);
            let amax = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if !(amax <= limit) {
                return Err(DicError::Diverged(format!(
                    "at iteration {it} a nodal displacement reached {amax:.1} px, beyond the image size; the images may not show the same scene (try a mask, brightness correction or a regularization length)"
                )));
            }
        }
        Ok((max_iter, false, inc))
    }

    /// After convergence: `M_e` (and `M`) over the pixels inside the deformed image, the
    /// matrix of the objective actually minimized, for the covariance. The iterations keep the
    /// full `M` factorized once: it only preconditions the fixed point `b(a) = 0`, which is the
    /// stationarity of the objective over the pixels inside at `a`. An element with fewer than
    /// [`MIN_INSIDE`] of its pixels inside keeps its full `M_e` so that `M` stays as regular as
    /// without the exclusion; the trust mask marks it `outside-image`.
    fn keep_inside_in_m(&mut self) {
        let npx = self.mesh.h * self.mesh.h;
        for e in 0..self.mesh.n_elements() {
            if self.elem_out[e][0] == 0.0 || !keeps_inside_in_m(&self.elem_out[e], npx) {
                continue;
            }
            let mut me = [0.0f64; 64];
            for k in 0..npx {
                if self.gw[e * npx + k].is_nan() {
                    continue;
                }
                let row = pixel_row(&self.ntab[k], self.fx[e * npx + k], self.fy[e * npx + k]);
                for i in 0..8 {
                    for j in 0..8 {
                        me[i * 8 + j] += row[i] * row[j];
                    }
                }
            }
            let change: [f64; 64] = std::array::from_fn(|i| me[i] - self.elem_m[e][i]);
            add_element(
                &self.pattern,
                &mut self.m_values,
                &self.dofs[e],
                &change,
                1.0,
            );
            self.elem_m[e] = me;
        }
    }

    /// Residual RMS over the ROI's pixels inside the deformed image (after
    /// [`Self::residual`]).
    fn residual_rms(&self) -> f64 {
        let s: f64 = self.elem_g.iter().map(|v| v[2]).sum();
        (s / self.kept().max(1.0)).sqrt()
    }
}

/// The normalized autocorrelation `ρ(dx, dy)` of the converged residual image (speckle-sized
/// for B-mode images, where the decorrelation noise is as large as the speckle), over the lags
/// `|dx| ≤ lx`, `|dy| ≤ ly`, each range ending where `ρ` along that axis falls below
/// [`ResidualCorrelation::CUTOFF`] (at most [`ResidualCorrelation::MAX_LAG`] px).
#[derive(Debug, Clone, serde::Serialize)]
pub struct ResidualCorrelation {
    pub lx: usize,
    pub ly: usize,
    /// `(2 ly + 1) x (2 lx + 1)` values, row `dy + ly`, column `dx + lx`.
    pub rho: Vec<f64>,
}

impl ResidualCorrelation {
    pub const CUTOFF: f64 = 0.05;
    pub const MAX_LAG: usize = 8;

    fn lag(r: &[f32], w: usize, h: usize, dx: i64, dy: i64) -> f64 {
        let (mut s, mut s0) = (0.0f64, 0.0f64);
        for y in 0..h as i64 {
            let y2 = y + dy;
            if y2 < 0 || y2 >= h as i64 {
                continue;
            }
            for x in 0..w as i64 {
                let x2 = x + dx;
                if x2 < 0 || x2 >= w as i64 {
                    continue;
                }
                let a = r[(y * w as i64 + x) as usize] as f64;
                let b = r[(y2 * w as i64 + x2) as usize] as f64;
                if a.is_finite() && b.is_finite() {
                    s += a * b;
                    s0 += a * a;
                }
            }
        }
        if s0 > 0.0 {
            s / s0
        } else {
            0.0
        }
    }

    /// From a residual image (NaN outside the mesh).
    pub fn of(r: &[f32], w: usize, h: usize) -> Self {
        let reach = |axis: usize| {
            (1..=Self::MAX_LAG)
                .find(|&k| {
                    let (dx, dy) = if axis == 0 {
                        (k as i64, 0)
                    } else {
                        (0, k as i64)
                    };
                    Self::lag(r, w, h, dx, dy) < Self::CUTOFF
                })
                .map_or(Self::MAX_LAG, |k| k - 1)
        };
        let (lx, ly) = (reach(0), reach(1));
        let rho = (0..=2 * ly)
            .flat_map(|j| (0..=2 * lx).map(move |i| (i, j)))
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(i, j)| Self::lag(r, w, h, i as i64 - lx as i64, j as i64 - ly as i64))
            .collect();
        ResidualCorrelation { lx, ly, rho }
    }

    #[inline]
    fn at(&self, dx: i64, dy: i64) -> f64 {
        self.rho
            [(dy + self.ly as i64) as usize * (2 * self.lx + 1) + (dx + self.lx as i64) as usize]
    }
}

/// The per-element noise matrices `σ_e² Σ_k Σ_l ρ(x_k − x_l) w_k w_lᵀ` (pixel pairs within the
/// element: the pairs that straddle two elements are left out, which underestimates the
/// variance by the share of pixels within a correlation length of an element edge).
fn noise_matrices(level: &Level, variance: &[f64], rho: &ResidualCorrelation) -> Vec<[f64; 64]> {
    let h = level.mesh.h;
    let npx = h * h;
    (0..level.mesh.n_elements())
        .into_par_iter()
        .map(|e| {
            let keep_all =
                level.elem_out[e][0] == 0.0 || !keeps_inside_in_m(&level.elem_out[e], npx);
            let w = |k: usize| {
                if !keep_all && level.gw[e * npx + k].is_nan() {
                    // Left out of the residual: no noise from it either.
                    return [0.0; 8];
                }
                pixel_row(&level.ntab[k], level.fx[e * npx + k], level.fy[e * npx + k])
            };
            let mut m = [0.0f64; 64];
            for k in 0..npx {
                let (kx, ky) = ((k % h) as i64, (k / h) as i64);
                let wk = w(k);
                let mut acc = [0.0; 8];
                for dy in -(rho.ly as i64)..=rho.ly as i64 {
                    let ly = ky + dy;
                    if ly < 0 || ly >= h as i64 {
                        continue;
                    }
                    for dx in -(rho.lx as i64)..=rho.lx as i64 {
                        let lx = kx + dx;
                        if lx < 0 || lx >= h as i64 {
                            continue;
                        }
                        let c = rho.at(dx, dy);
                        let wl = w((ly * h as i64 + lx) as usize);
                        for b in 0..8 {
                            acc[b] += c * wl[b];
                        }
                    }
                }
                for a in 0..8 {
                    for b in 0..8 {
                        m[a * 8 + b] += wk[a] * acc[b];
                    }
                }
            }
            for v in m.iter_mut() {
                *v *= variance[e];
            }
            m
        })
        .collect()
}

/// Smallest fraction of an element's pixels inside the deformed image for its pixels outside
/// to be left out of `M_e` and of its noise matrix (below it the element is not trusted:
/// [`crate::quality::Trust::OutsideImage`]).
pub const MIN_INSIDE: f64 = 0.5;

fn keeps_inside_in_m(out: &[f64; 3], npx: usize) -> bool {
    1.0 - out[0] / npx as f64 >= MIN_INSIDE
}

/// The row `(N0 fx, N0 fy, N1 fx, N1 fy, ...)` of one pixel: the shape functions `n` at the
/// pixel times the reference gradient `(gx, gy)` (eq. 2's `N ∇f`).
#[inline]
fn pixel_row(n: &[f64; 4], gx: f64, gy: f64) -> [f64; 8] {
    let mut row = [0.0; 8];
    for a in 0..4 {
        row[2 * a] = n[a] * gx;
        row[2 * a + 1] = n[a] * gy;
    }
    row
}

/// Adds `factor` times the 8 x 8 element matrix `me` (row-major) at the element's `dofs` into
/// `values`, stored on `pattern`.
pub(crate) fn add_element(
    pattern: &CscPattern,
    values: &mut [f64],
    dofs: &[usize; 8],
    me: &[f64; 64],
    factor: f64,
) {
    for i in 0..8 {
        for j in 0..8 {
            let pos = pattern
                .position(dofs[i], dofs[j])
                .expect("element entry in the pattern");
            values[pos] += factor * me[i * 8 + j];
        }
    }
}

/// Number of automatic pyramid levels: up to 2 while the reduced ROI holds 2 x 2 elements.
fn auto_levels(bb_w: usize, bb_h: usize, h: usize) -> usize {
    let mut l = 0;
    while l < 2 && bb_w >> (l + 1) >= 2 * h && bb_h >> (l + 1) >= 2 * h {
        l += 1;
    }
    l
}

/// Grey-level standard deviation over the pixels of a rectangle.
fn std_over(img: &GreyImage, x: usize, y: usize, w: usize, h: usize) -> f64 {
    let n = (w * h) as f64;
    let mut s1 = 0.0;
    let mut s2 = 0.0;
    for j in y..y + h {
        for v in &img.data[j * img.width + x..j * img.width + x + w] {
            s1 += v;
            s2 += v * v;
        }
    }
    let m = s1 / n;
    (s2 / n - m * m).max(0.0).sqrt()
}

/// Nodal values on `fine` from the field `u` on `coarse`, `k` pyramid levels above: a coarse
/// pixel centre `x_c` sits at `x = 2^k x_c + (2^k − 1)/2` in fine pixels, so
/// `u_fine(x) = 2^k u_coarse((x − (2^k − 1)/2) / 2^k)`; nodes outside the coarse mesh take the
/// value of the nearest coarse node.
fn prolong(coarse: &DicMesh, u: &[f64], fine: &DicMesh, k: usize) -> Vec<f64> {
    let f = (1usize << k) as f64;
    let off = 0.5 * (f - 1.0);
    let uc: Vec<[f64; 2]> = u.chunks(2).map(|c| [c[0], c[1]]).collect();
    let mut out = Vec::with_capacity(2 * fine.n_nodes());
    for p in &fine.nodes {
        let (xc, yc) = ((p[0] - off) / f, (p[1] - off) / f);
        let v = coarse.interpolate(&uc, xc, yc).unwrap_or_else(|| {
            let mut best = (f64::INFINITY, [0.0; 2]);
            for (q, val) in coarse.nodes.iter().zip(&uc) {
                let d = (q[0] - xc).powi(2) + (q[1] - yc).powi(2);
                if d < best.0 {
                    best = (d, *val);
                }
            }
            best.1
        });
        out.push(f * v[0]);
        out.push(f * v[1]);
    }
    out
}

/// Measures the displacement from `reference` to `deformed` over `roi` (global Q4 DIC, see the
/// module documentation). Input errors (sizes, ROI, element size, no texture) are reported
/// before any computation; a run that does not reach the tolerance returns its last field with
/// `converged = false`.
pub fn correlate(
    reference: &GreyImage,
    deformed: &GreyImage,
    roi: &Roi,
    opts: &DicOptions,
) -> Result<DicResult, DicError> {
    correlate_from(reference, deformed, roi, opts, None)
}

/// A displacement guess `u(x)` (full-resolution pixels) at a pixel position `x` of the
/// reference image.
pub type InitialGuess<'a> = &'a (dyn Fn([f64; 2]) -> [f64; 2] + Sync);

/// [`correlate`] started from `initial` instead of the FFT shift: the coarsest level's nodes
/// take the guess at their full-resolution position (a sequence's previous increment: a warm
/// start that keeps a large motion within the capture range).
pub fn correlate_from(
    reference: &GreyImage,
    deformed: &GreyImage,
    roi: &Roi,
    opts: &DicOptions,
    initial: Option<InitialGuess>,
) -> Result<DicResult, DicError> {
    correlate_with(reference, deformed, roi, opts, initial, true)
}

/// [`correlate`] for a rung of the automatic choice ([`crate::auto`]), which rejects a field
/// that did not converge whatever its quality: such a result skips what only the quality of a
/// kept field reads, its `element_texture`, `residual_image` and `system.elem_m_noise` being
/// empty and its `system.residual_correlation` the trivial one (no lag).
pub(crate) fn correlate_rung(
    reference: &GreyImage,
    deformed: &GreyImage,
    roi: &Roi,
    opts: &DicOptions,
) -> Result<DicResult, DicError> {
    correlate_with(reference, deformed, roi, opts, None, false)
}

/// [`correlate_from`]; `unconverged_diagnostics` false: see [`correlate_rung`].
fn correlate_with(
    reference: &GreyImage,
    deformed: &GreyImage,
    roi: &Roi,
    opts: &DicOptions,
    initial: Option<InitialGuess>,
    unconverged_diagnostics: bool,
) -> Result<DicResult, DicError> {
    let t0 = Instant::now();
    opts.validate()?;
    if (reference.width, reference.height) != (deformed.width, deformed.height) {
        return Err(DicError::SizeMismatch {
            reference: (reference.width, reference.height),
            deformed: (deformed.width, deformed.height),
        });
    }
    let (width, height) = (reference.width, reference.height);
    let h = opts.element_size;
    // Mesh first: ROI and element-size errors before any work.
    let fine_mesh = DicMesh::new(roi, width, height, h)?;
    let bb = roi.bounding_box(width, height)?;
    let (mx, my) = (fine_mesh.nx * h, fine_mesh.ny * h);
    if std_over(deformed, bb.x, bb.y, mx, my) < 1e-6 {
        return Err(DicError::NoTexture(
            "the deformed image is uniform over the region of interest: there is nothing to correlate".into(),
        ));
    }
    let n_levels = opts
        .pyramid_levels
        .unwrap_or_else(|| auto_levels(mx, my, h));
    // Pyramid of images and ROIs.
    let mut refs = vec![reference.clone()];
    let mut defs = vec![deformed.clone()];
    let mut rois = vec![roi.clone()];
    for l in 0..n_levels {
        refs.push(refs[l].half());
        defs.push(defs[l].half());
        rois.push(rois[l].half());
    }
    let mut timings = Timings::default();
    let splines: Vec<BSpline> = defs
        .par_iter()
        .map(|d| BSpline::new(&d.data, d.width, d.height))
        .collect();
    // FFT integer shift on the coarsest level that has a valid ROI.
    let mut shift_px = (0i64, 0i64);
    if opts.fft_init && initial.is_none() {
        for l in (0..=n_levels).rev() {
            if let Ok(b) = rois[l].bounding_box(refs[l].width, refs[l].height) {
                if b.w >= 8 && b.h >= 8 {
                    let crop = |img: &GreyImage| -> Vec<f64> {
                        (b.y..b.y + b.h)
                            .flat_map(|j| {
                                img.data[j * img.width + b.x..j * img.width + b.x + b.w]
                                    .iter()
                                    .copied()
                            })
                            .collect()
                    };
                    let s = crate::fft::integer_shift(&crop(&refs[l]), &crop(&defs[l]), b.w, b.h);
                    shift_px = (s.0 << l, s.1 << l);
                    break;
                }
            }
        }
    }
    timings.preparation_s = t0.elapsed().as_secs_f64();
    let limit = (width.max(height)) as f64;
    let mut levels = Vec::new();
    // The field carried from level to level: (mesh, nodal values) in that level's pixels.
    let mut carried: Option<(DicMesh, Vec<f64>, usize)> = None;
    let mut finest: Option<(Level, Vec<f64>, usize, bool, f64)> = None;
    for l in (0..=n_levels).rev() {
        let ts = Instant::now();
        let level = Level::new(
            &refs[l],
            &rois[l],
            h,
            // The same physical length on every level, but at least 4 elements: a shorter
            // plane wave is aliased on the node grid and would give a meaningless weight λ.
            opts.regularization_length.map(|v| {
                if l == 0 {
                    v
                } else {
                    (v / (1 << l) as f64).max(4.0 * h as f64)
                }
            }),
            opts.acceleration_depth,
        );
        let mut level = match level {
            Ok(lv) => lv,
            Err(e) if l > 0 => {
                levels.push(LevelReport {
                    level: l,
                    elements: 0,
                    nodes: 0,
                    iterations: 0,
                    converged: false,
                    last_increment_px: f64::NAN,
                    residual_rms: f64::NAN,
                    skipped: Some(e.to_string()),
                });
                continue;
            }
            Err(e) => return Err(e),
        };
        timings.setup_s += ts.elapsed().as_secs_f64();
        let ti = Instant::now();
        let mut a = match &carried {
            Some((mesh, u, from)) => prolong(mesh, u, &level.mesh, from - l),
            None => match initial {
                // Level `l` pixel `p` is full-resolution `f p + (f − 1)/2` ([`prolong`]).
                Some(guess) => {
                    let f = (1usize << l) as f64;
                    let off = 0.5 * (f - 1.0);
                    level
                        .mesh
                        .nodes
                        .iter()
                        .flat_map(|p| {
                            let u = guess([f * p[0] + off, f * p[1] + off]);
                            [u[0] / f, u[1] / f]
                        })
                        .collect()
                }
                None => {
                    let s = ((shift_px.0 >> l) as f64, (shift_px.1 >> l) as f64);
                    (0..level.mesh.n_nodes()).flat_map(|_| [s.0, s.1]).collect()
                }
            },
        };
        let (tol, max_iter) = if l == 0 {
            (opts.tolerance, opts.max_iterations)
        } else {
            (opts.tolerance.max(1e-2), opts.max_iterations.min(30))
        };
        let (its, conv, inc) = level.iterate(
            &splines[l],
            &mut a,
            opts.brightness,
            tol,
            max_iter,
            limit / (1 << l) as f64,
        )?;
        timings.iterations_s += ti.elapsed().as_secs_f64();
        level.warp(&splines[l], &a);
        level.residual(opts.brightness);
        levels.push(LevelReport {
            level: l,
            elements: level.mesh.n_elements(),
            nodes: level.mesh.n_nodes(),
            iterations: its,
            converged: conv,
            last_increment_px: inc,
            residual_rms: level.residual_rms(),
            skipped: None,
        });
        if l == 0 {
            finest = Some((level, a, its, conv, inc));
        } else {
            carried = Some((level.mesh.clone(), a, l));
        }
    }
    let (mut level, a, iterations, converged, last_increment_px) =
        finest.expect("level 0 is always built or returns an error");
    // Diagnostics on the finest level.
    let npx = h * h;
    let ne = level.mesh.n_elements();
    let element_residual: Vec<f64> = level
        .elem_g
        .iter()
        .zip(&level.elem_out)
        .map(|(v, o)| (v[2] / (npx as f64 - o[0]).max(1.0)).sqrt())
        .collect();
    let mut sorted = element_residual.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let median = sorted[ne / 2];
    let flagged: Vec<bool> = element_residual
        .iter()
        .map(|&r| r > opts.flag_factor * median)
        .collect();
    // What only the quality of a kept field reads.
    let diagnostics = converged || unconverged_diagnostics;
    let element_texture: Vec<ElementTexture> = (0..ne)
        .filter(|_| diagnostics)
        .map(|e| {
            let r = e * npx..(e + 1) * npx;
            let (s, o) = level.corr[e];
            let g: Vec<f64> = level.gw[r.clone()].iter().map(|g| s * g + o).collect();
            ElementTexture::of(&level.f[r.clone()], &level.fx[r.clone()], &level.fy[r], &g)
        })
        .collect();
    let mut residual_image = vec![f32::NAN; if diagnostics { width * height } else { 0 }];
    for e in (0..ne).filter(|_| diagnostics) {
        let (px, py) = level.mesh.element_origin(e);
        let (s, o) = level.corr[e];
        for k in 0..npx {
            // NaN (left out) where the warped position leaves the deformed image.
            let r = level.f[e * npx + k] - (s * level.gw[e * npx + k] + o);
            residual_image[(py + k / h) * width + px + k % h] = r as f32;
        }
    }
    let element_variance: Vec<f64> = element_residual.iter().map(|r| r * r).collect();
    let (rho, elem_m_noise) = if diagnostics {
        let rho = ResidualCorrelation::of(&residual_image, width, height);
        let noise = noise_matrices(&level, &element_variance, &rho);
        (rho, noise)
    } else {
        let rho = ResidualCorrelation {
            lx: 0,
            ly: 0,
            rho: vec![1.0],
        };
        (rho, Vec::new())
    };
    let (fmin, fmax) = level
        .f
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let residual_rms = level.residual_rms();
    if diagnostics {
        level.keep_inside_in_m();
    }
    timings.total_s = t0.elapsed().as_secs_f64();
    let system = GaussNewtonSystem {
        reg_values: level
            .reg
            .as_ref()
            .map(|(k, lambda)| k.iter().map(|v| lambda * v).collect()),
        lambda: level.reg.as_ref().map(|r| r.1),
        pattern: level.pattern,
        m_values: level.m_values,
        elem_m: level.elem_m,
        elem_m_noise,
        residual_correlation: rho,
        dofs: level.dofs,
    };
    Ok(DicResult {
        system,
        element_texture,
        displacement: a.chunks(2).map(|c| [c[0], c[1]]).collect(),
        iterations,
        converged,
        last_increment_px,
        residual_rms,
        residual_percent: 100.0 * residual_rms / (fmax - fmin).max(1e-12),
        element_residual,
        flagged,
        residual_image,
        initial_shift: shift_px,
        levels,
        timings,
        image_size: (width, height),
        mesh: level.mesh,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lab::{self, Speckle};
    use crate::mesh::Rect;

    /// A small speckle level: 64 x 64 image, ROI 16..48, 8 px elements (16 nodes x 2).
    fn small() -> (GreyImage, Level) {
        let s = Speckle::new(64, 64, 1.5, 5);
        let f = s.reference();
        let roi = Roi::Rect(Rect {
            x: 16,
            y: 16,
            w: 32,
            h: 32,
        });
        let level = Level::new(&f, &roi, 8, None, 0).unwrap();
        (f, level)
    }

    /// Residual vector `f − g(x + u)` (no brightness correction) at nodal values `a`.
    fn residuals(level: &mut Level, g: &BSpline, a: &[f64]) -> Vec<f64> {
        level.warp(g, a);
        level.f.iter().zip(&level.gw).map(|(f, g)| f - g).collect()
    }

    /// `M` (eq. 2) equals `JᵀJ` with `J = ∂r/∂a` by central finite differences at `u = 0`
    /// when the deformed image is the reference (there `∇g = ∇f` exactly). Step 1e-4 px:
    /// truncation O(ε²) ~ 1e-8 relative, well below the 1e-5 tolerance.
    #[test]
    fn hessian_matches_finite_difference_jacobian() {
        let (f, mut level) = small();
        let g = BSpline::new(&f.data, f.width, f.height);
        let n = 2 * level.mesh.n_nodes();
        let eps = 1e-4;
        let jac: Vec<Vec<f64>> = (0..n)
            .map(|q| {
                let mut a = vec![0.0; n];
                a[q] = eps;
                let rp = residuals(&mut level, &g, &a);
                a[q] = -eps;
                let rm = residuals(&mut level, &g, &a);
                rp.iter()
                    .zip(&rm)
                    .map(|(p, m)| (p - m) / (2.0 * eps))
                    .collect()
            })
            .collect();
        let scale = level.m_values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for p in 0..n {
            for q in 0..n {
                let jtj: f64 = jac[p].iter().zip(&jac[q]).map(|(a, b)| a * b).sum();
                let m = level
                    .pattern
                    .position(p, q)
                    .map_or(0.0, |k| level.m_values[k]);
                assert!(
                    (m - jtj).abs() < 1e-5 * scale,
                    "M[{p},{q}] = {m}, JᵀJ = {jtj}"
                );
            }
        }
    }

    /// The gradient of the cost (1), `∂Φ/∂a_i = −2 Σ r N_i ∇g(x + u)`, against central finite
    /// differences of Φ at a non-trivial field on a translated pair; and the modified
    /// Gauss–Newton right-hand side `b` (eq. 2) equals `−½ ∂Φ/∂a` up to the replacement of
    /// `∇g(x + u)` by `∇f(x)`, i.e. exactly at the solution of a pure translation.
    #[test]
    fn cost_gradient_matches_finite_differences() {
        let s = Speckle::new(64, 64, 1.5, 5);
        let f = s.reference();
        let gi = s.deformed(&lab::translation(0.3, -0.2));
        let roi = Roi::Rect(Rect {
            x: 16,
            y: 16,
            w: 32,
            h: 32,
        });
        let mut level = Level::new(&f, &roi, 8, None, 0).unwrap();
        let g = BSpline::new(&gi.data, gi.width, gi.height);
        let n = 2 * level.mesh.n_nodes();
        let a0: Vec<f64> = (0..n)
            .map(|q| 0.1 * ((q * 7 % 5) as f64 - 2.0) + if q % 2 == 0 { 0.3 } else { -0.2 })
            .collect();
        let cost = |level: &mut Level, a: &[f64]| {
            residuals(level, &g, a).iter().map(|r| r * r).sum::<f64>()
        };
        // Analytic gradient.
        let r = residuals(&mut level, &g, &a0);
        let h = level.mesh.h;
        let npx = h * h;
        let mut grad = vec![0.0; n];
        for e in 0..level.mesh.n_elements() {
            let (px, py) = level.mesh.element_origin(e);
            let c = level.mesh.conn[e];
            for k in 0..npx {
                let nn = level.ntab[k];
                let (mut ux, mut uy) = (0.0, 0.0);
                for i in 0..4 {
                    ux += nn[i] * a0[2 * c[i]];
                    uy += nn[i] * a0[2 * c[i] + 1];
                }
                let (_, gx, gy) = g.eval_grad((px + k % h) as f64 + ux, (py + k / h) as f64 + uy);
                for i in 0..4 {
                    grad[2 * c[i]] += -2.0 * r[e * npx + k] * nn[i] * gx;
                    grad[2 * c[i] + 1] += -2.0 * r[e * npx + k] * nn[i] * gy;
                }
            }
        }
        let eps = 1e-5;
        for q in 0..n {
            let mut a = a0.clone();
            a[q] += eps;
            let cp = cost(&mut level, &a);
            a[q] -= 2.0 * eps;
            let cm = cost(&mut level, &a);
            let fd = (cp - cm) / (2.0 * eps);
            assert!(
                (fd - grad[q]).abs() < 1e-5 * (1.0 + grad[q].abs()) + 1e-3,
                "dof {q}: {fd} vs {}",
                grad[q]
            );
        }
        // At the exact translation, b (eq. 2) and the cost gradient both vanish to the
        // interpolation error: both are small against their scale at a0.
        let exact: Vec<f64> = (0..n)
            .map(|q| if q % 2 == 0 { 0.3 } else { -0.2 })
            .collect();
        level.warp(&g, &exact);
        level.residual(Brightness::None);
        let b_max = level
            .elem_b
            .iter()
            .flat_map(|b| b.iter())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let g_max = grad.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(
            b_max < 0.01 * g_max,
            "b at the solution {b_max} vs gradient scale {g_max}"
        );
    }

    /// The Gauss–Newton Hessian of the whole cost, `2 (M + λK)`, against central second
    /// differences of `Φ(a) + λ aᵀKa` (eq. 1 and 3) at the solution of a noise-free translation
    /// (there `r ≈ 0`, so the term `Σ r ∇²r` that Gauss–Newton drops vanishes to the
    /// interpolation error). Step 1e-3 px: truncation O(ε²) relative ~1e-6; the tolerance 2 % of
    /// the largest entry covers the remaining residual term (r is the B-spline interpolation
    /// error, ~1e-2 grey levels here).
    #[test]
    fn regularized_hessian_matches_second_differences_of_the_cost() {
        let s = Speckle::new(64, 64, 1.5, 9);
        let f = s.reference();
        let (tx, ty) = (0.3, -0.2);
        let gi = s.deformed(&lab::translation(tx, ty));
        let roi = Roi::Rect(Rect {
            x: 16,
            y: 16,
            w: 32,
            h: 32,
        });
        let mut level = Level::new(&f, &roi, 8, Some(16.0), 0).unwrap();
        let g = BSpline::new(&gi.data, gi.width, gi.height);
        let n = 2 * level.mesh.n_nodes();
        let (kv, lambda) = level.reg.clone().expect("regularized");
        let cost = |level: &mut Level, a: &[f64]| {
            let r2: f64 = residuals(level, &g, a).iter().map(|r| r * r).sum();
            r2 + lambda * crate::sparse::quadratic_form(&level.pattern, &kv, a)
        };
        let a0: Vec<f64> = (0..n).map(|q| if q % 2 == 0 { tx } else { ty }).collect();
        let eps = 1e-3;
        let scale = level
            .m_values
            .iter()
            .zip(&kv)
            .fold(0.0f64, |m, (a, k)| m.max((a + lambda * k).abs()));
        let mut worst = 0.0f64;
        for p in 0..n {
            for q in 0..=p {
                let mut a = a0.clone();
                let mut at = |dp: f64, dq: f64| {
                    a.copy_from_slice(&a0);
                    a[p] += dp;
                    a[q] += dq;
                    cost(&mut level, &a)
                };
                let fd = (at(eps, eps) - at(eps, -eps) - at(-eps, eps) + at(-eps, -eps))
                    / (4.0 * eps * eps);
                let analytic = 2.0
                    * level
                        .pattern
                        .position(p, q)
                        .map_or(0.0, |k| level.m_values[k] + lambda * kv[k]);
                worst = worst.max((fd - analytic).abs() / (2.0 * scale));
            }
        }
        assert!(worst < 0.02, "largest relative difference {worst}");
    }

    /// A ladder rung's correlation is the correlation: the same field, iterations and residual;
    /// only a rung that did not converge skips the diagnostics of the quality (empty).
    #[test]
    fn rung_correlation_is_the_correlation_without_unused_diagnostics() {
        let s = Speckle::new(96, 96, 1.5, 3);
        let f = s.reference();
        let g = s.deformed(&lab::translation(0.4, -0.3));
        let roi = Roi::Rect(Rect {
            x: 16,
            y: 16,
            w: 64,
            h: 64,
        });
        for max_iterations in [2, 100] {
            let o = DicOptions {
                element_size: 16,
                max_iterations,
                tolerance: 1e-4,
                ..Default::default()
            };
            let full = correlate(&f, &g, &roi, &o).unwrap();
            let rung = correlate_rung(&f, &g, &roi, &o).unwrap();
            assert_eq!(full.displacement, rung.displacement);
            assert_eq!(full.iterations, rung.iterations);
            assert_eq!(full.converged, rung.converged);
            assert_eq!(full.residual_rms, rung.residual_rms);
            assert_eq!(full.element_residual, rung.element_residual);
            assert_eq!(full.converged, max_iterations == 100, "{}", full.iterations);
            if full.converged {
                assert_eq!(full.residual_image.len(), rung.residual_image.len());
                assert_eq!(full.system.elem_m_noise, rung.system.elem_m_noise);
            } else {
                assert!(rung.residual_image.is_empty() && rung.element_texture.is_empty());
                assert!(rung.system.elem_m_noise.is_empty());
                assert!(!full.system.elem_m_noise.is_empty());
            }
        }
    }

    /// Pixels whose warped position leaves the deformed image are left out of the sums. The
    /// whole image as the ROI and a field that carries the border up to 2.4 px out of the frame
    /// (the speckle continues beyond it in the deformed image, as a camera's would): the
    /// unregularized correlation converges and every node, the border's included, stays within
    /// 0.1 px of the true field. Reading the B-spline's mirror extension there instead pulled
    /// the border nodes 5 px away (on a 1024 x 1024 pair, by up to 245 px, and the iterations
    /// did not converge).
    #[test]
    fn pixels_warped_outside_the_image_are_left_out() {
        let s = Speckle::new(128, 128, 1.5, 11);
        let f = s.reference();
        let u = lab::affine([0.35, -0.45], [[0.02, 0.01], [-0.015, 0.025]], [64.0, 64.0]);
        let g = s.deformed(&u);
        let roi = Roi::Rect(Rect {
            x: 0,
            y: 0,
            w: 128,
            h: 128,
        });
        let o = DicOptions {
            element_size: 16,
            acceleration_depth: crate::anderson::DEFAULT_DEPTH,
            ..Default::default()
        };
        let res = correlate(&f, &g, &roi, &o).unwrap();
        assert!(
            res.converged,
            "{} iterations, last increment {} px",
            res.iterations, res.last_increment_px
        );
        let worst = res
            .mesh
            .nodes
            .iter()
            .zip(&res.displacement)
            .map(|(p, d)| {
                let t = u(p[0], p[1]);
                (d[0] - t[0]).hypot(d[1] - t[1])
            })
            .fold(0.0f64, f64::max);
        assert!(worst < 0.1, "largest nodal error {worst} px");
        // The border elements whose pixels leave the frame report it: at most 3 of the 16
        // columns and 2 of the 16 rows of a corner element (|ux| < 2.3 px, |uy| < 1.1 px;
        // 1 − 13·14/256 = 29 % of its pixels) leave.
        assert!(res.element_texture.iter().any(|t| t.inside < 1.0));
        let least = res
            .element_texture
            .iter()
            .map(|t| t.inside)
            .fold(1.0f64, f64::min);
        assert!(least >= 0.7, "{least}");
    }

    #[test]
    fn uniform_images_and_bad_options_are_refused() {
        let flat = GreyImage::new(64, 64, vec![100.0; 64 * 64]).unwrap();
        let s = Speckle::new(64, 64, 1.5, 1).reference();
        let roi = Roi::Rect(Rect {
            x: 0,
            y: 0,
            w: 64,
            h: 64,
        });
        let o = DicOptions::default();
        let e = correlate(&flat, &s, &roi, &o).unwrap_err();
        assert!(matches!(e, DicError::NoTexture(_)), "{e}");
        let e = correlate(&s, &flat, &roi, &o).unwrap_err();
        assert!(matches!(e, DicError::NoTexture(_)), "{e}");
        let small = GreyImage::new(32, 64, vec![1.0; 32 * 64]).unwrap();
        assert!(matches!(
            correlate(&s, &small, &roi, &o),
            Err(DicError::SizeMismatch { .. })
        ));
        let bad = DicOptions {
            tolerance: -1.0,
            ..Default::default()
        };
        assert!(matches!(
            correlate(&s, &s, &roi, &bad),
            Err(DicError::Option { .. })
        ));
        // A textureless patch inside a textured image: refused, naming the element.
        // (32 x 32 px flat corner: element 0 is 16 px from any texture, where the B-spline
        // gradient has decayed as 0.27^16 ~ 1e-9.)
        let mut patched = s.clone();
        for y in 0..32 {
            for x in 0..32 {
                patched.data[y * 64 + x] = 50.0;
            }
        }
        match correlate(&patched, &patched, &roi, &o) {
            Err(e) => assert!(e.to_string().contains("element 0"), "{e}"),
            Ok(_) => panic!("a textureless element was accepted"),
        }
    }
}
