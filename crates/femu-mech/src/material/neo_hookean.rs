//! Compressible Neo-Hookean material in the Abaqus form (seed Eq. 1).

use super::law::{AbaqusField, LawSpec, MaterialLaw, C10, D};
use super::hyperelastic::{inv_cbrt, volumetric_quadratic, Hyperelastic, InvariantDerivatives};

/// Compressible Neo-Hookean material in the Abaqus form (seed Eq. 1):
/// `W = C10 (I1bar - 3) + (1/D) (J - 1)^2`, `I1bar = J^(-2/3) I1`.
///
/// Small-strain equivalents: shear modulus `μ = 2 C10`, bulk modulus `K = 2/D` (the seed's
/// "K = D/2" is a typo). Units: C10 in MPa, D in MPa^-1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeoHookean {
    pub c10: f64,
    pub d: f64,
}

impl NeoHookean {
    /// A Neo-Hookean material; C10 > 0 and D > 0 (compressible) are required.
    pub fn new(c10: f64, d: f64) -> Result<Self, String> {
        if !(c10 > 0.0 && c10.is_finite()) {
            return Err(format!("C10 must be positive and finite, got {c10}"));
        }
        if !(d > 0.0 && d.is_finite()) {
            return Err(format!(
                "D must be positive and finite (compressible), got {d}"
            ));
        }
        Ok(NeoHookean { c10, d })
    }
}

/// `c10 (J^(-2/3) I1 - 3)` and its invariant derivatives.
#[inline(always)]
fn neo_hookean_isochoric(c10: f64, i1: f64, j: f64) -> InvariantDerivatives {
    // The powers of J from J^(-1/3) by products (no cube root, no division).
    let y = inv_cbrt(j);
    let jm23 = y * y;
    let jm1 = jm23 * y;
    let jm53 = jm23 * jm1;
    let jm83 = jm53 * jm1;
    InvariantDerivatives {
        w: c10 * (jm23 * i1 - 3.0),
        w_i: c10 * jm23,
        w_j: -2.0 / 3.0 * c10 * i1 * jm53,
        w_ii: 0.0,
        w_ij: -2.0 / 3.0 * c10 * jm53,
        w_jj: 10.0 / 9.0 * c10 * i1 * jm83,
    }
}

impl Hyperelastic for NeoHookean {
    #[inline]
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives {
        neo_hookean_isochoric(self.c10, i1, j)
    }

    #[inline]
    fn volumetric(&self, j: f64) -> [f64; 3] {
        volumetric_quadratic(1.0 / self.d, j)
    }
}

/// The energy `a (I1bar - 3) + b (J - 1)^2` with any real coefficients (no positivity check):
/// the terms of the Neo-Hookean energy. `W` is linear in C10 and in 1/D, so `∂W/∂C10` is this
/// form with `(a, b) = (1, 0)` and `∂W/∂D` with `(0, -1/D²)`; evaluated by an element, it
/// gives the exact `∂f_int/∂θ` (parameter sensitivities, seed §2.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeoHookeanRate {
    /// `a`, the rate of C10.
    pub c10: f64,
    /// `b`, the rate of 1/D.
    pub inv_d: f64,
}

impl NeoHookeanRate {
    /// `∂W/∂C10`: the energy `I1bar - 3`.
    pub const UNIT_C10: NeoHookeanRate = NeoHookeanRate {
        c10: 1.0,
        inv_d: 0.0,
    };
    /// `∂W/∂(1/D)`: the energy `(J - 1)²`.
    pub const UNIT_INV_D: NeoHookeanRate = NeoHookeanRate {
        c10: 0.0,
        inv_d: 1.0,
    };
}

impl Hyperelastic for NeoHookeanRate {
    fn isochoric(&self, i1: f64, j: f64) -> InvariantDerivatives {
        neo_hookean_isochoric(self.c10, i1, j)
    }

    fn volumetric(&self, j: f64) -> [f64; 3] {
        volumetric_quadratic(self.inv_d, j)
    }
}

impl MaterialLaw for NeoHookean {
    const SPEC: LawSpec = LawSpec {
        name: "neo-hookean",
        abaqus_keyword: "NEO HOOKE",
        abaqus_fields: &[
            AbaqusField {
                name: "C10",
                parameter: Some(0),
            },
            AbaqusField {
                name: "D1",
                parameter: Some(1),
            },
        ],
        parameters: &[C10, D],
        doc: "W = C10 (I1bar - 3) + (J - 1)²/D (Abaqus NEO HOOKE; seed Eq. 1)",
    };
    type UnitEnergy = NeoHookeanRate;

    fn with_parameters(values: &[f64]) -> Self {
        let [c10, d] = values.try_into().expect("two Neo-Hookean parameters");
        NeoHookean { c10, d }
    }

    fn parameter_value(&self, k: usize) -> f64 {
        [self.c10, self.d][k]
    }

    fn parameter_value_mut(&mut self, k: usize) -> &mut f64 {
        [&mut self.c10, &mut self.d].into_iter().nth(k).expect("a Neo-Hookean parameter")
    }

    fn unit_energy(k: usize) -> NeoHookeanRate {
        [NeoHookeanRate::UNIT_C10, NeoHookeanRate::UNIT_INV_D][k]
    }

    /// 1 for C10; `d(1/D)/dD = -1/D²` for D.
    fn coefficient_rate(&self, k: usize) -> f64 {
        [1.0, -1.0 / (self.d * self.d)][k]
    }

    /// `μ = 2 C10`, `K = 2/D`.
    fn small_strain_moduli(&self) -> [f64; 2] {
        [2.0 * self.c10, 2.0 / self.d]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_parameters() {
        assert!(NeoHookean::new(-1.0, 1.0).is_err());
        assert!(NeoHookean::new(1.0, 0.0).is_err());
        assert!(NeoHookean::new(f64::NAN, 1.0).is_err());
    }
}
