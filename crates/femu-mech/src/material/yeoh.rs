//! Compressible Yeoh material in the Abaqus form.

use super::hyperelastic::EnergyPart;
use super::law::{AbaqusField, Bound, LawSpec, MaterialLaw, ParameterSpec, Unit, C10, D};
use super::hyperelastic::{inv_cbrt, volumetric_quadratic, Hyperelastic, InvariantDerivatives};

/// Compressible Yeoh material (Yeoh 1993; Abaqus `*HYPERELASTIC, YEOH`):
/// `W = C10 (I1bar - 3) + C20 (I1bar - 3)² + C30 (I1bar - 3)³ + (1/D) (J - 1)²`.
///
/// Abaqus' data line is `C10, C20, C30, D1, D2, D3` with the volumetric terms
/// `Σ_i (J - 1)^(2i) / D_i`; femu implements the first (D = D1) and reads D2 and D3 only as 0
/// (a non-zero value is an error naming the deck line).
///
/// Small-strain moduli: `μ = 2 C10`, `K = 2/D`. Validity: C10 > 0, C30 ≥ 0, and
/// `∂W/∂I1bar = C10 + 2 C20 x + 3 C30 x² > 0` for every `x = I1bar - 3 ≥ 0` (the stress of
/// simple tension and shear grows with the stretch at every level), which for C20 < 0 is
/// `C20² < 3 C10 C30`. Units: C10, C20, C30 in MPa, D in MPa⁻¹.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Yeoh {
    pub c10: f64,
    pub c20: f64,
    pub c30: f64,
    pub d: f64,
}

/// The Yeoh energy with any real coefficients `(c10, c20, c30, inv_d)` (the last one the
/// coefficient of `(J - 1)²`, i.e. 1/D): the form of its terms `E_k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YeohTerms {
    pub c10: f64,
    pub c20: f64,
    pub c30: f64,
    pub inv_d: f64,
}

/// `Σ_i C_i0 x^i` with `x = J^(-2/3) I1 - 3` and its invariant derivatives (chain rule through
/// x: `x_I = J^(-2/3)`, `x_J = -2/3 I1 J^(-5/3)`, `x_IJ = -2/3 J^(-5/3)`,
/// `x_JJ = 10/9 I1 J^(-8/3)`).
#[inline(always)]
fn isochoric(c: [f64; 3], i1: f64, j: f64) -> InvariantDerivatives {
    let y = inv_cbrt(j);
    let jm23 = y * y;
    let jm1 = jm23 * y;
    let jm53 = jm23 * jm1;
    let jm83 = jm53 * jm1;
    let x = jm23 * i1 - 3.0;
    let w = x * (c[0] + x * (c[1] + x * c[2]));
    let dw = c[0] + x * (2.0 * c[1] + 3.0 * x * c[2]);
    let ddw = 2.0 * c[1] + 6.0 * x * c[2];
    let (x_i, x_j) = (jm23, -2.0 / 3.0 * i1 * jm53);
    let (x_ij, x_jj) = (-2.0 / 3.0 * jm53, 10.0 / 9.0 * i1 * jm83);
    InvariantDerivatives {
        w,
        w_i: dw * x_i,
        w_j: dw * x_j,
        w_ii: ddw * x_i * x_i,
        w_ij: ddw * x_i * x_j + dw * x_ij,
        w_jj: ddw * x_j * x_j + dw * x_jj,
    }
}

impl Hyperelastic for YeohTerms {
    #[inline]
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives {
        isochoric([self.c10, self.c20, self.c30], i1, j)
    }

    #[inline]
    fn volumetric(&self, j: f64) -> [f64; 3] {
        volumetric_quadratic(self.inv_d, j)
    }
}

impl Hyperelastic for Yeoh {
    #[inline]
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives {
        isochoric([self.c10, self.c20, self.c30], i1, j)
    }

    #[inline]
    fn volumetric(&self, j: f64) -> [f64; 3] {
        volumetric_quadratic(1.0 / self.d, j)
    }
}

/// C20 or C30: a coefficient of a higher power of `I1bar - 3`.
const fn higher(
    name: &'static str,
    lower: Bound,
    typical: f64,
    doc: &'static str,
) -> ParameterSpec {
    ParameterSpec {
        name,
        unit: Unit::Stress,
        lower,
        upper: Bound::Closed(super::law::STRESS_MAX_MPA),
        log_scale: false,
        part: EnergyPart::Isochoric,
        typical,
        doc,
    }
}

