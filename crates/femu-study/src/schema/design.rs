//! `[design]`: the candidate measurements `femu design` ranks (tests × probe sides × window
//! sizes, with the study's noise).
//!
//! ```toml
//! [design]
//! tests = ["contention", "compression"]    # the [[test]]s measured (all by default)
//! sides = ["anterior", "lateral", "medial", "posterior"]
//! windows_mm = [[40.0, 40.0], [60.0, 40.0]] # probe width x depth
//! spacing_mm = 1.6                          # grid spacing in a window (16 px of [probe])
//! max_measurements = 2                      # measurements per design
//! identifiable_sd = 0.1                     # a parameter is identified below this relative sd
//! grouped = false                           # tie [parameters] groups
//! ```

use super::identification::find_test;
use super::lines::KeyLines;
use super::loading_tests::TestSpec;
use super::raw::DesignEntry;
use super::ultrasound::ProbeSection;
use super::StudyError;
use femu_identify::design::DEFAULT_IDENTIFIABLE_SD;
use femu_mech::loading::Side;

/// The candidates and criteria of `femu design`.
#[derive(Debug, Clone, PartialEq)]
pub struct DesignSpec {
    /// Indices into [`super::Study::tests`].
    pub tests: Vec<usize>,
    pub sides: Vec<String>,
    /// Window sizes: width, depth (mm).
    pub windows_mm: Vec<[f64; 2]>,
    pub spacing_mm: f64,
    pub max_measurements: usize,
    pub identifiable_sd: f64,
    pub grouped: bool,
}

/// Checks `[design]`.
pub(crate) fn parse(
    e: Option<DesignEntry>,
    tests: &[TestSpec],
    probe: &ProbeSection,
    lines: &KeyLines,
) -> Result<DesignSpec, StudyError> {
    let err = |key: &str, message: String| lines.err("design", 0, key, message);
    let e = e.unwrap_or_default();
    let chosen = match &e.tests {
        None => (0..tests.len()).collect(),
        Some(names) => {
            let mut v = Vec::new();
            for n in names {
                let k = find_test(tests, n).map_err(|m| err("tests", m))?;
                if !v.contains(&k) {
                    v.push(k);
                }
            }
            v
        }
    };
    if chosen.is_empty() {
        return Err(err("tests", "name at least one [[test]]".into()));
    }
    let sides: Vec<String> = e.sides.unwrap_or_else(|| {
        ["anterior", "lateral", "medial", "posterior"]
            .map(String::from)
            .to_vec()
    });
    if sides.is_empty() {
        return Err(err("sides", "name at least one side".into()));
    }
    for s in &sides {
        Side::parse(s).map_err(|m| err("sides", m))?;
    }
    let windows_mm = e.windows_mm.unwrap_or(vec![[40.0, 40.0], [60.0, 40.0]]);
    if windows_mm.is_empty() {
        return Err(err("windows_mm", "give at least one window size".into()));
    }
    if let Some(w) = windows_mm
        .iter()
        .find(|w| !(w[0] > 0.0 && w[0] <= 200.0 && w[1] > 0.0 && w[1] <= 200.0))
    {
        return Err(err(
            "windows_mm",
            format!("{w:?}: width and depth must be in (0, 200] mm"),
        ));
    }
    let spacing_mm = match e.spacing_mm {
        Some(s) => lines.positive("design", 0, "spacing_mm", s)?,
        None => 16.0 / probe.px_per_mm,
    };
    let max_measurements = e.max_measurements.unwrap_or(2);
    if !(1..=4).contains(&max_measurements) {
        return Err(err(
            "max_measurements",
            format!("must be in [1, 4], got {max_measurements}"),
        ));
    }
    let identifiable_sd = match e.identifiable_sd {
        Some(v) => lines.positive("design", 0, "identifiable_sd", v)?,
        None => DEFAULT_IDENTIFIABLE_SD,
    };
    Ok(DesignSpec {
        tests: chosen,
        sides: sides
            .iter()
            .map(|s| s.trim().to_ascii_lowercase())
            .collect(),
        windows_mm,
        spacing_mm,
        max_measurements,
        identifiable_sd,
        grouped: e.grouped.unwrap_or(false),
    })
}
