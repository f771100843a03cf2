//! The study file (TOML): one schema for every command that reads a study — `femu run`,
//! `sensitivity`, `synth`, `identify`, `us-sim`, `convergence` and `femu solve MESH.msh
//! --study` each read the view of it they need. It gives the geometry and its materials, the
//! loading tests, the measurement (grid, noise, or a measured field and its frame), the
//! identification, which steps to run, the simulated ultrasound acquisition, the boundary
//! conditions of a Gmsh mesh and the convergence study. Every key is optional; units are in the
//! key names (conventions.md); the empty study is the seed's numerical example on a 6 000-element
//! thigh.
//!
//! Everything is checked here, before any computation: an unknown key, a missing value, a number
//! out of range or a wrong unit suffix is an error naming the key and its line. `femu init`
//! writes [`EXAMPLE_STUDY`], every key with its default and a comment.
//!
//! Relative file names (`[labels] image`, `[model] deck`, `[measurement] file`) are relative to
//! the study file's folder.

mod boundary;
mod convergence;
mod error;
mod geometry;
mod identification;
mod legacy;
mod lines;
mod materials;
mod measurement;
mod raw;
mod tests;
pub mod ultrasound;

pub use boundary::MeshBoundary;
pub use convergence::ConvergenceSpec;
pub use error::StudyError;
pub use femu_identify::campaign::Optimizer;
pub use geometry::{
    Geometry, LabelsSpec, QuadElement, Resolution, DEFAULT_ELEMENTS, DEFAULT_LABEL_SIZE_MM,
    ELEMENTS_RANGE,
};
pub use identification::{Grouping, IdentificationSpec, Steps};
pub use materials::MaterialSpec;
pub use measurement::{Frame, GridSpec, MeasurementSource, MeasurementSpec, Travel, SEED_SIGMA_MM};
pub use tests::{seed_tests, TestSpec};
pub use ultrasound::{ProbeSection, UltrasoundSection};

use lines::KeyLines;
use serde::Deserialize;
use std::path::Path;

/// The commented example study that `femu init` writes (every key, with its default).
pub const EXAMPLE_STUDY: &str = include_str!("example_study.toml");

/// The model a study describes, before it is built (see [`crate::model`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    pub geometry: Geometry,
    pub resolution: Resolution,
    pub element: QuadElement,
    /// The study's `[materials]` over the geometry's defaults (Table 1, or a deck's own).
    pub materials: Vec<MaterialSpec>,
}

/// A checked study.
#[derive(Debug, Clone)]
pub struct Study {
    pub model: ModelSpec,
    pub tests: Vec<TestSpec>,
    pub measurement: MeasurementSpec,
    /// Tied parameters (`[parameters] groups`; the seed's grouping when the study names none).
    pub groups: Vec<Vec<String>>,
    pub identification: IdentificationSpec,
    pub steps: Steps,
    /// `[probe]` and `[ultrasound]`: the simulated B-mode acquisition.
    pub probe: ProbeSection,
    pub ultrasound: UltrasoundSection,
    /// `[[fixed]]`, `[[pressure]]`, `[step]`: the Gmsh view.
    pub boundary: MeshBoundary,
    /// `[convergence]`: the convergence view (see [`Study::convergence_study`]).
    pub convergence: ConvergenceSpec,
    /// Whether `[grid]` and `[[test]]` were written (the convergence and Gmsh views need to
    /// know).
    grid_given: bool,
    tests_given: bool,
    /// The text's key lines, for the views checked later.
    lines: std::sync::Arc<KeyLines>,
}

impl Default for Study {
    fn default() -> Self {
        parse("", Path::new(".")).expect("the empty study is valid")
    }
}

/// The seed's grouping (§2.4.2): D of ischio, sartorius and gracilis tied.
pub fn seed_groups() -> Vec<Vec<String>> {
    vec![vec![
        "D_ISCHIO".into(),
        "D_SARTORIUS".into(),
        "D_GRACILIS".into(),
    ]]
}

/// The study of a command: the file if given (else the defaults), `--elements` over it.
pub fn load(study: Option<&Path>, elements: Option<usize>) -> Result<Study, StudyError> {
    let mut s = match study {
        Some(p) => read(p)?,
        None => Study::default(),
    };
    if let Some(n) = elements {
        if !ELEMENTS_RANGE.contains(&n) {
            return Err(StudyError::Study(format!(
                "--elements must be in [100, 500000], got {n}"
            )));
        }
        s.model.resolution = Resolution::Elements(n);
    }
    Ok(s)
}