impl MaterialLaw for Yeoh {
    const SPEC: LawSpec = LawSpec {
        name: "yeoh",
        abaqus_keyword: "YEOH",
        abaqus_fields: &[
            AbaqusField {
                name: "C10",
                parameter: Some(0),
            },
            AbaqusField {
                name: "C20",
                parameter: Some(1),
            },
            AbaqusField {
                name: "C30",
                parameter: Some(2),
            },
            AbaqusField {
                name: "D1",
                parameter: Some(3),
            },
            AbaqusField {
                name: "D2",
                parameter: None,
            },
            AbaqusField {
                name: "D3",
                parameter: None,
            },
        ],
        parameters: &[
            ParameterSpec {
                doc: "coefficient of I1bar - 3; small-strain shear modulus 2 C10",
                ..C10
            },
            higher(
                "C20",
                Bound::Closed(-super::law::STRESS_MAX_MPA),
                -0.3e-3,
                "coefficient of (I1bar - 3)²; if negative, C20² < 3 C10 C30",
            ),
            higher(
                "C30",
                Bound::Closed(0.0),
                0.2e-3,
                "coefficient of (I1bar - 3)³",
            ),
            D,
        ],
        doc: "W = C10 (I1bar - 3) + C20 (I1bar - 3)² + C30 (I1bar - 3)³ + (J - 1)²/D \
              (Abaqus YEOH with D2 = D3 = 0)",
    };
    type UnitEnergy = YeohTerms;

    fn with_parameters(values: &[f64]) -> Self {
        let [c10, c20, c30, d] = values.try_into().expect("four Yeoh parameters");
        Yeoh { c10, c20, c30, d }
    }

    fn parameter_value(&self, k: usize) -> f64 {
        [self.c10, self.c20, self.c30, self.d][k]
    }

    fn parameter_value_mut(&mut self, k: usize) -> &mut f64 {
        [&mut self.c10, &mut self.c20, &mut self.c30, &mut self.d]
            .into_iter()
            .nth(k)
            .expect("a Yeoh parameter")
    }

    fn unit_energy(k: usize) -> YeohTerms {
        let mut t = [0.0; 4];
        t[k] = 1.0;
        YeohTerms {
            c10: t[0],
            c20: t[1],
            c30: t[2],
            inv_d: t[3],
        }
    }

    /// 1 for C10, C20 and C30; `d(1/D)/dD = -1/D²` for D.
    fn coefficient_rate(&self, k: usize) -> f64 {
        [1.0, 1.0, 1.0, -1.0 / (self.d * self.d)][k]
    }

    /// `μ = 2 C10` (the higher terms vanish to second order at F = I), `K = 2/D`.
    fn small_strain_moduli(&self) -> [f64; 2] {
        [2.0 * self.c10, 2.0 / self.d]
    }

    /// `C10 + 2 C20 x + 3 C30 x² > 0` for all `x ≥ 0` (C10 > 0 and C30 ≥ 0 are the bounds).
    fn check_joint(&self) -> Result<(), String> {
        if self.c20 < 0.0 && !(self.c20 * self.c20 < 3.0 * self.c10 * self.c30) {
            return Err(format!(
                "C20 = {} MPa is negative, which needs C20² < 3 C10 C30 (here {:.3e} ≥ {:.3e} \
                 MPa²) for ∂W/∂I1bar to stay positive at every stretch",
                self.c20,
                self.c20 * self.c20,
                3.0 * self.c10 * self.c30
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stability condition on C20: at the limit `C20² = 3 C10 C30`, `∂W/∂I1bar` touches 0.
    #[test]
    fn negative_c20_needs_a_cubic_term() {
        let ok = Yeoh {
            c10: 1e-3,
            c20: -0.5e-3,
            c30: 0.1e-3,
            d: 10.0,
        };
        assert!(ok.check_joint().is_ok());
        let limit = Yeoh {
            c20: -(3.0f64 * 1e-3 * 0.1e-3).sqrt() * 1.0001,
            ..ok
        };
        assert!(limit.check_joint().unwrap_err().contains("C20²"));
        assert!(Yeoh { c30: 0.0, ..ok }.check_joint().is_err());
        assert!(Yeoh { c20: 0.5e-3, c30: 0.0, ..ok }.check_joint().is_ok());
    }
}
