//! Writes one sample picture of each kind of figure into a folder:
//!
//! ```sh
//! cargo run -p femu-plot --example gallery -- OUTDIR
//! ```
//!
//! The data are synthetic but shaped like femu's: an annulus (femur hole, two layers) squashed
//! by a rigid plate, Newton load curves, a mesh-convergence study, identification errors per
//! tissue and a speckle grey-level histogram. The test suite runs this example too
//! (`tests/gallery.rs`).

use femu_mesh::{generate, ElementKind, Mesh};
use femu_plot::{
    bar_chart_png, histogram_png, line_plot_png, mesh_field_png, node_field_png, BarChart,
    FieldPlot, Histogram, LegendPosition, LinePlot, LineStyle, Overlay, PlotError, Series,
};
use std::path::{Path, PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("femu-plot-gallery"));
    std::fs::create_dir_all(&dir)?;
    for p in write_gallery(&dir)? {
        println!("{}", p.display());
    }
    Ok(())
}

/// The synthetic displacement of the squashed annulus (mm): the top moves down 8 mm, the
/// sides bulge. Returns `(ux, uy)` and `d ux / dx`.
fn squash(x: f64, y: f64) -> ((f64, f64), f64) {
    let t = (y + 60.0) / 120.0;
    let ux = 0.1 * x * t - 0.03 * x;
    let uy = -8.0 * t * t;
    ((ux, uy), 0.1 * t - 0.03)
}

fn centroid(mesh: &Mesh, e: usize) -> [f64; 2] {
    let n = mesh.elements[e].nodes();
    let mut c = [0.0; 2];
    for &i in n {
        c[0] += mesh.nodes[i][0] / n.len() as f64;
        c[1] += mesh.nodes[i][1] / n.len() as f64;
    }
    c
}

