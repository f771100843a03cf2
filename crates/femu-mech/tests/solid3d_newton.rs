//! The 3D solve runs on the plane-strain solver's Newton driver: its cut-back and its report.

use femu_mech::solid3d::{self, Body3, Element3, Kind3, Options3};
use femu_mech::NeoHookean;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// An `n x n x n` C3D8 cube of side `l` on the symmetry planes x = 0, y = 0, z = 0, its face
/// x = l moved by `dx`.
fn cube(n: usize, l: f64, dx: f64) -> Body3 {
    let id = |i: usize, j: usize, k: usize| (k * (n + 1) + j) * (n + 1) + i;
    let h = l / n as f64;
    let mut nodes = vec![[0.0; 3]; (n + 1).pow(3)];
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                nodes[id(i, j, k)] = [i as f64 * h, j as f64 * h, k as f64 * h];
            }
        }
    }
    let mut elements = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let base = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
                let nodes = [k, k + 1]
                    .iter()
                    .flat_map(|&kk| base.iter().map(move |&(a, b)| id(a, b, kk)))
                    .collect();
                elements.push(Element3 {
                    kind: Kind3::C3d8,
                    nodes,
                    material: 0,
                });
            }
        }
    }
    let mut prescribed = Vec::new();
    for (a, x) in nodes.iter().enumerate() {
        for c in 0..3 {
            if x[c] == 0.0 {
                prescribed.push((a, c, 0.0));
            }
        }
        if (x[0] - l).abs() < 1e-12 {
            prescribed.push((a, 0, dx));
        }
    }
    Body3 {
        nodes,
        elements,
        materials: vec![Box::new(NeoHookean {
            c10: 1.75e-3,
            d: 18.0,
        })],
        prescribed,
        loads: Vec::new(),
        pressures: Vec::new(),
    }
}

/// Compressing the cube by 60 % in one increment moves the loaded face through the elements
/// next to it: the predictor inverts them, the driver cuts the increment back (as it does in
/// plane strain) and reaches the state the solve in eight increments reaches, with the report
/// counting the cut-back.
#[test]
fn a_3d_increment_that_inverts_elements_is_cut_back() {
    let body = cube(2, 1.0, -0.6);
    let tight = Options3 {
        increments: 1,
        tolerance: 1e-12,
        ..Default::default()
    };
    let one = solid3d::solve(&body, &tight).unwrap();
    let eight = solid3d::solve(
        &body,
        &Options3 {
            increments: 8,
            ..tight
        },
    )
    .unwrap();
    println!(
        "one increment: {} cut-backs, {} converged increments, {} iterations; eight: {} cut-backs",
        one.report.cutbacks,
        one.report.converged_increments,
        one.report.newton_iterations,
        eight.report.cutbacks
    );
    measure::record(
        "C3D8 cube compressed 60 % in one increment: cut-backs",
        one.report.cutbacks as f64,
        "≥ 1",
        "",
    );
    assert!(one.report.cutbacks >= 1, "{:?}", one.report.increments);
    assert_eq!(one.report.lambda, 1.0);
    assert_eq!(one.iterations.len(), one.report.converged_increments);
    let failure = one.report.increments[0].failure.as_deref().unwrap_or("");
    assert!(failure.contains("inverted"), "{failure}");
    // Two solves converged to 1e-12 of the reactions: equal to far below 1e-9 of the
    // displacement (the tangent is well conditioned at 40 % stretch).
    let scale = 0.6;
    let worst = one
        .u
        .iter()
        .zip(&eight.u)
        .flat_map(|(a, b)| (0..3).map(move |i| (a[i] - b[i]).abs()))
        .fold(0.0f64, f64::max);
    measure::record(
        "one increment cut back against eight increments: largest nodal difference / 0.6 mm",
        worst / scale,
        "≤ 1e-9",
        "",
    );
    assert!(worst <= 1e-9 * scale, "{worst:e}");
    // The homogeneous uniaxial state: u_x = -0.6 x at every node.
    let homogeneous = body
        .nodes
        .iter()
        .zip(&one.u)
        .fold(0.0f64, |m, (x, u)| m.max((u[0] - (-0.6 * x[0])).abs()));
    measure::record(
        "one increment cut back: largest |u_x + 0.6 x| (the homogeneous state)",
        homogeneous,
        "≤ 1e-9",
        "mm",
    );
    for (x, u) in body.nodes.iter().zip(&one.u) {
        assert!((u[0] - (-0.6 * x[0])).abs() <= 1e-9, "{x:?}: {u:?}");
    }
}
