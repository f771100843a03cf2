//! Anderson acceleration of the modified Gauss–Newton fixed-point iteration (Anderson 1965;
//! Walker & Ni 2011, "Anderson acceleration for fixed-point iterations", SIAM J. Numer. Anal.
//! 49(4), type II, their Algorithm AA with depth `m`).
//!
//! The modified Gauss–Newton scheme of [`crate::solver`] is the fixed-point iteration
//! `a ← G(a) = a + d(a)`, `d(a) = (M + λK)⁻¹ (b(a) − λ K a)`. It converges linearly, with a rate
//! that approaches 1 where the deformed speckle has decorrelated: there the curvature of the
//! grey-level cost is well below the Gauss–Newton matrix `M` built from the reference gradient,
//! so each step covers only a small fraction of the remaining distance (measured on the GE
//! Logiq E9 frames: rates of 0.95–0.98 per iteration, 100 iterations not enough). Anderson's
//! method combines the last `m` steps,
//!
//! ```text
//! γ = argmin ‖d_k − ΔD γ‖²,   a_{k+1} = a_k + d_k − (ΔA + ΔD) γ                         (AA)
//! ```
//!
//! with `ΔA`, `ΔD` the differences of successive iterates and steps, which amounts to a secant
//! estimate of the true Jacobian of `d` on the span of the recent steps: creeping modes are
//! extrapolated instead of crawled along. The fixed point (and so the measured field) is the
//! same; only the path to it changes. Safeguard: the history is dropped (a plain step is taken)
//! when a step grows by more than [`RESTART_GROWTH`] over the previous one, or when the
//! least-squares problem is singular.
//!
//! Every buffer is allocated once in [`Anderson::new`]; [`Anderson::update`] allocates nothing.

/// The depth `femu dic` and `femu dic-check` use.
pub const DEFAULT_DEPTH: usize = 5;

/// A step longer than this factor times the previous one restarts the history.
pub const RESTART_GROWTH: f64 = 2.0;

/// History and work space of Anderson acceleration of depth `m` for `n` unknowns.
#[derive(Debug, Clone)]
pub struct Anderson {
    n: usize,
    m: usize,
    /// Ring buffers of `m` columns of `n` values: `ΔA`, `ΔD`.
    da: Vec<f64>,
    dd: Vec<f64>,
    /// Number of stored columns (≤ m) and the next slot.
    stored: usize,
    next: usize,
    prev_a: Vec<f64>,
    prev_d: Vec<f64>,
    prev_norm: f64,
    has_prev: bool,
    /// Normal equations `ΔDᵀΔD γ = ΔDᵀ d` (m x m, row-major) and `γ`.
    gram: Vec<f64>,
    gamma: Vec<f64>,
}

impl Anderson {
    /// Depth `m` (0: no acceleration, plain fixed-point steps).
    pub fn new(n: usize, m: usize) -> Self {
        Anderson {
            n,
            m,
            da: vec![0.0; n * m],
            dd: vec![0.0; n * m],
            stored: 0,
            next: 0,
            prev_a: vec![0.0; n],
            prev_d: vec![0.0; n],
            prev_norm: f64::INFINITY,
            has_prev: false,
            gram: vec![0.0; m * m],
            gamma: vec![0.0; m],
        }
    }

    /// Forgets the history (the next update is a plain step).
    pub fn reset(&mut self) {
        self.stored = 0;
        self.next = 0;
        self.has_prev = false;
        self.prev_norm = f64::INFINITY;
    }

    /// Applies one accelerated step to `a` given the plain step `d = G(a) − a` (eq. AA).
    pub fn update(&mut self, a: &mut [f64], d: &[f64]) {
        debug_assert!(a.len() == self.n && d.len() == self.n);
        let n = self.n;
        let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
        if self.m == 0 {
            a.iter_mut().zip(d).for_each(|(x, s)| *x += s);
            return;
        }
        if self.has_prev && norm > RESTART_GROWTH * self.prev_norm {
            self.reset();
        }
        if self.has_prev {
            let col = self.next * n;
            for i in 0..n {
                self.da[col + i] = a[i] - self.prev_a[i];
                self.dd[col + i] = d[i] - self.prev_d[i];
            }
            self.next = (self.next + 1) % self.m;
            self.stored = (self.stored + 1).min(self.m);
        }
        self.prev_a.copy_from_slice(a);
        self.prev_d.copy_from_slice(d);
        self.prev_norm = norm;
        self.has_prev = true;
        let k = self.stored;
        if k == 0 || !self.solve_gamma(d, k) {
            if k > 0 {
                // Singular least squares: drop the history, keep this point as the start.
                self.stored = 0;
                self.next = 0;
            }
            a.iter_mut().zip(d).for_each(|(x, s)| *x += s);
            return;
        }
        for i in 0..n {
            let mut corr = 0.0;
            for j in 0..k {
                corr += self.gamma[j] * (self.da[j * n + i] + self.dd[j * n + i]);
            }
            a[i] += d[i] - corr;
        }
    }

