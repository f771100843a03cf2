//! The swept 3D thigh (`femu_geometry::thigh3d`) solved by femu's 3D solve
//! (`femu_mech::solid3d`):
//!
//! 1. [`plane_strain_sweep_reproduces_the_2d_solution`]: with its ends held along the axis the
//!    prism is in plane strain, and its solution is the 2D plane-strain solution of the section
//!    (C3D8H against CPE4H, C3D8 against CPE4: the 2x2x2 rule integrates a z-independent field
//!    as the 2x2 rule times the thickness, and the mean dilatation is the same average), within
//!    1e-6 of the largest displacement.
//! 2. [`calculix_agrees_on_a_swept_thigh`]: a few thousand hexahedra under a probe-sized
//!    pressure patch, the deck written by `write_inp3` and run by CalculiX 2.20 (`ccx`).
//!    CalculiX has no hybrid hexahedron and its static follower pressure depends on its
//!    increments (see tests/calculix.rs), so the comparison is C3D8 against C3D8 with the
//!    pressure as dead nodal loads (`*CLOAD`) equal to it on the reference geometry.

use femu_geometry::thigh3d::{skin_patch_2d, sweep_thigh, Sweep};
use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_mech::solid3d::{self, deck::pressures_to_dead_loads, Body3, Options3};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::{ElementKind, ElementKind3, FacePressure};
use std::time::Instant;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// 20 mmHg (MPa).
const P20: f64 = 20.0 * femu_mesh::MMHG_IN_MPA;

