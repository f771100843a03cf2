//! Variance components of a least-squares fit estimated from its own residuals (Helmert's
//! estimation, iterated as by Förstner 1979; at convergence it is the REML estimate for
//! Gaussian errors).
//!
//! **Why.** A measured field's error is not one σ: on ultrasound frames the lateral component
//! is several times worse than the axial one, and worse near the probe and at the lateral edges
//! of the image, where the receive aperture holds few elements and the point-spread function
//! changes with position. If the data are split into groups `k` (component × depth band × edge
//! band) of `n_k` values sharing a variance `σ²_k`, the weights `1/σ²_k` and the parameter
//! covariance follow from estimates of the `σ²_k`.
//!
//! **Why not the mean squared residual.** The residuals of a fit are smaller than the errors by
//! what the parameters absorbed, and not evenly: a group that alone informs a parameter (the
//! points of a thin layer for that layer's compressibility) loses much of its residual to it.
//! With the whole fit's correction `n / (n − p)` spread evenly, that group's variance is
//! underestimated, its points over-weighted, and the intervals of the parameter it informs too
//! narrow. Helmert's estimator charges each group its own share of the parameters, its
//! *redundancy*:
//!
//! `σ²_k = ẽ_kᵀ W_k ẽ_k / r_k σ⁻²_k`, written with the unit weights of the current iterate:
//! `σ²_k ← ẽ_kᵀ ẽ_k / r_k`, `r_k = n_k − tr(N⁻¹ N_k)`,
//!
//! with `N = Σ_k N_k`, `N_k = J_kᵀ J_k / σ²_k` (the normal matrix and each group's share of it)
//! and `ẽ` the residual of the fit weighted by the current `σ²_k`. The redundancies sum to
//! `n − p`. The fixed point of the iteration is unbiased for a linear model with the true
//! weights; with one group it is the usual `eᵀe / (n − p)`, so shift-invariant data (one
//! variance per component) get the fit they had.
//!
//! **Here** the model is linearized at a fit's optimum: given the raw residual `e` (model −
//! measured, unweighted) and the Jacobian `J` there, each iterate refits the weighted linearized
//! problem `δ = (Jᵀ W J)⁻¹ Jᵀ W e`, `ẽ = e − J δ`, so the estimate does not need a forward solve
//! per iterate; the caller refits the nonlinear problem with the final weights and may repeat.
//! A group whose redundancy is below [`MIN_REDUNDANCY`] has no estimate of its own and takes
//! the pooled variance of the others (reported in [`VarianceComponents::pooled`]).

use crate::fit_error::FitError;

/// The smallest redundancy a group needs for a variance of its own (a variance from fewer
/// degrees of freedom has a relative standard error above `√(2/2) = 100 %`).
pub const MIN_REDUNDANCY: f64 = 2.0;

/// The estimated variance components.
#[derive(Debug, Clone, PartialEq)]
pub struct VarianceComponents {
    /// Variance of each group (units of the residual, squared).
    pub variance: Vec<f64>,
    /// Redundancy `r_k` of each group at the final weights (sums to `n − p`).
    pub redundancy: Vec<f64>,
    /// Number of values in each group.
    pub count: Vec<usize>,
    /// Groups too small for a variance of their own, given the pooled variance.
    pub pooled: Vec<usize>,
    /// Iterations done.
    pub iterations: usize,
    /// Whether the relative change of every variance fell below the tolerance.
    pub converged: bool,
    /// The linearized parameter step `δ` of the final weighted fit (Jacobian units).
    pub step: Vec<f64>,
    /// The parameter covariance `N⁻¹` of the final weighted fit.
    pub covariance: Vec<Vec<f64>>,
}

impl VarianceComponents {
    /// Standard deviation of each group.
    pub fn sd(&self) -> Vec<f64> {
        self.variance.iter().map(|v| v.sqrt()).collect()
    }

