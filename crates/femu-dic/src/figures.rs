//! The maps of `femu dic` over the reference image (cropped to the mesh with a margin of one
//! element), with colour bars: displacements, strains, residual, and the quality (nodal
//! standard deviation, ZNCC per element, the trust mask).

use crate::auto::Measured;
use crate::error::DicError;
use crate::image::GreyImage;
use crate::output::{self, ModelFrame};
use crate::quality::{NodalCovariance, Trust};
use rayon::prelude::*;
use std::path::Path;

/// The files [`write_maps`] writes.
pub const MAPS: [&str; 9] = [
    "ux.png",
    "uy.png",
    "exx.png",
    "eyy.png",
    "exy.png",
    "residual.png",
    "sd.png",
    "zncc.png",
    "trust.png",
];

/// One map: file, values per pixel, title, colour-bar label, diverging, fixed range.
pub struct Map<'a> {
    pub name: &'a str,
    pub values: Vec<f64>,
    pub title: String,
    pub label: String,
    pub diverging: bool,
    pub range: Option<(f64, f64)>,
    /// Category names when the values are categories 1, 2, … (a legend instead of a colour
    /// bar); empty for continuous values.
    pub categories: Vec<String>,
}

/// Pixels the colour range's percentiles are taken over, at most (every k-th of the map's,
/// a regular sample: a map's values vary over elements of hundreds of pixels).
const RANGE_SAMPLE: usize = 1 << 17;

/// Draws `map` over `f`, cropped to `crop`; the colour range, unless given, from the 1st to the
/// 99th percentile (a few wild values do not wash out the map) of a regular sample of at most
/// [`RANGE_SAMPLE`] of its pixels.
pub fn draw(
    out: &Path,
    f: &GreyImage,
    map: &Map,
    crop: (usize, usize, usize, usize),
) -> Result<(), DicError> {
    let range = map.range.or_else(|| {
        let stride = map.values.len().div_ceil(RANGE_SAMPLE).max(1);
        let mut v: Vec<f64> = map
            .values
            .iter()
            .step_by(stride)
            .copied()
            .filter(|x| x.is_finite())
            .collect();
        // The two order statistics by selection (what a full sort would put there, in linear
        // time: the maps have a value per pixel).
        let n = v.len();
        (n > 1)
            .then(|| {
                let (lo, hi) = (n / 100, n - 1 - n / 100);
                let (_, &mut a, right) = v.select_nth_unstable_by(lo, |a, b| a.total_cmp(b));
                let b = if hi == lo {
                    a
                } else {
                    *right
                        .select_nth_unstable_by(hi - lo - 1, |a, b| a.total_cmp(b))
                        .1
                };
                (a, b)
            })
            .filter(|r| r.1 > r.0)
    });
    let opts = femu_plot::ImageField {
        title: map.title.clone(),
        value_label: map.label.clone(),
        diverging: map.diverging,
        range,
        crop: Some(crop),
        categories: map.categories.clone(),
        ..Default::default()
    };
    let path = out.join(map.name);
    femu_plot::image_field_png(&path, &f.data, f.width, f.height, &map.values, &opts).map_err(|e| {
        DicError::Write {
            path: path.clone(),
            message: e.to_string(),
        }
    })
}

/// Per pixel of the mesh: `value(element, ξ, η)` at the pixel's centre in its element's local
/// coordinates (`(x − x_e + ½) / h`, `(y − y_e + ½) / h` from the element's top-left pixel
/// `(x_e, y_e)`: the element's nodes lie on pixel edges, as [`pixel_local`] has them), NaN
/// elsewhere.
/// The bands of elements (one row of elements, `h` rows of pixels) are filled in parallel,
/// straight into the image.
fn per_pixel(
    m: &Measured,
    w: usize,
    h: usize,
    value: impl Fn(usize, f64, f64) -> f64 + Sync,
) -> Vec<f64> {
    let mesh = &m.res.mesh;
    let eh = mesh.h;
    let mut by_band: Vec<Vec<usize>> = vec![Vec::new(); mesh.ny];
    for (e, &(_, ey)) in mesh.cells.iter().enumerate() {
        by_band[ey].push(e);
    }
    let mut v = vec![f64::NAN; w * h];
    let first = mesh.y0 * w;
    let inv_h = 1.0 / eh as f64;
    v[first..]
        .par_chunks_mut(eh * w)
        .zip(by_band.par_iter())
        .for_each(|(band, elements)| {
            for &e in elements {
                let (px, _) = mesh.element_origin(e);
                for (j, row) in band.chunks_exact_mut(w).enumerate() {
                    for (i, out) in row[px..px + eh].iter_mut().enumerate() {
                        let (xi, eta) = pixel_local(i, j, inv_h);
                        *out = value(e, xi, eta);
                    }
                }
            }
        });
    v
}

/// The local coordinates `(ξ, η)` of the pixel `(i, j)` of an element (from its top-left pixel)
/// whose size is `1 / inv_h` pixels: its centre, half a pixel in from the element's edges
/// (where the nodes lie; [`crate::mesh::DicMesh::locate`]).
#[inline]
fn pixel_local(i: usize, j: usize, inv_h: f64) -> (f64, f64) {
    ((i as f64 + 0.5) * inv_h, (j as f64 + 0.5) * inv_h)
}

