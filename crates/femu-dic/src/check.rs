//! `femu dic-check FRAMES...` as a library function: the self-consistency of the DIC on a
//! sequence ([`crate::consistency`]), with the options `femu dic` would choose for each pair.
//!
//! For frames `F0 … Fn` it correlates every consecutive pair both ways (`Fk → Fk+1`,
//! `Fk+1 → Fk`: forward–backward) and every second frame directly (`Fk → Fk+2`: composition
//! against `Fk → Fk+1 → Fk+2`); with `unloaded`, the frames are repeated acquisitions of tissue
//! at rest and the forward fields themselves are the error (the seed's random error). A DICOM
//! file contributes all its frames.
//!
//! Files written into `out`: `pairs.csv` (one row per correlation: options chosen,
//! convergence, iterations, residual, trusted share, nodal sd), `checks.csv` (one row per check,
//! region and point set: mean and RMS of the difference and its predicted sd, px),
//! `points.csv` (one row per point of every check: its position in the reference frame, the
//! difference, its predicted sd and whether both fields trust it, px),
//! `<check>_<frames>.png` (the magnitude of the difference over the reference frame; with
//! figures), `summary.json` ([`CheckReport`]).

use crate::auto::Measured;
use crate::command::{write_json, CorrelationSpec};
use crate::consistency::{self, CheckPoint, CheckedField, RegionStats};
use crate::error::DicError;
use crate::figures::{self, Map};
use crate::image::GreyImage;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Everything `femu dic-check` needs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CheckJob {
    pub frames: Vec<PathBuf>,
    pub correlation: CorrelationSpec,
    /// The frames are repeated acquisitions of unloaded tissue.
    pub unloaded: bool,
    pub figures: bool,
    pub out: PathBuf,
}

/// One correlation of the check.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PairReport {
    pub reference: String,
    pub deformed: String,
    pub element_size_px: usize,
    pub regularization_px: Option<f64>,
    /// Correlations tried before this one was accepted (automatic choice).
    pub attempts: usize,
    pub converged: bool,
    pub iterations: usize,
    pub residual_rms: f64,
    pub trusted_fraction: f64,
    pub sd_median_px: [f64; 2],
    pub mean_u_px: [f64; 2],
    pub seconds: f64,
    /// Why it failed, when it did.
    pub error: Option<String>,
}

/// One instance of a check.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CheckSummary {
    /// `forward-backward`, `composition` or `repeated`.
    pub check: String,
    pub frames: Vec<String>,
    pub regions: Vec<RegionStats>,
}

/// What `femu dic-check` reports (`summary.json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct CheckReport {
    pub femu_version: &'static str,
    pub command: &'static str,
    pub job: CheckJob,
    pub pairs: Vec<PairReport>,
    pub checks: Vec<CheckSummary>,
    /// Every check type pooled over its instances.
    pub pooled: Vec<CheckSummary>,
    pub all_converged: bool,
    pub wall_time_s: f64,
}

/// A frame of the sequence: its image and label.
struct Frame {
    label: String,
    image: GreyImage,
}

fn load_frames(paths: &[PathBuf]) -> Result<Vec<Frame>, DicError> {
    let mut out = Vec::new();
    for p in paths {
        let stem = p
            .file_stem()
            .map_or_else(|| p.display().to_string(), |s| s.to_string_lossy().into());
        let n = if crate::dicom::is_dicom(p) {
            crate::dicom::dicom_info(p)?.frames
        } else {
            1
        };
        for k in 0..n {
            out.push(Frame {
                label: if n > 1 {
                    format!("{stem}#{k}")
                } else {
                    stem.clone()
                },
                image: GreyImage::open(p, k)?,
            });
        }
    }
    if out.len() < 2 {
        return Err(DicError::option(
            "frames",
            format!("{} frame(s) given, at least 2 are needed", out.len()),
        ));
    }
    Ok(out)
}

/// The file a frame's label comes from (`stem` or `stem#k`).
fn file_of(paths: &[PathBuf], label: &str) -> String {
    let stem = label.split('#').next().unwrap_or(label);
    paths
        .iter()
        .find(|p| p.file_stem().is_some_and(|s| s.to_string_lossy() == stem))
        .map_or_else(|| label.to_string(), |p| p.display().to_string())
}

