//! The study file as TOML gives it (serde), before any check: every table of the one schema.
//! Unknown keys are rejected here by the parser, which names them with their line.

use super::ultrasound::{ProbeSection, UltrasoundSection};
use femu_geometry::ThighParams;
use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct StudyFile {
    pub model: Option<ModelEntry>,
    pub thigh: Option<ThighParams>,
    pub labels: Option<LabelsEntry>,
    /// `[materials.REGION]`: a law and its parameters with unit suffixes, checked against the
    /// law's declared parameters (so any key may appear here).
    #[serde(default)]
    pub materials: BTreeMap<String, BTreeMap<String, toml::Value>>,
    /// `[[interface]]`: read by `crate::schema::parse_interfaces`.
    pub interface: Option<toml::Value>,
    /// `None`: no `[[test]]` (the seed's three); `Some([])`: `test = []`, an error.
    pub test: Option<Vec<TestEntry>>,
    pub grid: Option<GridEntry>,
    pub noise: Option<NoiseEntry>,
    /// `[measurement]` (one table) or `[[measurement]]` (a list of them), read into
    /// [`MeasurementEntry`] by `super::measurements` so that each entry's errors keep their line.
    pub measurement: Option<toml::Value>,
    pub parameters: Option<ParametersEntry>,
    pub identification: Option<IdentificationEntry>,
    pub run: Option<RunEntry>,
    pub probe: Option<ProbeSection>,
    pub ultrasound: Option<UltrasoundSection>,
    /// `[[fixed]]`, `[[pressure]]`, `[step]`: the boundary conditions of a Gmsh mesh.
    #[serde(default)]
    pub fixed: Vec<FixedEntry>,
    #[serde(default)]
    pub pressure: Vec<PressureEntry>,
    pub step: Option<StepEntry>,
    pub convergence: Option<ConvergenceEntry>,
    pub design: Option<DesignEntry>,
}

/// `[design]`: the candidate measurements of `femu design`.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct DesignEntry {
    /// The `[[test]]`s (names or kinds); all by default.
    pub tests: Option<Vec<String>>,
    pub sides: Option<Vec<String>>,
    pub windows_mm: Option<Vec<[f64; 2]>>,
    pub spacing_mm: Option<f64>,
    pub max_measurements: Option<usize>,
    pub identifiable_sd: Option<f64>,
    pub grouped: Option<bool>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct ModelEntry {
    pub elements: Option<usize>,
    pub size_mm: Option<f64>,
    pub element: Option<String>,
    pub deck: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct LabelsEntry {
    pub image: String,
    pub map: String,
    pub bone: Vec<u32>,
    pub background: Option<Vec<u32>>,
    pub slice: Option<usize>,
    pub pixel_size_mm: Option<f64>,
    pub min_island_mm2: Option<f64>,
}

/// A `[[test]]`: its kind, the curve of a Gmsh mesh it acts on, and the kind's own keys
/// (checked against the kind's declared keys, `femu_mech::loading::TEST_KINDS`).
#[derive(Debug, Deserialize)]
pub(crate) struct TestEntry {
    pub kind: String,
    /// The physical curve of a Gmsh mesh the test acts on.
    pub curve: Option<String>,
    #[serde(flatten)]
    pub keys: BTreeMap<String, toml::Value>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct GridEntry {
    pub counts: Option<[usize; 2]>,
    pub origin_mm: Option<[f64; 2]>,
    pub spacing_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct NoiseEntry {
    pub sigma_mm: f64,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct MeasurementEntry {
    /// The measured `[[test]]` (name or kind); `[identification] test` by default.
    pub test: Option<String>,
    /// The probe window: its side, its width and depth, the spacing of its grid.
    pub window: Option<String>,
    pub window_mm: Option<[f64; 2]>,
    pub spacing_mm: Option<f64>,
    /// The noise of this measurement (`[noise] sigma_mm` by default).
    pub sigma_mm: Option<f64>,
    pub source: Option<String>,
    pub file: Option<String>,
    pub units: Option<String>,
    pub pixel_size_mm: Option<f64>,
    pub origin_mm: Option<[f64; 2]>,
    pub x_axis: Option<[f64; 2]>,
    pub y_axis: Option<[f64; 2]>,
    pub travel_mm: Option<f64>,
    pub travel_sigma_mm: Option<f64>,
    pub covariance: Option<String>,
    /// How a measured file's misfit is weighted (`per-point`, `covariance`, `estimated`).
    pub weighting: Option<String>,
    /// Recorded frames (`source = "frames"`, `super::frames`).
    pub frames: Option<Vec<String>>,
    pub cine: Option<String>,
    pub frame_indices: Option<Vec<usize>>,
    pub frame_times_s: Option<Vec<f64>>,
    pub loads_n_per_mm: Option<Vec<f64>>,
    pub force_log: Option<String>,
    pub force_log_offset_s: Option<f64>,
    pub force_log_units: Option<Vec<String>>,
    /// The frames' pose: as given, or refined from the unloaded frame (`given`, `refined`).
    pub pose: Option<String>,
    /// The imaging of a measured file's frames, for the speckle's lateral shift under shear
    /// (`femu_identify::speckle`): centre frequency, lateral resolution, sound speed, and
    /// whether the shift's scale is fitted or held at the closed form's.
    pub speckle_frequency_mhz: Option<f64>,
    pub speckle_resolution_mm: Option<f64>,
    pub speckle_sound_speed_m_s: Option<f64>,
    pub speckle_shift: Option<String>,
    pub speckle_scale: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ParametersEntry {
    #[serde(default)]
    pub groups: Vec<Vec<String>>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct IdentificationEntry {
    pub test: Option<String>,
    pub fixed: Option<Vec<String>>,
    pub bounds_factor: Option<f64>,
    pub starts: Option<usize>,
    pub seed: Option<u64>,
    pub repeat: Option<usize>,
    pub grouped: Option<GroupedEntry>,
    pub optimizer: Option<String>,
    pub coarse_elements: Option<usize>,
    pub loss: Option<String>,
    pub discretization: Option<String>,
    pub data_refinement: Option<f64>,
    pub image_normalization_px: Option<f64>,
    pub image_pairing: Option<String>,
}

/// `grouped = true | false | "both"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub(crate) enum GroupedEntry {
    Flag(bool),
    Word(String),
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RunEntry {
    pub forward: Option<bool>,
    pub sensitivity: Option<bool>,
    pub identification: Option<bool>,
    pub design: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct FixedEntry {
    pub curve: String,
    pub dofs: Option<Vec<usize>>,
    pub value_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PressureEntry {
    pub curve: String,
    pub mmhg: Option<f64>,
    pub mpa: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct StepEntry {
    pub initial_increment: Option<f64>,
    pub min_increment: Option<f64>,
    pub max_increment: Option<f64>,
    pub max_increments: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ConvergenceEntry {
    pub element_types: Option<Vec<String>>,
    pub target_elements: Option<Vec<usize>>,
    pub element_size_mm: Option<Vec<f64>>,
    pub tolerance_mm: Option<f64>,
    pub locking: Option<bool>,
    pub d_scale: Option<f64>,
    pub locking_meshes: Option<usize>,
    pub raster_mm: Option<f64>,
    /// The `[[test]]` of the study run on every mesh (by name or kind); the first by default.
    pub test: Option<String>,
}
