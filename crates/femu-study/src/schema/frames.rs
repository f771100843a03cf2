//! `[measurement] source = "frames"`: a user's recorded B-mode frames, identified by
//! integrated DIC.
//!
//! ```toml
//! [measurement]
//! source = "frames"
//! frames = ["f0.png", "f1.png", "f2.png"]  # PNG/TIFF (8/16 bit) or DICOM; the unloaded first
//! pixel_size_mm = 0.1                      # mm per pixel (a DICOM gives its own)
//! loads_n_per_mm = [0.05, 0.1]             # the force of each loaded frame
//! origin_mm = [-20.0, 60.0]                # model point of pixel (0, 0); [probe] if absent
//! x_axis = [1.0, 0.0]                      # model direction of the columns
//! y_axis = [0.0, -1.0]                     # ... of the rows (down into the thigh here)
//!
//! # or one multi-frame DICOM, its frames chosen by index or time, the force from a log:
//! cine = "loop.dcm"
//! frame_times_s = [0.0, 1.2, 2.4]          # or frame_indices = [0, 30, 60]
//! force_log = "force.csv"                  # time,force; '# units: s, N/mm' or force_log_units
//! force_log_offset_s = 0.35                # the log's clock minus the loop's
//! ```
//!
//! The text is checked by [`parse`] when the study is read; the files (their sizes, the
//! DICOM's frames and times, the force log's coverage of the frames) by
//! [`FramesSpec::resolve`] before anything runs (`Study::check_model_inputs`), which the
//! measurement step calls again to read them.

use super::lines::{resolve, KeyLines};
use super::raw::MeasurementEntry;
use super::StudyError;
use femu_dic::cine::Region;
use femu_mech::loading::MAX_FORCE_N_PER_MM;
use std::path::{Path, PathBuf};

/// Recorded frames and the load of each (`source = "frames"`).
#[derive(Debug, Clone, PartialEq)]
pub struct FramesSpec {
    pub images: FrameImages,
    /// mm per pixel; `None`: the DICOM's own (Sequence of Ultrasound Regions, Pixel Spacing).
    pub pixel_size_mm: Option<f64>,
    /// Where pixel (0, 0) and the image axes lie in the model; `None`: the `[probe]` placement
    /// (`femu_ultrasound::probe::probe_on_skin`).
    pub placement: Option<Placement>,
    pub loads: FrameLoads,
    /// The acquisition time of each listed file (s), for a force log; with a cine, the times
    /// that choose its frames.
    pub frame_times_s: Option<Vec<f64>>,
    /// Whether the placement is refined from the unloaded frame (`pose = "refined"`:
    /// `femu_ultrasound::pose`).
    pub refine_pose: bool,
}

/// Where the frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameImages {
    /// One file per frame (`frames = [...]`).
    Files(Vec<PathBuf>),
    /// Frames of one multi-frame DICOM (`cine`), by `frame_indices` (from 0) or, when `None`,
    /// by [`FramesSpec::frame_times_s`].
    Cine {
        path: PathBuf,
        indices: Option<Vec<usize>>,
    },
}

/// The image-to-model placement of the frames: `X = origin + s (x e_x + y e_y)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    pub origin_mm: [f64; 2],
    pub x_axis: [f64; 2],
    pub y_axis: [f64; 2],
}

/// The force on each loaded frame.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameLoads {
    /// `loads_n_per_mm`: one per loaded frame (N per mm of thickness).
    PerFrame(Vec<f64>),
    /// `force_log`: a CSV `time,force` interpolated at the frames' times plus `offset_s`.
    ForceLog {
        path: PathBuf,
        offset_s: f64,
        /// `force_log_units` (time, force); `None`: the log's `# units:` line.
        units: Option<LogUnits>,
    },
}

/// The units of a force log's columns: factors to s and N/mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogUnits {
    pub time_to_s: f64,
    pub force_to_n_per_mm: f64,
}

impl LogUnits {
    /// `("s" | "ms", "N/mm" | "mN/mm")`.
    pub fn parse(time: &str, force: &str) -> Result<LogUnits, String> {
        let time_to_s = match time.trim() {
            "s" => 1.0,
            "ms" => 1e-3,
            other => return Err(format!("unknown time unit '{other}' (s, ms)")),
        };
        let force_to_n_per_mm = match force.trim() {
            "N/mm" => 1.0,
            "mN/mm" => 1e-3,
            "N" | "mN" => {
                return Err(format!(
                    "a force in {} is not per mm of thickness: the model is a plane-strain section; divide by the contact's length along the thigh and give N/mm",
                    force.trim()
                ))
            }
            other => return Err(format!("unknown force unit '{other}' (N/mm, mN/mm)")),
        };
        Ok(LogUnits {
            time_to_s,
            force_to_n_per_mm,
        })
    }
}

