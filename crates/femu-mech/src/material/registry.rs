//! Lookups in the registered laws ([`super::LAWS`]) and the conversions every reader and writer
//! of materials goes through: Abaqus data lines ([`material_from_def`], [`material_def`]) and
//! unit-suffixed study-file keys ([`material_from_keys`], [`set_from_keys`]).

use super::law::{LawSpec, Material, MaterialError, MaterialLaw, ParameterSpec};
use super::LAWS;
use femu_mesh::MaterialDef;

/// One registered law: its declaration and how to build it.
#[derive(Debug)]
pub struct LawEntry {
    pub spec: &'static LawSpec,
    build: fn(&[f64]) -> Box<dyn Material>,
}

fn build_law<L: MaterialLaw>(values: &[f64]) -> Box<dyn Material> {
    Box::new(L::with_parameters(values))
}

impl LawEntry {
    /// The entry of law `L` (`spec` is `&L::SPEC`; see `register_laws!`).
    pub const fn of<L: MaterialLaw>(spec: &'static LawSpec) -> LawEntry {
        LawEntry {
            spec,
            build: build_law::<L>,
        }
    }

    /// The law with `values` (one per parameter, in order, internal units), checked.
    pub fn build(&self, values: &[f64]) -> Result<Box<dyn Material>, MaterialError> {
        if values.len() != self.spec.parameters.len() {
            return Err(MaterialError::ParameterCount {
                law: self.spec.name,
                given: values.len(),
                expected: self.spec.parameters.len(),
            });
        }
        let material = (self.build)(values);
        material.check()?;
        Ok(material)
    }
}

fn known(describe: impl Fn(&LawSpec) -> &'static str) -> String {
    LAWS.iter()
        .map(|l| describe(l.spec))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The law registered as `name` (case-insensitive; `_` and `-` alike: `mooney_rivlin`).
pub fn law(name: &str) -> Result<&'static LawEntry, MaterialError> {
    let norm = |s: &str| s.trim().to_ascii_lowercase().replace('_', "-");
    LAWS.iter()
        .find(|l| l.spec.name == norm(name))
        .ok_or_else(|| MaterialError::UnknownLaw {
            name: name.to_string(),
            known: known(|s| s.name),
        })
}

/// The law of the Abaqus `*HYPERELASTIC` parameter `keyword` (case and blanks ignored:
/// `NEO HOOKE`, `neohooke`).
pub fn law_for_keyword(keyword: &str) -> Result<&'static LawEntry, MaterialError> {
    let squash = |s: &str| {
        s.chars()
            .filter(|c| !c.is_whitespace())
            .collect::<String>()
            .to_ascii_uppercase()
    };
    LAWS.iter()
        .find(|l| squash(l.spec.abaqus_keyword) == squash(keyword))
        .ok_or_else(|| MaterialError::UnknownKeyword {
            keyword: keyword.to_string(),
            known: known(|s| s.abaqus_keyword),
        })
}

/// The material of a deck's `*HYPERELASTIC` law and data line: the constants in the law's
/// Abaqus order, left-out trailing ones 0 (as Abaqus reads them), constants femu does not
/// implement required to be 0, every parameter within its bounds.
pub fn material_from_def(def: &MaterialDef) -> Result<Box<dyn Material>, MaterialError> {
    let entry = law_for_keyword(&def.keyword)?;
    let spec = entry.spec;
    if def.constants.len() > spec.abaqus_fields.len() {
        return Err(MaterialError::TooManyConstants {
            keyword: spec.abaqus_keyword,
            given: def.constants.len(),
            expected: spec.abaqus_data_line(),
        });
    }
    let mut values = vec![0.0; spec.parameters.len()];
    for (i, field) in spec.abaqus_fields.iter().enumerate() {
        let given = def.constants.get(i).copied();
        let value = given.unwrap_or(0.0);
        let Some(k) = field.parameter else {
            if value != 0.0 {
                return Err(MaterialError::UnsupportedConstant {
                    keyword: spec.abaqus_keyword,
                    field: field.name,
                    value,
                });
            }
            continue;
        };
        let p = &spec.parameters[k];
        if !p.admits(value) {
            return Err(match given {
                None => MaterialError::MissingConstant {
                    keyword: spec.abaqus_keyword,
                    field: field.name,
                    range: p.range(),
                    doc: p.doc,
                },
                Some(_) => out_of_range(p, field.name, value, p.unit.symbol(), 1.0),
            });
        }
        values[k] = value;
    }
    entry.build(&values)
}

/// The deck form of `material` named `name`: its law's keyword and full data line (constants
/// femu does not implement written as 0).
pub fn material_def(name: &str, material: &dyn Material) -> MaterialDef {
    let spec = material.spec();
    MaterialDef {
        name: name.to_string(),
        keyword: spec.abaqus_keyword.to_string(),
        constants: spec
            .abaqus_fields
            .iter()
            .map(|f| f.parameter.map_or(0.0, |k| material.parameter(k)))
            .collect(),
        line: None,
    }
}