/// What would fail every pair alike, refused before any correlation: frames of different
/// sizes (naming the first that differs and both sizes), a region of interest (`--roi`,
/// `--mask`) that does not fit the frames, an element size that does not fit the region.
fn check_inputs(
    paths: &[PathBuf],
    frames: &[Frame],
    spec: &CorrelationSpec,
) -> Result<(), DicError> {
    let first = &frames[0];
    let size = (first.image.width, first.image.height);
    if let Some(other) = frames
        .iter()
        .find(|f| (f.image.width, f.image.height) != size)
    {
        return Err(DicError::option(
            "frames",
            format!(
                "{} ({}) is {} x {} px, but {} ({}) is {} x {} px: the frames of a sequence must have one size (crop them alike)",
                file_of(paths, &other.label),
                other.label,
                other.image.width,
                other.image.height,
                file_of(paths, &first.label),
                first.label,
                size.0,
                size.1
            ),
        ));
    }
    let roi = spec.roi.resolve(size.0, size.1)?;
    let what = match &spec.roi {
        crate::command::RoiSpec::Rect(_) => "--roi",
        crate::command::RoiSpec::Mask(_) => "--mask",
        crate::command::RoiSpec::Whole => "the whole frame",
    };
    roi.bounding_box(size.0, size.1).map_err(|e| {
        DicError::Roi(format!(
            "{what}: {e} (the frames are {} x {} px)",
            size.0, size.1
        ))
    })?;
    if let crate::auto::Setting::Given(h) = spec.element {
        crate::mesh::DicMesh::new(&roi, size.0, size.1, h as usize)?;
    }
    Ok(())
}

type Field = Option<Measured>;

fn checked(m: &Measured) -> CheckedField<'_> {
    CheckedField {
        res: &m.res,
        cov: &m.cov,
        trust: &m.trust,
    }
}

/// Correlates `a → b` and records the pair. After a stop request nothing is correlated or
/// recorded (the pairs and checks finished are written, then the check stops).
fn pair(spec: &CorrelationSpec, a: &Frame, b: &Frame, pairs: &mut Vec<PairReport>) -> Field {
    let t = Instant::now();
    if femu_mesh::stop::requested() {
        return None;
    }
    let r = spec.measure(&a.image, &b.image);
    if matches!(r, Err(DicError::Interrupted(_))) {
        return None;
    }
    let mut rep = PairReport {
        reference: a.label.clone(),
        deformed: b.label.clone(),
        element_size_px: 0,
        regularization_px: None,
        attempts: 0,
        converged: false,
        iterations: 0,
        residual_rms: f64::NAN,
        trusted_fraction: 0.0,
        sd_median_px: [f64::NAN; 2],
        mean_u_px: [f64::NAN; 2],
        seconds: 0.0,
        error: None,
    };
    let out = match r {
        Ok((m, choice)) => {
            let q = crate::command::quality_summary(&m, &spec.trust);
            rep.element_size_px = choice.element_size_px;
            rep.regularization_px = choice.regularization_px;
            rep.attempts = choice.attempts.len();
            rep.converged = m.res.converged;
            rep.iterations = m.res.iterations;
            rep.residual_rms = m.res.residual_rms;
            rep.trusted_fraction = q.trusted_elements as f64 / m.trust.len().max(1) as f64;
            rep.sd_median_px = q.sd_median_px;
            rep.mean_u_px = crate::output::mean_std(&m.res.displacement).0;
            Some(m)
        }
        Err(e) => {
            rep.error = Some(e.to_string());
            None
        }
    };
    rep.seconds = t.elapsed().as_secs_f64();
    pairs.push(rep);
    out
}

