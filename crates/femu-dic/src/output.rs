//! Outputs of a correlation: the model frame (pixels → mm), the measured-field CSV of
//! `conventions.md` on a regular grid, nodal and element tables, the VTU file and the summary.

use crate::error::DicError;
use crate::quality::{NodalCovariance, Trust};
use crate::solver::{DicResult, LevelReport, Timings};
use femu_mesh::{FieldSet, FieldWriter, VtuField};
use std::io::Write;
use std::path::Path;

/// The model frame of the measured field: `X = sx (x − ox) dx`, `Y = sy (y − oy) dy` (mm)
/// for a pixel position `(x, y)`, with `dx, dy` the pixel size (mm/px) and `sx, sy = ±1` the
/// axis directions (image rows go down; `y_up` makes the model y axis point up).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ModelFrame {
    /// Pixel position of the model origin.
    pub origin_px: [f64; 2],
    /// Pixel size (mm/px) along x and y.
    pub pixel_size_mm: [f64; 2],
    pub x_left: bool,
    pub y_up: bool,
}

impl Default for ModelFrame {
    fn default() -> Self {
        ModelFrame {
            origin_px: [0.0, 0.0],
            pixel_size_mm: [1.0, 1.0],
            x_left: false,
            y_up: false,
        }
    }
}

impl ModelFrame {
    fn signs(&self) -> [f64; 2] {
        [
            if self.x_left { -1.0 } else { 1.0 },
            if self.y_up { -1.0 } else { 1.0 },
        ]
    }

    /// Model coordinates (mm) of a pixel position.
    pub fn point(&self, p: [f64; 2]) -> [f64; 2] {
        let s = self.signs();
        [
            s[0] * (p[0] - self.origin_px[0]) * self.pixel_size_mm[0],
            s[1] * (p[1] - self.origin_px[1]) * self.pixel_size_mm[1],
        ]
    }

    /// Model displacement (mm) of a displacement in pixels.
    pub fn displacement(&self, u: [f64; 2]) -> [f64; 2] {
        let s = self.signs();
        [
            s[0] * u[0] * self.pixel_size_mm[0],
            s[1] * u[1] * self.pixel_size_mm[1],
        ]
    }

    /// Small strain `(εXX, εYY, εXY)` in the model frame from the pixel displacement gradient
    /// `G_ij = ∂u_i/∂x_j`: `∂U_i/∂X_j = s_i d_i G_ij / (s_j d_j)`.
    pub fn strain(&self, g: [[f64; 2]; 2]) -> [f64; 3] {
        let s = self.signs();
        let d = self.pixel_size_mm;
        let m = |i: usize, j: usize| s[i] * d[i] * g[i][j] / (s[j] * d[j]);
        [m(0, 0), m(1, 1), 0.5 * (m(0, 1) + m(1, 0))]
    }
}

fn werr(path: &Path) -> impl Fn(std::io::Error) -> DicError + '_ {
    move |e| DicError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// One point of the measured field on the regular grid.
#[derive(Debug, Clone, Copy)]
pub struct GridPoint {
    /// Pixel position and displacement (pixels).
    pub x_px: [f64; 2],
    pub u_px: [f64; 2],
    /// In the model frame (mm).
    pub x_mm: [f64; 2],
    pub u_mm: [f64; 2],
    /// Standard deviations of the displacement in the model frame (mm), from the nodal
    /// covariance ([`crate::quality`]); NaN when no covariance was given.
    pub s_mm: [f64; 2],
    /// Weight: 1, or 0 in an element that is not trusted (flagged for a high residual, or by
    /// the trust mask when one is given).
    pub w: f64,
}

/// The field sampled every `step` pixels over the active elements (cell centres of a grid
/// tiling the mesh), without standard deviations; weight 0 in flagged elements.
pub fn grid(res: &DicResult, frame: &ModelFrame, step: f64) -> Result<Vec<GridPoint>, DicError> {
    grid_with_quality(res, None, frame, step)
}

