//! The study file (TOML) of `femu run`, `femu sensitivity`, `femu synth` and `femu identify`:
//! the geometry, its materials, the loading tests, the measurement (grid, noise, or a measured
//! field and its frame), the identification and which steps to run. Every key is optional. Units
//! are in the key names (conventions.md); the empty study is the seed's numerical example on a 6 000-element thigh.
//! Everything is checked here, before any computation: an unknown key, a
//! missing value, a number out of range or a wrong unit suffix is an error naming the key and its
//! line. `femu init` writes [`EXAMPLE_STUDY`], every key with its default and a comment.
//!
//! Relative file names (`[labels] image`, `[model] deck`, `[measurement] file`) are relative to
//! the study file's folder.

use anyhow::{bail, Context, Result};
use femu_geometry::ThighParams;
use femu_mech::loading::{Loading, Side};
use femu_mesh::MMHG_IN_MPA;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The commented example study that `femu init` writes (every key, with its default).
pub const EXAMPLE_STUDY: &str = include_str!("example_study.toml");

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct PlanFile {
    model: Option<ModelEntry>,
    thigh: Option<ThighParams>,
    labels: Option<LabelsEntry>,
    #[serde(default)]
    materials: BTreeMap<String, MaterialEntry>,
    #[serde(default)]
    test: Vec<TestEntry>,
    grid: Option<GridEntry>,
    noise: Option<NoiseEntry>,
    measurement: Option<MeasurementEntry>,
    parameters: Option<ParametersEntry>,
    identification: Option<IdentificationEntry>,
    run: Option<RunEntry>,
    probe: Option<crate::us_cmd::ProbeSection>,
    ultrasound: Option<crate::us_cmd::UltrasoundSection>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct IdentificationEntry {
    test: Option<String>,
    #[serde(default)]
    fixed: Vec<String>,
    bounds_factor: Option<f64>,
    starts: Option<usize>,
    seed: Option<u64>,
    repeat: Option<usize>,
    grouped: Option<GroupedEntry>,
    optimizer: Option<String>,
    coarse_elements: Option<usize>,
}

/// `grouped = true | false | "both"`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum GroupedEntry {
    Flag(bool),
    Word(String),
}

/// The optimizer of the identification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Optimizer {
    /// Levenberg–Marquardt with the exact Jacobian (default).
    LevenbergMarquardt,
    /// BFGS with the exact gradient `Jᵀr`.
    Bfgs,
    /// BFGS with central finite-difference gradients (the seed's method, §2.1.3).
    BfgsFiniteDifference,
}

impl Optimizer {
    pub fn name(self) -> &'static str {
        match self {
            Optimizer::LevenbergMarquardt => "lm",
            Optimizer::Bfgs => "bfgs",
            Optimizer::BfgsFiniteDifference => "bfgs-fd",
        }
    }
}

