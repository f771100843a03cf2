//! Every figure function writes a PNG of the requested size that is not blank; bad input is a
//! `PlotError`, never a panic; the field rasteriser fills the mesh and keeps equal scales.

use femu_mesh::{generate, Element, ElementKind, Mesh};
use femu_plot::{
    bar_chart_png, histogram_png, line_plot_png, mesh_field_png, node_field_png, BarChart,
    FieldPlot, Histogram, LinePlot, LineStyle, Overlay, PlotError, Series,
};
use std::path::PathBuf;

/// A fresh folder for one test.
fn out_dir(test: &str) -> PathBuf {
    let d = std::env::temp_dir()
        .join(format!("femu-plot-tests-{}", std::process::id()))
        .join(test);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Checks the PNG signature and the IHDR size, decodes the picture and returns it.
fn read_png(path: &std::path::Path, size: (u32, u32)) -> image::RgbImage {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{}: not a PNG",
        path.display()
    );
    assert_eq!(&bytes[12..16], b"IHDR");
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((w, h), size, "{}: size", path.display());
    let img = image::open(path).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), size);
    let first = *img.get_pixel(0, 0);
    assert!(
        img.pixels().any(|p| *p != first),
        "{}: a single colour",
        path.display()
    );
    img
}

fn annulus() -> Mesh {
    generate::annulus(14.0, 40.0, 60.0, 64, 6, 4, ElementKind::Cpe4).mesh
}

const YELLOW: image::Rgb<u8> = image::Rgb([0xFD, 0xE7, 0x25]);

#[test]
fn mesh_field_is_written_at_the_default_size() {
    let d = out_dir("mesh_field");
    let mesh = annulus();
    let values: Vec<f64> = (0..mesh.elements.len()).map(|e| e as f64).collect();
    let u: Vec<f64> = mesh
        .nodes
        .iter()
        .flat_map(|p| [0.05 * p[0], -0.1 * p[1]])
        .collect();
    let region: Vec<usize> = (0..mesh.elements.len()).map(|e| e % 3).collect();
    let opts = FieldPlot {
        title: "cells".into(),
        value_label: "index (-)".into(),
        region_of_element: Some(&region),
        overlays: vec![
            Overlay::polyline(vec![[-60.0, 60.0], [60.0, 60.0]], "plate"),
            Overlay::polyline(vec![[64.0, -50.0], [64.0, 50.0]], "side plate"),
            Overlay::circle([0.0, 0.0], 5.0, ""),
        ],
        show_reference_outline: true,
        ..Default::default()
    };
    let p = d.join("cells.png");
    mesh_field_png(&p, &mesh, Some(&u), &values, &opts).unwrap();
    read_png(&p, (1200, 900));
    let p = d.join("cells_diverging_small.png");
    let signed: Vec<f64> = values.iter().map(|v| v - 100.0).collect();
    let opts = FieldPlot {
        diverging: true,
        width: 640,
        height: 480,
        edges: Some(false),
        ..opts
    };
    mesh_field_png(&p, &mesh, None, &signed, &opts).unwrap();
    read_png(&p, (640, 480));
}

#[test]
fn node_field_and_triangles() {
    let d = out_dir("node_field");
    let mesh = annulus();
    let values: Vec<f64> = mesh.nodes.iter().map(|p| p[0] * p[1]).collect();
    let p = d.join("nodes.png");
    node_field_png(&p, &mesh, None, &values, &FieldPlot::default()).unwrap();
    read_png(&p, (1200, 900));

    let mut tri = Mesh::default();
    for x in [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]] {
        tri.add_node(x);
    }
    tri.add_element(Element::tri([0, 1, 2]));
    tri.add_element(Element::tri([0, 2, 3]));
    let p = d.join("triangles.png");
    node_field_png(&p, &tri, None, &[0.0, 1.0, 2.0, 3.0], &FieldPlot::default()).unwrap();
    read_png(&p, (1200, 900));
    let p = d.join("triangle_cells.png");
    mesh_field_png(&p, &tri, None, &[1.0, 2.0], &FieldPlot::default()).unwrap();
    read_png(&p, (1200, 900));
}

