//! The hyperelastic core every law and every element shares: in-plane tensors, the
//! [`Hyperelastic`] trait (an energy through its invariant derivatives, split into isochoric
//! and volumetric parts), the stress and tangent it gives, and the power functions of J.
//! Nothing here knows of elements or of the registry, so that both can build on it.

/// Which part of the energy a parameter's term `E_k` lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EnergyPart {
    /// `E_k(I1, J)` of the isochoric part (the hybrid element evaluates it at each Gauss point).
    Isochoric,
    /// `E_k(J)` of the volumetric part (the hybrid element evaluates it at the mean dilatation).
    Volumetric,
}

/// A 2x2 in-plane tensor stored row-major: `[F11, F12, F21, F22]`.
pub type Tensor2 = [f64; 4];
/// A fourth-order in-plane tensor `A[(iJ)][(kL)]`, indices as in [`Tensor2`].
pub type Tensor4 = [[f64; 4]; 4];

/// Determinant of a 2x2 tensor.
#[inline]
pub fn det2(f: &Tensor2) -> f64 {
    f[0] * f[3] - f[1] * f[2]
}

/// Cofactor `J F^-T` of a 2x2 tensor (the derivative of `det F`).
#[inline]
pub fn cof2(f: &Tensor2) -> Tensor2 {
    [f[3], -f[2], -f[1], f[0]]
}

/// `d cof(F)_α / d F_β` (constant in 2D): cof = [F22, -F21, -F12, F11].
pub const DCOF: Tensor4 = [
    [0.0, 0.0, 0.0, 1.0],
    [0.0, 0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0, 0.0],
    [1.0, 0.0, 0.0, 0.0],
];

/// Energy, stress and tangent of a material point.
#[derive(Debug, Clone, Copy, Default)]
pub struct StressResponse {
    /// Strain energy density W (MPa).
    pub energy: f64,
    /// First Piola–Kirchhoff stress (in-plane).
    pub pk1: Tensor2,
    /// Kirchhoff stress `τ33 = F33 ∂W/∂F33` out of plane (the constraint stress of plane strain).
    pub tau33: f64,
    /// `dP/dF` (only filled when asked for).
    pub tangent: Tensor4,
}

/// Derivatives of W with respect to the invariants (I1, J).
#[derive(Debug, Clone, Copy, Default)]
pub struct InvariantDerivatives {
    pub w: f64,
    pub w_i: f64,
    pub w_j: f64,
    pub w_ii: f64,
    pub w_ij: f64,
    pub w_jj: f64,
}

/// Error of a material evaluation: the element is inverted at this point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NonPositiveJacobian(pub f64);

/// A hyperelastic material of plane strain, split as `W = W_iso(F) + U(J)`.
pub trait Hyperelastic: Send + Sync + std::fmt::Debug {
    /// Isochoric part through its invariant derivatives at `(I1, J)`.
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives;
    /// Volumetric part `(U, U', U'')` at J.
    fn volumetric(&self, j: f64) -> [f64; 3];

    /// Derivatives of the whole energy `W_iso + U` with respect to `(I1, J)` at F. The
    /// elements build their forces and tangents from these directly (see
    /// [`crate::element`]), without forming P and A.
    #[inline]
    fn derivatives(&self, f: &Tensor2) -> Result<InvariantDerivatives, NonPositiveJacobian> {
        let mut d = self.derivatives_isochoric(f)?;
        let [u, du, ddu] = self.volumetric(det2(f));
        d.w += u;
        d.w_j += du;
        d.w_jj += ddu;
        Ok(d)
    }

    /// Derivatives of the isochoric part only, at F (the hybrid element adds the volumetric
    /// part of its mean dilatation).
    #[inline]
    fn derivatives_isochoric(
        &self,
        f: &Tensor2,
    ) -> Result<InvariantDerivatives, NonPositiveJacobian> {
        let j = det2(f);
        if !(j > 0.0) {
            return Err(NonPositiveJacobian(j));
        }
        let i1 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] + f[3] * f[3] + 1.0;
        Ok(self.isochoric(i1, j))
    }

    /// Full energy, stress and (if `tangent`) consistent tangent at F.
    fn response(&self, f: &Tensor2, tangent: bool) -> Result<StressResponse, NonPositiveJacobian> {
        let d = self.derivatives(f)?;
        Ok(assemble_response(f, det2(f), &d, tangent))
    }

    /// Isochoric energy, stress and tangent only (the hybrid element adds the volumetric part).
    fn response_isochoric(
        &self,
        f: &Tensor2,
        tangent: bool,
    ) -> Result<StressResponse, NonPositiveJacobian> {
        let d = self.derivatives_isochoric(f)?;
        Ok(assemble_response(f, det2(f), &d, tangent))
    }
}

/// `P = 2 W_I F + W_J cof F` and `τ33` from the invariant derivatives at F (J = det F).
#[inline]
fn stress(f: &Tensor2, j: f64, d: &InvariantDerivatives) -> (Tensor2, f64) {
    let c = cof2(f);
    let pk1 = std::array::from_fn(|a| 2.0 * d.w_i * f[a] + d.w_j * c[a]);
    // τ33 = F33 ∂W/∂F33 with F33 = 1: ∂I1/∂F33 = 2 F33, ∂J3/∂F33 = J2 (J3 = J2 F33).
    (pk1, 2.0 * d.w_i + d.w_j * j)
}

