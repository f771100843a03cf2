//! The identification from images in the report: integrated DIC beside DIC → FEMU (plain and
//! weighted by the DIC's covariance) on the same frames, errors and intervals side by side, the
//! frames, the grey-level residual before and after, the identified and the measured
//! displacement over the image.

use super::{esc, g, pct, Html};
use crate::steps::identify::IdentificationSummary;
use crate::steps::images::ImageIdentificationSummary;
use crate::steps::ultrasound::SimSummary;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One grouping's identification from images in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImageOverview {
    pub parameters: Vec<RouteRow>,
    pub idic_s: f64,
    pub dic_femu_s: f64,
    pub dic_weighted_s: f64,
    pub notes: Vec<String>,
}

/// One parameter by the three routes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RouteRow {
    pub name: String,
    pub reference: Option<f64>,
    pub idic: f64,
    pub idic_error: Option<f64>,
    pub idic_ci95: [f64; 2],
    pub idic_seen: bool,
    pub dic: f64,
    pub dic_error: Option<f64>,
    pub dic_ci95: [f64; 2],
    /// Which term set the DIC → FEMU interval's width (`femu_identify::misfit_intervals`).
    #[serde(default)]
    pub dic_width_from: Option<String>,
    pub weighted: f64,
    pub weighted_error: Option<f64>,
    pub weighted_ci95: [f64; 2],
    #[serde(default)]
    pub weighted_width_from: Option<String>,
}

/// Whether `dir` holds an identification from images (the routes' folders).
pub fn is_image_route(dir: &Path) -> bool {
    dir.join("dic").join("summary.json").is_file() && dir.join("dic-weighted").is_dir()
}

/// The section of one grouping (`identify/GROUPING/`); `measurement` is the run's measurement
/// folder (frames, DIC maps).
pub fn section(
    html: &mut Html,
    grouping: &str,
    dir: &Path,
    measurement: &Path,
) -> Option<ImageOverview> {
    let idic: ImageIdentificationSummary = html.read(&dir.join("summary.json"))?;
    let dic: IdentificationSummary = html.read(&dir.join("dic").join("summary.json"))?;
    let weighted: IdentificationSummary =
        html.read(&dir.join("dic-weighted").join("summary.json"))?;
    let sim: Option<SimSummary> = html.read(&measurement.join("summary.json"));
    html.h3(&format!("{grouping}: integrated DIC beside DIC → FEMU"));
    let dic_s = sim.as_ref().map_or(0.0, |s| s.timings_s.dic);
    let dic_route = dic_s + dic.wall_time_s;
    html.p(&method(&idic, dic_s, dic.wall_time_s));
    let rows = route_rows(&idic, &dic, &weighted);
    route_table(html, &rows);
    if !idic.notes.is_empty() {
        html.p(&format!(
            "* {}",
            idic.notes
                .iter()
                .map(|n| esc(n))
                .collect::<Vec<_>>()
                .join(" ")
        ));
    }
    figures(html, grouping, dir, measurement, idic.load_fractions.len());
    Some(ImageOverview {
        parameters: rows,
        idic_s: idic.wall_time_s,
        dic_femu_s: dic_route,
        dic_weighted_s: weighted.wall_time_s,
        notes: idic.notes,
    })
}

/// The paragraph on how the images were compared and the intervals made, and the times of
/// the two routes (`dic_s`: the DIC's, `femu_s`: the FEMU's on its field).
fn method(idic: &ImageIdentificationSummary, dic_s: f64, femu_s: f64) -> String {
    let dic_route = dic_s + femu_s;
    format!(
        "Integrated DIC (I-DIC, Leclerc et al. 2009): the parameters from the grey levels of the {} \
         frames ({}) directly, each load step's frame compared with {} at the \
         material points the finite-element model of that step moves ({} elements; {} pixels in \
         the tissue, {} in the bone's shadow, {} outside the tissue, masked by the model). \
         Brightness and contrast per depth band{}; coarse to fine over Gaussian smoothings of {} px. \
         Intervals: the larger of the block sandwich ({} blocks: the residual's own correlation) \
         and the jackknife over {} image regions, with the bias refined meshes of {} elements \
         imply (each extrapolated at the first-order rate, the parameters the images do not see \
         held as the identification holds them; the larger) and the change from the last smoothed scale added in quadrature. Time: {:.1} s (identification {:.1} s, discretization check \
         {:.1} s) against {:.1} s for the DIC → FEMU route (DIC {:.1} s, FEMU {:.1} s): ratio {:.2}.",
        idic.load_fractions.len() + 1,
        esc(&idic.source),
        match idic.pairing {
            femu_identify::idic::Pairing::Reference => "the unloaded one",
            femu_identify::idic::Pairing::Consecutive => "the one before it",
            femu_identify::idic::Pairing::Both => "the one before it and with the unloaded one",
            femu_identify::idic::Pairing::All => "every frame before it",
        },
        idic.elements,
        idic.pixels,
        idic.mask.shadow,
        idic.mask.outside,
        idic.local_normalization_px.map_or(String::new(), |w| format!(
            ", the frames locally normalized over {w} px (compared as their local patterns, not their local brightness)"
        )),
        idic.scales
            .iter()
            .map(|s| g(s.scale_px))
            .collect::<Vec<_>>()
            .join(", "),
        idic.sandwich_blocks,
        idic.jackknife_groups,
        // Every refined mesh of the discretization term (older summaries: the first only).
        match (&idic.mesh_correction, idic.refined_elements) {
            (Some(m), _) if !m.elements.is_empty() => m
                .elements
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" and "),
            (_, first) => first.map_or("(none)".to_string(), |n| n.to_string()),
        },
        idic.wall_time_s,
        idic.identification_s,
        idic.discretization_s,
        dic_route,
        dic_s,
        femu_s,
        idic.wall_time_s / dic_route.max(1e-9),
    )
}

