//! Point location and interpolation ([`femu_mesh::PointInterpolation`]): the operator that
//! compares meshes at the DIC grid points (seed §2.1.2.1, §2.4.1).

use femu_mesh::generate::{self, GeneratedMesh};
use femu_mesh::{ElementKind, PointInterpolation};

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// A 4 x 3 mm rectangle of 8 x 6 quads with every interior node moved by up to 30 % of the
/// spacing (a fixed pseudo-random pattern): the quads are general, not parallelograms.
fn distorted(kind: ElementKind) -> GeneratedMesh {
    let mut g = generate::rectangle(4.0, 3.0, 8, 6, ElementKind::Cpe4);
    let (lo, hi) = g.mesh.bounding_box();
    for (k, x) in g.mesh.nodes.iter_mut().enumerate() {
        let interior = x[0] > lo[0] + 1e-9
            && x[0] < hi[0] - 1e-9
            && x[1] > lo[1] + 1e-9
            && x[1] < hi[1] - 1e-9;
        if interior {
            let s = ((k * 7919) % 101) as f64 / 100.0 - 0.5;
            let t = ((k * 104_729) % 97) as f64 / 96.0 - 0.5;
            x[0] += 0.6 * 0.5 * s;
            x[1] += 0.6 * 0.5 * t;
        }
    }
    if kind == ElementKind::Cpe3 {
        g = generate::split_into_triangles(&g);
    } else {
        for el in &mut g.mesh.elements {
            el.kind = kind;
        }
    }
    g.mesh.check_orientation().unwrap();
    g
}

/// A linear field is in the span of the bilinear (and linear) shape functions: interpolated
/// exactly (to round-off) at any point of any element, quads and triangles.
#[test]
fn linear_field_is_interpolated_exactly_and_outside_points_are_masked() {
    let field = |p: [f64; 2]| {
        [
            0.3 + 1.5 * p[0] - 0.7 * p[1],
            -2.0 + 0.25 * p[0] + 3.0 * p[1],
        ]
    };
    for kind in [ElementKind::Cpe4, ElementKind::Cpe4h, ElementKind::Cpe3] {
        let g = distorted(kind);
        let u: Vec<f64> = g.mesh.nodes.iter().flat_map(|&p| field(p)).collect();
        // A 41 x 31 grid over [-0.5, 4.5] x [-0.5, 3.5]: the points beyond the rectangle are
        // outside the mesh.
        let mut pts = Vec::new();
        let mut expected_inside = 0;
        for j in 0..31 {
            for i in 0..41 {
                let p = [-0.5 + 5.0 * i as f64 / 40.0, -0.5 + 4.0 * j as f64 / 30.0];
                let inside = p[0] >= 0.0 && p[0] <= 4.0 && p[1] >= 0.0 && p[1] <= 3.0;
                expected_inside += usize::from(inside);
                pts.push(p);
            }
        }
        let ip = PointInterpolation::new(&g.mesh, &pts);
        assert_eq!(ip.inside(), expected_inside, "{kind:?}");
        assert_eq!(ip.masked(), pts.len() - expected_inside, "{kind:?}");
        let v = ip.interpolate_vector(&u);
        let mut worst = 0.0f64;
        for (p, v) in pts.iter().zip(&v) {
            let inside = p[0] >= 0.0 && p[0] <= 4.0 && p[1] >= 0.0 && p[1] <= 3.0;
            assert_eq!(v.is_some(), inside, "{kind:?} at {p:?}");
            if let Some(v) = v {
                let e = field(*p);
                worst = worst.max((v[0] - e[0]).abs()).max((v[1] - e[1]).abs());
            }
        }
        measure::record(
            &format!(
                "{} on a distorted mesh, linear field: largest interpolation error ({} of {} points inside, the rest masked)",
                kind.deck_name(),
                ip.inside(),
                pts.len()
            ),
            worst,
            "< 1e-12",
            "mm",
        );
        assert!(worst < 1e-12, "{kind:?}: largest error {worst:.3e}");
        // The projection operator gives the same values, and its rows sum to 1.
        let mut proj = vec![0.0; 2 * pts.len()];
        let mut row_sum = vec![0.0; 2 * pts.len()];
        for (r, c, w) in ip.projection_triplets() {
            proj[r] += w * u[c];
            row_sum[r] += w;
        }
        for (k, v) in v.iter().enumerate() {
            if let Some(v) = v {
                assert!(
                    (proj[2 * k] - v[0]).abs() < 1e-12 && (proj[2 * k + 1] - v[1]).abs() < 1e-12
                );
                assert!((row_sum[2 * k] - 1.0).abs() < 1e-12);
            } else {
                assert_eq!(row_sum[2 * k], 0.0);
            }
        }
    }
}

/// Nodes are found (weight 1 on themselves), and so are points in a hole's neighbourhood: an
/// annulus masks the points in its hole and outside.
#[test]
fn nodes_and_annulus_hole() {
    let g = generate::annulus(1.0, 1.5, 2.0, 32, 3, 2, ElementKind::Cpe4);
    let nodes = g.mesh.nodes.clone();
    let ip = PointInterpolation::new(&g.mesh, &nodes);
    assert_eq!(ip.masked(), 0);
    for (n, l) in ip.locations.iter().enumerate() {
        let l = l.unwrap();
        let a = (0..l.n_nodes).find(|&a| l.nodes[a] == n).unwrap();
        assert!((l.weights[a] - 1.0).abs() < 1e-9, "node {n}: {l:?}");
    }
    let pts = [
        [0.0, 0.0],
        [0.5, 0.5],
        [1.2, 0.0],
        [0.0, -1.8],
        [2.5, 0.0],
        [f64::NAN, 0.0],
    ];
    let ip = PointInterpolation::new(&g.mesh, &pts);
    let inside: Vec<bool> = ip.locations.iter().map(Option::is_some).collect();
    assert_eq!(inside, [false, false, true, true, false, false]);
}
