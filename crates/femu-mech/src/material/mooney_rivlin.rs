//! Compressible Mooney–Rivlin material in the Abaqus form.

use super::hyperelastic::{
    inv_cbrt, volumetric_quadratic, EnergyPart, Hyperelastic, InvariantDerivatives,
    InvariantDerivatives3,
};
use super::law::{AbaqusField, Bound, LawSpec, MaterialLaw, ParameterSpec, Unit, C10, D};

/// Compressible Mooney–Rivlin material (Abaqus `*HYPERELASTIC, MOONEY-RIVLIN`):
/// `W = C10 (I1bar - 3) + C01 (I2bar - 3) + (1/D) (J - 1)²`, `I1bar = J^(-2/3) I1`,
/// `I2bar = J^(-4/3) I2`.
///
/// **Plane strain.** With `F33 = 1` the right Cauchy–Green tensor has the eigenvalues `λ1²`,
/// `λ2²` and 1, so `I2 = λ1² λ2² + λ1² + λ2² = J² + I1 - 1`: the energy is a function of
/// `(I1, J)` like every law of [`crate::material`],
///
/// ```text
/// W_iso(I1, J) = C10 (J^(-2/3) I1 - 3) + C01 (J^(-4/3) (I1 - 1) + J^(2/3) - 3)
/// ```
///
/// (the identity is checked against `I2 = ½ (I1² - tr C²)` in a test); the 3D solid elements
/// use the energy in `(I1, I2, J)` ([`Hyperelastic::isochoric_3d`]). The identity holds for
/// every in-plane F, so the in-plane stress and tangent are exact, but its derivative along
/// F33 is not that of I2: the out-of-plane stress σzz adds the difference from the 3D form
/// ([`Hyperelastic::plane_strain_i2_tau33`], `2 C01 J^(-4/3) (I1 - 2 - J²)` in τ33).
/// Small-strain moduli: `μ = 2 (C10 + C01)`, `K = 2/D`. C10 > 0 and C01 ≥ 0 keep the energy
/// polyconvex (C01 = 0 is the Neo-Hookean law). Units: C10, C01 in MPa, D in MPa⁻¹.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MooneyRivlin {
    pub c10: f64,
    pub c01: f64,
    pub d: f64,
}

/// The Mooney–Rivlin energy with any real coefficients `(c10, c01, inv_d)` (the last one the
/// coefficient of `(J - 1)²`, i.e. 1/D): the form of its terms `E_k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MooneyRivlinTerms {
    pub c10: f64,
    pub c01: f64,
    pub inv_d: f64,
}

/// `J^(-1/3), J^(-2/3), J^(-4/3), J^(-5/3), J^(-7/3), J^(-8/3), J^(-10/3)` from `J^(-1/3)` by
/// products (no other root, no division).
#[inline(always)]
fn j_powers(j: f64) -> [f64; 7] {
    let y = inv_cbrt(j);
    let jm23 = y * y;
    let jm1 = jm23 * y;
    let jm43 = jm23 * jm23;
    let jm53 = jm23 * jm1;
    let jm73 = jm43 * jm1;
    [y, jm23, jm43, jm53, jm73, jm53 * jm1, jm73 * jm1]
}

/// `c10 (I1bar - 3) + c01 (I2bar - 3)` in plane strain and its invariant derivatives.
#[inline(always)]
fn isochoric(c10: f64, c01: f64, i1: f64, j: f64) -> InvariantDerivatives {
    let [y, jm23, jm43, jm53, jm73, jm83, jm103] = j_powers(j);
    let j23 = j * y;
    let i1m1 = i1 - 1.0;
    InvariantDerivatives {
        w: c10 * (jm23 * i1 - 3.0) + c01 * (jm43 * i1m1 + j23 - 3.0),
        w_i: c10 * jm23 + c01 * jm43,
        w_j: -2.0 / 3.0 * c10 * i1 * jm53 + c01 * (-4.0 / 3.0 * i1m1 * jm73 + 2.0 / 3.0 * y),
        w_ii: 0.0,
        w_ij: -2.0 / 3.0 * c10 * jm53 - 4.0 / 3.0 * c01 * jm73,
        w_jj: 10.0 / 9.0 * c10 * i1 * jm83 + c01 * (28.0 / 9.0 * i1m1 * jm103 - 2.0 / 9.0 * jm43),
    }
}

/// `c10 (I1bar - 3) + c01 (I2bar - 3)` in 3D (`I2bar = J^(-4/3) I2`, I2 independent of I1
/// and J) and its invariant derivatives.
#[inline(always)]
fn isochoric_3d(c10: f64, c01: f64, i1: f64, i2: f64, j: f64) -> InvariantDerivatives3 {
    let [_, jm23, jm43, jm53, jm73, jm83, jm103] = j_powers(j);
    InvariantDerivatives3 {
        w: c10 * (jm23 * i1 - 3.0) + c01 * (jm43 * i2 - 3.0),
        w_i: c10 * jm23,
        w_2: c01 * jm43,
        w_j: -2.0 / 3.0 * c10 * i1 * jm53 - 4.0 / 3.0 * c01 * i2 * jm73,
        w_ii: 0.0,
        w_i2: 0.0,
        w_22: 0.0,
        w_ij: -2.0 / 3.0 * c10 * jm53,
        w_2j: -4.0 / 3.0 * c01 * jm73,
        w_jj: 10.0 / 9.0 * c10 * i1 * jm83 + 28.0 / 9.0 * c01 * i2 * jm103,
    }
}

