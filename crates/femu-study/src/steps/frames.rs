//! A user's recorded B-mode frames (`[measurement] source = "frames"`): the measurement step
//! reads them, places them in the model and gives each loaded frame its load; the identification
//! step identifies the study's free parameters by integrated DIC from the frames themselves
//! (`super::images::identify_images`, the engine of `source = "ultrasound"`), started from the
//! DIC → FEMU optimum of a DIC of the sequence (`femu_dic::sequence`, as `femu dic F0 F1 ...`
//! runs it): the grey levels alone have no capture range from starts 25–75 % off.
//!
//! The measurement step writes into its folder
//!
//! - `frames.json` — [`FramesRecord`]: the files and frames read, the crop to the DICOM's
//!   ultrasound region, the pixel size and where it came from, the frames' placement in the
//!   model, each frame's time, load and fraction of the test's force;
//! - `frame_KK.png` — each frame as read (8-bit), the unloaded one `frame_00.png`;
//! - `force_log.png` — the force log with the chosen frames marked (with `force_log`);
//! - `measured.csv`, `sequence.csv` — the DIC of the sequence (first frame to the last, model
//!   frame, mm) and its increments, the starting point of the identification.
//!
//! The identification step writes `dic/` (DIC → FEMU on `measured.csv`) and, in its own folder,
//! what `identify_images` writes (`parameters.csv`, residual maps, `summary.json`). With a
//! refined placement its intervals carry the pose term (`pose_sd`: the estimate's sensitivity
//! to the placement times the refinement's covariance, `femu_identify::idic::pose_term`); a
//! given placement is taken as exact.

use crate::bail;
use crate::error::{Context, Result};
use crate::model::StudyModel;
use crate::output::{create_dir, write_json};
use crate::progress::Progress;
use crate::schema::frames::{test_force, FramesSpec, ResolvedFrames};
use crate::schema::{Measurement, ProbeSection, TestSpec};
use crate::steps::images::{identify_images, ImageRouteOptions, PlacementKnown};
use crate::steps::parameters::IdentificationInputs;
use crate::steps::sequence::ImageSequence;
use femu_dic::GreyImage;
use femu_identify::idic::pose_term::PlacementUncertainty;
use femu_identify::idic::ImageFrame;
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_identify::weighted::FieldCovariance;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the measurement step read (`frames.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FramesRecord {
    pub frames: ResolvedFrames,
    /// The fraction of the test's force of each loaded frame.
    pub load_fractions: Vec<f64>,
    pub test: String,
    pub test_force_n_per_mm: f64,
    /// The frames' placement in the model, and where it came from (`origin_mm, x_axis,
    /// y_axis` or `[probe]`).
    pub placement: ImageFrame,
    pub placement_from: String,
    /// The DIC of the sequence (the identification's start), when it converged.
    pub dic: Option<SequenceDic>,
    pub notes: Vec<String>,
    /// The refinement of the placement from the unloaded frame (`pose = "refined"`; the whole
    /// fit in `pose.json`).
    #[serde(default)]
    pub pose: Option<PoseRefinement>,
}

/// The placement's refinement from the unloaded frame (`femu_ultrasound::pose`): the
/// correction from the given placement and its standard deviation, as a rigid motion of the
/// image about the middle of its top edge (the probe face's centre).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PoseRefinement {
    /// `t_x`, `t_y` (mm, along the image's columns and rows) and the turn (degrees).
    pub correction: [f64; 3],
    /// Their standard deviations (mm, mm, degrees), from the sandwich over outline blocks.
    pub sd: [f64; 3],
    /// The model's outlines that supported the pose.
    pub found: Vec<String>,
    /// The pivot of the rigid motion (pixel; the probe face's centre) and the covariance of a
    /// further move of the refined placement about it, along the refined placement's own axes
    /// (mm², mm·rad, rad²): the refinement's sandwich turned by the correction's angle. The
    /// identification's pose term moves the placement by it.
    #[serde(default)]
    pub pivot_px: Option<[f64; 2]>,
    #[serde(default)]
    pub covariance: Option<[[f64; 3]; 3]>,
}