fn norm(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

#[test]
fn plane_strain_sweep_reproduces_the_2d_solution() {
    let params = ThighParams {
        element_size_mm: Some(4.5),
        ..ThighParams::default()
    };
    for (kind2, kind3) in [
        (ElementKind::Cpe4h, ElementKind3::C3d8h),
        (ElementKind::Cpe4, ElementKind3::C3d8),
    ] {
        let model = parametric_thigh(&params, kind2).unwrap();
        // The probe's width on the anterior skin at 20 mmHg.
        let patch = skin_patch_2d(&model, 90.0, 10.0);
        let p = P20;
        let mut deck2 = contention_deck(&model, &table1_materials(), 0.0).unwrap();
        deck2.pressures = patch
            .iter()
            .map(|&(element, face)| FacePressure {
                element,
                face,
                magnitude: p,
            })
            .collect();
        let model2 = Model::from_deck(deck2).unwrap();
        let options2 = SolverOptions {
            residual_tolerance: 1e-11,
            ..SolverOptions::default()
        };
        let u2 = StaticSolver::new(&model2, options2)
            .unwrap()
            .solve(&model2)
            .unwrap()
            .u;

        let sweep = Sweep {
            kind: kind3,
            ..Sweep::uniform(8.0, 2)
        };
        let thigh = sweep_thigh(&model, &sweep).unwrap();
        let faces = thigh.skin_patch(&model, 90.0, 10.0, 4.0, 8.0);
        assert_eq!(faces.len(), 2 * patch.len());
        let deck3 = thigh.deck(&table1_materials(), &faces, p, true).unwrap();
        let body = Body3::from_deck3(&deck3).unwrap();
        let options = Options3 {
            tolerance: 1e-11,
            ..Options3::default()
        };
        let sol = solid3d::solve(&body, &options).unwrap();
        let nn = model.mesh.mesh.nodes.len();
        let scale = (0..nn)
            .map(|n| u2[2 * n].hypot(u2[2 * n + 1]))
            .fold(0.0, f64::max);
        let mut worst: f64 = 0.0;
        for (i, u) in sol.u.iter().enumerate() {
            let n = i % nn;
            worst = worst.max(norm([u[0] - u2[2 * n], u[1] - u2[2 * n + 1], u[2]]));
        }
        let rel = worst / scale;
        println!(
            "{} vs {}: max |u_3D - u_2D| / max |u_2D| = {rel:.1e} (max |u| = {scale:.3} mm, {} hexahedra)",
            kind3.deck_name(),
            kind2.deck_name(),
            thigh.mesh.elements.len()
        );
        // Both solves converge to 1e-11 of the force scale; 1e-6 leaves room for the
        // conditioning of the nearly incompressible tissue (K / μ up to 80).
        measure::record(
            &format!(
                "{} swept thigh in plane strain against {}: largest difference / largest displacement",
                kind3.deck_name(),
                kind2.deck_name()
            ),
            rel,
            "< 1e-6",
            "",
        );
        assert!(rel < 1e-6, "{kind3:?}: {rel:e}");
    }
}

#[test]
fn calculix_agrees_on_a_swept_thigh() {
    if std::process::Command::new("ccx")
        .arg("-v")
        .output()
        .is_err()
    {
        println!("SKIPPED: ccx not installed (apt-get install calculix-ccx)");
        return;
    }
    let params = ThighParams {
        element_size_mm: Some(4.5),
        ..ThighParams::default()
    };
    let model = parametric_thigh(&params, ElementKind::Cpe4).unwrap();
    // 60 mm in 6 layers with a 10 % taper; the probe (40 mm x 10 mm) on the anterior skin.
    let sweep = Sweep {
        end_scale: 0.9,
        kind: ElementKind3::C3d8,
        ..Sweep::uniform(60.0, 6)
    };
    let thigh = sweep_thigh(&model, &sweep).unwrap();
    let faces = thigh.skin_patch(&model, 90.0, 10.0, 30.0, 40.0);
    let mut deck = thigh.deck(&table1_materials(), &faces, P20, false).unwrap();
    // The follower answer, for the record.
    let follower = {
        let body = Body3::from_deck3(&deck).unwrap();
        solid3d::solve(&body, &Options3::default()).unwrap()
    };
    pressures_to_dead_loads(&mut deck);
    deck.step.initial_increment = 0.25;
    deck.step.max_increment = 0.25;

    let dir = std::env::temp_dir().join(format!("femu-ccx-thigh3d-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut text = Vec::new();
    femu_mesh::write_inp3(&deck, &mut text).unwrap();
    std::fs::write(dir.join("job.inp"), &text).unwrap();
    let start = Instant::now();
    let out = std::process::Command::new("ccx")
        .args(["-i", "job"])
        .current_dir(&dir)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .unwrap();
    let ccx_s = start.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && !stdout.contains("*ERROR"),
        "ccx failed; deck kept in {}:\n{stdout}",
        dir.display()
    );
    let dat = std::fs::read_to_string(dir.join("job.dat")).unwrap();
    let ccx = femu_mesh::inp::parse_ccx_dat_displacements3(&dat, "job.dat").unwrap();

    let body = Body3::from_deck3(&deck).unwrap();
    let start = Instant::now();
    let sol = solid3d::solve(
        &body,
        &Options3 {
            tolerance: 1e-11,
            ..Options3::default()
        },
    )
    .unwrap();
    let femu_s = start.elapsed().as_secs_f64();
    assert_eq!(ccx.len(), thigh.mesh.nodes.len());
    let scale = ccx.iter().fold(0.0f64, |m, (_, u)| m.max(norm(*u)));
    let worst = ccx.iter().fold(0.0f64, |m, (label, u)| {
        let v = sol.u[*label as usize - 1];
        m.max(norm(std::array::from_fn(|i| v[i] - u[i])))
    }) / scale;
    let follower_gap = sol.u.iter().zip(&follower.u).fold(0.0f64, |m, (a, b)| {
        m.max(norm(std::array::from_fn(|i| a[i] - b[i])))
    }) / scale;
    println!(
        "swept thigh, {} C3D8, {} nodes, probe patch of {} faces at 20 mmHg as dead loads: \
         max |u_femu - u_ccx| / max |u_ccx| = {worst:.1e} (max |u| {scale:.3} mm); \
         femu {femu_s:.2} s, ccx {ccx_s:.2} s; follower vs dead load in femu: {follower_gap:.1e}",
        thigh.mesh.elements.len(),
        thigh.mesh.nodes.len(),
        faces.len()
    );
    // ccx prints 7 significant digits (5e-7 of the largest displacement); 1e-5 as the brief.
    measure::record(
        &format!(
            "swept thigh, {} C3D8, 20 mmHg probe patch as dead loads: largest difference from ccx / largest displacement",
            thigh.mesh.elements.len()
        ),
        worst,
        "< 1e-5",
        "",
    );
    measure::record(
        "swept thigh: follower against dead-load pressure in femu, largest difference / largest displacement",
        follower_gap,
        "not asserted",
        "",
    );
    assert!(worst < 1e-5, "{worst:e}; deck in {}", dir.display());
    let _ = std::fs::remove_dir_all(&dir);
}
