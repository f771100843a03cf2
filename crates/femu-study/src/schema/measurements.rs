//! `[measurement]` or `[[measurement]]`: what is measured — one test's field (the seed), or
//! several measurements fitted together (a joint identification), each a loading test seen on
//! the `[grid]`, through a probe window, or in a file, with its own noise.
//!
//! ```toml
//! [[measurement]]
//! test = "contention"          # a [[test]] (name or kind); [identification] test by default
//! window = "anterior"          # the probe's side: anterior, posterior, lateral, medial, degrees
//! window_mm = [40.0, 40.0]     # width x depth ([probe] by default)
//! spacing_mm = 1.6             # grid spacing in the window (16 px of [probe] by default)
//! sigma_mm = 0.0176            # noise ([noise] by default)
//! [[measurement]]
//! test = "compression"
//! window = "lateral"
//! ```
//!
//! A study with one `[measurement]` table (every key of which keeps working) is a joint study
//! of one. Without `window` a virtual measurement uses the `[grid]`; a file brings its points
//! and weights; an ultrasound measurement images its window (or `[probe]`).

use super::identification::find_test;
use super::lines::KeyLines;
use super::loading_tests::TestSpec;
use super::measurement::{check_entry, GridSpec, MeasurementSource, Travel};
use super::raw::MeasurementEntry;
use super::ultrasound::ProbeSection;
use super::StudyError;
use femu_mech::loading::Side;
use serde::Deserialize;
use std::path::Path;

/// One measurement of the study.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// Names its outputs: `contention_anterior`, `compression-anterior_grid`, ... (unique).
    pub name: String,
    /// Index into [`super::Study::tests`].
    pub test: usize,
    pub region: Region,
    /// Standard deviation of the measured displacement (mm) of a virtual measurement; a file
    /// carries its own weights.
    pub sigma_mm: f64,
    pub source: MeasurementSource,
    /// The actuator term of the test.
    pub travel: Option<Travel>,
}

/// Where a measurement sees the tissue.
#[derive(Debug, Clone, PartialEq)]
pub enum Region {
    /// The study's `[grid]` (the whole section by default, as the seed).
    Grid,
    /// A linear probe's field of view on one side of the thigh.
    Window(WindowSpec),
}

/// A probe window: the rectangle a linear probe on the skin sees (`femu_ultrasound::probe`),
/// with a grid of measured points in it.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowSpec {
    /// `anterior`, `posterior`, `lateral`, `medial` or an angle in degrees.
    pub side: String,
    pub width_mm: f64,
    pub depth_mm: f64,
    /// Distance between the grid's points (mm).
    pub spacing_mm: f64,
}

impl WindowSpec {
    /// `anterior 40 x 40 mm`.
    pub fn label(&self) -> String {
        format!(
            "{} {} x {} mm",
            self.side,
            fmt_mm(self.width_mm),
            fmt_mm(self.depth_mm)
        )
    }
}

fn fmt_mm(v: f64) -> String {
    if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

impl Measurement {
    /// `contention, anterior 40 x 40 mm`, `compression-anterior, grid`, ...
    pub fn label(&self, tests: &[TestSpec]) -> String {
        let test = tests[self.test].loading.name();
        match (&self.source, &self.region) {
            (MeasurementSource::File { path, .. }, _) => {
                format!("{test}, file {}", path.display())
            }
            (MeasurementSource::Frames(_), _) => format!("{test}, recorded frames"),
            (_, Region::Grid) => format!("{test}, grid"),
            (_, Region::Window(w)) => format!("{test}, {}", w.label()),
        }
    }
}

/// What the study's measurements are, and how they were written.
pub(crate) struct Parsed {
    pub measurements: Vec<Measurement>,
    /// `[[measurement]]` (a list, even of one).
    pub list: bool,
}

/// The defaults of a measurement's keys.
pub(crate) struct Defaults<'a> {
    pub sigma_mm: f64,
    pub test: usize,
    pub probe: &'a ProbeSection,
}

