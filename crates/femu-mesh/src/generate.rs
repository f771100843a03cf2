//! Structured meshes generated in code: rectangles (patch tests), annuli (thick-walled
//! cylinder verification) and a thigh-like ring mesh (benchmarks).
//!
//! Ring meshes map a structured `n_theta x n_rows` grid between an inner circle (the femur, a
//! hole whose edge is fixed) and an outer ellipse (the skin), along rays from the circle's
//! centre. Element node order, with `i` the angular and `j` the radial index:
//!
//! ```text
//!   (i+1,j) ---- (i+1,j+1)        local 4 ---- 3
//!      |              |                 |      |      face P2 (index 1) is the outer arc,
//!   (i,j) ------ (i,j+1)          local 1 ---- 2      face P4 (index 3) the inner arc
//! ```
//! (counter-clockwise: radial first, then angular).

use crate::mesh::{Element, ElementKind, Mesh};
use std::collections::BTreeMap;

/// A generated mesh with its named boundary faces `(element, face)` (0-based face index).
#[derive(Debug, Clone, Default)]
pub struct GeneratedMesh {
    pub mesh: Mesh,
    pub surfaces: BTreeMap<String, Vec<(usize, usize)>>,
}

/// Axis-aligned rectangle `[0, w] x [0, h]` of `nx x ny` quads of `kind`.
/// Node sets `LEFT`, `RIGHT`, `BOTTOM`, `TOP`, `ALL`; element set `ALL`; surfaces `LEFT`,
/// `RIGHT`, `BOTTOM`, `TOP`.
pub fn rectangle(w: f64, h: f64, nx: usize, ny: usize, kind: ElementKind) -> GeneratedMesh {
    let mut g = GeneratedMesh::default();
    let m = &mut g.mesh;
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    for j in 0..=ny {
        for i in 0..=nx {
            m.add_node([w * i as f64 / nx as f64, h * j as f64 / ny as f64]);
        }
    }
    let mut all = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let e = m.add_element(Element::quad(
                kind,
                [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
            ));
            all.push(e);
            if j == 0 {
                g.surfaces.entry("BOTTOM".into()).or_default().push((e, 0));
            }
            if i == nx - 1 {
                g.surfaces.entry("RIGHT".into()).or_default().push((e, 1));
            }
            if j == ny - 1 {
                g.surfaces.entry("TOP".into()).or_default().push((e, 2));
            }
            if i == 0 {
                g.surfaces.entry("LEFT".into()).or_default().push((e, 3));
            }
        }
    }
    m.element_sets.insert("ALL".into(), all);
    m.node_sets
        .insert("LEFT".into(), (0..=ny).map(|j| id(0, j)).collect());
    m.node_sets
        .insert("RIGHT".into(), (0..=ny).map(|j| id(nx, j)).collect());
    m.node_sets
        .insert("BOTTOM".into(), (0..=nx).map(|i| id(i, 0)).collect());
    m.node_sets
        .insert("TOP".into(), (0..=nx).map(|i| id(i, ny)).collect());
    m.node_sets
        .insert("ALL".into(), (0..m.nodes.len()).collect());
    g
}

/// Splits every quadrilateral into two CPE3 triangles (alternating diagonals); sets and
/// surfaces are carried over (a quad face maps to the triangle that owns it).
pub fn split_into_triangles(g: &GeneratedMesh) -> GeneratedMesh {
    let src = &g.mesh;
    let mut out = GeneratedMesh::default();
    out.mesh.nodes = src.nodes.clone();
    out.mesh.node_labels = src.node_labels.clone();
    out.mesh.node_sets = src.node_sets.clone();
    // For quad e: triangles (first, second) and the map quad face -> (triangle, face).
    let mut face_map: Vec<[(usize, usize); 4]> = Vec::with_capacity(src.elements.len());
    let mut tri_of: Vec<[usize; 2]> = Vec::with_capacity(src.elements.len());
    for (e, el) in src.elements.iter().enumerate() {
        let c = el.conn;
        if el.kind == ElementKind::Cpe3 {
            let t = out.mesh.add_element(*el);
            tri_of.push([t, t]);
            face_map.push([(t, 0), (t, 1), (t, 2), (t, 2)]);
            continue;
        }
        if e % 2 == 0 {
            // diagonal 1-3: triangles (1,2,3), (1,3,4)
            let t0 = out.mesh.add_element(Element::tri([c[0], c[1], c[2]]));
            let t1 = out.mesh.add_element(Element::tri([c[0], c[2], c[3]]));
            tri_of.push([t0, t1]);
            face_map.push([(t0, 0), (t0, 1), (t1, 1), (t1, 2)]);
        } else {
            // diagonal 2-4: triangles (1,2,4), (2,3,4)
            let t0 = out.mesh.add_element(Element::tri([c[0], c[1], c[3]]));
            let t1 = out.mesh.add_element(Element::tri([c[1], c[2], c[3]]));
            tri_of.push([t0, t1]);
            face_map.push([(t0, 0), (t1, 0), (t1, 1), (t0, 2)]);
        }
    }
    for (name, set) in &src.element_sets {
        let mut v: Vec<usize> = set.iter().flat_map(|&e| tri_of[e]).collect();
        v.dedup();
        out.mesh.element_sets.insert(name.clone(), v);
    }
    for (name, faces) in &g.surfaces {
        out.surfaces.insert(
            name.clone(),
            faces.iter().map(|&(e, f)| face_map[e][f]).collect(),
        );
    }
    out
}