/// Each parameter by the three routes.
fn route_rows(
    idic: &ImageIdentificationSummary,
    dic: &IdentificationSummary,
    weighted: &IdentificationSummary,
) -> Vec<RouteRow> {
    idic.parameters
        .iter()
        .zip(&dic.parameters)
        .zip(&weighted.parameters)
        .map(|((p, q), w)| RouteRow {
            name: p.name.clone(),
            reference: p.reference,
            idic: p.identified,
            idic_error: p.relative_error,
            idic_ci95: p.ci95,
            idic_seen: p.seen,
            dic: q.identified,
            dic_error: q.relative_error,
            dic_ci95: q.ci95,
            dic_width_from: q.width_from.clone(),
            weighted: w.identified,
            weighted_error: w.relative_error,
            weighted_ci95: w.ci95,
            weighted_width_from: w.width_from.clone(),
        })
        .collect()
}

/// The table of the three routes: value (error) [95 % interval] of each parameter.
fn route_table(html: &mut Html, rows: &[RouteRow]) {
    let cell = |v: f64, e: Option<f64>, ci: [f64; 2]| {
        format!(
            "{}{} [{}, {}]",
            g(v),
            e.map_or(String::new(), |e| format!(" ({})", pct(e))),
            g(ci[0]),
            g(ci[1])
        )
    };
    // The DIC routes' widths: which term set each (Fisher, Birge ratio, depth-block jackknife).
    let dic_cell = |v: f64, e: Option<f64>, ci: [f64; 2], from: &Option<String>| {
        let c = cell(v, e, ci);
        match from {
            Some(f) => format!("{c}, width set by: {f}"),
            None => c,
        }
    };
    let table: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                format!(
                    "{} ({}){}",
                    r.name,
                    super::internal_unit(&r.name),
                    if r.idic_seen { "" } else { " *" }
                ),
                r.reference.map(g).unwrap_or("-".into()),
                cell(r.idic, r.idic_error, r.idic_ci95),
                dic_cell(r.dic, r.dic_error, r.dic_ci95, &r.dic_width_from),
                dic_cell(
                    r.weighted,
                    r.weighted_error,
                    r.weighted_ci95,
                    &r.weighted_width_from,
                ),
            ]
        })
        .collect();
    html.table(
        &[
            "parameter (unit)",
            "reference",
            "I-DIC (error) [95 % interval]",
            "DIC → FEMU, one weight per point",
            "DIC → FEMU, DIC covariance + Huber",
        ],
        &table,
    );
}

/// The frames, the grey-level residuals and the identified and measured displacements
/// (`last`: the index of the frame at the full load).
fn figures(html: &mut Html, grouping: &str, dir: &Path, measurement: &Path, last: usize) {
    for (path, caption) in [
        (
            measurement.join("frame_00.png"),
            "Unloaded frame.".to_string(),
        ),
        (
            measurement.join(format!("frame_{last:02}.png")),
            "Frame at the full load.".to_string(),
        ),
        (
            dir.join("residual_before.png"),
            "Grey-level residual of the last load step before correlation (tissue at rest)."
                .to_string(),
        ),
        (
            dir.join("residual_after.png"),
            "Grey-level residual of the last load step at the I-DIC optimum.".to_string(),
        ),
        (
            dir.join("displacement_uy.png"),
            "Identified model (I-DIC): displacement uy over the unloaded image.".to_string(),
        ),
        (
            measurement.join("uy_dic.png"),
            "Measured by the incremental DIC: uy over the unloaded image.".to_string(),
        ),
        (
            dir.join("displacement_ux.png"),
            "Identified model (I-DIC): displacement ux over the unloaded image.".to_string(),
        ),
        (
            measurement.join("ux_dic.png"),
            "Measured by the incremental DIC: ux over the unloaded image.".to_string(),
        ),
    ] {
        html.figure(&path, &format!("{grouping}: {caption}"));
    }
}
