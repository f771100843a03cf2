//! Fields on a mesh: one value per element or per node, drawn on the reference or the deformed
//! shape, with a colour bar, element edges, region boundaries and overlays (a rigid plate, an
//! indenter).
//!
//! The field is rasterised directly (each triangle's pixels coloured by the linearly
//! interpolated value, a quad being split along its 1–3 diagonal), so a nodal field is smooth
//! and a cell field has no seams between elements. Axes keep 1 mm = 1 mm (x right, y up).

use crate::colorbar::{draw_color_bar, ColorBarPlace};
use crate::colormap::ColorMap;
use crate::text::{draw_title, font, tick_label, Sizes};
use crate::{check_range, check_size, de, finite_min_max, Canvas, PlotError};
use femu_mesh::Mesh;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::collections::HashMap;
use std::path::Path;

/// A polyline drawn over a field in thick black: a rigid plate's line, an indenter's circle.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Overlay {
    /// Points (mm), in the same frame as the mesh.
    pub points: Vec<[f64; 2]>,
    /// Whether the last point joins back to the first.
    pub closed: bool,
    /// Text written next to the overlay (empty for none).
    pub label: String,
}

impl Overlay {
    /// An open polyline through `points`.
    pub fn polyline(points: Vec<[f64; 2]>, label: &str) -> Self {
        Overlay {
            points,
            closed: false,
            label: label.to_string(),
        }
    }

    /// A circle of `radius` mm about `center`, as a closed 96-gon.
    pub fn circle(center: [f64; 2], radius: f64, label: &str) -> Self {
        let n = 96;
        let points = (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                [center[0] + radius * t.cos(), center[1] + radius * t.sin()]
            })
            .collect();
        Overlay {
            points,
            closed: true,
            label: label.to_string(),
        }
    }
}

/// Options of [`mesh_field_png`] and [`node_field_png`].
#[derive(Debug, Clone)]
pub struct FieldPlot<'a> {
    /// Title above the picture.
    pub title: String,
    /// Name and unit of the values, written along the colour bar (e.g. `"LE11 (-)"`).
    pub value_label: String,
    /// Axis descriptions (default `"x (mm)"`, `"y (mm)"`).
    pub x_label: String,
    pub y_label: String,
    /// A blue–white–red map symmetric about zero (signed data such as strains) instead of
    /// viridis (one-sided data such as stiffness or an error magnitude).
    pub diverging: bool,
    /// The value range of the colour map; by default the minimum and maximum of the finite
    /// values (for a diverging map, the range is made symmetric: `±max(|lo|, |hi|)`).
    pub range: Option<(f64, f64)>,
    /// Thin element edges: `Some(true)` always, `Some(false)` never, `None` (default) when there
    /// are at most 5000 elements and they are at least 5 px wide.
    pub edges: Option<bool>,
    /// Region of each element: edges between elements of different regions are drawn in black.
    pub region_of_element: Option<&'a [usize]>,
    /// Thick black polylines drawn over the field.
    pub overlays: Vec<Overlay>,
    /// Magnification of the displacement when the deformed shape is drawn (default 1: true
    /// scale).
    pub displacement_scale: f64,
    /// With a displacement, also draw the outline of the reference shape (dashed grey).
    pub show_reference_outline: bool,
    /// Picture size (px).
    pub width: u32,
    pub height: u32,
}