/// The keys of recorded frames, for the other sources' refusals.
pub(crate) const FRAME_KEYS: [&str; 9] = [
    "frames",
    "cine",
    "frame_indices",
    "frame_times_s",
    "loads_n_per_mm",
    "force_log",
    "force_log_offset_s",
    "force_log_units",
    "pose",
];

/// The frame keys `m` gives.
pub(crate) fn given_frame_keys(m: &MeasurementEntry) -> Vec<&'static str> {
    let given = [
        m.frames.is_some(),
        m.cine.is_some(),
        m.frame_indices.is_some(),
        m.frame_times_s.is_some(),
        m.loads_n_per_mm.is_some(),
        m.force_log.is_some(),
        m.force_log_offset_s.is_some(),
        m.force_log_units.is_some(),
        m.pose.is_some(),
    ];
    FRAME_KEYS
        .iter()
        .zip(given)
        .filter(|(_, g)| *g)
        .map(|(k, _)| *k)
        .collect()
}

/// The most frames of a sequence (each is compared with every earlier one).
pub const MAX_FRAMES: usize = 64;

/// Checks the keys of `source = "frames"` in the `index`-th `[measurement]` (the text only;
/// the files are read by [`FramesSpec::resolve`]).
pub(crate) fn parse(
    m: &MeasurementEntry,
    index: usize,
    lines: &KeyLines,
    base: &Path,
) -> Result<FramesSpec, StudyError> {
    let at = At { lines, index };
    refuse_field_keys(m, at)?;
    if let Some(u) = m.units.as_deref() {
        if u != "px" {
            return Err(at.err(
                "units",
                format!("frames are images, in pixels: units = \"px\" or leave it out, got '{u}'"),
            ));
        }
    }
    let times = frame_times(m, at)?;
    let images = frame_images(m, times.as_deref(), at, base)?;
    let n_frames = match &images {
        FrameImages::Files(f) => f.len(),
        FrameImages::Cine {
            indices: Some(ix), ..
        } => ix.len(),
        FrameImages::Cine { indices: None, .. } => times.as_ref().map_or(0, |t| t.len()),
    };
    let pixel_size_mm = match m.pixel_size_mm {
        Some(s) => Some(lines.at_most(
            "measurement",
            index,
            "pixel_size_mm",
            s,
            super::geometry::MAX_LENGTH_MM,
        )?),
        None => None,
    };
    let placement = placement(m, index, lines)?;
    let loads = match (&m.loads_n_per_mm, &m.force_log) {
        (Some(_), Some(_)) => {
            return Err(at.err(
                "force_log",
                "give loads_n_per_mm or force_log, not both".into(),
            ))
        }
        (None, None) => {
            return Err(at.err(
                "source",
                "recorded frames need their loads: loads_n_per_mm = [...] (one per loaded frame) or force_log = \"force.csv\"".into(),
            ))
        }
        (Some(loads), None) => per_frame_loads(m, loads, n_frames, at)?,
        (None, Some(log)) => {
            if matches!(images, FrameImages::Files(_)) && times.is_none() {
                return Err(at.err(
                    "force_log",
                    "needs the frames' times: give frame_times_s (one per file), or read the frames from a cine whose Frame Time the log is interpolated at".into(),
                ));
            }
            force_log_loads(m, resolve(base, log), at)?
        }
    };
    let refine_pose = super::keys::word_or_default("measurement", "pose", m.pose.as_deref())
        .map_err(|e| at.err("pose", e))?
        == "refined";
    Ok(FramesSpec {
        images,
        pixel_size_mm,
        placement,
        loads,
        frame_times_s: times,
        refine_pose,
    })
}

/// Where in the study a `[measurement]` key is: its table's index and the lines of the keys.
#[derive(Clone, Copy)]
struct At<'a> {
    lines: &'a KeyLines,
    index: usize,
}

impl At<'_> {
    /// The error `message` at `key` of this `[measurement]`.
    fn err(self, key: &str, message: String) -> StudyError {
        self.lines.err("measurement", self.index, key, message)
    }

    /// Refuses a number of frames `n` out of `2..=MAX_FRAMES` (given by `key`).
    fn count_ok(self, key: &str, n: usize) -> Result<(), StudyError> {
        if !(2..=MAX_FRAMES).contains(&n) {
            return Err(self.err(
                key,
                format!("needs the unloaded frame and at least one loaded frame, at most {MAX_FRAMES} in all; got {n}"),
            ));
        }
        Ok(())
    }
}

