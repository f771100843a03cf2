//! `[grid]`, `[noise]`, `[measurement]`: what is measured, where, and how well.

use super::lines::{resolve, KeyLines};
use super::raw::{GridEntry, MeasurementEntry, NoiseEntry};
use super::StudyError;
use std::path::{Path, PathBuf};

/// The seed's measurement noise: 1.5 px = 1.76e-2 mm (§3.1.3).
pub const SEED_SIGMA_MM: f64 = 1.76e-2;

/// The measurement of the study.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementSpec {
    /// The DIC grid of a virtual experiment (and of the identifiability).
    pub grid: GridSpec,
    /// Standard deviation of the measured displacement (mm).
    pub sigma_mm: f64,
    pub source: MeasurementSource,
    /// The actuator term: the travel of the force-controlled body.
    pub travel: Option<Travel>,
}

/// The measured field of the identification (`[measurement] source`).
#[derive(Debug, Clone, PartialEq)]
pub enum MeasurementSource {
    /// The virtual experiment (seed §2.4.1): the FE field of the reference parameters on the
    /// grid plus the study's noise.
    Virtual,
    /// A measured-field CSV (conventions.md) in its own frame, mapped to the model's, and
    /// optionally the full covariance of its components (a dense symmetric Matrix Market
    /// array in the file's units², as `femu dic` writes `field_covariance.mtx`).
    File {
        path: PathBuf,
        frame: Frame,
        covariance: Option<PathBuf>,
        weighting: Weighting,
        /// The speckle's lateral shift under shear in the measurement model (B-mode frames).
        speckle: Option<Speckle>,
    },
    /// The virtual experiment with images (`femu us-sim`): B-mode images of the unloaded and
    /// loaded thigh under `[probe]` simulated with `[ultrasound]`, correlated by the DIC; the
    /// identification fits the DIC field.
    Ultrasound,
    /// A user's recorded B-mode frames (the unloaded first) and the load of each, placed in
    /// the model by their frame keys or `[probe]`: identified by integrated DIC from the
    /// frames themselves ([`super::frames`]).
    Frames(Box<super::frames::FramesSpec>),
}

/// How the misfit of a measured file is weighted (`[measurement] weighting`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Weighting {
    /// Each point by its own weight (`1/sx²`, `1/sy²` or `w`), the default without a covariance.
    PerPoint,
    /// By the field's full covariance alone (`covariance`): for a covariance known to hold the
    /// field's whole error.
    Covariance,
    /// By the field's covariance (or, without one, its per-point variances) plus the error its
    /// residuals show beyond it, estimated from a first fit (`femu_identify::error_model`); the
    /// default with a covariance.
    Estimated,
}

/// The imaging of a measured file's B-mode frames (`[measurement] speckle_*`): the speckle's
/// lateral shift under shear (`femu_identify::speckle`), depth measured along the file's +y
/// from its y = 0 (the probe face: rows going down, as `femu dic` writes).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Speckle {
    pub frequency_mhz: f64,
    pub resolution_mm: f64,
    pub sound_speed_m_s: f64,
    /// The shift's scale fitted with the parameters (`speckle_shift = "fitted"`, the default),
    /// or held (`"fixed"`) at `scale` (`speckle_scale`, 1 by default: the closed form's).
    pub fitted: bool,
    pub scale: f64,
}

impl Speckle {
    /// The shift in the model frame of a file placed by `frame`.
    pub fn in_frame(&self, frame: &Frame) -> femu_identify::speckle::SpeckleShift {
        use femu_identify::speckle::{ShiftScale, SpeckleShift};
        SpeckleShift {
            frequency_mhz: self.frequency_mhz,
            resolution_mm: self.resolution_mm,
            sound_speed_m_s: self.sound_speed_m_s,
            face: frame.origin,
            lateral: frame.x_axis,
            axial: frame.y_axis,
            scale: if self.fitted {
                ShiftScale::Fitted
            } else {
                ShiftScale::Fixed(self.scale)
            },
        }
    }
}

