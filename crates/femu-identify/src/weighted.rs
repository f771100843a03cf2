//! Weighted FEMU: the misfit of a measured field weighted by the measurement's own covariance,
//! and a robust loss for the points it gets wrong.
//!
//! **Covariance.** A DIC field's errors are not one σ everywhere: its nodal covariance is
//! `C = A⁻¹ M_σ A⁻¹` (the Gauss–Newton matrix of the correlation and the grey-level residual's
//! variance and correlation; `femu_dic::quality`), large where the texture is poor or the images
//! decorrelate, and correlated between neighbouring points. The generalized least-squares misfit
//! `(u_m − u)ᵀ C⁻¹ (u_m − u)` is that of the whitened residual `L⁻¹ (u_m − u)`, `C = L Lᵀ`
//! (Cholesky): the [`crate::fit::Problem`] minimizes it with the Jacobian whitened alike
//! ([`crate::fit::Problem::with_covariance`]). Points left out (outside the tissue, untrusted
//! elements) are marginalized exactly: the covariance of the points kept is the sub-block of `C`.
//!
//! **Robust loss.** A few points that no noise model explains (a DIC element that followed the
//! wrong speckle) would pull a least-squares fit. With Huber's loss on the whitened residuals,
//! `ρ(r) = r²/2` for `|r| ≤ k` and `k|r| − k²/2` beyond, they count linearly. The optimizers
//! minimize `½ Σ ρ̃²` with `ρ̃ = sign(r) √(2ρ(r))` (Triggs et al. 2000), whose derivative is
//! `ψ(r)/√(2ρ(r)) ∂r` (exact; `ψ = ρ'`). `k = 1.345` keeps 95 % of the efficiency of least
//! squares for Gaussian errors.

use crate::fit_error::FitError;
use serde::{Deserialize, Serialize};

/// The covariance of a measured field's components `[ux0, uy0, ux1, uy1, ...]` in the model
/// frame (mm²), dense, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldCovariance {
    pub points: usize,
    pub values: Vec<f64>,
}

