//! `femu dic REF DEF` as a library function: read the images, choose the options
//! ([`crate::auto`]), correlate, compute the quality ([`crate::quality`]) and write the output
//! folder. The CLI parses its arguments into a [`DicJob`] and calls [`run_dic`].
//!
//! Files written into `out` (all coordinates and displacements in the model frame, mm, unless
//! the column name says px):
//!
//! | file | content |
//! |---|---|
//! | `field.csv` | the measured-field CSV of conventions.md: `x,y,ux,uy,sx,sy,w` on a regular grid; `sx, sy` standard deviations from the nodal covariance, `w` = 0 in the elements the trust mask rejects |
//! | `nodes.csv` | `node,x_px,y_px,ux_px,uy_px,x_mm,y_mm,ux_mm,uy_mm,sd_ux_px,sd_uy_px,corr_xy,w` |
//! | `elements.csv` | strain, residual, ZNCC, grey-level std, structure-tensor eigenvalues, `trust` (reason) and `w` per element |
//! | `covariance.mtx` | the nodal covariance `C = A⁻¹ M_σ A⁻¹` (px²; `M_σ` by its symmetric part) on the pattern of `A` (nodal 2 x 2 blocks and the pairs of nodes sharing an element or a regularization row), Matrix Market, lower triangle, equation `2 (node − 1) + c + 1` |
//! | `hessian.mtx` | `A = M + λK`, the Gauss–Newton matrix of the iterations (grey levels² / px²) |
//! | `hessian_noise.mtx` | `M_σ`, the covariance of the right-hand side under the residual's noise (grey levels⁴ / px²): with `A`, the factors of `C` |
//! | `field_covariance.mtx` | the full covariance of `field.csv`'s components (mm², dense symmetric Matrix Market array, ux and uy of each row in its order), `N C Nᵀ` at the grid points; written up to [`output::MAX_COVARIANCE_POINTS`] points: `[measurement] covariance` of a study reads it for weighted FEMU |
//! | `result.vtu` | mesh with displacement, standard deviations, strain, residual, trust |
//! | `ux.png` … `residual.png`, `sd.png`, `zncc.png`, `trust.png` | maps over the reference image |
//! | `summary.json` | [`DicReport`]: inputs, the choice of the options and every attempt, the result, the quality |

use crate::auto::{self, Choice, Measured};
use crate::error::DicError;
use crate::image::{GreyImage, PixelSize};
use crate::mesh::Rect;
use crate::output::{self, DicSummary, ModelFrame, Quality};
use crate::quality::{Trust, TrustCriteria};
use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

pub use crate::output::write_json;
pub use crate::spec::{CorrelationSpec, RoiSpec};

/// Everything `femu dic` needs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DicJob {
    pub reference: PathBuf,
    pub deformed: PathBuf,
    pub frame_ref: usize,
    pub frame_def: usize,
    pub correlation: CorrelationSpec,
    /// Pixel size given by the user (overrides the DICOM header).
    pub pixel_size: Option<PixelSize>,
    pub origin_px: [f64; 2],
    pub x_left: bool,
    pub y_up: bool,
    /// Step of the grid of `field.csv` (pixels; default the element size).
    pub grid_step_px: Option<f64>,
    pub figures: bool,
    pub out: PathBuf,
}

/// Summary of the quality of a field.
#[derive(Debug, Clone, serde::Serialize)]
pub struct QualitySummary {
    pub trusted_elements: usize,
    /// Elements per reason (`outside-image`, `decorrelated`, `high-residual`, `shadow`,
    /// `low-texture`).
    pub untrusted: Vec<(String, usize)>,
    /// Median and 90th percentile of the nodal standard deviations (px), over the trusted
    /// nodes.
    pub sd_median_px: [f64; 2],
    pub sd_p90_px: [f64; 2],
    /// Correlation lengths of the residual used in the covariance (px).
    pub residual_correlation_lags_px: [usize; 2],
    pub criteria: TrustCriteria,
}

/// What `femu dic` reports (`summary.json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct DicReport {
    pub femu_version: &'static str,
    pub command: &'static str,
    pub job: DicJob,
    pub image_size_px: (usize, usize),
    /// Pixel size (mm/px) and its source; null if unknown (then mm = px).
    pub pixel_size: Option<PixelSize>,
    pub model_frame: ModelFrame,
    pub choice: Choice,
    pub result: DicSummary,
    pub quality: QualitySummary,
    pub grid_points: usize,
    pub outputs: Vec<&'static str>,
    pub warnings: Vec<String>,
    /// What to try next, when the correlation did not converge.
    pub advice: Option<String>,
    pub wall_time_s: f64,
}