/// A 10 mm square at the top of the colour range fills a square of yellow pixels: the
/// rasteriser covers the elements and both axes have the same scale.
#[test]
fn a_square_mesh_is_drawn_square_and_filled() {
    let d = out_dir("square");
    let mesh = generate::rectangle(10.0, 10.0, 5, 5, ElementKind::Cpe4).mesh;
    let p = d.join("square.png");
    let opts = FieldPlot {
        range: Some((0.0, 1.0)),
        edges: Some(false),
        ..Default::default()
    };
    mesh_field_png(&p, &mesh, None, &[1.0; 25], &opts).unwrap();
    let img = read_png(&p, (1200, 900));
    // The colour bar also holds yellow: keep the first run of columns that hold yellow.
    let has_yellow = |x: u32| (0..img.height()).any(|y| *img.get_pixel(x, y) == YELLOW);
    let first = (0..img.width()).find(|&x| has_yellow(x)).unwrap();
    let end = (first..img.width()).find(|&x| !has_yellow(x)).unwrap();
    let (mut x0, mut x1, mut y0, mut y1, mut n) = (u32::MAX, 0, u32::MAX, 0, 0u64);
    for (x, y, px) in img.enumerate_pixels() {
        if *px == YELLOW && x < end {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
            n += 1;
        }
    }
    let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
    assert!(w > 500, "square drawn {w} px wide");
    assert!(w.abs_diff(h) <= 3, "square drawn {w} x {h} px");
    // Interior pixels under the boundary line are black, so allow the outline.
    assert!(
        n as f64 > 0.97 * (w * h) as f64,
        "{n} of {} pixels filled",
        w * h
    );
}

#[test]
fn nan_values_are_grey_not_a_panic() {
    let d = out_dir("nan");
    let mesh = annulus();
    let mut cells: Vec<f64> = (0..mesh.elements.len()).map(|e| e as f64).collect();
    cells[3] = f64::NAN;
    cells[7] = f64::INFINITY;
    let p = d.join("cells_nan.png");
    mesh_field_png(&p, &mesh, None, &cells, &FieldPlot::default()).unwrap();
    let img = read_png(&p, (1200, 900));
    assert!(img.pixels().any(|p| *p == image::Rgb([190, 190, 190])));

    let mut nodes = vec![1.0; mesh.nodes.len()];
    nodes[0] = f64::NAN;
    nodes[1] = 2.0;
    let p = d.join("nodes_nan.png");
    node_field_png(&p, &mesh, None, &nodes, &FieldPlot::default()).unwrap();
    read_png(&p, (1200, 900));

    // Every value missing: an error without a range, a grey picture with one.
    let all_nan = vec![f64::NAN; mesh.elements.len()];
    let p = d.join("all_nan.png");
    let err = mesh_field_png(&p, &mesh, None, &all_nan, &FieldPlot::default()).unwrap_err();
    assert!(matches!(err, PlotError::InvalidData(_)), "{err}");
    let opts = FieldPlot {
        range: Some((0.0, 1.0)),
        ..Default::default()
    };
    mesh_field_png(&p, &mesh, None, &all_nan, &opts).unwrap();
    read_png(&p, (1200, 900));
}

#[test]
fn bad_field_inputs_are_errors() {
    let d = out_dir("bad_field");
    let p = d.join("never.png");
    let mesh = annulus();
    let ne = mesh.elements.len();
    let o = FieldPlot::default();
    let e = mesh_field_png(&p, &Mesh::default(), None, &[], &o).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let e = mesh_field_png(&p, &mesh, None, &[1.0], &o).unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let e = node_field_png(&p, &mesh, None, &vec![0.0; ne], &o).unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let e = mesh_field_png(&p, &mesh, Some(&[0.0; 3]), &vec![0.0; ne], &o).unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let bad_range = FieldPlot {
        range: Some((1.0, 1.0)),
        ..Default::default()
    };
    let e = mesh_field_png(&p, &mesh, None, &vec![0.0; ne], &bad_range).unwrap_err();
    assert!(matches!(e, PlotError::InvalidOption(_)), "{e}");
    let tiny = FieldPlot {
        width: 10,
        ..Default::default()
    };
    let e = mesh_field_png(&p, &mesh, None, &vec![0.0; ne], &tiny).unwrap_err();
    assert!(matches!(e, PlotError::InvalidOption(_)), "{e}");
    let mut broken = mesh.clone();
    broken.elements[0].conn[0] = 999_999;
    let e = mesh_field_png(&p, &broken, None, &vec![0.0; ne], &o).unwrap_err();
    assert!(matches!(e, PlotError::InvalidData(_)), "{e}");
    // A folder that does not exist.
    let e = mesh_field_png(&d.join("missing/x.png"), &mesh, None, &vec![0.0; ne], &o).unwrap_err();
    assert!(matches!(e, PlotError::Write { .. }), "{e}");
    assert!(!p.exists());
}