/// Builds a ring mesh; `radius(i, j)` gives the radial parameter `s ∈ [0, 1]` of node row `j`
/// on ray `i`, `outer(phi)` the skin point on the ray at angle `phi` from `center`, and
/// `region(i, j)` the region index of element `(i, j)`.
/// The structured grid of a ring mesh: inner circle, counts and element kind.
struct RingGrid {
    center: [f64; 2],
    r_inner: f64,
    n_theta: usize,
    n_rows: usize,
    kind: ElementKind,
}

fn ring(
    grid: RingGrid,
    outer: impl Fn(f64) -> [f64; 2],
    radius: impl Fn(usize, usize) -> f64,
    region: impl Fn(usize, usize) -> usize,
    region_names: &[&str],
) -> GeneratedMesh {
    let RingGrid {
        center,
        r_inner,
        n_theta,
        n_rows,
        kind,
    } = grid;
    let mut g = GeneratedMesh::default();
    let m = &mut g.mesh;
    let id = |i: usize, j: usize| (i % n_theta) * (n_rows + 1) + j;
    for i in 0..n_theta {
        let phi = 2.0 * std::f64::consts::PI * i as f64 / n_theta as f64;
        let a = [
            center[0] + r_inner * phi.cos(),
            center[1] + r_inner * phi.sin(),
        ];
        let b = outer(phi);
        for j in 0..=n_rows {
            let s = radius(i, j);
            m.add_node([a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])]);
        }
    }
    let mut sets: Vec<Vec<usize>> = vec![Vec::new(); region_names.len()];
    let mut skin = Vec::new();
    let mut bone = Vec::new();
    for i in 0..n_theta {
        for j in 0..n_rows {
            let e = m.add_element(Element::quad(
                kind,
                [id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)],
            ));
            sets[region(i, j)].push(e);
            if j == n_rows - 1 {
                skin.push((e, 1));
            }
            if j == 0 {
                bone.push((e, 3));
            }
        }
    }
    for (name, set) in region_names.iter().zip(sets) {
        if !set.is_empty() {
            m.element_sets.insert((*name).to_string(), set);
        }
    }
    m.node_sets
        .insert("INNER".into(), (0..n_theta).map(|i| id(i, 0)).collect());
    m.node_sets.insert(
        "OUTER".into(),
        (0..n_theta).map(|i| id(i, n_rows)).collect(),
    );
    g.surfaces.insert("OUTER".into(), skin);
    g.surfaces.insert("INNER".into(), bone);
    g
}

/// Annulus `r_in < r < r_out` centred at the origin, two materials split at `r_mid`
/// (element sets `INNER_LAYER`, `OUTER_LAYER`; `rows_inner` and `rows_outer` element rows,
/// uniform in each layer). Node sets `INNER`, `OUTER`; surfaces `INNER`, `OUTER`.
pub fn annulus(
    r_in: f64,
    r_mid: f64,
    r_out: f64,
    n_theta: usize,
    rows_inner: usize,
    rows_outer: usize,
    kind: ElementKind,
) -> GeneratedMesh {
    let s_mid = (r_mid - r_in) / (r_out - r_in);
    ring(
        RingGrid {
            center: [0.0, 0.0],
            r_inner: r_in,
            n_theta,
            n_rows: rows_inner + rows_outer,
            kind,
        },
        |phi| [r_out * phi.cos(), r_out * phi.sin()],
        |_, j| {
            if j <= rows_inner {
                s_mid * j as f64 / rows_inner as f64
            } else {
                s_mid + (1.0 - s_mid) * (j - rows_inner) as f64 / rows_outer as f64
            }
        },
        |_, j| usize::from(j >= rows_inner),
        &["INNER_LAYER", "OUTER_LAYER"],
    )
}

/// Dimensions of the thigh-like ring mesh (mm). Regions: `FAT` (outer band), and the muscle
/// band split by angle around the femur into `QUADRICEPS` (anterior, +y), `SARTORIUS`
/// (antero-medial), `GRACILIS` (medial, -x) and `ISCHIO` (posterior).
#[derive(Debug, Clone, Copy)]
pub struct ThighLikeParams {
    /// Skin ellipse semi-axes (x, y).
    pub skin_semi_axes: [f64; 2],
    pub femur_center: [f64; 2],
    pub femur_radius: f64,
    pub fat_thickness: f64,
    pub n_theta: usize,
    pub muscle_rows: usize,
    pub fat_rows: usize,
    pub kind: ElementKind,
}

