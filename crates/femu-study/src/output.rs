//! Writing an output folder: files with the path in every error, each written whole or not at
//! all (a temporary name renamed when complete: [`femu_mesh::atomic`]).

use crate::error::{Context, Result};
use femu_mesh::atomic::AtomicFile;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Creates `dir` (and its parents).
pub fn create_dir(dir: &Path) -> Result<()> {
    femu_mesh::atomic::create_dir_all(dir)
        .with_context(|| format!("cannot create output folder {}", dir.display()))
}

/// Writes `text` to `path`.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    femu_mesh::atomic::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Starts writing `path` under a temporary name; [`commit`] gives it its name.
pub fn create_file(path: &Path) -> Result<AtomicFile> {
    AtomicFile::create(path).with_context(|| format!("cannot write {}", path.display()))
}

/// Completes a file begun with [`create_file`].
pub fn commit(file: AtomicFile) -> Result<()> {
    let path = file.path().to_path_buf();
    file.commit()
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `value` as pretty JSON to `path`.
pub fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    write_text(path, &serde_json::to_string_pretty(value)?)
}

/// Reads the JSON file `path` as a `T` (a non-finite number, written as `null`, reads back as
/// NaN: see [`crate::json`]).
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    crate::json::from_str(&text).with_context(|| format!("{} is not a femu result", path.display()))
}

/// `summary.json` of a command the user stopped before its results were complete (`femu
/// identify` before a repeat finished, `femu dic`, `femu convergence`): what it was doing and
/// which files it kept.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StoppedSummary {
    pub command: String,
    pub version: String,
    /// Always `interrupted`.
    pub status: String,
    /// What was stopped and what was kept, in words.
    pub interrupted: String,
    /// The files of the folder that hold finished work.
    pub kept: Vec<String>,
    pub wall_time_s: f64,
}

/// Writes `out/summary.json` for a command stopped by the user (see [`StoppedSummary`]).
pub fn write_stopped(
    out: &Path,
    command: &str,
    interrupted: &str,
    kept: &[&str],
    wall_time_s: f64,
) -> Result<()> {
    create_dir(out)?;
    write_json(
        &out.join("summary.json"),
        &StoppedSummary {
            command: command.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            status: "interrupted".into(),
            interrupted: interrupted.into(),
            kept: kept.iter().map(|k| k.to_string()).collect(),
            wall_time_s,
        },
    )
}

/// A model parameter as the summaries list it, from what its law declares
/// ([`femu_mech::material::ParameterSpec`]): the same entry for every registered law, so that
/// C20 and C30 of a Yeoh tissue or C01 of a Mooney–Rivlin one are listed like C10 and D.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterEntry {
    /// `C20_FAT`: the law's parameter and the material.
    pub name: String,
    /// The law's parameter: `C10`, `C20`, `C01`, `D`, ...
    pub kind: String,
    /// The material (tissue): `FAT`.
    pub material: String,
    /// The material's law: `neo-hookean`, `mooney-rivlin`, `yeoh`.
    pub law: String,
    /// The value in the internal unit [`ParameterEntry::unit`] (the decks').
    pub value: f64,
    /// `MPa`, `MPa⁻¹`.
    pub unit: String,
    /// The study-file key of [`ParameterEntry::shown`] (`c20_kpa`, `d_per_mpa`).
    pub key: String,
    /// The value in the unit reports show it in (kPa for a stress coefficient).
    pub shown: f64,
    pub shown_unit: String,
    /// Whether the law declares it a positive scale parameter (identified on a log scale).
    pub log_scale: bool,
}

impl ParameterEntry {
    /// Parameter `p` of `model`.
    pub fn of(model: &femu_mech::Model, p: &femu_mech::sensitivity::Parameter) -> ParameterEntry {
        let spec = p.spec();
        let (shown_unit, factor) = spec.unit.report();
        let value = p.value(model);
        ParameterEntry {
            name: p.name(model),
            kind: spec.name.to_string(),
            material: model.materials[p.material].name.clone(),
            law: model.materials[p.material].law.spec().name.to_string(),
            value,
            unit: spec.unit.symbol().to_string(),
            key: shown_key(spec),
            shown: value * factor,
            shown_unit: shown_unit.to_string(),
            log_scale: spec.log_scale,
        }
    }

    /// Every parameter of `model`, material by material in the law's order.
    pub fn all(model: &femu_mech::Model) -> Vec<ParameterEntry> {
        femu_mech::sensitivity::all_parameters(model)
            .iter()
            .map(|p| ParameterEntry::of(model, p))
            .collect()
    }
}

/// The study-file key of `spec` in the unit reports show it in: the key suffix whose factor
/// undoes the report's (`c10_kpa`, `c20_kpa`, `d_per_mpa`); the first suffix if none does.
pub fn shown_key(spec: &femu_mech::material::ParameterSpec) -> String {
    let (_, factor) = spec.unit.report();
    let suffixes = spec.unit.key_suffixes();
    // The factors are powers of ten written as literals (1e-3 · 1e3): equal to 1 within a
    // rounding.
    let suffix = suffixes
        .iter()
        .find(|(_, f)| (f * factor - 1.0).abs() < 1e-12)
        .or(suffixes.first())
        .map_or("", |(s, _)| s);
    format!("{}_{suffix}", spec.name.to_ascii_lowercase())
}

/// The keyed values of `material`'s parameters (`{"c10_kpa": 0.8, "c20_kpa": 0.3, ...}`), each
/// in the unit its key names.
pub fn keyed_parameters(
    material: &dyn femu_mech::material::Material,
) -> std::collections::BTreeMap<String, f64> {
    material
        .spec()
        .parameters
        .iter()
        .enumerate()
        .map(|(k, spec)| {
            (
                shown_key(spec),
                material.parameter(k) * spec.unit.report().1,
            )
        })
        .collect()
}
