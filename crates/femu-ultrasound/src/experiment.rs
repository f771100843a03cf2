//! The virtual experiment with images (mission, "beyond the study"): the unloaded and the
//! loaded tissue imaged by the simulator (the same scatterers, moved by the FE displacement),
//! the DIC between the two images, and its comparison with the FE field it should recover.
//! The measured field is written in the measured-field CSV of `conventions.md` (model frame,
//! mm), so `femu identify --measured` identifies from images instead of from the FE field
//! plus white noise (seed §2.4.1).

use crate::error::UsError;
use crate::phantom::{Phantom, PhantomState};
use crate::probe::{Probe, Transducer};
use crate::render::{render, Frame, Scanner, BONE, NO_TISSUE};
use femu_dic::{correlate, DicOptions, DicResult, Roi};
use femu_mesh::locate::PointLocator;
use std::path::Path;

/// Options of the virtual experiment.
#[derive(Debug, Clone)]
pub struct ExperimentOptions {
    pub transducer: Transducer,
    pub scanner: Scanner,
    pub dic: DicOptions,
    /// Spacing of the output grid (px).
    pub grid_step_px: f64,
    /// Pixels are left out of the ROI where the echo lies this far below the TGC (dB):
    /// the bone shadow and tissue too deep for the frequency.
    pub max_net_attenuation_db: f64,
    /// Seed of the electronic noise of the reference image (the deformed one uses seed + 1).
    pub noise_seed: u64,
    /// Fraction of the scatterers renewed between successive load steps (out-of-plane motion;
    /// [`Phantom::renewed`]): 0 keeps every scatterer, as before this option existed.
    pub decorrelation: f64,
}

impl Default for ExperimentOptions {
    fn default() -> Self {
        ExperimentOptions {
            transducer: Transducer::default(),
            scanner: Scanner::default(),
            dic: DicOptions::default(),
            grid_step_px: 16.0,
            max_net_attenuation_db: 35.0,
            noise_seed: 1,
            decorrelation: 0.0,
        }
    }
}

/// One point of the compared fields.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct ComparedPoint {
    /// Position in the reference image (px) and in the model frame (mm).
    pub x_px: [f64; 2],
    pub x_mm: [f64; 2],
    /// DIC and FE displacement in image pixels and in the model frame (mm).
    pub dic_px: [f64; 2],
    pub true_px: [f64; 2],
    pub dic_mm: [f64; 2],
    pub true_mm: [f64; 2],
    /// 1, or 0 in a DIC element flagged for a high grey-level residual.
    pub w: f64,
}

/// DIC-vs-truth error statistics over the unflagged grid points in tissue.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct FieldError {
    pub points: usize,
    /// Mean (bias), standard deviation, RMS and largest magnitude of the error per component
    /// (image x = lateral, y = depth), px.
    pub bias_px: [f64; 2],
    pub std_px: [f64; 2],
    pub rms_px: [f64; 2],
    pub max_abs_px: [f64; 2],
    /// The same RMS and maximum in mm.
    pub rms_mm: [f64; 2],
    pub max_abs_mm: [f64; 2],
    /// Largest true displacement over the points (px).
    pub max_true_px: f64,
}

/// The result of the virtual experiment.
pub struct Experiment {
    pub reference: Frame,
    pub deformed: Frame,
    /// The DIC region of the first step (true inside).
    pub roi: Vec<bool>,
    /// Number of DIC steps (1: directly from the unloaded to the loaded image).
    pub steps: usize,
    /// The 8-bit image of every state: the unloaded one first, then one per load step.
    pub frames: Vec<femu_dic::GreyImage>,
    /// The DIC of the first step.
    pub dic: DicResult,
    /// The DIC of every step (the first is [`Experiment::dic`]).
    pub increments: Vec<DicResult>,
    pub points: Vec<ComparedPoint>,
    /// Where each point lay in the reference image of each step (px): the material path the
    /// increments were composed along.
    pub paths: Vec<Vec<[f64; 2]>>,
    pub error: FieldError,
    pub phantom_scatterers: usize,
}

/// Runs the virtual experiment for the nodal displacement `u` of `phantom.mesh`, in one DIC
/// step from the unloaded to the loaded image.
pub fn run(
    phantom: &Phantom,
    u: &[f64],
    probe: &Probe,
    opts: &ExperimentOptions,
) -> Result<Experiment, UsError> {
    run_incremental(phantom, &[u.to_vec()], probe, opts)
}

