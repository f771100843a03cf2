//! The tangent factorization whole (faer's supernodal LDLᵀ, one core) against by halves
//! (`SplitLdlt`, the two halves of the bisected mesh on two cores), on the built-in thigh at
//! paper scale under contention, alternated so that both see the same machine load:
//!
//! ```sh
//! cargo run --release -p femu-mech --example factorization_cost -- [elements] [repeat] [cpe4|cpe4h]
//! ```
//!
//! Prints, per variant, the median and best of: solver setup (pattern, ordering, symbolic
//! analysis), the whole Newton solve, one assembly + factorization at the solution, one solve
//! with ten right-hand sides; and the largest difference between the two solutions.

mod common;

use common::{cost_args, print_model, thigh_deck, CostArgs};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;
use std::time::Instant;

fn stats(v: &[f64]) -> String {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    format!("median {:.4} s, best {:.4} s", s[s.len() / 2], s[0])
}

fn main() {
    let CostArgs {
        elements,
        repeat,
        kind,
    } = cost_args(5, ElementKind::Cpe4);
    let model = Model::from_deck(thigh_deck(elements, kind).0).expect("model");
    print_model(&model, kind);
    let variants = [
        (
            "whole ",
            SolverOptions {
                split_min_equations: usize::MAX,
                ..Default::default()
            },
        ),
        ("halves", SolverOptions::default()),
    ];
    let mut times = vec![[const { Vec::new() }; 4]; variants.len()];
    let mut solutions: Vec<Vec<f64>> = vec![Vec::new(); variants.len()];
    for _ in 0..repeat {
        for (v, (_, options)) in variants.iter().enumerate() {
            let t = Instant::now();
            let mut solver = StaticSolver::new(&model, *options).expect("setup");
            times[v][0].push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let solution = solver.solve(&model).expect("solve");
            times[v][1].push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            solver
                .assemble_at(&model, &solution.state)
                .expect("assembly");
            let mut lin = solver.linearize(&model, &solution.state).expect("tangent");
            lin.factorize().expect("factorize");
            times[v][2].push(t.elapsed().as_secs_f64());
            let n = lin.equations();
            let mut rhs: Vec<f64> = (0..10 * n).map(|i| ((i % 97) as f64).sin()).collect();
            let t = Instant::now();
            lin.solve_many(&mut rhs, 10);
            times[v][3].push(t.elapsed().as_secs_f64());
            solutions[v] = solution.u;
        }
    }
    for (v, (name, _)) in variants.iter().enumerate() {
        println!(
            "{name}: setup {}; Newton solve {}; assembly + factorization {}; 10 solves {}",
            stats(&times[v][0]),
            stats(&times[v][1]),
            stats(&times[v][2]),
            stats(&times[v][3])
        );
    }
    let scale = solutions[0].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = solutions[0]
        .iter()
        .zip(&solutions[1])
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    println!("max |u_whole - u_halves| / max |u| = {:.2e}", diff / scale);
}
