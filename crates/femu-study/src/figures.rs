//! The pictures of a solve: the deformed shape coloured by LE11 (the seed's Fig. 3.D–F), and
//! for each rigid body the contact pressure along the skin and the force–travel curve.

use crate::error::{Context, Result};
use femu_mech::output::element_fields;
use femu_mech::{Model, Solution};
use femu_plot::{line_plot_png, mesh_field_png, FieldPlot, LinePlot, LineStyle, Overlay, Series};
use std::path::Path;

/// Writes `deformed_le11.png` into `out`, and `contact_pressure.png` and
/// `force_displacement.png` into each rigid body's folder (`body_dirs`, in body order).
pub(crate) fn write_solve_figures(
    out: &Path,
    body_dirs: &[std::path::PathBuf],
    title: &str,
    model: &Model,
    solution: &Solution,
) -> Result<()> {
    let fields = element_fields(model, &solution.u);
    let le11: Vec<f64> = fields.log_strain.iter().map(|le| le[0]).collect();
    let (lo, hi) = model.mesh.bounding_box();
    let half = 0.6 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let overlays = model
        .contacts
        .iter()
        .zip(&solution.bodies)
        .map(|(c, b)| {
            let pts = c.body.outline(c.first_contact + b.travel, half);
            let closed = pts.len() > 2;
            Overlay {
                points: pts,
                closed,
                label: c.name.clone(),
            }
        })
        .collect();
    let path = out.join("deformed_le11.png");
    mesh_field_png(
        &path,
        &model.mesh,
        Some(&solution.u),
        &le11,
        &FieldPlot {
            title: format!("{title}: logarithmic strain LE11, deformed shape"),
            value_label: "LE11 (-)".into(),
            diverging: true,
            region_of_element: Some(&model.element_region),
            overlays,
            show_reference_outline: true,
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot draw {}", path.display()))?;
    for (b, dir) in body_dirs.iter().enumerate() {
        write_body_figures(dir, model, solution, b)?;
    }
    Ok(())
}

/// Writes `contact_pressure.png` (zoomed on the contact zone) and `force_displacement.png` of
/// rigid body `b` into `dir`.
fn write_body_figures(dir: &Path, model: &Model, solution: &Solution, b: usize) -> Result<()> {
    let c = &model.contacts[b];
    let mut profile: Vec<(f64, f64)> = femu_mech::output::contact_profile(model, solution, b)
        .iter()
        .map(|p| (p.angle_deg, 1e3 * p.pressure))
        .collect();
    profile.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Zoom on the contact zone (with a margin of a few nodes on each side).
    let active: Vec<f64> = profile.iter().filter(|p| p.1 > 0.0).map(|p| p.0).collect();
    let x_range = match (
        active.iter().copied().reduce(f64::min),
        active.iter().copied().reduce(f64::max),
    ) {
        (Some(a), Some(z)) => {
            let m = (0.3 * (z - a)).max(2.0);
            Some((a - m, z + m))
        }
        _ => None,
    };
    let path = dir.join("contact_pressure.png");
    line_plot_png(
        &path,
        &[Series::new(
            "contact pressure",
            profile,
            LineStyle::LineAndMarkers,
        )],
        &LinePlot {
            title: format!("{}: contact pressure along the skin", c.name),
            x_label: "position around the section centre (deg)".into(),
            y_label: "contact pressure (kPa)".into(),
            x_range,
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot draw {}", path.display()))?;
    let mut curve = vec![(0.0, 0.0)];
    curve.extend(
        solution
            .report
            .force_travel(b)
            .into_iter()
            .map(|[t, f]| (t, f)),
    );
    let path = dir.join("force_displacement.png");
    line_plot_png(
        &path,
        &[Series::new(&c.name, curve, LineStyle::LineAndMarkers)],
        &LinePlot {
            title: format!("{}: force against travel beyond first contact", c.name),
            x_label: "travel (mm)".into(),
            y_label: "force (N per mm of thickness)".into(),
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot draw {}", path.display()))?;
    Ok(())
}