/// Refuses the keys of a measured field, which recorded frames do not have.
fn refuse_field_keys(m: &MeasurementEntry, at: At) -> Result<(), StudyError> {
    for (key, given) in [
        ("file", m.file.is_some()),
        ("covariance", m.covariance.is_some()),
        ("window", m.window.is_some()),
        ("window_mm", m.window_mm.is_some()),
        ("spacing_mm", m.spacing_mm.is_some()),
        ("sigma_mm", m.sigma_mm.is_some()),
    ] {
        if given {
            return Err(at.err(
                key,
                "does not apply to recorded frames (source = \"frames\"): the frames are compared themselves, placed by origin_mm, x_axis, y_axis or [probe]".into(),
            ));
        }
    }
    Ok(())
}

/// `frame_times_s`, when given: finite and increasing.
fn frame_times(m: &MeasurementEntry, at: At) -> Result<Option<Vec<f64>>, StudyError> {
    let Some(t) = &m.frame_times_s else {
        return Ok(None);
    };
    if let Some((k, v)) = t.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(at.err(
            "frame_times_s",
            format!("time {} is {v}: must be finite", k + 1),
        ));
    }
    if let Some(k) = (1..t.len()).find(|&k| t[k] <= t[k - 1]) {
        return Err(at.err(
            "frame_times_s",
            format!(
                "must increase (the unloaded frame first): time {} ({} s) is not after time {} ({} s)",
                k + 1,
                t[k],
                k,
                t[k - 1]
            ),
        ));
    }
    Ok(Some(t.clone()))
}

/// The frames' images: one file per frame (`frames`), or a cine (`cine`) whose frames are
/// chosen by `frame_indices` or by the frame `times`.
fn frame_images(
    m: &MeasurementEntry,
    times: Option<&[f64]>,
    at: At,
    base: &Path,
) -> Result<FrameImages, StudyError> {
    match (&m.frames, &m.cine) {
        (Some(_), Some(_)) => Err(at.err(
            "cine",
            "give frames (one file per frame) or cine (one multi-frame DICOM), not both".into(),
        )),
        (None, None) => Err(at.err(
            "source",
            "source = \"frames\" needs frames = [\"f0.png\", ...] (the unloaded frame first) or cine = \"loop.dcm\"".into(),
        )),
        (Some(files), None) => {
            if m.frame_indices.is_some() {
                return Err(at.err(
                    "frame_indices",
                    "chooses frames of a cine; with frames = [...] every listed file is a frame"
                        .into(),
                ));
            }
            at.count_ok("frames", files.len())?;
            if let Some(t) = times {
                if t.len() != files.len() {
                    return Err(at.err(
                        "frame_times_s",
                        format!(
                            "{} times for the {} files of frames: one per file",
                            t.len(),
                            files.len()
                        ),
                    ));
                }
            }
            Ok(FrameImages::Files(
                files.iter().map(|f| resolve(base, f)).collect(),
            ))
        }
        (None, Some(cine)) => Ok(FrameImages::Cine {
            path: resolve(base, cine),
            indices: cine_indices(m, times, at)?,
        }),
    }
}

/// The cine's frames chosen by `frame_indices` (distinct), or `None` when the frame `times`
/// choose them.
fn cine_indices(
    m: &MeasurementEntry,
    times: Option<&[f64]>,
    at: At,
) -> Result<Option<Vec<usize>>, StudyError> {
    match (&m.frame_indices, times) {
        (Some(_), Some(_)) => Err(at.err(
            "frame_times_s",
            "give frame_indices or frame_times_s to choose the cine's frames, not both".into(),
        )),
        (None, None) => Err(at.err(
            "cine",
            "choose its frames with frame_indices = [...] or frame_times_s = [...] (the unloaded frame first)".into(),
        )),
        (Some(ix), None) => {
            at.count_ok("frame_indices", ix.len())?;
            if let Some(k) = (1..ix.len()).find(|&k| ix[..k].contains(&ix[k])) {
                return Err(at.err(
                    "frame_indices",
                    format!("frame {} is given twice", ix[k]),
                ));
            }
            Ok(Some(ix.clone()))
        }
        (None, Some(t)) => {
            at.count_ok("frame_times_s", t.len())?;
            Ok(None)
        }
    }
}

/// `loads_n_per_mm`: one positive force per loaded frame (of `n_frames`).
fn per_frame_loads(
    m: &MeasurementEntry,
    loads: &[f64],
    n_frames: usize,
    at: At,
) -> Result<FrameLoads, StudyError> {
    for key in ["force_log_offset_s", "force_log_units"] {
        if given_frame_keys(m).contains(&key) {
            return Err(at.err(key, "applies to force_log only".into()));
        }
    }
    if loads.len() + 1 != n_frames {
        return Err(at.err(
            "loads_n_per_mm",
            format!(
                "{} loads for {n_frames} frames: give one per loaded frame ({}; the first frame is the unloaded one)",
                loads.len(),
                n_frames - 1
            ),
        ));
    }
    if let Some((k, v)) = loads
        .iter()
        .enumerate()
        .find(|(_, v)| !(v.is_finite() && **v > 0.0 && **v <= MAX_FORCE_N_PER_MM))
    {
        return Err(at.err(
            "loads_n_per_mm",
            format!(
                "the load of frame {} is {v}: each loaded frame's force must be positive and at most {MAX_FORCE_N_PER_MM} N/mm (the unloaded frame is the first and has no entry)",
                k + 1
            ),
        ));
    }
    Ok(FrameLoads::PerFrame(loads.to_vec()))
}