impl PoseRefinement {
    /// The refinement in words, for the placement's origin.
    fn describe(&self) -> String {
        format!(
            "refined from the unloaded frame by ({:+.3}, {:+.3}) mm and {:+.3}° (sd {:.3} mm, {:.3} mm, {:.3}°; outlines {})",
            self.correction[0],
            self.correction[1],
            self.correction[2],
            self.sd[0],
            self.sd[1],
            self.sd[2],
            self.found.join(", ")
        )
    }

    /// A note when the outlines pin the pose only weakly along the skin or in its turn (sd
    /// above 1 mm or 1°).
    fn weakly_pinned(&self) -> Option<String> {
        (self.sd[0] > 1.0 || self.sd[2] > 1.0).then(|| format!(
            "the refined placement is pinned only weakly along the skin and in its turn (sd {:.2} mm and {:.2}°): the outlines in view ({}) are nearly parallel; a window that shows the bone or a septum across the beam pins it",
            self.sd[0],
            self.sd[2],
            self.found.join(", ")
        ))
    }
}

/// The DIC of the sequence: per increment, and the composed field.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SequenceDic {
    pub points: usize,
    pub trusted: usize,
    /// Whether the automatic DIC failed and the fixed-option chain gave the field.
    #[serde(default)]
    pub fallback: bool,
    /// Per increment: element size (px), regularization (px), iterations, trusted fraction.
    pub increments: Vec<(usize, Option<f64>, usize, f64)>,
    pub time_s: f64,
}

/// Reads the frames `r` names: each decoded (PNG/TIFF 8/16 bit, DICOM) and cropped to the
/// ultrasound region.
pub fn read_frames(r: &ResolvedFrames) -> Result<Vec<GreyImage>> {
    r.sources
        .iter()
        .enumerate()
        .map(|(k, (path, frame))| {
            let img = GreyImage::open(path, *frame)
                .with_context(|| format!("frame {k} ({}, frame {frame})", path.display()))?;
            Ok(match r.region {
                Some(reg) => crop(&img, reg)?,
                None => img,
            })
        })
        .collect()
}

fn crop(img: &GreyImage, r: femu_dic::cine::Region) -> Result<GreyImage> {
    let (w, h) = r.size();
    let mut data = Vec::with_capacity(w * h);
    for y in r.y0..=r.y1 {
        data.extend_from_slice(&img.data[y * img.width + r.x0..=y * img.width + r.x1]);
    }
    let mut out = GreyImage::new(w, h, data)?;
    out.pixel_size = img.pixel_size;
    Ok(out)
}

/// Where the frames lie in the model: the study's `origin_mm`, `x_axis`, `y_axis` with the
/// frames' pixel size, or the placement of `[probe]` `probe` (`femu_ultrasound::probe::probe_on_skin`
/// on the model's skin, the window the frames' own width and depth at their pixel size).
pub fn placement(
    probe: &ProbeSection,
    built: &StudyModel,
    spec: &FramesSpec,
    r: &ResolvedFrames,
) -> Result<(ImageFrame, String)> {
    let s = r.pixel_size_mm;
    match &spec.placement {
        Some(p) => Ok((
            ImageFrame::new(p.origin_mm, s, p.x_axis, p.y_axis)
                .map_err(|e| crate::input!("[measurement] frame keys: {e}"))?,
            "[measurement] origin_mm, x_axis, y_axis".into(),
        )),
        None => {
            let mut section = probe.clone();
            section.width_mm = r.width as f64 * s;
            section.depth_mm = r.height as f64 * s;
            section.px_per_mm = 1.0 / s;
            let probe = super::ultrasound::place_probe(&built.model.mesh, &built.skin, &section)
                .context("placing the frames by [probe]")?;
            Ok((
                super::sequence::image_frame(&probe),
                format!(
                    "[probe] side {} on the model's skin, {:.3} x {:.3} mm at {} mm/px",
                    section.side, section.width_mm, section.depth_mm, s
                ),
            ))
        }
    }
}

