//! DIC on a sequence of frames (a B-mode cine loop of tissue under an increasing load): each
//! frame correlated with the one before, warm-started by the previous increment, and the
//! increments composed along the material points of the first frame.
//!
//! A large motion (the skin moving tens of pixels between the unloaded and the last frame)
//! leaves the capture range of one correlation and decorrelates the speckle; consecutive frames
//! differ by a small increment. For a material point `p₀` of the first frame,
//! `p_k = p_{k−1} + d_k(p_{k−1})` and `u_{0→k}(p₀) = p_k − p₀`, with `d_k` the field measured
//! from frame `k − 1` to frame `k` (as incremental elastography does).
//!
//! **Covariance through the composition.** Each increment's field has the nodal covariance
//! `A⁻¹ M_σ A⁻¹` of its own pair of frames ([`crate::quality`]); the increments are independent
//! (each correlates a new pair), so the composed displacement's covariance at the points is the
//! sum over the increments of `N_k C_k N_kᵀ`, each carried by the shape functions at the point's
//! position in that increment's reference frame. A point is trusted (`w = 1`) only when every
//! increment trusts the element it crosses.
//!
//! **Where to correlate.** Without a region of interest, each pair is correlated over the tissue
//! its reference frame shows ([`tissue_mask`]: the bright, textured part of a B-mode frame; the
//! coupling gel, the dark band above the skin and acoustic shadows left out).

use crate::auto::{correlate_ladder, Choice, Measured};
use crate::error::DicError;
use crate::image::GreyImage;
use crate::mesh::Roi;
use crate::output::{GridPoint, ModelFrame};
use crate::quality::{self, Trust, TrustCriteria};
use crate::solver::{correlate_from, DicOptions, DicResult};
use crate::spec::{CorrelationSpec, RoiSpec};

/// Pyramid levels of a sequence's correlations when none are given: B-mode increments of a
/// compression move the tissue by 10–30 px, which three levels bring within the coarsest
/// level's capture range.
pub const SEQUENCE_LEVELS: usize = 3;

/// The lowest ZNCC an element of a sequence may keep and still be trusted, and the fraction of
/// its pair's median ZNCC below which it is not: consecutive B-mode frames of tissue under
/// load decorrelate as a whole (the speckle changes with the strain and with the depth-varying
/// point-spread function as the tissue moves through it: on frames of an independent simulator,
/// even the exact warp leaves a median ZNCC of 0.45 between the unloaded and the first loaded
/// frame), so "decorrelated" is judged against the pair's own level — `min(min_zncc, max(0.2,
/// 0.6 median))` — not against a fixed 0.5 alone.
const ZNCC_FLOOR: f64 = 0.2;
const ZNCC_RELATIVE: f64 = 0.6;

/// Half-width (px) of the box over which [`tissue_mask`] averages the brightness.
const MASK_RADIUS: usize = 6;

/// Fraction of the median brightness of the imaged area below which a pixel's neighbourhood
/// is not tissue (gel, shadow, the dark band above the skin).
const MASK_FRACTION: f64 = 0.35;

/// The tissue of a B-mode frame: pixels whose mean brightness over a `13 x 13` box is at least
/// [`MASK_FRACTION`] of the median over the imaged (non-black) area, 3 px from the border.
pub fn tissue_mask(img: &GreyImage) -> Vec<bool> {
    let (w, h) = (img.width, img.height);
    // Integral image of the brightness.
    let mut sum = vec![0.0f64; (w + 1) * (h + 1)];
    for j in 0..h {
        let mut row = 0.0;
        for i in 0..w {
            row += img.data[j * w + i];
            sum[(j + 1) * (w + 1) + i + 1] = sum[j * (w + 1) + i + 1] + row;
        }
    }
    let r = MASK_RADIUS;
    let mean: Vec<f64> = (0..w * h)
        .map(|k| {
            let (i, j) = (k % w, k / w);
            let (x0, x1) = (i.saturating_sub(r), (i + r + 1).min(w));
            let (y0, y1) = (j.saturating_sub(r), (j + r + 1).min(h));
            let s = sum[y1 * (w + 1) + x1] - sum[y0 * (w + 1) + x1] - sum[y1 * (w + 1) + x0]
                + sum[y0 * (w + 1) + x0];
            s / ((x1 - x0) * (y1 - y0)) as f64
        })
        .collect();
    let (lo, hi) = mean
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let floor = lo + 0.02 * (hi - lo);
    let mut imaged: Vec<f64> = mean.iter().copied().filter(|&v| v > floor).collect();
    if imaged.is_empty() {
        return vec![false; w * h];
    }
    let mid = imaged.len() / 2;
    let median = *imaged.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
    let threshold = floor.max(lo + MASK_FRACTION * (median - lo));
    (0..w * h)
        .map(|k| {
            let (i, j) = (k % w, k / w);
            i >= 3 && j >= 3 && i + 3 < w && j + 3 < h && mean[k] >= threshold
        })
        .collect()
}

