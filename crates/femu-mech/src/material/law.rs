//! What a registered material law declares ([`MaterialLaw`], [`LawSpec`], [`ParameterSpec`]) and
//! the object-safe [`Material`] every model material is used through.
//!
//! Every law is written as `W = Σ_k c_k(θ_k) E_k(F)`: each parameter `θ_k` enters through one
//! coefficient `c_k` (C10 → C10, D → 1/D) of a fixed energy `E_k` that lives either in the
//! isochoric part `W_iso(I1, J)` or in the volumetric part `U(J)` ([`EnergyPart`]). The three
//! registered laws are of this form, and it gives the parameter derivatives the sensitivities
//! need exactly: `∂W/∂θ_k = c_k'(θ_k) E_k`, an energy the elements integrate like any other
//! (seed §2.3). A law that is not linear in a function of each parameter (Ogden's exponents)
//! would need a different rate; none is registered.

use super::hyperelastic::{EnergyPart, Hyperelastic, NonPositiveJacobian};
use crate::element::{ElementGeometry, ElementResult, MAX_DOFS};
use std::fmt;

/// The physical unit of a parameter. Values are stored in the internal units of the decks (MPa,
/// MPa⁻¹); study files name their unit in the key (`c10_kpa`), reports show [`Unit::report`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Unit {
    /// A stress or energy density coefficient (C10, C01, C20, ...): MPa, shown in kPa.
    Stress,
    /// A volumetric compliance (D): MPa⁻¹.
    Compliance,
}

impl Unit {
    /// The internal unit (the deck's).
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Stress => "MPa",
            Unit::Compliance => "MPa⁻¹",
        }
    }

    /// The unit reports show (the seed's Table 1) and the factor from the internal unit to it.
    pub fn report(self) -> (&'static str, f64) {
        match self {
            Unit::Stress => ("kPa", 1e3),
            Unit::Compliance => ("MPa⁻¹", 1.0),
        }
    }

    /// The key suffixes a study file may use for this unit and the factor from the keyed value
    /// to the internal unit: `c10_kpa = 1.75` is 1.75e-3 MPa.
    pub fn key_suffixes(self) -> &'static [(&'static str, f64)] {
        match self {
            Unit::Stress => &[("kpa", 1e-3), ("mpa", 1.0)],
            Unit::Compliance => &[("per_mpa", 1.0), ("per_kpa", 1e3)],
        }
    }
}

/// One end of a parameter's validity range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// The value itself is excluded (`C10 > 0`).
    Open(f64),
    /// The value itself is allowed (`C01 ≥ 0`).
    Closed(f64),
    /// No bound on this side (besides finiteness).
    Unbounded,
}

/// A parameter as its law declares it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParameterSpec {
    /// `C10`, `C01`, `D`, ...: with the material's name it makes the parameter's name
    /// (`C10_FAT`), and lower case with a unit suffix its study-file key (`c10_kpa`).
    pub name: &'static str,
    pub unit: Unit,
    pub lower: Bound,
    pub upper: Bound,
    /// Whether the identification should work on `ln θ` (a positive scale parameter).
    pub log_scale: bool,
    /// Where its energy term lives (see the module documentation).
    pub part: EnergyPart,
    /// A representative value in internal units (thigh tissue; documentation, and the value
    /// the generic tests of every registered law start from).
    pub typical: f64,
    pub doc: &'static str,
}

impl ParameterSpec {
    /// Whether `value` is finite and within the bounds.
    pub fn admits(&self, value: f64) -> bool {
        let lower = match self.lower {
            Bound::Open(b) => value > b,
            Bound::Closed(b) => value >= b,
            Bound::Unbounded => true,
        };
        let upper = match self.upper {
            Bound::Open(b) => value < b,
            Bound::Closed(b) => value <= b,
            Bound::Unbounded => true,
        };
        value.is_finite() && lower && upper
    }

    /// The valid range in words: `> 0`, `≥ 0 and ≤ 1`, `any finite value`.
    pub fn range(&self) -> String {
        let lower = match self.lower {
            Bound::Open(b) => Some(format!("> {b}")),
            Bound::Closed(b) => Some(format!("≥ {b}")),
            Bound::Unbounded => None,
        };
        let upper = match self.upper {
            Bound::Open(b) => Some(format!("< {b}")),
            Bound::Closed(b) => Some(format!("≤ {b}")),
            Bound::Unbounded => None,
        };
        match (lower, upper) {
            (Some(l), Some(u)) => format!("{l} and {u}"),
            (Some(b), None) | (None, Some(b)) => b,
            (None, None) => "any finite value".to_string(),
        }
    }