/// The quality a grid reads: the nodal covariance and the trust of each element.
pub struct Quality<'a> {
    pub cov: &'a NodalCovariance,
    pub trust: &'a [Trust],
}

/// [`grid`] with the standard deviations of each point (`sx, sy`, mm) and weight 0 in the
/// elements the trust mask rejects.
pub fn grid_with_quality(
    res: &DicResult,
    quality: Option<&Quality>,
    frame: &ModelFrame,
    step: f64,
) -> Result<Vec<GridPoint>, DicError> {
    if !(step > 0.0 && step.is_finite()) {
        return Err(DicError::option(
            "grid step",
            format!("{step} px must be positive"),
        ));
    }
    let m = &res.mesh;
    let (x0, y0) = (m.x0 as f64 - 0.5, m.y0 as f64 - 0.5);
    let (wx, wy) = ((m.nx * m.h) as f64, (m.ny * m.h) as f64);
    let (nx, ny) = ((wx / step).floor() as usize, (wy / step).floor() as usize);
    let mut out = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let p = [x0 + (i as f64 + 0.5) * step, y0 + (j as f64 + 0.5) * step];
            if let Some((e, _, _)) = m.locate(p[0], p[1]) {
                let u = m
                    .interpolate(&res.displacement, p[0], p[1])
                    .expect("located");
                let (s_mm, trusted) = match quality {
                    Some(q) => {
                        let sd = q.cov.point_sd(res, p[0], p[1]).expect("located");
                        let d = frame.pixel_size_mm;
                        ([sd[0] * d[0], sd[1] * d[1]], q.trust[e] == Trust::Trusted)
                    }
                    None => ([f64::NAN; 2], !res.flagged[e]),
                };
                out.push(GridPoint {
                    x_px: p,
                    u_px: u,
                    x_mm: frame.point(p),
                    u_mm: frame.displacement(u),
                    s_mm,
                    w: if trusted { 1.0 } else { 0.0 },
                });
            }
        }
    }
    Ok(out)
}

/// Writes the measured-field CSV with `comments` as `#` lines: `x,y,ux,uy,sx,sy,w` (mm) when
/// the points carry standard deviations, `x,y,ux,uy,w` otherwise.
pub fn write_field_csv(
    path: &Path,
    points: &[GridPoint],
    comments: &[String],
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    for c in comments {
        writeln!(f, "# {c}").map_err(&e)?;
    }
    let with_sd = points.iter().all(|p| p.s_mm.iter().all(|v| v.is_finite()));
    writeln!(
        f,
        "{}",
        if with_sd {
            "x,y,ux,uy,sx,sy,w"
        } else {
            "x,y,ux,uy,w"
        }
    )
    .map_err(&e)?;
    for p in points {
        write!(
            f,
            "{:.12e},{:.12e},{:.12e},{:.12e},",
            p.x_mm[0], p.x_mm[1], p.u_mm[0], p.u_mm[1]
        )
        .map_err(&e)?;
        if with_sd {
            write!(f, "{:.6e},{:.6e},", p.s_mm[0], p.s_mm[1]).map_err(&e)?;
        }
        writeln!(f, "{}", p.w).map_err(&e)?;
    }
    f.commit().map_err(&e)
}

