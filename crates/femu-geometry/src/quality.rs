//! Mesh quality: scaled Jacobian, aspect ratio and corner angles of quadrilaterals, per region.
//!
//! Definitions (as in the Verdict library, C. Stimpson et al., "The Verdict Geometric Quality
//! Library", Sandia report SAND2007-1751):
//!
//! ```text
//!        x4 ---------- x3
//!        |  \          |       corner k: edges a = x(k+1) - x(k), b = x(k-1) - x(k)
//!        |     \       |       scaled Jacobian  = min_k (a × b) / (|a| |b|)   (= sin of the
//!        |        \    |                          smallest-sine corner angle; 1 for a square,
//!        x1 ---------- x2                         ≤ 0 for an inverted or degenerate quad)
//! ```
//!
//! - aspect ratio: longest edge / shortest edge (Verdict's *edge ratio*), 1 for a square;
//! - angles: the four interior corner angles (degrees), 90 for a square.
//!
//! An element whose scaled Jacobian is not above [`DEGENERATE_SCALED_JACOBIAN`] is an error.

use crate::GeometryError;
use femu_mesh::Mesh;
use serde::Serialize;

/// Scaled Jacobian at or below which an element counts as inverted or degenerate.
pub const DEGENERATE_SCALED_JACOBIAN: f64 = 1e-6;

/// Quality figures of one region (or of the whole mesh, region `ALL`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RegionQuality {
    pub region: String,
    pub elements: usize,
    pub area_mm2: f64,
    pub min_scaled_jacobian: f64,
    pub max_scaled_jacobian: f64,
    pub mean_scaled_jacobian: f64,
    pub max_aspect_ratio: f64,
    pub mean_aspect_ratio: f64,
    pub min_angle_deg: f64,
    pub max_angle_deg: f64,
    /// Elements whose scaled Jacobian is below 0.3.
    pub below_0_3: usize,
}

/// The quality report: one row per region, then `ALL`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct QualityReport {
    pub regions: Vec<RegionQuality>,
    pub total: RegionQuality,
}

impl QualityReport {
    /// CSV: header then one row per region and `ALL`.
    pub fn to_csv(&self) -> String {
        let mut s = String::from(
            "region,elements,area_mm2,min_scaled_jacobian,max_scaled_jacobian,mean_scaled_jacobian,max_aspect_ratio,mean_aspect_ratio,min_angle_deg,max_angle_deg,below_0_3\n",
        );
        for r in self.regions.iter().chain(std::iter::once(&self.total)) {
            s.push_str(&format!(
                "{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.4},{:.4},{}\n",
                r.region,
                r.elements,
                r.area_mm2,
                r.min_scaled_jacobian,
                r.max_scaled_jacobian,
                r.mean_scaled_jacobian,
                r.max_aspect_ratio,
                r.mean_aspect_ratio,
                r.min_angle_deg,
                r.max_angle_deg,
                r.below_0_3
            ));
        }
        s
    }
}