    /// The weight `1/σ²` of every value given its group.
    pub fn weights(&self, group: &[usize]) -> Vec<f64> {
        group.iter().map(|&g| 1.0 / self.variance[g]).collect()
    }
}

/// Helmert's variance components (module doc) of the residual `residual` (length `n`) with the
/// Jacobian `jacobian` (`p` columns of length `n`, as [`crate::fit::FitResult::jacobian`]) at
/// the fit's optimum, the values in groups `group[i] < groups`. Iterates until every variance
/// changes by less than `tol` (relative) or `max_iter` iterations.
pub fn helmert(
    jacobian: &[Vec<f64>],
    residual: &[f64],
    group: &[usize],
    groups: usize,
    tol: f64,
    max_iter: usize,
) -> Result<VarianceComponents, FitError> {
    let n = residual.len();
    let p = jacobian.len();
    let bad = |msg: String| Err(FitError::Covariance(format!("variance components: {msg}")));
    if group.len() != n {
        return bad(format!("{} group labels for {n} residuals", group.len()));
    }
    if let Some(c) = jacobian.iter().position(|c| c.len() != n) {
        return bad(format!(
            "Jacobian column {c} has {} rows, {n} expected",
            jacobian[c].len()
        ));
    }
    if let Some(i) = group.iter().position(|&g| g >= groups) {
        return bad(format!("group {} of value {i} >= {groups}", group[i]));
    }
    if let Some(i) = residual.iter().position(|r| !r.is_finite()) {
        return bad(format!("residual {i} is not finite"));
    }
    if n <= p {
        return bad(format!("{n} residuals for {p} parameters"));
    }
    let mut count = vec![0usize; groups];
    for &g in group {
        count[g] += 1;
    }
    // Start: one variance for all, the usual eᵀe / (n − p) (the ordinary fit's).
    let s0 = residual.iter().map(|r| r * r).sum::<f64>() / (n - p) as f64;
    let start = if s0 > 0.0 { s0 } else { 1.0 };
    let mut variance = vec![start; groups];
    let mut out = VarianceComponents {
        variance: variance.clone(),
        redundancy: vec![0.0; groups],
        count: count.clone(),
        pooled: Vec::new(),
        iterations: 0,
        converged: false,
        step: vec![0.0; p],
        covariance: vec![vec![0.0; p]; p],
    };
    for it in 1..=max_iter {
        let w: Vec<f64> = group.iter().map(|&g| 1.0 / variance[g]).collect();
        // N = Jᵀ W J, g = Jᵀ W e.
        let mut normal = vec![vec![0.0; p]; p];
        let mut rhs = vec![0.0; p];
        for i in 0..n {
            for a in 0..p {
                let ja = jacobian[a][i] * w[i];
                rhs[a] += ja * residual[i];
                for b in 0..=a {
                    normal[a][b] += ja * jacobian[b][i];
                }
            }
        }
        for a in 0..p {
            for b in 0..a {
                normal[b][a] = normal[a][b];
            }
        }
        let ninv = invert_spd(&normal).ok_or_else(|| {
            FitError::Covariance(
                "variance components: the weighted normal matrix is singular (a parameter no data informs)"
                    .to_string(),
            )
        })?;
        let step: Vec<f64> = (0..p)
            .map(|a| (0..p).map(|b| ninv[a][b] * rhs[b]).sum())
            .collect();
        // Residual of the weighted linearized fit, and each group's share of tr(N⁻¹ N) = p:
        // tr(N⁻¹ N_k) = Σ_{i∈k} w_i j_iᵀ N⁻¹ j_i (the weighted leverages).
        let mut ss = vec![0.0; groups];
        let mut leverage = vec![0.0; groups];
        let mut row = vec![0.0; p];
        for i in 0..n {
            for a in 0..p {
                row[a] = jacobian[a][i];
            }
            let fitted: f64 = (0..p).map(|a| row[a] * step[a]).sum();
            let e = residual[i] - fitted;
            ss[group[i]] += e * e;
            let mut h = 0.0;
            for a in 0..p {
                let na: f64 = (0..p).map(|b| ninv[a][b] * row[b]).sum();
                h += row[a] * na;
            }
            leverage[group[i]] += w[i] * h;
        }
        let redundancy: Vec<f64> = (0..groups).map(|k| count[k] as f64 - leverage[k]).collect();
        let mut next = vec![0.0; groups];
        let mut pooled = Vec::new();
        let (mut pool_ss, mut pool_r) = (0.0, 0.0);
        for k in 0..groups {
            if count[k] == 0 {
                continue;
            }
            if redundancy[k] >= MIN_REDUNDANCY {
                next[k] = (ss[k] / redundancy[k]).max(f64::MIN_POSITIVE);
                pool_ss += ss[k];
                pool_r += redundancy[k];
            } else {
                pooled.push(k);
            }
        }
        let pool = if pool_r > 0.0 {
            pool_ss / pool_r
        } else {
            start
        };
        for &k in &pooled {
            next[k] = pool.max(f64::MIN_POSITIVE);
        }
        for k in 0..groups {
            if count[k] == 0 {
                next[k] = pool.max(f64::MIN_POSITIVE);
            }
        }
        let change = (0..groups)
            .filter(|&k| count[k] > 0)
            .map(|k| ((next[k] - variance[k]) / variance[k]).abs())
            .fold(0.0, f64::max);
        variance = next;
        out = VarianceComponents {
            variance: variance.clone(),
            redundancy,
            count: count.clone(),
            pooled,
            iterations: it,
            converged: change < tol,
            step,
            covariance: ninv,
        };
        if out.converged {
            break;
        }
    }
    Ok(out)
}