/// One increment of a sequence: frame `k − 1` to frame `k`.
pub struct Increment {
    pub measured: Measured,
    /// The options' choice (the first increment's ladder; later ones reuse its element size
    /// and regularization, warm-started).
    pub choice: Choice,
    /// Whether the correlation started from the previous increment.
    pub warm_start: bool,
    /// The ZNCC below which an element of this pair is not trusted ([`ZNCC_RELATIVE`]).
    pub min_zncc: f64,
    pub time_s: f64,
}

/// A correlated sequence: its increments and the composed paths of the material points.
pub struct Sequence {
    pub increments: Vec<Increment>,
    /// Material points of the first frame (px): the centres of a grid over the first
    /// increment's mesh.
    pub points: Vec<[f64; 2]>,
    /// Each point's position in frames `0..=k` for as far as it stays in the meshes
    /// (`paths[i][k]`: frame `k`).
    pub paths: Vec<Vec<[f64; 2]>>,
    /// Whether every increment so far trusts the element each point crosses, per frame
    /// (`trusted[i][k − 1]` for frame `k`).
    pub trusted: Vec<Vec<bool>>,
}

/// The displacement of `res` at `p`, or at its nearest node outside the mesh (a guess only).
fn field_or_nearest(res: &DicResult, p: [f64; 2]) -> [f64; 2] {
    if let Some(u) = res.mesh.interpolate(&res.displacement, p[0], p[1]) {
        return u;
    }
    let mut best = (f64::INFINITY, [0.0; 2]);
    for (q, u) in res.mesh.nodes.iter().zip(&res.displacement) {
        let d = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
        if d < best.0 {
            best = (d, *u);
        }
    }
    best.1
}

/// The trust criteria of a pair of a sequence: the spec's, with the ZNCC threshold judged
/// against the pair's median ZNCC ([`ZNCC_RELATIVE`]).
fn pair_criteria(res: &DicResult, spec: &CorrelationSpec) -> TrustCriteria {
    let mut z: Vec<f64> = res.element_texture.iter().map(|t| t.zncc).collect();
    let mid = z.len() / 2;
    let median = if z.is_empty() {
        0.0
    } else {
        *z.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    };
    TrustCriteria {
        min_zncc: spec
            .trust
            .min_zncc
            .min((ZNCC_RELATIVE * median).max(ZNCC_FLOOR)),
        ..spec.trust
    }
}

/// `res` with its covariance and the trust of its pair.
fn measured(res: DicResult, spec: &CorrelationSpec) -> Result<Measured, DicError> {
    let cov = quality::covariance(&res)?;
    let trust = quality::element_trust(&res, &cov, &pair_criteria(&res, spec));
    Ok(Measured { res, cov, trust })
}

/// The regions to correlate the pair `f → g` over, in `f`, in the order tried: the spec's; or
/// the tissue `f` shows, then the tissue both frames show. (The ROI lies in the reference frame:
/// the first keeps the skin line that anchors a large motion where the deformed frame already
/// shows gel; the second leaves out what the deformed frame does not show, which helps when the
/// speckle near the skin decorrelates.)
fn pair_rois(spec: &CorrelationSpec, f: &GreyImage, g: &GreyImage) -> Result<Vec<Roi>, DicError> {
    match spec.roi {
        RoiSpec::Whole => {
            let reference = tissue_mask(f);
            if !reference.iter().any(|&v| v) {
                return Err(DicError::Roi(
                    "no tissue in the frame (dark or uniform): give --roi or --mask".into(),
                ));
            }
            let both: Vec<bool> = reference
                .iter()
                .zip(tissue_mask(g))
                .map(|(a, b)| *a && b)
                .collect();
            let mask = |inside| Roi::Mask {
                width: f.width,
                height: f.height,
                inside,
            };
            let mut rois = vec![mask(reference)];
            if both.iter().any(|&v| v) {
                rois.push(mask(both));
            }
            Ok(rois)
        }
        _ => Ok(vec![spec.roi.resolve(f.width, f.height)?]),
    }
}