/// What the measurement step of recorded frames made, for the identification: its record
/// (`frames.json`), the frames as read, and the DIC of the sequence as `measured.csv` holds it.
#[derive(Debug, Clone)]
pub struct RecordedFrames {
    pub record: FramesRecord,
    /// The frames, the unloaded one first, decoded and cropped.
    pub frames: Vec<GreyImage>,
    /// The composed DIC field (model frame, mm) as written, and its file; `None` when the DIC
    /// of the sequence failed.
    pub measured: Option<(MeasuredField, PathBuf)>,
    /// The composed field's full covariance (model frame, mm², as `measured_covariance.mtx`
    /// holds it), when the field has at most [`femu_dic::output::MAX_COVARIANCE_POINTS`] points.
    pub covariance: Option<FieldCovariance>,
}

impl RecordedFrames {
    /// The image sequence: the frames, placed and loaded as the record says.
    pub fn sequence(&self) -> ImageSequence {
        let record = &self.record;
        let files: Vec<String> = record
            .frames
            .sources
            .iter()
            .map(|(p, k)| match k {
                0 => p.display().to_string(),
                k => format!("{} frame {k}", p.display()),
            })
            .collect();
        ImageSequence {
            frames: self.frames.clone(),
            load_fractions: record.load_fractions.clone(),
            frame: record.placement,
            source: format!(
                "{} recorded frames ({}), {} mm/px, loads {:?} N/mm",
                files.len(),
                files.join(", "),
                record.frames.pixel_size_mm,
                record.frames.loads_n_per_mm
            ),
        }
    }
}

