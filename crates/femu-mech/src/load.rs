//! Loads: follower pressure on element faces (with its load stiffness) and dead nodal forces.

/// Follower pressure `p` (MPa, positive pushing into the element) on a straight 2-node face
/// whose nodes `a → b` run counter-clockwise around the element, in plane strain per mm of
/// thickness.
///
/// With the current tangent `t = x_b - x_a` the outward normal times length is `(t_y, -t_x)`,
/// so the force `-p (t_y, -t_x)` is shared equally by both nodes (exact for a straight face).
/// The face's contribution to the residual `R = f_int - f_ext` and its load stiffness
/// `K_L = -∂f_ext/∂x` are given by [`PressureFace::external_force`] and
/// [`PressureFace::load_stiffness`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureFace {
    pub element: usize,
    /// Local node numbers of the face within its element (a, b).
    pub local: [usize; 2],
    /// Global node indices (a, b).
    pub nodes: [usize; 2],
    pub pressure: f64,
}

impl PressureFace {
    /// Nodal forces `[f_ax, f_ay, f_bx, f_by]` at current positions `xa`, `xb`, scaled by `lambda`.
    #[inline]
    pub fn external_force(&self, xa: [f64; 2], xb: [f64; 2], lambda: f64) -> [f64; 4] {
        let h = 0.5 * lambda * self.pressure;
        let fx = -h * (xb[1] - xa[1]);
        let fy = h * (xb[0] - xa[0]);
        [fx, fy, fx, fy]
    }

    /// `K_L = -∂f_ext/∂x` (4x4 row-major over `[ax, ay, bx, by]`), constant for a straight face.
    #[inline]
    pub fn load_stiffness(&self, lambda: f64) -> [[f64; 4]; 4] {
        let h = 0.5 * lambda * self.pressure;
        // f_x = -h (y_b - y_a): ∂/∂y_a = h, ∂/∂y_b = -h.  f_y = h (x_b - x_a): ∂/∂x_a = -h, ∂/∂x_b = h.
        let rx = [0.0, -h, 0.0, h];
        let ry = [h, 0.0, -h, 0.0];
        [rx, ry, rx, ry]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pressure_on_bottom_face_pushes_up() {
        // Bottom face of a CCW element runs +x; pressure pushes into the element (+y).
        let f = PressureFace {
            element: 0,
            local: [0, 1],
            nodes: [0, 1],
            pressure: 2.0,
        };
        let r = f.external_force([0.0, 0.0], [3.0, 0.0], 1.0);
        assert_eq!(r, [0.0, 3.0, 0.0, 3.0]);
    }

    #[test]
    fn load_stiffness_matches_finite_differences() {
        let f = PressureFace {
            element: 0,
            local: [0, 1],
            nodes: [0, 1],
            pressure: 0.7,
        };
        let x = [0.3, -0.2, 1.4, 0.5];
        let k = f.load_stiffness(0.9);
        let h = 1e-6;
        for j in 0..4 {
            let mut xp = x;
            let mut xm = x;
            xp[j] += h;
            xm[j] -= h;
            let fp = f.external_force([xp[0], xp[1]], [xp[2], xp[3]], 0.9);
            let fm = f.external_force([xm[0], xm[1]], [xm[2], xm[3]], 0.9);
            for i in 0..4 {
                let fd = -(fp[i] - fm[i]) / (2.0 * h);
                assert!((fd - k[i][j]).abs() < 1e-9);
            }
        }
    }
}