/// Runs `femu dic-check`: writes the output folder and returns the report. Pairs that fail are
/// reported (and the checks that need them skipped), not fatal.
pub fn run_check(job: &CheckJob) -> Result<CheckReport, DicError> {
    let t0 = Instant::now();
    let mut inputs: Vec<&Path> = job.frames.iter().map(PathBuf::as_path).collect();
    inputs.extend(job.correlation.roi.mask_file());
    femu_mesh::folder::refuse_inputs_in(&job.out, &inputs)?;
    let frames = load_frames(&job.frames)?;
    check_inputs(&job.frames, &frames, &job.correlation)?;
    femu_mesh::atomic::create_dir_all(&job.out).map_err(|e| DicError::Write {
        path: job.out.clone(),
        message: e.to_string(),
    })?;
    let spec = &job.correlation;
    let n = frames.len();
    let mut pairs = Vec::new();
    let fwd: Vec<Field> = (0..n - 1)
        .map(|k| pair(spec, &frames[k], &frames[k + 1], &mut pairs))
        .collect();
    let mut checks: Vec<(CheckSummary, Vec<CheckPoint>, [f64; 2])> = Vec::new();
    // Records one check (points at the nodes of `on`) and draws its map over frame `idx[0]`.
    let mut record = |name: &str, idx: &[usize], pts: Vec<CheckPoint>, on: &Measured| {
        let mesh = &on.res.mesh;
        let yr = [
            mesh.y0 as f64 - 0.5,
            (mesh.y0 + mesh.ny * mesh.h) as f64 - 0.5,
        ];
        let summary = CheckSummary {
            check: name.into(),
            frames: idx.iter().map(|&i| frames[i].label.clone()).collect(),
            regions: consistency::region_stats(&pts, yr),
        };
        if job.figures {
            draw_check(&job.out, &frames[idx[0]].image, on, &summary, &pts)?;
        }
        checks.push((summary, pts, yr));
        Ok::<(), DicError>(())
    };
    if job.unloaded {
        for (k, f) in fwd.iter().enumerate() {
            if let Some(ab) = f {
                record(
                    "repeated",
                    &[k, k + 1],
                    consistency::repeated(&checked(ab)),
                    ab,
                )?;
            }
        }
    }
    for (k, f) in fwd.iter().enumerate() {
        let back = pair(spec, &frames[k + 1], &frames[k], &mut pairs);
        if let (Some(ab), Some(ba)) = (f, &back) {
            let pts = consistency::forward_backward(&checked(ab), &checked(ba));
            record("forward-backward", &[k, k + 1, k], pts, ab)?;
        }
    }
    for k in 0..n.saturating_sub(2) {
        let ac = pair(spec, &frames[k], &frames[k + 2], &mut pairs);
        if let (Some(ab), Some(bc), Some(ac)) = (&fwd[k], &fwd[k + 1], &ac) {
            let pts = consistency::composition(&checked(ab), &checked(bc), &checked(ac));
            record("composition", &[k, k + 1, k + 2], pts, ac)?;
        }
    }
    let mut pooled = Vec::new();
    for name in ["repeated", "forward-backward", "composition"] {
        let of: Vec<&(CheckSummary, Vec<CheckPoint>, [f64; 2])> =
            checks.iter().filter(|c| c.0.check == name).collect();
        if let Some(first) = of.first() {
            let all: Vec<CheckPoint> = of.iter().flat_map(|c| c.1.iter().copied()).collect();
            pooled.push(CheckSummary {
                check: name.into(),
                frames: vec![format!("{} instance(s)", of.len())],
                regions: consistency::region_stats(&all, first.2),
            });
        }
    }
    write_pairs_csv(&job.out.join("pairs.csv"), &pairs)?;
    write_checks_csv(
        &job.out.join("checks.csv"),
        checks.iter().map(|c| &c.0).chain(pooled.iter()),
    )?;
    write_points_csv(
        &job.out.join("points.csv"),
        checks.iter().map(|c| (&c.0, c.1.as_slice())),
    )?;
    if femu_mesh::stop::requested() {
        // Stopped: the pairs and checks finished are in pairs.csv and checks.csv.
        return Err(DicError::Interrupted(femu_mesh::stop::Interrupted));
    }
    let report = CheckReport {
        femu_version: env!("CARGO_PKG_VERSION"),
        command: "dic-check",
        job: job.clone(),
        all_converged: pairs.iter().all(|p| p.converged),
        pairs,
        checks: checks.into_iter().map(|c| c.0).collect(),
        pooled,
        wall_time_s: t0.elapsed().as_secs_f64(),
    };
    write_json(&job.out.join("summary.json"), &report)?;
    Ok(report)
}

fn werr(path: &Path) -> impl Fn(std::io::Error) -> DicError + '_ {
    move |e| DicError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn write_pairs_csv(path: &Path, pairs: &[PairReport]) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    writeln!(f, "reference,deformed,element_px,regularization_px,attempts,converged,iterations,residual_rms,trusted_fraction,sd_median_ux_px,sd_median_uy_px,mean_ux_px,mean_uy_px,seconds,error").map_err(&e)?;
    for p in pairs {
        writeln!(
            f,
            "{},{},{},{},{},{},{},{:.4},{:.4},{:.5},{:.5},{:.4},{:.4},{:.3},{}",
            p.reference,
            p.deformed,
            p.element_size_px,
            p.regularization_px.map_or("off".into(), |l| l.to_string()),
            p.attempts,
            p.converged,
            p.iterations,
            p.residual_rms,
            p.trusted_fraction,
            p.sd_median_px[0],
            p.sd_median_px[1],
            p.mean_u_px[0],
            p.mean_u_px[1],
            p.seconds,
            p.error.as_deref().unwrap_or("").replace([',', '\n'], ";")
        )
        .map_err(&e)?;
    }
    f.commit().map_err(&e)
}