/// Checks `[measurement]` / `[[measurement]]` (`value` as TOML gave it).
pub(crate) fn parse(
    value: Option<toml::Value>,
    tests: &[TestSpec],
    defaults: &Defaults,
    lines: &KeyLines,
    base: &Path,
) -> Result<Parsed, StudyError> {
    let (entries, list) = match value {
        None => (vec![MeasurementEntry::default()], false),
        Some(toml::Value::Array(items)) => {
            if items.is_empty() {
                return Err(StudyError::Study(
                    "measurement = []: give at least one [[measurement]] (or leave it out for the virtual experiment on the [grid])".into(),
                ));
            }
            let entries = items
                .into_iter()
                .enumerate()
                .map(|(k, v)| entry(v, k, lines))
                .collect::<Result<Vec<_>, _>>()?;
            (entries, true)
        }
        Some(v) => (vec![entry(v, 0, lines)?], false),
    };
    let mut measurements: Vec<Measurement> = Vec::new();
    for (k, mut e) in entries.into_iter().enumerate() {
        let mut m = one(&mut e, k, tests, defaults, lines, base)?;
        // Unique names: a second measurement of the same test and window gets its number.
        if measurements.iter().any(|o| o.name == m.name) {
            m.name = format!("{}_{}", m.name, k + 1);
        }
        measurements.push(m);
    }
    same_file_twice(&measurements, lines)?;
    if measurements.len() > 1 {
        if let Some(k) = measurements
            .iter()
            .position(|m| matches!(m.source, MeasurementSource::Frames(_)))
        {
            return Err(lines.err(
                "measurement",
                k,
                "source",
                "recorded frames are identified alone (integrated DIC of one test): give one [measurement]".into(),
            ));
        }
    }
    for (k, m) in measurements.iter().enumerate() {
        let twice = measurements[..k]
            .iter()
            .any(|o| o.test == m.test && o.travel.is_some() && m.travel.is_some());
        if twice {
            return Err(lines.err(
                "measurement",
                k,
                "travel_sigma_mm",
                format!(
                    "the travel of {} is already measured by an earlier measurement: give its actuator term once per test",
                    tests[m.test].loading.name()
                ),
            ));
        }
    }
    Ok(Parsed { measurements, list })
}

/// The largest noise standard deviation (mm) of a measurement or an actuator's travel: 10 mm,
/// more than the tests' largest displacements.
pub const MAX_SIGMA_MM: f64 = 10.0;

/// The magnitudes the parsers of `[grid]`, `[noise]` and the measurements' frames leave open,
/// checked on what they return: positions within the model's coordinates
/// ([`femu_mesh::mesh::MAX_COORDINATE_MM`]), noises up to [`MAX_SIGMA_MM`], pixels up to
/// 100 mm.
pub(crate) fn check_magnitudes(
    grid: &GridSpec,
    noise_sigma_mm: f64,
    measurements: &[Measurement],
    lines: &KeyLines,
) -> Result<(), StudyError> {
    use femu_mesh::mesh::{check_coordinate, MAX_COORDINATE_MM};
    if let Some(o) = grid.origin {
        for v in o {
            check_coordinate(v).map_err(|m| lines.err("grid", 0, "origin_mm", m))?;
        }
    }
    if let Some(s) = grid.spacing {
        let span = s * (grid.counts[0].max(grid.counts[1]) - 1) as f64;
        if span > MAX_COORDINATE_MM {
            return Err(lines.err(
                "grid",
                0,
                "spacing_mm",
                format!(
                    "{s} mm makes the grid {span:e} mm long, beyond the ±{MAX_COORDINATE_MM:e} mm of the model's coordinates"
                ),
            ));
        }
    }
    lines.at_most("noise", 0, "sigma_mm", noise_sigma_mm, MAX_SIGMA_MM)?;
    for (k, m) in measurements.iter().enumerate() {
        lines.at_most("measurement", k, "sigma_mm", m.sigma_mm, MAX_SIGMA_MM)?;
        if let Some(t) = &m.travel {
            lines.at_most(
                "measurement",
                k,
                "travel_sigma_mm",
                t.sigma_mm,
                MAX_SIGMA_MM,
            )?;
            // A plate's travel beyond a metre is a unit mistake.
            if let Some(v) = t.measured_mm {
                if v.abs() > 1000.0 {
                    return Err(lines.err(
                        "measurement",
                        k,
                        "travel_mm",
                        format!("must be within ±1000 mm, got {v}"),
                    ));
                }
            }
        }
        if let MeasurementSource::File { frame, .. } = &m.source {
            lines.at_most(
                "measurement",
                k,
                "pixel_size_mm",
                frame.scale,
                super::geometry::MAX_LENGTH_MM,
            )?;
        }
    }
    Ok(())
}

/// Refuses two measurements reading the same measured field (its points would count twice, and
/// the intervals shrink as if the data were independent). Paths are compared canonicalized
/// (`a/../field.csv`, a link), as written when the file does not exist (a later check says so).
fn same_file_twice(measurements: &[Measurement], lines: &KeyLines) -> Result<(), StudyError> {
    let files: Vec<Option<(usize, &Path, std::path::PathBuf)>> = measurements
        .iter()
        .enumerate()
        .map(|(k, m)| match &m.source {
            MeasurementSource::File { path, .. } => Some((
                k,
                path.as_path(),
                std::fs::canonicalize(path).unwrap_or_else(|_| path.clone()),
            )),
            _ => None,
        })
        .collect();
    let files: Vec<_> = files.into_iter().flatten().collect();
    for (j, (k, path, canonical)) in files.iter().enumerate() {
        if let Some((first, _, _)) = files[..j].iter().find(|f| &f.2 == canonical) {
            return Err(lines.err(
                "measurement",
                *k,
                "file",
                format!(
                    "{} is already read by {}: the same measured field given twice would count its points twice",
                    path.display(),
                    lines.at("measurement", *first, "file")
                ),
            ));
        }
    }
    Ok(())
}

