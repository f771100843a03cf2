//! The measured displacement field (conventions.md): what DIC writes and the identification
//! reads.
//!
//! ```text
//! # optional comment lines: source, units, pixel size, frame
//! x,y,ux,uy[,sx,sy][,w]
//! ```
//!
//! `x,y` reference coordinates in the model frame (mm), `ux,uy` the measured displacement (mm),
//! optional standard deviations `sx,sy` (mm) and a weight `w` (it multiplies the inverse
//! variances; `w = 0` leaves a point out). A comment line `# units: mm` or `# units: px` declares
//! the units (`femu dic` writes it); a study's frame keys must agree with it. A non-finite or
//! non-numeric cell is an error naming its line, and so is a point given twice (same `x,y`).

use std::io::Write;
use std::path::Path;

/// The largest coordinate or displacement a measured-field file may hold (mm or px): a
/// thigh is well under a metre and an image under a million pixels, so a larger value is a
/// broken file, not a measurement.
pub const MAX_MAGNITUDE: f64 = 1e6;

/// The units a measured-field file declares in a `# units: mm` or `# units: px` comment line
/// (`femu dic` writes one): coordinates and displacements in the model's mm, or in image
/// pixels that a pixel size must map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeclaredUnits {
    Mm,
    Px,
}

impl DeclaredUnits {
    pub fn name(self) -> &'static str {
        match self {
            DeclaredUnits::Mm => "mm",
            DeclaredUnits::Px => "px",
        }
    }
}

/// One measured point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredPoint {
    pub x: [f64; 2],
    pub u: [f64; 2],
    /// Weight of each component in the least squares: `1/sx², 1/sy²`, or `w, w`, or `1, 1`.
    pub weight: [f64; 2],
}

/// A measured field.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MeasuredField {
    pub points: Vec<MeasuredPoint>,
    /// Comment lines (without `#`).
    pub comments: Vec<String>,
}

/// Why a measured-field file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum MeasuredError {
    #[error("{path}: cannot read: {message}")]
    Io { path: String, message: String },
    #[error("{path}:{line}: {message}")]
    Bad {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{path}: no data row (expected a header line x,y,ux,uy[,sx,sy][,w] and one row per measured point, mm)")]
    Empty { path: String },
}