impl Hyperelastic for MooneyRivlinTerms {
    #[inline]
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives {
        isochoric(self.c10, self.c01, i1, j)
    }

    #[inline]
    fn isochoric_3d(&self, i1: f64, i2: f64, j: f64) -> InvariantDerivatives3 {
        isochoric_3d(self.c10, self.c01, i1, i2, j)
    }

    #[inline]
    fn volumetric(&self, j: f64) -> [f64; 3] {
        volumetric_quadratic(self.inv_d, j)
    }
}

impl Hyperelastic for MooneyRivlin {
    #[inline]
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives {
        isochoric(self.c10, self.c01, i1, j)
    }

    #[inline]
    fn isochoric_3d(&self, i1: f64, i2: f64, j: f64) -> InvariantDerivatives3 {
        isochoric_3d(self.c10, self.c01, i1, i2, j)
    }

    #[inline]
    fn volumetric(&self, j: f64) -> [f64; 3] {
        volumetric_quadratic(1.0 / self.d, j)
    }
}

impl MaterialLaw for MooneyRivlin {
    const SPEC: LawSpec = LawSpec {
        name: "mooney-rivlin",
        abaqus_keyword: "MOONEY-RIVLIN",
        abaqus_fields: &[
            AbaqusField {
                name: "C10",
                parameter: Some(0),
            },
            AbaqusField {
                name: "C01",
                parameter: Some(1),
            },
            AbaqusField {
                name: "D1",
                parameter: Some(2),
            },
        ],
        parameters: &[
            ParameterSpec {
                typical: 1.0e-3,
                doc: "coefficient of I1bar - 3; small-strain shear modulus 2 (C10 + C01)",
                ..C10
            },
            ParameterSpec {
                name: "C01",
                unit: Unit::Stress,
                lower: Bound::Closed(0.0),
                upper: Bound::Closed(super::law::STRESS_MAX_MPA),
                log_scale: false,
                part: EnergyPart::Isochoric,
                typical: 0.75e-3,
                doc: "coefficient of I2bar - 3; 0 is the Neo-Hookean law",
            },
            D,
        ],
        doc: "W = C10 (I1bar - 3) + C01 (I2bar - 3) + (J - 1)²/D (Abaqus MOONEY-RIVLIN)",
    };
    type UnitEnergy = MooneyRivlinTerms;

    fn with_parameters(values: &[f64]) -> Self {
        let [c10, c01, d] = values.try_into().expect("three Mooney-Rivlin parameters");
        MooneyRivlin { c10, c01, d }
    }

    fn parameter_value(&self, k: usize) -> f64 {
        [self.c10, self.c01, self.d][k]
    }

    fn parameter_value_mut(&mut self, k: usize) -> &mut f64 {
        [&mut self.c10, &mut self.c01, &mut self.d]
            .into_iter()
            .nth(k)
            .expect("a Mooney-Rivlin parameter")
    }

    fn unit_energy(k: usize) -> MooneyRivlinTerms {
        let mut t = [0.0; 3];
        t[k] = 1.0;
        MooneyRivlinTerms {
            c10: t[0],
            c01: t[1],
            inv_d: t[2],
        }
    }

    /// 1 for C10 and C01; `d(1/D)/dD = -1/D²` for D.
    fn coefficient_rate(&self, k: usize) -> f64 {
        [1.0, 1.0, -1.0 / (self.d * self.d)][k]
    }

    /// `μ = 2 (C10 + C01)`, `K = 2/D`.
    fn small_strain_moduli(&self) -> [f64; 2] {
        [2.0 * (self.c10 + self.c01), 2.0 / self.d]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `I2 = J² + I1 - 1` in plane strain: against `½ (I1² - tr C²)` of the 3D tensor
    /// `C = diag(C2, 1)` for random in-plane F.
    #[test]
    fn plane_strain_second_invariant() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..1000 {
            let f = [1.0 + next(), next(), next(), 1.0 + next()];
            let c = [
                f[0] * f[0] + f[2] * f[2],
                f[0] * f[1] + f[2] * f[3],
                f[1] * f[1] + f[3] * f[3],
            ];
            let i1 = c[0] + c[2] + 1.0;
            let tr_c2 = c[0] * c[0] + 2.0 * c[1] * c[1] + c[2] * c[2] + 1.0;
            let i2 = 0.5 * (i1 * i1 - tr_c2);
            let j = f[0] * f[3] - f[1] * f[2];
            assert!((i2 - (j * j + i1 - 1.0)).abs() < 1e-13 * i2.abs().max(1.0));
        }
    }

    /// With C01 = 0 the law is the Neo-Hookean one (to round-off: the same terms summed).
    #[test]
    fn c01_zero_is_neo_hookean() {
        let mr = MooneyRivlin {
            c10: 1.75e-3,
            c01: 0.0,
            d: 18.0,
        };
        let nh = super::super::NeoHookean { c10: 1.75e-3, d: 18.0 };
        let f = [1.1, 0.2, -0.1, 0.9];
        let (a, b) = (mr.derivatives(&f).unwrap(), nh.derivatives(&f).unwrap());
        for (x, y) in [
            (a.w, b.w),
            (a.w_i, b.w_i),
            (a.w_j, b.w_j),
            (a.w_ij, b.w_ij),
            (a.w_jj, b.w_jj),
        ] {
            assert!((x - y).abs() <= 1e-15 * y.abs().max(1e-3), "{x} vs {y}");
        }
    }
}
