//! How good a measured field is: the nodal covariance from the Gauss–Newton system and the
//! grey-level noise, per-point standard deviations, and the mask of the elements not to trust.
//!
//! **Covariance.** At convergence the nodal values solve `A a = b(a) + …` with
//! `A = M + λK` (eq. 2–3 of [`crate::solver`]). A grey-level perturbation `η(x)` of the residual
//! (image noise, speckle decorrelation) moves them by `δa = A⁻¹ Σ_x (N ∇f)(x) η(x)`; with `η`
//! independent from pixel to pixel, of variance `σ_e²` in element `e`, the covariance is the
//! sandwich
//!
//! ```text
//! C = A⁻¹ M_σ A⁻¹,   M_σ = Σ_e σ_e² M_e                                                  (4)
//! ```
//!
//! (Besnard, Hild & Roux 2006; Leclerc et al. 2009 for the regularized case). Without
//! regularization and with one `σ` everywhere it is the familiar `C = σ² M⁻¹`. `σ_e²` is the
//! variance of the converged residual `f − g̃(x + u)` over the element, i.e. the noise of both
//! images together (`2σ²` for independent noise of variance `σ²` in each), estimated from the
//! frame pair itself, so decorrelated elements get large variances. The virtual lab checks (4)
//! against the scatter of many noise realizations (`tests/covariance.rs`).
//!
//! `C` is dense; what is computed here is its restriction to the pattern of `A` (the
//! covariances between equations that share an element or a regularization row), which holds
//! every nodal 2 x 2 block and what a point inside an element needs, from the selected inverse
//! of `A + t M_σ` differentiated in `t` ([`crate::selected`]): about three sparse
//! factorizations, no column of `C`.
//!
//! **Trust.** An element is not to be trusted when its corrected deformed image does not match
//! the reference (zero-normalized cross-correlation below [`TrustCriteria::min_zncc`]:
//! decorrelated speckle, out-of-plane motion), when its residual is flagged (above
//! `flag_factor` times the median), when it lies in a shadow (grey-level standard deviation
//! below [`TrustCriteria::min_std_fraction`] of the median element's), or when the predicted
//! standard deviation of one of its nodes exceeds [`TrustCriteria::max_sd_factor`] times the
//! median (too little texture, or texture along one direction only).

use crate::error::DicError;
use crate::solver::{add_element, DicResult};
use crate::sparse::Cholesky;
use rayon::prelude::*;

/// The nodal covariance (eq. 4) on the pattern of the Gauss–Newton matrix.
#[derive(Debug, Clone)]
pub struct NodalCovariance {
    /// `σ_e²` per element (grey levels²).
    pub element_variance: Vec<f64>,
    /// `C` on `res.system.pattern` (pixels²).
    pub values: Vec<f64>,
    /// Per node: standard deviations of ux, uy (pixels) and their correlation coefficient.
    pub node: Vec<NodeSd>,
}

/// Standard deviations of one node (pixels) and the correlation of its two components.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct NodeSd {
    pub sd_ux_px: f64,
    pub sd_uy_px: f64,
    pub corr_xy: f64,
}

/// `M_σ = Σ_e σ_e² M_e` on the pattern of the system.
pub fn noise_weighted_matrix(res: &DicResult, element_variance: &[f64]) -> Vec<f64> {
    let sys = &res.system;
    let mut v = vec![0.0; sys.pattern.nnz()];
    for ((d, me), &s2) in sys.dofs.iter().zip(&sys.elem_m).zip(element_variance) {
        add_element(&sys.pattern, &mut v, d, me, s2);
    }
    v
}

/// The covariance (eq. 4) with `σ_e²` the residual variance of each element and the residual's
/// spatial correlation (`res.system.elem_m_noise`).
pub fn covariance(res: &DicResult) -> Result<NodalCovariance, DicError> {
    let var: Vec<f64> = res.element_residual.iter().map(|r| r * r).collect();
    sandwich(res, &var, &noise_matrix(res))
}

