//! The probe pose's part of the uncertainty: how far the identified parameters move when the
//! images' placement in the model moves within its own uncertainty.
//!
//! The placement is a rigid motion `p = (t_x, t_y, α)` of the image about a pivot pixel `c`
//! (the probe face's centre; `femu_ultrasound::pose`, eq. 1 there): the image's axes turned by
//! `α`, the pivot moved by `t_x e_x + t_y e_y` (mm, along the unmoved axes). Moving it changes
//! which material point `X_p` each reference pixel `x_p` images, and so the pixel displacement
//! of every loaded frame,
//!
//! ```text
//!   δd_i(x_p) = P' u_i(X'_p) − P u_i(X_p),    X'_p = the moved placement's model point of x_p   (1)
//! ```
//!
//! (`P`, `P'` the placements' maps from mm to pixels; `u_i` the finite-element displacement of
//! load step `i` at the estimate, located again in the mesh at the moved points: no new solve).
//! The residual changes by `δr = (∂r/∂d) δd` (first order in `δd`, which is a fraction of a
//! pixel: the strain times the move, and the turn times the displacement), and the estimate by
//! one Gauss–Newton step, `δφ = −H⁻¹ Jᵀ δr` (eq. 3 of [`super::uncertainty`], the same held
//! parameters as the discretization term). Central differences of (1) along each eigenvector
//! `v_k` of the placement's covariance `Σ`, at one standard deviation `h_k = √λ_k`, give the
//! columns of the sensitivity `S = ∂φ/∂p`,
//!
//! ```text
//!   S v_k ≈ (δφ(+h_k v_k) − δφ(−h_k v_k)) / (2 h_k),    Cov_pose(φ̂) = S Σ Sᵀ = Σ_k (S v_k h_k)(S v_k h_k)ᵀ   (2)
//! ```
//!
//! the delta method for the placement's covariance (the refinement's sandwich). The term is
//! systematic for one recording (the same placement serves every frame) and enters the
//! interval beside the noise and the mesh's terms.

use super::frame::ImageFrame;
use super::problem::IdicProblem;
use crate::fit::{FitError, LeastSquares};
use femu_mesh::locate::PointLocator;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The uncertainty of the images' placement: the covariance of a rigid motion
/// `p = (t_x mm, t_y mm, α rad)` of the image about `pivot_px` (module documentation), along
/// the axes of the placement the problem uses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlacementUncertainty {
    pub pivot_px: [f64; 2],
    /// `Cov(p)` (mm², mm·rad, rad²).
    pub covariance: [[f64; 3]; 3],
}

/// The pose term of the estimate's covariance (eq. 2) and what it was computed from.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PoseTerm {
    /// The moves of the placement (`t_x` mm, `t_y` mm, `α` rad): one standard deviation along
    /// each eigenvector of the covariance (the largest first).
    pub steps: Vec<[f64; 3]>,
    /// The one-step Gauss–Newton shift of `ln θ` at `+step` and at `−step`, per step.
    pub shifts_plus: Vec<Vec<f64>>,
    pub shifts_minus: Vec<Vec<f64>>,
    /// `∂ ln θ_j / ∂(t_x, t_y, α)` per parameter (per mm, per mm, per rad).
    pub sensitivity: Vec<[f64; 3]>,
    /// `S Σ Sᵀ` (log-parameters) and its diagonal's square roots.
    pub covariance: Vec<Vec<f64>>,
    pub sd: Vec<f64>,
    /// The most pixels a moved placement put outside the mesh (their displacement change is
    /// taken as zero), of the problem's pixels.
    pub pixels_outside: usize,
    pub pixels: usize,
}

