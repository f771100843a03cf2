//! One assembly of the residual and tangent (element loop and gather, no factorization) on the
//! built-in thigh at paper scale under contention, at the converged state, many times in one
//! process (the best of many is steady on a noisy machine):
//!
//! ```sh
//! cargo run --release -p femu-mech --example assembly_cost -- [elements] [repeat] [cpe4|cpe4h]
//! ```

use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let elements: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(25_000);
    let repeat: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(50);
    let kind = match args.next().as_deref() {
        Some("cpe4h") => ElementKind::Cpe4h,
        _ => ElementKind::Cpe4,
    };
    let params = femu_geometry::ThighParams {
        target_elements: Some(elements),
        ..Default::default()
    };
    let thigh = femu_geometry::parametric_thigh(&params, kind).expect("thigh");
    let deck = femu_geometry::contention_deck(
        &thigh,
        &femu_geometry::Material::table1(),
        femu_geometry::CONTENTION_MPA,
    )
    .expect("deck");
    let model = Model::from_deck(deck).expect("model");
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
        "{} {kind:?} elements, {} threads: assembly with tangent best {:.2} ms, median {:.2} ms ({repeat} runs)",
        model.mesh.elements.len(),
        rayon::current_num_threads(),
        times[0] * 1e3,
        times[repeat / 2] * 1e3
    );
}