/// Incremental DIC (as elastography does for large strains): `stages` are the nodal
/// displacements at increasing loads, the last one the loaded state. Each successive pair of
/// images is correlated (small increments stay within the DIC's capture range and decorrelate
/// the speckle less), and the increments are composed along the material points:
/// `p_{i+1} = p_i + d_i(p_i)`, `u = p_n − p_0`. A point is weighted 0 if any step flags it.
pub fn run_incremental(
    phantom: &Phantom,
    stages: &[Vec<f64>],
    probe: &Probe,
    opts: &ExperimentOptions,
) -> Result<Experiment, UsError> {
    let Some(u) = stages.last() else {
        return Err(UsError::param("stages", "no loaded state"));
    };
    let mut states = vec![phantom.reference()];
    for s in stages {
        states.push(phantom.displaced(s)?);
    }
    run_states(phantom, &states, u, probe, opts)
}

fn run_states(
    phantom: &Phantom,
    states: &[PhantomState],
    u: &[f64],
    probe: &Probe,
    opts: &ExperimentOptions,
) -> Result<Experiment, UsError> {
    if !(opts.grid_step_px >= 1.0) {
        return Err(UsError::param(
            "grid step",
            format!("{} px must be at least 1", opts.grid_step_px),
        ));
    }
    let frames = render_sequence(phantom, states, probe, opts)?;
    let (w, h) = (frames[0].width, frames[0].height);
    let locator = PointLocator::new(&phantom.mesh);
    // True displacement (px) at a pixel position of the reference image.
    let truth = |p: [f64; 2]| -> Option<[f64; 2]> {
        let x = probe.pixel_to_model(p);
        let loc = locator.locate(x)?;
        Some(probe.displacement_to_pixels([loc.interpolate(u, 2, 0), loc.interpolate(u, 2, 1)]))
    };
    let f = opts.transducer.frequency_mhz;
    // Usable pixels of a frame: tissue with an echo above the noise.
    let usable = |fr: &Frame, k: usize| -> bool {
        let t = fr.tissue[k];
        let d = ((k / w) as f64 + 0.5) / probe.px_per_mm;
        t != NO_TISSUE
            && t != BONE
            && fr.attenuation_db[k] - opts.scanner.tgc_db(f, d) <= opts.max_net_attenuation_db
    };
    // ROI of each step: usable in both images and at least 2 px from the image edge (an
    // experimenter draws it where the tissue is seen in both images).
    let mut rois = Vec::new();
    for s in 0..frames.len() - 1 {
        let roi: Vec<bool> = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                i >= 2
                    && j >= 2
                    && i + 3 <= w
                    && j + 3 <= h
                    && usable(&frames[s], k)
                    && usable(&frames[s + 1], k)
            })
            .collect();
        if !roi.iter().any(|&b| b) {
            return Err(UsError::Geometry(format!(
                "step {}: no tissue pixel is usable for the DIC in the field of view",
                s + 1
            )));
        }
        rois.push(roi);
    }
    let mut dics = Vec::new();
    for s in 0..frames.len() - 1 {
        let roi = Roi::Mask {
            width: w,
            height: h,
            inside: rois[s].clone(),
        };
        let d =
            correlate(&frames[s].image, &frames[s + 1].image, &roi, &opts.dic).map_err(|e| {
                UsError::Geometry(format!("DIC step {} of {}: {e}", s + 1, frames.len() - 1))
            })?;
        dics.push(d);
    }
    let grid = femu_dic::output::grid(
        &dics[0],
        &femu_dic::output::ModelFrame::default(),
        opts.grid_step_px,
    )?;
    let (points, paths): (Vec<ComparedPoint>, Vec<Vec<[f64; 2]>>) = grid
        .iter()
        .filter_map(|g| {
            let t = truth(g.x_px)?;
            let mut p = g.x_px;
            let mut wgt = g.w;
            let mut path = Vec::with_capacity(dics.len());
            for d in &dics {
                let (e, _, _) = d.mesh.locate(p[0], p[1])?;
                let inc = d.mesh.interpolate(&d.displacement, p[0], p[1])?;
                if d.flagged[e] {
                    wgt = 0.0;
                }
                path.push(p);
                p = [p[0] + inc[0], p[1] + inc[1]];
            }
            let u_px = [p[0] - g.x_px[0], p[1] - g.x_px[1]];
            Some((
                ComparedPoint {
                    x_px: g.x_px,
                    x_mm: probe.pixel_to_model(g.x_px),
                    dic_px: u_px,
                    true_px: t,
                    dic_mm: probe.displacement_to_model(u_px),
                    true_mm: probe.displacement_to_model(t),
                    w: wgt,
                },
                path,
            ))
        })
        .unzip();
    let error = field_error(&points, probe.px_per_mm);
    let images = frames.iter().map(|f| f.image.clone()).collect();
    let mut frames = frames;
    let deformed = frames.pop().expect("two frames at least");
    let reference = frames.swap_remove(0);
    let roi = rois.swap_remove(0);
    Ok(Experiment {
        reference,
        deformed,
        roi,
        steps: dics.len(),
        frames: images,
        dic: dics[0].clone(),
        increments: dics,
        paths,
        error,
        points,
        phantom_scatterers: phantom.scatterers.len(),
    })
}