/// The crop of the maps: the mesh with a margin of one element.
pub fn crop_of(m: &Measured, w: usize, h: usize) -> (usize, usize, usize, usize) {
    let mesh = &m.res.mesh;
    let x0 = mesh.x0.saturating_sub(mesh.h);
    let y0 = mesh.y0.saturating_sub(mesh.h);
    let x1 = (mesh.x0 + mesh.nx * mesh.h + mesh.h).min(w);
    let y1 = (mesh.y0 + mesh.ny * mesh.h + mesh.h).min(h);
    (x0, y0, x1 - x0, y1 - y0)
}

/// Writes the nine maps of [`MAPS`]; `min_zncc` is the ZNCC below which the trust mask left
/// elements out (the pair's own level for a B-mode pair), named in the ZNCC map's title.
pub fn write_maps(
    out: &Path,
    f: &GreyImage,
    m: &Measured,
    frame: &ModelFrame,
    mm: bool,
    min_zncc: f64,
) -> Result<(), DicError> {
    let (w, h) = (f.width, f.height);
    let res = &m.res;
    let mesh = &res.mesh;
    let unit = if mm { "mm" } else { "px" };
    let disp = |c: usize| {
        per_pixel(m, w, h, |e, xi, eta| {
            let u = mesh.interpolate_in(&res.displacement, e, xi, eta);
            if mm {
                frame.displacement(u)[c]
            } else {
                u[c]
            }
        })
    };
    let es = output::element_strains(res, frame);
    let strain = |c: usize| per_pixel(m, w, h, |e, _, _| es[e][c]);
    let blocks = m.cov.element_blocks(res);
    let sd = per_pixel(m, w, h, |e, xi, eta| {
        let s = NodalCovariance::local_sd(&blocks[e], xi, eta);
        s[0].max(s[1])
    });
    let untrusted = m.trust.iter().filter(|&&t| t != Trust::Trusted).count();
    let maps = [
        Map {
            name: "ux.png",
            values: disp(0),
            title: "Horizontal displacement ux".into(),
            label: format!("ux ({unit})"),
            diverging: false,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "uy.png",
            values: disp(1),
            title: "Vertical displacement uy".into(),
            label: format!("uy ({unit})"),
            diverging: false,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "exx.png",
            values: strain(0),
            title: "Strain exx (element centres)".into(),
            label: "exx (-)".into(),
            diverging: true,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "eyy.png",
            values: strain(1),
            title: "Strain eyy (element centres)".into(),
            label: "eyy (-)".into(),
            diverging: true,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "exy.png",
            values: strain(2),
            title: "Shear strain exy (element centres)".into(),
            label: "exy (-)".into(),
            diverging: true,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "residual.png",
            values: res.residual_image.iter().map(|&v| v as f64).collect(),
            title: format!("Grey-level residual (RMS {:.2})", res.residual_rms),
            label: "f - g(x+u) (grey levels)".into(),
            diverging: true,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "sd.png",
            values: sd,
            title: "Standard deviation of the displacement (larger component)".into(),
            label: "sd (px)".into(),
            diverging: false,
            range: None,
            categories: Vec::new(),
        },
        Map {
            name: "zncc.png",
            values: per_pixel(m, w, h, |e, _, _| res.element_texture[e].zncc),
            title: format!("Correlation score per element (ZNCC; below {min_zncc:.2} not trusted)"),
            label: "ZNCC (-)".into(),
            diverging: false,
            range: Some((0.0, 1.0)),
            categories: Vec::new(),
        },
        Map {
            name: "trust.png",
            values: per_pixel(m, w, h, |e, _, _| match m.trust[e] {
                Trust::Trusted => f64::NAN,
                t => t.code() as f64,
            }),
            title: format!(
                "Not trusted: {untrusted} of {} elements, by reason",
                m.trust.len()
            ),
            label: "not trusted".into(),
            diverging: false,
            range: Some((1.0, Trust::UNTRUSTED.len() as f64)),
            categories: Trust::UNTRUSTED
                .iter()
                .map(|t| t.reason().to_string())
                .collect(),
        },
    ];
    let crop = crop_of(m, w, h);
    maps.par_iter().try_for_each(|map| draw(out, f, map, crop))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{DicMesh, Rect, Roi};

    /// The maps' local coordinates of a pixel are those the mesh locates it at: every pixel of
    /// every element, 16 px elements away from the image's origin.
    #[test]
    fn pixel_local_is_where_the_mesh_locates_the_pixel() {
        let roi = Roi::Rect(Rect {
            x: 10,
            y: 20,
            w: 70,
            h: 33,
        });
        let mesh = DicMesh::new(&roi, 100, 60, 16).unwrap();
        let inv_h = 1.0 / mesh.h as f64;
        for e in 0..mesh.n_elements() {
            let (px, py) = mesh.element_origin(e);
            for j in 0..mesh.h {
                for i in 0..mesh.h {
                    let (e2, xi, eta) = mesh.locate((px + i) as f64, (py + j) as f64).unwrap();
                    let (a, b) = pixel_local(i, j, inv_h);
                    assert_eq!(e2, e);
                    assert!(
                        (a - xi).abs() < 1e-12 && (b - eta).abs() < 1e-12,
                        "{e} ({i}, {j})"
                    );
                }
            }
        }
    }
}