/// The measurement step of recorded frames `spec` of the test `test` on `built`: reads and
/// places them (by `spec`'s keys or `[probe]` `probe`), gives each its load, writes the record
/// and figures, and correlates the sequence for the identification's start (a DIC that fails is
/// a note: the identification then starts from the Latin-hypercube starts).
pub fn measure(
    test: &TestSpec,
    probe: &ProbeSection,
    built: &StudyModel,
    spec: &FramesSpec,
    out: &Path,
    progress: &dyn Progress,
) -> Result<RecordedFrames> {
    create_dir(out)?;
    let resolved = spec
        .resolve()
        .map_err(|e| crate::input!("[measurement] {}: {}", e.key, e.message))?;
    let force = test_force(test).context("the frames' test has no force")?;
    let frames = read_frames(&resolved)?;
    let (mut placement, mut placement_from) = placement(probe, built, spec, &resolved)?;
    let mut notes = Vec::new();
    let pose = if spec.refine_pose {
        let (refined, record) = refine_placement(&frames[0], &placement, built, out)?;
        placement = refined;
        placement_from = format!("{placement_from}, {}", record.describe());
        notes.extend(record.weakly_pinned());
        Some(record)
    } else {
        None
    };
    if let Some(note) = pose.as_ref().and_then(PoseRefinement::weakly_pinned) {
        progress.warn(&note);
    }
    if let Some(log) = &resolved.force_log {
        let f0 = log.at_frames[0];
        let fmax = log.at_frames.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        if f0.abs() > 0.02 * fmax {
            notes.push(format!(
                "the force log gives the first frame {f0:.4} N/mm ({:.0} % of the largest): the model takes that frame as unloaded",
                100.0 * f0.abs() / fmax
            ));
        }
        force_log_figure(&out.join("force_log.png"), log, resolved.times_s.as_deref())?;
    }
    for (k, f) in frames.iter().enumerate() {
        let p = out.join(format!("frame_{k:02}.png"));
        f.save_png(&p)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    let load_fractions = resolved.load_fractions(force);
    progress.note(&format!(
        "recorded frames: {} of {} x {} px at {} mm/px ({}), loads {:?} N/mm ({} at {} N/mm), placed by {}",
        frames.len(),
        resolved.width,
        resolved.height,
        resolved.pixel_size_mm,
        resolved.pixel_size_from,
        resolved.loads_n_per_mm,
        test.loading.name(),
        force,
        placement_from
    ));
    let (dic, measured, covariance) = match sequence_dic(&frames, &placement, out, progress) {
        Ok((d, field, covariance)) => {
            (Some(d), Some((field, out.join("measured.csv"))), covariance)
        }
        Err(e) if e.is_interrupted() => return Err(e),
        Err(e) => {
            let note = format!(
                "the DIC of the sequence failed ({}): the identification starts from the Latin-hypercube starts alone, from which the grey levels may not capture the motion",
                e.chain()
            );
            progress.warn(&note);
            notes.push(note);
            (None, None, None)
        }
    };
    let record = FramesRecord {
        frames: resolved,
        load_fractions,
        test: test.loading.name(),
        test_force_n_per_mm: force,
        placement,
        placement_from,
        dic,
        notes,
        pose,
    };
    write_json(&out.join("frames.json"), &record)?;
    Ok(RecordedFrames {
        record,
        frames,
        measured,
        covariance,
    })
}

/// The placement refined from the unloaded frame `frame0` (`femu_ultrasound::pose`): the
/// model's skin, fascia and bone surface matched to the frame's bright lines, starting from
/// `given`. Writes the whole fit (`pose.json`) and the outlines on the frame before and after
/// (`pose_overlay.png`); a pose that no interface supports is an error naming the outlines.
fn refine_placement(
    frame0: &GreyImage,
    given: &ImageFrame,
    built: &StudyModel,
    out: &Path,
) -> Result<(ImageFrame, PoseRefinement)> {
    use femu_ultrasound::pose::{model_outlines, refine_pose, ImagePose, PoseOptions};
    let mesh = &built.model.mesh;
    let bone = super::ultrasound::bone_faces(mesh, &built.skin);
    let outlines = model_outlines(mesh, &built.model.region_names, &bone);
    let initial = ImagePose::new(given.origin_mm, given.x_axis, given.y_axis, given.mm_per_px)?;
    let fit = refine_pose(frame0, &initial, &outlines, &PoseOptions::default())
        .context("[measurement] pose = \"refined\": refining the frames' placement")?;
    write_json(&out.join("pose.json"), &fit)?;
    let to_px = |p: &ImagePose| -> Vec<[[f64; 2]; 2]> {
        outlines
            .iter()
            .flat_map(|o| o.segments.iter())
            .map(|s| [p.model_to_pixel(s[0]), p.model_to_pixel(s[1])])
            .collect()
    };
    let overlay = out.join("pose_overlay.png");
    femu_plot::overlay::outline_overlay_png(
        &overlay,
        &frame0.data,
        frame0.width,
        frame0.height,
        fit.pose.pixel_size_mm,
        &[
            femu_plot::overlay::OutlineSet {
                label: "given placement".into(),
                segments_px: to_px(&fit.initial),
                color: (230, 60, 40),
                dashed: true,
            },
            femu_plot::overlay::OutlineSet {
                label: "refined placement".into(),
                segments_px: to_px(&fit.pose),
                color: (40, 200, 255),
                dashed: false,
            },
        ],
        &femu_plot::overlay::OverlayOptions {
            title: "The model's outlines on the unloaded frame".into(),
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot write {}", overlay.display()))?;
    let p = fit.pose;
    let refined = ImageFrame::new(p.origin_mm, p.pixel_size_mm, p.x_axis, p.y_axis)
        .map_err(|e| crate::input!("the refined placement: {e}"))?;
    let record = PoseRefinement {
        correction: [
            fit.correction[0],
            fit.correction[1],
            fit.correction[2].to_degrees(),
        ],
        sd: fit.sd,
        pivot_px: Some(fit.pivot_px),
        covariance: Some(in_refined_axes(&fit.covariance, fit.correction[2])),
        found: fit
            .support
            .iter()
            .filter(|o| o.found)
            .map(|o| o.name.clone())
            .collect(),
    };
    Ok((refined, record))
}

/// The covariance `cov` of a correction `(t_x, t_y, α)` along a placement's axes, along the
/// axes of that placement turned by `angle` (rad): a move `(t_x, t_y)` along the old axes is
/// `(c t_x + s t_y, −s t_x + c t_y)` along the turned ones (`c, s` the angle's cosine and
/// sine), the turn unchanged; `J cov Jᵀ`.
fn in_refined_axes(cov: &[[f64; 3]; 3], angle: f64) -> [[f64; 3]; 3] {
    let (c, s) = (angle.cos(), angle.sin());
    let j = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]];
    let mut out = [[0.0; 3]; 3];
    for (a, row) in out.iter_mut().enumerate() {
        for (b, v) in row.iter_mut().enumerate() {
            *v = (0..3)
                .map(|k| (0..3).map(|l| j[a][k] * cov[k][l] * j[b][l]).sum::<f64>())
                .sum();
        }
    }
    out
}

/// The force log against time (the log's clock), the chosen frames marked.
fn force_log_figure(
    path: &Path,
    log: &crate::schema::frames::ForceLog,
    times: Option<&[f64]>,
) -> Result<()> {
    use femu_plot::{LinePlot, LineStyle, Series};
    let curve: Vec<(f64, f64)> = log
        .time_s
        .iter()
        .zip(&log.force_n_per_mm)
        .map(|(&t, &f)| (t, f))
        .collect();
    let marks: Vec<(f64, f64)> = times
        .unwrap_or(&[])
        .iter()
        .zip(&log.at_frames)
        .map(|(&t, &f)| (t + log.offset_s, f))
        .collect();
    femu_plot::line_plot_png(
        path,
        &[
            Series::new(
                &format!(
                    "force log {}",
                    log.path.file_name().unwrap_or_default().to_string_lossy()
                ),
                curve,
                LineStyle::Line,
            ),
            Series::new(
                "frames identified (unloaded first)",
                marks,
                LineStyle::Markers,
            ),
        ],
        &LinePlot {
            title: format!(
                "Force log and the chosen frames (offset {} s)",
                log.offset_s
            ),
            x_label: "time on the log's clock (s)".into(),
            y_label: "force (N/mm)".into(),
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot write {}", path.display()))
}

/// The DIC of the sequence (frame to frame, composed to the first: `femu dic F0 F1 ...` with
/// its defaults), written as `measured.csv` in the model frame and `sequence.csv`, and the
/// composed field's covariance as `measured_covariance.mtx` (up to
/// [`femu_dic::output::MAX_COVARIANCE_POINTS`] points, as `femu dic` writes it).
fn sequence_dic(
    frames: &[GreyImage],
    placement: &ImageFrame,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(SequenceDic, MeasuredField, Option<FieldCovariance>)> {
    use femu_dic::command::{CorrelationSpec, RoiSpec};
    let t0 = std::time::Instant::now();
    let spec = CorrelationSpec {
        roi: RoiSpec::Whole,
        options: femu_dic::DicOptions {
            acceleration_depth: femu_dic::anderson::DEFAULT_DEPTH,
            ..Default::default()
        },
        element: femu_dic::auto::Setting::Auto,
        regularization: femu_dic::auto::Setting::Auto,
        trust: femu_dic::quality::TrustCriteria::default(),
    };
    let bar = progress.task("DIC of the sequence", Some(frames.len() - 1));
    let seq = femu_dic::sequence::correlate_sequence(frames, &spec, None, &|_, _| bar.inc(1));
    drop(bar);
    progress.check()?;
    let seq = match seq {
        Ok(seq) => seq,
        Err(e) => {
            let why = format!("{e}");
            progress.warn(&format!(
                "the DIC of the sequence (automatic options) failed: {why}; correlating again with 16 px elements over the tissue both frames of each pair show, unconverged increments kept (a start only)"
            ));
            let field = plain_chain(frames)
                .with_context(|| format!("after the automatic DIC failed ({why})"))?;
            let (d, field) = finish_start(field, placement, out, Vec::new(), t0, progress)?;
            return Ok((d, field, None));
        }
    };
    let last = frames.len() - 1;
    let px = seq.field(last, &femu_dic::output::ModelFrame::default());
    // In pixels² (the default frame: 1 mm per px, image axes), mapped below as the field is.
    let covariance_px = (px.len() <= femu_dic::output::MAX_COVARIANCE_POINTS)
        .then(|| {
            seq.covariance(
                last,
                &seq.reaching(last),
                &femu_dic::output::ModelFrame::default(),
            )
        })
        .transpose()
        .context("the covariance of the sequence's composed field")?;
    let field = MeasuredField {
        points: px
            .iter()
            .map(|g| {
                let var = [g.s_mm[0] * g.s_mm[0], g.s_mm[1] * g.s_mm[1]];
                MeasuredPoint {
                    x: g.x_px,
                    u: g.u_px,
                    weight: var.map(|v| if v > 0.0 && v.is_finite() { g.w / v } else { 0.0 }),
                }
            })
            .collect(),
        comments: vec![format!(
            "femu {}: DIC of the recorded frames (frame to frame, composed to the first), first frame to the last",
            env!("CARGO_PKG_VERSION")
        )],
    };
    let mut increments = Vec::new();
    let mut csv =
        String::from("increment,element_px,regularization_px,iterations,trusted_fraction,time_s\n");
    for (k, inc) in seq.increments.iter().enumerate() {
        let res = &inc.measured.res;
        let trusted = inc
            .measured
            .trust
            .iter()
            .filter(|&&t| t == femu_dic::quality::Trust::Trusted)
            .count() as f64
            / inc.measured.trust.len().max(1) as f64;
        csv += &format!(
            "{},{},{},{},{:.4},{:.3}\n",
            k + 1,
            inc.choice.element_size_px,
            inc.choice
                .regularization_px
                .map_or(String::new(), |r| format!("{r}")),
            res.iterations,
            trusted,
            inc.time_s
        );
        increments.push((
            inc.choice.element_size_px,
            inc.choice.regularization_px,
            res.iterations,
            trusted,
        ));
    }
    femu_mesh::atomic::write(out.join("sequence.csv"), csv)
        .with_context(|| format!("cannot write {}", out.join("sequence.csv").display()))?;
    let (d, field) = finish_start(field, placement, out, increments, t0, progress)?;
    let covariance = match covariance_px {
        Some(values) => Some(write_covariance(
            FieldCovariance::new(px.len(), values)?,
            placement,
            out,
        )?),
        None => {
            progress.note(&format!(
                "the composed field has {} points: its full covariance is formed up to {}; DIC -> weighted FEMU weighs it by its points' variances and the error its residuals show",
                px.len(),
                femu_dic::output::MAX_COVARIANCE_POINTS
            ));
            None
        }
    };
    Ok((d, field, covariance))
}

/// The composed field's covariance `px2` (pixels², image axes) mapped to the model frame as the
/// field is (`u = s (u_x e_x + u_y e_y)`: `C = T C_px Tᵀ` per point pair), written as
/// `measured_covariance.mtx` beside `measured.csv` (which weighted FEMU reads with it), and
/// returned as the file holds it.
fn write_covariance(
    px2: FieldCovariance,
    placement: &ImageFrame,
    out: &Path,
) -> Result<FieldCovariance> {
    let (s, ex, ey) = (placement.mm_per_px, placement.x_axis, placement.y_axis);
    let model = px2.mapped([[s * ex[0], s * ey[0]], [s * ex[1], s * ey[1]]]);
    let path = out.join("measured_covariance.mtx");
    model
        .write_mtx(
            &path,
            &[
                format!(
                    "femu {}: covariance of measured.csv's components (ux, uy per point, in its order), mm^2, model frame",
                    env!("CARGO_PKG_VERSION")
                ),
                "the DIC increments' covariances summed along each point's path (femu_dic::sequence)".into(),
            ],
        )
        .with_context(|| format!("cannot write {}", path.display()))?;
    FieldCovariance::read_mtx(&path).with_context(|| format!("cannot read {}", path.display()))
}

/// The composed field in pixels `field` mapped to the model, written as `measured.csv`;
/// returns the DIC's account and the field as the file holds it.
fn finish_start(
    field: MeasuredField,
    placement: &ImageFrame,
    out: &Path,
    increments: Vec<(usize, Option<f64>, usize, f64)>,
    t0: std::time::Instant,
    progress: &dyn Progress,
) -> Result<(SequenceDic, MeasuredField)> {
    let model = field.to_model_frame(
        placement.mm_per_px,
        placement.origin_mm,
        placement.x_axis,
        placement.y_axis,
    );
    let (kept, _) = model.weighted_points();
    if kept.points.is_empty() {
        bail!("no point of the composed field is trusted");
    }
    let written = write_measured(&out.join("measured.csv"), &model)?;
    let d = SequenceDic {
        points: model.points.len(),
        trusted: kept.points.len(),
        fallback: increments.is_empty(),
        increments,
        time_s: t0.elapsed().as_secs_f64(),
    };
    progress.note(&format!(
        "DIC of the sequence: {} increments, {} of {} points trusted, {:.1} s -> {}",
        d.increments.len(),
        d.trusted,
        d.points,
        d.time_s,
        out.join("measured.csv").display()
    ));
    Ok((d, written))
}

/// The fallback of the sequence's DIC: each pair correlated with fixed options (16 px elements,
/// no regularization, global brightness, three pyramid levels, as the simulated experiment
/// correlates its frames) over the tissue both frames show (`femu_dic::sequence::tissue_mask`),
/// an increment kept whether or not it converged (the field only starts the integrated DIC,
/// which compares the frames themselves), the increments composed along the points of a 16-px
/// grid over the first; a point is weighted 0 in an element any increment flags.
fn plain_chain(frames: &[GreyImage]) -> Result<MeasuredField> {
    use femu_dic::sequence::tissue_mask;
    let opts = femu_dic::DicOptions {
        element_size: 16,
        regularization_length: None,
        brightness: femu_dic::Brightness::Global,
        pyramid_levels: Some(3),
        ..Default::default()
    };
    let (w, h) = (frames[0].width, frames[0].height);
    let mut dics = Vec::new();
    for k in 1..frames.len() {
        let inside: Vec<bool> = tissue_mask(&frames[k - 1])
            .into_iter()
            .zip(tissue_mask(&frames[k]))
            .map(|(a, b)| a && b)
            .collect();
        let roi = femu_dic::Roi::Mask {
            width: w,
            height: h,
            inside,
        };
        dics.push(
            femu_dic::correlate(&frames[k - 1], &frames[k], &roi, &opts)
                .with_context(|| format!("pair {} -> {k}", k - 1))?,
        );
    }
    let grid = femu_dic::output::grid(&dics[0], &femu_dic::output::ModelFrame::default(), 16.0)?;
    let points = grid
        .iter()
        .filter_map(|g| {
            let mut p = g.x_px;
            let mut wgt = g.w;
            for d in &dics {
                let (e, _, _) = d.mesh.locate(p[0], p[1])?;
                let inc = d.mesh.interpolate(&d.displacement, p[0], p[1])?;
                if d.flagged[e] {
                    wgt = 0.0;
                }
                p = [p[0] + inc[0], p[1] + inc[1]];
            }
            Some(MeasuredPoint {
                x: g.x_px,
                u: [p[0] - g.x_px[0], p[1] - g.x_px[1]],
                weight: [wgt, wgt],
            })
        })
        .collect();
    Ok(MeasuredField {
        points,
        comments: vec![format!(
            "femu {}: DIC of the recorded frames, fixed options (16 px, three levels), unconverged increments kept, composed to the first frame; a start of the integrated DIC",
            env!("CARGO_PKG_VERSION")
        )],
    })
}

/// Writes a model-frame field with its weights as `sx,sy,w` (conventions.md); returns the
/// field as the file holds it (its text parsed: the digits and weights written).
fn write_measured(path: &Path, f: &MeasuredField) -> Result<MeasuredField> {
    let mut s = String::new();
    for c in &f.comments {
        s += &format!("# {c}\n");
    }
    s += "# units: mm\nx,y,ux,uy,sx,sy,w\n";
    for p in &f.points {
        let sd = p.weight.map(|w| if w > 0.0 { 1.0 / w.sqrt() } else { 1.0 });
        let w = if p.weight.iter().any(|&w| w > 0.0) {
            1
        } else {
            0
        };
        s += &format!(
            "{:.12e},{:.12e},{:.12e},{:.12e},{:.6e},{:.6e},{w}\n",
            p.x[0], p.x[1], p.u[0], p.u[1], sd[0], sd[1]
        );
    }
    femu_mesh::atomic::write(path, &s)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(MeasuredField::parse(&s, &path.display().to_string())?)
}

/// The identification from recorded frames of the measurement `m` (what `inputs` reads of a
/// study): DIC → FEMU on the sequence's DIC (`dic/`, its optimum the start), then integrated DIC
/// from the frames (`out`).
pub fn identify_frames(
    inputs: &IdentificationInputs,
    m: &Measurement,
    grouped: bool,
    built: &StudyModel,
    recorded: &RecordedFrames,
    out: &Path,
    progress: &dyn Progress,
) -> Result<super::images::ImageIdentificationSummary> {
    use crate::steps::measure::{Measured, Prepared, PreparedData};
    let seq = recorded.sequence();
    let mut idic_spec = inputs.identification.clone();
    idic_spec.test = m.test;
    let mut starts = Vec::new();
    if let Some((measured, path)) = &recorded.measured {
        let (field, kept) = measured.weighted_points();
        let prepared = |data: Measured| Prepared {
            name: m.name.clone(),
            label: m.label(inputs.tests),
            test: m.test,
            data: PreparedData::Measured(data),
            travel: None,
        };
        let source = format!("DIC of the recorded frames ({})", path.display());
        let mut squared = idic_spec.clone();
        squared.loss = femu_identify::weighted::Loss::Squared;
        progress.note("DIC -> FEMU on the sequence's DIC (the start of the integrated DIC):");
        let a = super::identify::identify_on(
            &inputs.with(&squared),
            grouped,
            built,
            &[prepared(Measured::plain(field.clone(), source.clone()))],
            &out.join("dic"),
            progress,
        )?;
        starts.push(a.parameters.iter().map(|p| p.identified).collect());
        // The optimum is the start (as for simulated images): no Latin-hypercube starts.
        idic_spec.starts = 0;
        // DIC -> weighted FEMU beside it, for comparison (not a start of the integrated DIC):
        // the composed field weighted by its covariance (or, without one, its points'
        // variances) plus the error its residuals show, Huber's loss; as for simulated images.
        let weighted = prepared(Measured {
            field,
            source: format!(
                "{source}, weighted by its {}",
                if recorded.covariance.is_some() {
                    "covariance"
                } else {
                    "points' variances"
                }
            ),
            reference_known: false,
            // The rows of the points that weigh something, as the field keeps them.
            covariance: recorded.covariance.as_ref().map(|c| c.sub(&kept)),
            weighting: crate::schema::Weighting::Estimated,
            speckle_shift: None,
            simulated: None,
        });
        // The identification's own starts (the integrated DIC's were set to the optimum above).
        let mut huber = inputs.identification.clone();
        huber.test = m.test;
        huber.loss = femu_identify::weighted::Loss::Huber {
            k: femu_identify::weighted::HUBER_K,
        };
        progress.note("DIC -> FEMU on the sequence's DIC, weighted by its covariance, Huber's loss (for comparison):");
        super::identify::identify_on(
            &inputs.with(&huber),
            grouped,
            built,
            &[weighted],
            &out.join("dic-weighted"),
            progress,
        )?;
    }
    let mut route = ImageRouteOptions::for_identification(inputs.identification);
    route.placement = match &recorded.record.pose {
        Some(PoseRefinement {
            pivot_px: Some(pivot_px),
            covariance: Some(covariance),
            ..
        }) => PlacementKnown::Refined(PlacementUncertainty {
            pivot_px: *pivot_px,
            covariance: *covariance,
        }),
        _ => PlacementKnown::Given,
    };
    identify_images(
        &inputs.with(&idic_spec),
        grouped,
        &seq,
        false,
        starts,
        &route,
        out,
        progress,
    )
}
