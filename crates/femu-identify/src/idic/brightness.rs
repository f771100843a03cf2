//! Brightness and contrast of a frame pair, eliminated by variable projection.
//!
//! In each brightness band `b` (a range of image rows, where the scanner's gain, the
//! time-gain compensation and the attenuation of the tissue above act alike) the moving frame's
//! grey levels `G` are matched to the fixed ones `F` by a contrast `s` and an offset `o`,
//! `r = F − s G − o`, with `(s, o)` the least-squares fit for the current parameters
//!
//! ```text
//!   [s, o]ᵀ = (AᵀA)⁻¹ Aᵀ F,      A = [G  1]                                        (1)
//! ```
//!
//! so the residual is the projection `r = P⊥ F` onto the complement of the span of `A`
//! (Golub & Pereyra 1973), and its cost `Σ r² = n var(F) (1 − ZNCC(F, G)²)`: the band's
//! zero-normalized correlation. Its derivative along a change `(δF, δG)` of the grey levels
//! (the model moving the material points) is exact:
//!
//! ```text
//!   δr = P⊥ (δF − s δG) − A (AᵀA)⁻¹ [Σ δG r, 0]ᵀ                                    (2)
//! ```
//!
//! (the second term is Kaufman's "omitted" term; it vanishes when the residual does, and is
//! kept so that the Jacobian is the derivative of the residual the optimizer sees).

/// The fitted contrast and offset of a band and what (2) needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BandFit {
    pub contrast: f64,
    pub offset: f64,
    /// `(AᵀA)⁻¹` (symmetric 2 x 2), or `None` without correction.
    inverse: Option<[f64; 3]>,
}

/// Sums of a band's grey levels: `n, ΣG, ΣG², ΣF, ΣGF`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BandSums {
    pub n: f64,
    pub g: f64,
    pub gg: f64,
    pub f: f64,
    pub gf: f64,
}

impl BandSums {
    pub fn add(&mut self, f: f64, g: f64) {
        self.n += 1.0;
        self.g += g;
        self.gg += g * g;
        self.f += f;
        self.gf += g * f;
    }

    pub fn merge(mut self, o: BandSums) -> BandSums {
        self.n += o.n;
        self.g += o.g;
        self.gg += o.gg;
        self.f += o.f;
        self.gf += o.gf;
        self
    }

    /// The least-squares contrast and offset (1); `corrected = false`: `s = 1, o = 0`. A band
    /// whose moving grey levels do not vary (`var G` below 1e-12 of their mean square) keeps
    /// `s = 1` and fits the offset alone.
    pub fn fit(&self, corrected: bool) -> BandFit {
        if !corrected || self.n < 2.0 {
            return BandFit {
                contrast: 1.0,
                offset: 0.0,
                inverse: None,
            };
        }
        let det = self.n * self.gg - self.g * self.g;
        if !(det > 1e-12 * self.n * self.gg.max(f64::MIN_POSITIVE)) {
            return BandFit {
                contrast: 1.0,
                offset: (self.f - self.g) / self.n,
                inverse: None,
            };
        }
        let s = (self.n * self.gf - self.g * self.f) / det;
        let o = (self.f - s * self.g) / self.n;
        // (AᵀA)⁻¹ = [[n, −ΣG], [−ΣG, ΣG²]] / det, stored as (a11, a12, a22).
        BandFit {
            contrast: s,
            offset: o,
            inverse: Some([self.n / det, -self.g / det, self.gg / det]),
        }
    }
}

impl BandFit {
    /// The residual `F − s G − o`.
    #[inline]
    pub fn residual(&self, f: f64, g: f64) -> f64 {
        f - self.contrast * g - self.offset
    }

    /// The correction coefficients `q = (AᵀA)⁻¹ [Σ G v + Σ δG r, Σ v]` of (2) for one
    /// direction, from the band sums `Σ G v`, `Σ v` and `Σ δG r` (`v = δF − s δG`); the
    /// derivative is then `δr = v − (G q₀ + q₁)`. Zero without correction.
    #[inline]
    pub fn correction(&self, gv: f64, v: f64, dg_r: f64) -> [f64; 2] {
        match self.inverse {
            None => [0.0, 0.0],
            Some([a11, a12, a22]) => {
                let (b0, b1) = (gv + dg_r, v);
                [a11 * b0 + a12 * b1, a12 * b0 + a22 * b1]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (2) against central finite differences of the projected residual (1) of a band whose
    /// fixed and moving grey levels both change along a direction (step 1e-6: truncation
    /// ~1e-12, rounding ~1e-10 of the residual scale).
    #[test]
    fn projected_residual_derivative_matches_finite_differences() {
        let n = 50;
        let f0: Vec<f64> = (0..n)
            .map(|k| 100.0 + 30.0 * (0.37 * k as f64).sin())
            .collect();
        let g0: Vec<f64> = (0..n)
            .map(|k| 80.0 + 20.0 * (0.37 * k as f64 + 0.2).sin() + (k % 7) as f64)
            .collect();
        let df: Vec<f64> = (0..n).map(|k| (0.11 * k as f64).cos()).collect();
        let dg: Vec<f64> = (0..n).map(|k| (0.23 * k as f64).sin() * 2.0).collect();
        let residuals = |t: f64| -> Vec<f64> {
            let f: Vec<f64> = (0..n).map(|k| f0[k] + t * df[k]).collect();
            let g: Vec<f64> = (0..n).map(|k| g0[k] + t * dg[k]).collect();
            let mut sums = BandSums::default();
            for k in 0..n {
                sums.add(f[k], g[k]);
            }
            let fit = sums.fit(true);
            (0..n).map(|k| fit.residual(f[k], g[k])).collect()
        };
        let mut sums = BandSums::default();
        for k in 0..n {
            sums.add(f0[k], g0[k]);
        }
        let fit = sums.fit(true);
        let r: Vec<f64> = (0..n).map(|k| fit.residual(f0[k], g0[k])).collect();
        let v: Vec<f64> = (0..n).map(|k| df[k] - fit.contrast * dg[k]).collect();
        let gv: f64 = (0..n).map(|k| g0[k] * v[k]).sum();
        let sv: f64 = v.iter().sum();
        let dgr: f64 = (0..n).map(|k| dg[k] * r[k]).sum();
        let q = fit.correction(gv, sv, dgr);
        let h = 1e-6;
        let (rp, rm) = (residuals(h), residuals(-h));
        for k in 0..n {
            let fd = (rp[k] - rm[k]) / (2.0 * h);
            let exact = v[k] - (g0[k] * q[0] + q[1]);
            assert!(
                (fd - exact).abs() < 1e-6 * (1.0 + exact.abs()),
                "{k}: {fd} vs {exact}"
            );
        }
        // The residual is orthogonal to A = [G 1].
        let rg: f64 = (0..n).map(|k| r[k] * g0[k]).sum();
        assert!(rg.abs() < 1e-8 * 1e4 && r.iter().sum::<f64>().abs() < 1e-8);
    }
}