/// A pair of frames correlated without a previous increment to start from: the automatic
/// ladder over the first region of `rois` on which it succeeds, its rungs judged with the
/// lowest ZNCC threshold ([`ZNCC_FLOOR`]), the trust of the result then decided by the pair's
/// own criteria ([`pair_criteria`]).
fn correlate_first(
    f: &GreyImage,
    g: &GreyImage,
    rois: &[Roi],
    spec: &CorrelationSpec,
) -> Result<(Measured, Choice), DicError> {
    let floor = TrustCriteria {
        min_zncc: spec.trust.min_zncc.min(ZNCC_FLOOR),
        ..spec.trust
    };
    let mut result = Err(DicError::Roi("no region".into()));
    for roi in rois {
        result = correlate_ladder(
            f,
            g,
            roi,
            &spec.options,
            spec.element,
            spec.regularization,
            &floor,
            false,
        );
        if result.is_ok() {
            break;
        }
    }
    let (m, c) = result?;
    Ok((measured(m.res, spec)?, c))
}

/// One pair of B-mode frames correlated as a sequence's first increment is: over the tissue
/// the reference frame shows ([`tissue_mask`], unless `spec` gives a region), with
/// [`SEQUENCE_LEVELS`] pyramid levels unless `spec` gives them, and the ZNCC trust judged
/// against the pair's own median ([`ZNCC_RELATIVE`]). `femu dic` falls back to it when a pair
/// does not correlate over the whole image: B-mode frames under a compression decorrelate as a
/// whole and move by more than two pyramid levels can follow. Returns the field and the
/// choice, and the ZNCC threshold the trust used.
pub fn correlate_bmode_pair(
    f: &GreyImage,
    g: &GreyImage,
    spec: &CorrelationSpec,
) -> Result<(Measured, Choice, f64), DicError> {
    let mut spec = spec.clone();
    if spec.options.pyramid_levels.is_none() {
        spec.options.pyramid_levels = Some(SEQUENCE_LEVELS);
    }
    let rois = pair_rois(&spec, f, g)?;
    let (m, c) = correlate_first(f, g, &rois, &spec)?;
    if !m.res.converged {
        return Err(DicError::option(
            "convergence",
            format!(
                "not converged in {} iterations (last increment {:.2e} px)",
                m.res.iterations, m.res.last_increment_px
            ),
        ));
    }
    let min_zncc = pair_criteria(&m.res, &spec).min_zncc;
    Ok((m, c, min_zncc))
}