/// `force_log` (at `path`) with its offset and units.
fn force_log_loads(m: &MeasurementEntry, path: PathBuf, at: At) -> Result<FrameLoads, StudyError> {
    let offset_s: f64 =
        super::keys::or_default(m.force_log_offset_s, "measurement", "force_log_offset_s");
    if !offset_s.is_finite() {
        return Err(at.err("force_log_offset_s", "must be finite".into()));
    }
    let units = match &m.force_log_units {
        None => None,
        Some(u) => match u.as_slice() {
            [t, f] => Some(LogUnits::parse(t, f).map_err(|e| at.err("force_log_units", e))?),
            _ => {
                return Err(at.err(
                    "force_log_units",
                    format!(
                    "give the time's and the force's unit, e.g. [\"s\", \"N/mm\"]; got {} values",
                    u.len()
                ),
                ))
            }
        },
    };
    Ok(FrameLoads::ForceLog {
        path,
        offset_s,
        units,
    })
}

fn placement(
    m: &MeasurementEntry,
    index: usize,
    lines: &KeyLines,
) -> Result<Option<Placement>, StudyError> {
    let err = |key: &str, message: String| lines.err("measurement", index, key, message);
    let Some(origin_mm) = m.origin_mm else {
        for (key, given) in [
            ("x_axis", m.x_axis.is_some()),
            ("y_axis", m.y_axis.is_some()),
        ] {
            if given {
                return Err(err(
                    key,
                    "give origin_mm too (the model point of pixel (0, 0)), or leave the placement out for [probe]'s".into(),
                ));
            }
        }
        return Ok(None);
    };
    if !(origin_mm[0].is_finite() && origin_mm[1].is_finite()) {
        return Err(err("origin_mm", "must be finite".into()));
    }
    let (x_axis, y_axis) = image_axes(m, &err)?;
    Ok(Some(Placement {
        origin_mm,
        x_axis,
        y_axis,
    }))
}

/// The force (N/mm) of a test pushed by a force (`force_n_per_mm`): the scale of the frames'
/// loads. `None` for a test loaded otherwise (contention's pressure).
pub fn test_force(test: &super::TestSpec) -> Option<f64> {
    test.loading
        .keys()
        .into_iter()
        .find_map(|(k, v)| match (k, v) {
            ("force_n_per_mm", femu_mech::loading::KeyValue::Number(f)) => Some(f),
            _ => None,
        })
}

/// Checks what the frames need of their test and the model's coordinates.
pub(crate) fn check_with_test(
    f: &FramesSpec,
    test: &super::TestSpec,
    index: usize,
    lines: &KeyLines,
) -> Result<(), StudyError> {
    if test_force(test).is_none() {
        return Err(lines.err(
            "measurement",
            index,
            "source",
            format!(
                "recorded frames are loaded by a force (loads_n_per_mm, force_log): their test must be a compression or an indentation, not {}",
                test.loading.name()
            ),
        ));
    }
    if let Some(p) = &f.placement {
        for v in p.origin_mm {
            femu_mesh::mesh::check_coordinate(v)
                .map_err(|m| lines.err("measurement", index, "origin_mm", m))?;
        }
    }
    Ok(())
}

impl ResolvedFrames {
    /// The fraction of the test's force (`test_force`) of each loaded frame.
    pub fn load_fractions(&self, test_force_n_per_mm: f64) -> Vec<f64> {
        self.loads_n_per_mm
            .iter()
            .map(|l| l / test_force_n_per_mm)
            .collect()
    }
}

/// A frames key found wrong in its files: the key and the message.
#[derive(Debug, Clone, PartialEq)]
pub struct FramesError {
    pub key: &'static str,
    pub message: String,
}

fn ferr(key: &'static str, message: String) -> FramesError {
    FramesError { key, message }
}

/// What the files say: which frame of which file each frame is, the frames' size and pixel
/// size, their times and loads. Read from the headers (and the force log), no pixel decoded
/// but a PNG/TIFF frame's.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResolvedFrames {
    /// `(file, frame of the file)`, the unloaded frame first.
    pub sources: Vec<(PathBuf, usize)>,
    /// The frames' size (px), after the crop to the ultrasound region.
    pub width: usize,
    pub height: usize,
    /// The DICOM's ultrasound region the frames are cropped to.
    pub region: Option<Region>,
    pub pixel_size_mm: f64,
    /// Where the pixel size comes from (`pixel_size_mm`, `SequenceOfUltrasoundRegions`, ...).
    pub pixel_size_from: String,
    /// Each frame's time (s), when known.
    pub times_s: Option<Vec<f64>>,
    /// The force of each loaded frame (N/mm).
    pub loads_n_per_mm: Vec<f64>,
    /// The force log as read (s, N/mm), with the force it gives the unloaded frame.
    pub force_log: Option<ForceLog>,
}