#[test]
fn line_plots_linear_and_log_log() {
    let d = out_dir("lines");
    let s = |label: &str, k: f64, style| {
        Series::new(
            label,
            (1..=8).map(|i| (i as f64, k * (i * i) as f64)).collect(),
            style,
        )
    };
    let series = [
        s("a", 1.0, LineStyle::Line),
        s("b", 2.0, LineStyle::Markers),
        s("c", 3.0, LineStyle::LineAndMarkers),
        s("d", 4.0, LineStyle::LineAndMarkers),
        s("e", 5.0, LineStyle::LineAndMarkers),
    ];
    let mut opts = LinePlot {
        title: "t".into(),
        x_label: "x (mm)".into(),
        y_label: "y (N)".into(),
        ..Default::default()
    };
    let p = d.join("linear.png");
    line_plot_png(&p, &series, &opts).unwrap();
    read_png(&p, (1200, 900));
    opts.log_x = true;
    opts.log_y = true;
    let p = d.join("loglog.png");
    line_plot_png(&p, &series, &opts).unwrap();
    read_png(&p, (1200, 900));
    // One series, a NaN point, one log axis, a custom size.
    let mut one = s("only", 1.0, LineStyle::Line);
    one.points.push((f64::NAN, 1.0));
    opts.log_x = false;
    opts.width = 800;
    opts.height = 600;
    let p = d.join("semilog.png");
    line_plot_png(&p, &[one], &opts).unwrap();
    read_png(&p, (800, 600));
}

#[test]
fn bad_line_inputs_are_errors() {
    let p = out_dir("bad_lines").join("never.png");
    let o = LinePlot::default();
    let e = line_plot_png(&p, &[], &o).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let empty = Series::new("e", vec![], LineStyle::Line);
    let e = line_plot_png(&p, &[empty], &o).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let zero = Series::new("z", vec![(0.0, 1.0), (1.0, 2.0)], LineStyle::Line);
    let log = LinePlot {
        log_x: true,
        ..Default::default()
    };
    let e = line_plot_png(&p, &[zero], &log).unwrap_err();
    assert!(matches!(e, PlotError::InvalidData(_)), "{e}");
    assert!(!p.exists());
}

#[test]
fn bar_charts_with_and_without_error_bars() {
    let d = out_dir("bars");
    let cats: Vec<String> = ["fat", "muscle", "tendon"].map(String::from).to_vec();
    let groups = vec![
        ("C10".to_string(), vec![1.0, -2.0, 3.0]),
        ("D".to_string(), vec![2.0, f64::NAN, 1.0]),
    ];
    let err = vec![vec![0.5, 0.2, 0.1], vec![0.3, 0.0, f64::NAN]];
    let opts = BarChart {
        title: "bars".into(),
        y_label: "error (%)".into(),
        ..Default::default()
    };
    let p = d.join("bars_err.png");
    bar_chart_png(&p, &cats, &groups, Some(&err), &opts).unwrap();
    read_png(&p, (1200, 900));
    let p = d.join("bars_one_group.png");
    bar_chart_png(&p, &cats, &groups[..1], None, &opts).unwrap();
    read_png(&p, (1200, 900));

    let e = bar_chart_png(&p, &[], &groups, None, &opts).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let e = bar_chart_png(&p, &cats, &[], None, &opts).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let short = vec![("x".to_string(), vec![1.0])];
    let e = bar_chart_png(&p, &cats, &short, None, &opts).unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let e = bar_chart_png(&p, &cats, &groups, Some(&err[..1]), &opts).unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let negative = vec![vec![-1.0, 0.0, 0.0], vec![0.0; 3]];
    let e = bar_chart_png(&p, &cats, &groups, Some(&negative), &opts).unwrap_err();
    assert!(matches!(e, PlotError::InvalidData(_)), "{e}");
}

#[test]
fn histograms() {
    let d = out_dir("histogram");
    let values: Vec<f64> = (0..1000).map(|i| ((i * 37) % 101) as f64).collect();
    let p = d.join("hist.png");
    let opts = Histogram {
        title: "h".into(),
        x_label: "grey level (-)".into(),
        ..Default::default()
    };
    histogram_png(&p, &values, 20, &opts).unwrap();
    read_png(&p, (1200, 900));
    let p = d.join("hist_constant_nan.png");
    histogram_png(&p, &[5.0, 5.0, f64::NAN], 10, &opts).unwrap();
    read_png(&p, (1200, 900));

    let e = histogram_png(&p, &[], 10, &opts).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let e = histogram_png(&p, &[f64::NAN], 10, &opts).unwrap_err();
    assert!(matches!(e, PlotError::Empty(_)), "{e}");
    let e = histogram_png(&p, &values, 0, &opts).unwrap_err();
    assert!(matches!(e, PlotError::InvalidOption(_)), "{e}");
}
