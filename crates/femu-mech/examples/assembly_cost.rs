//! One assembly of the residual and tangent (element loop and gather, no factorization) on the
//! built-in thigh at paper scale under contention, at the converged state, many times in one
//! process (the best of many is steady on a noisy machine):
//!
//! ```sh
//! cargo run --release -p femu-mech --example assembly_cost -- [elements] [repeat] [cpe4|cpe4h]
//! ```

mod common;

use common::{cost_args, print_model, thigh_deck, CostArgs};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;
use std::time::Instant;

fn main() {
    let CostArgs {
        elements,
        repeat,
        kind,
    } = cost_args(50, ElementKind::Cpe4);
    let model = Model::from_deck(thigh_deck(elements, kind).0).expect("model");
    print_model(&model, kind);
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).expect("setup");
    let state = solver.solve(&model).expect("solve").state;
    let mut times = Vec::with_capacity(repeat);
    for _ in 0..repeat {
        let t = Instant::now();
        solver.assemble_at(&model, &state).expect("assembly");
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    println!(
        "assembly with tangent best {:.2} ms, median {:.2} ms ({repeat} runs)",
        times[0] * 1e3,
        times[repeat / 2] * 1e3
    );
}
