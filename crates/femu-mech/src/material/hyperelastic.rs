//! The hyperelastic core every law and every element shares: in-plane tensors, the
//! [`Hyperelastic`] trait (an energy through its invariant derivatives, split into isochoric
//! and volumetric parts), the stress and tangent it gives, and the power functions of J.
//! Nothing here knows of elements or of the registry, so that both can build on it. The 3D
//! counterparts (3x3 tensors, the invariants `(I1, I2, J)`, P and A of a 3D F) serve the
//! solid elements of [`crate::solid3d`].

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
    /// Kirchhoff stress `τ33 = F33 ∂W/∂F33` out of plane (the constraint stress of plane strain),
    /// of the 3D energy at `F33 = 1` (see [`Hyperelastic::plane_strain_i2_tau33`]).
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
        let mut r = assemble_response(f, det2(f), &d, tangent);
        r.tau33 = with_i2_term(r.tau33, self.plane_strain_i2_tau33(f));
        Ok(r)
    }

    /// Isochoric energy, stress and tangent only (the hybrid element adds the volumetric part).
    fn response_isochoric(
        &self,
        f: &Tensor2,
        tangent: bool,
    ) -> Result<StressResponse, NonPositiveJacobian> {
        let d = self.derivatives_isochoric(f)?;
        let mut r = assemble_response(f, det2(f), &d, tangent);
        r.tau33 = with_i2_term(r.tau33, self.plane_strain_i2_tau33(f));
        Ok(r)
    }

    /// The part of the out-of-plane Kirchhoff stress `τ33 = F33 ∂W/∂F33` (at `F33 = 1`) that
    /// the plane-strain energy `W(I1, J)` of [`Hyperelastic::isochoric`] misses when it writes
    /// an `I2` term through the identity `I2 = J² + I1 - 1`: `2 W_2 (I1 - 2 - J²)`, with
    /// `W_2 = ∂W/∂I2` of the 3D form ([`Hyperelastic::isochoric_3d`]) at the plane-strain state.
    ///
    /// With `C = diag(C_2D, 1)`: `∂I1/∂F33 = 2`, `∂I2/∂F33 = 2 (I1 - C33) = 2 (I1 - 1)`,
    /// `∂J/∂F33 = J`, so the 3D law gives `τ33 = 2 W_1 + 2 W_2 (I1 - 1) + W_J J`; the chain rule
    /// through the identity gives the plane-strain derivatives `w_I = W_1 + W_2`,
    /// `w_J = W_J + 2 J W_2`, whose `τ33 = 2 w_I + w_J J` (of `stress`) is short by the term
    /// returned. The in-plane stress and tangent are exact either way (I2 and its identity
    /// agree for every in-plane F). Zero for a law of `(I1, J)` (the default
    /// `isochoric_3d` has no `I2` dependence).
    #[inline]
    fn plane_strain_i2_tau33(&self, f: &Tensor2) -> f64 {
        let j = det2(f);
        let i1 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] + f[3] * f[3] + 1.0;
        let w2 = self.isochoric_3d(i1, j * j + i1 - 1.0, j).w_2;
        2.0 * w2 * (i1 - 2.0 - j * j)
    }

    /// The isochoric part in three dimensions through its derivatives at `(I1, I2, J)`, with
    /// `I1 = tr C`, `I2 = ½ (I1² - C:C)` of the 3D `C = FᵀF`.
    ///
    /// [`Hyperelastic::isochoric`] is already the 3D energy as a function of `(I1, J)` for every
    /// law without an `I2` term (the plane-strain elements only set `F33 = 1`), so the default
    /// is that, with no `I2` dependence. A law with an `I2` term writes it through the
    /// plane-strain identity `I2 = J² + I1 - 1` in `isochoric` and must give its 3D form here
    /// (Mooney–Rivlin does).
    #[inline]
    fn isochoric_3d(&self, i1: f64, i2: f64, j: f64) -> InvariantDerivatives3 {
        let _ = i2;
        InvariantDerivatives3::from(self.isochoric(i1, j))
    }

    /// Derivatives of the isochoric part at a 3D deformation gradient F (row-major 3x3).
    #[inline]
    fn derivatives_isochoric_3d(
        &self,
        f: &Tensor3,
    ) -> Result<InvariantDerivatives3, NonPositiveJacobian> {
        let [i1, i2, j] = invariants3(f);
        if !(j > 0.0) {
            return Err(NonPositiveJacobian(j));
        }
        Ok(self.isochoric_3d(i1, i2, j))
    }

    /// Derivatives of the whole energy `W_iso + U` at a 3D deformation gradient F.
    #[inline]
    fn derivatives_3d(&self, f: &Tensor3) -> Result<InvariantDerivatives3, NonPositiveJacobian> {
        let mut d = self.derivatives_isochoric_3d(f)?;
        let [u, du, ddu] = self.volumetric(det3(f));
        d.w += u;
        d.w_j += du;
        d.w_jj += ddu;
        Ok(d)
    }
}