/// The measured travel of the force-controlled plate or indenter (`None` for a virtual
/// experiment, which synthesizes it) and its standard deviation (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Travel {
    pub measured_mm: Option<f64>,
    pub sigma_mm: f64,
}

/// The map from a measured field's frame (image pixels or mm) to the model frame (mm):
/// `X = origin + s (x e_x + y e_y)`, `U = s (u_x e_x + u_y e_y)`; `e_x`, `e_y` orthonormal.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Frame {
    /// mm per unit of the file (the pixel size for a field in px; 1 for mm).
    pub scale: f64,
    /// The file's coordinates are image pixels (`units = "px"`), not mm.
    #[serde(default)]
    pub pixels: bool,
    pub origin: [f64; 2],
    pub x_axis: [f64; 2],
    pub y_axis: [f64; 2],
}

impl Frame {
    /// The model's own frame: mm, no offset, the model's axes.
    pub fn model() -> Frame {
        Frame {
            scale: 1.0,
            pixels: false,
            origin: [0.0; 2],
            x_axis: [1.0, 0.0],
            y_axis: [0.0, 1.0],
        }
    }
}

/// The measurement grid: `counts` points `spacing` apart from `origin` (mm); `None` fields are
/// fitted to the model's skin.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSpec {
    pub counts: [usize; 2],
    pub origin: Option<[f64; 2]>,
    pub spacing: Option<f64>,
}

