//! Solves the thigh-like contention problem (about 25 000 CPE4 quads, 20 mmHg on the skin)
//! and prints the Newton table and timings: `cargo run --release -p femu-mech --example thigh_contention`.

use femu_mech::build::DeckBuilder;
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::generate::{thigh_like, ThighLikeParams};
use std::time::Instant;

fn main() {
    let t0 = Instant::now();
    let g = thigh_like(&ThighLikeParams::default());
    let deck = DeckBuilder::new(g)
        .material("FAT", 0.8e-3, 30.8)
        .material("QUADRICEPS", 1.75e-3, 18.0)
        .material("ISCHIO", 3.0e-3, 18.0)
        .material("GRACILIS", 2.2e-3, 18.0)
        .material("SARTORIUS", 3.75e-3, 18.0)
        .fix("INNER")
        .pressure("OUTER", 2.666e-3)
        .build();
    let model = Model::from_deck(deck).unwrap();
    let t1 = Instant::now();
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
    let t2 = Instant::now();
    let sol = solver.solve(&model).unwrap();
    let t3 = Instant::now();
    for inc in &sol.report.increments {
        for it in &inc.iterations {
            println!(
                "inc {} it {} |R| {:.3e} ref {:.3e} E {:.3e} alpha {:.2}",
                inc.increment,
                it.iteration,
                it.residual_norm,
                it.reference_force,
                it.energy_norm,
                it.step_length
            );
        }
    }
    let umax = sol.u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    println!(
        "elements {} eqs {} nnz {} | model {:.3}s setup {:.3}s solve {:.3}s | max|u| {:.4} mm | reaction {:?}",
        model.mesh.elements.len(),
        sol.report.equations,
        sol.report.matrix_nonzeros,
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        (t3 - t2).as_secs_f64(),
        umax,
        sol.report.reaction_total
    );
    let r = &sol.report;
    println!(
        "assembly {:.3}s factorization {:.3}s triangular {:.3}s ({:?})",
        r.assembly_time_s, r.factorization_time_s, r.triangular_solve_time_s, r.factorization
    );
    // warm start from the solution with slightly changed parameters
    let mut m2 = model.clone();
    m2.materials[1].law.c10 *= 1.01;
    let t4 = Instant::now();
    let sol2 = solver.solve_with(&m2, Some(&sol.u), &mut |_| {}).unwrap();
    println!(
        "warm start: {:.3}s, {} iterations",
        t4.elapsed().as_secs_f64(),
        sol2.report.newton_iterations
    );
}