/// A force log in s and N/mm, and the forces at the frames.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ForceLog {
    pub path: PathBuf,
    pub time_s: Vec<f64>,
    pub force_n_per_mm: Vec<f64>,
    pub offset_s: f64,
    /// The force the log gives every frame (the unloaded one first).
    pub at_frames: Vec<f64>,
}

impl FramesSpec {
    /// The files the frames read: the frames or the cine, and the force log.
    pub fn input_files(&self) -> Vec<&Path> {
        let mut files: Vec<&Path> = match &self.images {
            FrameImages::Files(f) => f.iter().map(|p| p.as_path()).collect(),
            FrameImages::Cine { path, .. } => vec![path.as_path()],
        };
        if let FrameLoads::ForceLog { path, .. } = &self.loads {
            files.push(path);
        }
        files
    }

    /// The files read and checked (see [`ResolvedFrames`]): every frame exists and is readable,
    /// all have one size, a cine holds the frames asked for (and their times when asked), the
    /// pixel size is known, the force log covers every frame's time.
    pub fn resolve(&self) -> Result<ResolvedFrames, FramesError> {
        let (sources, region, size, dicom_pixel, times) = match &self.images {
            FrameImages::Files(files) => self.resolve_files(files)?,
            FrameImages::Cine { path, indices } => self.resolve_cine(path, indices.as_deref())?,
        };
        let (pixel_size_mm, pixel_size_from) = match (self.pixel_size_mm, dicom_pixel) {
            (Some(s), _) => (s, "pixel_size_mm".to_string()),
            (None, Some((s, from))) => (s, from),
            (None, None) => {
                return Err(ferr(
                    "pixel_size_mm",
                    "the frames carry no pixel size (PNG/TIFF, or a DICOM without Sequence of Ultrasound Regions physical deltas or Pixel Spacing): give pixel_size_mm".into(),
                ))
            }
        };
        let (loads_n_per_mm, force_log) = match &self.loads {
            FrameLoads::PerFrame(l) => (l.clone(), None),
            FrameLoads::ForceLog {
                path,
                offset_s,
                units,
            } => {
                let t = times.as_ref().ok_or_else(|| {
                    ferr(
                        "force_log",
                        "needs the frames' times, which the frames do not give: give frame_times_s"
                            .into(),
                    )
                })?;
                let from = match (&self.images, &self.frame_times_s) {
                    (_, Some(_)) => "frame_times_s",
                    _ => "the cine's frame times",
                };
                let log = read_force_log(path, *units, *offset_s, t, from)?;
                (log.at_frames[1..].to_vec(), Some(log))
            }
        };
        if let Some(log) = &force_log {
            if let Some((k, f)) = loads_n_per_mm
                .iter()
                .enumerate()
                .find(|(_, f)| !(**f > 0.0))
            {
                return Err(ferr(
                    "force_log",
                    format!(
                        "{}: the force at frame {} (t = {} s on the log's clock) is {f} N/mm; every loaded frame needs a positive force (is force_log_offset_s right?)",
                        log.path.display(),
                        k + 1,
                        times.as_ref().map_or(f64::NAN, |t| t[k + 1] + log.offset_s)
                    ),
                ));
            }
        }
        Ok(ResolvedFrames {
            sources,
            width: size.0,
            height: size.1,
            region,
            pixel_size_mm,
            pixel_size_from,
            times_s: times,
            loads_n_per_mm,
            force_log,
        })
    }

    #[allow(clippy::type_complexity)]
    fn resolve_files(
        &self,
        files: &[PathBuf],
    ) -> Result<
        (
            Vec<(PathBuf, usize)>,
            Option<Region>,
            (usize, usize),
            Option<(f64, String)>,
            Option<Vec<f64>>,
        ),
        FramesError,
    > {
        let mut size = None;
        let mut pixel: Option<(f64, String)> = None;
        for (k, f) in files.iter().enumerate() {
            if !f.is_file() {
                return Err(ferr(
                    "frames",
                    format!(
                        "frame {k}: {} does not exist (relative names start from the study file's folder)",
                        f.display()
                    ),
                ));
            }
            let img = femu_dic::GreyImage::open(f, 0)
                .map_err(|e| ferr("frames", format!("frame {k}: {e}")))?;
            match size {
                None => size = Some((img.width, img.height, f.clone())),
                Some((w, h, ref first)) if (w, h) != (img.width, img.height) => {
                    return Err(ferr(
                        "frames",
                        format!(
                            "frame {k}, {}, is {} x {} px; frame 0, {}, is {w} x {h} px: every frame must have the size of the first",
                            f.display(),
                            img.width,
                            img.height,
                            first.display()
                        ),
                    ))
                }
                _ => {}
            }
            if let (None, Some(p)) = (&pixel, img.pixel_size) {
                pixel = Some((p.dx_mm, format!("{} of {}", p.source, f.display())));
            }
        }
        let (w, h, _) = size.expect("at least two frames");
        Ok((
            files.iter().map(|f| (f.clone(), 0)).collect(),
            None,
            (w, h),
            pixel,
            self.frame_times_s.clone(),
        ))
    }