/// The identification settings (`[identification]`).
#[derive(Debug, Clone, PartialEq)]
pub struct IdentificationPlan {
    /// Index into [`Plan::tests`] of the test whose field is measured.
    pub test: usize,
    /// Parameters held at their reference value (`C10_FAT`, ...).
    pub fixed: Vec<String>,
    /// Bounds: reference / factor .. reference x factor.
    pub bounds_factor: f64,
    pub starts: usize,
    pub seed: u64,
    /// Noise realizations (Monte Carlo).
    pub repeat: usize,
    /// Whether `[parameters] groups` are tied.
    pub grouped: bool,
    /// `grouped = "both"` (the default): `femu run` identifies ungrouped and grouped (seed
    /// Fig. 9); `femu identify` runs the grouped one.
    pub both_groupings: bool,
    pub optimizer: Optimizer,
    /// Multilevel: run the starts on the built-in thigh with this many elements and refine the
    /// best on the study's mesh.
    pub coarse_elements: Option<usize>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct ModelEntry {
    elements: Option<usize>,
    size_mm: Option<f64>,
    element: Option<String>,
    deck: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LabelsEntry {
    image: String,
    map: String,
    bone: Vec<u32>,
    background: Option<Vec<u32>>,
    slice: Option<usize>,
    pixel_size_mm: Option<f64>,
    min_island_mm2: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialEntry {
    c10_kpa: Option<f64>,
    c10_mpa: Option<f64>,
    d_per_mpa: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TestEntry {
    kind: String,
    pressure_mmhg: Option<f64>,
    pressure_mpa: Option<f64>,
    side: Option<String>,
    force_n_per_mm: Option<f64>,
    radius_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GridEntry {
    counts: Option<[usize; 2]>,
    origin_mm: Option<[f64; 2]>,
    spacing_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NoiseEntry {
    sigma_mm: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MeasurementEntry {
    source: Option<String>,
    file: Option<String>,
    units: Option<String>,
    pixel_size_mm: Option<f64>,
    origin_mm: Option<[f64; 2]>,
    x_axis: Option<[f64; 2]>,
    y_axis: Option<[f64; 2]>,
    travel_mm: Option<f64>,
    travel_sigma_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParametersEntry {
    #[serde(default)]
    groups: Vec<Vec<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RunEntry {
    forward: Option<bool>,
    sensitivity: Option<bool>,
    identification: Option<bool>,
}

/// Where the model comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// The built-in parametric thigh with these dimensions (`[thigh]`).
    Thigh(Box<ThighParams>),
    /// A segmented image (`[labels]`).
    Labels(LabelsPlan),
    /// An Abaqus/CalculiX deck (`[model] deck`): its materials and boundary conditions; the
    /// skin is the set of faces its `*DLOAD` loads (a contention deck, as `femu mesh` writes).
    Deck(PathBuf),
}

/// A label image to mesh (`[labels]`).
#[derive(Debug, Clone, PartialEq)]
pub struct LabelsPlan {
    pub image: PathBuf,
    /// `1=fat,2=quadriceps,...`
    pub map: String,
    pub bone: Vec<u32>,
    pub background: Vec<u32>,
    pub slice: Option<usize>,
    pub pixel_size_mm: Option<f64>,
    pub min_island_mm2: f64,
}

/// The measured field of the identification (`[measurement]`).
#[derive(Debug, Clone, PartialEq)]
pub enum MeasurementPlan {
    /// The virtual experiment (seed §2.4.1): the FE field of the reference parameters on the
    /// grid plus the study's noise.
    Virtual,
    /// A measured-field CSV (conventions.md) in its own frame, mapped to the model's.
    File { path: PathBuf, frame: Frame },
    /// The virtual experiment with images (issue 8, `femu us-sim`): B-mode images of the
    /// unloaded and loaded thigh under `[probe]` simulated with `[ultrasound]`, correlated by
    /// the DIC; the identification fits the DIC field.
    Ultrasound,
}

/// The map from a measured field's frame (image pixels or mm) to the model frame (mm):
/// `X = origin + s (x e_x + y e_y)`, `U = s (u_x e_x + u_y e_y)`; `e_x`, `e_y` orthonormal.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Frame {
    /// mm per unit of the file (the pixel size for a field in px; 1 for mm).
    pub scale: f64,
    pub origin: [f64; 2],
    pub x_axis: [f64; 2],
    pub y_axis: [f64; 2],
}

/// The steps of `femu run` (`[run]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steps {
    pub forward: bool,
    pub sensitivity: bool,
    pub identification: bool,
}

/// The measurement grid: `counts` points `spacing` apart from `origin` (mm); `None` fields are
/// fitted to the model's skin.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSpec {
    pub counts: [usize; 2],
    pub origin: Option<[f64; 2]>,
    pub spacing: Option<f64>,
}

impl GridSpec {
    /// The grid points (row by row, x fastest) for a model whose reference bounding box is
    /// `lo..hi`.
    pub fn points(&self, lo: [f64; 2], hi: [f64; 2]) -> Vec<[f64; 2]> {
        let [nx, ny] = self.counts;
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let spacing = self
            .spacing
            .unwrap_or(extent / (nx.max(ny).max(2) - 1) as f64);
        let origin = self.origin.unwrap_or([
            0.5 * (lo[0] + hi[0]) - 0.5 * spacing * (nx - 1) as f64,
            0.5 * (lo[1] + hi[1]) - 0.5 * spacing * (ny - 1) as f64,
        ]);
        (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    [
                        origin[0] + i as f64 * spacing,
                        origin[1] + j as f64 * spacing,
                    ]
                })
            })
            .collect()
    }
}

/// A checked study.
#[derive(Debug, Clone)]
pub struct Plan {
    pub geometry: Geometry,
    pub elements: Option<usize>,
    pub size_mm: Option<f64>,
    pub element: crate::QuadElement,
    /// `(region, C10 MPa, D MPa⁻¹)` overrides of Table 1 (or of the deck's materials).
    pub materials: Vec<(String, Option<f64>, Option<f64>)>,
    pub tests: Vec<Loading>,
    pub grid: GridSpec,
    pub sigma_mm: f64,
    pub measurement: MeasurementPlan,
    /// The actuator term: the measured travel of the force-controlled body (mm; `None` for a
    /// virtual experiment, which synthesizes it) and its standard deviation (mm).
    pub travel: Option<(Option<f64>, f64)>,
    pub groups: Vec<Vec<String>>,
    pub identification: IdentificationPlan,
    pub steps: Steps,
    /// `[probe]` and `[ultrasound]`: the simulated B-mode acquisition (`femu us-sim`,
    /// `[measurement] source = "ultrasound"`).
    pub probe: crate::us_cmd::ProbeSection,
    pub ultrasound: crate::us_cmd::UltrasoundSection,
}

impl Default for Plan {
    fn default() -> Self {
        parse("", Path::new(".")).expect("the empty study is valid")
    }
}

/// The seed's measurement noise: 1.5 px = 1.76e-2 mm (§3.1.3).
pub const SEED_SIGMA_MM: f64 = 1.76e-2;

/// The seed's grouping (§2.4.2): D of ischio, sartorius and gracilis tied.
pub fn seed_groups() -> Vec<Vec<String>> {
    vec![vec![
        "D_ISCHIO".into(),
        "D_SARTORIUS".into(),
        "D_GRACILIS".into(),
    ]]
}

/// The study of a command: the file if given (else the defaults), `--elements` over it, and the
/// seed's grouping when the study names none.
pub fn load(study: Option<&Path>, elements: Option<usize>) -> Result<Plan> {
    let mut plan = match study {
        Some(p) => read(p)?,
        None => Plan::default(),
    };
    if let Some(n) = elements {
        plan.elements = Some(n);
        plan.size_mm = None;
    }
    if plan.groups.is_empty() {
        plan.groups = seed_groups();
    }
    Ok(plan)
}

/// Reads and checks a study file.
pub fn read(path: &Path) -> Result<Plan> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read study file {}", path.display()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse(&text, base).with_context(|| format!("study file {}", path.display()))
}

/// Line numbers of the keys of a TOML text by table (`noise`, `materials.FAT`, `test`), entry of
/// an array of tables (0 for a plain table) and key — so that a value the TOML parser accepted
/// but the study rejects is reported with its line.
struct KeyLines {
    keys: Vec<(String, usize, String, usize)>,
}

impl KeyLines {
    fn new(text: &str) -> KeyLines {
        let mut keys = Vec::new();
        let mut table = String::new();
        let mut index = 0;
        let mut counts: BTreeMap<String, usize> = BTreeMap::new();
        for (k, raw) in text.lines().enumerate() {
            let t = raw.trim();
            if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
                table = name.trim().to_string();
                let c = counts.entry(table.clone()).or_insert(0);
                index = *c;
                *c += 1;
                keys.push((table.clone(), index, String::new(), k + 1));
            } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
                table = name.trim().trim_matches('"').to_string();
                index = 0;
                keys.push((table.clone(), 0, String::new(), k + 1));
            } else if let Some((key, _)) = t.split_once('=') {
                if !t.starts_with('#') {
                    keys.push((table.clone(), index, key.trim().to_string(), k + 1));
                }
            }
        }
        KeyLines { keys }
    }

    /// `"[table] key (line N)"`; the table header's line when the key is absent.
    fn at(&self, table: &str, index: usize, key: &str) -> String {
        let find = |key: &str| {
            self.keys
                .iter()
                .find(|(t, i, k, _)| t.eq_ignore_ascii_case(table) && *i == index && k == key)
                .map(|e| e.3)
        };
        let name = if table == "test" {
            format!("[[test]] {}", index + 1)
        } else {
            format!("[{table}]")
        };
        let key_part = if key.is_empty() {
            String::new()
        } else {
            format!(" {key}")
        };
        match find(key).or_else(|| find("")) {
            Some(line) => format!("{name}{key_part} (line {line})"),
            None => format!("{name}{key_part}"),
        }
    }
}