/// Correlates `frames[k − 1] → frames[k]` for every `k` and composes the increments along the
/// material points of `frames[0]` on a grid `grid_step_px` apart (default: the element size).
/// `on_increment(k, n)` is called after each increment (progress). An increment that does not
/// converge, or in which no element is trusted, is an error naming its pair.
pub fn correlate_sequence(
    frames: &[GreyImage],
    spec: &CorrelationSpec,
    grid_step_px: Option<f64>,
    on_increment: &dyn Fn(usize, usize),
) -> Result<Sequence, DicError> {
    if frames.len() < 2 {
        return Err(DicError::option(
            "frames",
            format!("a sequence needs at least 2 frames, got {}", frames.len()),
        ));
    }
    let (w, h) = (frames[0].width, frames[0].height);
    if let Some((k, f)) = frames
        .iter()
        .enumerate()
        .find(|(_, f)| (f.width, f.height) != (w, h))
    {
        return Err(DicError::option(
            "frames",
            format!(
                "frame {k} is {} x {} px, frame 0 is {w} x {h} px",
                f.width, f.height
            ),
        ));
    }
    let mut spec = spec.clone();
    if spec.options.pyramid_levels.is_none() {
        spec.options.pyramid_levels = Some(SEQUENCE_LEVELS);
    }
    let n = frames.len() - 1;
    let mut increments: Vec<Increment> = Vec::with_capacity(n);
    for k in 1..=n {
        let t0 = std::time::Instant::now();
        let (f, g) = (&frames[k - 1], &frames[k]);
        let rois = pair_rois(&spec, f, g)?;
        let roi = &rois[0];
        let pair = |e: DicError| DicError::option("frames", format!("pair {} -> {k}: {e}", k - 1));
        let warm = increments.last().and_then(|prev| {
            let opts = DicOptions {
                element_size: prev.choice.element_size_px,
                regularization_length: prev.choice.regularization_px,
                ..spec.options.clone()
            };
            let prev_res = &prev.measured.res;
            let guess = |p: [f64; 2]| field_or_nearest(prev_res, p);
            let res = correlate_from(f, g, roi, &opts, Some(&guess)).ok()?;
            if !res.converged {
                return None;
            }
            let m = measured(res, &spec).ok()?;
            let trusted = m.trust.iter().filter(|&&t| t == Trust::Trusted).count();
            (trusted as f64 >= crate::auto::MIN_TRUSTED * m.trust.len() as f64)
                .then(|| (m, prev.choice.clone()))
        });
        let (m, choice, warm_start) = match warm {
            Some((m, c)) => (m, c, true),
            None => {
                let (m, c) = correlate_first(f, g, &rois, &spec).map_err(pair)?;
                (m, c, false)
            }
        };
        if !m.res.converged {
            return Err(pair(DicError::option(
                "convergence",
                format!(
                    "not converged in {} iterations (last increment {:.2e} px)",
                    m.res.iterations, m.res.last_increment_px
                ),
            )));
        }
        if !m.trust.contains(&Trust::Trusted) {
            return Err(pair(DicError::option(
                "trust",
                "no element is trusted: the frames do not show the same tissue",
            )));
        }
        increments.push(Increment {
            min_zncc: pair_criteria(&m.res, &spec).min_zncc,
            measured: m,
            choice,
            warm_start,
            time_s: t0.elapsed().as_secs_f64(),
        });
        on_increment(k, n);
    }
    // Material points: a grid over the first increment's mesh.
    let first = &increments[0].measured.res;
    let step = grid_step_px.unwrap_or(first.mesh.h as f64);
    let grid = crate::output::grid(first, &ModelFrame::default(), step)?;
    let mut points = Vec::with_capacity(grid.len());
    let mut paths = Vec::with_capacity(grid.len());
    let mut trusted = Vec::with_capacity(grid.len());
    for g in &grid {
        let mut p = g.x_px;
        let mut path = vec![p];
        let mut ok = Vec::with_capacity(n);
        let mut all = true;
        for inc in &increments {
            let m = &inc.measured;
            let Some((e, _, _)) = m.res.mesh.locate(p[0], p[1]) else {
                break;
            };
            let d = m
                .res
                .mesh
                .interpolate(&m.res.displacement, p[0], p[1])
                .expect("located");
            all &= m.trust[e] == Trust::Trusted;
            ok.push(all);
            p = [p[0] + d[0], p[1] + d[1]];
            path.push(p);
        }
        points.push(g.x_px);
        paths.push(path);
        trusted.push(ok);
    }
    Ok(Sequence {
        increments,
        points,
        paths,
        trusted,
    })
}