impl Default for FieldPlot<'_> {
    fn default() -> Self {
        FieldPlot {
            title: String::new(),
            value_label: String::new(),
            x_label: "x (mm)".into(),
            y_label: "y (mm)".into(),
            diverging: false,
            range: None,
            edges: None,
            region_of_element: None,
            overlays: Vec::new(),
            displacement_scale: 1.0,
            show_reference_outline: false,
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// Writes a PNG of `cell_values` (one per element, in element order) on `mesh` to `path`.
///
/// With `displacement` (`[ux0, uy0, ux1, ...]`, mm, one pair per node) the deformed shape
/// `x = X + displacement_scale · u` is drawn. NaN values are drawn grey and left out of the
/// automatic range.
pub fn mesh_field_png(
    path: &Path,
    mesh: &Mesh,
    displacement: Option<&[f64]>,
    cell_values: &[f64],
    opts: &FieldPlot,
) -> Result<(), PlotError> {
    if cell_values.len() != mesh.elements.len() {
        return Err(PlotError::LengthMismatch {
            what: "cell values (one per element)".into(),
            expected: mesh.elements.len(),
            found: cell_values.len(),
        });
    }
    draw_field(path, mesh, displacement, Values::Cell(cell_values), opts)
}

/// Writes a PNG of `node_values` (one per node) on `mesh` to `path`: the value is interpolated
/// linearly over each triangle (quads split along their 1–3 diagonal), so the picture is smooth.
///
/// Displacement, options and NaN handling as in [`mesh_field_png`]; a triangle with a NaN
/// corner is drawn grey.
pub fn node_field_png(
    path: &Path,
    mesh: &Mesh,
    displacement: Option<&[f64]>,
    node_values: &[f64],
    opts: &FieldPlot,
) -> Result<(), PlotError> {
    if node_values.len() != mesh.nodes.len() {
        return Err(PlotError::LengthMismatch {
            what: "node values (one per node)".into(),
            expected: mesh.nodes.len(),
            found: node_values.len(),
        });
    }
    draw_field(path, mesh, displacement, Values::Node(node_values), opts)
}

#[derive(Clone, Copy)]
enum Values<'a> {
    Cell(&'a [f64]),
    Node(&'a [f64]),
}

impl Values<'_> {
    fn all(&self) -> &[f64] {
        match self {
            Values::Cell(v) | Values::Node(v) => v,
        }
    }
}

/// Checks the inputs shared by both field functions and returns the drawn node positions.
fn validate(
    mesh: &Mesh,
    displacement: Option<&[f64]>,
    opts: &FieldPlot,
) -> Result<Vec<[f64; 2]>, PlotError> {
    check_size(opts.width, opts.height)?;
    check_range("value range", opts.range)?;
    if mesh.elements.is_empty() || mesh.nodes.is_empty() {
        return Err(PlotError::Empty("the mesh has no element".into()));
    }
    if !(opts.displacement_scale.is_finite()) {
        return Err(PlotError::InvalidOption(format!(
            "displacement scale {} is not finite",
            opts.displacement_scale
        )));
    }
    let n = mesh.nodes.len();
    for (e, el) in mesh.elements.iter().enumerate() {
        if let Some(&bad) = el.nodes().iter().find(|&&i| i >= n) {
            return Err(PlotError::InvalidData(format!(
                "element {e} refers to node index {bad}, but the mesh has {n} nodes"
            )));
        }
    }
    if let Some(regions) = opts.region_of_element {
        if regions.len() != mesh.elements.len() {
            return Err(PlotError::LengthMismatch {
                what: "region_of_element (one per element)".into(),
                expected: mesh.elements.len(),
                found: regions.len(),
            });
        }
    }
    for (i, o) in opts.overlays.iter().enumerate() {
        if o.points.iter().flatten().any(|c| !c.is_finite()) {
            return Err(PlotError::InvalidData(format!(
                "overlay {i} ('{}') has a non-finite point",
                o.label
            )));
        }
    }
    let mut pos = mesh.nodes.clone();
    if let Some(u) = displacement {
        if u.len() != 2 * n {
            return Err(PlotError::LengthMismatch {
                what: "displacement ([ux, uy] per node)".into(),
                expected: 2 * n,
                found: u.len(),
            });
        }
        for (i, p) in pos.iter_mut().enumerate() {
            p[0] += opts.displacement_scale * u[2 * i];
            p[1] += opts.displacement_scale * u[2 * i + 1];
        }
    }
    for (i, p) in pos.iter().enumerate() {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(PlotError::InvalidData(format!(
                "node {i} has a non-finite (displaced) position {p:?}"
            )));
        }
    }
    Ok(pos)
}

/// The colour map of the plot: the user's range or the finite data's, symmetric if diverging.
fn color_map(values: &[f64], opts: &FieldPlot) -> Result<ColorMap, PlotError> {
    let (lo, hi) = match opts.range {
        Some(r) => r,
        None => finite_min_max(values.iter().copied()).ok_or_else(|| {
            PlotError::InvalidData("every value is NaN or infinite; give a range".into())
        })?,
    };
    Ok(ColorMap::new(lo, hi, opts.diverging))
}

/// The edges of the mesh, each with the element(s) that share it.
fn edge_map(mesh: &Mesh) -> Vec<([usize; 2], usize, Option<usize>)> {
    let mut map: HashMap<[usize; 2], usize> = HashMap::new();
    let mut edges: Vec<([usize; 2], usize, Option<usize>)> = Vec::new();
    for (e, el) in mesh.elements.iter().enumerate() {
        for f in 0..el.face_count() {
            let [a, b] = el.face_nodes(f);
            let key = [a.min(b), a.max(b)];
            match map.get(&key) {
                Some(&k) => edges[k].2 = Some(e),
                None => {
                    map.insert(key, edges.len());
                    edges.push(([a, b], e, None));
                }
            }
        }
    }
    edges
}

/// Layout of a field picture: the plot rectangle keeps equal scales on both axes.
struct FieldLayout {
    /// Data ranges of the axes (mm).
    x: (f64, f64),
    y: (f64, f64),
    /// Plot rectangle: left, top, width, height (px).
    left: u32,
    top: u32,
    pw: u32,
    ph: u32,
    /// Label area sizes (px): left of and below the plot.
    yla: u32,
    xla: u32,
    /// The colour bar (beside the plot rectangle).
    bar: ColorBarPlace,
}

fn layout(bbox: ([f64; 2], [f64; 2]), opts: &FieldPlot, s: Sizes) -> FieldLayout {
    let (lo, hi) = bbox;
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let pad = 0.03 * size;
    let (dx, dy) = (
        (hi[0] - lo[0] + 2.0 * pad).max(1e-9),
        (hi[1] - lo[1] + 2.0 * pad).max(1e-9),
    );
    let (cx, cy) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
    let (yla, xla) = (s.px(100.0), s.px(80.0));
    let (cb_gap, cb_w, cb_la) = (s.px(40.0), s.px(34.0), s.px(140.0));
    let cb_band = cb_gap + cb_w + cb_la + s.px(12.0);
    let avail_left = yla + s.px(16.0);
    let avail_top = s.title_band() + s.px(10.0);
    let aw = opts.width.saturating_sub(avail_left + cb_band).max(20);
    let ah = opts
        .height
        .saturating_sub(avail_top + xla + s.px(10.0))
        .max(20);
    let scale = (aw as f64 / dx).min(ah as f64 / dy);
    let pw = ((scale * dx).floor() as u32).clamp(10, aw);
    let ph = ((scale * dy).floor() as u32).clamp(10, ah);
    // Exact equal scales after rounding: widen the data range of the looser direction.
    let k = (pw as f64 / dx).min(ph as f64 / dy);
    let (hx, hy) = (0.5 * pw as f64 / k, 0.5 * ph as f64 / k);
    let left = avail_left + (aw - pw) / 2;
    let top = avail_top + (ah - ph) / 2;
    FieldLayout {
        x: (cx - hx, cx + hx),
        y: (cy - hy, cy + hy),
        left,
        top,
        pw,
        ph,
        yla,
        xla,
        bar: ColorBarPlace {
            left: left + pw + cb_gap,
            top,
            width: cb_w,
            height: ph,
            label_width: cb_la,
        },
    }
}

fn draw_field(
    path: &Path,
    mesh: &Mesh,
    displacement: Option<&[f64]>,
    values: Values,
    opts: &FieldPlot,
) -> Result<(), PlotError> {
    let pos = validate(mesh, displacement, opts)?;
    let cmap = color_map(values.all(), opts)?;
    let any_nan = values.all().iter().any(|v| v.is_nan());
    let s = Sizes::new(opts.width, opts.height);

    // Bounding box of everything drawn.
    let mut pts: Vec<[f64; 2]> = pos.clone();
    if displacement.is_some() && opts.show_reference_outline {
        pts.extend_from_slice(&mesh.nodes);
    }
    for o in &opts.overlays {
        pts.extend_from_slice(&o.points);
    }
    let bx = finite_min_max(pts.iter().map(|p| p[0])).unwrap_or((0.0, 1.0));
    let by = finite_min_max(pts.iter().map(|p| p[1])).unwrap_or((0.0, 1.0));
    let lay = layout(([bx.0, by.0], [bx.1, by.1]), opts, s);
    let edges = edge_map(mesh);

    let canvas = Canvas::new(opts.width, opts.height);
    canvas.draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let area = root.clone().shrink(
            (lay.left - lay.yla, lay.top),
            (lay.yla + lay.pw, lay.ph + lay.xla),
        );
        let mut chart = ChartBuilder::on(&area)
            .margin(0)
            .y_label_area_size(lay.yla)
            .x_label_area_size(lay.xla)
            .build_cartesian_2d(lay.x.0..lay.x.1, lay.y.0..lay.y.1)
            .map_err(de)?;

        rasterise(root, &chart, mesh, &pos, values, &cmap)?;

        // Thin element edges, when asked or when they stay visible.
        let mean_px = (lay.pw as f64 * lay.ph as f64 / mesh.elements.len() as f64).sqrt()
            * mesh_fill_fraction(mesh, &pos, &lay);
        let draw_edges = opts
            .edges
            .unwrap_or(mesh.elements.len() <= 5000 && mean_px >= 5.0);
        let seg = |a: usize, b: usize| vec![(pos[a][0], pos[a][1]), (pos[b][0], pos[b][1])];
        if draw_edges {
            chart
                .draw_series(
                    edges
                        .iter()
                        .map(|(n, _, _)| PathElement::new(seg(n[0], n[1]), BLACK.mix(0.35))),
                )
                .map_err(de)?;
        }
        // The reference outline (dashed grey) under the deformed shape.
        if displacement.is_some() && opts.show_reference_outline {
            let dash = s.px(6.0);
            for (n, _, other) in &edges {
                if other.is_none() {
                    let p = [mesh.nodes[n[0]], mesh.nodes[n[1]]].map(|q| (q[0], q[1]));
                    chart
                        .draw_series(std::iter::once(DashedPathElement::new(
                            p,
                            dash,
                            dash,
                            RGBColor(110, 110, 110).stroke_width(s.px(1.5)),
                        )))
                        .map_err(de)?;
                }
            }
        }
        // Boundary of the body, and edges between regions.
        chart
            .draw_series(
                edges
                    .iter()
                    .filter(|(_, _, o)| o.is_none())
                    .map(|(n, _, _)| {
                        PathElement::new(seg(n[0], n[1]), BLACK.stroke_width(s.px(1.5)))
                    }),
            )
            .map_err(de)?;
        if let Some(region) = opts.region_of_element {
            chart
                .draw_series(
                    edges
                        .iter()
                        .filter(|(_, e, o)| o.is_some_and(|o| region[o] != region[*e]))
                        .map(|(n, _, _)| {
                            PathElement::new(seg(n[0], n[1]), BLACK.stroke_width(s.px(2.5)))
                        }),
                )
                .map_err(de)?;
        }
        // Overlays and their labels.
        for o in &opts.overlays {
            let mut p: Vec<(f64, f64)> = o.points.iter().map(|q| (q[0], q[1])).collect();
            if o.closed && p.len() > 2 {
                p.push(p[0]);
            }
            chart
                .draw_series(std::iter::once(PathElement::new(
                    p.clone(),
                    BLACK.stroke_width(s.px(3.5)),
                )))
                .map_err(de)?;
            if !o.label.is_empty() && !p.is_empty() {
                draw_overlay_label(root, &chart, &p, o.closed, &o.label, &lay, s)?;
            }
        }

        let (x0, x1, y0, y1) = (lay.x.0, lay.x.1, lay.y.0, lay.y.1);
        chart
            .configure_mesh()
            .set_all_tick_mark_size(s.px(7.0))
            .disable_mesh()
            .x_desc(opts.x_label.as_str())
            .y_desc(opts.y_label.as_str())
            .label_style(font(s.tick()))
            .axis_desc_style(font(s.desc()))
            .x_labels(((lay.pw / s.px(110.0)) as usize).clamp(3, 12))
            .y_labels(((lay.ph / s.px(70.0)) as usize).clamp(3, 12))
            .x_label_formatter(&|v| tick_label(*v, x0, x1))
            .y_label_formatter(&|v| tick_label(*v, y0, y1))
            .draw()
            .map_err(de)?;

        draw_color_bar(root, &cmap, &opts.value_label, any_nan, lay.bar, s)
    })
}