/// Writes the sample pictures into `dir` and returns their paths.
pub fn write_gallery(dir: &Path) -> Result<Vec<PathBuf>, PlotError> {
    let mut written = Vec::new();
    let g = generate::annulus(14.0, 40.0, 60.0, 64, 6, 4, ElementKind::Cpe4);
    let mesh = &g.mesh;
    let mut region = vec![0usize; mesh.elements.len()];
    for &e in mesh.element_sets.get("OUTER_LAYER").into_iter().flatten() {
        region[e] = 1;
    }
    let mut u = Vec::with_capacity(2 * mesh.nodes.len());
    for p in &mesh.nodes {
        let ((ux, uy), _) = squash(p[0], p[1]);
        u.extend([ux, uy]);
    }
    let le11: Vec<f64> = (0..mesh.elements.len())
        .map(|e| {
            let c = centroid(mesh, e);
            (1.0 + squash(c[0], c[1]).1).ln()
        })
        .collect();
    let plate = Overlay::polyline(vec![[-50.0, 52.0], [50.0, 52.0]], "rigid plate");

    // 1. A signed cell field on the deformed shape: diverging map, regions, plate.
    let p = dir.join("annulus_le11_cells.png");
    mesh_field_png(
        &p,
        mesh,
        Some(&u),
        &le11,
        &FieldPlot {
            title: "Logarithmic strain LE11, plate displaced 8 mm".into(),
            value_label: "LE11 (-)".into(),
            diverging: true,
            region_of_element: Some(&region),
            overlays: vec![plate.clone()],
            show_reference_outline: true,
            ..Default::default()
        },
    )?;
    written.push(p);

    // 2. A nodal field (displacement magnitude), interpolated, with an indenter.
    let umag: Vec<f64> = u.chunks(2).map(|d| d[0].hypot(d[1])).collect();
    let p = dir.join("annulus_umag_nodes.png");
    node_field_png(
        &p,
        mesh,
        None,
        &umag,
        &FieldPlot {
            title: "Displacement magnitude on the reference shape".into(),
            value_label: "|u| (mm)".into(),
            edges: Some(true),
            overlays: vec![Overlay::circle([0.0, 70.0], 10.0, "indenter")],
            ..Default::default()
        },
    )?;
    written.push(p);

    // 3. A field with missing values (no DIC data on the left), drawn grey.
    let measured: Vec<f64> = (0..mesh.elements.len())
        .map(|e| {
            if centroid(mesh, e)[0] < -25.0 {
                f64::NAN
            } else {
                le11[e].abs() * 100.0
            }
        })
        .collect();
    let p = dir.join("annulus_measured_nan.png");
    mesh_field_png(
        &p,
        mesh,
        None,
        &measured,
        &FieldPlot {
            title: "Measured |LE11| (left part outside the DIC region of interest)".into(),
            value_label: "|LE11| (%)".into(),
            region_of_element: Some(&region),
            ..Default::default()
        },
    )?;
    written.push(p);

    // 4. Load curves.
    let curve = |k: f64, c: f64| -> Vec<(f64, f64)> {
        (0..=20)
            .map(|i| {
                let d = 0.4 * i as f64;
                (d, k * d + c * d * d * d)
            })
            .collect()
    };
    let p = dir.join("load_curves.png");
    line_plot_png(
        &p,
        &[
            Series::new("fat (C10 = 0.8 kPa)", curve(0.05, 0.0010), LineStyle::Line),
            Series::new(
                "muscle (C10 = 2.5 kPa)",
                curve(0.12, 0.0030),
                LineStyle::LineAndMarkers,
            ),
            Series::new("measured", curve(0.09, 0.0021), LineStyle::Markers),
        ],
        &LinePlot {
            title: "Plate force against plate displacement".into(),
            x_label: "plate displacement (mm)".into(),
            y_label: "force per unit thickness (N/mm)".into(),
            legend: LegendPosition::UpperLeft,
            ..Default::default()
        },
    )?;
    written.push(p);

    // 5. A log-log convergence plot.
    let h = [8.0, 4.0, 2.0, 1.0, 0.5, 0.25];
    let p = dir.join("convergence.png");
    line_plot_png(
        &p,
        &[
            Series::new(
                "CPE4 (rate 1.99)",
                h.iter().map(|&h| (h, 2.0e-3 * h * h)).collect(),
                LineStyle::LineAndMarkers,
            ),
            Series::new(
                "CPE4H (rate 1.99)",
                h.iter().map(|&h| (h, 1.0e-4 * h * h)).collect(),
                LineStyle::LineAndMarkers,
            ),
            Series::new(
                "CPE3 (rate 1.0)",
                h.iter().map(|&h| (h, 3.0e-3 * h)).collect(),
                LineStyle::LineAndMarkers,
            ),
        ],
        &LinePlot {
            title: "Mesh convergence, two-layer cylinder under 20 mmHg".into(),
            x_label: "element size h (mm)".into(),
            y_label: "relative displacement error (-)".into(),
            log_x: true,
            log_y: true,
            ..Default::default()
        },
    )?;
    written.push(p);

    // 6. Identification errors per tissue with error bars (like the seed's Fig. 9).
    let tissues: Vec<String> = ["fat", "quadriceps", "ischio", "gracilis", "sartorius"]
        .map(String::from)
        .to_vec();
    let p = dir.join("identification_errors.png");
    bar_chart_png(
        &p,
        &tissues,
        &[
            ("C10".into(), vec![3.1, 5.4, 8.2, 12.5, 9.7]),
            ("D".into(), vec![6.0, 9.1, 14.3, 21.0, 17.2]),
        ],
        Some(&[vec![1.0, 1.6, 2.2, 4.1, 3.0], vec![2.1, 3.0, 4.4, 6.5, 5.1]]),
        &BarChart {
            title: "Identification error per tissue (10 noisy virtual tests)".into(),
            x_label: "tissue".into(),
            y_label: "relative error (%)".into(),
            ..Default::default()
        },
    )?;
    written.push(p);

    // 7. A grey-level histogram of a synthetic speckle (two Gaussian modes).
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut grey = Vec::with_capacity(50_000);
    for i in 0..50_000 {
        let (a, b) = (uniform().max(1e-300), uniform());
        let z = (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos();
        let (m, sd) = if i % 3 == 0 {
            (60.0, 15.0)
        } else {
            (170.0, 25.0)
        };
        grey.push((m + sd * z).clamp(0.0, 255.0).round());
    }
    let p = dir.join("grey_histogram.png");
    histogram_png(
        &p,
        &grey,
        64,
        &Histogram {
            title: "Grey levels of a synthetic speckle image".into(),
            x_label: "grey level (-)".into(),
            y_label: "pixels".into(),
            range: Some((0.0, 256.0)),
            ..Default::default()
        },
    )?;
    written.push(p);
    Ok(written)
}