fn percentile(mut v: Vec<f64>, p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// The quality summary of a measured field.
pub fn quality_summary(m: &Measured, criteria: &TrustCriteria) -> QualitySummary {
    let w = output::node_weights(&m.res, &m.trust);
    let pick = |c: usize| -> Vec<f64> {
        m.cov
            .node
            .iter()
            .zip(&w)
            .filter(|(_, &w)| w == 1)
            .map(|(n, _)| if c == 0 { n.sd_ux_px } else { n.sd_uy_px })
            .collect()
    };
    let untrusted = [
        Trust::OutsideImage,
        Trust::Decorrelated,
        Trust::HighResidual,
        Trust::Shadow,
        Trust::LowTexture,
    ]
    .iter()
    .map(|t| {
        (
            t.name().to_string(),
            m.trust.iter().filter(|&x| x == t).count(),
        )
    })
    .collect();
    let rho = &m.res.system.residual_correlation;
    QualitySummary {
        trusted_elements: m.trust.iter().filter(|&&t| t == Trust::Trusted).count(),
        untrusted,
        sd_median_px: [percentile(pick(0), 0.5), percentile(pick(1), 0.5)],
        sd_p90_px: [percentile(pick(0), 0.9), percentile(pick(1), 0.9)],
        residual_correlation_lags_px: [rho.lx, rho.ly],
        criteria: *criteria,
    }
}

/// The pair `f → g` correlated as `spec` says; when the whole image (no ROI, no mask) does not
/// correlate, the pair is tried again as a B-mode pair
/// ([`crate::sequence::correlate_bmode_pair`]: the tissue mask, three pyramid levels, the ZNCC
/// trust judged against the pair's median), whose ZNCC threshold is then returned. The first
/// error is kept when the second try fails too.
pub fn measure_pair(
    spec: &CorrelationSpec,
    f: &GreyImage,
    g: &GreyImage,
) -> Result<(Measured, Choice, Option<f64>), DicError> {
    match spec.measure(f, g) {
        Ok((m, c)) => Ok((m, c, None)),
        Err(e) if matches!(spec.roi, RoiSpec::Whole) => {
            crate::sequence::correlate_bmode_pair(f, g, spec)
                .map(|(m, c, z)| (m, c, Some(z)))
                .map_err(|_| e)
        }
        Err(e) => Err(e),
    }
}

/// Runs `femu dic`: writes the output folder and returns the report. A correlation that ran
/// with given options but did not converge is written and reported (`result.converged`
/// false); the caller decides how to exit.
pub fn run_dic(job: &DicJob) -> Result<DicReport, DicError> {
    let t0 = Instant::now();
    let mut inputs = vec![job.reference.as_path(), job.deformed.as_path()];
    inputs.extend(job.correlation.roi.mask_file());
    femu_mesh::folder::refuse_inputs_in(&job.out, &inputs)?;
    let f = GreyImage::open(&job.reference, job.frame_ref)?;
    let g = GreyImage::open(&job.deformed, job.frame_def)?;
    run_dic_on(job, &f, &g, t0).map(|run| run.report)
}

/// What [`run_dic_on`] computed, besides the files: the report, the measured field with its
/// covariance and trust, and the points of `field.csv`.
pub struct DicRun {
    pub report: DicReport,
    pub measured: Measured,
    pub grid: Vec<output::GridPoint>,
}

/// `femu dic` on images already in memory (read from `job`'s files, or handed over by a
/// script; `job.reference` and `job.deformed` then only name them): correlates, writes
/// `job.out` and returns the report with the field; `t0` is when the work began.
pub fn run_dic_on(
    job: &DicJob,
    f: &GreyImage,
    g: &GreyImage,
    t0: Instant,
) -> Result<DicRun, DicError> {
    let pixel_size = job.pixel_size.or(f.pixel_size);
    let frame = ModelFrame {
        origin_px: job.origin_px,
        pixel_size_mm: pixel_size.map_or([1.0, 1.0], |p| [p.dx_mm, p.dy_mm]),
        x_left: job.x_left,
        y_up: job.y_up,
    };
    let (m, choice, bmode) = measure_pair(&job.correlation, f, g)?;
    femu_mesh::atomic::create_dir_all(&job.out).map_err(|e| DicError::Write {
        path: job.out.clone(),
        message: e.to_string(),
    })?;
    let step = job.grid_step_px.unwrap_or(m.res.mesh.h as f64);
    let q = Quality {
        cov: &m.cov,
        trust: &m.trust,
    };
    let points = output::grid_with_quality(&m.res, Some(&q), &frame, step)?;
    let mut warnings = Vec::new();
    if points.len() > output::MAX_COVARIANCE_POINTS {
        warnings.push(format!(
            "{} grid points: field_covariance.mtx (dense) is written up to {} points; weighted FEMU runs without it ([measurement] weighting = \"estimated\": sx, sy of field.csv plus the error its residuals show), or give a larger --grid-step to write it",
            points.len(),
            output::MAX_COVARIANCE_POINTS
        ));
    }
    if pixel_size.is_none() {
        warnings.push(
            "pixel size unknown (no DICOM header, no --pixel-size): the mm columns are in pixels"
                .to_string(),
        );
    }
    // The trust criteria as applied: the pair's own ZNCC level for a B-mode pair.
    let criteria = TrustCriteria {
        min_zncc: bmode.unwrap_or(job.correlation.trust.min_zncc),
        ..job.correlation.trust
    };
    // The tables and matrices beside the maps: the tables are written one after the other, the
    // maps drawn in parallel; together they keep both cores busy.
    let (tables, maps) = rayon::join(
        || -> Result<bool, DicError> {
            write_tables(job, &m, &choice, &frame, pixel_size, &points)?;
            // The field's full covariance for weighted FEMU (`[measurement] covariance`), when
            // the grid is small enough to write it densely.
            let covariance_written = points.len() <= output::MAX_COVARIANCE_POINTS;
            if covariance_written {
                let c = output::grid_covariance(&m.res, &points, &frame)?;
                output::write_dense_symmetric(
                    &job.out.join("field_covariance.mtx"),
                    2 * points.len(),
                    &c,
                    &[
                        "femu dic: covariance of field.csv's components (ux, uy per row, in its order), mm^2 in its frame".into(),
                        "N A^-1 M_sigma A^-1 N^T: the nodal covariance (covariance.mtx) at the grid points".into(),
                    ],
                )?;
            }
            Ok(covariance_written)
        },
        || {
            if job.figures {
                crate::figures::write_maps(
                    &job.out,
                    f,
                    &m,
                    &frame,
                    pixel_size.is_some(),
                    criteria.min_zncc,
                )
            } else {
                Ok(())
            }
        },
    );
    let covariance_written = tables?;
    maps?;
    let mut outputs = vec![
        "field.csv",
        "nodes.csv",
        "elements.csv",
        "covariance.mtx",
        "hessian.mtx",
        "hessian_noise.mtx",
        "result.vtu",
        "summary.json",
    ];
    if covariance_written {
        outputs.push("field_covariance.mtx");
    }
    if job.figures {
        outputs.extend(crate::figures::MAPS);
    }
    let quality = quality_summary(&m, &criteria);
    if let Some(z) = bmode {
        warnings.push(format!(
            "the whole image did not correlate: correlated as a B-mode pair, over the tissue the reference frame shows, with {} pyramid levels and elements trusted from a ZNCC of {z:.2} (the pair's own level)",
            job.correlation.options.pyramid_levels.unwrap_or(crate::sequence::SEQUENCE_LEVELS)
        ));
    }
    let untrusted = m.trust.len() - quality.trusted_elements;
    if untrusted > 0 {
        warnings.push(format!(
            "{untrusted} of {} elements not trusted ({}): w = 0 in field.csv",
            m.trust.len(),
            quality
                .untrusted
                .iter()
                .filter(|(_, n)| *n > 0)
                .map(|(r, n)| format!("{n} {r}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if m.res.residual_percent > 5.0 {
        warnings.push(format!(
            "high grey-level residual ({:.1} % of the dynamic range): the images may not show the same texture (try --brightness per-element, a mask or a longer regularization)",
            m.res.residual_percent
        ));
    }
    if !m.res.converged {
        warnings.push(format!(
            "not converged in {} iterations (last increment {:.2e} px)",
            m.res.iterations, m.res.last_increment_px
        ));
    }
    let report = DicReport {
        femu_version: env!("CARGO_PKG_VERSION"),
        command: "dic",
        job: job.clone(),
        image_size_px: (f.width, f.height),
        pixel_size,
        model_frame: frame,
        choice,
        result: DicSummary::of(&m.res),
        quality,
        grid_points: points.len(),
        outputs,
        warnings,
        advice: (!m.res.converged).then(|| {
            let mesh = &m.res.mesh;
            let bb = Rect {
                x: mesh.x0,
                y: mesh.y0,
                w: mesh.nx * mesh.h,
                h: mesh.ny * mesh.h,
            };
            auto::advice(f, &bb, mesh.h)
        }),
        wall_time_s: t0.elapsed().as_secs_f64(),
    };
    write_json(&job.out.join("summary.json"), &report)?;
    Ok(DicRun {
        report,
        measured: m,
        grid: points,
    })
}

/// `field.csv`, `nodes.csv`, `elements.csv`, the three matrices and `result.vtu`.
fn write_tables(
    job: &DicJob,
    m: &Measured,
    choice: &Choice,
    frame: &ModelFrame,
    pixel_size: Option<PixelSize>,
    points: &[output::GridPoint],
) -> Result<(), DicError> {
    let out = &job.out;
    let size_note = match pixel_size {
        Some(p) => format!("pixel size {} x {} mm ({})", p.dx_mm, p.dy_mm, p.source),
        None => "pixel size unknown: 1 mm = 1 px".to_string(),
    };
    let comments = vec![
        // Machine-readable: the identification checks a study's frame keys against it.
        format!(
            "units: {}",
            if pixel_size.is_some() { "mm" } else { "px" }
        ),
        format!(
            "femu dic {}: reference {} (frame {}), deformed {} (frame {})",
            env!("CARGO_PKG_VERSION"),
            job.reference.display(),
            job.frame_ref,
            job.deformed.display(),
            job.frame_def
        ),
        format!(
            "frame: {size_note}; origin at pixel ({}, {}); x {}, y {}",
            frame.origin_px[0],
            frame.origin_px[1],
            if frame.x_left { "left" } else { "right" },
            if frame.y_up { "up" } else { "down" }
        ),
        format!(
            "global Q4 DIC, element {} px, regularization {}, grid step {} px; sx, sy: standard deviations from the nodal covariance (covariance.mtx); w = 0 in elements not trusted (elements.csv)",
            choice.element_size_px,
            choice
                .regularization_px
                .map_or("off".to_string(), |l| format!("{l} px")),
            points
                .get(1)
                .map_or(f64::NAN, |p| (p.x_px[0] - points[0].x_px[0]).abs())
        ),
    ];
    let q = Quality {
        cov: &m.cov,
        trust: &m.trust,
    };
    let sys = &m.res.system;
    let eq = "equation 2 (node - 1) + c + 1, c = 0 for ux, 1 for uy, node of nodes.csv";
    // The files are independent: written in parallel (with the maps, when they are drawn).
    let writers: [&(dyn Fn() -> Result<(), DicError> + Sync); 7] = [
        &|| output::write_field_csv(&out.join("field.csv"), points, &comments),
        &|| output::write_nodes_csv(&out.join("nodes.csv"), &m.res, frame, Some(&q)),
        &|| output::write_elements_csv(&out.join("elements.csv"), &m.res, frame, Some(&m.trust)),
        &|| {
            output::write_matrix_market(
                &out.join("covariance.mtx"),
                &sys.pattern,
                &m.cov.values,
                &[
                    "femu dic: nodal covariance C = A^-1 M_sigma A^-1 (px^2), entries on the pattern of A only".into(),
                    eq.into(),
                ],
            )
        },
        &|| {
            output::write_matrix_market(
                &out.join("hessian.mtx"),
                &sys.pattern,
                &sys.a_values(),
                &[
                    format!(
                        "femu dic: Gauss-Newton matrix A = M + lambda K (grey levels^2/px^2), lambda = {}",
                        sys.lambda.unwrap_or(0.0)
                    ),
                    eq.into(),
                ],
            )
        },
        &|| {
            let m_sigma = crate::quality::noise_matrix(&m.res);
            output::write_matrix_market(
                &out.join("hessian_noise.mtx"),
                &sys.pattern,
                &m_sigma,
                &[
                    "femu dic: M_sigma, covariance of the Gauss-Newton right-hand side under the residual noise; C = A^-1 M_sigma A^-1".into(),
                    eq.into(),
                ],
            )
        },
        &|| {
            output::write_fields(
                &femu_mesh::VtuWriter,
                &out.join("result.vtu"),
                &m.res,
                frame,
            )
        },
    ];
    writers.par_iter().try_for_each(|write| write())
}
