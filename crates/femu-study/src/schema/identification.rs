//! `[parameters]`, `[identification]`, `[run]`: what is identified, how, and which steps run.

use super::geometry::{thigh_elements, Geometry, Resolution, DEFAULT_ELEMENTS};
use super::keys;
use super::lines::KeyLines;
use super::loading_tests::TestSpec;
use super::raw::{GroupedEntry, IdentificationEntry, RunEntry};
use super::StudyError;
use femu_identify::campaign::Optimizer;

/// Which groupings `femu run` identifies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grouping {
    /// Every parameter free.
    Ungrouped,
    /// `[parameters] groups` tied.
    Grouped,
    /// Both, one after the other (the seed's Fig. 9).
    Both,
}

/// The identification settings (`[identification]`).
#[derive(Debug, Clone, PartialEq)]
pub struct IdentificationSpec {
    /// Index into [`super::Study::tests`] of the test whose field is measured.
    pub test: usize,
    /// Parameters held at their reference value (`C10_FAT`, ...).
    pub fixed: Vec<String>,
    /// Bounds: reference / factor .. reference x factor.
    pub bounds_factor: f64,
    pub starts: usize,
    pub seed: u64,
    /// Noise realizations (Monte Carlo).
    pub repeat: usize,
    pub grouping: Grouping,
    pub optimizer: Optimizer,
    /// Multilevel: run the starts on the built-in thigh with this many elements and refine the
    /// best on the study's mesh.
    pub coarse_elements: Option<usize>,
    /// The loss on the (whitened) residuals of a measured field (`loss = "squared" | "huber"`).
    pub loss: femu_identify::weighted::Loss,
    /// What to do about the model's discretization error.
    pub discretization: Discretization,
    /// The virtual data are made on a mesh of the same geometry with the element size divided
    /// by this (1: the model's own mesh, the seed's numerical example).
    pub data_refinement: f64,
    /// Identification from images: the window (px) over which the integrated correlation
    /// normalizes each frame's grey levels (`IdicOptions::local_normalization_px`); `None`
    /// (`image_normalization_px = 0`): the grey levels as recorded.
    pub image_normalization_px: Option<f64>,
    /// Identification from images: which frames the integrated correlation compares
    /// (`image_pairing = "all" | "both" | "consecutive" | "reference"`).
    pub image_pairing: femu_identify::idic::Pairing,
}

/// Default `[identification] image_normalization_px` (px): below the speckle's size, so that
/// an interface's echo, renewed in part between load steps, is matched by its position and not
/// its brightness (README, images → parameters: chosen on realizations 1–20, checked on 21–30).
pub const DEFAULT_IMAGE_NORMALIZATION_PX: f64 = 0.75;

/// Default `[identification] image_pairing`: each frame against every earlier one (README,
/// images → parameters: on realizations 1–30, D_FAT's largest error 5.7 % against 7.0 % with
/// "both", for 1.4 times the pairs).
pub const DEFAULT_IMAGE_PAIRING: femu_identify::idic::Pairing = femu_identify::idic::Pairing::All;

/// `[identification] discretization`: the discretization check of every identification.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Discretization {
    /// No check.
    Off,
    /// At the optimum, refined meshes estimate the bias the mesh implies; the intervals are
    /// widened when it is not negligible (default).
    Check,
    /// As `Check`, and when the bias is not negligible the identification is continued on the
    /// finest refined mesh.
    Refine,
}

impl IdentificationSpec {
    /// Whether `[parameters] groups` are tied in a single identification (`femu identify`:
    /// the grouped one when `grouped = "both"`).
    pub fn grouped(&self) -> bool {
        self.grouping != Grouping::Ungrouped
    }
}

/// The steps of `femu run` (`[run]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steps {
    pub forward: bool,
    pub sensitivity: bool,
    pub identification: bool,
    /// `femu design`'s ranking of tests and probe windows (`[design]`), off by default.
    pub design: bool,
}

