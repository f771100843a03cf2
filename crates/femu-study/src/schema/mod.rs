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
mod deck;
mod deck_loads;
mod design;
mod error;
pub mod files;
pub mod frames;
mod geometry;
mod identification;
mod interface;
pub mod keys;
mod legacy;
mod lines;
mod loading_tests;
mod materials;
mod measurement;
mod measurements;
mod raw;
mod regions;
pub mod ultrasound;

pub use boundary::MeshBoundary;
pub use convergence::ConvergenceSpec;
pub(crate) use deck::{read_deck, read_deck_split};
pub use design::DesignSpec;
pub use error::StudyError;
pub use femu_identify::campaign::Optimizer;
pub use files::{absolute_file_names, is_file_key, FILE_KEYS};
pub(crate) use geometry::thigh_elements;
pub use geometry::{
    Geometry, LabelsSpec, QuadElement, Resolution, DEFAULT_ELEMENTS, DEFAULT_LABEL_SIZE_MM,
};
pub use identification::{
    Discretization, Grouping, IdentificationSpec, Steps, DEFAULT_IMAGE_NORMALIZATION_PX,
    DEFAULT_IMAGE_PAIRING,
};
pub use interface::{parse_interfaces, InterfaceLaw, InterfaceSpec};
pub use keys::{
    ELEMENTS_RANGE, MAX_BOUNDS_FACTOR, MAX_IMAGE_NORMALIZATION_PX, MAX_RENDER_REFINE,
    MIN_IMAGE_NORMALIZATION_PX,
};
pub use loading_tests::{seed_tests, TestSpec};
pub use materials::{table1, MaterialSpec};
pub use measurement::{
    Frame, GridSpec, MeasurementSource, MeasurementSpec, Speckle, Travel, Weighting, SEED_SIGMA_MM,
};
pub use measurements::{Measurement, Region, WindowSpec};
pub use ultrasound::{ProbeSection, UltrasoundSection};

use lines::KeyLines;
use serde::Deserialize;
use std::path::Path;

/// The commented example study that `femu init` writes (every key, with its default): the file
/// [`keys::init_file`] generates from the declarations (the `study_keys` test keeps it so).
pub const EXAMPLE_STUDY: &str = include_str!("example_study.toml");

/// The model a study describes, before it is built (see [`crate::model`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    pub geometry: Geometry,
    pub resolution: Resolution,
    pub element: QuadElement,
    /// The study's `[materials]` over the geometry's defaults (Table 1, or a deck's own).
    pub materials: Vec<MaterialSpec>,
    /// `[[interface]]`: the sliding interfaces between regions (none: the mesh as meshed).
    pub interfaces: Vec<InterfaceSpec>,
}

/// A checked study.
#[derive(Debug, Clone)]
pub struct Study {
    pub model: ModelSpec,
    pub tests: Vec<TestSpec>,
    /// The grid, the default noise, and the first measurement's source and actuator term (the
    /// one `[measurement]` of a single-measurement study).
    pub measurement: MeasurementSpec,
    /// Every measurement (one for a single `[measurement]` or none given; a joint
    /// identification fits them all).
    pub measurements: Vec<Measurement>,
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
    /// `[design]`: the candidates of `femu design`.
    pub design: DesignSpec,
    /// Whether `[grid]`, `[[test]]` and `[parameters] groups` were written (the convergence and
    /// Gmsh views, and the check of the group names, need to know).
    grid_given: bool,
    /// Whether the measurements were written as `[[measurement]]` (outputs per measurement).
    measurement_list: bool,
    tests_given: bool,
    groups_given: bool,
    /// The text's key lines, for the views checked later.
    lines: std::sync::Arc<KeyLines>,
    /// The study file, when read from one (named by the errors of the checks made later).
    file: Option<std::path::PathBuf>,
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
        Some(p) => read_for_model(p)?,
        None => Study::default(),
    };
    if let Some(n) = elements {
        let checked = match &s.model.geometry {
            Geometry::Thigh(t) => geometry::thigh_elements(t, n),
            _ if !ELEMENTS_RANGE.contains(&n) => Err(format!("must be in [100, 500000], got {n}")),
            _ => Ok(()),
        };
        checked.map_err(|m| StudyError::Study(format!("--elements: {m}")))?;
        s.model.resolution = Resolution::Elements(n);
    }
    Ok(s)
}