/// A 3x3 tensor stored row-major: `[F11, F12, F13, F21, ..., F33]`.
pub type Tensor3 = [f64; 9];
/// A fourth-order 3D tensor `A[(iJ)][(kL)]`, indices as in [`Tensor3`].
pub type Tensor4x3 = [[f64; 9]; 9];

/// Determinant of a 3x3 tensor.
#[inline]
pub fn det3(f: &Tensor3) -> f64 {
    f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6])
        + f[2] * (f[3] * f[7] - f[4] * f[6])
}

/// Cofactor `H = J F^-T` of a 3x3 tensor (`∂ det F / ∂F`; `H_iJ = ½ ε_ijk ε_JKL F_jK F_kL`).
#[inline]
pub fn cof3(f: &Tensor3) -> Tensor3 {
    [
        f[4] * f[8] - f[5] * f[7],
        f[5] * f[6] - f[3] * f[8],
        f[3] * f[7] - f[4] * f[6],
        f[2] * f[7] - f[1] * f[8],
        f[0] * f[8] - f[2] * f[6],
        f[1] * f[6] - f[0] * f[7],
        f[1] * f[5] - f[2] * f[4],
        f[2] * f[3] - f[0] * f[5],
        f[0] * f[4] - f[1] * f[3],
    ]
}

/// `(I1, I2, J)` of a 3D deformation gradient: `I1 = F:F = tr C`, `I2 = H:H = tr cof C`
/// (`= ½ (I1² - C:C)`), `J = det F`.
#[inline]
pub fn invariants3(f: &Tensor3) -> [f64; 3] {
    let h = cof3(f);
    let i1 = f.iter().map(|v| v * v).sum();
    let i2 = h.iter().map(|v| v * v).sum();
    [i1, i2, det3(f)]
}

/// Derivatives of W with respect to the 3D invariants (I1, I2, J); `w_i`, `w_ii`, `w_ij` are
/// those of [`InvariantDerivatives`] (with respect to I1), the others name I2 by `2`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InvariantDerivatives3 {
    pub w: f64,
    pub w_i: f64,
    pub w_2: f64,
    pub w_j: f64,
    pub w_ii: f64,
    pub w_i2: f64,
    pub w_22: f64,
    pub w_ij: f64,
    pub w_2j: f64,
    pub w_jj: f64,
}

impl From<InvariantDerivatives> for InvariantDerivatives3 {
    /// An energy of (I1, J) only.
    fn from(d: InvariantDerivatives) -> Self {
        InvariantDerivatives3 {
            w: d.w,
            w_i: d.w_i,
            w_j: d.w_j,
            w_ii: d.w_ii,
            w_ij: d.w_ij,
            w_jj: d.w_jj,
            ..Default::default()
        }
    }
}

/// `∂I2/∂F = 2 (I1 F - F C)` at F.
#[inline]
fn di2_df(f: &Tensor3, i1: f64) -> Tensor3 {
    let c = right_cauchy_green3(f);
    std::array::from_fn(|r| {
        let (i, jj) = (r / 3, r % 3);
        let fc: f64 = (0..3).map(|m| f[3 * i + m] * c[3 * m + jj]).sum();
        2.0 * (i1 * f[r] - fc)
    })
}

/// `C = FᵀF` (row-major).
#[inline]
pub fn right_cauchy_green3(f: &Tensor3) -> Tensor3 {
    std::array::from_fn(|r| {
        let (a, b) = (r / 3, r % 3);
        (0..3).map(|m| f[3 * m + a] * f[3 * m + b]).sum()
    })
}

/// First Piola–Kirchhoff stress `P = 2 W_1 F + 2 W_2 (I1 F - F C) + W_J H` (H = cof F) from
/// the invariant derivatives at a 3D F (Holzapfel, *Nonlinear Solid Mechanics*, 2000, §6.2:
/// `P = Σ_a W_a ∂I_a/∂F`).
pub fn pk1_3d(f: &Tensor3, d: &InvariantDerivatives3) -> Tensor3 {
    let h = cof3(f);
    let i1: f64 = f.iter().map(|v| v * v).sum();
    let s2 = if d.w_2 != 0.0 {
        di2_df(f, i1)
    } else {
        [0.0; 9]
    };
    std::array::from_fn(|r| 2.0 * d.w_i * f[r] + d.w_2 * s2[r] + d.w_j * h[r])
}

/// The Levi-Civita symbol `ε_ijk`.
#[inline]
fn levi_civita(i: usize, j: usize, k: usize) -> f64 {
    match (i, j, k) {
        (0, 1, 2) | (1, 2, 0) | (2, 0, 1) => 1.0,
        (0, 2, 1) | (2, 1, 0) | (1, 0, 2) => -1.0,
        _ => 0.0,
    }
}