/// Rough fraction of the plot's side covered by the mesh (to estimate the element size in px).
fn mesh_fill_fraction(mesh: &Mesh, pos: &[[f64; 2]], lay: &FieldLayout) -> f64 {
    let area: f64 = mesh
        .elements
        .iter()
        .map(|el| {
            let n = el.nodes();
            let mut a = 0.0;
            for i in 0..n.len() {
                let (p, q) = (pos[n[i]], pos[n[(i + 1) % n.len()]]);
                a += p[0] * q[1] - q[0] * p[1];
            }
            0.5 * a.abs()
        })
        .sum();
    let plot_area = (lay.x.1 - lay.x.0) * (lay.y.1 - lay.y.0);
    (area / plot_area).clamp(0.0, 1.0).sqrt()
}

type Chart<'c, 'b> =
    ChartContext<'c, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Colours every pixel of the plot rectangle covered by a triangle of the mesh.
fn rasterise(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    chart: &Chart<'_, '_>,
    mesh: &Mesh,
    pos: &[[f64; 2]],
    values: Values,
    cmap: &ColorMap,
) -> Result<(), String> {
    // Affine map data → pixel, from plotters' own mapping of two opposite corners.
    let xr = chart.x_range();
    let yr = chart.y_range();
    let (a0, a1) = (
        chart.backend_coord(&(xr.start, yr.start)),
        chart.backend_coord(&(xr.end, yr.end)),
    );
    let sx = (a1.0 - a0.0) as f64 / (xr.end - xr.start);
    let sy = (a1.1 - a0.1) as f64 / (yr.end - yr.start);
    let to_px = |p: [f64; 2]| {
        (
            a0.0 as f64 + (p[0] - xr.start) * sx,
            a0.1 as f64 + (p[1] - yr.start) * sy,
        )
    };
    let (cx, cy) = chart.plotting_area().get_pixel_range();
    for (e, el) in mesh.elements.iter().enumerate() {
        let n = el.nodes();
        let tris: &[[usize; 3]] = if n.len() == 4 {
            &[[0, 1, 2], [0, 2, 3]]
        } else {
            &[[0, 1, 2]]
        };
        for t in tris {
            let p = t.map(|k| to_px(pos[n[k]]));
            let v = match values {
                Values::Cell(c) => [c[e]; 3],
                Values::Node(v) => t.map(|k| v[n[k]]),
            };
            let area =
                (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
            if area.abs() < 1e-12 {
                continue;
            }
            let xmin =
                (p.iter().map(|q| q.0).fold(f64::INFINITY, f64::min).floor() as i32).max(cx.start);
            let xmax = (p
                .iter()
                .map(|q| q.0)
                .fold(f64::NEG_INFINITY, f64::max)
                .ceil() as i32)
                .min(cx.end - 1);
            let ymin =
                (p.iter().map(|q| q.1).fold(f64::INFINITY, f64::min).floor() as i32).max(cy.start);
            let ymax = (p
                .iter()
                .map(|q| q.1)
                .fold(f64::NEG_INFINITY, f64::max)
                .ceil() as i32)
                .min(cy.end - 1);
            let tol = -1e-9;
            for py in ymin..=ymax {
                for px in xmin..=xmax {
                    let (x, y) = (px as f64, py as f64);
                    let w0 = ((p[1].0 - x) * (p[2].1 - y) - (p[2].0 - x) * (p[1].1 - y)) / area;
                    let w1 = ((p[2].0 - x) * (p[0].1 - y) - (p[0].0 - x) * (p[2].1 - y)) / area;
                    let w2 = 1.0 - w0 - w1;
                    if w0 >= tol && w1 >= tol && w2 >= tol {
                        let val = w0 * v[0] + w1 * v[1] + w2 * v[2];
                        let val = if v.iter().any(|x| x.is_nan()) {
                            f64::NAN
                        } else {
                            val
                        };
                        root.draw_pixel((px, py), &cmap.color(val)).map_err(de)?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Writes an overlay's label. An open line (a rigid plate, which reaches past the body on both
/// sides) has it at an end, clear of the body and of the reference outline the plate has
/// pressed into: a line across the picture just above its right end (or below it when there is
/// no room above), right-aligned; a line along it beside its top end, on the side away from
/// the picture's centre. A closed one (an indenter) has it centred above it. Either falls back
/// to right of the overlay, level with its top, or else below it.
fn draw_overlay_label(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    chart: &Chart<'_, '_>,
    p: &[(f64, f64)],
    closed: bool,
    label: &str,
    lay: &FieldLayout,
    s: Sizes,
) -> Result<(), String> {
    let px: Vec<(i32, i32)> = p.iter().map(|q| chart.backend_coord(q)).collect();
    let x0 = px.iter().map(|q| q.0).min().unwrap_or(0);
    let x1 = px.iter().map(|q| q.0).max().unwrap_or(0);
    let y0 = px.iter().map(|q| q.1).min().unwrap_or(0);
    let y1 = px.iter().map(|q| q.1).max().unwrap_or(0);
    let gap = s.px(8.0) as i32;
    let (w, h) = root
        .estimate_text_size(label, &font(s.legend()))
        .map_err(de)?;
    let (w, h) = (w as i32, h as i32);
    let (left, right) = (lay.left as i32, (lay.left + lay.pw) as i32);
    let (top, bottom) = (lay.top as i32, (lay.top + lay.ph) as i32);
    // An open line: across the picture (wider than tall on screen) or along it.
    let open = !closed && px.len() >= 2;
    let across = x1 - x0 >= y1 - y0;
    // Across: the right end, the label above it (or below), right-aligned along the line.
    let right_end = px
        .iter()
        .copied()
        .max_by_key(|q| (q.0, -q.1))
        .filter(|&(ex, _)| open && across && ex.min(right) - w >= left);
    // Along: the top end, the label beside it on the side away from the picture's centre.
    let outward = x0 > (left + right) / 2;
    let top_end = px.iter().copied().min_by_key(|q| q.1).filter(|&(ex, _)| {
        open && !across
            && if outward {
                ex + gap + w <= right
            } else {
                ex - gap - w >= left
            }
    });
    let (x, y, hp, vp) = if let Some((ex, ey)) = right_end.filter(|&(_, ey)| ey - gap - h >= top) {
        (ex.min(right), ey - gap, HPos::Right, VPos::Bottom)
    } else if let Some((ex, ey)) = right_end.filter(|&(_, ey)| ey + gap + h <= bottom) {
        (ex.min(right), ey + gap, HPos::Right, VPos::Top)
    } else if let Some((ex, ey)) = top_end {
        if outward {
            (ex + gap, ey, HPos::Left, VPos::Top)
        } else {
            (ex - gap, ey, HPos::Right, VPos::Top)
        }
    } else if y0 - gap - h >= top {
        let x = ((x0 + x1) / 2).clamp(left + w / 2, right - w / 2);
        (x, y0 - gap, HPos::Center, VPos::Bottom)
    } else if x1 + gap + w <= right {
        // Level with the overlay's top: an indenter's top is outside the body, its middle at
        // the skin (and the reference outline) it presses into.
        (x1 + gap, y0, HPos::Left, VPos::Top)
    } else {
        let x = ((x0 + x1) / 2).clamp(left + w / 2, right - w / 2);
        (x, y1 + gap, HPos::Center, VPos::Top)
    };
    root.draw(&Text::new(
        label.to_string(),
        (x, y),
        font(s.legend()).pos(Pos::new(hp, vp)),
    ))
    .map_err(de)
}