    #[allow(clippy::type_complexity)]
    fn resolve_cine(
        &self,
        path: &Path,
        indices: Option<&[usize]>,
    ) -> Result<
        (
            Vec<(PathBuf, usize)>,
            Option<Region>,
            (usize, usize),
            Option<(f64, String)>,
            Option<Vec<f64>>,
        ),
        FramesError,
    > {
        if !path.is_file() {
            return Err(ferr(
                "cine",
                format!(
                    "{} does not exist (relative names start from the study file's folder)",
                    path.display()
                ),
            ));
        }
        if !femu_dic::dicom::is_dicom(path) {
            return Err(ferr(
                "cine",
                format!(
                    "{} is not a DICOM file (no .dcm extension, no DICM magic): a cine is one multi-frame DICOM; list single images with frames = [...]",
                    path.display()
                ),
            ));
        }
        let info = femu_dic::cine::cine_info(path).map_err(|e| ferr("cine", e.to_string()))?;
        let (chosen, times) = self.cine_frames(&info, path, indices)?;
        if matches!(self.loads, FrameLoads::ForceLog { .. }) && times.is_none() {
            return Err(ferr(
                "force_log",
                format!(
                    "{} gives no frame times (neither Frame Time (0018,1063) nor Frame Time Vector (0018,1065)) to interpolate the force log at: give loads_n_per_mm instead",
                    path.display()
                ),
            ));
        }
        let size = info
            .region
            .map_or((info.info.width, info.info.height), |r| r.size());
        let pixel = info
            .info
            .pixel_size
            .map(|p| (p.dx_mm, format!("{} of {}", p.source, path.display())));
        if self.pixel_size_mm.is_none() {
            square_pixels(&info.info, path)?;
        }
        Ok((
            chosen.iter().map(|&i| (path.to_path_buf(), i)).collect(),
            info.region,
            size,
            pixel,
            times,
        ))
    }

    /// The cine's frames to compare (`indices`, or the frames at the study's frame times) and
    /// their times when the cine gives them.
    fn cine_frames(
        &self,
        info: &femu_dic::cine::CineInfo,
        path: &Path,
        indices: Option<&[usize]>,
    ) -> Result<(Vec<usize>, Option<Vec<f64>>), FramesError> {
        let n = info.info.frames;
        match indices {
            Some(ix) => {
                if let Some(&bad) = ix.iter().find(|&&i| i >= n) {
                    return Err(ferr(
                        "frame_indices",
                        format!(
                            "frame {bad} asked for, but {} holds {n} frame(s) (indices from 0)",
                            path.display()
                        ),
                    ));
                }
                let times = info
                    .frame_times_s
                    .as_ref()
                    .map(|t| ix.iter().map(|&i| t[i]).collect());
                Ok((ix.to_vec(), times))
            }
            None => {
                let asked = self.frame_times_s.as_deref().unwrap_or(&[]);
                let t = info.frame_times_s.as_ref().ok_or_else(|| {
                    ferr(
                        "frame_times_s",
                        format!(
                            "{} gives no frame times (neither Frame Time (0018,1063) nor Frame Time Vector (0018,1065)): choose its frames with frame_indices",
                            path.display()
                        ),
                    )
                })?;
                let chosen = frames_at_times(t, asked)
                    .map_err(|m| ferr("frame_times_s", format!("{}: {m}", path.display())))?;
                let times = chosen.iter().map(|&i| t[i]).collect();
                Ok((chosen, Some(times)))
            }
        }
    }
}

/// Refuses a cine whose header gives pixels that are not square (integrated DIC needs square
/// pixels; `pixel_size_mm` in the study overrides the header).
fn square_pixels(info: &femu_dic::dicom::DicomInfo, path: &Path) -> Result<(), FramesError> {
    if let Some(p) = info.pixel_size {
        if (p.dx_mm - p.dy_mm).abs() > 1e-6 * p.dx_mm {
            return Err(ferr(
                    "pixel_size_mm",
                    format!(
                        "{} has pixels of {} x {} mm; integrated DIC needs square pixels: resample the loop, or give pixel_size_mm if the header is wrong",
                        path.display(),
                        p.dx_mm,
                        p.dy_mm
                    ),
                ));
        }
    }
    Ok(())
}