/// Scaled Jacobian of a quadrilateral (see the module documentation).
pub fn scaled_jacobian(x: &[[f64; 2]; 4]) -> f64 {
    (0..4)
        .map(|k| {
            let p = x[k];
            let a = [x[(k + 1) % 4][0] - p[0], x[(k + 1) % 4][1] - p[1]];
            let b = [x[(k + 3) % 4][0] - p[0], x[(k + 3) % 4][1] - p[1]];
            let la = a[0].hypot(a[1]);
            let lb = b[0].hypot(b[1]);
            if la == 0.0 || lb == 0.0 {
                return 0.0;
            }
            (a[0] * b[1] - a[1] * b[0]) / (la * lb)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Longest over shortest edge.
pub fn aspect_ratio(x: &[[f64; 2]; 4]) -> f64 {
    let l: Vec<f64> = (0..4)
        .map(|k| (x[(k + 1) % 4][0] - x[k][0]).hypot(x[(k + 1) % 4][1] - x[k][1]))
        .collect();
    let (lo, hi) = l.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
        (lo.min(v), hi.max(v))
    });
    if lo > 0.0 {
        hi / lo
    } else {
        f64::INFINITY
    }
}

/// The four interior angles (degrees) of a counter-clockwise quad; a reflex corner reports its
/// angle above 180.
pub fn corner_angles(x: &[[f64; 2]; 4]) -> [f64; 4] {
    let mut out = [0.0; 4];
    for k in 0..4 {
        let p = x[k];
        let a = [x[(k + 1) % 4][0] - p[0], x[(k + 1) % 4][1] - p[1]];
        let b = [x[(k + 3) % 4][0] - p[0], x[(k + 3) % 4][1] - p[1]];
        let cross = a[0] * b[1] - a[1] * b[0];
        let dot = a[0] * b[0] + a[1] * b[1];
        let ang = cross.atan2(dot).to_degrees();
        out[k] = if ang < 0.0 { 360.0 + ang } else { ang };
    }
    out
}

/// Quality of every region of `mesh` (element sets `regions`), quads only. An inverted or
/// degenerate element is an error naming it.
pub fn quality_report(mesh: &Mesh, regions: &[String]) -> Result<QualityReport, GeometryError> {
    let mut rows = Vec::new();
    let mut all: Vec<usize> = Vec::new();
    for r in regions {
        let set = mesh.element_set(r).unwrap_or(&[]);
        rows.push(stats(mesh, r, set)?);
        all.extend_from_slice(set);
    }
    let total = stats(mesh, "ALL", &all)?;
    Ok(QualityReport {
        regions: rows,
        total,
    })
}

fn stats(mesh: &Mesh, name: &str, set: &[usize]) -> Result<RegionQuality, GeometryError> {
    let mut q = RegionQuality {
        region: name.to_string(),
        elements: set.len(),
        area_mm2: 0.0,
        min_scaled_jacobian: f64::INFINITY,
        max_scaled_jacobian: f64::NEG_INFINITY,
        mean_scaled_jacobian: 0.0,
        max_aspect_ratio: 0.0,
        mean_aspect_ratio: 0.0,
        min_angle_deg: f64::INFINITY,
        max_angle_deg: 0.0,
        below_0_3: 0,
    };
    for &e in set {
        let (x, n) = mesh.element_coords(e);
        if n != 4 {
            continue;
        }
        let sj = scaled_jacobian(&x);
        if !(sj > DEGENERATE_SCALED_JACOBIAN) {
            return Err(GeometryError::BadElement {
                label: mesh.element_labels[e],
                region: name.to_string(),
                scaled_jacobian: sj,
            });
        }
        let ar = aspect_ratio(&x);
        q.area_mm2 += element_area(mesh, e);
        q.min_scaled_jacobian = q.min_scaled_jacobian.min(sj);
        q.max_scaled_jacobian = q.max_scaled_jacobian.max(sj);
        q.mean_scaled_jacobian += sj;
        q.max_aspect_ratio = q.max_aspect_ratio.max(ar);
        q.mean_aspect_ratio += ar;
        for a in corner_angles(&x) {
            q.min_angle_deg = q.min_angle_deg.min(a);
            q.max_angle_deg = q.max_angle_deg.max(a);
        }
        if sj < 0.3 {
            q.below_0_3 += 1;
        }
    }
    if !set.is_empty() {
        q.mean_scaled_jacobian /= set.len() as f64;
        q.mean_aspect_ratio /= set.len() as f64;
    } else {
        q.min_scaled_jacobian = 0.0;
        q.max_scaled_jacobian = 0.0;
        q.min_angle_deg = 0.0;
    }
    Ok(q)
}

/// Area of a quad or triangle (shoelace).
pub(crate) fn element_area(m: &Mesh, e: usize) -> f64 {
    let (x, n) = m.element_coords(e);
    (0..n)
        .map(|k| {
            let (p, q) = (x[k], x[(k + 1) % n]);
            0.5 * (p[0] * q[1] - q[0] * p[1])
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mesh::{Element, ElementKind};

    #[test]
    fn square_rhombus_and_inverted_quad() {
        let sq = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!((scaled_jacobian(&sq) - 1.0).abs() < 1e-12);
        assert!((aspect_ratio(&sq) - 1.0).abs() < 1e-12);
        assert_eq!(corner_angles(&sq).map(|a| a.round()), [90.0; 4]);
        // Rhombus with 60° and 120° corners: scaled Jacobian sin 60°.
        let s3 = 3f64.sqrt() / 2.0;
        let rh = [[0.0, 0.0], [1.0, 0.0], [1.5, s3], [0.5, s3]];
        assert!((scaled_jacobian(&rh) - s3).abs() < 1e-12);
        let ang = corner_angles(&rh);
        assert!((ang[0] - 60.0).abs() < 1e-9 && (ang[1] - 120.0).abs() < 1e-9);
        // A 2x1 rectangle: aspect ratio 2.
        assert!(
            (aspect_ratio(&[[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]) - 2.0).abs() < 1e-12
        );
        // Clockwise (inverted) quad and a degenerate one are errors.
        let mut m = Mesh::default();
        for p in sq {
            m.add_node(p);
        }
        m.add_element(Element::quad(ElementKind::Cpe4, [0, 3, 2, 1]));
        m.element_sets.insert("A".into(), vec![0]);
        let err = quality_report(&m, &["A".to_string()]).unwrap_err();
        assert!(
            matches!(err, GeometryError::BadElement { label: 1, .. }),
            "{err}"
        );
        m.elements[0].conn = [0, 1, 2, 2];
        assert!(quality_report(&m, &["A".to_string()]).is_err());
        m.elements[0].conn = [0, 1, 2, 3];
        let r = quality_report(&m, &["A".to_string()]).unwrap();
        assert_eq!(r.total.elements, 1);
        assert!((r.total.area_mm2 - 1.0).abs() < 1e-12);
        assert!(r.to_csv().lines().count() == 3);
    }
}
