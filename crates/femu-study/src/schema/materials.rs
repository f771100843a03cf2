//! `[materials.REGION]`: the law of a region and its parameters, each key carrying its unit
//! (`c10_kpa` or `c10_mpa`, `d_per_mpa`, `c01_kpa`, ...). The laws and their keys are the
//! registry's (`femu_mech::material::LAWS`): nothing here names a parameter.
//!
//! ```toml
//! [materials.FAT]             # override parameters of the region's law (Table 1: Neo-Hookean)
//! c10_kpa = 0.8
//! [materials.QUADRICEPS]      # or give the region another law, with every parameter
//! law = "mooney-rivlin"
//! c10_kpa = 1.0
//! c01_kpa = 0.75
//! d_per_mpa = 18.0
//! ```

use super::lines::KeyLines;
use super::StudyError;
use femu_mech::material::{
    law, material_from_keys, parameter_key, set_from_keys, LawEntry, Material, MaterialError,
};
use femu_mech::model::NamedMaterial;
use std::collections::BTreeMap;

/// The seed's Table 1 ([`femu_geometry::TABLE1`]), the default materials of the built-in
/// thigh's regions: compressible Neo-Hookean, named by region (C10 in MPa, D in MPa⁻¹).
pub fn table1() -> Vec<NamedMaterial> {
    femu_geometry::TABLE1
        .iter()
        .map(|&(region, c10_kpa, d)| NamedMaterial::neo_hookean(region, c10_kpa * 1e-3, d))
        .collect()
}

/// A region's material as the study gives it.
#[derive(Debug, Clone)]
pub struct MaterialSpec {
    /// The region (or a deck's material, or a Gmsh physical surface) name as written; regions
    /// are matched without regard to case.
    pub region: String,
    /// `law = ...`: the region gets this law, every parameter given; `None`: the region keeps
    /// its model's law (Table 1's Neo-Hookean, a deck's own) and the keys override parameters.
    pub law: Option<&'static LawEntry>,
    /// The parameter keys and values as written (`("c10_kpa", 0.8)`).
    pub keys: Vec<(String, f64)>,
}

impl PartialEq for MaterialSpec {
    fn eq(&self, other: &Self) -> bool {
        self.region == other.region
            && self.keys == other.keys
            && self.law.map(|l| l.spec.name) == other.law.map(|l| l.spec.name)
    }
}

impl MaterialSpec {
    fn pairs(&self) -> impl Iterator<Item = (&str, f64)> {
        self.keys.iter().map(|(k, v)| (k.as_str(), *v))
    }

    /// The material of the region: `default` (the model's own) with the study's law or values.
    pub fn apply(&self, default: &dyn Material) -> Result<Box<dyn Material>, MaterialError> {
        match self.law {
            Some(entry) => material_from_keys(entry.spec.name, self.pairs()),
            None => {
                let mut m = default.boxed();
                set_from_keys(&mut *m, self.pairs())?;
                Ok(m)
            }
        }
    }

    /// The material of a region with no default (a Gmsh physical surface): its law
    /// (Neo-Hookean unless named) with every parameter given.
    pub fn build(&self) -> Result<Box<dyn Material>, MaterialError> {
        let name = self.law.map_or("neo-hookean", |l| l.spec.name);
        material_from_keys(name, self.pairs())
    }
}

/// Checks every `[materials.REGION]` table; `default_law` is the law a region keeps when the
/// study names none (`None` for a deck, whose materials are read later).
pub(crate) fn parse(
    tables: &BTreeMap<String, BTreeMap<String, toml::Value>>,
    default_law: Option<&'static LawEntry>,
    lines: &KeyLines,
) -> Result<Vec<MaterialSpec>, StudyError> {
    tables
        .iter()
        .map(|(region, keys)| parse_one(region, keys, default_law, lines))
        .collect()
}

fn parse_one(
    region: &str,
    table: &BTreeMap<String, toml::Value>,
    default_law: Option<&'static LawEntry>,
    lines: &KeyLines,
) -> Result<MaterialSpec, StudyError> {
    let at = format!("materials.{region}");
    let law = match table.get("law") {
        None => None,
        Some(toml::Value::String(name)) => {
            Some(law(name).map_err(|e| lines.err(&at, 0, "law", e.to_string()))?)
        }
        Some(other) => {
            return Err(lines.err(&at, 0, "law", format!("must be a law's name, got {other}")))
        }
    };
    let mut keys = Vec::new();
    for (key, v) in table.iter().filter(|(k, _)| *k != "law") {
        let value = match v {
            toml::Value::Float(f) => *f,
            toml::Value::Integer(i) => *i as f64,
            other => return Err(lines.err(&at, 0, key, format!("must be a number, got {other}"))),
        };
        keys.push((key.clone(), value));
    }
    let spec = MaterialSpec {
        region: region.to_string(),
        law,
        keys,
    };
    // Checked now against the law the region will have (a deck's, when no law is named, only
    // once the deck is read).
    let checked = match (law, default_law) {
        (Some(_), _) => spec.build().map(|_| ()),
        (None, Some(entry)) => entry
            .build(
                &entry
                    .spec
                    .parameters
                    .iter()
                    .map(|p| p.typical)
                    .collect::<Vec<_>>(),
            )
            .and_then(|mut m| set_from_keys(&mut *m, spec.pairs())),
        (None, None) => Ok(()),
    };
    checked.map_err(|e| {
        let key = key_of(&e, &spec, law.or(default_law));
        lines.err(&at, 0, &key, e.to_string())
    })?;
    Ok(spec)
}

/// The study key an error is about (empty: the table).
fn key_of(e: &MaterialError, spec: &MaterialSpec, law: Option<&'static LawEntry>) -> String {
    match e {
        MaterialError::UnknownKey { key, .. } => key.clone(),
        MaterialError::DuplicateParameter { second, .. } => second.clone(),
        MaterialError::OutOfRange { parameter, .. } => spec
            .keys
            .iter()
            .map(|(k, _)| k)
            .find(|k| {
                *k == parameter
                    || law.is_some_and(|l| {
                        parameter_key(l.spec, k)
                            .is_some_and(|(i, _)| l.spec.parameters[i].name == parameter)
                    })
            })
            .cloned()
            .unwrap_or_default(),
        _ => String::new(),
    }
}
