//! Independent reference solutions for verification.
//!
//! [`ThickCylinder`]: a plane-strain annulus of one or more concentric Neo-Hookean layers,
//! inner radius fixed, outer radius loaded by a follower pressure. The radially symmetric
//! problem is a two-point boundary-value ODE in the reference radius R for the state
//! `(r, P_rr)`:
//!
//! ```text
//! dr/dR    = λ_r                        (λ_r solved from P_rr(λ_r, λ_θ = r/R) = P_rr)
//! dP_rr/dR = -(P_rr - P_θθ) / R         (radial equilibrium, first Piola–Kirchhoff)
//! r(R_in) = R_in,   P_rr(R_out) = -p r(R_out)/R_out   (σ_rr = -p on the deformed surface)
//! ```
//!
//! with `P_rr = ∂W/∂λ_r`, `P_θθ = ∂W/∂λ_θ` written out from the principal stretches
//! (independent of the tensor code of [`crate::material`]). Shooting on `P_rr(R_in)` with
//! Newton (secant) iterations, classical RK4 integration.

/// One layer `r_from < R < r_to` of Neo-Hookean material.
#[derive(Debug, Clone, Copy)]
pub struct Layer {
    pub r_to: f64,
    pub c10: f64,
    pub d: f64,
}

/// The thick-walled cylinder problem.
#[derive(Debug, Clone)]
pub struct ThickCylinder {
    pub r_in: f64,
    /// Layers from inside to outside; the last `r_to` is the outer radius.
    pub layers: Vec<Layer>,
    /// Outer follower pressure (MPa).
    pub pressure: f64,
}

fn principal_stresses(c10: f64, d: f64, lr: f64, lt: f64) -> (f64, f64) {
    let j = lr * lt;
    let i1 = lr * lr + lt * lt + 1.0;
    let jm23 = j.powf(-2.0 / 3.0);
    let vol = 2.0 / d * (j - 1.0);
    let prr = c10 * (2.0 * lr * jm23 - 2.0 / 3.0 * i1 * jm23 / j * lt) + vol * lt;
    let ptt = c10 * (2.0 * lt * jm23 - 2.0 / 3.0 * i1 * jm23 / j * lr) + vol * lr;
    (prr, ptt)
}

impl ThickCylinder {
    /// Outer radius.
    pub fn r_out(&self) -> f64 {
        self.layers.last().map_or(self.r_in, |l| l.r_to)
    }

    fn layer_at(&self, r: f64) -> &Layer {
        self.layers
            .iter()
            .find(|l| r < l.r_to)
            .unwrap_or(self.layers.last().unwrap())
    }

    /// λ_r such that P_rr(λ_r, λ_θ) = target (P_rr increases monotonically with λ_r).
    fn stretch(&self, layer: &Layer, lt: f64, target: f64) -> f64 {
        let mut lr: f64 = 1.0;
        for _ in 0..100 {
            let (p, _) = principal_stresses(layer.c10, layer.d, lr, lt);
            let h = 1e-7 * lr;
            let (pp, _) = principal_stresses(layer.c10, layer.d, lr + h, lt);
            let dp = (pp - p) / h;
            let step = (p - target) / dp;
            let mut next = lr - step;
            if next <= 0.0 {
                next = 0.5 * lr;
            }
            if (next - lr).abs() < 1e-15 * lr {
                return next;
            }
            lr = next;
        }
        lr
    }

    fn rhs(&self, layer: &Layer, rr: f64, y: [f64; 2]) -> [f64; 2] {
        let lt = y[0] / rr;
        let lr = self.stretch(layer, lt, y[1]);
        let (prr, ptt) = principal_stresses(layer.c10, layer.d, lr, lt);
        [lr, -(prr - ptt) / rr]
    }