/// `M_σ` assembled from the per-element noise matrices (`res.system.elem_m_noise`).
pub fn noise_matrix(res: &DicResult) -> Vec<f64> {
    let sys = &res.system;
    let mut m_sigma = vec![0.0; sys.pattern.nnz()];
    for (d, me) in sys.dofs.iter().zip(&sys.elem_m_noise) {
        add_element(&sys.pattern, &mut m_sigma, d, me, 1.0);
    }
    m_sigma
}

/// The covariance (eq. 4) for given element noise variances `σ_e²` (grey levels²) and white
/// noise (no spatial correlation).
pub fn covariance_with(
    res: &DicResult,
    element_variance: &[f64],
) -> Result<NodalCovariance, DicError> {
    let m_sigma = noise_weighted_matrix(res, element_variance);
    sandwich(res, element_variance, &m_sigma)
}

/// The covariance an unregularized Q4 DIC would have on the same images and mesh,
/// `M⁻¹ M_σ M⁻¹` (the same noise, `λ = 0`): the expected scatter of a DIC without
/// regularization (muDIC, for instance) where it converges to the same minimum.
pub fn covariance_unregularized(res: &DicResult) -> Result<NodalCovariance, DicError> {
    let var: Vec<f64> = res.element_residual.iter().map(|r| r * r).collect();
    let m = res.system.m_values.clone();
    sandwich_with(res, &var, &noise_matrix(res), &m)
}

/// `C = A⁻¹ M_σ A⁻¹` on the pattern of `A`.
fn sandwich(
    res: &DicResult,
    element_variance: &[f64],
    m_sigma: &[f64],
) -> Result<NodalCovariance, DicError> {
    sandwich_with(res, element_variance, m_sigma, &res.system.a_values())
}

/// `C = A⁻¹ M_σ A⁻¹` for the matrix `a_values` on the pattern of the system.
fn sandwich_with(
    res: &DicResult,
    element_variance: &[f64],
    m_sigma: &[f64],
    a_values: &[f64],
) -> Result<NodalCovariance, DicError> {
    let sys = &res.system;
    let p = &sys.pattern;
    let n = p.n;
    femu_mesh::stop::check()?;
    let values = crate::selected::sandwich_on_pattern(p, a_values, m_sigma)?;
    let at = |r: usize, c: usize| p.position(r, c).map_or(0.0, |k| values[k]);
    let node = (0..n / 2)
        .map(|q| {
            let (vx, vy, cxy) = (
                at(2 * q, 2 * q),
                at(2 * q + 1, 2 * q + 1),
                at(2 * q, 2 * q + 1),
            );
            NodeSd {
                sd_ux_px: vx.max(0.0).sqrt(),
                sd_uy_px: vy.max(0.0).sqrt(),
                corr_xy: if vx > 0.0 && vy > 0.0 {
                    cxy / (vx * vy).sqrt()
                } else {
                    0.0
                },
            }
        })
        .collect();
    Ok(NodalCovariance {
        element_variance: element_variance.to_vec(),
        values,
        node,
    })
}