/// The placement `frame` moved by `p = (t_x mm, t_y mm, α rad)` about the pixel `pivot_px`:
/// the axes turned by `α` (from `x_axis` towards `y_axis`), the pivot's model point moved by
/// `t_x x_axis + t_y y_axis` (the form of `femu_ultrasound::pose::ImagePose::moved`).
pub fn moved_frame(frame: &ImageFrame, pivot_px: [f64; 2], p: [f64; 3]) -> ImageFrame {
    let (a, b) = (frame.x_axis, frame.y_axis);
    let (c, s) = (p[2].cos(), p[2].sin());
    let a2 = [c * a[0] + s * b[0], c * a[1] + s * b[1]];
    let b2 = [-s * a[0] + c * b[0], -s * a[1] + c * b[1]];
    let x = frame.pixel_to_model(pivot_px);
    let xp = [
        x[0] + p[0] * a[0] + p[1] * b[0],
        x[1] + p[0] * a[1] + p[1] * b[1],
    ];
    let m = frame.mm_per_px;
    ImageFrame {
        origin_mm: [
            xp[0] - m * (pivot_px[0] * a2[0] + pivot_px[1] * b2[0]),
            xp[1] - m * (pivot_px[0] * a2[1] + pivot_px[1] * b2[1]),
        ],
        mm_per_px: m,
        x_axis: a2,
        y_axis: b2,
    }
}

/// A pixel displacement (px) per load step and pixel, `[step][pixel]`.
pub type StepPixels = Vec<Vec<[f64; 2]>>;

/// The change (1) of every load step's pixel displacements (px, `[step][pixel]`) if the
/// problem's images were placed by `moved` instead, at the steps' last solved states; and how
/// many pixels `moved` puts outside the mesh (their change is zero).
pub fn pixel_shift(
    problem: &IdicProblem,
    moved: &ImageFrame,
) -> Result<(StepPixels, usize), FitError> {
    let states = problem
        .states()
        .ok_or_else(|| FitError::Solve("the pose term needs a solved problem".into()))?;
    let locator = PointLocator::new(&problem.model(0).mesh);
    let pixels = problem.pixels();
    let located: Vec<_> = pixels
        .px
        .par_iter()
        .map(|p| locator.locate(moved.pixel_to_model([p[0] as f64, p[1] as f64])))
        .collect();
    let outside = located.iter().filter(|l| l.is_none()).count();
    let own = problem.frame();
    let shift = states
        .iter()
        .map(|u| {
            located
                .par_iter()
                .zip(pixels.loc.par_iter())
                .map(|(l, l0)| match l {
                    Some(l) => {
                        let (d, d0) = (moved.field_to_pixels(l, u), own.field_to_pixels(l0, u));
                        [d[0] - d0[0], d[1] - d0[1]]
                    }
                    None => [0.0, 0.0],
                })
                .collect()
        })
        .collect();
    Ok((shift, outside))
}

/// The one-step Gauss–Newton shift of `ln θ` if the images were placed by the problem's own
/// placement moved by `p` about `pivot_px` (eq. 1 and eq. 3 of [`super::uncertainty`]), the
/// parameters with `moving[k] == false` held; and the pixels the move put outside the mesh.
/// The problem must have been evaluated with its Jacobian at the estimate.
pub fn shift_for_pose(
    problem: &IdicProblem,
    pivot_px: [f64; 2],
    p: [f64; 3],
    moving: &[bool],
) -> Result<(Vec<f64>, usize), FitError> {
    let moved = moved_frame(problem.frame(), pivot_px, p);
    let (delta, outside) = pixel_shift(problem, &moved)?;
    Ok((problem.shift_for(&delta, moving), outside))
}

/// The pose term (eq. 2) of the estimate at which `problem` was last evaluated with its
/// Jacobian, for the placement's uncertainty `u`; the parameters with `moving[k] == false`
/// held (their term 0). Six one-step shifts, no forward solve.
pub fn pose_term(
    problem: &IdicProblem,
    u: &PlacementUncertainty,
    moving: &[bool],
) -> Result<PoseTerm, FitError> {
    let n = problem.free().len();
    let (values, vectors) = symmetric_eigen3(u.covariance);
    let mut steps = Vec::new();
    let (mut plus, mut minus) = (Vec::new(), Vec::new());
    let mut sensitivity = vec![[0.0; 3]; n];
    let mut covariance = vec![vec![0.0; n]; n];
    let mut pixels_outside = 0;
    for (k, &lambda) in values.iter().enumerate() {
        if !(lambda > 0.0 && lambda.is_finite()) {
            continue;
        }
        let h = lambda.sqrt();
        let v = vectors[k];
        let step = [h * v[0], h * v[1], h * v[2]];
        let (sp, op) = shift_for_pose(problem, u.pivot_px, step, moving)?;
        let (sm, om) = shift_for_pose(problem, u.pivot_px, step.map(|x| -x), moving)?;
        pixels_outside = pixels_outside.max(op).max(om);
        // (S v_k) h_k, the shift of one standard deviation along v_k.
        let one_sd: Vec<f64> = sp.iter().zip(&sm).map(|(a, b)| 0.5 * (a - b)).collect();
        for j in 0..n {
            for c in 0..3 {
                sensitivity[j][c] += one_sd[j] / h * v[c];
            }
            for i in 0..n {
                covariance[j][i] += one_sd[j] * one_sd[i];
            }
        }
        steps.push(step);
        plus.push(sp);
        minus.push(sm);
    }
    let sd = (0..n).map(|j| covariance[j][j].max(0.0).sqrt()).collect();
    Ok(PoseTerm {
        steps,
        shifts_plus: plus,
        shifts_minus: minus,
        sensitivity,
        covariance,
        sd,
        pixels_outside,
        pixels: problem.pixels().len(),
    })
}

