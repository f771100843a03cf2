//! The output folder of a study (conventions.md): `convergence.csv` and `convergence.json`
//! (one row per solve), `convergence.png` (log-log: difference from the finest mesh against
//! the node spacing, the fitted rate per element type in the legend), `locking.png`
//! (displacement over the reference's against the node spacing, Table 1 and small D),
//! `reference_grid.csv` (the finest reference mesh's displacement at the common grid points, in
//! the measured-field format of conventions.md) and `summary.json`.

use crate::rate::RateFit;
use crate::run::{ElementSummary, MeshRun, StudyResult};
use crate::study::{ConvergenceStudy, MeshSequence};
use crate::ConvergenceError;
use femu_plot::{line_plot_png, LegendPosition, LinePlot, LineStyle, Series};
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

fn io_err(path: &Path, e: impl std::fmt::Display) -> ConvergenceError {
    ConvergenceError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn write(path: &Path, text: &str) -> Result<(), ConvergenceError> {
    femu_mesh::atomic::write(path, text).map_err(|e| io_err(path, e))
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v:.9e}"))
}

/// Writes every output file of `result` into `out` (created if absent).
pub fn write_outputs(
    out: &Path,
    study: &ConvergenceStudy,
    result: &StudyResult,
) -> Result<(), ConvergenceError> {
    femu_mesh::atomic::create_dir_all(out).map_err(|e| io_err(out, e))?;
    write_table(out, &result.runs)?;
    let table = serde_json::to_string_pretty(&json!({
        "runs": result.runs,
        "fits": result.elements,
    }))
    .map_err(|e| io_err(&out.join("convergence.json"), e))?;
    write(&out.join("convergence.json"), &table)?;
    write_figures_and_summary(out, study, result)
}

/// Writes the solves a stopped study finished (`convergence.csv`, without the differences:
/// the finest meshes they are measured against were not solved) into `out`.
pub fn write_finished_runs(out: &Path, runs: &[MeshRun]) -> Result<(), ConvergenceError> {
    femu_mesh::atomic::create_dir_all(out).map_err(|e| io_err(out, e))?;
    write_table(out, runs)
}

/// `convergence.csv`: one row per solve.
fn write_table(out: &Path, runs: &[MeshRun]) -> Result<(), ConvergenceError> {
    let mut csv = String::from(
        "test,element,d_scale,mesh,target_elements,element_size_mm,elements,nodes,h_mm,status,points_inside,max_diff_mm,rms_diff_mm,rms_displacement_mm,displacement_ratio,max_displacement_mm,reaction_x_n_per_mm,reaction_y_n_per_mm,travel_mm,contact_force_n_per_mm,increments,newton_iterations,mesh_s,solve_s,peak_memory_mb\n",
    );
    for r in runs {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{:.6},{},{},{:.6},{},{},{},{},{},{},{:.9e},{:.9e},{:.9e},{},{},{},{},{:.4},{:.4},{}",
            r.test,
            r.element,
            r.d_scale,
            r.mesh + 1,
            r.target_elements.map_or(String::new(), |v| v.to_string()),
            r.element_size_mm,
            r.elements,
            r.nodes,
            r.h_mm,
            r.status.replace(',', ";"),
            r.points_inside,
            opt(r.max_diff_mm),
            opt(r.rms_diff_mm),
            opt(r.rms_displacement_mm),
            opt(r.displacement_ratio),
            r.max_displacement_mm,
            r.reaction_n_per_mm[0],
            r.reaction_n_per_mm[1],
            opt(r.travel_mm),
            opt(r.contact_force_n_per_mm),
            r.increments,
            r.newton_iterations,
            r.mesh_s,
            r.solve_s,
            r.peak_memory_mb.map_or(String::new(), |v| format!("{v:.1}")),
        );
    }
    write(&out.join("convergence.csv"), &csv)
}