impl Default for GridSpec {
    /// The seed's 64 x 64 points over the whole section.
    fn default() -> Self {
        GridSpec {
            counts: super::keys::default("grid", "counts"),
            origin: None,
            spacing: None,
        }
    }
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

/// Checks `[grid]` and `[noise]`: the grid and the default noise of every measurement.
pub(crate) fn parse_grid_noise(
    grid: Option<GridEntry>,
    noise: Option<NoiseEntry>,
    lines: &KeyLines,
) -> Result<(GridSpec, f64), StudyError> {
    let grid = match grid {
        None => GridSpec::default(),
        Some(g) => check_grid(g, lines)?,
    };
    let sigma_mm = match noise {
        None => super::keys::default("noise", "sigma_mm"),
        Some(n) => lines.positive("noise", 0, "sigma_mm", n.sigma_mm)?,
    };
    Ok((grid, sigma_mm))
}

/// Checks the source and the actuator term of the `index`-th `[measurement]` entry.
pub(crate) fn check_entry(
    m: &mut MeasurementEntry,
    index: usize,
    lines: &KeyLines,
    base: &Path,
) -> Result<(MeasurementSource, Option<Travel>), StudyError> {
    let travel = check_travel(m.travel_mm.take(), m.travel_sigma_mm.take(), index, lines)?;
    let source = check_source(m, index, lines, base)?;
    match (&source, travel) {
        (
            MeasurementSource::File { .. },
            Some(Travel {
                measured_mm: None, ..
            }),
        ) => {
            return Err(lines.err(
                "measurement",
                index,
                "travel_sigma_mm",
                "a measured field needs its measured travel_mm".into(),
            ))
        }
        (
            MeasurementSource::Virtual,
            Some(Travel {
                measured_mm: Some(_),
                ..
            }),
        ) => {
            return Err(lines.err(
                "measurement",
                index,
                "travel_mm",
                "the virtual experiment synthesizes the travel; give only travel_sigma_mm".into(),
            ))
        }
        (MeasurementSource::Frames(_), Some(_)) => {
            return Err(lines.err(
                "measurement",
                index,
                "travel_sigma_mm",
                "the actuator term applies to a measured field or the virtual experiment, not to recorded frames".into(),
            ))
        }
        _ => {}
    }
    Ok((source, travel))
}

/// The largest measurement grid (points).
pub const MAX_GRID_POINTS: usize = 4_000_000;

fn check_grid(g: GridEntry, lines: &KeyLines) -> Result<GridSpec, StudyError> {
    let counts: [usize; 2] = super::keys::or_default(g.counts, "grid", "counts");
    // 4e6 points: the projection and the Jacobian hold 2 rows per point and parameter, some
    // 1 GB for ten parameters (issue 28.4; the product saturates, a huge count cannot wrap).
    let points = counts[0].saturating_mul(counts[1]);
    if counts[0] < 2 || counts[1] < 2 || points > MAX_GRID_POINTS {
        return Err(lines.err(
            "grid",
            0,
            "counts",
            format!(
                "must be at least 2 x 2 and at most {MAX_GRID_POINTS} points, got {counts:?} ({:.1e} points)",
                points as f64
            ),
        ));
    }
    if let Some(s) = g.spacing_mm {
        lines.positive("grid", 0, "spacing_mm", s)?;
    }
    if let Some(o) = g.origin_mm {
        if !(o[0].is_finite() && o[1].is_finite()) {
            return Err(lines.err("grid", 0, "origin_mm", format!("must be finite, got {o:?}")));
        }
    }
    Ok(GridSpec {
        counts,
        origin: g.origin_mm,
        spacing: g.spacing_mm,
    })
}

fn check_travel(
    travel: Option<f64>,
    sigma: Option<f64>,
    index: usize,
    lines: &KeyLines,
) -> Result<Option<Travel>, StudyError> {
    match (travel, sigma) {
        (None, None) => Ok(None),
        (t, Some(sigma)) => {
            lines.positive("measurement", index, "travel_sigma_mm", sigma)?;
            if let Some(t) = t {
                if !t.is_finite() {
                    return Err(lines.err(
                        "measurement",
                        index,
                        "travel_mm",
                        "must be finite".into(),
                    ));
                }
            }
            Ok(Some(Travel {
                measured_mm: t,
                sigma_mm: sigma,
            }))
        }
        (Some(_), None) => Err(lines.err(
            "measurement",
            index,
            "travel_mm",
            "give travel_sigma_mm too".into(),
        )),
    }
}

/// Checks the source of `[measurement]` and, for a file, its frame.
fn check_source(
    m: &MeasurementEntry,
    index: usize,
    lines: &KeyLines,
    base: &Path,
) -> Result<MeasurementSource, StudyError> {
    let err = |key: &str, message: &str| lines.err("measurement", index, key, message.into());
    let source = super::keys::word(
        "measurement",
        "source",
        m.source.as_deref().unwrap_or(if m.file.is_some() {
            "file"
        } else {
            super::keys::default_word("measurement", "source")
        }),
    )
    .map_err(|e| err("source", &e))?;
    if source != "frames" {
        if let Some(key) = super::frames::given_frame_keys(m).first() {
            return Err(err(
                key,
                &format!("is a key of recorded frames: give source = \"frames\" (the source is \"{source}\")"),
            ));
        }
    }
    if source != "file" {
        if let Some(key) = speckle_keys(m).first() {
            return Err(err(
                key,
                &format!("is the imaging of a measured field's frames (source = \"file\"; the source is \"{source}\")"),
            ));
        }
    }
    if m.weighting.is_some() && source != "file" {
        return Err(err(
            "weighting",
            &format!(
                "weighs a measured file's misfit (source = \"file\"; the source is \"{source}\")"
            ),
        ));
    }
    match source {
        "frames" => Ok(MeasurementSource::Frames(Box::new(super::frames::parse(
            m, index, lines, base,
        )?))),
        "ultrasound" => {
            if m.file.is_some()
                || m.units.is_some()
                || m.origin_mm.is_some()
                || m.covariance.is_some()
            {
                return Err(err(
                    "source",
                    "the ultrasound experiment writes its own field in the model frame",
                ));
            }
            Ok(MeasurementSource::Ultrasound)
        }
        "virtual" => {
            check_virtual(m, index, lines)?;
            Ok(MeasurementSource::Virtual)
        }
        "file" => file_source(m, index, lines, base),
        other => Err(err(
            "source",
            &super::keys::unhandled("measurement", "source", other),
        )),
    }
}

/// Refuses a file's keys on a virtual measurement.
fn check_virtual(m: &MeasurementEntry, index: usize, lines: &KeyLines) -> Result<(), StudyError> {
    let err = |key: &str, message: &str| lines.err("measurement", index, key, message.into());
    if m.file.is_some() {
        return Err(err("file", "a virtual measurement reads no file"));
    }
    // A file's frame on a measurement without a file would be silently unused (and
    // `femu identify --measured` would read its file in the model frame).
    for (key, given) in [
        ("units", m.units.is_some()),
        ("pixel_size_mm", m.pixel_size_mm.is_some()),
        ("origin_mm", m.origin_mm.is_some()),
        ("x_axis", m.x_axis.is_some()),
        ("y_axis", m.y_axis.is_some()),
    ] {
        if given {
            return Err(err(
                key,
                "is the frame of a measured file, and this measurement is virtual: give file (femu identify --measured FILE replaces it) or remove the frame keys",
            ));
        }
    }
    if m.covariance.is_some() {
        return Err(err(
            "covariance",
            "a virtual measurement has the noise of [noise]",
        ));
    }
    Ok(())
}

/// A measured file (`source = "file"`): its path, frame, covariance and weighting.
fn file_source(
    m: &MeasurementEntry,
    index: usize,
    lines: &KeyLines,
    base: &Path,
) -> Result<MeasurementSource, StudyError> {
    let err = |key: &str, message: &str| lines.err("measurement", index, key, message.into());
    let file = m
        .file
        .as_deref()
        .ok_or_else(|| err("source", "source = \"file\" needs file"))?;
    let frame = file_frame(m, index, lines)?;
    let weighting = weighting(m, index, lines)?;
    let speckle = speckle(m, index, lines)?;
    Ok(MeasurementSource::File {
        path: resolve(base, file),
        frame,
        covariance: m.covariance.as_deref().map(|c| resolve(base, c)),
        weighting,
        speckle,
    })
}

/// The speckle keys given.
fn speckle_keys(m: &MeasurementEntry) -> Vec<&'static str> {
    [
        ("speckle_frequency_mhz", m.speckle_frequency_mhz.is_some()),
        ("speckle_resolution_mm", m.speckle_resolution_mm.is_some()),
        (
            "speckle_sound_speed_m_s",
            m.speckle_sound_speed_m_s.is_some(),
        ),
        ("speckle_shift", m.speckle_shift.is_some()),
        ("speckle_scale", m.speckle_scale.is_some()),
    ]
    .into_iter()
    .filter_map(|(k, given)| given.then_some(k))
    .collect()
}