/// The covariance `P C Pᵀ` of linear combinations of the nodal values, `C = A⁻¹ M_σ A⁻¹`
/// (eq. 4) in full (not restricted to the pattern of `A`): `rows` are `m` row vectors over the
/// equations, each a sparse list of `(equation, weight)` (a grid point's component is the four
/// shape-function weights of its element's nodes; a node's component is one entry). Returns
/// the `m x m` matrix row-major (pixels²). Costs two block solves with `m` columns and `m`
/// products by `M_σ`.
pub fn combined_covariance(
    pattern: &crate::sparse::CscPattern,
    a_values: &[f64],
    m_sigma: &[f64],
    rows: &[Vec<(usize, f64)>],
) -> Result<Vec<f64>, DicError> {
    let n = pattern.n;
    let m = rows.len();
    let chol = Cholesky::factorize(pattern, a_values)?;
    // Z = A⁻¹ Pᵀ, Y = M_σ Z, then (P C Pᵀ)_ij = (A⁻¹ P_iᵀ)ᵀ M_σ (A⁻¹ P_jᵀ) = Z_iᵀ Y_j.
    const BLOCK: usize = 64;
    let blocks: Vec<(Vec<f64>, Vec<f64>)> = (0..m.div_ceil(BLOCK))
        .into_par_iter()
        .map(|blk| {
            let j0 = blk * BLOCK;
            let nc = BLOCK.min(m - j0);
            let mut z = vec![0.0; n * nc];
            for c in 0..nc {
                for &(q, w) in &rows[j0 + c] {
                    z[c * n + q] += w;
                }
            }
            chol.solve_columns_in_place(&mut z, nc);
            let mut y = vec![0.0; n * nc];
            for c in 0..nc {
                pattern.mul_vec(m_sigma, &z[c * n..(c + 1) * n], &mut y[c * n..(c + 1) * n]);
            }
            (z, y)
        })
        .collect();
    let z: Vec<f64> = blocks.iter().flat_map(|b| b.0.iter().copied()).collect();
    let y: Vec<f64> = blocks.iter().flat_map(|b| b.1.iter().copied()).collect();
    // Zᵀ Y by a matrix product (column-major: entry (i, j) at i + j m; symmetrized below).
    let mut out = vec![0.0; m * m];
    faer::linalg::matmul::matmul(
        faer::MatMut::from_column_major_slice_mut(&mut out, m, m),
        faer::Accum::Replace,
        faer::MatRef::from_column_major_slice(&z, n, m).transpose(),
        faer::MatRef::from_column_major_slice(&y, n, m),
        1.0,
        faer::Par::rayon(0),
    );
    // Symmetrize the round-off.
    for i in 0..m {
        for j in 0..i {
            let v = 0.5 * (out[i * m + j] + out[j * m + i]);
            out[i * m + j] = v;
            out[j * m + i] = v;
        }
    }
    Ok(out)
}

impl NodalCovariance {
    /// Standard deviations of ux, uy (pixels) at `(x, y)` inside the mesh: `u = Σ N_a a_a`, so
    /// `var u_x = Σ_ab N_a N_b C[2a, 2b]` over the element's nodes.
    pub fn point_sd(&self, res: &DicResult, x: f64, y: f64) -> Option<[f64; 2]> {
        let (e, xi, eta) = res.mesh.locate(x, y)?;
        let nsh = crate::mesh::DicMesh::shape(xi, eta);
        let c = res.mesh.conn[e];
        let p = &res.system.pattern;
        let mut v = [0.0; 2];
        for comp in 0..2 {
            for a in 0..4 {
                for b in 0..4 {
                    let pos = p.position(2 * c[a] + comp, 2 * c[b] + comp)?;
                    v[comp] += nsh[a] * nsh[b] * self.values[pos];
                }
            }
        }
        Some([v[0].max(0.0).sqrt(), v[1].max(0.0).sqrt()])
    }

    /// Per element, the covariances `C[2a + c, 2b + c]` of its nodes `a, b` for each
    /// component `c` (`[c][4 a + b]`): what [`NodalCovariance::point_sd_with`] reads, gathered
    /// once for the many points of a map.
    pub fn element_blocks(&self, res: &DicResult) -> Vec<[[f64; 16]; 2]> {
        let p = &res.system.pattern;
        res.mesh
            .conn
            .par_iter()
            .map(|c| {
                let mut b = [[0.0; 16]; 2];
                for (comp, bc) in b.iter_mut().enumerate() {
                    for i in 0..4 {
                        for j in 0..4 {
                            bc[4 * i + j] = p
                                .position(2 * c[i] + comp, 2 * c[j] + comp)
                                .map_or(0.0, |k| self.values[k]);
                        }
                    }
                }
                b
            })
            .collect()
    }

    /// [`NodalCovariance::point_sd`] from the blocks of [`NodalCovariance::element_blocks`]
    /// (the same sums in the same order).
    pub fn point_sd_with(
        res: &DicResult,
        blocks: &[[[f64; 16]; 2]],
        x: f64,
        y: f64,
    ) -> Option<[f64; 2]> {
        let (e, xi, eta) = res.mesh.locate(x, y)?;
        Some(Self::local_sd(&blocks[e], xi, eta))
    }

