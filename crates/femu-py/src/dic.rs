//! `femu.dic`: `femu dic REF DEF` on two NumPy images (or image/DICOM files) with the same
//! options and defaults (`femu_dic::command::run_dic_on`): the output folder as the command
//! writes it, and the field, the nodal displacements and the nodal covariance as arrays.

use crate::convert;
use crate::errors::{self, IntoPy};
use crate::running;
use femu_dic::auto::Setting;
use femu_dic::command::{run_dic_on, CorrelationSpec, DicJob, RoiSpec};
use femu_dic::quality::TrustCriteria;
use femu_dic::{Brightness, DicOptions, GreyImage, PixelSize, Rect};
use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// An image argument: a path (PNG, TIFF, DICOM; `frame` of a multi-frame file) or a
/// two-dimensional array of grey levels on the 0–255 scale (`uint16` arrays are divided by 257,
/// as 16-bit files are). Returns the image and the name the outputs give it.
fn image(obj: &Bound<'_, PyAny>, frame: usize, what: &str) -> PyResult<(GreyImage, PathBuf)> {
    let py = obj.py();
    if obj.is_instance_of::<PyString>() || obj.hasattr("__fspath__")? {
        let path: PathBuf = obj.extract()?;
        let img = py.detach(|| GreyImage::open(&path, frame)).py_err()?;
        return Ok((img, path));
    }
    let np = py.import("numpy")?;
    let a = np.call_method1("asarray", (obj,))?;
    let scale = if a.getattr("dtype")?.str()?.to_cow()? == "uint16" {
        1.0 / 257.0
    } else {
        1.0
    };
    let a = np.call_method1("ascontiguousarray", (a, "float64"))?;
    let arr: PyReadonlyArray2<'_, f64> = a.extract().map_err(|_| {
        errors::input(format!(
            "{what}: expected a path or a two-dimensional array of grey levels (rows x columns)"
        ))
    })?;
    let (h, w) = (arr.shape()[0], arr.shape()[1]);
    let data: Vec<f64> = arr.as_slice()?.iter().map(|v| v * scale).collect();
    let img = GreyImage::new(w, h, data)
        .map_err(|e| errors::DicError::new_err(format!("{what}: {e}")))?;
    Ok((
        img,
        PathBuf::from(format!("({what}: NumPy array {w} x {h})")),
    ))
}

/// The region of interest: `roi` (x, y, w, h), or `mask` (a path, or an array whose non-zero
/// pixels are inside, saved as `out/mask.png` for the record), or the whole image.
fn roi_spec(
    roi: Option<(usize, usize, usize, usize)>,
    mask: Option<&Bound<'_, PyAny>>,
    out: &Path,
) -> PyResult<RoiSpec> {
    match (roi, mask) {
        (Some(_), Some(_)) => Err(errors::input("give roi or mask, not both")),
        (Some((x, y, w, h)), None) => Ok(RoiSpec::Rect(Rect { x, y, w, h })),
        (None, Some(m)) if m.is_instance_of::<PyString>() || m.hasattr("__fspath__")? => {
            Ok(RoiSpec::Mask(m.extract()?))
        }
        (None, Some(m)) => {
            let np = m.py().import("numpy")?;
            let inside = np.call_method1("not_equal", (m, 0))?;
            let (img, _) = image(&inside.call_method1("astype", ("float64",))?, 0, "mask")?;
            let bright = GreyImage::new(
                img.width,
                img.height,
                img.data.iter().map(|v| v * 255.0).collect(),
            )
            .py_err()?;
            std::fs::create_dir_all(out).py_err()?;
            let path = out.join("mask.png");
            bright.save_png(&path).py_err()?;
            Ok(RoiSpec::Mask(path))
        }
        (None, None) => Ok(RoiSpec::Whole),
    }
}

/// `regularization`: `"auto"`, `"off"`/`None`, or a length in pixels.
fn regularization(obj: &Bound<'_, PyAny>) -> PyResult<Setting> {
    if obj.is_none() {
        return Ok(Setting::Off);
    }
    if let Ok(s) = obj.extract::<String>() {
        return match s.trim() {
            "auto" => Ok(Setting::Auto),
            "off" | "none" => Ok(Setting::Off),
            v => v
                .parse::<f64>()
                .ok()
                .filter(|l| *l > 0.0)
                .map(Setting::Given)
                .ok_or_else(|| {
                    errors::input(format!(
                        "regularization '{v}': expected a length in pixels, 'auto' or 'off'"
                    ))
                }),
        };
    }
    let l: f64 = obj.extract().map_err(|_| {
        errors::input("regularization: expected a length in pixels, 'auto' or 'off'")
    })?;
    if !(l > 0.0 && l.is_finite()) {
        return Err(errors::input(format!(
            "regularization {l}: the length must be positive"
        )));
    }
    Ok(Setting::Given(l))
}