/// The imaging of a measured file's frames: none without `speckle_frequency_mhz`, which needs
/// `speckle_resolution_mm` (and the other way round).
fn speckle(
    m: &MeasurementEntry,
    index: usize,
    lines: &KeyLines,
) -> Result<Option<Speckle>, StudyError> {
    let err = |key: &str, message: &str| lines.err("measurement", index, key, message.into());
    let (frequency, resolution) = match (m.speckle_frequency_mhz, m.speckle_resolution_mm) {
        (None, None) => {
            return match speckle_keys(m).first() {
                Some(key) => Err(err(
                    key,
                    "needs speckle_frequency_mhz and speckle_resolution_mm (the frames' centre frequency and lateral resolution)",
                )),
                None => Ok(None),
            }
        }
        (Some(_), None) => {
            return Err(err(
                "speckle_frequency_mhz",
                "needs speckle_resolution_mm too (the lateral resolution: FWHM of the point-spread function, mm)",
            ))
        }
        (None, Some(_)) => {
            return Err(err(
                "speckle_resolution_mm",
                "needs speckle_frequency_mhz too (the centre frequency of the echo, MHz)",
            ))
        }
        (Some(f), Some(r)) => (f, r),
    };
    let positive = |key: &str, v: f64| lines.positive("measurement", index, key, v);
    let fitted = match super::keys::word_or_default(
        "measurement",
        "speckle_shift",
        m.speckle_shift.as_deref(),
    )
    .map_err(|e| err("speckle_shift", &e))?
    {
        "fitted" => true,
        "fixed" => false,
        other => {
            return Err(err(
                "speckle_shift",
                &super::keys::unhandled("measurement", "speckle_shift", other),
            ))
        }
    };
    let scale = match (fitted, m.speckle_scale) {
        (true, Some(_)) => {
            return Err(err(
                "speckle_scale",
                "holds the scale with speckle_shift = \"fixed\" (the default fits it)",
            ))
        }
        (_, Some(k)) if !(k.is_finite() && k >= 0.0) => {
            return Err(err(
                "speckle_scale",
                &format!("must be finite and at least 0, got {k}"),
            ))
        }
        (_, k) => k.unwrap_or_else(|| super::keys::default("measurement", "speckle_scale")),
    };
    Ok(Some(Speckle {
        scale,
        frequency_mhz: positive("speckle_frequency_mhz", frequency)?,
        resolution_mm: positive("speckle_resolution_mm", resolution)?,
        sound_speed_m_s: positive(
            "speckle_sound_speed_m_s",
            m.speckle_sound_speed_m_s
                .unwrap_or_else(|| super::keys::default("measurement", "speckle_sound_speed_m_s")),
        )?,
        fitted,
    }))
}