impl FieldCovariance {
    /// A covariance over `points` points (`(2 points)²` values, symmetric).
    pub fn new(points: usize, values: Vec<f64>) -> Result<FieldCovariance, FitError> {
        let m = 2 * points;
        if values.len() != m * m {
            return Err(FitError::Covariance(format!(
                "{} values for {points} points ({m} x {m} expected)",
                values.len()
            )));
        }
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err(FitError::Covariance(format!(
                "entry ({}, {}) is not finite",
                k / m,
                k % m
            )));
        }
        Ok(FieldCovariance { points, values })
    }

    /// The covariance of the points `keep` (indices), in that order.
    pub fn sub(&self, keep: &[usize]) -> FieldCovariance {
        let m = 2 * self.points;
        let k = 2 * keep.len();
        let mut values = vec![0.0; k * k];
        for (i, &pi) in keep.iter().enumerate() {
            for (j, &pj) in keep.iter().enumerate() {
                for a in 0..2 {
                    for b in 0..2 {
                        values[(2 * i + a) * k + 2 * j + b] =
                            self.values[(2 * pi + a) * m + 2 * pj + b];
                    }
                }
            }
        }
        FieldCovariance {
            points: keep.len(),
            values,
        }
    }

    /// Writes the covariance as a dense symmetric Matrix Market array (lower triangle, column by
    /// column), with comment lines.
    pub fn write_mtx(&self, path: &std::path::Path, comments: &[String]) -> Result<(), FitError> {
        femu_dic::output::write_dense_symmetric(path, 2 * self.points, &self.values, comments)
            .map_err(|e| FitError::Covariance(e.to_string()))
    }

    /// Reads a dense symmetric Matrix Market array as [`FieldCovariance::write_mtx`] writes it;
    /// errors name the file and line.
    pub fn read_mtx(path: &std::path::Path) -> Result<FieldCovariance, FitError> {
        let name = path.display().to_string();
        let bad = |line: usize, msg: &str| FitError::Covariance(format!("{name}:{line}: {msg}"));
        let text = std::fs::read_to_string(path)
            .map_err(|e| FitError::Covariance(format!("{name}: cannot read: {e}")))?;
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, h))
                if h.to_ascii_lowercase()
                    .starts_with("%%matrixmarket matrix array real symmetric") => {}
            _ => return Err(bad(1, "not a dense symmetric real Matrix Market array")),
        }
        let mut m = 0usize;
        let mut values = Vec::new();
        let (mut i, mut j) = (0usize, 0usize);
        for (k, l) in lines {
            let t = l.trim();
            if t.is_empty() || t.starts_with('%') {
                continue;
            }
            if m == 0 {
                let f: Vec<&str> = t.split_whitespace().collect();
                let (Some(a), Some(b)) = (f.first(), f.get(1)) else {
                    return Err(bad(k + 1, "expected the size 'rows cols'"));
                };
                let (Ok(a), Ok(b)) = (a.parse::<usize>(), b.parse::<usize>()) else {
                    return Err(bad(k + 1, "expected the size 'rows cols'"));
                };
                if a != b || a == 0 || a % 2 != 0 {
                    return Err(bad(
                        k + 1,
                        "the size must be square, even (ux, uy per point) and positive",
                    ));
                }
                m = a;
                values = vec![0.0; m * m];
                i = 0;
                j = 0;
                continue;
            }
            if j >= m {
                return Err(bad(k + 1, "more values than the size allows"));
            }
            let v: f64 = t
                .parse()
                .map_err(|_| bad(k + 1, &format!("'{t}' is not a number")))?;
            if !v.is_finite() {
                return Err(bad(k + 1, "not finite"));
            }
            values[i * m + j] = v;
            values[j * m + i] = v;
            i += 1;
            if i == m {
                j += 1;
                i = j;
            }
        }
        if m == 0 || j < m {
            return Err(bad(0, "fewer values than the size needs"));
        }
        FieldCovariance::new(m / 2, values)
    }

    /// The covariance of the field mapped by the same linear map per point, `u' = T u`
    /// (`C' = T C Tᵀ` block by block): a change of units or axes.
    pub fn mapped(&self, t: [[f64; 2]; 2]) -> FieldCovariance {
        let n = self.points;
        let m = 2 * n;
        let mut out = vec![0.0; m * m];
        for bi in 0..n {
            for bj in 0..n {
                for r in 0..2 {
                    for s in 0..2 {
                        let mut v = 0.0;
                        for a in 0..2 {
                            for b in 0..2 {
                                v += t[r][a] * self.values[(2 * bi + a) * m + 2 * bj + b] * t[s][b];
                            }
                        }
                        out[(2 * bi + r) * m + 2 * bj + s] = v;
                    }
                }
            }
        }
        FieldCovariance {
            points: n,
            values: out,
        }
    }

    /// Standard deviation of each component (mm).
    pub fn sd(&self) -> Vec<f64> {
        let m = 2 * self.points;
        (0..m)
            .map(|i| self.values[i * m + i].max(0.0).sqrt())
            .collect()
    }
}

/// `v ↦ L⁻¹ v` for the Cholesky factor `L` of a covariance.
#[derive(Debug, Clone)]
pub struct Whitening {
    l: faer::Mat<f64>,
}

impl Whitening {
    /// The factor of `cov`. A covariance that is not positive definite (a field whose points
    /// repeat, a DIC whose noise matrix is singular) is an error.
    pub fn new(cov: &FieldCovariance) -> Result<Whitening, FitError> {
        let m = 2 * cov.points;
        let a = faer::Mat::<f64>::from_fn(m, m, |i, j| cov.values[i * m + j]);
        let llt = a.llt(faer::Side::Lower).map_err(|_| {
            FitError::Covariance("the measured field's covariance is not positive definite".into())
        })?;
        Ok(Whitening {
            l: llt.L().to_owned(),
        })
    }

    /// Solves `L x = v` in place (forward substitution).
    pub fn apply(&self, v: &mut [f64]) {
        let m = v.len();
        debug_assert_eq!(m, self.l.nrows());
        for i in 0..m {
            let mut s = v[i];
            for j in 0..i {
                s -= self.l[(i, j)] * v[j];
            }
            v[i] = s / self.l[(i, i)];
        }
    }

    pub fn len(&self) -> usize {
        self.l.nrows()
    }

    pub fn is_empty(&self) -> bool {
        self.l.nrows() == 0
    }
}

/// The loss on the (whitened) residuals.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Loss {
    /// Least squares.
    #[default]
    Squared,
    /// Huber's loss with threshold `k` (in standard deviations of the whitened residual).
    Huber { k: f64 },
}

/// Huber's threshold of 95 % efficiency for Gaussian errors.
pub const HUBER_K: f64 = 1.345;