fn positive(name: &str, v: f64) -> Result<f64> {
    if !(v > 0.0 && v.is_finite()) {
        bail!("{name} must be positive and finite, got {v}");
    }
    Ok(v)
}

fn resolve(base: &Path, file: &str) -> PathBuf {
    let p = PathBuf::from(file);
    if p.is_absolute() {
        p
    } else {
        base.join(p)
    }
}

/// Parses and checks a study (see the module documentation); `base` is the folder relative file
/// names start from.
pub fn parse(text: &str, base: &Path) -> Result<Plan> {
    let file: PlanFile = toml::from_str(text).map_err(|e| anyhow::anyhow!("{e}"))?;
    let lines = KeyLines::new(text);
    let model = file.model.unwrap_or_default();
    if model.elements.is_some() && model.size_mm.is_some() {
        bail!(
            "{}: give elements or size_mm, not both",
            lines.at("model", 0, "size_mm")
        );
    }
    if let Some(h) = model.size_mm {
        positive(&lines.at("model", 0, "size_mm"), h)?;
    }
    if let Some(n) = model.elements {
        if !(100..=500_000).contains(&n) {
            bail!(
                "{} must be in [100, 500000], got {n}",
                lines.at("model", 0, "elements")
            );
        }
    }
    let element = match model
        .element
        .as_deref()
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        None | Some("cpe4h") => crate::QuadElement::Cpe4h,
        Some("cpe4") => crate::QuadElement::Cpe4,
        Some(other) => bail!(
            "{}: unknown element type '{other}' (cpe4, cpe4h)",
            lines.at("model", 0, "element")
        ),
    };
    let geometry = match (model.deck, file.thigh, file.labels) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) | (None, Some(_), Some(_)) => bail!(
            "give one geometry: [thigh] (the built-in thigh), [labels] (a label image) or [model] deck"
        ),
        (Some(deck), None, None) => {
            if model.elements.is_some() || model.size_mm.is_some() {
                bail!(
                    "{}: a deck brings its own mesh; elements and size_mm do not apply",
                    lines.at("model", 0, "deck")
                );
            }
            Geometry::Deck(resolve(base, &deck))
        }
        (None, thigh, None) => {
            let t = thigh.unwrap_or_default();
            if t.element_size_mm.is_some() || t.target_elements.is_some() {
                bail!(
                    "{}: give the mesh size in [model] (elements or size_mm)",
                    lines.at("thigh", 0, "")
                );
            }
            let mut check = t.clone();
            check.target_elements = Some(1000);
            check
                .validate()
                .map_err(|e| anyhow::anyhow!("{}: {e}", lines.at("thigh", 0, "")))?;
            Geometry::Thigh(Box::new(t))
        }
        (None, None, Some(l)) => {
            if model.elements.is_some() {
                bail!(
                    "{}: a label image is meshed by element size; give [model] size_mm",
                    lines.at("model", 0, "elements")
                );
            }
            if let Some(s) = l.pixel_size_mm {
                positive(&lines.at("labels", 0, "pixel_size_mm"), s)?;
            }
            let min_island = l.min_island_mm2.unwrap_or(5.0);
            if !(min_island >= 0.0 && min_island.is_finite()) {
                bail!(
                    "{} must be a finite area >= 0, got {min_island}",
                    lines.at("labels", 0, "min_island_mm2")
                );
            }
            femu_geometry::LabelSpec::new(
                &l.map,
                &l.bone,
                l.background.as_deref().unwrap_or(&[0]),
            )
            .map_err(|e| anyhow::anyhow!("{}: {e}", lines.at("labels", 0, "map")))?;
            Geometry::Labels(LabelsPlan {
                image: resolve(base, &l.image),
                map: l.map,
                bone: l.bone,
                background: l.background.unwrap_or_else(|| vec![0]),
                slice: l.slice,
                pixel_size_mm: l.pixel_size_mm,
                min_island_mm2: min_island,
            })
        }
    };
    let mut materials = Vec::new();
    for (region, m) in &file.materials {
        let table = format!("materials.{region}");
        let c10 = match (m.c10_kpa, m.c10_mpa) {
            (Some(_), Some(_)) => bail!(
                "{}: give c10_kpa or c10_mpa, not both",
                lines.at(&table, 0, "c10_mpa")
            ),
            (Some(k), None) => Some(positive(&lines.at(&table, 0, "c10_kpa"), k)? * 1e-3),
            (None, Some(v)) => Some(positive(&lines.at(&table, 0, "c10_mpa"), v)?),
            (None, None) => None,
        };
        let d = m
            .d_per_mpa
            .map(|d| positive(&lines.at(&table, 0, "d_per_mpa"), d))
            .transpose()?;
        materials.push((region.to_ascii_uppercase(), c10, d));
    }
    let mut tests = Vec::new();
    for (k, t) in file.test.iter().enumerate() {
        let at = |key: &str| format!("{} ({})", lines.at("test", k, key), t.kind);
        let side = |t: &TestEntry| -> Result<Side> {
            Side::parse(t.side.as_deref().unwrap_or("anterior"))
                .map_err(|e| anyhow::anyhow!("{}: {e}", at("side")))
        };
        let force = |t: &TestEntry| -> Result<f64> {
            positive(
                &at("force_n_per_mm"),
                t.force_n_per_mm
                    .with_context(|| format!("{}: force_n_per_mm is missing", at("")))?,
            )
        };
        let loading = match t.kind.to_ascii_lowercase().as_str() {
            "contention" => {
                let p = match (t.pressure_mmhg, t.pressure_mpa) {
                    (Some(_), Some(_)) => {
                        bail!("{}: give pressure_mmhg or pressure_mpa", at("pressure_mpa"))
                    }
                    (Some(mmhg), None) => positive(&at("pressure_mmhg"), mmhg)? * MMHG_IN_MPA,
                    (None, Some(mpa)) => positive(&at("pressure_mpa"), mpa)?,
                    (None, None) => 20.0 * MMHG_IN_MPA,
                };
                Loading::Contention { pressure: p }
            }
            "compression" => Loading::Compression {
                side: side(t)?,
                force: force(t)?,
            },
            "indentation" => Loading::Indentation {
                site: side(t)?,
                radius: positive(&at("radius_mm"), t.radius_mm.unwrap_or(10.0))?,
                force: force(t)?,
            },
            other => bail!(
                "{}: unknown kind '{other}' (contention, compression, indentation)",
                lines.at("test", k, "kind")
            ),
        };
        let extra = match t.kind.to_ascii_lowercase().as_str() {
            "contention" => t.side.is_some() || t.force_n_per_mm.is_some() || t.radius_mm.is_some(),
            "compression" => {
                t.pressure_mmhg.is_some() || t.pressure_mpa.is_some() || t.radius_mm.is_some()
            }
            _ => t.pressure_mmhg.is_some() || t.pressure_mpa.is_some(),
        };
        if extra {
            bail!("{}: a key of another kind of test is given", at(""));
        }
        if tests.iter().any(|o: &Loading| o.name() == loading.name()) {
            bail!(
                "{}: a second test named {} (one per kind and side)",
                at(""),
                loading.name()
            );
        }
        tests.push(loading);
    }
    if tests.is_empty() {
        tests = vec![
            Loading::SEED_CONTENTION,
            Loading::SEED_COMPRESSION,
            Loading::Indentation {
                site: Side::Anterior,
                radius: 10.0,
                force: 0.1,
            },
        ];
    }
    let grid = match file.grid {
        None => GridSpec {
            counts: [64, 64],
            origin: None,
            spacing: None,
        },
        Some(g) => {
            let counts = g.counts.unwrap_or([64, 64]);
            if counts[0] < 2 || counts[1] < 2 || counts[0] * counts[1] > 4_000_000 {
                bail!(
                    "{} must be at least 2 x 2 and at most 4e6 points, got {counts:?}",
                    lines.at("grid", 0, "counts")
                );
            }
            if let Some(s) = g.spacing_mm {
                positive(&lines.at("grid", 0, "spacing_mm"), s)?;
            }
            if let Some(o) = g.origin_mm {
                if !(o[0].is_finite() && o[1].is_finite()) {
                    bail!(
                        "{} must be finite, got {o:?}",
                        lines.at("grid", 0, "origin_mm")
                    );
                }
            }
            GridSpec {
                counts,
                origin: g.origin_mm,
                spacing: g.spacing_mm,
            }
        }
    };
    let sigma_mm = match file.noise {
        None => SEED_SIGMA_MM,
        Some(n) => positive(&lines.at("noise", 0, "sigma_mm"), n.sigma_mm)?,
    };
    let (measurement, travel) = match file.measurement {
        None => (MeasurementPlan::Virtual, None),
        Some(mut m) => {
            let at = |key: &str| lines.at("measurement", 0, key);
            let travel = match (m.travel_mm.take(), m.travel_sigma_mm.take()) {
                (None, None) => None,
                (t, Some(sigma)) => {
                    positive(&at("travel_sigma_mm"), sigma)?;
                    if let Some(t) = t {
                        if !t.is_finite() {
                            bail!("{} must be finite", at("travel_mm"));
                        }
                    }
                    Some((t, sigma))
                }
                (Some(_), None) => bail!("{}: give travel_sigma_mm too", at("travel_mm")),
            };
            let plan = measurement(m, &lines, base)?;
            match (&plan, travel) {
                (MeasurementPlan::File { .. }, Some((None, _))) => bail!(
                    "{}: a measured field needs its measured travel_mm",
                    at("travel_sigma_mm")
                ),
                (MeasurementPlan::Virtual, Some((Some(_), _))) => bail!(
                    "{}: the virtual experiment synthesizes the travel; give only travel_sigma_mm",
                    at("travel_mm")
                ),
                _ => {}
            }
            (plan, travel)
        }
    };
    let identification = {
        let e = file.identification.unwrap_or_default();
        let test = match &e.test {
            None => tests
                .iter()
                .position(|t| matches!(t, Loading::Compression { .. }))
                .unwrap_or(0),
            Some(name) => tests
                .iter()
                .position(|t| {
                    t.name().eq_ignore_ascii_case(name)
                        || t.name()
                            .split('-')
                            .next()
                            .is_some_and(|k| k.eq_ignore_ascii_case(name))
                })
                .with_context(|| {
                    format!(
                        "{}: no test '{name}' (tests: {})",
                        lines.at("identification", 0, "test"),
                        tests
                            .iter()
                            .map(|t| t.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                })?,
        };
        let bounds_factor = e.bounds_factor.unwrap_or(4.0);
        if !(bounds_factor > 1.0 && bounds_factor.is_finite()) {
            bail!(
                "{} must be above 1, got {bounds_factor}",
                lines.at("identification", 0, "bounds_factor")
            );
        }
        let starts = e.starts.unwrap_or(5);
        if !(1..=64).contains(&starts) {
            bail!(
                "{} must be in [1, 64], got {starts}",
                lines.at("identification", 0, "starts")
            );
        }
        let repeat = e.repeat.unwrap_or(1);
        if !(1..=1000).contains(&repeat) {
            bail!(
                "{} must be in [1, 1000], got {repeat}",
                lines.at("identification", 0, "repeat")
            );
        }
        let (grouped, both_groupings) = match e.grouped {
            None => (true, true),
            Some(GroupedEntry::Flag(b)) => (b, false),
            Some(GroupedEntry::Word(w)) if w.eq_ignore_ascii_case("both") => (true, true),
            Some(GroupedEntry::Word(w)) => bail!(
                "{}: '{w}' is not true, false or \"both\"",
                lines.at("identification", 0, "grouped")
            ),
        };
        let optimizer = match e
            .optimizer
            .as_deref()
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            None | Some("lm") => Optimizer::LevenbergMarquardt,
            Some("bfgs") => Optimizer::Bfgs,
            Some("bfgs-fd") => Optimizer::BfgsFiniteDifference,
            Some(other) => bail!(
                "{}: unknown optimizer '{other}' (lm, bfgs, bfgs-fd)",
                lines.at("identification", 0, "optimizer")
            ),
        };
        let coarse_elements = match e.coarse_elements {
            None => None,
            Some(n) => {
                let at = lines.at("identification", 0, "coarse_elements");
                if !matches!(geometry, Geometry::Thigh(_)) {
                    bail!("{at}: multilevel identification needs the built-in thigh ([thigh])");
                }
                if !(100..=500_000).contains(&n) {
                    bail!("{at} must be in [100, 500000], got {n}");
                }
                Some(n)
            }
        };
        IdentificationPlan {
            coarse_elements,
            test,
            fixed: e.fixed,
            bounds_factor,
            starts,
            seed: e.seed.unwrap_or(1),
            repeat,
            grouped,
            both_groupings,
            optimizer,
        }
    };
    let steps = match file.run {
        None => Steps {
            forward: true,
            sensitivity: true,
            identification: true,
        },
        Some(r) => Steps {
            forward: r.forward.unwrap_or(true),
            sensitivity: r.sensitivity.unwrap_or(true),
            identification: r.identification.unwrap_or(true),
        },
    };
    Ok(Plan {
        geometry,
        identification,
        elements: model.elements,
        size_mm: model.size_mm,
        element,
        materials,
        tests,
        grid,
        sigma_mm,
        measurement,
        travel,
        probe: file.probe.unwrap_or_default(),
        ultrasound: file.ultrasound.unwrap_or_default(),
        groups: file.parameters.map(|p| p.groups).unwrap_or_default(),
        steps,
    })
}

