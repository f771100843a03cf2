//! The tangent factorized by halves of the bisected mesh (`SplitLdlt`, used for large models)
//! gives the same Newton solutions as the whole factorization: contention (follower pressure),
//! force-controlled compression (a bordered equation in the separator) and force-controlled
//! indentation, on a built-in thigh small enough for a test, with the split forced.

use common::thigh_model as thigh;
use femu_mech::loading::Loading;
use femu_mech::Factorization;
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;

mod common;

fn compare(model: &Model) {
    let options = |split_min_equations| SolverOptions {
        residual_tolerance: 1e-10,
        split_min_equations,
        ..Default::default()
    };
    let whole = StaticSolver::new(model, options(usize::MAX))
        .unwrap()
        .solve(model)
        .expect("whole converges");
    let halves = StaticSolver::new(model, options(0))
        .unwrap()
        .solve(model)
        .expect("halves converge");
    assert_eq!(whole.report.factorization, Some(Factorization::Ldlt));
    assert_eq!(halves.report.factorization, Some(Factorization::SplitLdlt));
    // The same Newton path: iteration counts equal, states equal to rounding amplified by the
    // Newton iterations (1e-9 of the largest displacement is far below the 1e-10 residual
    // tolerance's effect on the displacements, ~1e-8).
    assert_eq!(
        whole.report.newton_iterations,
        halves.report.newton_iterations
    );
    let scale = whole.u.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = whole
        .u
        .iter()
        .zip(&halves.u)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    println!(
        "{} Newton iterations, max |u_whole - u_halves| / max |u| = {:.1e}",
        whole.report.newton_iterations,
        diff / scale
    );
    assert!(diff <= 1e-9 * scale, "{diff} vs {scale}");
}

#[test]
fn halves_equal_whole_under_contention() {
    compare(&thigh(3000, ElementKind::Cpe4, &Loading::seed_contention()));
}

#[test]
fn halves_equal_whole_under_force_controlled_compression() {
    compare(&thigh(
        2000,
        ElementKind::Cpe4h,
        &Loading::seed_compression(),
    ));
}

#[test]
fn halves_equal_whole_under_indentation() {
    compare(&thigh(
        2000,
        ElementKind::Cpe4h,
        &Loading::new(femu_mech::loading::Indentation {
            site: femu_mech::loading::Side::Lateral,
            radius: 10.0,
            force: 0.02,
        }),
    ));
}