    /// The standard deviations (px) of `(ux, uy)` at the local coordinates `(ξ, η)` of the
    /// element whose block of [`NodalCovariance::element_blocks`] is `block`.
    #[inline]
    pub fn local_sd(block: &[[f64; 16]; 2], xi: f64, eta: f64) -> [f64; 2] {
        let nsh = crate::mesh::DicMesh::shape(xi, eta);
        let mut v = [0.0; 2];
        for comp in 0..2 {
            for a in 0..4 {
                for b in 0..4 {
                    v[comp] += nsh[a] * nsh[b] * block[comp][4 * a + b];
                }
            }
        }
        [v[0].max(0.0).sqrt(), v[1].max(0.0).sqrt()]
    }
}

/// Why an element is (not) trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Trust {
    Trusted,
    /// Fewer than [`crate::solver::MIN_INSIDE`] of the element's pixels stay inside the
    /// deformed image once displaced (the field carries it out of the frame).
    OutsideImage,
    /// The deformed image does not match the reference (low ZNCC).
    Decorrelated,
    /// Residual above `flag_factor` times the median.
    HighResidual,
    /// Too little grey-level variation (acoustic shadow, black band).
    Shadow,
    /// Predicted nodal standard deviation far above the median (little or one-directional
    /// texture).
    LowTexture,
}

impl Trust {
    /// The reasons for not trusting an element, in the order of their [`Trust::code`] (1, 2, …).
    pub const UNTRUSTED: [Trust; 5] = [
        Trust::Decorrelated,
        Trust::HighResidual,
        Trust::Shadow,
        Trust::LowTexture,
        Trust::OutsideImage,
    ];

    /// The reason in words, for the trust map's legend.
    pub fn reason(self) -> &'static str {
        match self {
            Trust::Trusted => "trusted",
            Trust::Decorrelated => "decorrelated",
            Trust::HighResidual => "high residual",
            Trust::Shadow => "shadow",
            Trust::LowTexture => "low texture",
            Trust::OutsideImage => "outside the image",
        }
    }

    /// The name written in `elements.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Trust::Trusted => "trusted",
            Trust::Decorrelated => "decorrelated",
            Trust::HighResidual => "high-residual",
            Trust::Shadow => "shadow",
            Trust::LowTexture => "low-texture",
            Trust::OutsideImage => "outside-image",
        }
    }

    /// A number per reason (0 trusted), for the maps.
    pub fn code(self) -> u8 {
        match self {
            Trust::Trusted => 0,
            Trust::Decorrelated => 1,
            Trust::HighResidual => 2,
            Trust::Shadow => 3,
            Trust::LowTexture => 4,
            Trust::OutsideImage => 5,
        }
    }
}

/// Thresholds of the trust mask.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TrustCriteria {
    /// Minimum ZNCC of `f` and `g̃(x + u)` over the element.
    pub min_zncc: f64,
    /// Minimum grey-level standard deviation as a fraction of the median element's.
    pub min_std_fraction: f64,
    /// Maximum nodal standard deviation as a multiple of the median over the nodes.
    pub max_sd_factor: f64,
}

