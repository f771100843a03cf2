//! The smoothed master surface: a C1 cubic Hermite curve through the master nodes, with
//! Catmull–Rom nodal tangents `t_i = (x_{i+1} - x_{i-1}) / 2` (one-sided `x_{i+1} - x_i` at a
//! chain's ends), and the closest-point gap of a slave node on it, with its exact first and
//! second derivatives over the ten dofs `(x_s, x_a, x_b, x_p, x_n)` (slave, segment, the node
//! before `a` and the node after `b`).
//!
//! On segment `[x_a, x_b]`, with `h00 = 2ξ³ - 3ξ² + 1`, `h10 = ξ³ - 2ξ² + ξ`,
//! `h01 = -2ξ³ + 3ξ²`, `h11 = ξ³ - ξ²` (the cubic Hermite basis):
//!
//! ```text
//! x(ξ) = h00 x_a + h10 t_a + h01 x_b + h11 t_b,   t_a = (x_b - x_p)/2,  t_b = (x_n - x_a)/2
//! closest point:  F(ξ) = (x_s - x(ξ))·x'(ξ) = 0
//! g_N = (x_s - x(ξ))·n(ξ),   n = (x'_y, -x'_x) / |x'|
//! ```
//!
//! The nodal tangent is shared by the two segments of a node, so the surface's normal, and a
//! slave node's force, are continuous when the node passes from one segment to the next. This
//! is the smoothing of the master surface by Hermite (or Bézier) interpolation of
//! Padmanabhan & Laursen (Finite Elem. Anal. Des. 37, 2001) and of Wriggers, Computational
//! Contact Mechanics, 2nd ed., §9.4. On straight, evenly spaced master nodes the curve is the
//! segment itself with `ξ` its linear coordinate.
//!
//! The derivatives are exact: the projection is solved in `f64` by Newton's method, then two
//! more Newton steps are taken in second-order forward-mode arithmetic ([`Dual`]); each Newton
//! step doubles the number of correct derivative orders of the implicit `ξ(x)` (value → first
//! → first three), so the gradient and Hessian of `ξ` and of `g_N` are those of the exact
//! projection.

use std::ops::{Add, Mul, Neg, Sub};

/// Number of dofs of a smoothed pairing.
pub const N: usize = 10;

/// A value with its gradient and Hessian over the [`N`] dofs (second-order forward mode).
#[derive(Debug, Clone, Copy)]
pub struct Dual {
    pub v: f64,
    pub g: [f64; N],
    pub h: [[f64; N]; N],
}

impl Dual {
    pub fn constant(v: f64) -> Self {
        Dual {
            v,
            g: [0.0; N],
            h: [[0.0; N]; N],
        }
    }

    pub fn variable(v: f64, i: usize) -> Self {
        let mut d = Self::constant(v);
        d.g[i] = 1.0;
        d
    }

    /// `f(self)` from `f`, `f'`, `f''` at `self.v` (chain rule).
    fn chain(&self, f: f64, f1: f64, f2: f64) -> Self {
        let mut out = Self::constant(f);
        for i in 0..N {
            out.g[i] = f1 * self.g[i];
            for j in 0..N {
                out.h[i][j] = f1 * self.h[i][j] + f2 * self.g[i] * self.g[j];
            }
        }
        out
    }

    pub fn recip(&self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r, 2.0 * r * r * r)
    }

    pub fn sqrt(&self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s, -0.25 / (s * self.v))
    }

    pub fn scale(&self, c: f64) -> Self {
        self.chain(c * self.v, c, 0.0)
    }
}

impl Add for Dual {
    type Output = Dual;
    fn add(mut self, o: Dual) -> Dual {
        self.v += o.v;
        for i in 0..N {
            self.g[i] += o.g[i];
            for j in 0..N {
                self.h[i][j] += o.h[i][j];
            }
        }
        self
    }
}

impl Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        self.scale(-1.0)
    }
}

impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        self + (-o)
    }
}

impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        let mut out = Dual::constant(self.v * o.v);
        for i in 0..N {
            out.g[i] = self.v * o.g[i] + o.v * self.g[i];
            for j in 0..N {
                out.h[i][j] = self.v * o.h[i][j]
                    + o.v * self.h[i][j]
                    + self.g[i] * o.g[j]
                    + o.g[i] * self.g[j];
            }
        }
        out
    }
}

/// Arithmetic the Hermite curve is evaluated in: `f64` for the projection, [`Dual`] for the
/// derivatives.
pub trait Num: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> {
    fn c(v: f64) -> Self;
}

impl Num for f64 {
    fn c(v: f64) -> Self {
        v
    }
}

impl Num for Dual {
    fn c(v: f64) -> Self {
        Dual::constant(v)
    }
}

type V<T> = [T; 2];

fn dot<T: Num>(a: V<T>, b: V<T>) -> T {
    a[0] * b[0] + a[1] * b[1]
}