    /// The study-file keys of this parameter: `c10_kpa`, `c10_mpa`, ...
    pub fn keys(&self) -> impl Iterator<Item = String> + '_ {
        let stem = self.name.to_ascii_lowercase();
        self.unit
            .key_suffixes()
            .iter()
            .map(move |(suffix, _)| format!("{stem}_{suffix}"))
    }

    /// Checks `value` against the bounds.
    pub fn check(&self, value: f64) -> Result<(), MaterialError> {
        if self.admits(value) {
            Ok(())
        } else {
            Err(MaterialError::OutOfRange {
                parameter: self.name.to_string(),
                value,
                unit: self.unit.symbol().to_string(),
                range: self.range(),
                doc: self.doc,
            })
        }
    }
}

/// One number of a law's Abaqus data line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AbaqusField {
    /// Its name in the Abaqus manual (`C10`, `D1`, `D2`).
    pub name: &'static str,
    /// The parameter it holds, or `None` for a constant femu does not implement: it must be 0
    /// when read, and is written as 0.
    pub parameter: Option<usize>,
}

/// What a law is: its names, its Abaqus form and its parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LawSpec {
    /// The study-file name (`law = "mooney-rivlin"`), lower case.
    pub name: &'static str,
    /// The `*HYPERELASTIC` parameter of the Abaqus/CalculiX deck (`MOONEY-RIVLIN`).
    pub abaqus_keyword: &'static str,
    /// The Abaqus data line, in order.
    pub abaqus_fields: &'static [AbaqusField],
    /// The parameters, in the order of [`crate::sensitivity::all_parameters`] and of
    /// [`MaterialLaw::with_parameters`].
    pub parameters: &'static [ParameterSpec],
    /// The energy with its reference (a line for documentation and reports).
    pub doc: &'static str,
}

impl LawSpec {
    /// Index of the parameter named `name` (case-insensitive).
    pub fn parameter_index(&self, name: &str) -> Option<usize> {
        self.parameters
            .iter()
            .position(|p| p.name.eq_ignore_ascii_case(name))
    }

