//! The measurements of a study made ready to fit: a virtual measurement's points in the tissue
//! (the `[grid]`, or a probe window's grid), a file's field in the model frame, or the DIC of
//! simulated B-mode images of its window. The identification (`identify_on`) fits them all.

use crate::bail;
use crate::error::{Context, Result};
use crate::model::StudyModel;
use crate::progress::Progress;
use crate::schema::{
    GridSpec, Measurement, MeasurementSource, ModelSpec, ProbeSection, Region, Study, TestSpec,
    UltrasoundSection, WindowSpec,
};
use crate::steps::ultrasound::{SimInputs, SimulatedImages};
use femu_identify::campaign::{self, TravelTerm};
use femu_identify::measured::{DeclaredUnits, MeasuredField};
use femu_identify::weighted::FieldCovariance;
use femu_mech::loading::Side;
use femu_mesh::locate::PointLocator;
use std::path::Path;
use std::sync::Arc;

/// The measured field of an identification and where it came from.
#[derive(Debug, Clone)]
pub struct Measured {
    pub field: MeasuredField,
    pub source: String,
    /// Whether the reference parameters of the model are the truth (a simulated experiment).
    pub reference_known: bool,
    /// The full covariance of the field's components (model frame, mm²): the misfit is then
    /// weighted by it (weighted FEMU, `femu_identify::weighted`) instead of the per-point
    /// weights.
    pub covariance: Option<FieldCovariance>,
    /// How the misfit is weighted (`[measurement] weighting`).
    pub weighting: crate::schema::Weighting,
    /// The speckle's lateral shift under shear in the measurement model (model frame;
    /// `[measurement] speckle_*`).
    pub speckle_shift: Option<femu_identify::speckle::SpeckleShift>,
    /// The simulated experiment the field is the DIC of, when it was simulated here (its
    /// images are identified from by integrated DIC).
    pub simulated: Option<Arc<SimulatedImages>>,
}

impl Measured {
    /// A measured field from `source`, weighted per point, its parameters unknown.
    pub fn plain(field: MeasuredField, source: String) -> Measured {
        Measured {
            field,
            source,
            reference_known: false,
            covariance: None,
            weighting: crate::schema::Weighting::PerPoint,
            speckle_shift: None,
            simulated: None,
        }
    }
}

/// A measurement ready to fit.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Names its outputs (see [`Measurement::name`]).
    pub name: String,
    /// `contention, anterior 40 x 40 mm`.
    pub label: String,
    /// Index into the study's tests.
    pub test: usize,
    pub data: PreparedData,
    pub travel: Option<TravelTerm>,
}

/// The data of a prepared measurement.
#[derive(Debug, Clone)]
pub enum PreparedData {
    /// The virtual experiment at these points in the tissue (of `total` grid or window points)
    /// with noise `sigma` (mm).
    Virtual {
        points: Vec<[f64; 2]>,
        total: usize,
        sigma: f64,
    },
    /// A measured field in the model frame.
    Measured(Measured),
}

impl Prepared {
    /// Where the data come from, for the summary.
    pub fn source(&self) -> String {
        match &self.data {
            PreparedData::Virtual { .. } => "virtual experiment (femu synth)".into(),
            PreparedData::Measured(m) => m.source.clone(),
        }
    }
}

/// The points of a probe window in the tissue of `built` (on the side of `w`, its width and
/// depth, a grid `spacing_mm` apart centred in it), and the number of grid points.
pub fn window_points(built: &StudyModel, w: &WindowSpec) -> Result<(Vec<[f64; 2]>, usize)> {
    let side = Side::parse(&w.side).map_err(|e| crate::input!("window side: {e}"))?;
    // The probe's image is only used for its frame: 10 px/mm keeps it within its limits.
    let probe = femu_ultrasound::probe::probe_on_skin(
        &built.model.mesh,
        &built.skin,
        side.direction(),
        w.width_mm,
        w.depth_mm,
        10.0f64.min(4000.0 / w.width_mm.max(w.depth_mm)).max(1.0),
    )
    .with_context(|| format!("placing the {} window", w.label()))?;
    let (nl, nd) = (
        ((w.width_mm / w.spacing_mm).floor() as usize).max(1),
        ((w.depth_mm / w.spacing_mm).floor() as usize).max(1),
    );
    let locator = PointLocator::new(&built.model.mesh);
    let mut points = Vec::new();
    for j in 0..nd {
        for i in 0..nl {
            let l = -0.5 * w.width_mm + (i as f64 + 0.5) * w.width_mm / nl as f64;
            let d = (j as f64 + 0.5) * w.depth_mm / nd as f64;
            let x = probe.probe_to_model([l, d]);
            if locator.locate(x).is_some() {
                points.push(x);
            }
        }
    }
    Ok((points, nl * nd))
}