/// The eigenvalues (descending) and unit eigenvectors of a symmetric 3 x 3 matrix: the
/// mechanics' cyclic Jacobi ([`femu_mech::solver::symmetric_eigen3`]), ordered.
pub fn symmetric_eigen3(m: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let (values, vectors) = femu_mech::solver::symmetric_eigen3(m);
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    (order.map(|i| values[i]), order.map(|i| vectors[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The eigenpairs rebuild the matrix (`Σ λ_k v_k v_kᵀ`) to rounding, on a covariance of
    /// the pose's mixed units (mm² and rad²: entries 10⁻² to 10⁻⁶).
    #[test]
    fn eigen3_rebuilds_a_pose_covariance() {
        let m = [
            [0.029, 0.004, -2.0e-4],
            [0.004, 0.011, 3.0e-5],
            [-2.0e-4, 3.0e-5, 5.0e-6],
        ];
        let (l, v) = symmetric_eigen3(m);
        assert!(l[0] >= l[1] && l[1] >= l[2] && l[2] > 0.0, "{l:?}");
        for i in 0..3 {
            for j in 0..3 {
                let r: f64 = (0..3).map(|k| l[k] * v[k][i] * v[k][j]).sum();
                assert!((r - m[i][j]).abs() < 1e-15, "{i} {j}: {r} vs {}", m[i][j]);
            }
            let norm: f64 = v[i].iter().map(|x| x * x).sum();
            assert!((norm - 1.0).abs() < 1e-12);
        }
    }

    /// The moved placement keeps the pivot's image at the pivot moved by `(t_x, t_y)` along
    /// the old axes, turns the axes by `α`, and a move and its opposite return to the start
    /// (to first order in α: the turn is about the moved pivot; asserted for the pure parts).
    #[test]
    fn moved_frame_moves_the_pivot_and_turns_the_axes() {
        let f = ImageFrame::new([-20.0, 60.0], 0.1, [1.0, 0.0], [0.0, -1.0]).unwrap();
        let pivot = [199.5, -0.5];
        let x0 = f.pixel_to_model(pivot);
        let g = moved_frame(&f, pivot, [0.3, -0.2, 0.05]);
        let x1 = g.pixel_to_model(pivot);
        assert!((x1[0] - (x0[0] + 0.3)).abs() < 1e-12, "{x1:?}");
        assert!((x1[1] - (x0[1] + 0.2)).abs() < 1e-12, "{x1:?}");
        let turn = (g.x_axis[0] * f.y_axis[0] + g.x_axis[1] * f.y_axis[1])
            .atan2(g.x_axis[0] * f.x_axis[0] + g.x_axis[1] * f.x_axis[1]);
        assert!((turn - 0.05).abs() < 1e-12, "{turn}");
        assert!(ImageFrame::new(g.origin_mm, g.mm_per_px, g.x_axis, g.y_axis).is_ok());
        let back = moved_frame(
            &moved_frame(&f, pivot, [0.0, 0.0, 0.05]),
            pivot,
            [0.0, 0.0, -0.05],
        );
        for k in 0..2 {
            assert!((back.origin_mm[k] - f.origin_mm[k]).abs() < 1e-12);
        }
    }
}