    /// The study-file keys of every parameter, comma-separated (for messages).
    pub fn keys(&self) -> String {
        self.parameters
            .iter()
            .flat_map(|p| p.keys())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The names of the Abaqus data line, comma-separated (`C10, C01, D1`).
    pub fn abaqus_data_line(&self) -> String {
        self.abaqus_fields
            .iter()
            .map(|f| f.name)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The largest stress-like coefficient a law accepts (MPa): 10 GPa, stiffer than cortical
/// bone; far above any soft tissue, and far below the overflow of the element arithmetic.
pub const STRESS_MAX_MPA: f64 = 1e4;
/// The bounds of a volumetric compliance (MPa⁻¹): bulk moduli from 2e6 MPa down to 2e-6 MPa.
pub const COMPLIANCE_RANGE: (f64, f64) = (1e-6, 1e6);

/// C10, the coefficient of `I1bar - 3`, as the Neo-Hookean law declares it (the other laws
/// start from it).
pub const C10: ParameterSpec = ParameterSpec {
    name: "C10",
    unit: Unit::Stress,
    lower: Bound::Open(0.0),
    upper: Bound::Closed(STRESS_MAX_MPA),
    log_scale: true,
    part: EnergyPart::Isochoric,
    typical: 1.75e-3,
    doc: "coefficient of I1bar - 3; small-strain shear modulus 2 C10",
};

/// D (Abaqus D1), the compliance of the volumetric term `(J - 1)²/D` every registered law
/// shares.
pub const D: ParameterSpec = ParameterSpec {
    name: "D",
    unit: Unit::Compliance,
    lower: Bound::Closed(COMPLIANCE_RANGE.0),
    upper: Bound::Closed(COMPLIANCE_RANGE.1),
    log_scale: true,
    part: EnergyPart::Volumetric,
    typical: 18.0,
    doc: "volumetric compliance, Abaqus D1: U = (J - 1)²/D, bulk modulus 2/D; D = 0 \
          (incompressible) is not supported",
};

/// A hyperelastic law of the registry: one type per law, its parameters as fields, registered
/// by one line in [`crate::material`]'s list. Everything else (deck reading and writing, study
/// keys, parameters, sensitivities, the element kernels) works from what it declares here.
pub trait MaterialLaw: Hyperelastic + Copy + PartialEq + 'static {
    /// Names, Abaqus form and parameters.
    const SPEC: LawSpec;
    /// The energy of the law with arbitrary real coefficients (no validity check): the form of
    /// the terms `E_k` of [`MaterialLaw::unit_energy`].
    type UnitEnergy: Hyperelastic;

    /// The law with `values` (in [`LawSpec::parameters`] order, internal units), unchecked.
    fn with_parameters(values: &[f64]) -> Self;
    /// The value of parameter `k`.
    fn parameter_value(&self, k: usize) -> f64;
    /// The value of parameter `k`, to change it.
    fn parameter_value_mut(&mut self, k: usize) -> &mut f64;
    /// `E_k`, the energy that parameter `k`'s coefficient multiplies (`W = Σ c_k E_k`); it has
    /// no term in the other [`EnergyPart`] (`tests/materials.rs` checks the rates built from it
    /// against finite differences for every registered law, which fails for a term declared in
    /// the wrong part).
    fn unit_energy(k: usize) -> Self::UnitEnergy;
    /// `dc_k/dθ_k` at the current value (1 for a coefficient, `-1/D²` for `1/D`).
    fn coefficient_rate(&self, k: usize) -> f64;
    /// Small-strain shear and bulk moduli `[μ, K]` (MPa): the linearization at F = I.
    fn small_strain_moduli(&self) -> [f64; 2];
    /// Conditions that join several parameters (checked after each one's bounds); none by
    /// default.
    fn check_joint(&self) -> Result<(), String> {
        Ok(())
    }
}

/// A material of a model, used through one dynamic call per element: every [`MaterialLaw`] is
/// one (blanket implementation), and its element kernel is compiled for it
/// ([`Material::evaluate_element`]).
pub trait Material: Hyperelastic {
    /// The law's declaration.
    fn spec(&self) -> &'static LawSpec;
    /// The value of parameter `k` (internal units).
    fn parameter(&self, k: usize) -> f64;
    /// Sets parameter `k` (internal units). Unchecked: the caller keeps it valid (the
    /// optimizer within bounds); [`Material::check`] tells.
    fn set_parameter(&mut self, k: usize, value: f64);
    /// Small-strain shear modulus μ (MPa).
    fn shear_modulus(&self) -> f64;
    /// Small-strain bulk modulus K (MPa).
    fn bulk_modulus(&self) -> f64;
    /// Every parameter within its bounds and the law's joint conditions.
    fn check(&self) -> Result<(), MaterialError>;
    /// [`crate::element::SolidElement::evaluate`] of `geo`'s element type with this material
    /// inlined into the Gauss-point loop (and run as its AVX2 copy where the CPU has it): the
    /// static solver's hot loop, see [`crate::element::evaluate_static`].
    fn evaluate_element(
        &self,
        geo: &ElementGeometry,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian>;
    /// `∂f_e/∂θ_k`, the element internal force's derivative with respect to each parameter, at
    /// local displacements `u`: `forces[k * MAX_DOFS..][..2 n]` for parameter k (so `forces`
    /// holds at least `parameters · MAX_DOFS` values). Exact: the force of the energy
    /// `c_k'(θ_k) E_k` (see the module documentation).
    fn rate_forces(
        &self,
        geo: &ElementGeometry,
        u: &[[f64; 2]],
        forces: &mut [f64],
    ) -> Result<(), NonPositiveJacobian>;
    /// [`Material::rate_forces`] of a 3D element ([`crate::solid3d::rate_forces`]):
    /// `forces[k * MAX_DOFS_3D..][..3 n]` for parameter k.
    fn rate_forces_3d(
        &self,
        geo: &crate::solid3d::Geometry3,
        u: &[[f64; 3]],
        forces: &mut [f64],
    ) -> Result<(), NonPositiveJacobian>;
    /// A boxed copy.
    fn boxed(&self) -> Box<dyn Material>;
}

impl<L: MaterialLaw> Material for L {
    fn spec(&self) -> &'static LawSpec {
        &L::SPEC
    }

    fn parameter(&self, k: usize) -> f64 {
        self.parameter_value(k)
    }

    fn set_parameter(&mut self, k: usize, value: f64) {
        *self.parameter_value_mut(k) = value;
    }

    fn shear_modulus(&self) -> f64 {
        self.small_strain_moduli()[0]
    }

    fn bulk_modulus(&self) -> f64 {
        self.small_strain_moduli()[1]
    }

    fn check(&self) -> Result<(), MaterialError> {
        for (k, p) in L::SPEC.parameters.iter().enumerate() {
            p.check(self.parameter_value(k))?;
        }
        self.check_joint().map_err(|message| MaterialError::Joint {
            law: L::SPEC.name,
            message,
        })
    }

    fn evaluate_element(
        &self,
        geo: &ElementGeometry,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian> {
        crate::element::evaluate_static(geo, self, u, out)
    }

    fn rate_forces(
        &self,
        geo: &ElementGeometry,
        u: &[[f64; 2]],
        forces: &mut [f64],
    ) -> Result<(), NonPositiveJacobian> {
        let parameters = L::SPEC.parameters;
        crate::element::unit_energy_forces(
            geo,
            u,
            parameters.len(),
            |k| (L::unit_energy(k), parameters[k].part),
            forces,
        )?;
        let nd = 2 * geo.n_nodes;
        for k in 0..parameters.len() {
            let rate = self.coefficient_rate(k);
            // (`v · rate` is `rate · v` to the bit: the former sensitivities' product.)
            for v in &mut forces[k * MAX_DOFS..k * MAX_DOFS + nd] {
                *v *= rate;
            }
        }
        Ok(())
    }

    fn rate_forces_3d(
        &self,
        geo: &crate::solid3d::Geometry3,
        u: &[[f64; 3]],
        forces: &mut [f64],
    ) -> Result<(), NonPositiveJacobian> {
        crate::solid3d::rate_forces(self, geo, u, forces)
    }

    fn boxed(&self) -> Box<dyn Material> {
        Box::new(*self)
    }
}

impl<'a> dyn Material + 'a {
    /// Index of the parameter named `name` (case-insensitive).
    pub fn parameter_index(&self, name: &str) -> Option<usize> {
        self.spec().parameter_index(name)
    }

    /// The values of all parameters, in order.
    pub fn parameters(&self) -> Vec<f64> {
        (0..self.spec().parameters.len())
            .map(|k| self.parameter(k))
            .collect()
    }
}

impl Clone for Box<dyn Material> {
    fn clone(&self) -> Self {
        self.boxed()
    }
}

/// Two materials are equal when they are the same law with the same parameter values.
impl PartialEq for dyn Material {
    fn eq(&self, other: &Self) -> bool {
        // By the law's name, not its address: a law's spec is an associated const, which each
        // crate that monomorphizes `spec()` may promote to its own copy (femu-study's
        // the_example_study_is_the_default saw two FAT Neo-Hookeans compare unequal).
        self.spec().name == other.spec().name && self.parameters() == other.parameters()
    }
}

/// A material that cannot be built or is not valid: what is wrong and what would be valid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MaterialError {
    #[error("unknown material law '{name}' (registered: {known})")]
    UnknownLaw { name: String, known: String },
    #[error("*HYPERELASTIC, {keyword} is not supported (femu implements: {known})")]
    UnknownKeyword { keyword: String, known: String },
    #[error("'{key}' is not a parameter key of the {law} law (valid keys: {valid})")]
    UnknownKey {
        key: String,
        law: &'static str,
        valid: String,
    },
    #[error("{parameter} is given twice ({first} and {second}); give one of them")]
    DuplicateParameter {
        parameter: &'static str,
        first: String,
        second: String,
    },
    #[error("the {law} law needs {parameter}: give one of {keys}")]
    MissingParameter {
        law: &'static str,
        parameter: &'static str,
        keys: String,
    },
    #[error(
        "{parameter} = {value}{} is out of range: it must be {range} ({doc})",
        unit_suffix(unit)
    )]
    OutOfRange {
        parameter: String,
        value: f64,
        /// The unit of `value` (empty when `parameter` is a key that names it).
        unit: String,
        range: String,
        doc: &'static str,
    },
    #[error("the {law} law has {expected} parameters, {given} values were given")]
    ParameterCount {
        law: &'static str,
        given: usize,
        expected: usize,
    },
    #[error("{law}: {message}")]
    Joint { law: &'static str, message: String },
    #[error("*HYPERELASTIC, {keyword} has {given} constants; its data line is '{expected}'")]
    TooManyConstants {
        keyword: &'static str,
        given: usize,
        expected: String,
    },
    #[error("*HYPERELASTIC, {keyword}: {field} = {value} is not supported (femu implements {keyword} with {field} = 0)")]
    UnsupportedConstant {
        keyword: &'static str,
        field: &'static str,
        value: f64,
    },
    #[error("*HYPERELASTIC, {keyword}: {field} = 0 (or left out) is out of range: it must be {range} ({doc})")]
    MissingConstant {
        keyword: &'static str,
        field: &'static str,
        range: String,
        doc: &'static str,
    },
}

fn unit_suffix(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

impl fmt::Display for LawSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}