/// The points of a virtual measurement on `built` (the study's `grid`, or its window) in the
/// tissue, and how many the grid or window has.
pub fn virtual_points(
    grid: &GridSpec,
    built: &StudyModel,
    m: &Measurement,
) -> Result<(Vec<[f64; 2]>, usize)> {
    match &m.region {
        Region::Grid => {
            let (lo, hi) = built.model.mesh.bounding_box();
            let grid = grid.points(lo, hi);
            Ok((campaign::points_in_tissue(&built.model, &grid), grid.len()))
        }
        Region::Window(w) => window_points(built, w),
    }
}

/// What the measurement step reads of a study: its measurements and tests, the `[grid]` of a
/// virtual one, and for simulated images the model, `[probe]` and `[ultrasound]`.
#[derive(Debug, Clone, Copy)]
pub struct MeasureInputs<'a> {
    pub measurements: &'a [Measurement],
    pub tests: &'a [TestSpec],
    /// `[grid]`: the points of a virtual measurement without a window.
    pub grid: &'a GridSpec,
    /// Whether the measurements were written as a `[[measurement]]` list (a folder each).
    pub measurement_list: bool,
    /// The model the images of an ultrasound measurement are rendered from.
    pub model: &'a ModelSpec,
    pub probe: &'a ProbeSection,
    pub ultrasound: &'a UltrasoundSection,
}