fn write_checks_csv<'a>(
    path: &Path,
    checks: impl Iterator<Item = &'a CheckSummary>,
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    writeln!(f, "check,frames,region,points_set,points,mean_dx_px,mean_dy_px,rms_dx_px,rms_dy_px,predicted_sd_x_px,predicted_sd_y_px").map_err(&e)?;
    for c in checks {
        for r in &c.regions {
            writeln!(
                f,
                "{},{},{},{},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5}",
                c.check,
                c.frames.join(">"),
                r.region,
                if r.trusted_only { "trusted" } else { "all" },
                r.points,
                r.mean_px[0],
                r.mean_px[1],
                r.rms_px[0],
                r.rms_px[1],
                r.predicted_sd_px[0],
                r.predicted_sd_px[1]
            )
            .map_err(&e)?;
        }
    }
    f.commit().map_err(&e)
}

/// Every point of every check: where a check fails, not only how much (`points.csv`).
fn write_points_csv<'a>(
    path: &Path,
    checks: impl Iterator<Item = (&'a CheckSummary, &'a [CheckPoint])>,
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    writeln!(
        f,
        "check,frames,x_px,y_px,dx_px,dy_px,predicted_sd_x_px,predicted_sd_y_px,trusted"
    )
    .map_err(&e)?;
    for (c, pts) in checks {
        let frames = c.frames.join(">");
        for p in pts {
            writeln!(
                f,
                "{},{},{:.3},{:.3},{:.5},{:.5},{:.5},{:.5},{}",
                c.check,
                frames,
                p.x[0],
                p.x[1],
                p.diff[0],
                p.diff[1],
                p.sd[0],
                p.sd[1],
                u8::from(p.trusted)
            )
            .map_err(&e)?;
        }
    }
    f.commit().map_err(&e)
}

/// The magnitude of the difference over the first frame, interpolated from the nodes of `ab`
/// (the field at whose nodes the points of the check are).
fn draw_check(
    out: &Path,
    f: &GreyImage,
    ab: &Measured,
    summary: &CheckSummary,
    pts: &[CheckPoint],
) -> Result<(), DicError> {
    let mesh = &ab.res.mesh;
    let mut nodal = vec![[f64::NAN; 2]; mesh.n_nodes()];
    for p in pts {
        if let Some((e, xi, eta)) = mesh.locate(p.x[0], p.x[1]) {
            // The node of element e at (xi, eta) ∈ {0, 1}².
            let a = match (xi > 0.5, eta > 0.5) {
                (false, false) => 0,
                (true, false) => 1,
                (true, true) => 2,
                (false, true) => 3,
            };
            nodal[mesh.conn[e][a]] = p.diff;
        }
    }
    let (w, h) = (f.width, f.height);
    let mut values = vec![f64::NAN; w * h];
    for e in 0..mesh.n_elements() {
        let (px, py) = mesh.element_origin(e);
        for j in 0..mesh.h {
            for i in 0..mesh.h {
                let (x, y) = (px + i, py + j);
                if let Some(d) = mesh.interpolate(&nodal, x as f64, y as f64) {
                    values[y * w + x] = d[0].hypot(d[1]);
                }
            }
        }
    }
    let all = &summary.regions[0];
    let tr = &summary.regions[4];
    let name = format!("{}_{}.png", summary.check, summary.frames.join("_"));
    let map = Map {
        name: &name,
        values,
        title: format!(
            "{} {}: RMS (x, y) = ({:.2}, {:.2}) px, trusted ({:.2}, {:.2}) px",
            summary.check,
            summary.frames.join(" > "),
            all.rms_px[0],
            all.rms_px[1],
            tr.rms_px[0],
            tr.rms_px[1]
        ),
        label: "|difference| (px)".into(),
        diverging: false,
        range: None,
        categories: Vec::new(),
    };
    figures::draw(out, f, &map, figures::crop_of(ab, w, h))
}
