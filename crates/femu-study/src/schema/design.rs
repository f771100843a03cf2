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

/// The most points all the design's windows may hold together (every side and size): the
/// points and one window's whitened Jacobian (2 rows per point and free parameter) are held at
/// once, some 0.3 GB for ten parameters at the limit. The default windows hold some 6 000.
pub const MAX_DESIGN_POINTS: usize = 2_000_000;

/// The most designs ranked: each scored design is kept (its names, sds and criteria) for
/// `designs.csv` and the two rankings; `femu design` of 78 778 designs peaked at 0.3 GB, so
/// some 0.8 GB at the limit. The defaults make 288; 4 measurements of 3 tests x 4 sides x 2
/// sizes some 1e4.
pub const MAX_DESIGNS: usize = 200_000;

/// The points along one side of a window of `length_mm` at `spacing_mm` (as the design's
/// windows place them: at least one).
fn window_points(length_mm: f64, spacing_mm: f64) -> f64 {
    (length_mm / spacing_mm).floor().max(1.0)
}

/// How many designs of 1 to `max_size` candidates there are when `groups` groups (a test seen
/// from one side) of `per_group` candidates each (the window sizes) do not combine within a
/// group: `Σ_k C(groups, k) per_group^k` (as a float: it may be huge).
pub fn design_count(groups: usize, per_group: usize, max_size: usize) -> f64 {
    let mut total = 0.0;
    let mut choose = 1.0;
    for k in 1..=max_size.min(groups) {
        choose *= (groups + 1 - k) as f64 / k as f64;
        total += choose * (per_group as f64).powi(k as i32);
    }
    total
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
    let chosen = chosen_tests(&e, tests, lines)?;
    let sides: Vec<String> = super::keys::or_default(e.sides.clone(), "design", "sides");
    if sides.is_empty() {
        return Err(err("sides", "name at least one side".into()));
    }
    for s in &sides {
        Side::parse(s).map_err(|m| err("sides", m))?;
    }
    let (windows_mm, spacing_mm) = windows(&e, probe, lines)?;
    check_point_count(&e, sides.len(), &windows_mm, spacing_mm, lines)?;
    let max_measurements = super::keys::check_int(
        "design",
        "max_measurements",
        super::keys::or_default(e.max_measurements, "design", "max_measurements"),
    )
    .map_err(|m| err("max_measurements", m))?;
    let candidates = [chosen.len(), sides.len(), windows_mm.len()];
    check_design_count(candidates, max_measurements, lines)?;
    let identifiable_sd = super::keys::check_real(
        "design",
        "identifiable_sd",
        super::keys::or_default(e.identifiable_sd, "design", "identifiable_sd"),
    )
    .map_err(|m| {
        err(
            "identifiable_sd",
            format!("a relative standard deviation {m}"),
        )
    })?;
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
        grouped: super::keys::or_default(e.grouped, "design", "grouped"),
    })
}

/// The indices of the `[[test]]`s `[design] tests` names (each once), all by default.
fn chosen_tests(
    e: &DesignEntry,
    tests: &[TestSpec],
    lines: &KeyLines,
) -> Result<Vec<usize>, StudyError> {
    let err = |key: &str, message: String| lines.err("design", 0, key, message);
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
    Ok(chosen)
}

/// The window sizes (width, depth in mm) and the spacing of their grids: each window holds
/// more than one point.
fn windows(
    e: &DesignEntry,
    probe: &ProbeSection,
    lines: &KeyLines,
) -> Result<(Vec<[f64; 2]>, f64), StudyError> {
    let err = |key: &str, message: String| lines.err("design", 0, key, message);
    let windows_mm: Vec<[f64; 2]> =
        super::keys::or_default(e.windows_mm.clone(), "design", "windows_mm");
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
    if let Some(w) = windows_mm.iter().find(|w| spacing_mm > w[0].min(w[1])) {
        return Err(err(
            spacing_or_windows(e),
            format!(
                "{spacing_mm} mm is larger than the {} x {} mm window: its grid would hold a single point",
                w[0], w[1]
            ),
        ));
    }
    Ok((windows_mm, spacing_mm))
}

/// The key to blame for too fine a grid: `spacing_mm` when given, else `windows_mm`.
fn spacing_or_windows(e: &DesignEntry) -> &'static str {
    if e.spacing_mm.is_some() {
        "spacing_mm"
    } else {
        "windows_mm"
    }
}

/// Refuses more than [`MAX_DESIGN_POINTS`] points in all the windows of every side: every
/// window of every side is held at once, bounded before the step allocates them.
fn check_point_count(
    e: &DesignEntry,
    sides: usize,
    windows_mm: &[[f64; 2]],
    spacing_mm: f64,
    lines: &KeyLines,
) -> Result<(), StudyError> {
    let points = (sides as f64)
        * windows_mm
            .iter()
            .map(|w| window_points(w[0], spacing_mm) * window_points(w[1], spacing_mm))
            .sum::<f64>();
    if points > MAX_DESIGN_POINTS as f64 {
        return Err(lines.err(
            "design",
            0,
            spacing_or_windows(e),
            format!(
                "{spacing_mm} mm gives {points:.1e} points in the {} windows ({} sides x {} sizes), above the limit of {MAX_DESIGN_POINTS}: give a larger spacing_mm",
                sides * windows_mm.len(),
                sides,
                windows_mm.len()
            ),
        ));
    }
    Ok(())
}

/// Refuses more than [`MAX_DESIGNS`] designs of up to `max_measurements` of the candidates
/// (`[tests, sides, window sizes]`, no test seen twice from one side).
fn check_design_count(
    [tests, sides, sizes]: [usize; 3],
    max_measurements: usize,
    lines: &KeyLines,
) -> Result<(), StudyError> {
    let designs = design_count(tests * sides, sizes, max_measurements);
    if designs > MAX_DESIGNS as f64 {
        return Err(lines.err(
            "design",
            0,
            "max_measurements",
            format!(
                "{max_measurements} measurements per design of {} candidates ({tests} tests x {sides} sides x {sizes} window sizes) make {designs:.1e} designs, above the limit of {MAX_DESIGNS}: give fewer window sizes, sides or measurements per design",
                tests * sides * sizes,
            ),
        ));
    }
    Ok(())
}