/// `p` at `value` (in the unit of `factor`: internal value = value · factor) is out of range.
fn out_of_range(
    p: &ParameterSpec,
    name: &str,
    value: f64,
    unit: &str,
    factor: f64,
) -> MaterialError {
    let scaled = ParameterSpec {
        lower: scale_bound(p.lower, factor),
        upper: scale_bound(p.upper, factor),
        ..*p
    };
    MaterialError::OutOfRange {
        parameter: name.to_string(),
        value,
        unit: unit.to_string(),
        range: scaled.range(),
        doc: p.doc,
    }
}

fn scale_bound(b: super::Bound, factor: f64) -> super::Bound {
    use super::Bound;
    match b {
        Bound::Open(v) => Bound::Open(v / factor),
        Bound::Closed(v) => Bound::Closed(v / factor),
        Bound::Unbounded => Bound::Unbounded,
    }
}

/// The parameter a study-file key names in `spec` and the factor from the keyed value to the
/// internal unit (`c10_kpa` → (C10, 1e-3)), case-insensitive.
pub fn parameter_key(spec: &LawSpec, key: &str) -> Option<(usize, f64)> {
    let key = key.trim().to_ascii_lowercase();
    spec.parameters.iter().enumerate().find_map(|(k, p)| {
        let rest = key.strip_prefix(&p.name.to_ascii_lowercase())?;
        let suffix = rest.strip_prefix('_')?;
        p.unit
            .key_suffixes()
            .iter()
            .find(|(s, _)| *s == suffix)
            .map(|&(_, factor)| (k, factor))
    })
}

/// The keyed values converted to internal units, one slot per parameter (with the key that gave
/// it), each checked against its bounds.
fn keyed_values<'a>(
    spec: &'static LawSpec,
    keys: impl IntoIterator<Item = (&'a str, f64)>,
) -> Result<Vec<Option<(f64, &'a str)>>, MaterialError> {
    let mut values: Vec<Option<(f64, &str)>> = vec![None; spec.parameters.len()];
    for (key, value) in keys {
        let (k, factor) = parameter_key(spec, key).ok_or_else(|| MaterialError::UnknownKey {
            key: key.to_string(),
            law: spec.name,
            valid: spec.keys(),
        })?;
        let p = &spec.parameters[k];
        if let Some((_, first)) = values[k] {
            return Err(MaterialError::DuplicateParameter {
                parameter: p.name,
                first: first.to_string(),
                second: key.to_string(),
            });
        }
        let internal = value * factor;
        if !p.admits(internal) || !value.is_finite() {
            return Err(out_of_range(p, key, value, "", factor));
        }
        values[k] = Some((internal, key));
    }
    Ok(values)
}

/// A material of the law registered as `law` from unit-suffixed keys, e.g. `mooney-rivlin`
/// with `c10_kpa = 1.0`, `c01_kpa = 0.75`, `d_per_mpa = 18`: every parameter exactly once, in
/// any of its units ([`crate::material::Unit::key_suffixes`]), within its bounds. Errors name
/// the key and what is valid.
pub fn material_from_keys<'a>(
    law_name: &str,
    keys: impl IntoIterator<Item = (&'a str, f64)>,
) -> Result<Box<dyn Material>, MaterialError> {
    let entry = law(law_name)?;
    let spec = entry.spec;
    let values = keyed_values(spec, keys)?;
    let mut internal = Vec::with_capacity(values.len());
    for (p, v) in spec.parameters.iter().zip(&values) {
        let Some((v, _)) = v else {
            return Err(MaterialError::MissingParameter {
                law: spec.name,
                parameter: p.name,
                keys: p.keys().collect::<Vec<_>>().join(" or "),
            });
        };
        internal.push(*v);
    }
    entry.build(&internal)
}

/// Overrides the parameters of `material` given by unit-suffixed keys (the others keep their
/// values), then checks the whole material. On error `material` is unchanged.
pub fn set_from_keys<'a>(
    material: &mut dyn Material,
    keys: impl IntoIterator<Item = (&'a str, f64)>,
) -> Result<(), MaterialError> {
    let spec = material.spec();
    let values = keyed_values(spec, keys)?;
    let mut changed = material.boxed();
    for (k, v) in values.iter().enumerate() {
        if let Some((v, _)) = v {
            changed.set_parameter(k, *v);
        }
    }
    changed.check()?;
    for (k, v) in values.iter().enumerate() {
        if let Some((v, _)) = v {
            material.set_parameter(k, *v);
        }
    }
    Ok(())
}