fn sub<T: Num>(a: V<T>, b: V<T>) -> V<T> {
    [a[0] - b[0], a[1] - b[1]]
}

/// The Hermite segment: nodes and nodal tangents.
#[derive(Clone, Copy)]
struct Curve<T> {
    xa: V<T>,
    xb: V<T>,
    ta: V<T>,
    tb: V<T>,
}

impl<T: Num> Curve<T> {
    /// `x`, `x'`, `x''` at `ξ` (module docs).
    fn eval(&self, xi: T) -> [V<T>; 3] {
        let c = T::c;
        let (x2, x3) = (xi * xi, xi * xi * xi);
        let h = [
            c(2.0) * x3 - c(3.0) * x2 + c(1.0),
            x3 - c(2.0) * x2 + xi,
            c(3.0) * x2 - c(2.0) * x3,
            x3 - x2,
        ];
        let h1 = [
            c(6.0) * x2 - c(6.0) * xi,
            c(3.0) * x2 - c(4.0) * xi + c(1.0),
            c(6.0) * xi - c(6.0) * x2,
            c(3.0) * x2 - c(2.0) * xi,
        ];
        let h2 = [
            c(12.0) * xi - c(6.0),
            c(6.0) * xi - c(4.0),
            c(6.0) - c(12.0) * xi,
            c(6.0) * xi - c(2.0),
        ];
        let comb = |w: [T; 4]| -> V<T> {
            let mut out = [c(0.0); 2];
            for (i, o) in out.iter_mut().enumerate() {
                *o = w[0] * self.xa[i] + w[1] * self.ta[i] + w[2] * self.xb[i] + w[3] * self.tb[i];
            }
            out
        };
        [comb(h), comb(h1), comb(h2)]
    }

    /// `F(ξ) = (x_s - x)·x'` and `F'(ξ) = -x'·x' + (x_s - x)·x''`.
    fn projection(&self, xs: V<T>, xi: T) -> (T, T) {
        let [x, x1, x2] = self.eval(xi);
        let d = sub(xs, x);
        (dot(d, x1), dot(d, x2) - dot(x1, x1))
    }
}

/// The curve of segment `[xa, xb]` with neighbours `xp` (before `a`) and `xn` (after `b`), or
/// reflections `2 x_a - x_b`, `2 x_b - x_a` at a chain's end.
fn curve<T: Num>(xa: V<T>, xb: V<T>, xp: Option<V<T>>, xn: Option<V<T>>) -> Curve<T> {
    let half = T::c(0.5);
    let ta = match xp {
        Some(p) => [half * (xb[0] - p[0]), half * (xb[1] - p[1])],
        None => sub(xb, xa),
    };
    let tb = match xn {
        Some(n) => [half * (n[0] - xa[0]), half * (n[1] - xa[1])],
        None => sub(xb, xa),
    };
    Curve { xa, xb, ta, tb }
}

/// The closest point `ξ` of `xs` on the curve of `[xa, xb]` (f64), started from the straight
/// segment's projection, and its distance; `None` if Newton's method does not converge (a
/// point far beyond the segment's ends, where the cubic turns).
pub fn project(
    xs: [f64; 2],
    xa: [f64; 2],
    xb: [f64; 2],
    xp: Option<[f64; 2]>,
    xn: Option<[f64; 2]>,
) -> Option<(f64, f64)> {
    let c = curve(xa, xb, xp, xn);
    let l = sub(xb, xa);
    let mut xi = (dot(sub(xs, xa), l) / dot(l, l)).clamp(-0.5, 1.5);
    for _ in 0..50 {
        let (f, f1) = c.projection(xs, xi);
        // A maximum of the distance (F' ≥ 0) is no closest point.
        if f1 >= 0.0 || !f1.is_finite() {
            return None;
        }
        let step = f / f1;
        xi -= step;
        if !(-2.0..=3.0).contains(&xi) {
            return None;
        }
        // Converged to round-off of ξ (an O(1) coordinate).
        if step.abs() <= 1e-14 {
            let [x, _, _] = c.eval(xi);
            let d = sub(xs, x);
            return Some((xi, dot(d, d).sqrt()));
        }
    }
    None
}