/// Cauchy stress `[σxx, σyy, σzz, σxy]` at F from the invariant derivatives `d` of the energy
/// there.
pub fn cauchy_from_derivatives(f: &Tensor2, d: &InvariantDerivatives) -> [f64; 4] {
    let (pk1, tau33) = stress(f, det2(f), d);
    cauchy_from_pk1(f, &pk1, tau33)
}

/// Builds P, τ33 and A from the invariant derivatives (see the module documentation).
fn assemble_response(
    f: &Tensor2,
    j: f64,
    d: &InvariantDerivatives,
    tangent: bool,
) -> StressResponse {
    let c = cof2(f);
    let (pk1, tau33) = stress(f, j, d);
    let mut a4 = [[0.0; 4]; 4];
    if tangent {
        for a in 0..4 {
            for b in 0..4 {
                a4[a][b] = 4.0 * d.w_ii * f[a] * f[b]
                    + 2.0 * d.w_ij * (f[a] * c[b] + c[a] * f[b])
                    + d.w_jj * c[a] * c[b]
                    + d.w_j * DCOF[a][b];
            }
            a4[a][a] += 2.0 * d.w_i;
        }
    }
    StressResponse {
        energy: d.w,
        pk1,
        tau33,
        tangent: a4,
    }
}

/// `J^(-1/3)` for `J > 0`, within 1.5 ulp of `1 / J.cbrt()` (unit test), at less than half its
/// cost: a first guess from the exponent bits (about 3 % off), then three steps of the
/// cubically convergent `y ← y (1 + r/3 + 2r²/9)`, `r = 1 - J y³` (the series of
/// `(1 - r)^(-1/3)`; relative error 3 % → 1e-4 → 1e-13 → round-off). Values outside
/// `[1e-30, 1e30]` (never a deformation) go through `cbrt`.
#[inline(always)]
pub fn inv_cbrt(j: f64) -> f64 {
    if !(1e-30..=1e30).contains(&j) {
        return 1.0 / j.cbrt();
    }
    // Dividing the bits by three divides the biased exponent by three; the constant restores
    // the bias and negates the exponent (the inverse-square-root trick, for cube roots).
    let mut y = f64::from_bits(0x553e_f0ff_289d_d796u64.wrapping_sub(j.to_bits() / 3));
    for _ in 0..3 {
        let r = 1.0 - j * y * y * y;
        y += y * r * (1.0 / 3.0 + 2.0 / 9.0 * r);
    }
    y
}

/// `inv_d (J - 1)²` and its first two derivatives: the volumetric term every registered law
/// shares (`inv_d` = 1/D).
#[inline(always)]
pub fn volumetric_quadratic(inv_d: f64, j: f64) -> [f64; 3] {
    let jm1 = j - 1.0;
    [jm1 * jm1 * inv_d, 2.0 * jm1 * inv_d, 2.0 * inv_d]
}

/// Cauchy stress `[σxx, σyy, σzz, σxy]` from a response at F (J = det F).
pub fn cauchy_from_pk1(f: &Tensor2, pk1: &Tensor2, tau33: f64) -> [f64; 4] {
    let j = det2(f);
    // τ = P F^T
    let txx = pk1[0] * f[0] + pk1[1] * f[1];
    let txy = pk1[0] * f[2] + pk1[1] * f[3];
    let tyy = pk1[2] * f[2] + pk1[3] * f[3];
    [txx / j, tyy / j, tau33 / j, txy / j]
}

/// Logarithmic (Hencky) strain `LE = ln V = ½ ln(F F^T)` as `[LExx, LEyy, LEzz, LExy]`
/// (LEzz = 0 in plane strain) — Abaqus' LE, shown in the seed's Fig. 3.
pub fn log_strain(f: &Tensor2) -> [f64; 4] {
    let bxx = f[0] * f[0] + f[1] * f[1];
    let bxy = f[0] * f[2] + f[1] * f[3];
    let byy = f[2] * f[2] + f[3] * f[3];
    let mean = 0.5 * (bxx + byy);
    let half_diff = 0.5 * (bxx - byy);
    let r = (half_diff * half_diff + bxy * bxy).sqrt();
    let l1 = mean + r;
    let l2 = mean - r;
    let (e1, e2) = (0.5 * l1.ln(), 0.5 * l2.ln());
    if r < 1e-14 * mean.abs().max(1.0) {
        return [e1, e1, 0.0, 0.0];
    }
    // Eigenvector of the larger eigenvalue: (cos φ, sin φ) with cos 2φ = (bxx - byy) / (2 r),
    // sin 2φ = bxy / r; `e1 c² + e2 s² = (e1 + e2)/2 + (e1 - e2)/2 cos 2φ` and so on, without
    // evaluating φ.
    let (cos2, sin2) = (half_diff / r, bxy / r);
    let (m, h) = (0.5 * (e1 + e2), 0.5 * (e1 - e2));
    [m + h * cos2, m - h * cos2, 0.0, h * sin2]
}