fn brightness(name: &str) -> PyResult<Brightness> {
    match name {
        "none" => Ok(Brightness::None),
        "global" => Ok(Brightness::Global),
        "per-element" | "per_element" => Ok(Brightness::PerElement),
        other => Err(errors::input(format!(
            "brightness '{other}': none, global or per-element"
        ))),
    }
}

/// `pixel_size`: one value or (x, y), mm.
fn pixel_size(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<PixelSize>> {
    let Some(obj) = obj else {
        return Ok(None);
    };
    let [dx, dy] = match obj.extract::<f64>() {
        Ok(s) => [s, s],
        Err(_) => {
            let (a, b): (f64, f64) = obj
                .extract()
                .map_err(|_| errors::input("pixel_size: one number or two (x, y), in mm"))?;
            [a, b]
        }
    };
    if !(dx > 0.0 && dy > 0.0 && dx.is_finite() && dy.is_finite()) {
        return Err(errors::input(format!(
            "pixel_size ({dx}, {dy}): must be positive (mm)"
        )));
    }
    Ok(Some(PixelSize {
        dx_mm: dx,
        dy_mm: dy,
        source: "option --pixel-size",
    }))
}

/// `femu dic` on `reference` and `deformed` into `out` (see the module documentation); the
/// keyword arguments are the command's options, with its defaults.
#[pyfunction]
#[pyo3(signature = (
    reference, deformed, out, *, roi = None, mask = None, element = None, tolerance = 1e-3,
    acceleration = femu_dic::anderson::DEFAULT_DEPTH, max_iterations = 100,
    brightness = "global", regularization = None, levels = None, fft = true, flag_factor = 3.0,
    min_zncc = 0.5, pixel_size = None, origin = (0.0, 0.0), y_up = false, x_left = false,
    grid = None, frame_ref = 0, frame_def = 0, figures = true, reporter = None
))]
#[allow(clippy::too_many_arguments)]
pub fn dic<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    deformed: &Bound<'py, PyAny>,
    out: PathBuf,
    roi: Option<(usize, usize, usize, usize)>,
    mask: Option<&Bound<'py, PyAny>>,
    element: Option<usize>,
    tolerance: f64,
    acceleration: usize,
    max_iterations: usize,
    brightness: &str,
    regularization: Option<&Bound<'py, PyAny>>,
    levels: Option<usize>,
    fft: bool,
    flag_factor: f64,
    min_zncc: f64,
    pixel_size: Option<&Bound<'py, PyAny>>,
    origin: (f64, f64),
    y_up: bool,
    x_left: bool,
    grid: Option<f64>,
    frame_ref: usize,
    frame_def: usize,
    figures: bool,
    reporter: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let t0 = Instant::now();
    if !(min_zncc > -1.0 && min_zncc < 1.0) {
        return Err(errors::input(format!(
            "min_zncc {min_zncc}: must lie in (-1, 1)"
        )));
    }
    let (f, f_name) = image(reference, frame_ref, "reference")?;
    let (g, g_name) = image(deformed, frame_def, "deformed")?;
    let job = DicJob {
        reference: f_name,
        deformed: g_name,
        frame_ref,
        frame_def,
        correlation: CorrelationSpec {
            roi: roi_spec(roi, mask, &out)?,
            options: DicOptions {
                tolerance,
                max_iterations,
                brightness: self::brightness(brightness)?,
                pyramid_levels: levels,
                fft_init: fft,
                flag_factor,
                acceleration_depth: acceleration,
                ..Default::default()
            },
            element: element.map_or(Setting::Auto, |h| Setting::Given(h as f64)),
            regularization: match regularization {
                None => Setting::Auto,
                Some(r) => self::regularization(r)?,
            },
            trust: TrustCriteria {
                min_zncc,
                ..Default::default()
            },
        },
        pixel_size: self::pixel_size(pixel_size)?,
        origin_px: [origin.0, origin.1],
        x_left,
        y_up,
        grid_step_px: grid,
        figures,
        out,
    };
    let run = running::run(py, reporter.as_ref(), |progress| {
        progress.note(&format!(
            "DIC: {} x {} px -> {}",
            f.width,
            f.height,
            job.out.display()
        ));
        Ok(run_dic_on(&job, &f, &g, t0)?)
    })?;
    let d = PyDict::new(py);
    d.set_item("report", convert::json(&run.report)?)?;
    let m = &run.measured;
    let g = &run.grid;
    let n = g.len();
    let col = |f: &dyn Fn(&femu_dic::output::GridPoint) -> f64| g.iter().map(f).collect();
    let field = PyDict::new(py);
    field.set_item("x", convert::array(py, col(&|p| p.x_mm[0]), &[n])?)?;
    field.set_item("y", convert::array(py, col(&|p| p.x_mm[1]), &[n])?)?;
    field.set_item("ux", convert::array(py, col(&|p| p.u_mm[0]), &[n])?)?;
    field.set_item("uy", convert::array(py, col(&|p| p.u_mm[1]), &[n])?)?;
    field.set_item("sx", convert::array(py, col(&|p| p.s_mm[0]), &[n])?)?;
    field.set_item("sy", convert::array(py, col(&|p| p.s_mm[1]), &[n])?)?;
    field.set_item("w", convert::array(py, col(&|p| p.w), &[n])?)?;
    field.set_item("x_px", convert::array(py, col(&|p| p.x_px[0]), &[n])?)?;
    field.set_item("y_px", convert::array(py, col(&|p| p.x_px[1]), &[n])?)?;
    field.set_item("ux_px", convert::array(py, col(&|p| p.u_px[0]), &[n])?)?;
    field.set_item("uy_px", convert::array(py, col(&|p| p.u_px[1]), &[n])?)?;
    d.set_item("field", field)?;
    let res = &m.res;
    let nn = res.mesh.nodes.len();
    let nodes = PyDict::new(py);
    let flat = |v: &[[f64; 2]]| v.iter().flatten().copied().collect::<Vec<f64>>();
    nodes.set_item("x_px", convert::array(py, flat(&res.mesh.nodes), &[nn, 2])?)?;
    nodes.set_item(
        "u_px",
        convert::array(py, flat(&res.displacement), &[nn, 2])?,
    )?;
    let sd: Vec<f64> = m
        .cov
        .node
        .iter()
        .flat_map(|s| [s.sd_ux_px, s.sd_uy_px])
        .collect();
    nodes.set_item("sd_px", convert::array(py, sd, &[nn, 2])?)?;
    nodes.set_item(
        "corr_xy",
        convert::array(py, m.cov.node.iter().map(|s| s.corr_xy).collect(), &[nn])?,
    )?;
    let w = femu_dic::output::node_weights(res, &m.trust);
    nodes.set_item(
        "w",
        convert::int_array(py, w.iter().map(|&v| v as i64).collect(), &[nn])?,
    )?;
    let conn: Vec<i64> = res.mesh.conn.iter().flatten().map(|&k| k as i64).collect();
    nodes.set_item(
        "elements",
        convert::int_array(py, conn, &[res.mesh.conn.len(), 4])?,
    )?;
    d.set_item("nodes", nodes)?;
    // The nodal covariance C (px²) on the pattern of the Gauss–Newton matrix, both triangles, in
    // compressed columns: equation 2 node + c (c = 0 for ux, 1 for uy).
    let p = &res.system.pattern;
    let cov = PyDict::new(py);
    cov.set_item("n", p.n)?;
    let ints = |v: &[usize]| v.iter().map(|&k| k as i64).collect::<Vec<i64>>();
    cov.set_item(
        "col_ptr",
        convert::int_array(py, ints(&p.col_ptr), &[p.col_ptr.len()])?,
    )?;
    cov.set_item(
        "row_idx",
        convert::int_array(py, ints(&p.row_idx), &[p.row_idx.len()])?,
    )?;
    cov.set_item(
        "values",
        convert::array(py, m.cov.values.clone(), &[m.cov.values.len()])?,
    )?;
    d.set_item("covariance", cov)?;
    Ok(d)
}

/// An image as a NumPy array and its pixel size `(dx, dy)` in mm, when known.
type ImageAndPixelSize<'py> = (Bound<'py, PyAny>, Option<(f64, f64)>);

/// An image file as a NumPy array of grey levels (0–255 scale, as femu reads it: colour as
/// BT.601 luminance, 16-bit divided by 257) and its pixel size `(dx, dy)` in mm when the file
/// (DICOM) gives it.
#[pyfunction]
#[pyo3(signature = (path, frame = 0))]
pub fn read_image<'py>(
    py: Python<'py>,
    path: PathBuf,
    frame: usize,
) -> PyResult<ImageAndPixelSize<'py>> {
    let img = py.detach(|| GreyImage::open(&path, frame)).py_err()?;
    let size = img.pixel_size.map(|p| (p.dx_mm, p.dy_mm));
    Ok((
        convert::array(py, img.data, &[img.height, img.width])?,
        size,
    ))
}