impl Default for TrustCriteria {
    fn default() -> Self {
        TrustCriteria {
            min_zncc: 0.5,
            min_std_fraction: 0.3,
            max_sd_factor: 4.0,
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// The trust of every element (the first failed criterion in the order of [`Trust`]).
pub fn element_trust(res: &DicResult, cov: &NodalCovariance, c: &TrustCriteria) -> Vec<Trust> {
    let std_med = median(res.element_texture.iter().map(|t| t.std).collect());
    let sd = |q: usize| cov.node[q].sd_ux_px.max(cov.node[q].sd_uy_px);
    let sd_med = median((0..cov.node.len()).map(sd).collect());
    (0..res.mesh.n_elements())
        .map(|e| {
            let t = &res.element_texture[e];
            if t.inside < crate::solver::MIN_INSIDE {
                Trust::OutsideImage
            } else if t.zncc < c.min_zncc {
                Trust::Decorrelated
            } else if res.flagged[e] {
                Trust::HighResidual
            } else if t.std < c.min_std_fraction * std_med {
                Trust::Shadow
            } else if res.mesh.conn[e]
                .iter()
                .any(|&q| sd(q) > c.max_sd_factor * sd_med)
            {
                Trust::LowTexture
            } else {
                Trust::Trusted
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    /// [`Trust::UNTRUSTED`] lists every reason once, in the order of its code.
    #[test]
    fn untrusted_reasons_are_in_code_order() {
        for (k, t) in Trust::UNTRUSTED.iter().enumerate() {
            assert_eq!(t.code() as usize, k + 1, "{}", t.name());
        }
    }

    use super::*;
    use crate::lab::{self, Speckle};
    use crate::{correlate, DicOptions, Rect, Roi};

    /// The covariance on the pattern from the selected inverse against the columns of `C`
    /// solved one by one ([`combined_covariance`] with a unit row per equation: `A⁻¹ e_j`, then
    /// `M_σ`, then the products), on a virtual-lab correlation (64 x 64 px ROI, 16 px elements:
    /// 25 nodes, 50 equations), with and without regularization, for the correlated noise of
    /// `femu dic`, the white noise and the unregularized matrix. Both are exact but for
    /// round-off on systems of condition number below 1e6: agreement to 1e-10 of
    /// `sqrt(C_ii C_jj)`, the scale of entry `(i, j)`.
    #[test]
    fn covariance_on_pattern_equals_the_solved_columns() {
        let s = Speckle::new(128, 128, 1.5, 7);
        let f = lab::add_noise(&s.reference(), 2.0, 11);
        let g = lab::add_noise(&s.deformed(&lab::translation(0.3, -0.2)), 2.0, 12);
        let roi = Roi::Rect(Rect {
            x: 32,
            y: 32,
            w: 64,
            h: 64,
        });
        for reg in [None, Some(48.0)] {
            let opts = DicOptions {
                element_size: 16,
                regularization_length: reg,
                ..Default::default()
            };
            let res = correlate(&f, &g, &roi, &opts).expect("correlation");
            let p = &res.system.pattern;
            let n = p.n;
            let var: Vec<f64> = res.element_residual.iter().map(|r| r * r).collect();
            let a = res.system.a_values();
            let cases = [
                (
                    "correlated",
                    covariance(&res).unwrap(),
                    a.clone(),
                    noise_matrix(&res),
                ),
                (
                    "white",
                    covariance_with(&res, &var).unwrap(),
                    a.clone(),
                    noise_weighted_matrix(&res, &var),
                ),
                (
                    "unregularized",
                    covariance_unregularized(&res).unwrap(),
                    res.system.m_values.clone(),
                    noise_matrix(&res),
                ),
            ];
            let unit: Vec<Vec<(usize, f64)>> = (0..n).map(|j| vec![(j, 1.0)]).collect();
            for (name, cov, a_values, m_sigma) in cases {
                let full = combined_covariance(p, &a_values, &m_sigma, &unit).unwrap();
                let mut worst = 0.0f64;
                for c in 0..n {
                    for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                        let r = p.row_idx[k];
                        let scale = (full[r * n + r] * full[c * n + c]).sqrt();
                        worst = worst.max((cov.values[k] - full[r * n + c]).abs() / scale);
                    }
                }
                assert!(worst < 1e-10, "{reg:?} {name}: {worst:e}");
                // The sd of a point from the gathered element blocks: the same sums.
                let blocks = cov.element_blocks(&res);
                for (x, y) in [(40.0, 40.0), (47.5, 71.25), (95.0, 33.0), (64.0, 64.0)] {
                    assert_eq!(
                        NodalCovariance::point_sd_with(&res, &blocks, x, y),
                        cov.point_sd(&res, x, y)
                    );
                }
                for (q, node) in cov.node.iter().enumerate() {
                    let sx = full[2 * q * n + 2 * q].sqrt();
                    assert!((node.sd_ux_px - sx).abs() <= 1e-10 * sx, "{name}: node {q}");
                }
            }
        }
    }
}