/// The frame of a measured file: its units (mm, or px of `pixel_size_mm`), origin and axes in
/// the model.
fn file_frame(m: &MeasurementEntry, index: usize, lines: &KeyLines) -> Result<Frame, StudyError> {
    let err = |key: &str, message: &str| lines.err("measurement", index, key, message.into());
    let units = super::keys::word_or_default("measurement", "units", m.units.as_deref())
        .map_err(|e| err("units", &e))?;
    let scale = match units {
        "mm" => match m.pixel_size_mm {
            Some(_) => return Err(err("pixel_size_mm", "a field in mm has no pixel size")),
            None => 1.0,
        },
        "px" => lines.positive(
            "measurement",
            index,
            "pixel_size_mm",
            m.pixel_size_mm
                .ok_or_else(|| err("units", "units = \"px\" needs pixel_size_mm"))?,
        )?,
        other => {
            return Err(err(
                "units",
                &super::keys::unhandled("measurement", "units", other),
            ));
        }
    };
    let (x_axis, y_axis) = super::frames::image_axes(m, &|key, message| err(key, &message))?;
    let origin = m.origin_mm.unwrap_or([0.0, 0.0]);
    if !(origin[0].is_finite() && origin[1].is_finite()) {
        return Err(err("origin_mm", "must be finite"));
    }
    Ok(Frame {
        scale,
        pixels: units == "px",
        origin,
        x_axis,
        y_axis,
    })
}

/// How a measured file's misfit is weighed (`weighting`, by default estimated with a
/// covariance and per point without).
fn weighting(
    m: &MeasurementEntry,
    index: usize,
    lines: &KeyLines,
) -> Result<Weighting, StudyError> {
    let err = |key: &str, message: &str| lines.err("measurement", index, key, message.into());
    let weighting = m
        .weighting
        .as_deref()
        .map(|w| super::keys::word("measurement", "weighting", w))
        .transpose()
        .map_err(|e| err("weighting", &e))?;
    let weighting = match weighting {
        None if m.covariance.is_some() => Weighting::Estimated,
        None | Some("per-point") => Weighting::PerPoint,
        Some("estimated") => Weighting::Estimated,
        Some("covariance") if m.covariance.is_some() => Weighting::Covariance,
        Some("covariance") => {
            return Err(err(
                "weighting",
                "weighting = \"covariance\" needs covariance (the field's covariance file)",
            ))
        }
        Some(other) => {
            return Err(err(
                "weighting",
                &super::keys::unhandled("measurement", "weighting", other),
            ))
        }
    };
    if weighting == Weighting::PerPoint && m.covariance.is_some() {
        return Err(err(
            "weighting",
            "weighting = \"per-point\" leaves the covariance unused: remove covariance or choose covariance or estimated",
        ));
    }
    Ok(weighting)
}