/// Reads and checks a study file for a command that builds the study's model (every command
/// but `femu solve MESH.msh --study`, whose materials name the mesh's physical surfaces):
/// [`read`], then what needs the files: [`Study::check_model_inputs`].
pub fn read_for_model(path: &Path) -> Result<Study, StudyError> {
    let study = read(path)?;
    study.check_model_inputs().map_err(|e| e.in_file(path))?;
    Ok(study)
}

/// Reads and checks a study file.
pub fn read(path: &Path) -> Result<Study, StudyError> {
    let text = std::fs::read_to_string(path).map_err(|error| StudyError::Read {
        path: path.to_path_buf(),
        error,
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut study = parse(&text, base).map_err(|e| e.in_file(path))?;
    study.file = Some(path.to_path_buf());
    Ok(study)
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
    let interfaces = parse_interface_tables(file.interface, &geometry, &lines)?;
    let mut tests = loading_tests::parse(file.test.as_deref(), &lines)?;
    if let Geometry::Deck(deck) = &geometry {
        deck_loads::apply(deck, &mut tests, file.test.as_deref(), &lines)?;
    }
    let identification =
        identification::parse(file.identification, &tests, &geometry, resolution, &lines)?;
    let (grid, sigma_mm) = measurement::parse_grid_noise(file.grid.clone(), file.noise, &lines)?;
    let probe = file.probe.unwrap_or_default();
    ultrasound::check_probe(&probe, &lines)?;
    let parsed = measurements::parse(
        file.measurement,
        &tests,
        &measurements::Defaults {
            sigma_mm,
            test: identification.test,
            probe: &probe,
        },
        &lines,
        base,
    )?;
    measurements::check_magnitudes(&grid, sigma_mm, &parsed.measurements, &lines)?;
    let design = design::parse(file.design, &tests, &probe, &lines)?;
    let first = &parsed.measurements[0];
    let measurement = MeasurementSpec {
        grid,
        sigma_mm: if parsed.list {
            sigma_mm
        } else {
            first.sigma_mm
        },
        source: first.source.clone(),
        travel: first.travel,
    };
    let boundary = boundary::parse(&file.fixed, &file.pressure, file.step.as_ref(), &lines)?;
    let convergence = convergence::parse(file.convergence, &tests, &lines)?;
    let ultrasound_section = file.ultrasound.unwrap_or_default();
    ultrasound::check(&ultrasound_section, &lines)?;
    let groups_given = matches!(&file.parameters, Some(p) if !p.groups.is_empty());
    let groups = match file.parameters {
        Some(p) if !p.groups.is_empty() => p.groups,
        _ => keys::default("parameters", "groups"),
    };
    let study = Study {
        model: ModelSpec {
            geometry,
            resolution,
            element,
            materials,
            interfaces,
        },
        tests,
        measurement,
        measurements: parsed.measurements,
        groups,
        identification,
        steps: identification::parse_steps(file.run),
        probe,
        ultrasound: ultrasound_section,
        boundary,
        convergence,
        design,
        grid_given: file.grid.is_some(),
        measurement_list: parsed.list,
        tests_given: file.test.is_some(),
        groups_given,
        lines: std::sync::Arc::new(lines),
        file: None,
    };
    if study.convergence.given {
        study.convergence_study()?;
    }
    Ok(study)
}

/// The `[[interface]]` tables (see [`parse_interfaces`]); a sliding one on
/// a deck is an error (a deck's regions are not split).
fn parse_interface_tables(
    value: Option<toml::Value>,
    geometry: &Geometry,
    lines: &KeyLines,
) -> Result<Vec<InterfaceSpec>, StudyError> {
    let Some(value) = value else {
        return Ok(Vec::new());
    };
    let line = lines
        .first_line_of("interface")
        .map(|l| format!(" (line {l})"))
        .unwrap_or_default();
    let mut doc = toml::Table::new();
    doc.insert("interface".into(), value);
    let specs = parse_interfaces(&toml::Value::Table(doc))
        .map_err(|e| StudyError::Study(format!("{e}{line}")))?;
    if matches!(geometry, Geometry::Deck(_)) && specs.iter().any(|s| s.law != InterfaceLaw::Tied) {
        return Err(StudyError::Study(format!(
            "[[interface]]{line}: a sliding interface needs a meshed thigh ([thigh] or [labels]); a [model] deck's regions are not split"
        )));
    }
    Ok(specs)
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

    /// The checks that need the files and the model's regions, before anything runs (issue
    /// 32.11): the label image, deck and measured field exist; every region has a material and
    /// every `[materials]` table a region (see [`regions`]); the names in `[identification]
    /// fixed` and `[parameters] groups` are parameters of the model (a deck is read for its
    /// materials).
    pub fn check_model_inputs(&self) -> Result<(), StudyError> {
        let mut files = Vec::new();
        match &self.model.geometry {
            Geometry::Labels(l) => files.push(("labels", "image", &l.image)),
            Geometry::Deck(p) => files.push(("model", "deck", p)),
            Geometry::Thigh(_) => {}
        }
        for m in &self.measurements {
            if let MeasurementSource::File {
                path, covariance, ..
            } = &m.source
            {
                files.push(("measurement", "file", path));
                if let Some(c) = covariance {
                    files.push(("measurement", "covariance", c));
                }
            }
        }
        for (table, key, path) in files {
            self.lines.existing_file(table, key, path)?;
        }
        for (k, m) in self.measurements.iter().enumerate() {
            if let MeasurementSource::Frames(f) = &m.source {
                f.resolve()
                    .map_err(|e| self.lines.err("measurement", k, e.key, e.message))?;
            }
        }
        let regions =
            match regions::of_geometry(&self.model.geometry, &self.model.materials, &self.lines)? {
                Some(r) => r,
                None => {
                    let Geometry::Deck(path) = &self.model.geometry else {
                        unreachable!("of_geometry knows every other geometry")
                    };
                    let (deck, _) = read_deck(&self.model.materials, path)
                        .map_err(|e| self.lines.err("model", 0, "deck", e.chain()))?;
                    deck.materials
                        .iter()
                        .map(|m| regions::RegionLaw {
                            name: m.name.clone(),
                            law: m.law.spec(),
                        })
                        .collect()
                }
            };
        regions::check_parameter_names(
            &regions,
            &self.identification.fixed,
            self.groups_given.then_some(&self.groups[..]),
            &self.lines,
        )
    }

    /// The data files the study reads: its label image, deck and measured field (an output
    /// folder must not hold them: `femu_mesh::folder`).
    pub fn input_files(&self) -> Vec<&Path> {
        let mut files = Vec::new();
        match &self.model.geometry {
            Geometry::Labels(l) => files.push(l.image.as_path()),
            Geometry::Deck(p) => files.push(p.as_path()),
            Geometry::Thigh(_) => {}
        }
        for m in &self.measurements {
            if let MeasurementSource::File {
                path, covariance, ..
            } = &m.source
            {
                files.push(path.as_path());
                files.extend(covariance.as_deref());
            }
            if let MeasurementSource::Frames(f) = &m.source {
                files.extend(f.input_files());
            }
        }
        files
    }

    /// Whether the measurements were written as a list (`[[measurement]]`, even of one): the
    /// outputs are then per measurement.
    pub fn measurement_list(&self) -> bool {
        self.measurement_list
    }

    /// Whether the study names its tests (`[[test]]`), rather than taking the seed's three.
    pub fn tests_given(&self) -> bool {
        self.tests_given
    }

    /// The error of a key found wrong after parsing (e.g. a region the built model lacks),
    /// named with its line.
    pub fn key_error(&self, table: &str, key: &str, message: String) -> StudyError {
        let e = self.lines.err(table, 0, key, message);
        match &self.file {
            Some(f) => e.in_file(f),
            None => e,
        }
    }
}

#[cfg(test)]
mod keys_tests;
#[cfg(test)]
mod measurement_tests;
#[cfg(test)]
mod unit_tests;
