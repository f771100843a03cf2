//! A PNG picture of the regions of a meshed thigh: elements filled with the colour of their
//! region, element edges, the femur edge and the skin in black, axes in mm and a legend.
//!
//! Drawn with `plotters`' bitmap backend; text uses the DejaVu Sans font embedded by the
//! `dejavu` crate (no system font library needed), and the PNG is encoded by `image`.

use crate::mesher::ThighModel;
use crate::GeometryError;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::Once;

/// The colour of a region: the seed's five tissues have fixed colours, others a palette's.
pub fn region_colour(name: &str, index: usize) -> RGBColor {
    match name {
        "FAT" => RGBColor(250, 215, 120),
        "QUADRICEPS" => RGBColor(214, 82, 72),
        "ISCHIO" => RGBColor(140, 80, 170),
        "GRACILIS" => RGBColor(60, 130, 215),
        "SARTORIUS" => RGBColor(60, 170, 95),
        _ => {
            const PALETTE: [RGBColor; 6] = [
                RGBColor(230, 140, 40),
                RGBColor(40, 180, 180),
                RGBColor(200, 90, 160),
                RGBColor(120, 120, 120),
                RGBColor(150, 190, 60),
                RGBColor(90, 90, 200),
            ];
            PALETTE[index % PALETTE.len()]
        }
    }
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is a valid TrueType file; a failure would only lose the text.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

/// Writes the picture of `model` to `path` (PNG), `width` pixels wide (the height follows the
/// model's aspect ratio), with `title` above it.
pub fn write_regions_png(
    model: &ThighModel,
    path: &Path,
    width: u32,
    title: &str,
) -> Result<(), GeometryError> {
    register_font();
    let err = |message: String| GeometryError::Picture {
        path: path.to_path_buf(),
        message,
    };
    let m = &model.mesh.mesh;
    let (lo, hi) = m.bounding_box();
    let pad = 0.04 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let (x0, x1) = (lo[0] - pad, hi[0] + pad);
    let (y0, y1) = (lo[1] - pad, hi[1] + pad);
    // Plot area keeps 1 mm = 1 mm; margins for the axes, the title and the legend.
    let (left, bottom, top, right) = (70u32, 60u32, 50u32, 190u32);
    let plot_w = width.saturating_sub(left + right).max(200);
    let plot_h = ((plot_w as f64) * (y1 - y0) / (x1 - x0)).round() as u32;
    let (w, h) = (plot_w + left + right, plot_h + bottom + top);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let (plot, legend_area) = root.split_horizontally(w - right + 10);
        let mut chart = ChartBuilder::on(&plot)
            .caption(title, ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(bottom - 10)
            .y_label_area_size(left - 10)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x (mm)")
            .y_desc("y (mm)")
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 15))
            .draw()
            .map_err(|e| err(e.to_string()))?;
        let poly = |e: usize| -> Vec<(f64, f64)> {
            m.elements[e]
                .nodes()
                .iter()
                .map(|&n| (m.nodes[n][0], m.nodes[n][1]))
                .collect()
        };
        // Edges are drawn only if they stay visible (at least ~3 px per element).
        let px_per_mm = plot_w as f64 / (x1 - x0);
        let draw_edges = model.element_size_mm * px_per_mm >= 3.0;
        for (r, name) in model.regions.iter().enumerate() {
            let colour = region_colour(name, r);
            let set = m.element_set(name).unwrap_or(&[]);
            chart
                .draw_series(set.iter().map(|&e| Polygon::new(poly(e), colour.filled())))
                .map_err(|e| err(e.to_string()))?;
            if draw_edges {
                let edge = RGBColor(
                    (colour.0 as f64 * 0.55) as u8,
                    (colour.1 as f64 * 0.55) as u8,
                    (colour.2 as f64 * 0.55) as u8,
                );
                chart
                    .draw_series(set.iter().map(|&e| {
                        let mut p = poly(e);
                        p.push(p[0]);
                        PathElement::new(p, edge.stroke_width(1))
                    }))
                    .map_err(|e| err(e.to_string()))?;
            }
        }
        // The faces of a surface as line segments.
        let face_paths = |faces: &[(usize, usize)], style: ShapeStyle| {
            faces
                .iter()
                .map(|&(e, f)| {
                    let [a, b] = m.elements[e].face_nodes(f);
                    PathElement::new(
                        vec![
                            (m.nodes[a][0], m.nodes[a][1]),
                            (m.nodes[b][0], m.nodes[b][1]),
                        ],
                        style,
                    )
                })
                .collect::<Vec<_>>()
        };
        for (surface, colour, width) in [("SKIN", BLACK, 2), ("FEMUR", BLACK, 3)] {
            let faces = model
                .mesh
                .surfaces
                .get(surface)
                .map_or(&[][..], Vec::as_slice);
            chart
                .draw_series(face_paths(faces, colour.stroke_width(width)))
                .map_err(|e| err(e.to_string()))?;
        }
        // Sliding interfaces (surfaces `INTERFACE_*`, where the mesh is split): a white line
        // on a dark one, over the edges.
        let interfaces: Vec<&Vec<(usize, usize)>> = model
            .mesh
            .surfaces
            .iter()
            .filter(|(name, _)| name.starts_with("INTERFACE_"))
            .map(|(_, faces)| faces)
            .collect();
        for (colour, width) in [(RGBColor(20, 20, 20), 5), (WHITE, 2)] {
            for faces in &interfaces {
                chart
                    .draw_series(face_paths(faces, colour.stroke_width(width)))
                    .map_err(|e| err(e.to_string()))?;
            }
        }
        // Legend: a swatch and the name of each region, its element count and area.
        let areas = model.region_areas();
        let font = ("sans-serif", 14).into_font();
        let mut y = top as i32 + 10;
        legend_area
            .draw(&Text::new("regions", (8, y), font.clone()))
            .map_err(|e| err(e.to_string()))?;
        y += 24;
        for (r, name) in model.regions.iter().enumerate() {
            let colour = region_colour(name, r);
            legend_area
                .draw(&Rectangle::new([(8, y), (26, y + 14)], colour.filled()))
                .map_err(|e| err(e.to_string()))?;
            legend_area
                .draw(&Rectangle::new(
                    [(8, y), (26, y + 14)],
                    BLACK.stroke_width(1),
                ))
                .map_err(|e| err(e.to_string()))?;
            let n = m.element_set(name).map_or(0, <[usize]>::len);
            legend_area
                .draw(&Text::new(name.to_lowercase(), (32, y), font.clone()))
                .map_err(|e| err(e.to_string()))?;
            legend_area
                .draw(&Text::new(
                    format!("{n} el., {:.0} mm²", areas[name]),
                    (32, y + 15),
                    ("sans-serif", 11).into_font(),
                ))
                .map_err(|e| err(e.to_string()))?;
            y += 38;
        }
        legend_area
            .draw(&PathElement::new(
                vec![(8, y + 7), (26, y + 7)],
                BLACK.stroke_width(3),
            ))
            .map_err(|e| err(e.to_string()))?;
        legend_area
            .draw(&Text::new("femur (fixed)", (32, y), font.clone()))
            .map_err(|e| err(e.to_string()))?;
        y += 24;
        legend_area
            .draw(&PathElement::new(
                vec![(8, y + 7), (26, y + 7)],
                BLACK.stroke_width(2),
            ))
            .map_err(|e| err(e.to_string()))?;
        legend_area
            .draw(&Text::new("skin", (32, y), font.clone()))
            .map_err(|e| err(e.to_string()))?;
        if !interfaces.is_empty() {
            y += 24;
            for (colour, width) in [(RGBColor(20, 20, 20), 5), (WHITE, 2)] {
                legend_area
                    .draw(&PathElement::new(
                        vec![(8, y + 7), (26, y + 7)],
                        colour.stroke_width(width),
                    ))
                    .map_err(|e| err(e.to_string()))?;
            }
            legend_area
                .draw(&Text::new("sliding interface", (32, y), font.clone()))
                .map_err(|e| err(e.to_string()))?;
            legend_area
                .draw(&Text::new(
                    "(nodes split)",
                    (32, y + 15),
                    ("sans-serif", 11).into_font(),
                ))
                .map_err(|e| err(e.to_string()))?;
        }
        root.present().map_err(|e| err(e.to_string()))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| err("picture buffer has the wrong size".into()))?;
    femu_mesh::atomic::write_with(path, |f| img.write_to(f, image::ImageFormat::Png))
        .map_err(|e| err(e.to_string()))
}