/// Checks `[measurement]`.
fn measurement(m: MeasurementEntry, lines: &KeyLines, base: &Path) -> Result<MeasurementPlan> {
    let at = |key: &str| lines.at("measurement", 0, key);
    let source = m
        .source
        .as_deref()
        .unwrap_or(if m.file.is_some() { "file" } else { "virtual" })
        .to_ascii_lowercase();
    match source.as_str() {
        "ultrasound" => {
            if m.file.is_some() || m.units.is_some() || m.origin_mm.is_some() {
                bail!(
                    "{}: the ultrasound experiment writes its own field in the model frame",
                    at("source")
                );
            }
            Ok(MeasurementPlan::Ultrasound)
        }
        "virtual" => {
            if m.file.is_some() {
                bail!("{}: a virtual measurement reads no file", at("file"));
            }
            Ok(MeasurementPlan::Virtual)
        }
        "file" => {
            let file = m
                .file
                .with_context(|| format!("{}: source = \"file\" needs file", at("source")))?;
            let scale = match m.units.as_deref().unwrap_or("mm") {
                "mm" => match m.pixel_size_mm {
                    Some(_) => bail!("{}: a field in mm has no pixel size", at("pixel_size_mm")),
                    None => 1.0,
                },
                "px" => positive(
                    &at("pixel_size_mm"),
                    m.pixel_size_mm.with_context(|| {
                        format!("{}: units = \"px\" needs pixel_size_mm", at("units"))
                    })?,
                )?,
                other => bail!("{}: unknown units '{other}' (mm, px)", at("units")),
            };
            let unit = |v: [f64; 2], key: &str| -> Result<[f64; 2]> {
                let n = v[0].hypot(v[1]);
                if !((n - 1.0).abs() < 1e-6) {
                    bail!("{} must be a unit vector, got {v:?}", at(key));
                }
                Ok(v)
            };
            let x_axis = unit(m.x_axis.unwrap_or([1.0, 0.0]), "x_axis")?;
            let y_axis = unit(m.y_axis.unwrap_or([0.0, 1.0]), "y_axis")?;
            if (x_axis[0] * y_axis[0] + x_axis[1] * y_axis[1]).abs() > 1e-6 {
                bail!(
                    "{}: x_axis {x_axis:?} and y_axis {y_axis:?} must be perpendicular",
                    at("y_axis")
                );
            }
            let origin = m.origin_mm.unwrap_or([0.0, 0.0]);
            if !(origin[0].is_finite() && origin[1].is_finite()) {
                bail!("{} must be finite", at("origin_mm"));
            }
            Ok(MeasurementPlan::File {
                path: resolve(base, &file),
                frame: Frame {
                    scale,
                    origin,
                    x_axis,
                    y_axis,
                },
            })
        }
        other => bail!("{}: unknown source '{other}' (virtual, file)", at("source")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_seed() {
        let p = Plan::default();
        assert_eq!(p.tests.len(), 3);
        assert_eq!(p.grid.counts, [64, 64]);
        assert_eq!(p.sigma_mm, SEED_SIGMA_MM);
        let pts = p.grid.points([-70.0, -60.0], [70.0, 60.0]);
        assert_eq!(pts.len(), 64 * 64);
        assert!((pts[0][0] + 70.0).abs() < 1e-12 && (pts[63][0] - 70.0).abs() < 1e-12);
    }

    #[test]
    fn reads_keys_and_names_bad_ones() {
        let p = parse(
            "[model]\nelements = 800\nelement = \"cpe4\"\n[materials.fat]\nc10_kpa = 1.0\n\
             [[test]]\nkind = \"compression\"\nside = \"lateral\"\nforce_n_per_mm = 0.2\n\
             [noise]\nsigma_mm = 0.01\n[parameters]\ngroups = [[\"D_ISCHIO\", \"D_GRACILIS\"]]\n",
            Path::new("."),
        )
        .unwrap();
        assert_eq!(p.elements, Some(800));
        assert_eq!(p.materials, vec![("FAT".into(), Some(1e-3), None)]);
        assert_eq!(p.tests.len(), 1);
        assert_eq!(p.groups.len(), 1);
        let err = |t: &str| format!("{:#}", parse(t, Path::new(".")).unwrap_err());
        let e = err("[model]\nelemnts = 3\n");
        assert!(e.contains("elemnts") && e.contains("line 2"), "{e}");
        assert!(err("[[test]]\nkind = \"stretch\"\n").contains("stretch"));
        assert!(err("[[test]]\nkind = \"compression\"\n").contains("force_n_per_mm"));
        assert!(err("[noise]\nsigma_mm = -1\n").contains("sigma_mm"));
        assert!(err("[materials.fat]\nc10_kpa = 1\nc10_mpa = 1\n").contains("not both"));
        assert!(
            err("[[test]]\nkind = \"contention\"\nforce_n_per_mm = 1\n").contains("another kind")
        );
    }

    /// The example of `femu init` is valid and spells out the defaults.
    #[test]
    fn the_example_study_is_the_default() {
        let e = parse(EXAMPLE_STUDY, Path::new(".")).unwrap();
        let d = Plan::default();
        assert_eq!(e.geometry, d.geometry);
        assert_eq!(e.tests, d.tests);
        assert_eq!(e.grid, d.grid);
        assert_eq!(e.sigma_mm, d.sigma_mm);
        assert_eq!(e.measurement, d.measurement);
        assert_eq!(e.identification, d.identification);
        assert_eq!(e.steps, d.steps);
        assert_eq!(e.groups, seed_groups());
        assert_eq!(e.elements, Some(6000));
        // Every Table 1 value restated.
        for (region, c10, d) in &e.materials {
            let t = femu_geometry::TABLE1
                .iter()
                .find(|t| t.0 == region)
                .expect("a Table 1 region");
            assert_eq!((c10.unwrap(), d.unwrap()), (t.1 * 1e-3, t.2), "{region}");
        }
    }

    /// Each kind of mistake of issue 9 names the key and its line.
    #[test]
    fn mistakes_name_the_key_and_line() {
        let err = |t: &str| format!("{:#}", parse(t, Path::new("/data")).unwrap_err());
        // Out of range, with the line.
        let e = err("[noise]\n\nsigma_mm = -1\n");
        assert!(e.contains("[noise] sigma_mm (line 3)"), "{e}");
        let e = err("[[test]]\nkind = \"contention\"\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0\n");
        assert!(e.contains("[[test]] 2 force_n_per_mm (line 5)"), "{e}");
        // Wrong unit: an unknown unit suffix is an unknown key.
        let e = err("[[test]]\nkind = \"contention\"\npressure_kpa = 2.6\n");
        assert!(e.contains("pressure_kpa") && e.contains("line 3"), "{e}");
        let e = err("[measurement]\nsource = \"file\"\nfile = \"f.csv\"\nunits = \"inch\"\n");
        assert!(e.contains("[measurement] units (line 4)"), "{e}");
        // Missing value.
        let e = err("[measurement]\nsource = \"file\"\nunits = \"px\"\n");
        assert!(e.contains("needs file"), "{e}");
        let e = err("[measurement]\nfile = \"f.csv\"\nunits = \"px\"\n");
        assert!(e.contains("needs pixel_size_mm"), "{e}");
        let e = err("[labels]\nimage = \"a.png\"\nbone = [7]\n");
        assert!(e.contains("map"), "{e}");
        // Geometry conflicts and dimensions.
        assert!(err("[model]\ndeck = \"a.inp\"\n[thigh]\n").contains("one geometry"));
        let e = err("[thigh]\nfat_thickness_mm = 100\n");
        assert!(e.contains("[thigh]") && e.contains("fat_thickness"), "{e}");
        let e = err("[identification]\ngrouped = \"maybe\"\n");
        assert!(e.contains("[identification] grouped (line 2)"), "{e}");
        let e = err("[identification]\noptimizer = \"nelder\"\n");
        assert!(e.contains("optimizer") && e.contains("lm, bfgs"), "{e}");
        let e = err("[model]\nelements = 5\n");
        assert!(e.contains("[model] elements (line 2)"), "{e}");
    }

    #[test]
    fn measurement_frame_and_files_are_relative_to_the_study() {
        let p = parse(
            "[measurement]\nfile = \"dic/field.csv\"\nunits = \"px\"\npixel_size_mm = 0.1\n\
             origin_mm = [-20, 60]\ny_axis = [0, -1]\n[labels]\nimage = \"l.png\"\n\
             map = \"1=fat,2=quadriceps\"\nbone = [7]\n[model]\nsize_mm = 2.0\n",
            Path::new("/data/s"),
        )
        .unwrap();
        let MeasurementPlan::File { path, frame } = &p.measurement else {
            panic!("a file measurement");
        };
        assert_eq!(path, &PathBuf::from("/data/s/dic/field.csv"));
        assert_eq!(frame.scale, 0.1);
        assert_eq!(frame.origin, [-20.0, 60.0]);
        assert_eq!(frame.y_axis, [0.0, -1.0]);
        let Geometry::Labels(l) = &p.geometry else {
            panic!("labels");
        };
        assert_eq!(l.image, PathBuf::from("/data/s/l.png"));
        assert_eq!(l.background, vec![0]);
    }
}