/// The consistent tangent `A = dP/dF` at a 3D F from the invariant derivatives: with
/// `S_1 = 2F`, `S_2 = ∂I2/∂F`, `S_J = H`,
///
/// ```text
/// A = Σ_ab W_ab S_a ⊗ S_b + 2 W_1 𝕀 + W_2 ∂S_2/∂F + W_J ∂H/∂F,
/// ∂S_2/∂F_(iJ)(kL) = 2 (2 F_iJ F_kL + I1 δ_ik δ_JL - δ_ik C_JL - F_iL F_kJ - b_ik δ_JL),
/// ∂H_iJ/∂F_kL = ε_ikm ε_JLM F_mM
/// ```
///
/// (b = F Fᵀ). The 2D tangent of [`Hyperelastic::response`] is its restriction to `F33 = 1`
/// (`∂H/∂F` then reduces to the constant [`DCOF`]); `tests/solid3d.rs` checks that.
pub fn tangent_3d(f: &Tensor3, d: &InvariantDerivatives3) -> Tensor4x3 {
    let h = cof3(f);
    let s1: Tensor3 = f.map(|v| 2.0 * v);
    let has_i2 = d.w_2 != 0.0 || d.w_22 != 0.0 || d.w_i2 != 0.0 || d.w_2j != 0.0;
    let i1: f64 = f.iter().map(|v| v * v).sum();
    let s2 = if has_i2 { di2_df(f, i1) } else { [0.0; 9] };
    let mut a = [[0.0; 9]; 9];
    for r in 0..9 {
        for c in 0..9 {
            a[r][c] = d.w_ii * s1[r] * s1[c]
                + d.w_i2 * (s1[r] * s2[c] + s2[r] * s1[c])
                + d.w_22 * s2[r] * s2[c]
                + d.w_ij * (s1[r] * h[c] + h[r] * s1[c])
                + d.w_2j * (s2[r] * h[c] + h[r] * s2[c])
                + d.w_jj * h[r] * h[c];
        }
        a[r][r] += 2.0 * d.w_i;
    }
    // W_J ∂H/∂F: ε_ikm ε_JLM F_mM is non-zero only for i ≠ k and J ≠ L, with m and M the
    // remaining indices (3 - i - k, 3 - J - L).
    for i in 0..3 {
        for k in (0..3).filter(|&k| k != i) {
            let m = 3 - i - k;
            let e_ikm = levi_civita(i, k, m);
            for jj in 0..3 {
                for l in (0..3).filter(|&l| l != jj) {
                    let mm = 3 - jj - l;
                    a[3 * i + jj][3 * k + l] +=
                        d.w_j * e_ikm * levi_civita(jj, l, mm) * f[3 * m + mm];
                }
            }
        }
    }
    if d.w_2 != 0.0 {
        let c = right_cauchy_green3(f);
        let b: Tensor3 = std::array::from_fn(|r| {
            let (p, q) = (r / 3, r % 3);
            (0..3).map(|m| f[3 * p + m] * f[3 * q + m]).sum()
        });
        for i in 0..3 {
            for jj in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        let (dik, djl) =
                            (f64::from(u8::from(i == k)), f64::from(u8::from(jj == l)));
                        let v = 2.0 * f[3 * i + jj] * f[3 * k + l] + i1 * dik * djl
                            - dik * c[3 * jj + l]
                            - f[3 * i + l] * f[3 * k + jj]
                            - b[3 * i + k] * djl;
                        a[3 * i + jj][3 * k + l] += 2.0 * d.w_2 * v;
                    }
                }
            }
        }
    }
    a
}

/// Cauchy stress `σ = P Fᵀ / J` in Abaqus order `[σ11, σ22, σ33, σ12, σ13, σ23]` from the
/// invariant derivatives `d` of the energy at a 3D F.
pub fn cauchy_3d(f: &Tensor3, d: &InvariantDerivatives3) -> [f64; 6] {
    let p = pk1_3d(f, d);
    let j = det3(f);
    let s = |i: usize, k: usize| (0..3).map(|m| p[3 * i + m] * f[3 * k + m]).sum::<f64>() / j;
    [s(0, 0), s(1, 1), s(2, 2), s(0, 1), s(0, 2), s(1, 2)]
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
/// of `law` there (its whole energy, or its isochoric part for the hybrid element), σzz with
/// the `I2` term of [`Hyperelastic::plane_strain_i2_tau33`].
pub fn cauchy_from_derivatives<H: Hyperelastic + ?Sized>(
    law: &H,
    f: &Tensor2,
    d: &InvariantDerivatives,
) -> [f64; 4] {
    let (pk1, tau33) = stress(f, det2(f), d);
    let tau33 = with_i2_term(tau33, law.plane_strain_i2_tau33(f));
    cauchy_from_pk1(f, &pk1, tau33)
}

/// `tau33 + i2_term`, and `tau33` itself (to the bit, signed zero included) when the term is
/// zero: a law of `(I1, J)` keeps its τ33 unchanged.
#[inline(always)]
fn with_i2_term(tau33: f64, i2_term: f64) -> f64 {
    if i2_term == 0.0 {
        tau33
    } else {
        tau33 + i2_term
    }
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