/// The reference grid, the figures and `summary.json` of a finished study.
fn write_figures_and_summary(
    out: &Path,
    study: &ConvergenceStudy,
    result: &StudyResult,
) -> Result<(), ConvergenceError> {
    // The reference displacement at the common grid points.
    let reference = result.runs.iter().find(|r| {
        r.test == result.loading
            && r.element == result.reference_element
            && r.d_scale == 1.0
            && r.mesh + 1 == study.meshes.len()
            && r.status == "converged"
    });
    if let Some(r) = reference {
        let mut s = format!(
            "# femu convergence: {} mesh {} ({} elements), {}, displacement at the common grid points (mm)\nx,y,ux,uy\n",
            r.element,
            r.mesh + 1,
            r.elements,
            result.loading
        );
        for ((p, u), &c) in study
            .grid
            .points()
            .iter()
            .zip(&r.u_points)
            .zip(&result.common)
        {
            if let (true, Some(u)) = (c, u) {
                let _ = writeln!(s, "{:.9e},{:.9e},{:.12e},{:.12e}", p[0], p[1], u[0], u[1]);
            }
        }
        write(&out.join("reference_grid.csv"), &s)?;
    }

    // The convergence figure.
    // The largest differences as lines, the RMS ones as markers, each with its fitted rate.
    type Diff = fn(&MeshRun) -> Option<f64>;
    type Rate = fn(&ElementSummary) -> Option<RateFit>;
    let kinds: [(&str, LineStyle, Diff, Rate); 2] = [
        (
            "max",
            LineStyle::LineAndMarkers,
            |r| r.max_diff_mm,
            |s| s.rate_max,
        ),
        ("RMS", LineStyle::Markers, |r| r.rms_diff_mm, |s| s.rate_rms),
    ];
    let mut series = Vec::new();
    for (label, style, diff, rate) in kinds {
        for s in result
            .elements
            .iter()
            .filter(|s| s.test == result.loading && s.d_scale == 1.0)
        {
            let pts: Vec<(f64, f64)> = result
                .runs
                .iter()
                .filter(|r| {
                    r.test == result.loading
                        && r.element == s.element
                        && r.d_scale == 1.0
                        && r.mesh + 1 < study.meshes.len()
                })
                .filter_map(|r| diff(r).filter(|d| *d > 0.0).map(|d| (r.h_mm, d)))
                .collect();
            if pts.is_empty() {
                continue;
            }
            let rate = rate(s).map_or("no rate".to_string(), |f| format!("rate {:.2}", f.rate));
            series.push(Series::new(
                &format!("{} {label} ({rate})", s.element),
                pts,
                style,
            ));
        }
    }
    if !series.is_empty() {
        let hs: Vec<f64> = series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .collect();
        let (lo, hi) = hs
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &h| (a.min(h), b.max(h)));
        series.push(Series::new(
            &format!("tolerance {:.0e} mm", study.tolerance_mm),
            vec![(lo, study.tolerance_mm), (hi, study.tolerance_mm)],
            LineStyle::Line,
        ));
        let path = out.join("convergence.png");
        line_plot_png(
            &path,
            &series,
            &LinePlot {
                title: format!(
                    "Built-in thigh, {}: displacement difference from the finest mesh ({} grid points)",
                    result.loading, result.common_points
                ),
                x_label: "node spacing h = sqrt(area / nodes) (mm)".into(),
                y_label: "difference from the finest mesh (mm)".into(),
                log_x: true,
                log_y: true,
                legend: LegendPosition::LowerRight,
                ..LinePlot::default()
            },
        )
        .map_err(|source| ConvergenceError::Plot { path, source })?;
    }

    // The locking figure.
    if let Some(l) = &result.locking {
        let mut series = Vec::new();
        for d in [l.d_scale, 1.0] {
            for kind in &study.elements {
                let pts: Vec<(f64, f64)> = result
                    .runs
                    .iter()
                    .filter(|r| r.test == l.test && r.element == kind.deck_name() && r.d_scale == d)
                    .filter_map(|r| r.displacement_ratio.map(|v| (r.h_mm, v)))
                    .collect();
                if !pts.is_empty() {
                    let label = if d == 1.0 {
                        format!("{}, Table 1 D", kind.deck_name())
                    } else {
                        format!("{}, D x {d}", kind.deck_name())
                    };
                    let style = if d == 1.0 {
                        LineStyle::Markers
                    } else {
                        LineStyle::LineAndMarkers
                    };
                    series.push(Series::new(&label, pts, style));
                }
            }
        }
        if !series.is_empty() {
            let path = out.join("locking.png");
            line_plot_png(
                &path,
                &series,
                &LinePlot {
                    title: format!(
                        "Volumetric locking ({}): RMS displacement over the finest {} mesh's",
                        l.test, result.reference_element
                    ),
                    x_label: "node spacing h (mm)".into(),
                    y_label: "RMS |u| / reference RMS |u| (1 = converged, < 1 = too stiff)".into(),
                    log_x: false,
                    log_y: false,
                    // Room above the converged line (1) for the legend.
                    y_range: Some((0.0, 1.45)),
                    legend: LegendPosition::UpperRight,
                    ..LinePlot::default()
                },
            )
            .map_err(|source| ConvergenceError::Plot { path, source })?;
        }
    }

    // The summary.
    let meshes = match &study.meshes {
        MeshSequence::TargetElements(v) => json!({ "target_elements": v }),
        MeshSequence::ElementSizes(v) => json!({ "element_size_mm": v }),
    };
    let summary = json!({
        "femu_version": env!("CARGO_PKG_VERSION"),
        "command": "convergence",
        "inputs": {
            "thigh": study.thigh,
            "materials": study.materials.iter().map(|m| {
                let value = |name: &str| m.law.parameter_index(name).map(|k| m.law.parameter(k));
                json!({
                    "region": m.name,
                    "c10_kpa": value("C10").map(|c| c * 1e3),
                    "d_per_mpa": value("D"),
                })
            }).collect::<Vec<_>>(),
            "loading": result.loading,
            "loading_detail": format!("{:?}", study.loading),
            "elements": study.elements.iter().map(|k| k.deck_name()).collect::<Vec<_>>(),
            "meshes": meshes,
            "tolerance_mm": study.tolerance_mm,
            "locking": study.locking,
            "d_scale": study.d_scale,
            "grid": {
                "origin_mm": study.grid.origin_mm,
                "spacing_mm": study.grid.spacing_mm,
                "counts": study.grid.counts,
            },
        },
        "grid_points": result.grid_points,
        "common_points": result.common_points,
        "masked_points": result.masked_points,
        "reference_element": result.reference_element,
        "raster_mm": result.raster_mm,
        "recommended": result.recommended.as_ref().map(|(e, m)| {
            let r = result.runs.iter().find(|r| {
                r.test == result.loading && &r.element == e && r.mesh == *m && r.d_scale == 1.0
            });
            json!({
                "element": e,
                "mesh": m + 1,
                "elements": r.map(|r| r.elements),
                "nodes": r.map(|r| r.nodes),
                "h_mm": r.map(|r| r.h_mm),
                "max_diff_mm": r.and_then(|r| r.max_diff_mm),
                "solve_s": r.map(|r| r.solve_s),
            })
        }),
        "recommendation": result.recommendation,
        "per_element": result.elements,
        "locking": result.locking,
        "total_s": result.total_s,
    });
    let text =
        serde_json::to_string_pretty(&summary).map_err(|e| io_err(&out.join("summary.json"), e))?;
    write(&out.join("summary.json"), &text)
}