    /// Integrates from the inner radius with `P_rr(R_in) = p0`; returns the state at every layer
    /// end (the last is the outer surface).
    fn shoot(&self, p0: f64, steps_per_layer: usize) -> Vec<[f64; 2]> {
        let mut y = [self.r_in, p0];
        let mut r0 = self.r_in;
        let mut out = Vec::with_capacity(self.layers.len());
        for layer in &self.layers {
            let h = (layer.r_to - r0) / steps_per_layer as f64;
            for k in 0..steps_per_layer {
                let rr = r0 + k as f64 * h;
                let k1 = self.rhs(layer, rr, y);
                let k2 = self.rhs(
                    layer,
                    rr + 0.5 * h,
                    [y[0] + 0.5 * h * k1[0], y[1] + 0.5 * h * k1[1]],
                );
                let k3 = self.rhs(
                    layer,
                    rr + 0.5 * h,
                    [y[0] + 0.5 * h * k2[0], y[1] + 0.5 * h * k2[1]],
                );
                let k4 = self.rhs(layer, rr + h, [y[0] + h * k3[0], y[1] + h * k3[1]]);
                for i in 0..2 {
                    y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
            r0 = layer.r_to;
            out.push(y);
        }
        out
    }

    fn outer_mismatch(&self, p0: f64, steps: usize) -> (f64, Vec<[f64; 2]>) {
        let states = self.shoot(p0, steps);
        let y = *states.last().unwrap();
        let ro = self.r_out();
        (y[1] + self.pressure * y[0] / ro, states)
    }

    /// Deformed radius at every layer end (the last is the outer surface), solved so that the
    /// outer boundary condition holds to round-off, with `steps_per_layer` RK4 steps.
    pub fn solve(&self, steps_per_layer: usize) -> Vec<f64> {
        let _ = self.layer_at(self.r_in);
        // Secant iterations on P_rr(R_in), starting from the small-strain guess -p.
        let mut p_a = -self.pressure;
        let mut p_b = -1.1 * self.pressure;
        let (mut f_a, _) = self.outer_mismatch(p_a, steps_per_layer);
        let mut states = Vec::new();
        for _ in 0..60 {
            let (f_b, s) = self.outer_mismatch(p_b, steps_per_layer);
            states = s;
            if f_b.abs() < 1e-15 * self.pressure.abs().max(1e-300) || f_b == f_a {
                break;
            }
            let p_c = p_b - f_b * (p_b - p_a) / (f_b - f_a);
            p_a = p_b;
            f_a = f_b;
            p_b = p_c;
        }
        states.iter().map(|y| y[0]).collect()
    }

    /// Radial displacement of the outer surface, converged in the number of RK4 steps to about
    /// 1e-10 relative (checked by step doubling).
    pub fn outer_displacement(&self) -> f64 {
        let ro = self.r_out();
        let coarse = self.solve(2000).last().copied().unwrap() - ro;
        let fine = self.solve(4000).last().copied().unwrap() - ro;
        debug_assert!(
            (coarse - fine).abs() <= 1e-8 * fine.abs() + 1e-13 * ro,
            "{coarse} vs {fine}"
        );
        fine
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_pressure_matches_linear_elasticity() {
        // Single layer, tiny pressure: Lamé solution for plane strain, inner radius fixed.
        let (c10, d) = (1.0, 0.2); // μ = 2, K = 10
        let mu = 2.0 * c10;
        let k = 2.0 / d;
        let lam = k - 2.0 / 3.0 * mu;
        let (a, b, p) = (1.0, 2.0, 1e-6);
        let cyl = ThickCylinder {
            r_in: a,
            layers: vec![Layer { r_to: b, c10, d }],
            pressure: p,
        };
        // u = A r + B / r, u(a) = 0, σ_rr(b) = 2(λ+μ) A - 2μ B / b² = -p.
        let bb = -p / (2.0 * (lam + mu) * (-1.0 / (a * a)) - 2.0 * mu / (b * b));
        let aa = -bb / (a * a);
        let u_lin = aa * b + bb / b;
        let u = cyl.outer_displacement();
        assert!((u - u_lin).abs() < 1e-5 * u_lin.abs(), "{u} vs {u_lin}");
    }
}