impl Default for ThighLikeParams {
    /// About 25 000 quads, the seed's scale.
    fn default() -> Self {
        ThighLikeParams {
            skin_semi_axes: [70.0, 60.0],
            femur_center: [5.0, -4.0],
            femur_radius: 14.0,
            fat_thickness: 8.0,
            n_theta: 480,
            muscle_rows: 44,
            fat_rows: 8,
            kind: ElementKind::Cpe4,
        }
    }
}

/// Region names of [`thigh_like`], in region-index order.
pub const THIGH_REGIONS: [&str; 5] = ["FAT", "QUADRICEPS", "ISCHIO", "GRACILIS", "SARTORIUS"];

/// A thigh-like cross-section: femur hole (node set `INNER`), skin (node set and surface
/// `OUTER`), fat band and four muscle sectors. Used by the solver benchmark; the anatomical
/// parametric thigh is a separate model.
pub fn thigh_like(p: &ThighLikeParams) -> GeneratedMesh {
    let [a, b] = p.skin_semi_axes;
    let c = p.femur_center;
    let outer = move |phi: f64| {
        // Ray c + t d meets the ellipse (x/a)^2 + (y/b)^2 = 1.
        let d = [phi.cos(), phi.sin()];
        let qa = (d[0] / a).powi(2) + (d[1] / b).powi(2);
        let qb = 2.0 * (c[0] * d[0] / (a * a) + c[1] * d[1] / (b * b));
        let qc = (c[0] / a).powi(2) + (c[1] / b).powi(2) - 1.0;
        let t = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
        [c[0] + t * d[0], c[1] + t * d[1]]
    };
    let n_theta = p.n_theta;
    let rows = p.muscle_rows + p.fat_rows;
    let r_f = p.femur_radius;
    let s_fat = move |i: usize| {
        let phi = 2.0 * std::f64::consts::PI * i as f64 / n_theta as f64;
        let o = outer(phi);
        let len = ((o[0] - c[0]).powi(2) + (o[1] - c[1]).powi(2)).sqrt() - r_f;
        1.0 - p.fat_thickness / len
    };
    let (mr, fr) = (p.muscle_rows, p.fat_rows);
    ring(
        RingGrid {
            center: c,
            r_inner: r_f,
            n_theta,
            n_rows: rows,
            kind: p.kind,
        },
        outer,
        move |i, j| {
            let sf = s_fat(i);
            if j <= mr {
                sf * j as f64 / mr as f64
            } else {
                sf + (1.0 - sf) * (j - mr) as f64 / fr as f64
            }
        },
        move |i, j| {
            if j >= mr {
                return 0;
            }
            let deg = 360.0 * (i as f64 + 0.5) / n_theta as f64;
            match deg {
                d if (15.0..150.0).contains(&d) => 1,
                d if (150.0..172.0).contains(&d) => 4,
                d if (172.0..215.0).contains(&d) => 3,
                _ => 2,
            }
        },
        &THIGH_REGIONS,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_meshes_are_valid() {
        let r = rectangle(2.0, 1.0, 4, 3, ElementKind::Cpe4);
        assert_eq!(r.mesh.elements.len(), 12);
        r.mesh.check_orientation().unwrap();
        let t = split_into_triangles(&r);
        assert_eq!(t.mesh.elements.len(), 24);
        t.mesh.check_orientation().unwrap();
        assert_eq!(t.surfaces["TOP"].len(), 4);
        let a = annulus(1.0, 1.5, 2.0, 32, 3, 3, ElementKind::Cpe4h);
        a.mesh.check_orientation().unwrap();
        assert_eq!(a.mesh.boundary_faces().len(), 64);
        let th = thigh_like(&ThighLikeParams {
            n_theta: 96,
            muscle_rows: 10,
            fat_rows: 3,
            ..Default::default()
        });
        th.mesh.check_orientation().unwrap();
        assert_eq!(th.mesh.element_sets.len(), 5);
        let total: f64 = (0..th.mesh.elements.len())
            .map(|e| {
                let (x, _) = th.mesh.element_coords(e);
                0.5 * ((x[2][0] - x[0][0]) * (x[3][1] - x[1][1])
                    - (x[3][0] - x[1][0]) * (x[2][1] - x[0][1]))
            })
            .sum();
        let exact = std::f64::consts::PI * (70.0 * 60.0 - 14.0 * 14.0);
        assert!((total - exact).abs() < 0.01 * exact, "{total} vs {exact}");
    }
}