/// Writes `node,x_px,y_px,ux_px,uy_px,x_mm,y_mm,ux_mm,uy_mm`, and with a quality also
/// `sd_ux_px,sd_uy_px,corr_xy,w` (`w` = 1 when every element around the node is trusted).
pub fn write_nodes_csv(
    path: &Path,
    res: &DicResult,
    frame: &ModelFrame,
    quality: Option<&Quality>,
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    let node_w = quality.map(|q| node_weights(res, q.trust));
    write!(f, "node,x_px,y_px,ux_px,uy_px,x_mm,y_mm,ux_mm,uy_mm").map_err(&e)?;
    writeln!(
        f,
        "{}",
        if quality.is_some() {
            ",sd_ux_px,sd_uy_px,corr_xy,w"
        } else {
            ""
        }
    )
    .map_err(&e)?;
    for (n, (p, u)) in res.mesh.nodes.iter().zip(&res.displacement).enumerate() {
        let (xm, um) = (frame.point(*p), frame.displacement(*u));
        write!(
            f,
            "{},{},{},{:.12e},{:.12e},{:.12e},{:.12e},{:.12e},{:.12e}",
            n + 1,
            p[0],
            p[1],
            u[0],
            u[1],
            xm[0],
            xm[1],
            um[0],
            um[1]
        )
        .map_err(&e)?;
        if let (Some(q), Some(w)) = (quality, &node_w) {
            let s = q.cov.node[n];
            write!(
                f,
                ",{:.6e},{:.6e},{:.6e},{}",
                s.sd_ux_px, s.sd_uy_px, s.corr_xy, w[n]
            )
            .map_err(&e)?;
        }
        writeln!(f).map_err(&e)?;
    }
    f.commit().map_err(&e)
}

/// 1 for a node whose elements are all trusted, else 0.
pub fn node_weights(res: &DicResult, trust: &[Trust]) -> Vec<u8> {
    let mut w = vec![1u8; res.mesh.n_nodes()];
    for (c, t) in res.mesh.conn.iter().zip(trust) {
        if *t != Trust::Trusted {
            for &q in c {
                w[q] = 0;
            }
        }
    }
    w
}

/// Writes the symmetric matrix `values` on `pattern` in the Matrix Market coordinate format
/// (`real symmetric`: the lower triangle, 1-based indices; equation `2 (node − 1) + c + 1` for
/// component `c` = 0 (x), 1 (y) of the 1-based `node` of `nodes.csv`), `comments` as `%` lines.
/// Each value is written in the shortest form that reads back to the same `f64`.
pub fn write_matrix_market(
    path: &Path,
    pattern: &crate::sparse::CscPattern,
    values: &[f64],
    comments: &[String],
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    writeln!(f, "%%MatrixMarket matrix coordinate real symmetric").map_err(&e)?;
    for c in comments {
        writeln!(f, "% {c}").map_err(&e)?;
    }
    let lower = (0..pattern.n)
        .map(|c| {
            pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]]
                .iter()
                .filter(|&&r| r >= c)
                .count()
        })
        .sum::<usize>();
    writeln!(f, "{} {} {}", pattern.n, pattern.n, lower).map_err(&e)?;
    for c in 0..pattern.n {
        for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
            let r = pattern.row_idx[k];
            if r >= c {
                writeln!(f, "{} {} {:e}", r + 1, c + 1, values[k]).map_err(&e)?;
            }
        }
    }
    f.commit().map_err(&e)
}

/// Writes a dense symmetric `m x m` matrix (row-major `values`) as a Matrix Market array: the
/// lower triangle column by column, with comment lines.
pub fn write_dense_symmetric(
    path: &Path,
    m: usize,
    values: &[f64],
    comments: &[String],
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    writeln!(f, "%%MatrixMarket matrix array real symmetric").map_err(&e)?;
    for c in comments {
        writeln!(f, "% {c}").map_err(&e)?;
    }
    writeln!(f, "{m} {m}").map_err(&e)?;
    for j in 0..m {
        for i in j..m {
            writeln!(f, "{:.9e}", values[i * m + j]).map_err(&e)?;
        }
    }
    f.commit().map_err(&e)
}

/// Largest grid of `field.csv` whose full covariance `femu dic` writes (`field_covariance.mtx`,
/// dense: 600 points are 1 200 x 1 200, about 10 MB of text).
pub const MAX_COVARIANCE_POINTS: usize = 600;