/// The frames of `states` (the unloaded state first): frame `k` images the phantom with
/// `opts.decorrelation` of its scatterers renewed at each of the `k` load steps before it
/// (seeded by `opts.noise_seed` and `k`), with electronic noise seeded by `noise_seed + k`.
/// Frames render in parallel.
pub fn render_sequence(
    phantom: &Phantom,
    states: &[PhantomState],
    probe: &Probe,
    opts: &ExperimentOptions,
) -> Result<Vec<Frame>, UsError> {
    let mut phantoms = vec![std::borrow::Cow::Borrowed(phantom)];
    for k in 1..states.len() {
        if opts.decorrelation == 0.0 {
            phantoms.push(std::borrow::Cow::Borrowed(phantom));
            continue;
        }
        let renewed = phantoms[k - 1].renewed(
            opts.decorrelation,
            opts.noise_seed
                .wrapping_mul(1_000_003)
                .wrapping_add(k as u64),
        )?;
        phantoms.push(std::borrow::Cow::Owned(renewed));
    }
    use rayon::prelude::*;
    states
        .par_iter()
        .zip(phantoms.par_iter())
        .enumerate()
        .map(|(k, (st, ph))| {
            render(
                ph,
                st,
                probe,
                &opts.transducer,
                &opts.scanner,
                opts.noise_seed + k as u64,
            )
        })
        .collect()
}

/// Runs the experiment for an analytic displacement `x ↦ u(x)` (mm) applied to the scatterers
/// and the mesh (verification with known fields, e.g. affine).
pub fn run_analytic(
    phantom: &Phantom,
    field: &(dyn Fn([f64; 2]) -> [f64; 2] + Sync),
    probe: &Probe,
    opts: &ExperimentOptions,
) -> Result<Experiment, UsError> {
    let u: Vec<f64> = phantom.mesh.nodes.iter().flat_map(|&x| field(x)).collect();
    let states = [phantom.reference(), phantom.moved_by(field)];
    run_states(phantom, &states, &u, probe, opts)
}

/// The covariance of the composed DIC displacement at `points` (indices into
/// [`Experiment::points`]), in the model frame (mm², `[ux, uy]` per point, row-major): each
/// increment's nodal covariance `A⁻¹ M_σ A⁻¹` (`femu_dic::quality`, the Gauss–Newton matrix and
/// the grey-level residual's own variance and correlation) carried to the points by the shape
/// functions at their position in that step, the increments independent (each correlates a new
/// pair of frames), summed; then rotated and scaled by the probe's pose.
pub fn grid_covariance(
    exp: &Experiment,
    points: &[usize],
    probe: &Probe,
) -> Result<Vec<f64>, UsError> {
    let m = 2 * points.len();
    let increments: Vec<&femu_dic::DicResult> = exp.increments.iter().collect();
    let paths: Vec<&[[f64; 2]]> = points.iter().map(|&i| exp.paths[i].as_slice()).collect();
    let c = femu_dic::sequence::composed_covariance(&increments, &paths)
        .map_err(|e| UsError::Geometry(format!("covariance of the DIC increments: {e}")))?;
    // Model frame: u_mm = T u_px blockwise, C_mm = T C Tᵀ.
    let t = [
        probe.displacement_to_model([1.0, 0.0]),
        probe.displacement_to_model([0.0, 1.0]),
    ];
    let tm = |r: usize, col: usize| t[col][r]; // T[r][col]
    let mut out = vec![0.0; m * m];
    for bi in 0..points.len() {
        for bj in 0..points.len() {
            for r in 0..2 {
                for s in 0..2 {
                    let mut v = 0.0;
                    for a in 0..2 {
                        for b in 0..2 {
                            v += tm(r, a) * c[(2 * bi + a) * m + 2 * bj + b] * tm(s, b);
                        }
                    }
                    out[(2 * bi + r) * m + 2 * bj + s] = v;
                }
            }
        }
    }
    Ok(out)
}