impl Sequence {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.increments.len() + 1
    }

    /// The indices of the points whose path reaches frame `k`.
    pub fn reaching(&self, k: usize) -> Vec<usize> {
        (0..self.points.len())
            .filter(|&i| self.paths[i].len() > k)
            .collect()
    }

    /// The composed field from the first frame to frame `k ≥ 1` at the points that reach it,
    /// in `frame`: positions of the first frame, displacements `p_k − p₀`, standard deviations
    /// from the summed increments' covariances, `w` = 1 where every increment trusts the point.
    pub fn field(&self, k: usize, frame: &ModelFrame) -> Vec<GridPoint> {
        self.reaching(k)
            .into_iter()
            .map(|i| {
                let path = &self.paths[i];
                let mut var = [0.0; 2];
                for (inc, p) in self.increments[..k].iter().zip(path) {
                    let m = &inc.measured;
                    let sd = m.cov.point_sd(&m.res, p[0], p[1]).expect("on the path");
                    var[0] += sd[0] * sd[0];
                    var[1] += sd[1] * sd[1];
                }
                let (p0, pk) = (path[0], path[k]);
                let u = [pk[0] - p0[0], pk[1] - p0[1]];
                let d = frame.pixel_size_mm;
                GridPoint {
                    x_px: p0,
                    u_px: u,
                    x_mm: frame.point(p0),
                    u_mm: frame.displacement(u),
                    s_mm: [var[0].sqrt() * d[0], var[1].sqrt() * d[1]],
                    w: if self.trusted[i][k - 1] { 1.0 } else { 0.0 },
                }
            })
            .collect()
    }

    /// The covariance of the composed field to frame `k` at `points` (indices, as
    /// [`Sequence::reaching`] gives) in `frame` (mm², `[ux, uy]` per point, row-major): the sum
    /// over the increments of each one's `N C Nᵀ` at the points' positions in its reference
    /// frame (the module documentation).
    pub fn covariance(
        &self,
        k: usize,
        points: &[usize],
        frame: &ModelFrame,
    ) -> Result<Vec<f64>, DicError> {
        let paths: Vec<&[[f64; 2]]> = points.iter().map(|&i| &self.paths[i][..k]).collect();
        let results: Vec<&DicResult> = self.increments[..k]
            .iter()
            .map(|inc| &inc.measured.res)
            .collect();
        let mut c = composed_covariance(&results, &paths)?;
        let scale = frame.displacement([1.0, 1.0]);
        let m = 2 * points.len();
        for i in 0..m {
            for j in 0..m {
                c[i * m + j] *= scale[i % 2] * scale[j % 2];
            }
        }
        Ok(c)
    }
}

/// The covariance (px², `[ux, uy]` per point, row-major) of displacements composed from the
/// independent increments `increments`, point `i` at `paths[i][k]` in increment `k`'s
/// reference image: `Σ_k N_k A_k⁻¹ M_σ,k A_k⁻¹ N_kᵀ`.
pub fn composed_covariance(
    increments: &[&DicResult],
    paths: &[&[[f64; 2]]],
) -> Result<Vec<f64>, DicError> {
    let m = 2 * paths.len();
    let mut c = vec![0.0; m * m];
    for (k, d) in increments.iter().enumerate() {
        let rows: Vec<Vec<(usize, f64)>> = paths
            .iter()
            .flat_map(|path| {
                let p = path[k];
                let (e, xi, eta) = d.mesh.locate(p[0], p[1]).expect("located when composed");
                let n = crate::DicMesh::shape(xi, eta);
                let conn = d.mesh.conn[e];
                (0..2).map(move |comp| (0..4).map(|a| (2 * conn[a] + comp, n[a])).collect())
            })
            .collect();
        let sys = &d.system;
        let ck = quality::combined_covariance(
            &sys.pattern,
            &sys.a_values(),
            &quality::noise_matrix(d),
            &rows,
        )?;
        c.iter_mut().zip(&ck).for_each(|(a, b)| *a += b);
    }
    Ok(c)
}

/// Everything `femu dic` needs for a sequence.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SequenceJob {
    /// The frames, the unloaded one first: a file and its frame (of a multi-frame DICOM).
    pub frames: Vec<(std::path::PathBuf, usize)>,
    pub correlation: CorrelationSpec,
    pub pixel_size: Option<crate::image::PixelSize>,
    pub origin_px: [f64; 2],
    pub x_left: bool,
    pub y_up: bool,
    pub grid_step_px: Option<f64>,
    pub out: std::path::PathBuf,
}

/// One increment as `summary.json` and `increments.csv` report it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct IncrementReport {
    pub from_frame: usize,
    pub to_frame: usize,
    pub element_size_px: usize,
    pub regularization_px: Option<f64>,
    pub warm_start: bool,
    /// The ZNCC below which an element of this pair is not trusted.
    pub min_zncc: f64,
    pub iterations: usize,
    pub residual_percent_of_dynamic: f64,
    pub trusted_fraction: f64,
    pub mean_u_px: [f64; 2],
    pub time_s: f64,
}