impl<'a> MeasureInputs<'a> {
    /// The study's measurements, tests, grid, model, probe and ultrasound settings.
    pub fn of(study: &'a Study) -> MeasureInputs<'a> {
        MeasureInputs {
            measurements: &study.measurements,
            tests: &study.tests,
            grid: &study.measurement.grid,
            measurement_list: study.measurement_list(),
            model: &study.model,
            probe: &study.probe,
            ultrasound: &study.ultrasound,
        }
    }
}

/// The measurements of `inputs` made ready to fit on `built`; an ultrasound measurement's
/// images and DIC are simulated into `dir` (its sub-folder `NAME` for a list of measurements).
pub fn prepare(
    inputs: &MeasureInputs,
    built: &StudyModel,
    dir: &Path,
    progress: &dyn Progress,
) -> Result<Vec<Prepared>> {
    inputs
        .measurements
        .iter()
        .map(|m| {
            let label = m.label(inputs.tests);
            let data = match &m.source {
                MeasurementSource::Virtual => {
                    let (points, total) = virtual_points(inputs.grid, built, m)
                        .with_context(|| format!("measurement {label}"))?;
                    if points.is_empty() {
                        bail!("measurement {label}: no point of its grid lies in the tissue");
                    }
                    PreparedData::Virtual {
                        points,
                        total,
                        sigma: m.sigma_mm,
                    }
                }
                MeasurementSource::File {
                    path,
                    frame,
                    covariance,
                    weighting,
                    speckle,
                } => PreparedData::Measured(read_measured(
                    path,
                    frame,
                    covariance.as_deref(),
                    *weighting,
                    speckle.as_ref(),
                )?),
                MeasurementSource::Frames(_) => bail!(
                    "measurement {label}: recorded frames are identified from the frames themselves by `femu run` (integrated DIC); to fit a measured field, correlate them with `femu dic F0 F1 ...` and give its field.csv with --measured"
                ),
                MeasurementSource::Ultrasound => {
                    let out = if inputs.measurement_list {
                        dir.join(&m.name)
                    } else {
                        dir.to_path_buf()
                    };
                    PreparedData::Measured(ultrasound_measurement(inputs, m, &out, progress)?)
                }
            };
            Ok(Prepared {
                name: m.name.clone(),
                label,
                test: m.test,
                data,
                travel: m.travel.map(|t| TravelTerm {
                    measured_mm: t.measured_mm,
                    sigma_mm: t.sigma_mm,
                }),
            })
        })
        .collect()
}

/// The study's single measured field and its speckle shift, when it has one: the
/// identification's one block that carries the term (the fit, its discretization check, its
/// figures and summary).
pub fn measured_speckle(
    prepared: &[Prepared],
) -> Option<(&MeasuredField, femu_identify::speckle::SpeckleShift)> {
    match prepared {
        [Prepared {
            data: PreparedData::Measured(m),
            ..
        }] => m.speckle_shift.map(|s| (&m.field, s)),
        _ => None,
    }
}

/// A measured-field file made ready to fit, whichever command reads it (`[measurement] file`
/// or `femu identify --measured`): read; its declared units (`# units: px` or `mm`, as `femu
/// dic` writes) checked against the study's `frame`; mapped to the model frame; the points that
/// weigh nothing (`w = 0`: not trusted by the DIC) left out, with their rows of the full
/// covariance `covariance` (`[measurement] covariance`, in the file's frame), so that a file
/// with such rows and the same file without them give the same fit and the same intervals.
pub fn read_measured(
    path: &Path,
    frame: &crate::schema::Frame,
    covariance: Option<&Path>,
    weighting: crate::schema::Weighting,
    speckle: Option<&crate::schema::Speckle>,
) -> Result<Measured> {
    let all = MeasuredField::read(path)?;
    let declared = all
        .declared_units()
        .map_err(|e| crate::input!("{}: {e}", path.display()))?;
    match declared {
        Some(DeclaredUnits::Px) if !frame.pixels => bail!(
            "{}: the file says its coordinates are pixels ('# units: px': no pixel size was known when it was written), and the study reads it in mm: give [measurement] units = \"px\" with pixel_size_mm (and origin_mm, x_axis, y_axis to place the image in the model)",
            path.display()
        ),
        Some(DeclaredUnits::Mm) if frame.pixels => bail!(
            "{}: the file says its coordinates are mm ('# units: mm'), and [measurement] units = \"px\" would scale them by pixel_size_mm again: remove units and pixel_size_mm (origin_mm and the axes still place it)",
            path.display()
        ),
        _ => {}
    }
    let (field, kept) = all.weighted_points();
    if field.points.is_empty() {
        bail!(
            "{}: every point has weight 0 (w = 0: none is trusted), nothing to fit",
            path.display()
        );
    }
    let covariance = match covariance {
        Some(c) => {
            let s = frame.scale;
            let t = [
                [s * frame.x_axis[0], s * frame.y_axis[0]],
                [s * frame.x_axis[1], s * frame.y_axis[1]],
            ];
            let full = read_covariance(c, path, all.points.len(), Some(t))?;
            let cov = if kept.len() == all.points.len() {
                full
            } else {
                full.sub(&kept)
            };
            // Checked here, where the file can be named, not first at the fit.
            femu_identify::weighted::Whitening::new(&cov).map_err(|e| {
                crate::input!(
                    "[measurement] covariance {}: {e} (of the {} points of {} that weigh something)",
                    c.display(),
                    kept.len(),
                    path.display()
                )
            })?;
            Some(cov)
        }
        None => None,
    };
    let left_out = all.points.len() - kept.len();
    let mut field = field.to_model_frame(frame.scale, frame.origin, frame.x_axis, frame.y_axis);
    if left_out > 0 {
        field.comments.push(format!(
            "{left_out} of {} points left out: weight 0 (not trusted)",
            all.points.len()
        ));
    }
    Ok(Measured {
        field,
        source: path.display().to_string(),
        reference_known: false,
        covariance,
        weighting,
        speckle_shift: speckle.map(|s| s.in_frame(frame)),
        simulated: None,
    })
}

/// `[measurement] covariance` read from `c` (mapped by `map` to the model frame when the field
/// is in another), its point count checked against the field `path`'s `points`.
pub(crate) fn read_covariance(
    c: &Path,
    path: &Path,
    points: usize,
    map: Option<[[f64; 2]; 2]>,
) -> Result<FieldCovariance> {
    let cov = FieldCovariance::read_mtx(c)?;
    let cov = match map {
        Some(t) => cov.mapped(t),
        None => cov,
    };
    if cov.points != points {
        bail!(
            "[measurement] covariance {}: {} points, the field {} has {points}",
            c.display(),
            cov.points,
            path.display(),
        );
    }
    Ok(cov)
}

/// The DIC field of simulated B-mode images of `m`'s test under its window (or `[probe]`),
/// written into `out` by `femu us-sim`'s step, with the experiment it came from.
fn ultrasound_measurement(
    inputs: &MeasureInputs,
    m: &Measurement,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Measured> {
    let mut probe = inputs.probe.clone();
    if let Region::Window(w) = &m.region {
        probe.side = w.side.clone();
        probe.width_mm = w.width_mm;
        probe.depth_mm = w.depth_mm;
    }
    let sim_inputs = SimInputs {
        model: inputs.model,
        test: &inputs.tests[m.test].loading,
        probe: &probe,
        ultrasound: inputs.ultrasound,
    };
    let simulated = super::ultrasound::sim(
        sim_inputs,
        &super::ultrasound::SimOptions::default(),
        out,
        progress,
    )?;
    Ok(Measured {
        field: simulated.measured.clone(),
        source: format!(
            "DIC of simulated B-mode images (femu us-sim, {})",
            out.join("measured.csv").display()
        ),
        reference_known: true,
        covariance: None,
        weighting: crate::schema::Weighting::PerPoint,
        speckle_shift: None,
        simulated: Some(Arc::new(simulated)),
    })
}
