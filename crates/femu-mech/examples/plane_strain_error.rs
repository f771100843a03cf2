//! How far the plane-strain section is from a thigh of finite length under a probe.
//!
//! The parametric thigh's section (4.5 mm quads, CPE4H) is solved in plane strain under a
//! pressure on a 10 mm wide skin patch (anterior); the same section swept along the femur axis
//! into C3D8H hexahedra (`femu_geometry::thigh3d`), of length L with free ends, is loaded by
//! the same pressure on a patch of that width and of a given length along the axis, centred at
//! L / 2, and solved in 3D (`femu_mech::solid3d`). The layers are 4 mm or finer under the
//! patch and grow by 1.6 per layer towards the ends. Printed per case: the mid-section's
//! in-plane displacement against the 2D solution (max and RMS of |Δu| relative to the 2D
//! max and RMS of |u|; the mid-section is a plane of symmetry, so its axial displacement is
//! zero) and the displacement, in 3D and 2D, of the node that moves most in 2D (under the probe).
//!
//! Run with `cargo run --profile test -p femu-mech --example plane_strain_error [-- PRESSURE_KPA]`
//! (default 2.67 kPa, 20 mmHg).

use femu_geometry::thigh3d::{skin_patch_2d, sweep_thigh, Sweep};
use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_mech::solid3d::{self, Body3, Options3};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::{ElementKind, FacePressure};
use std::time::Instant;

fn main() {
    let kpa: f64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("a pressure in kPa"))
        .unwrap_or(20.0 * femu_mesh::MMHG_IN_MPA * 1e3);
    let p = kpa * 1e-3;
    let params = ThighParams {
        element_size_mm: Some(4.5),
        ..ThighParams::default()
    };
    let model = parametric_thigh(&params, ElementKind::Cpe4h).expect("section");
    let width = 10.0;
    let patch = skin_patch_2d(&model, 90.0, width);
    let mut deck2 = contention_deck(&model, &table1_materials(), 0.0).expect("deck");
    deck2.pressures = patch
        .iter()
        .map(|&(element, face)| FacePressure {
            element,
            face,
            magnitude: p,
        })
        .collect();
    let model2 = Model::from_deck(deck2).expect("model");
    let u2 = StaticSolver::new(&model2, SolverOptions::default())
        .expect("solver")
        .solve(&model2)
        .expect("2D solve")
        .u;
    let nn = model.mesh.mesh.nodes.len();
    let u2_at = |n: usize| [u2[2 * n], u2[2 * n + 1]];
    let mag = |v: [f64; 2]| v[0].hypot(v[1]);
    let max2 = (0..nn).map(|n| mag(u2_at(n))).fold(0.0, f64::max);
    let rms2 = ((0..nn).map(|n| mag(u2_at(n)).powi(2)).sum::<f64>() / nn as f64).sqrt();
    // The node of the patch with the largest 2D displacement: the indentation.
    let probe = (0..nn)
        .max_by(|&a, &b| mag(u2_at(a)).total_cmp(&mag(u2_at(b))))
        .unwrap();
    println!(
        "section: {} quads, {nn} nodes; patch {width} mm wide ({} skin faces); pressure {kpa:.1} kPa; \
         2D: max |u| {max2:.3} mm, RMS |u| {rms2:.3} mm",
        model.mesh.mesh.elements.len(),
        patch.len()
    );
    println!(
        "| L (mm) | patch along axis (mm) | hexahedra | max |Δu| / max |u_2D| | RMS |Δu| / RMS |u_2D| | |u| at the probe 3D / 2D | solve (s) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (length, along) in [(60.0, 40.0), (120.0, 40.0), (120.0, 10.0), (240.0, 40.0)] {
        let half: f64 = 0.5 * along;
        let fine = half / (half / 4.0).ceil();
        let sweep = Sweep::graded(length, 0.5 * length, half, fine, 1.6);
        let mid = sweep
            .levels
            .iter()
            .position(|&z| (z - 0.5 * length).abs() < 1e-9)
            .expect("a level at L / 2");
        let thigh = sweep_thigh(&model, &sweep).expect("sweep");
        let faces = thigh.skin_patch(&model, 90.0, width, 0.5 * length, along);
        let deck3 = thigh
            .deck(&table1_materials(), &faces, p, false)
            .expect("deck");
        let body = Body3::from_deck3(&deck3).expect("body");
        let start = Instant::now();
        let sol = solid3d::solve(
            &body,
            &Options3 {
                increments: 2,
                ..Options3::default()
            },
        )
        .expect("3D solve");
        let seconds = start.elapsed().as_secs_f64();
        let (mut max_d, mut sum_d) = (0.0f64, 0.0);
        for n in 0..nn {
            let u = sol.u[mid * nn + n];
            let d = mag([u[0] - u2[2 * n], u[1] - u2[2 * n + 1]]);
            max_d = max_d.max(d);
            sum_d += d * d;
        }
        let rms_d = (sum_d / nn as f64).sqrt();
        let up = sol.u[mid * nn + probe];
        println!(
            "| {length:.0} | {along:.0} | {} | {:.3} | {:.3} | {:.3} / {:.3} mm | {seconds:.1} |",
            thigh.mesh.elements.len(),
            max_d / max2,
            rms_d / rms2,
            mag([up[0], up[1]]),
            mag(u2_at(probe)),
        );
    }
}