/// The `index`-th entry as the schema's type; an unknown or mistyped key is named with its
/// line.
fn entry(v: toml::Value, index: usize, lines: &KeyLines) -> Result<MeasurementEntry, StudyError> {
    MeasurementEntry::deserialize(v).map_err(|e| {
        let msg = e.to_string();
        let key = msg.split('`').nth(1).unwrap_or("");
        lines.err("measurement", index, key, msg.trim_end().to_string())
    })
}

/// Checks one entry.
fn one(
    e: &mut MeasurementEntry,
    k: usize,
    tests: &[TestSpec],
    defaults: &Defaults,
    lines: &KeyLines,
    base: &Path,
) -> Result<Measurement, StudyError> {
    let test = match &e.test {
        None => defaults.test,
        Some(name) => find_test(tests, name).map_err(|m| lines.err("measurement", k, "test", m))?,
    };
    let (source, travel) = check_entry(e, k, lines, base)?;
    if let MeasurementSource::File { frame, .. } = &source {
        for v in frame.origin {
            femu_mesh::mesh::check_coordinate(v)
                .map_err(|m| lines.err("measurement", k, "origin_mm", m))?;
        }
    }
    if let MeasurementSource::Frames(f) = &source {
        super::frames::check_with_test(f, &tests[test], k, lines)?;
    }
    if travel.is_some() && !tests[test].loading.has_rigid_body() {
        return Err(lines.err(
            "measurement",
            k,
            "travel_sigma_mm",
            format!(
                "the actuator term needs a test with a rigid body, not {}",
                tests[test].loading.name()
            ),
        ));
    }
    let sigma_mm = match e.sigma_mm {
        None => defaults.sigma_mm,
        Some(s) => {
            if matches!(source, MeasurementSource::File { .. }) {
                return Err(lines.err(
                    "measurement",
                    k,
                    "sigma_mm",
                    "a measured field carries its noise in its sx,sy or w columns".into(),
                ));
            }
            lines.positive("measurement", k, "sigma_mm", s)?
        }
    };
    let region = window(e, k, &source, defaults.probe, lines)?;
    let test_name = tests[test].loading.name();
    let name = match (&source, &region) {
        (MeasurementSource::File { path, .. }, _) => format!(
            "{test_name}_{}",
            path.file_stem()
                .map_or("file".into(), |s| s.to_string_lossy().to_string())
        ),
        (MeasurementSource::Frames(_), _) => format!("{test_name}_frames"),
        (_, Region::Grid) => format!("{test_name}_grid"),
        (_, Region::Window(w)) => format!("{test_name}_{}", w.side.replace(' ', "")),
    };
    Ok(Measurement {
        name,
        test,
        region,
        sigma_mm,
        source,
        travel,
    })
}

/// The region of an entry: its window if it names one, else the grid.
fn window(
    e: &MeasurementEntry,
    k: usize,
    source: &MeasurementSource,
    probe: &ProbeSection,
    lines: &KeyLines,
) -> Result<Region, StudyError> {
    let err = |key: &str, message: String| lines.err("measurement", k, key, message);
    let Some(side) = &e.window else {
        for (key, given) in [
            ("window_mm", e.window_mm.is_some()),
            ("spacing_mm", e.spacing_mm.is_some()),
        ] {
            if given {
                return Err(err(
                    key,
                    "give the window's side too (window = \"anterior\", ...)".into(),
                ));
            }
        }
        return Ok(Region::Grid);
    };
    if matches!(source, MeasurementSource::File { .. }) {
        return Err(err(
            "window",
            "a measured field brings its own points; a window applies to virtual and ultrasound measurements".into(),
        ));
    }
    Side::parse(side).map_err(|m| err("window", m))?;
    let [width_mm, depth_mm] = e.window_mm.unwrap_or([probe.width_mm, probe.depth_mm]);
    for (v, what) in [(width_mm, "width"), (depth_mm, "depth")] {
        if !(v > 0.0 && v <= 200.0) {
            return Err(err(
                "window_mm",
                format!("the {what} must be in (0, 200] mm, got {v}"),
            ));
        }
    }
    let spacing_mm = match e.spacing_mm {
        Some(s) => lines.positive("measurement", k, "spacing_mm", s)?,
        // The seed's DIC grid: 16 px apart, at the probe's pixel size.
        None => 16.0 / probe.px_per_mm,
    };
    if spacing_mm > width_mm.min(depth_mm) {
        return Err(err(
            "spacing_mm",
            format!(
                "{spacing_mm} mm is larger than the {width_mm} x {depth_mm} mm window: its grid would hold a single point"
            ),
        ));
    }
    if (width_mm / spacing_mm + 1.0) * (depth_mm / spacing_mm + 1.0) > 4e6 {
        return Err(err(
            "spacing_mm",
            format!("{spacing_mm} mm gives more than 4e6 points in the window"),
        ));
    }
    Ok(Region::Window(WindowSpec {
        side: side.trim().to_ascii_lowercase(),
        width_mm,
        depth_mm,
        spacing_mm,
    }))
}