impl MeasuredField {
    /// Reads a measured-field CSV.
    pub fn read(path: &Path) -> Result<MeasuredField, MeasuredError> {
        let text = std::fs::read_to_string(path).map_err(|e| MeasuredError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses the text of a measured-field CSV (`name` is used in messages).
    pub fn parse(text: &str, name: &str) -> Result<MeasuredField, MeasuredError> {
        let bad = |line: usize, message: String| MeasuredError::Bad {
            path: name.to_string(),
            line,
            message,
        };
        let mut field = MeasuredField::default();
        // The line of each point, by its coordinates' bits (0.0 and -0.0 as one).
        let mut seen: std::collections::HashMap<[u64; 2], usize> = Default::default();
        let mut columns: Option<Vec<String>> = None;
        let mut idx = [usize::MAX; 7];
        for (k, raw) in text.lines().enumerate() {
            let line = k + 1;
            let t = raw.trim();
            if t.is_empty() {
                continue;
            }
            if let Some(c) = t.strip_prefix('#') {
                field.comments.push(c.trim().to_string());
                continue;
            }
            let cells: Vec<&str> = t.split(',').map(str::trim).collect();
            let Some(cols) = &columns else {
                let names: Vec<String> = cells.iter().map(|c| c.to_ascii_lowercase()).collect();
                for (slot, want) in ["x", "y", "ux", "uy", "sx", "sy", "w"].iter().enumerate() {
                    if let Some(p) = names.iter().position(|n| n == want) {
                        idx[slot] = p;
                    }
                }
                if idx[..4].contains(&usize::MAX) {
                    return Err(bad(
                        line,
                        format!("the header must name x,y,ux,uy (got '{t}')"),
                    ));
                }
                if (idx[4] == usize::MAX) != (idx[5] == usize::MAX) {
                    return Err(bad(line, "sx and sy go together".into()));
                }
                if let Some(u) = names
                    .iter()
                    .find(|n| !["x", "y", "ux", "uy", "sx", "sy", "w"].contains(&n.as_str()))
                {
                    return Err(bad(line, format!("unknown column '{u}'")));
                }
                columns = Some(names);
                continue;
            };
            if cells.len() != cols.len() {
                return Err(bad(
                    line,
                    format!("{} cells, the header has {}", cells.len(), cols.len()),
                ));
            }
            let get = |slot: usize| -> Result<f64, MeasuredError> {
                let cell = cells[idx[slot]];
                let v: f64 = cell.parse().map_err(|_| {
                    bad(
                        line,
                        format!("column {}: '{cell}' is not a number", cols[idx[slot]]),
                    )
                })?;
                if !v.is_finite() {
                    return Err(bad(
                        line,
                        format!("column {}: {cell} is not finite", cols[idx[slot]]),
                    ));
                }
                Ok(v)
            };
            // `w` multiplies the inverse variances `1/sx², 1/sy²` (1 without them): `femu dic`
            // writes both, `w = 0` for a point it does not trust.
            let w = if idx[6] != usize::MAX {
                let w = get(6)?;
                if !(w >= 0.0) {
                    return Err(bad(line, format!("w must be non-negative, got {w}")));
                }
                w
            } else {
                1.0
            };
            let weight = if idx[4] != usize::MAX {
                let (sx, sy) = (get(4)?, get(5)?);
                if !(sx > 0.0 && sy > 0.0) {
                    return Err(bad(
                        line,
                        format!("sx, sy must be positive, got {sx}, {sy}"),
                    ));
                }
                let weight = [w / (sx * sx), w / (sy * sy)];
                if !weight.iter().all(|v| v.is_finite()) {
                    return Err(bad(
                        line,
                        format!("sx, sy = {sx}, {sy}: too small to weigh (1/s² overflows)"),
                    ));
                }
                weight
            } else {
                [w, w]
            };
            let plausible = |slot: usize| -> Result<f64, MeasuredError> {
                let v = get(slot)?;
                if v.abs() > MAX_MAGNITUDE {
                    return Err(bad(
                        line,
                        format!(
                            "column {}: {v:e} is beyond {MAX_MAGNITUDE:e} (mm or px): not a position or displacement of an image or a thigh",
                            cols[idx[slot]]
                        ),
                    ));
                }
                Ok(v)
            };
            let x = [plausible(0)?, plausible(1)?];
            if let Some(first) = seen.insert(x.map(|c| (c + 0.0).to_bits()), line) {
                return Err(bad(
                    line,
                    format!(
                        "the point ({}, {}) is also on line {first}: a point measured twice counts twice in the fit and shrinks its standard deviations; keep one (or average them)",
                        x[0], x[1]
                    ),
                ));
            }
            field.points.push(MeasuredPoint {
                x,
                u: [plausible(2)?, plausible(3)?],
                weight,
            });
        }
        if field.points.is_empty() {
            return Err(MeasuredError::Empty {
                path: name.to_string(),
            });
        }
        Ok(field)
    }

    /// The units the file declares (`# units: mm` or `# units: px`), if it declares them.
    pub fn declared_units(&self) -> Result<Option<DeclaredUnits>, String> {
        let mut found = None;
        for c in &self.comments {
            let Some(v) = c
                .strip_prefix("units:")
                .or_else(|| c.strip_prefix("units :"))
            else {
                continue;
            };
            let u = match v.trim().to_ascii_lowercase().as_str() {
                "mm" => DeclaredUnits::Mm,
                "px" => DeclaredUnits::Px,
                other => return Err(format!("'# units: {other}': the units are mm or px")),
            };
            if found.is_some_and(|f| f != u) {
                return Err("two '# units:' lines that disagree".into());
            }
            found = Some(u);
        }
        Ok(found)
    }

    /// The points that weigh something (a point whose two weights are 0, e.g. one `femu dic`
    /// does not trust, carries no information and is left out of the fit), and the index in
    /// `self.points` of each point kept — to take the same rows of a full covariance.
    pub fn weighted_points(&self) -> (MeasuredField, Vec<usize>) {
        let keep: Vec<usize> = (0..self.points.len())
            .filter(|&i| self.points[i].weight.iter().any(|&w| w > 0.0))
            .collect();
        let field = MeasuredField {
            points: keep.iter().map(|&i| self.points[i]).collect(),
            comments: self.comments.clone(),
        };
        (field, keep)
    }

    /// Writes the field as `x,y,ux,uy` (and `sx,sy` when every weight is `1/s²` of a common
    /// `sigma`, given here), full precision, with the comment lines.
    pub fn write(&self, path: &Path, sigma: Option<f64>) -> std::io::Result<()> {
        let mut w = femu_mesh::atomic::AtomicFile::create(path)?;
        for c in &self.comments {
            writeln!(w, "# {c}")?;
        }
        match sigma {
            Some(_) => writeln!(w, "x,y,ux,uy,sx,sy")?,
            None => writeln!(w, "x,y,ux,uy")?,
        }
        for p in &self.points {
            write!(
                w,
                "{:.12e},{:.12e},{:.12e},{:.12e}",
                p.x[0], p.x[1], p.u[0], p.u[1]
            )?;
            if let Some(s) = sigma {
                write!(w, ",{s:.6e},{s:.6e}")?;
            }
            writeln!(w)?;
        }
        w.commit()
    }

    /// The field in the model frame, from a file frame (image pixels or mm): positions
    /// `X = origin + s (x e_x + y e_y)`, displacements `U = s (u_x e_x + u_y e_y)`, with `e_x`,
    /// `e_y` orthonormal model directions of the file's axes and `s` mm per file unit. Weights
    /// are inverse variances, so they transform as `σ_X² = s² (σ_x² e_x,X² + σ_y² e_y,X²)` — the
    /// diagonal of the rotated covariance (exact for axes along the model's, ± and swapped).
    pub fn to_model_frame(
        &self,
        scale: f64,
        origin: [f64; 2],
        x_axis: [f64; 2],
        y_axis: [f64; 2],
    ) -> MeasuredField {
        let map = |v: [f64; 2]| {
            [
                scale * (v[0] * x_axis[0] + v[1] * y_axis[0]),
                scale * (v[0] * x_axis[1] + v[1] * y_axis[1]),
            ]
        };
        let points = self
            .points
            .iter()
            .map(|p| {
                let x = map(p.x);
                // A component of weight 0 (a point left out) has an infinite variance: it
                // reaches only the model components its axis has a share in (no `∞ · 0`).
                let var = [1.0 / p.weight[0], 1.0 / p.weight[1]];
                let part = |v: f64, c: f64| if c == 0.0 { 0.0 } else { v * c * c };
                let var_model = [
                    scale * scale * (part(var[0], x_axis[0]) + part(var[1], y_axis[0])),
                    scale * scale * (part(var[0], x_axis[1]) + part(var[1], y_axis[1])),
                ];
                MeasuredPoint {
                    x: [origin[0] + x[0], origin[1] + x[1]],
                    u: map(p.u),
                    weight: var_model.map(|v| if v.is_finite() { 1.0 / v } else { 0.0 }),
                }
            })
            .collect();
        let mut comments = self.comments.clone();
        comments.push(format!(
            "mapped to the model frame: {scale} mm per unit, origin {origin:?} mm, x axis {x_axis:?}, y axis {y_axis:?}"
        ));
        MeasuredField { points, comments }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_weights_and_names_bad_lines() {
        let f = MeasuredField::parse("# DIC\nx,y,ux,uy,sx,sy\n1,2,0.1,0.2,0.5,0.25\n", "m.csv")
            .unwrap();
        assert_eq!(f.points[0].weight, [4.0, 16.0]);
        assert_eq!(f.comments, vec!["DIC".to_string()]);
        let f = MeasuredField::parse("x,y,ux,uy,w\n1,2,0.1,0.2,3\n", "m.csv").unwrap();
        assert_eq!(f.points[0].weight, [3.0, 3.0]);
        let err = |t: &str| MeasuredField::parse(t, "m.csv").unwrap_err().to_string();
        assert!(err("x,y,ux,uy\n1,2,3,4\n1,2,NaN,4\n").contains("m.csv:3"));
        assert!(err("x,y,ux,uy\n1,2,3,abc\n").contains("'abc' is not a number"));
        assert!(err("x,y,ux\n").contains("x,y,ux,uy"));
        assert!(err("x,y,ux,uy\n1,2,3\n").contains("m.csv:2"));
        assert!(err("x,y,ux,uy\n").contains("no data"));
        assert!(err("x,y,ux,uy,q\n").contains("unknown column 'q'"));
        // What `femu dic` writes: sx, sy and w together; w multiplies the inverse variances.
        let f = MeasuredField::parse(
            "# units: mm\nx,y,ux,uy,sx,sy,w\n1,2,0.1,0.2,0.5,0.25,1\n3,2,0.1,0.2,0.5,0.25,0\n",
            "m.csv",
        )
        .unwrap();
        assert_eq!(f.points[0].weight, [4.0, 16.0]);
        assert_eq!(f.points[1].weight, [0.0, 0.0]);
        assert_eq!(f.declared_units(), Ok(Some(DeclaredUnits::Mm)));
        let (kept, index) = f.weighted_points();
        assert_eq!((kept.points.len(), index), (1, vec![0]));
        assert!(err("x,y,ux,uy\n1e308,2,3,4\n").contains("m.csv:2"));
        assert!(err("x,y,ux,uy\n1,2,3,-2e6\n").contains("column uy"));
        assert!(err("x,y,ux,uy,sx,sy\n1,2,3,4,1e-200,1\n").contains("overflows"));
        // Issue 32.6: a point repeated (2 500 times in the audit) would weigh 2 500 times and
        // shrink the reported sd; refused naming both lines.
        let e = err("x,y,ux,uy\n1,2,3,4\n5,6,7,8\n1.0,2,3,4\n");
        assert!(e.contains("m.csv:4") && e.contains("also on line 2"), "{e}");
        assert!(err("x,y,ux,uy\n0,2,3,4\n-0,2,3,4\n").contains("also on line 2"));
    }

    #[test]
    fn round_trip() {
        let dir = std::env::temp_dir().join(format!("femu-measured-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = MeasuredField {
            points: vec![MeasuredPoint {
                x: [1.5, -2.0],
                u: [1e-3, -0.25],
                weight: [1.0, 1.0],
            }],
            comments: vec!["synthetic".into()],
        };
        let p = dir.join("m.csv");
        f.write(&p, Some(0.5)).unwrap();
        let g = MeasuredField::read(&p).unwrap();
        assert_eq!(g.points[0].x, f.points[0].x);
        assert_eq!(g.points[0].u, f.points[0].u);
        assert_eq!(g.points[0].weight, [4.0, 4.0]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn image_frame_maps_to_the_model_frame() {
        // An image field in px (rows going down) with sigmas (1, 2) px.
        let f = MeasuredField::parse("x,y,ux,uy,sx,sy\n10,20,1,-2,1,2\n", "t").unwrap();
        let m = f.to_model_frame(0.1, [-5.0, 7.0], [1.0, 0.0], [0.0, -1.0]);
        let p = m.points[0];
        assert!((p.x[0] - (-4.0)).abs() < 1e-12 && (p.x[1] - 5.0).abs() < 1e-12);
        assert!((p.u[0] - 0.1).abs() < 1e-12 && (p.u[1] - 0.2).abs() < 1e-12);
        // Weights 1/(0.1)^2 and 1/(0.2)^2.
        assert!((p.weight[0] - 100.0).abs() < 1e-9 && (p.weight[1] - 25.0).abs() < 1e-9);
        // Axes swapped: the sigmas swap.
        let m = f.to_model_frame(1.0, [0.0; 2], [0.0, 1.0], [1.0, 0.0]);
        assert_eq!(m.points[0].u, [-2.0, 1.0]);
        assert!((m.points[0].weight[0] - 0.25).abs() < 1e-12);
        // A point left out (w = 0) stays out in any frame, with no NaN weight.
        let f = MeasuredField::parse("x,y,ux,uy,w\n10,20,1,-2,0\n", "t").unwrap();
        for axes in [([1.0, 0.0], [0.0, -1.0]), ([0.0, 1.0], [1.0, 0.0])] {
            let m = f.to_model_frame(0.1, [0.0; 2], axes.0, axes.1);
            assert_eq!(m.points[0].weight, [0.0, 0.0]);
        }
    }
}