/// The smoothed gap and its derivatives: `(g_N, ξ, L)` as [`Dual`]s over
/// `(x_s, x_a, x_b, x_p, x_n)` (two components each), with `L = |x_b - x_a|` the chord, at the
/// converged projection `xi`.
pub fn gap(x: [[f64; 2]; 5], has_p: bool, has_n: bool, xi: f64) -> (Dual, Dual, Dual) {
    let var = |node: usize| -> V<Dual> {
        [
            Dual::variable(x[node][0], 2 * node),
            Dual::variable(x[node][1], 2 * node + 1),
        ]
    };
    let (xs, xa, xb) = (var(0), var(1), var(2));
    let c = curve(xa, xb, has_p.then(|| var(3)), has_n.then(|| var(4)));
    let mut xi = Dual::constant(xi);
    for _ in 0..2 {
        let (f, f1) = c.projection(xs, xi);
        xi = xi - f * f1.recip();
    }
    let [xc, x1, _] = c.eval(xi);
    let d = sub(xs, xc);
    // n = (x'_y, -x'_x) / |x'|: g = (d_x x'_y - d_y x'_x) / |x'|.
    let g = (d[0] * x1[1] - d[1] * x1[0]) * dot(x1, x1).sqrt().recip();
    let l = sub(xb, xa);
    let len = dot(l, l).sqrt();
    (g, xi, len)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(x: &[f64; N], has: bool) -> Option<(Dual, Dual, Dual)> {
        let p = |k: usize| [x[2 * k], x[2 * k + 1]];
        let (xi, _) = project(p(0), p(1), p(2), has.then(|| p(3)), has.then(|| p(4)))?;
        Some(gap([p(0), p(1), p(2), p(3), p(4)], has, has, xi))
    }

    /// Gradient and Hessian of `g_N`, `ξ` against central differences, on a curved chain and
    /// at a chain's end.
    #[test]
    fn smoothed_gap_derivatives_match_finite_differences() {
        let x0 = [0.4, -0.1, 0.0, 0.0, 1.0, 0.2, -0.9, 0.3, 1.8, 0.7];
        for has in [true, false] {
            let (g0, xi0, _) = values(&x0, has).unwrap();
            // Step 1e-6 on O(1) coordinates: central-difference error ~1e-10, round-off
            // ~1e-16 / 1e-6 = 1e-10 in the gradient differences.
            let h = 1e-6;
            for k in 0..N {
                let (mut xp, mut xm) = (x0, x0);
                xp[k] += h;
                xm[k] -= h;
                let (gp, xip, _) = values(&xp, has).unwrap();
                let (gm, xim, _) = values(&xm, has).unwrap();
                for (d0, dp, dm) in [(g0, gp, gm), (xi0, xip, xim)] {
                    let fd = (dp.v - dm.v) / (2.0 * h);
                    assert!((fd - d0.g[k]).abs() < 1e-8, "grad {k}: {fd} vs {}", d0.g[k]);
                    for j in 0..N {
                        let fd = (dp.g[j] - dm.g[j]) / (2.0 * h);
                        assert!(
                            (fd - d0.h[j][k]).abs() < 1e-7,
                            "hess {j} {k}: {fd} vs {}",
                            d0.h[j][k]
                        );
                    }
                }
            }
        }
    }

    /// On straight, evenly spaced nodes the curve is the segment: the straight gap and `ξ`.
    #[test]
    fn straight_even_chain_is_the_segment() {
        let (xs, xa, xb) = ([0.3, -0.25], [0.0, 0.0], [1.0, 0.0]);
        let (xi, _) = project(xs, xa, xb, Some([-1.0, 0.0]), Some([2.0, 0.0])).unwrap();
        let (g, xi_d, _) = gap([xs, xa, xb, [-1.0, 0.0], [2.0, 0.0]], true, true, xi);
        assert!((xi - 0.3).abs() < 1e-14 && (xi_d.v - 0.3).abs() < 1e-14);
        assert!((g.v - 0.25).abs() < 1e-14);
    }

    /// The normal is continuous across a master vertex: the gap gradient on the slave node at
    /// the end of one segment equals that at the start of the next.
    #[test]
    fn normal_is_continuous_across_a_vertex() {
        let nodes = [[-1.0, 0.3], [0.0, 0.0], [1.0, 0.2], [2.0, 0.9]];
        // 0.2 below the vertex along its normal (t_1 = (x_2 - x_0) / 2 = (1, -0.05)).
        let t = [1.0f64, -0.05];
        let norm = t[0].hypot(t[1]);
        let xs = [0.2 * t[1] / norm, -0.2 * t[0] / norm];
        // Segment 0-1 (neighbours none, 2) and segment 1-2 (neighbours 0, 3).
        let (xi_l, _) = project(xs, nodes[0], nodes[1], None, Some(nodes[2])).unwrap();
        let (xi_r, _) = project(xs, nodes[1], nodes[2], Some(nodes[0]), Some(nodes[3])).unwrap();
        let (gl, _, _) = gap(
            [xs, nodes[0], nodes[1], [0.0; 2], nodes[2]],
            false,
            true,
            xi_l,
        );
        let (gr, _, _) = gap(
            [xs, nodes[1], nodes[2], nodes[0], nodes[3]],
            true,
            true,
            xi_r,
        );
        // The point lies below the vertex along its normal: ξ = 1 on the left, 0 on the right.
        assert!(
            (xi_l - 1.0).abs() < 1e-12 && xi_r.abs() < 1e-12,
            "{xi_l} {xi_r}"
        );
        assert!((gl.v - gr.v).abs() < 1e-12);
        assert!((gl.g[0] - gr.g[0]).abs() < 1e-12 && (gl.g[1] - gr.g[1]).abs() < 1e-12);
    }
}
