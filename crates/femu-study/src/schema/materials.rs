//! `[materials.REGION]`: the law of a region and its parameters, each key carrying its unit
//! (`c10_kpa` or `c10_mpa`, `d_per_mpa`).

use super::lines::KeyLines;
use super::StudyError;
use std::collections::BTreeMap;

/// The unit family of a material parameter, which decides the key suffixes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParameterUnit {
    /// A stress-like coefficient: `_kpa` or `_mpa` (stored in MPa).
    Stress,
    /// A compliance: `_per_mpa` (stored in MPa⁻¹).
    Compliance,
}

impl ParameterUnit {
    /// The key suffixes and their factor to the stored unit.
    fn suffixes(self) -> &'static [(&'static str, f64)] {
        match self {
            ParameterUnit::Stress => &[("kpa", 1e-3), ("mpa", 1.0)],
            ParameterUnit::Compliance => &[("per_mpa", 1.0)],
        }
    }
}

/// The parameters of the compressible Neo-Hookean law (seed Eq. 1), in the order of
/// `femu_mech`'s parameters of a material.
const NEO_HOOKEAN: [(&str, ParameterUnit); 2] = [
    ("C10", ParameterUnit::Stress),
    ("D", ParameterUnit::Compliance),
];

/// A region's material as the study gives it: the values it sets (the rest keep the model's
/// defaults: Table 1 for the built-in thigh, the deck's own for a deck).
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialSpec {
    /// The region (or a deck's material, or a Gmsh physical surface) name as written; regions
    /// are matched without regard to case.
    pub region: String,
    /// `(parameter, value in MPa or MPa⁻¹)`, e.g. `("C10", 1.75e-3)`.
    pub values: Vec<(String, f64)>,
}

impl MaterialSpec {
    /// The value the study sets for `parameter` (`"C10"`, `"D"`), if any.
    pub fn value(&self, parameter: &str) -> Option<f64> {
        self.values
            .iter()
            .find(|(p, _)| p.eq_ignore_ascii_case(parameter))
            .map(|v| v.1)
    }
}

/// Checks every `[materials.REGION]` table.
pub(crate) fn parse(
    tables: &BTreeMap<String, BTreeMap<String, toml::Value>>,
    lines: &KeyLines,
) -> Result<Vec<MaterialSpec>, StudyError> {
    tables
        .iter()
        .map(|(region, keys)| parse_one(region, keys, lines))
        .collect()
}

fn parse_one(
    region: &str,
    keys: &BTreeMap<String, toml::Value>,
    lines: &KeyLines,
) -> Result<MaterialSpec, StudyError> {
    let table = format!("materials.{region}");
    let valid = || {
        NEO_HOOKEAN
            .iter()
            .flat_map(|(p, u)| {
                u.suffixes()
                    .iter()
                    .map(move |(s, _)| format!("{}_{s}", p.to_ascii_lowercase()))
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut values = Vec::new();
    for key in keys.keys() {
        let known = NEO_HOOKEAN.iter().any(|(p, u)| {
            u.suffixes()
                .iter()
                .any(|(s, _)| *key == format!("{}_{s}", p.to_ascii_lowercase()))
        });
        if !known {
            return Err(lines.err(
                &table,
                0,
                key,
                format!("unknown field `{key}` (valid: {})", valid()),
            ));
        }
    }
    for (parameter, unit) in NEO_HOOKEAN {
        let stem = parameter.to_ascii_lowercase();
        let given: Vec<(String, f64)> = unit
            .suffixes()
            .iter()
            .map(|(s, f)| (format!("{stem}_{s}"), *f))
            .filter(|(k, _)| keys.contains_key(k))
            .collect();
        match given.as_slice() {
            [] => {}
            [(key, factor)] => {
                let v = number(&keys[key]).ok_or_else(|| {
                    lines.err(
                        &table,
                        0,
                        key,
                        format!("must be a number, got {}", keys[key]),
                    )
                })?;
                let v = lines.positive(&table, 0, key, v)?;
                values.push((parameter.to_string(), v * factor));
            }
            [_, (second, _), ..] => {
                return Err(lines.err(
                    &table,
                    0,
                    second,
                    format!(
                        "give {} not both",
                        given
                            .iter()
                            .map(|(k, _)| k.as_str())
                            .collect::<Vec<_>>()
                            .join(" or ")
                            + ","
                    ),
                ))
            }
        }
    }
    Ok(MaterialSpec {
        region: region.to_string(),
        values,
    })
}

/// A TOML number (an integer is a number too).
fn number(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}