/// Checks `[identification]`.
pub(crate) fn parse(
    e: Option<IdentificationEntry>,
    tests: &[TestSpec],
    geometry: &Geometry,
    resolution: Resolution,
    lines: &KeyLines,
) -> Result<IdentificationSpec, StudyError> {
    let e = e.unwrap_or_default();
    let err = |key: &str, message: String| lines.err("identification", 0, key, message);
    let test = match &e.test {
        None => tests
            .iter()
            .position(|t| t.loading.is(&femu_mech::loading::compression::KIND))
            .unwrap_or(0),
        Some(name) => find_test(tests, name).map_err(|m| err("test", m))?,
    };
    let int =
        |key: &str, v: usize| keys::check_int("identification", key, v).map_err(|m| err(key, m));
    let real =
        |key: &str, v: f64| keys::check_real("identification", key, v).map_err(|m| err(key, m));
    // Beyond 100 (MAX_BOUNDS_FACTOR, its declared maximum) the bounds span over four decades
    // around the reference: wider than any soft tissue's range, and the starts drawn in them
    // mostly fail to solve.
    let or_default = |v: Option<usize>, key: &str| keys::or_default(v, "identification", key);
    let bounds_factor = real(
        "bounds_factor",
        keys::or_default(e.bounds_factor, "identification", "bounds_factor"),
    )?;
    let starts = int("starts", or_default(e.starts, "starts"))?;
    let repeat = int("repeat", or_default(e.repeat, "repeat"))?;
    let grouped = match e.grouped.clone() {
        Some(g) => g,
        None => keys::default("identification", "grouped"),
    };
    let grouping = match grouped {
        GroupedEntry::Flag(true) => Grouping::Grouped,
        GroupedEntry::Flag(false) => Grouping::Ungrouped,
        GroupedEntry::Word(w) if w.eq_ignore_ascii_case("both") => Grouping::Both,
        GroupedEntry::Word(w) => {
            return Err(err(
                "grouped",
                format!("'{w}' is not true, false or \"both\""),
            ))
        }
    };
    let optimizer = Choices::optimizer(&e, lines)?;
    let coarse_elements = match e.coarse_elements {
        None => None,
        Some(n) => Some(coarse_elements(n, geometry, resolution, lines)?),
    };
    let choices = Choices::parse(&e, lines)?;
    let data_refinement = data_refinement(&e, geometry, lines)?;
    let (image_normalization_px, image_pairing) = image_settings(&e, lines)?;
    Ok(IdentificationSpec {
        image_normalization_px,
        image_pairing,
        loss: choices.loss,
        test,
        discretization: choices.discretization,
        data_refinement,
        fixed: keys::or_default(e.fixed.clone(), "identification", "fixed"),
        bounds_factor,
        starts,
        seed: keys::or_default(e.seed, "identification", "seed"),
        repeat,
        grouping,
        optimizer,
        coarse_elements,
    })
}

/// The `[identification]` keys that choose a method by a word.
struct Choices {
    loss: femu_identify::weighted::Loss,
    discretization: Discretization,
}

impl Choices {
    /// `optimizer`.
    fn optimizer(e: &IdentificationEntry, lines: &KeyLines) -> Result<Optimizer, StudyError> {
        let err = |m: String| lines.err("identification", 0, "optimizer", m);
        let word = keys::word_or_default("identification", "optimizer", e.optimizer.as_deref())
            .map_err(err)?;
        match word {
            "lm" => Ok(Optimizer::LevenbergMarquardt),
            "bfgs" => Ok(Optimizer::Bfgs),
            "bfgs-fd" => Ok(Optimizer::BfgsFiniteDifference),
            other => Err(err(keys::unhandled("identification", "optimizer", other))),
        }
    }

    /// `loss` and `discretization`.
    fn parse(e: &IdentificationEntry, lines: &KeyLines) -> Result<Choices, StudyError> {
        let err = |key: &str, message: String| lines.err("identification", 0, key, message);
        let word = |key: &str, v: Option<&str>| {
            keys::word_or_default("identification", key, v).map_err(|m| err(key, m))
        };
        let unhandled = |key: &str, v: &str| err(key, keys::unhandled("identification", key, v));
        let loss = match word("loss", e.loss.as_deref())? {
            "squared" => femu_identify::weighted::Loss::Squared,
            "huber" => femu_identify::weighted::Loss::Huber {
                k: femu_identify::weighted::HUBER_K,
            },
            other => return Err(unhandled("loss", other)),
        };
        let discretization = match word("discretization", e.discretization.as_deref())? {
            "check" => Discretization::Check,
            "refine" => Discretization::Refine,
            "off" => Discretization::Off,
            other => return Err(unhandled("discretization", other)),
        };
        Ok(Choices {
            loss,
            discretization,
        })
    }
}