/// The covariance of the grid points' displacements in the model frame (mm², `[ux, uy]` per
/// point, row-major): the nodal covariance `A⁻¹ M_σ A⁻¹` of `res` carried to each point by its
/// element's shape functions ([`crate::quality::combined_covariance`]), scaled and flipped as
/// the frame maps pixels to mm.
pub fn grid_covariance(
    res: &DicResult,
    points: &[GridPoint],
    frame: &ModelFrame,
) -> Result<Vec<f64>, DicError> {
    let rows: Vec<Vec<(usize, f64)>> = points
        .iter()
        .flat_map(|p| {
            let (e, xi, eta) = res
                .mesh
                .locate(p.x_px[0], p.x_px[1])
                .expect("grid points lie in the mesh");
            let n = crate::DicMesh::shape(xi, eta);
            let c = res.mesh.conn[e];
            (0..2).map(move |comp| (0..4).map(|a| (2 * c[a] + comp, n[a])).collect())
        })
        .collect();
    let sys = &res.system;
    let mut c = crate::quality::combined_covariance(
        &sys.pattern,
        &sys.a_values(),
        &crate::quality::noise_matrix(res),
        &rows,
    )?;
    let scale = frame.displacement([1.0, 1.0]);
    let m = rows.len();
    for i in 0..m {
        for j in 0..m {
            c[i * m + j] *= scale[i % 2] * scale[j % 2];
        }
    }
    Ok(c)
}

/// Reads a symmetric real Matrix Market file as [`write_matrix_market`] writes it (the lower
/// triangle, 1-based): the pattern (both triangles) and the values on it. A malformed line is
/// an error naming the file and the line.
pub fn read_matrix_market(path: &Path) -> Result<(crate::sparse::CscPattern, Vec<f64>), DicError> {
    let bad = |line: usize, message: String| DicError::ImageRead {
        path: path.to_path_buf(),
        message: format!("line {line}: {message}"),
    };
    let text = std::fs::read_to_string(path).map_err(|e| DicError::ImageRead {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h))
            if h.to_ascii_lowercase()
                .starts_with("%%matrixmarket matrix coordinate real symmetric") => {}
        _ => {
            return Err(bad(
                1,
                "not a symmetric real Matrix Market coordinate file".into(),
            ))
        }
    }
    let mut size: Option<(usize, usize)> = None;
    let mut entries: Vec<(usize, usize, f64)> = Vec::new();
    for (k, l) in lines {
        let t = l.trim();
        if t.is_empty() || t.starts_with('%') {
            continue;
        }
        let f: Vec<&str> = t.split_whitespace().collect();
        match size {
            None => {
                let n: usize = f
                    .first()
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| bad(k + 1, "size line".into()))?;
                let nnz: usize = f
                    .get(2)
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| bad(k + 1, "size line".into()))?;
                size = Some((n, nnz));
                entries.reserve(nnz);
            }
            Some((n, _)) => {
                let (r, c, v) = match (f.first(), f.get(1), f.get(2)) {
                    (Some(r), Some(c), Some(v)) => {
                        (r.parse::<usize>(), c.parse::<usize>(), v.parse::<f64>())
                    }
                    _ => return Err(bad(k + 1, format!("'{t}' is not 'row col value'"))),
                };
                let (Ok(r), Ok(c), Ok(v)) = (r, c, v) else {
                    return Err(bad(k + 1, format!("'{t}' is not 'row col value'")));
                };
                if r == 0 || c == 0 || r > n || c > n || !v.is_finite() {
                    return Err(bad(
                        k + 1,
                        format!("entry ({r}, {c}) = {v} outside a {n} x {n} matrix or not finite"),
                    ));
                }
                entries.push((r - 1, c - 1, v));
            }
        }
    }
    let (n, _) = size.ok_or_else(|| bad(1, "no size line".into()))?;
    let mut pairs: Vec<(usize, usize)> = entries
        .iter()
        .flat_map(|&(r, c, _)| [(r, c), (c, r)])
        .collect();
    let pattern = femu_sparse::CscPattern::from_pairs(n, &mut pairs);
    let mut values = vec![0.0; pattern.nnz()];
    for &(r, c, v) in &entries {
        values[pattern.position(r, c).expect("entry in the pattern")] = v;
        values[pattern.position(c, r).expect("entry in the pattern")] = v;
    }
    Ok((pattern, values))
}