/// What `femu dic` on a sequence reports (`summary.json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct SequenceReport {
    pub femu_version: &'static str,
    pub command: &'static str,
    pub job: SequenceJob,
    pub image_size_px: (usize, usize),
    pub model_frame: ModelFrame,
    pub increments: Vec<IncrementReport>,
    /// Grid points of the first frame, and how many reach each frame `1..=n`.
    pub points: usize,
    pub points_reaching: Vec<usize>,
    /// Trusted points (w = 1) of each frame's composed field.
    pub points_trusted: Vec<usize>,
    pub outputs: Vec<String>,
    pub warnings: Vec<String>,
    pub wall_time_s: f64,
}

/// `femu dic` on a sequence: reads the frames, correlates and composes them
/// ([`correlate_sequence`]) and writes into `job.out`: `field.csv` (the first frame to the last,
/// the measured-field CSV; `field_covariance.mtx` beside it up to
/// [`crate::output::MAX_COVARIANCE_POINTS`] points), `frame_K/field.csv` for every frame `K`
/// (the last one's with its covariance too), `increments.csv` and `summary.json`.
pub fn run_sequence(
    job: &SequenceJob,
    on_increment: &dyn Fn(usize, usize),
) -> Result<SequenceReport, DicError> {
    let t0 = std::time::Instant::now();
    let mut inputs: Vec<&std::path::Path> = job.frames.iter().map(|(p, _)| p.as_path()).collect();
    inputs.extend(job.correlation.roi.mask_file());
    femu_mesh::folder::refuse_inputs_in(&job.out, &inputs)?;
    let frames = job
        .frames
        .iter()
        .map(|(p, k)| GreyImage::open(p, *k))
        .collect::<Result<Vec<_>, _>>()?;
    let pixel_size = job.pixel_size.or(frames[0].pixel_size);
    let frame = ModelFrame {
        origin_px: job.origin_px,
        pixel_size_mm: pixel_size.map_or([1.0, 1.0], |p| [p.dx_mm, p.dy_mm]),
        x_left: job.x_left,
        y_up: job.y_up,
    };
    let seq = correlate_sequence(&frames, &job.correlation, job.grid_step_px, on_increment)?;
    let werr = |path: &std::path::Path, e: std::io::Error| DicError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    femu_mesh::atomic::create_dir_all(&job.out).map_err(|e| werr(&job.out, e))?;
    let n = seq.frames() - 1;
    let mut outputs = Vec::new();
    let mut warnings = Vec::new();
    if pixel_size.is_none() {
        warnings.push(
            "pixel size unknown (no DICOM header, no --pixel-size): the fields are in pixels ('# units: px')"
                .to_string(),
        );
    }
    let mut points_reaching = Vec::new();
    let mut points_trusted = Vec::new();
    for k in 1..=n {
        let reaching = seq.reaching(k);
        let field = seq.field(k, &frame);
        points_reaching.push(field.len());
        points_trusted.push(field.iter().filter(|p| p.w > 0.0).count());
        let comments = vec![
            format!("units: {}", if pixel_size.is_some() { "mm" } else { "px" }),
            format!(
                "femu dic {}: frames 0 -> {k} of a sequence of {}, composed from {k} increments (each frame correlated with the one before); positions in frame 0 ({})",
                env!("CARGO_PKG_VERSION"),
                n + 1,
                job.frames[0].0.display()
            ),
            format!(
                "frame: origin at pixel ({}, {}); x {}, y {}; sx, sy from the increments' covariances summed; w = 0 where an increment does not trust the point",
                frame.origin_px[0],
                frame.origin_px[1],
                if frame.x_left { "left" } else { "right" },
                if frame.y_up { "up" } else { "down" }
            ),
        ];
        let dirs: Vec<std::path::PathBuf> = if k == n {
            vec![job.out.join(format!("frame_{k}")), job.out.clone()]
        } else {
            vec![job.out.join(format!("frame_{k}"))]
        };
        // The full covariance of the field the identification reads (the last frame's): it
        // costs a solve per point and increment, the intermediate frames carry sx, sy.
        let cov = (k == n && field.len() <= crate::output::MAX_COVARIANCE_POINTS)
            .then(|| seq.covariance(k, &reaching, &frame))
            .transpose()?;
        for dir in dirs {
            femu_mesh::atomic::create_dir_all(&dir).map_err(|e| werr(&dir, e))?;
            crate::output::write_field_csv(&dir.join("field.csv"), &field, &comments)?;
            let rel = |f: &str| {
                dir.join(f)
                    .strip_prefix(&job.out)
                    .map(|p| p.display().to_string())
                    .unwrap_or_default()
            };
            outputs.push(rel("field.csv"));
            if let Some(c) = &cov {
                crate::output::write_dense_symmetric(
                    &dir.join("field_covariance.mtx"),
                    2 * field.len(),
                    c,
                    &[format!("femu dic: covariance of field.csv's components (ux, uy per row, in its order), mm^2 in its frame; frames 0 -> {k}, the increments' covariances summed")],
                )?;
                outputs.push(rel("field_covariance.mtx"));
            }
        }
        if k == n && cov.is_none() {
            warnings.push(format!(
                "frame {k}: {} grid points: field_covariance.mtx (dense) is written up to {} points; weighted FEMU runs without it ([measurement] weighting = \"estimated\": sx, sy of field.csv plus the error its residuals show), or give a larger --grid to write it",
                field.len(),
                crate::output::MAX_COVARIANCE_POINTS
            ));
        }
    }
    let increments: Vec<IncrementReport> = seq
        .increments
        .iter()
        .enumerate()
        .map(|(k, inc)| {
            let r = &inc.measured.res;
            let nu = r.displacement.len().max(1) as f64;
            IncrementReport {
                from_frame: k,
                to_frame: k + 1,
                element_size_px: inc.choice.element_size_px,
                regularization_px: inc.choice.regularization_px,
                warm_start: inc.warm_start,
                min_zncc: inc.min_zncc,
                iterations: r.iterations,
                residual_percent_of_dynamic: r.residual_percent,
                trusted_fraction: inc
                    .measured
                    .trust
                    .iter()
                    .filter(|&&t| t == Trust::Trusted)
                    .count() as f64
                    / inc.measured.trust.len().max(1) as f64,
                mean_u_px: [
                    r.displacement.iter().map(|u| u[0]).sum::<f64>() / nu,
                    r.displacement.iter().map(|u| u[1]).sum::<f64>() / nu,
                ],
                time_s: inc.time_s,
            }
        })
        .collect();
    let mut csv = String::from("from_frame,to_frame,element_px,regularization_px,warm_start,min_zncc,iterations,residual_percent,trusted_fraction,mean_ux_px,mean_uy_px,time_s\n");
    for r in &increments {
        csv.push_str(&format!(
            "{},{},{},{},{},{:.3},{},{:.4},{:.4},{:.4},{:.4},{:.4}\n",
            r.from_frame,
            r.to_frame,
            r.element_size_px,
            r.regularization_px
                .map_or("off".to_string(), |l| l.to_string()),
            r.warm_start,
            r.min_zncc,
            r.iterations,
            r.residual_percent_of_dynamic,
            r.trusted_fraction,
            r.mean_u_px[0],
            r.mean_u_px[1],
            r.time_s
        ));
    }
    let p = job.out.join("increments.csv");
    femu_mesh::atomic::write(&p, csv).map_err(|e| werr(&p, e))?;
    outputs.push("increments.csv".into());
    outputs.push("summary.json".into());
    let report = SequenceReport {
        femu_version: env!("CARGO_PKG_VERSION"),
        command: "dic (sequence)",
        job: job.clone(),
        image_size_px: (frames[0].width, frames[0].height),
        model_frame: frame,
        increments,
        points: seq.points.len(),
        points_reaching,
        points_trusted,
        outputs,
        warnings,
        wall_time_s: t0.elapsed().as_secs_f64(),
    };
    crate::output::write_json(&job.out.join("summary.json"), &report)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dark band above a bright textured one: the mask keeps the band, 3 px from the border.
    #[test]
    fn tissue_mask_leaves_out_the_dark_band() {
        let (w, h) = (64, 64);
        let data: Vec<f64> = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                if j < 20 {
                    2.0
                } else {
                    100.0 + 50.0 * ((i * 7 + j * 13) % 5) as f64
                }
            })
            .collect();
        let img = GreyImage::new(w, h, data).unwrap();
        let m = tissue_mask(&img);
        assert!(!m[10 * w + 30] && m[40 * w + 30]);
        assert!(!m[40 * w + 1] && !m[w * (h - 2) + 30]);
    }
}