/// Group labels of a field's points for [`helmert`]: the values `[ux0, uy0, ux1, uy1, ...]` of
/// points at `x` (model frame, mm; `x[1]` the depth coordinate, increasing away from the
/// probe at `probe_y`) in groups `component × depth band × (interior, lateral edge)`: depth bands
/// bounded by `depth_edges` (mm from the probe, increasing; points beyond the last edge in the
/// last band), the lateral edge the points within `edge_mm` of the field's lateral extremes
/// (`edge_mm = 0` for none). Returns the labels and the number of groups.
pub fn field_groups(
    x: &[[f64; 2]],
    probe_y: f64,
    depth_edges: &[f64],
    edge_mm: f64,
) -> (Vec<usize>, usize) {
    let bands = depth_edges.len() + 1;
    let sides = if edge_mm > 0.0 { 2 } else { 1 };
    let (lo, hi) = x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[0]), hi.max(p[0]))
        });
    let mut labels = Vec::with_capacity(2 * x.len());
    for p in x {
        let depth = (p[1] - probe_y).abs();
        let band = depth_edges.iter().filter(|&&e| depth >= e).count();
        let side = usize::from(sides == 2 && (p[0] - lo < edge_mm || hi - p[0] < edge_mm));
        for c in 0..2 {
            labels.push((c * bands + band) * sides + side);
        }
    }
    (labels, 2 * bands * sides)
}

/// Inverse of a small symmetric positive definite matrix by Cholesky; `None` if not positive
/// definite.
pub(crate) fn invert_spd(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let p = a.len();
    let mut l = vec![vec![0.0; p]; p];
    for i in 0..p {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    // Columns of L⁻ᵀ L⁻¹ by solving L y = e_c, Lᵀ x = y.
    let mut inv = vec![vec![0.0; p]; p];
    for c in 0..p {
        let mut y = vec![0.0; p];
        for i in 0..p {
            let b = if i == c { 1.0 } else { 0.0 };
            y[i] = (b - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
        }
        let mut x = vec![0.0; p];
        for i in (0..p).rev() {
            x[i] = (y[i] - (i + 1..p).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
        }
        for i in 0..p {
            inv[i][c] = x[i];
        }
    }
    Some(inv)
}

#[cfg(test)]
mod tests;
