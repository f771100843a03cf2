//! Follower pressure on a face of a 3D element: the 3D counterpart of [`crate::load`].
//!
//! A pressure p on a face acts against its current outward normal: with the face map
//! `x(ξ, η) = Σ_a N_a(ξ, η) x_a` (current positions) and the face nodes ordered so that
//! `x_,ξ × x_,η` points out of the body,
//!
//! ```text
//! f_a = -p ∫ N_a (x_,ξ × x_,η) dξ dη
//! ∂f_a/∂x_b = -p ∫ N_a (N_b,η [x_,ξ]× - N_b,ξ [x_,η]×) dξ dη
//! ```
//!
//! (`[v]×` the matrix of `w ↦ v × w`); the second is the load stiffness, which the Newton
//! tangent subtracts (Bonet & Wood, *Nonlinear Continuum Mechanics for Finite Element
//! Analysis*, 2nd ed., §8.4.2). Faces: the 4-node bilinear quadrilateral (a hexahedron's face,
//! 2x2 Gauss points), the 3-node triangle (a C3D4 face, one point, exact for its linear shape
//! functions and constant normal) and the 6-node triangle (a C3D10 face: corners, then the
//! mid-edge nodes of 1–2, 2–3, 3–1; the 6-point rule of degree 4, exact for the quadratic shape
//! functions times the quadratic normal of a curved face; Dunavant 1985).

/// Largest number of face nodes and face dofs.
pub const MAX_FACE_NODES: usize = 6;
pub const MAX_FACE_DOFS: usize = 3 * MAX_FACE_NODES;