    /// Solves the `k x k` normal equations of (AA) by Cholesky with a relative diagonal shift
    /// of 1e-12 (the columns of `ΔD` may be nearly dependent near convergence). Returns false
    /// when they are singular or the coefficients are not finite.
    fn solve_gamma(&mut self, d: &[f64], k: usize) -> bool {
        let n = self.n;
        let col = |j: usize| &self.dd[j * n..(j + 1) * n];
        let mut trace = 0.0;
        for i in 0..k {
            for j in 0..=i {
                let s: f64 = col(i).iter().zip(col(j)).map(|(x, y)| x * y).sum();
                self.gram[i * k + j] = s;
                self.gram[j * k + i] = s;
            }
            trace += self.gram[i * k + i];
            self.gamma[i] = col(i).iter().zip(d).map(|(x, y)| x * y).sum();
        }
        if !(trace > 0.0 && trace.is_finite()) {
            return false;
        }
        for i in 0..k {
            self.gram[i * k + i] += 1e-12 * trace;
        }
        // In-place Cholesky of the k x k Gram matrix, then two triangular solves.
        let g = &mut self.gram;
        for j in 0..k {
            let mut s = g[j * k + j];
            for p in 0..j {
                s -= g[j * k + p] * g[j * k + p];
            }
            if !(s > 0.0) {
                return false;
            }
            let l = s.sqrt();
            g[j * k + j] = l;
            for i in j + 1..k {
                let mut t = g[i * k + j];
                for p in 0..j {
                    t -= g[i * k + p] * g[j * k + p];
                }
                g[i * k + j] = t / l;
            }
        }
        for i in 0..k {
            let mut t = self.gamma[i];
            for p in 0..i {
                t -= g[i * k + p] * self.gamma[p];
            }
            self.gamma[i] = t / g[i * k + i];
        }
        for i in (0..k).rev() {
            let mut t = self.gamma[i];
            for p in i + 1..k {
                t -= g[p * k + i] * self.gamma[p];
            }
            self.gamma[i] = t / g[i * k + i];
        }
        self.gamma[..k].iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slowly contracting linear fixed-point map `a ← a + P (c − B a)` (plain rate 0.98):
    /// Anderson reaches 1e-10 in far fewer steps than the plain iteration, at the same fixed
    /// point `B⁻¹ c`.
    #[test]
    fn accelerates_a_slow_linear_iteration_to_the_same_fixed_point() {
        let n = 6;
        // B diagonal with spread eigenvalues, P = 1 / max(B): rates 1 − B_i / max(B).
        let b: Vec<f64> = (0..n)
            .map(|i| [1.0, 0.02, 0.05, 0.3, 0.6, 0.9][i])
            .collect();
        let c: Vec<f64> = (0..n).map(|i| (i as f64 + 1.0).sin()).collect();
        let exact: Vec<f64> = (0..n).map(|i| c[i] / b[i]).collect();
        let run = |m: usize| {
            let mut acc = Anderson::new(n, m);
            let mut a = vec![0.0; n];
            let mut d = vec![0.0; n];
            for it in 1..=5000 {
                for i in 0..n {
                    d[i] = c[i] - b[i] * a[i];
                }
                if d.iter().map(|v| v * v).sum::<f64>().sqrt() < 1e-10 {
                    return (it, a);
                }
                acc.update(&mut a, &d);
            }
            (5000, a)
        };
        let (plain_its, plain) = run(0);
        let (aa_its, aa) = run(5);
        assert!(
            aa_its * 10 < plain_its,
            "Anderson {aa_its} vs plain {plain_its}"
        );
        for i in 0..n {
            assert!(
                (aa[i] - exact[i]).abs() < 1e-8,
                "{i}: {} vs {}",
                aa[i],
                exact[i]
            );
            assert!((plain[i] - exact[i]).abs() < 1e-7);
        }
    }
}