/// Reads and checks a study file.
pub fn read(path: &Path) -> Result<Study, StudyError> {
    let text = std::fs::read_to_string(path).map_err(|error| StudyError::Read {
        path: path.to_path_buf(),
        error,
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse(&text, base).map_err(|e| e.in_file(path))
}

/// The typed tables of `text`, with older layouts moved into the schema (see [`legacy`]).
fn raw_tables(text: &str) -> Result<(raw::StudyFile, KeyLines), StudyError> {
    let mut doc: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| StudyError::Syntax(e.to_string()))?;
    let moved = legacy::translate(&mut doc);
    let lines = KeyLines::new(text);
    if moved.is_empty() {
        // Parsed from the text so that the parser's messages keep their line and column.
        let file = toml::from_str(text).map_err(|e| StudyError::Syntax(e.to_string()))?;
        return Ok((file, lines));
    }
    let file = raw::StudyFile::deserialize(toml::Value::Table(doc)).map_err(|e| {
        let msg = e.to_string();
        let line = msg
            .split('`')
            .nth(1)
            .and_then(|key| lines.first_line_of(key))
            .map(|l| format!(" (line {l})"))
            .unwrap_or_default();
        StudyError::Syntax(format!("{}{line}", msg.trim_end()))
    })?;
    Ok((file, lines.with_moved(moved)))
}

/// Parses and checks a study (see the module documentation); `base` is the folder relative file
/// names start from.
pub fn parse(text: &str, base: &Path) -> Result<Study, StudyError> {
    let (file, lines) = raw_tables(text)?;
    let (geometry, resolution, element) = geometry::parse(
        file.model.unwrap_or_default(),
        file.thigh,
        file.labels,
        &lines,
        base,
    )?;
    // A region keeps Table 1's Neo-Hookean unless the study names a law; a deck's materials
    // are its own, checked once it is read.
    let default_law = match geometry {
        Geometry::Deck(_) => None,
        _ => femu_mech::material::law("neo-hookean").ok(),
    };
    let materials = materials::parse(&file.materials, default_law, &lines)?;
    let tests = tests::parse(file.test.as_deref(), &lines)?;
    let measurement = measurement::parse(
        file.grid.clone(),
        file.noise,
        file.measurement,
        &lines,
        base,
    )?;
    let identification =
        identification::parse(file.identification, &tests, &geometry, resolution, &lines)?;
    let boundary = boundary::parse(&file.fixed, &file.pressure, file.step.as_ref(), &lines)?;
    let convergence = convergence::parse(file.convergence, &tests, &lines)?;
    let ultrasound_section = file.ultrasound.unwrap_or_default();
    ultrasound::check(&ultrasound_section, &lines)?;
    let groups = match file.parameters {
        Some(p) if !p.groups.is_empty() => p.groups,
        _ => seed_groups(),
    };
    let study = Study {
        model: ModelSpec {
            geometry,
            resolution,
            element,
            materials,
        },
        tests,
        measurement,
        groups,
        identification,
        steps: identification::parse_steps(file.run),
        probe: file.probe.unwrap_or_default(),
        ultrasound: ultrasound_section,
        boundary,
        convergence,
        grid_given: file.grid.is_some(),
        tests_given: file.test.is_some(),
        lines: std::sync::Arc::new(lines),
    };
    if study.convergence.given {
        study.convergence_study()?;
    }
    Ok(study)
}

impl Study {
    /// The identification test.
    pub fn identification_test(&self) -> &TestSpec {
        &self.tests[self.identification.test]
    }

    /// The convergence view: the `[convergence]` table with the study's thigh, materials, test
    /// and grid, checked in full.
    pub fn convergence_study(&self) -> Result<femu_convergence::ConvergenceStudy, StudyError> {
        convergence::view(
            convergence::ViewInputs {
                spec: &self.convergence,
                geometry: &self.model.geometry,
                resolution: self.model.resolution,
                materials: &self.model.materials,
                tests: &self.tests,
                grid: self.grid_given.then_some(&self.measurement.grid),
            },
            &self.lines,
        )
    }

    /// Whether the study names its tests (`[[test]]`), rather than taking the seed's three.
    pub fn tests_given(&self) -> bool {
        self.tests_given
    }

    /// The error of a key found wrong after parsing (e.g. a region the built model lacks),
    /// named with its line.
    pub fn key_error(&self, table: &str, key: &str, message: String) -> StudyError {
        self.lines.err(table, 0, key, message)
    }
}

#[cfg(test)]
mod unit_tests;