/// `coarse_elements = n`: a built-in thigh of `n` elements, coarser than the model's.
fn coarse_elements(
    n: usize,
    geometry: &Geometry,
    resolution: Resolution,
    lines: &KeyLines,
) -> Result<usize, StudyError> {
    let err = |message: String| lines.err("identification", 0, "coarse_elements", message);
    let Geometry::Thigh(thigh) = geometry else {
        return Err(err(
            "multilevel identification needs the built-in thigh ([thigh])".into(),
        ));
    };
    thigh_elements(thigh, n).map_err(err)?;
    let fine = match resolution {
        Resolution::Elements(m) => m,
        Resolution::Default => DEFAULT_ELEMENTS,
        Resolution::SizeMm(_) => usize::MAX,
    };
    if n >= fine {
        return Err(err(format!(
            "{n} is not coarser than the model's {fine} elements: the starts run on the coarse mesh and the best is refined on [model]'s; give fewer (e.g. {})",
            (fine / 3).max(thigh.min_target_elements())
        )));
    }
    Ok(n)
}

/// `data_refinement`: in its range, and above 1 only for a geometry femu can refine.
fn data_refinement(
    e: &IdentificationEntry,
    geometry: &Geometry,
    lines: &KeyLines,
) -> Result<f64, StudyError> {
    let err = |message: String| lines.err("identification", 0, "data_refinement", message);
    let data_refinement = keys::check_real(
        "identification",
        "data_refinement",
        keys::or_default(e.data_refinement, "identification", "data_refinement"),
    )
    .map_err(|m| {
        err(format!(
            "{m} (the element size of the virtual data's mesh is divided by it)"
        ))
    })?;
    if data_refinement > 1.0 && matches!(geometry, Geometry::Deck(_)) {
        return Err(err(
            "femu cannot refine a deck; virtual data on another mesh need the built-in thigh or a label image".into(),
        ));
    }
    Ok(data_refinement)
}

/// The identification from images: the grey levels' normalization window (`None`: as
/// recorded) and the frames compared.
fn image_settings(
    e: &IdentificationEntry,
    lines: &KeyLines,
) -> Result<(Option<f64>, femu_identify::idic::Pairing), StudyError> {
    let err = |key: &str, message: String| lines.err("identification", 0, key, message);
    let normalization = keys::check_real(
        "identification",
        "image_normalization_px",
        keys::or_default(
            e.image_normalization_px,
            "identification",
            "image_normalization_px",
        ),
    )
    .map_err(|m| {
        err(
            "image_normalization_px",
            format!(
                "{m} (0: the grey levels as recorded; default {DEFAULT_IMAGE_NORMALIZATION_PX})"
            ),
        )
    })?;
    let image_pairing = keys::word_or_default(
        "identification",
        "image_pairing",
        e.image_pairing.as_deref(),
    )
    .map_err(|m| err("image_pairing", m))?
    .parse()
    .map_err(|why| err("image_pairing", why))?;
    Ok((
        (normalization > 0.0).then_some(normalization),
        image_pairing,
    ))
}

/// The test of `tests` named `name` (its full name, `compression-lateral`, or its kind,
/// `compression`: the first of that kind); the message names the tests otherwise.
pub(crate) fn find_test(tests: &[TestSpec], name: &str) -> Result<usize, String> {
    tests
        .iter()
        .position(|t| t.loading.name().eq_ignore_ascii_case(name))
        .or_else(|| {
            tests.iter().position(|t| {
                t.loading
                    .name()
                    .split('-')
                    .next()
                    .is_some_and(|k| k.eq_ignore_ascii_case(name))
            })
        })
        .ok_or_else(|| {
            format!(
                "no test '{name}' (tests: {})",
                tests
                    .iter()
                    .map(|t| t.loading.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
}

/// Checks `[run]`.
pub(crate) fn parse_steps(r: Option<RunEntry>) -> Steps {
    let r = r.unwrap_or_default();
    let flag = |v: Option<bool>, key: &str| keys::or_default(v, "run", key);
    Steps {
        forward: flag(r.forward, "forward"),
        sensitivity: flag(r.sensitivity, "sensitivity"),
        identification: flag(r.identification, "identification"),
        design: flag(r.design, "design"),
    }
}
