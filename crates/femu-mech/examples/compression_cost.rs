//! The paper-scale compression test (rigid plate, 0.1 N/mm, anterior, femur fixed) with its
//! Newton history, for studying the increment settings:
//!
//! ```text
//! cargo run --release -p femu-mech --example compression_cost -- \
//!     [elements 25000] [cpe4|cpe4h] [intermediate_tolerance 2e-2] [growth 2] [penalty_factor 10] \
//!     [initial_increment 0.02]
//! ```
//!
//! Prints, per increment, the load factor, the number of Newton iterations and after each
//! iteration the relative residual `‖R‖/‖f_ref‖` with the step length taken (`residual@step`);
//! then the plate's travel and force, the time of setup + solve and where it went.

use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;
use std::time::Instant;

fn arg<T: std::str::FromStr>(k: usize, default: T) -> T {
    std::env::args()
        .nth(k)
        .and_then(|a| a.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let elements: usize = arg(1, 25_000);
    let kind = match std::env::args().nth(2).as_deref() {
        Some("cpe4h") => ElementKind::Cpe4h,
        _ => ElementKind::Cpe4,
    };
    let defaults = SolverOptions::default();
    let options = SolverOptions {
        intermediate_tolerance: arg(3, defaults.intermediate_tolerance),
        growth: arg(4, defaults.growth),
        ..defaults
    };
    let thigh = parametric_thigh(
        &ThighParams {
            target_elements: Some(elements),
            ..Default::default()
        },
        kind,
    )
    .expect("built-in thigh");
    let skin = thigh.mesh.surfaces["SKIN"].clone();
    let mut deck = contention_deck(&thigh, &table1_materials(), 0.0).expect("deck");
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).expect("model");
    apply_loading(&mut model, &skin, &Loading::seed_compression()).expect("compression");
    model.contacts[0].penalty_factor = arg(5, model.contacts[0].penalty_factor);
    model.step.initial_increment = arg(6, model.step.initial_increment);
    println!(
        "{} elements ({kind:?}), intermediate tolerance {:e}, growth {}, penalty factor {}",
        model.mesh.elements.len(),
        options.intermediate_tolerance,
        options.growth,
        model.contacts[0].penalty_factor
    );
    let t0 = Instant::now();
    let solution = StaticSolver::new(&model, options).and_then(|mut s| s.solve(&model));
    let seconds = t0.elapsed().as_secs_f64();
    let solution = match solution {
        Ok(s) => s,
        Err(e) => {
            eprintln!("compression test failed after {seconds:.3} s: {e}");
            std::process::exit(1);
        }
    };
    for inc in &solution.report.increments {
        let history: Vec<String> = inc
            .iterations
            .iter()
            .map(|i| {
                format!(
                    "{:.1e}@{:.2}",
                    i.residual_norm / i.reference_force,
                    i.step_length
                )
            })
            .collect();
        println!(
            "increment {:2}: load factor {:.4}, {:2} iterations: {}{}",
            inc.increment,
            inc.lambda,
            inc.iterations.len(),
            history.join(" "),
            if inc.converged { "" } else { " (cut back)" }
        );
    }
    if let Some([travel, force]) = solution
        .report
        .increments
        .last()
        .and_then(|i| i.bodies.first())
    {
        println!("plate travel {travel:.4} mm for {force:.4e} N/mm");
    }
    println!(
        "setup + solve {seconds:.3} s: {} increments, {} Newton iterations",
        solution.report.converged_increments, solution.report.newton_iterations
    );
    let r = &solution.report;
    println!(
        "  setup {:.3} s, assembly {:.3} s, factorization {:.3} s, triangular solves {:.3} s, rest {:.3} s",
        r.setup_time_s,
        r.assembly_time_s,
        r.factorization_time_s,
        r.triangular_solve_time_s,
        seconds - r.setup_time_s - r.assembly_time_s - r.factorization_time_s - r.triangular_solve_time_s
    );
}