impl Loss {
    /// The transformed residual `sign(r) √(2ρ(r))` and its derivative with respect to `r`.
    #[inline]
    pub fn transform(self, r: f64) -> (f64, f64) {
        match self {
            Loss::Squared => (r, 1.0),
            Loss::Huber { k } => {
                let a = r.abs();
                if a <= k {
                    (r, 1.0)
                } else {
                    let t = (2.0 * k * a - k * k).sqrt();
                    (r.signum() * t, k / t)
                }
            }
        }
    }

    /// Applies the loss to the residuals and, if given, to the Jacobian columns (rows scaled by
    /// the derivative of the transform).
    pub fn apply(self, r: &mut [f64], jacobian: Option<&mut Vec<Vec<f64>>>) {
        if self == Loss::Squared {
            return;
        }
        let d: Vec<f64> = r
            .iter_mut()
            .map(|ri| {
                let (t, dt) = self.transform(*ri);
                *ri = t;
                dt
            })
            .collect();
        if let Some(j) = jacobian {
            for col in j.iter_mut() {
                for (c, dt) in col.iter_mut().zip(&d) {
                    *c *= dt;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The whitened residual's squared norm is the generalized misfit `vᵀ C⁻¹ v`.
    #[test]
    fn whitening_gives_the_mahalanobis_norm() {
        let c = FieldCovariance::new(
            2,
            vec![
                4.0, 1.0, 0.5, 0.0, //
                1.0, 3.0, 0.0, 0.2, //
                0.5, 0.0, 2.0, 0.3, //
                0.0, 0.2, 0.3, 1.0,
            ],
        )
        .unwrap();
        let w = Whitening::new(&c).unwrap();
        let v = [0.3, -1.2, 0.7, 0.1];
        let mut x = v;
        w.apply(&mut x);
        let norm: f64 = x.iter().map(|a| a * a).sum();
        let m = faer::Mat::<f64>::from_fn(4, 4, |i, j| c.values[i * 4 + j]);
        let b = faer::Mat::<f64>::from_fn(4, 1, |i, _| v[i]);
        use faer::linalg::solvers::Solve;
        let y = m.partial_piv_lu().solve(&b);
        let quad: f64 = (0..4).map(|i| v[i] * y[(i, 0)]).sum();
        assert!((norm - quad).abs() < 1e-12 * quad, "{norm} vs {quad}");
        let s = c.sub(&[1]);
        assert_eq!(s.values, vec![2.0, 0.3, 0.3, 1.0]);
        assert!(
            Whitening::new(&FieldCovariance::new(1, vec![1.0, 2.0, 2.0, 1.0]).unwrap()).is_err()
        );
        assert!(FieldCovariance::new(1, vec![1.0; 3]).is_err());
        let dir = std::env::temp_dir().join(format!("femu-cov-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.mtx");
        c.write_mtx(&p, &["test".into()]).unwrap();
        let back = FieldCovariance::read_mtx(&p).unwrap();
        assert!(back
            .values
            .iter()
            .zip(&c.values)
            .all(|(a, b)| (a - b).abs() < 1e-9 * b.abs().max(1.0)));
        std::fs::write(
            &p,
            "%%MatrixMarket matrix array real symmetric\n4 4\n1\nx\n",
        )
        .unwrap();
        let e = FieldCovariance::read_mtx(&p).unwrap_err().to_string();
        assert!(e.contains("c.mtx:4") && e.contains("'x'"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
        // A map by a rotation keeps the trace of each 2 x 2 block.
        let r = c.mapped([[0.0, -1.0], [1.0, 0.0]]);
        assert!((r.values[0] + r.values[4 + 1] - 7.0).abs() < 1e-12);
    }

    /// `½ ρ̃²` is Huber's `ρ`, and the derivative of the transform matches central differences
    /// (step 1e-6: truncation ~1e-12).
    #[test]
    fn huber_transform_is_the_loss_and_its_derivative() {
        let loss = Loss::Huber { k: HUBER_K };
        for r in [-5.0, -1.0, 0.3, 1.345, 2.0, 40.0] {
            let (t, dt) = loss.transform(r);
            let rho = if r.abs() <= HUBER_K {
                0.5 * r * r
            } else {
                HUBER_K * r.abs() - 0.5 * HUBER_K * HUBER_K
            };
            assert!((0.5 * t * t - rho).abs() < 1e-12 * (1.0 + rho), "{r}");
            let h = 1e-6;
            let fd = (loss.transform(r + h).0 - loss.transform(r - h).0) / (2.0 * h);
            assert!((fd - dt).abs() < 1e-6, "{r}: {fd} vs {dt}");
        }
    }
}