/// The frames of a loop with frame times `t` (s) nearest to the times `asked`: each must lie
/// within half a frame interval of its frame.
fn frames_at_times(t: &[f64], asked: &[f64]) -> Result<Vec<usize>, String> {
    let mut out = Vec::with_capacity(asked.len());
    for &a in asked {
        let (k, d) = t
            .iter()
            .enumerate()
            .map(|(k, &tk)| (k, (tk - a).abs()))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .ok_or("the loop holds no frame")?;
        let interval = match (k.checked_sub(1).map(|j| t[k] - t[j]), t.get(k + 1)) {
            (Some(b), Some(n)) => b.min(n - t[k]),
            (Some(b), None) => b,
            (None, Some(n)) => n - t[k],
            (None, None) => f64::INFINITY,
        };
        if d > 0.5 * interval + 1e-9 {
            return Err(format!(
                "time {a} s is not a frame's: the loop's frames run from {} to {} s, {:.4} s apart; the nearest is frame {k} at {} s",
                t[0],
                t[t.len() - 1],
                interval,
                t[k]
            ));
        }
        if out.contains(&k) {
            return Err(format!("time {a} s picks frame {k} again"));
        }
        out.push(k);
    }
    Ok(out)
}

/// The rows `(time, force, line)` of a force log's `text` (comments `#` and an optional header
/// row skipped; times increasing) and the units of its `# units: TIME, FORCE` line, if any
/// (`at` makes the error of a message).
#[allow(clippy::type_complexity)]
fn force_log_rows(
    text: &str,
    at: &dyn Fn(String) -> FramesError,
) -> Result<(Vec<(f64, f64, usize)>, Option<LogUnits>), FramesError> {
    let mut declared = None;
    let mut rows: Vec<(f64, f64, usize)> = Vec::new();
    let mut header_seen = false;
    for (k, raw) in text.lines().enumerate() {
        let line = raw.trim();
        let n = k + 1;
        if line.is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            if let Some(u) = c.trim().strip_prefix("units:") {
                let parts: Vec<&str> = u.split(',').collect();
                let [t, f] = parts.as_slice() else {
                    return Err(at(format!(
                        "line {n}: '# units:' needs the time's and the force's unit, e.g. '# units: s, N/mm'"
                    )));
                };
                declared = Some(LogUnits::parse(t, f).map_err(|e| at(format!("line {n}: {e}")))?);
            }
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let parsed: Vec<Option<f64>> = cells.iter().map(|c| c.parse::<f64>().ok()).collect();
        if rows.is_empty() && !header_seen && parsed.iter().any(|v| v.is_none()) {
            header_seen = true;
            continue;
        }
        let (Some(Some(t)), Some(Some(f)), 2) = (parsed.first(), parsed.get(1), cells.len()) else {
            return Err(at(format!(
                "line {n}: '{line}' is not two numbers 'time,force'"
            )));
        };
        if !(t.is_finite() && f.is_finite()) {
            return Err(at(format!("line {n}: {t}, {f} is not finite")));
        }
        if let Some(&(prev, _, _)) = rows.last() {
            if *t <= prev {
                return Err(at(format!(
                    "line {n}: time {t} is not after the previous {prev}: the log's times must increase"
                )));
            }
        }
        rows.push((*t, *f, n));
    }
    Ok((rows, declared))
}

/// Reads a force log (`time,force` rows; comments `#`; an optional header row; units from
/// `units` or a `# units: TIME, FORCE` line) and interpolates it linearly at `frame_times + offset`.
fn read_force_log(
    path: &Path,
    units: Option<LogUnits>,
    offset_s: f64,
    frame_times: &[f64],
    times_from: &str,
) -> Result<ForceLog, FramesError> {
    let at = |m: String| ferr("force_log", format!("{}: {m}", path.display()));
    if !path.is_file() {
        return Err(at(
            "does not exist (relative names start from the study file's folder)".into(),
        ));
    }
    let text = std::fs::read_to_string(path).map_err(|e| at(format!("cannot read it: {e}")))?;
    let (rows, declared) = force_log_rows(&text, &at)?;
    if rows.len() < 2 {
        return Err(at(format!("{} rows: needs at least two", rows.len())));
    }
    let u = match (units, declared) {
        (Some(u), _) => u,
        (None, Some(u)) => u,
        (None, None) => {
            return Err(at(
                "its units are not given: add a line '# units: s, N/mm' to the log, or force_log_units = [\"s\", \"N/mm\"] to the study".into(),
            ))
        }
    };
    let time_s: Vec<f64> = rows.iter().map(|r| r.0 * u.time_to_s).collect();
    let force: Vec<f64> = rows.iter().map(|r| r.1 * u.force_to_n_per_mm).collect();
    if let Some((f, r)) = force
        .iter()
        .zip(&rows)
        .find(|(f, _)| f.abs() > MAX_FORCE_N_PER_MM)
    {
        return Err(at(format!(
            "line {}: force {f} N/mm is beyond {MAX_FORCE_N_PER_MM} N/mm: a broken log, or its units are wrong",
            r.2
        )));
    }
    let (lo, hi) = (time_s[0], time_s[time_s.len() - 1]);
    let mut at_frames = Vec::with_capacity(frame_times.len());
    for (k, &tf) in frame_times.iter().enumerate() {
        let t = tf + offset_s;
        if !(t >= lo && t <= hi) {
            return Err(at(format!(
                "frame {k} at {tf} s ({times_from}) is {t} s on the log's clock (force_log_offset_s = {offset_s}), outside the log's {lo} to {hi} s: the log must cover every frame"
            )));
        }
        let j = time_s
            .partition_point(|&x| x <= t)
            .clamp(1, time_s.len() - 1);
        let (t0, t1) = (time_s[j - 1], time_s[j]);
        let w = (t - t0) / (t1 - t0);
        at_frames.push(force[j - 1] + w * (force[j] - force[j - 1]));
    }
    Ok(ForceLog {
        path: path.to_path_buf(),
        time_s,
        force_n_per_mm: force,
        offset_s,
        at_frames,
    })
}