/// Error statistics over the points of weight 1.
pub fn field_error(points: &[ComparedPoint], px_per_mm: f64) -> FieldError {
    let used: Vec<&ComparedPoint> = points.iter().filter(|p| p.w > 0.0).collect();
    let n = used.len();
    if n == 0 {
        return FieldError::default();
    }
    let mut e = FieldError {
        points: n,
        ..Default::default()
    };
    for c in 0..2 {
        let errs: Vec<f64> = used.iter().map(|p| p.dic_px[c] - p.true_px[c]).collect();
        let (m, s) = crate::stats::mean_sd(&errs);
        e.bias_px[c] = m;
        e.std_px[c] = s;
        e.rms_px[c] = (errs.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        e.max_abs_px[c] = errs.iter().fold(0.0, |a, v| a.max(v.abs()));
        e.rms_mm[c] = e.rms_px[c] / px_per_mm;
        e.max_abs_mm[c] = e.max_abs_px[c] / px_per_mm;
    }
    e.max_true_px = used
        .iter()
        .fold(0.0, |a, p| a.max(p.true_px[0].hypot(p.true_px[1])));
    e
}

/// Writes the measured field (`x,y,ux,uy,w`, model frame, mm; conventions.md) of the DIC, or
/// the FE truth at the same points when `truth` is set.
pub fn write_field_csv(
    path: &Path,
    points: &[ComparedPoint],
    truth: bool,
    comments: &[String],
) -> Result<(), UsError> {
    let mut body = String::new();
    for c in comments {
        body += &format!("# {c}\n");
    }
    body += "x,y,ux,uy,w\n";
    for p in points {
        let u = if truth { p.true_mm } else { p.dic_mm };
        body += &format!(
            "{:.9e},{:.9e},{:.9e},{:.9e},{}\n",
            p.x_mm[0], p.x_mm[1], u[0], u[1], p.w
        );
    }
    femu_mesh::atomic::write(path, body).map_err(|e| UsError::write(path, e))
}

/// Per-pixel maps over the ROI (NaN outside): DIC ux, uy, true ux, uy (px), in that order.
/// The DIC maps are those of the grid points (nearest grid point within half a step), which
/// hold the composed field of an incremental run.
pub fn pixel_maps(
    exp: &Experiment,
    phantom: &Phantom,
    u: &[f64],
    probe: &Probe,
    grid_step_px: f64,
) -> [Vec<f64>; 4] {
    let (w, h) = (exp.reference.width, exp.reference.height);
    let locator = PointLocator::new(&phantom.mesh);
    let m = &exp.dic.mesh;
    let origin = [m.x0 as f64 - 0.5, m.y0 as f64 - 0.5];
    let cell = |p: [f64; 2]| {
        (
            ((p[0] - origin[0]) / grid_step_px).floor() as i64,
            ((p[1] - origin[1]) / grid_step_px).floor() as i64,
        )
    };
    let by_cell: std::collections::HashMap<(i64, i64), &ComparedPoint> =
        exp.points.iter().map(|p| (cell(p.x_px), p)).collect();
    let nan = vec![f64::NAN; w * h];
    let mut maps = [nan.clone(), nan.clone(), nan.clone(), nan];
    for k in 0..w * h {
        if !exp.roi[k] {
            continue;
        }
        let p = [(k % w) as f64, (k / w) as f64];
        let Some(g) = by_cell.get(&cell(p)) else {
            continue;
        };
        let Some(loc) = locator.locate(probe.pixel_to_model(p)) else {
            continue;
        };
        let t = probe.displacement_to_pixels([loc.interpolate(u, 2, 0), loc.interpolate(u, 2, 1)]);
        maps[0][k] = g.dic_px[0];
        maps[1][k] = g.dic_px[1];
        maps[2][k] = t[0];
        maps[3][k] = t[1];
    }
    maps
}