/// Element table: `element,n1,n2,n3,n4,exx,eyy,exy,residual,flagged,zncc,grey_std,
/// texture_small,texture_large` (strain in the model frame, residual RMS and grey-level
/// standard deviation in grey levels, structure-tensor eigenvalues in grey levels²/px²), and
/// with a trust mask `trust,w` (the reason, `trusted`, `decorrelated`, `high-residual`,
/// `shadow`, `low-texture`, `outside-image`, and the weight 1/0).
pub fn write_elements_csv(
    path: &Path,
    res: &DicResult,
    frame: &ModelFrame,
    trust: Option<&[Trust]>,
) -> Result<(), DicError> {
    let e = werr(path);
    let mut f = femu_mesh::atomic::AtomicFile::create(path).map_err(&e)?;
    writeln!(
        f,
        "element,n1,n2,n3,n4,exx,eyy,exy,residual,flagged,zncc,grey_std,texture_small,texture_large{}",
        if trust.is_some() { ",trust,w" } else { "" }
    )
    .map_err(&e)?;
    for (k, c) in res.mesh.conn.iter().enumerate() {
        let s = frame.strain(res.mesh.gradient_at_centre(&res.displacement, k));
        let t = &res.element_texture[k];
        write!(
            f,
            "{},{},{},{},{},{:.9e},{:.9e},{:.9e},{:.6e},{},{:.4},{:.4},{:.6e},{:.6e}",
            k + 1,
            c[0] + 1,
            c[1] + 1,
            c[2] + 1,
            c[3] + 1,
            s[0],
            s[1],
            s[2],
            res.element_residual[k],
            res.flagged[k] as u8,
            t.zncc,
            t.std,
            t.structure[0],
            t.structure[1]
        )
        .map_err(&e)?;
        if let Some(tr) = trust {
            write!(f, ",{},{}", tr[k].name(), (tr[k] == Trust::Trusted) as u8).map_err(&e)?;
        }
        writeln!(f).map_err(&e)?;
    }
    f.commit().map_err(&e)
}

/// Element strains in the model frame.
pub fn element_strains(res: &DicResult, frame: &ModelFrame) -> Vec<[f64; 3]> {
    (0..res.mesh.n_elements())
        .map(|k| frame.strain(res.mesh.gradient_at_centre(&res.displacement, k)))
        .collect()
}