/// The image axes of a `[measurement]` in the model (`x_axis`, `y_axis`, their declared
/// defaults when absent): unit vectors, perpendicular; `err` names the key at fault.
pub(crate) fn image_axes(
    m: &MeasurementEntry,
    err: &dyn Fn(&str, String) -> StudyError,
) -> Result<([f64; 2], [f64; 2]), StudyError> {
    let axis = |v: Option<[f64; 2]>, key: &str| -> Result<[f64; 2], StudyError> {
        let v = super::keys::or_default(v, "measurement", key);
        if !((v[0].hypot(v[1]) - 1.0).abs() < 1e-6) {
            return Err(err(key, format!("must be a unit vector, got {v:?}")));
        }
        Ok(v)
    };
    let x_axis = axis(m.x_axis, "x_axis")?;
    let y_axis = axis(m.y_axis, "y_axis")?;
    if (x_axis[0] * y_axis[0] + x_axis[1] * y_axis[1]).abs() > 1e-6 {
        return Err(err(
            "y_axis",
            format!("x_axis {x_axis:?} and y_axis {y_axis:?} must be perpendicular"),
        ));
    }
    Ok((x_axis, y_axis))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_chosen_by_time_within_half_an_interval() {
        let t: Vec<f64> = (0..10).map(|k| 0.1 * k as f64).collect();
        assert_eq!(
            frames_at_times(&t, &[0.0, 0.31, 0.9]).unwrap(),
            vec![0, 3, 9]
        );
        let e = frames_at_times(&t, &[0.0, 1.5]).unwrap_err();
        assert!(e.contains("not a frame's") && e.contains("frame 9"), "{e}");
        let e = frames_at_times(&t, &[0.0, 0.01]).unwrap_err();
        assert!(e.contains("again"), "{e}");
    }

    #[test]
    fn a_force_log_is_interpolated_and_must_cover_the_frames() {
        let dir = std::env::temp_dir().join(format!("femu-forcelog-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("force.csv");
        std::fs::write(
            &p,
            "# units: ms, mN/mm\ntime,force\n0,0\n1000,50\n2000,100\n",
        )
        .unwrap();
        let log = read_force_log(&p, None, 0.5, &[0.0, 1.0, 1.5], "frame_times_s").unwrap();
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-15);
        assert!(
            close(&log.at_frames, &[0.025, 0.075, 0.1]),
            "{:?}",
            log.at_frames
        );
        let e = read_force_log(&p, None, 0.6, &[0.0, 1.0, 1.5], "frame_times_s").unwrap_err();
        assert!(
            e.message.contains("outside the log") && e.message.contains("frame 2"),
            "{e:?}"
        );
        std::fs::write(&p, "time,force\n0,0\n1,0.1\n").unwrap();
        let e = read_force_log(&p, None, 0.0, &[0.0, 1.0], "frame_times_s").unwrap_err();
        assert!(e.message.contains("units are not given"), "{e:?}");
        let u = LogUnits::parse("s", "N/mm").unwrap();
        let log = read_force_log(&p, Some(u), 0.0, &[0.0, 1.0], "frame_times_s").unwrap();
        assert!(close(&log.at_frames, &[0.0, 0.1]), "{:?}", log.at_frames);
        std::fs::write(&p, "# units: s, N/mm\n0,0\n1,nan\n").unwrap();
        let e = read_force_log(&p, None, 0.0, &[0.0], "frame_times_s").unwrap_err();
        assert!(e.message.contains("line 3"), "{e:?}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