/// The points `(ξ, η)`, weights, shape functions and their derivatives of a face of `n` nodes.
fn face_rule(n: usize) -> Vec<(f64, [f64; 6], [[f64; 2]; 6])> {
    match n {
        4 => {
            const G: f64 = 0.577_350_269_189_625_8; // 1/sqrt(3)
            [[-G, -G], [G, -G], [G, G], [-G, G]]
                .iter()
                .map(|&[xi, eta]| {
                    let s = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
                    let (mut n, mut dn) = ([0.0; 6], [[0.0; 2]; 6]);
                    for (k, [a, b]) in s.into_iter().enumerate() {
                        n[k] = 0.25 * (1.0 + a * xi) * (1.0 + b * eta);
                        dn[k] = [0.25 * a * (1.0 + b * eta), 0.25 * b * (1.0 + a * xi)];
                    }
                    (1.0, n, dn)
                })
                .collect()
        }
        3 => vec![(
            0.5,
            [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, 0.0, 0.0, 0.0],
            [
                [-1.0, -1.0],
                [1.0, 0.0],
                [0.0, 1.0],
                [0.0; 2],
                [0.0; 2],
                [0.0; 2],
            ],
        )],
        6 => {
            const A: f64 = 0.445_948_490_915_965;
            const WA: f64 = 0.223_381_589_678_011;
            const B: f64 = 0.091_576_213_509_771;
            const WB: f64 = 0.109_951_743_655_322;
            let points = [
                ([A, A], WA),
                ([1.0 - 2.0 * A, A], WA),
                ([A, 1.0 - 2.0 * A], WA),
                ([B, B], WB),
                ([1.0 - 2.0 * B, B], WB),
                ([B, 1.0 - 2.0 * B], WB),
            ];
            points
                .iter()
                .map(|&([xi, eta], w)| {
                    let l = [1.0 - xi - eta, xi, eta];
                    let dl = [[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]];
                    let (mut n, mut dn) = ([0.0; 6], [[0.0; 2]; 6]);
                    for a in 0..3 {
                        n[a] = l[a] * (2.0 * l[a] - 1.0);
                        dn[a] = dl[a].map(|v| (4.0 * l[a] - 1.0) * v);
                    }
                    for (e, [i, j]) in [[0, 1], [1, 2], [2, 0]].into_iter().enumerate() {
                        n[3 + e] = 4.0 * l[i] * l[j];
                        dn[3 + e] =
                            std::array::from_fn(|r| 4.0 * (l[i] * dl[j][r] + l[j] * dl[i][r]));
                    }
                    // The weights are for a unit area; the reference triangle's is 1/2.
                    (0.5 * w, n, dn)
                })
                .collect()
        }
        n => panic!("pressure faces have 3, 4 or 6 nodes, not {n}"),
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The external force (`3 n`) of a pressure `p` on the face whose current node positions are
/// `x` (3, 4 or 6 nodes, outward order), and if asked its derivative with respect to the node
/// positions (row-major `3n x 3n`, `∂f_(ai)/∂x_(bk)`).
pub fn face_pressure(x: &[[f64; 3]], p: f64, force: &mut [f64], stiffness: Option<&mut [f64]>) {
    let n = x.len();
    let nd = 3 * n;
    force[..nd].fill(0.0);
    let mut stiffness = stiffness;
    if let Some(k) = stiffness.as_deref_mut() {
        k[..nd * nd].fill(0.0);
    }
    for (w, shape, dn) in face_rule(n) {
        let tangent = |r: usize| -> [f64; 3] {
            std::array::from_fn(|i| (0..n).map(|a| dn[a][r] * x[a][i]).sum())
        };
        let (t1, t2) = (tangent(0), tangent(1));
        let normal = cross(t1, t2);
        for a in 0..n {
            for i in 0..3 {
                force[3 * a + i] -= p * w * shape[a] * normal[i];
            }
        }
        if let Some(k) = stiffness.as_deref_mut() {
            // [v]× as rows: ([v]×)_ik = ε_ijk v_j
            let skew = |v: [f64; 3]| [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]];
            let (s1, s2) = (skew(t1), skew(t2));
            for a in 0..n {
                for b in 0..n {
                    let c = -p * w * shape[a];
                    for i in 0..3 {
                        for kk in 0..3 {
                            k[(3 * a + i) * nd + 3 * b + kk] +=
                                c * (dn[b][1] * s1[i][kk] - dn[b][0] * s2[i][kk]);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a flat unit square (outward +z) the total force is `-p` times the area along z, a
    /// quarter on each node; on a triangle a third; on a 6-node triangle a third on each mid-edge
    /// node.
    #[test]
    fn flat_faces_carry_pressure_times_area() {
        let square = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [2.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let mut f = [0.0; 12];
        face_pressure(&square, 0.5, &mut f, None);
        for a in 0..4 {
            assert!((f[3 * a + 2] + 0.25).abs() < 1e-15 && f[3 * a].abs() < 1e-15);
        }
        let tri = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        face_pressure(&tri, 0.6, &mut f, None);
        for a in 0..3 {
            assert!((f[3 * a + 2] + 0.2).abs() < 1e-15);
        }
        // The 6-node triangle: nothing on the corners, a third on each mid-edge node (to the
        // 15 digits of the rule's constants).
        let tri6 = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.5, 0.0],
            [0.0, 0.5, 0.0],
        ];
        let mut f6 = [0.0; 18];
        face_pressure(&tri6, 0.6, &mut f6, None);
        for a in 0..6 {
            let want = if a < 3 { 0.0 } else { -0.2 };
            assert!(
                (f6[3 * a + 2] - want).abs() < 1e-14,
                "{a}: {}",
                f6[3 * a + 2]
            );
        }
    }

    /// The load stiffness is the derivative of the force, on warped and curved faces.
    #[test]
    fn load_stiffness_is_the_derivative_of_the_force() {
        let quad = vec![
            [0.0, 0.0, 0.1],
            [2.1, 0.2, -0.1],
            [1.9, 1.2, 0.3],
            [-0.2, 0.9, 0.0],
        ];
        let tri = vec![[0.0, 0.0, 0.1], [2.1, 0.2, -0.1], [0.3, 1.2, 0.3]];
        let mut tri6 = tri.clone();
        for ([i, j], bump) in [([0, 1], 0.05), ([1, 2], -0.04), ([2, 0], 0.03)] {
            tri6.push(std::array::from_fn(|r| {
                0.5 * (tri[i][r] + tri[j][r]) + bump
            }));
        }
        for x in [quad, tri, tri6] {
            let nd = 3 * x.len();
            let (mut f, mut k) = ([0.0; 18], [0.0; 324]);
            face_pressure(&x, 0.7, &mut f, Some(&mut k));
            let scale = k[..nd * nd].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            // The force is quadratic in the positions: central differences are exact but for
            // round-off (ε |f| / h ≈ 1e-10 at h = 1e-6).
            let h = 1e-6;
            for c in 0..nd {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[c / 3][c % 3] += h;
                xm[c / 3][c % 3] -= h;
                let (mut fp, mut fm) = ([0.0; 18], [0.0; 18]);
                face_pressure(&xp, 0.7, &mut fp, None);
                face_pressure(&xm, 0.7, &mut fm, None);
                for r in 0..nd {
                    let fd = (fp[r] - fm[r]) / (2.0 * h);
                    assert!((fd - k[r * nd + c]).abs() < 1e-8 * scale, "{r} {c}");
                }
            }
        }
    }
}