/// The mesh in the model frame (mm) with displacement (mm), pixel displacement, strain,
/// residual and flags, written by `writer` (ParaView's `.vtu` with
/// [`femu_mesh::VtuWriter`]).
pub fn write_fields(
    writer: &dyn FieldWriter,
    path: &Path,
    res: &DicResult,
    frame: &ModelFrame,
) -> Result<(), DicError> {
    let mut mesh = res.mesh.to_mesh();
    for p in &mut mesh.nodes {
        *p = frame.point(*p);
    }
    let u_mm: Vec<[f64; 2]> = res
        .displacement
        .iter()
        .map(|u| frame.displacement(*u))
        .collect();
    let u_px: Vec<f64> = res
        .displacement
        .iter()
        .flat_map(|u| [u[0], u[1], 0.0])
        .collect();
    let strain: Vec<f64> = element_strains(res, frame)
        .iter()
        .flat_map(|s| [s[0], s[1], 0.0, s[2]])
        .collect();
    let flagged: Vec<f64> = res.flagged.iter().map(|&b| b as u8 as f64).collect();
    writer
        .write(
            path,
            &FieldSet {
                mesh: &mesh,
                displacement: Some(&u_mm),
                point_fields: &[VtuField {
                    name: "displacement_px",
                    components: 3,
                    data: &u_px,
                }],
                cell_fields: &[
                    VtuField {
                        name: "strain",
                        components: 4,
                        data: &strain,
                    },
                    VtuField {
                        name: "residual",
                        components: 1,
                        data: &res.element_residual,
                    },
                    VtuField {
                        name: "flagged",
                        components: 1,
                        data: &flagged,
                    },
                ],
                int_cell_fields: &[],
            },
        )
        .map_err(|e| DicError::Write {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// The numbers a user quotes, for `summary.json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DicSummary {
    pub elements: usize,
    pub nodes: usize,
    pub element_size_px: usize,
    pub iterations: usize,
    pub converged: bool,
    pub last_increment_px: f64,
    pub residual_rms: f64,
    pub residual_percent_of_dynamic: f64,
    pub flagged_elements: usize,
    pub initial_shift_px: (i64, i64),
    /// Mean and standard deviation of the nodal displacements (pixels).
    pub mean_u_px: [f64; 2],
    pub std_u_px: [f64; 2],
    pub levels: Vec<LevelReport>,
    pub timings: Timings,
}

impl DicSummary {
    pub fn of(res: &DicResult) -> Self {
        let (mean, std) = mean_std(&res.displacement);
        DicSummary {
            elements: res.mesh.n_elements(),
            nodes: res.mesh.n_nodes(),
            element_size_px: res.mesh.h,
            iterations: res.iterations,
            converged: res.converged,
            last_increment_px: res.last_increment_px,
            residual_rms: res.residual_rms,
            residual_percent_of_dynamic: res.residual_percent,
            flagged_elements: res.flagged.iter().filter(|&&b| b).count(),
            initial_shift_px: res.initial_shift,
            mean_u_px: mean,
            std_u_px: std,
            levels: res.levels.clone(),
            timings: res.timings.clone(),
        }
    }
}

/// Mean and (population) standard deviation of each component.
pub fn mean_std(u: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let n = u.len().max(1) as f64;
    let mut m = [0.0; 2];
    for v in u {
        m[0] += v[0] / n;
        m[1] += v[1] / n;
    }
    let mut s = [0.0; 2];
    for v in u {
        s[0] += (v[0] - m[0]).powi(2) / n;
        s[1] += (v[1] - m[1]).powi(2) / n;
    }
    (m, [s[0].sqrt(), s[1].sqrt()])
}

/// Writes a serializable value as pretty JSON.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), DicError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| DicError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    femu_mesh::atomic::write(path, text).map_err(|e| DicError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_frame_maps_points_displacements_and_strains() {
        let f = ModelFrame {
            origin_px: [10.0, 20.0],
            pixel_size_mm: [0.1, 0.2],
            x_left: false,
            y_up: true,
        };
        assert_eq!(f.point([12.0, 25.0]), [0.2, -1.0]);
        let u = f.displacement([1.0, 1.0]);
        assert!((u[0] - 0.1).abs() < 1e-15 && (u[1] + 0.2).abs() < 1e-15);
        // u_px = G x: model gradient by finite differences of the mapped field.
        let g = [[0.01, 0.02], [0.03, -0.005]];
        let s = f.strain(g);
        let map = |x: [f64; 2]| {
            let up = [
                g[0][0] * x[0] + g[0][1] * x[1],
                g[1][0] * x[0] + g[1][1] * x[1],
            ];
            (f.point(x), f.displacement(up))
        };
        let (p0, u0) = map([0.0, 0.0]);
        let (p1, u1) = map([1.0, 0.0]);
        let (p2, u2) = map([0.0, 1.0]);
        let duxdx = (u1[0] - u0[0]) / (p1[0] - p0[0]);
        let duydy = (u2[1] - u0[1]) / (p2[1] - p0[1]);
        let duxdy = (u2[0] - u0[0]) / (p2[1] - p0[1]);
        let duydx = (u1[1] - u0[1]) / (p1[0] - p0[0]);
        assert!((s[0] - duxdx).abs() < 1e-12 && (s[1] - duydy).abs() < 1e-12);
        assert!((s[2] - 0.5 * (duxdy + duydx)).abs() < 1e-12);
    }
}
