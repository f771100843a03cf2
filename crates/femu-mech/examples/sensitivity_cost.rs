//! Cost of the ten direct-differentiation sensitivities against the forward solve (issue 5:
//! at most 30 %), on the built-in parametric thigh at paper scale, contention (20 mmHg) and
//! compression (0.1 N/mm), both measured in one run so that they see the same machine load:
//!
//! ```sh
//! cargo run --release -p femu-mech --example sensitivity_cost -- [elements] [repeat] [cpe4h|cpe4]
//! ```
//!
//! For each test and repeat: a fresh solver (setup not timed, as in `femu sensitivity`), the
//! forward solve timed, then `DirectSensitivity::compute` timed; the ratio of the best times
//! and the median of the per-repeat ratios are printed, with the sensitivity report (solves,
//! refactorization, residual).

mod common;

use common::{cost_args, print_model, thigh_deck, CostArgs};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::sensitivity::{all_parameters, DirectSensitivity};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;
use std::time::Instant;

fn main() {
    let CostArgs {
        elements,
        repeat,
        kind,
    } = cost_args(3, ElementKind::Cpe4h);
    let (mut deck, skin) = thigh_deck(elements, kind);
    deck.pressures.clear();
    let base = Model::from_deck(deck).expect("model");
    print_model(&base, kind);
    let tests = [Loading::seed_contention(), Loading::seed_compression()];
    let mut models = Vec::new();
    for loading in &tests {
        let mut model = base.clone();
        apply_loading(&mut model, &skin, loading).expect("loading");
        models.push(model);
    }
    let parameters = all_parameters(&base);
    let mut times: Vec<Vec<(f64, f64)>> = vec![Vec::new(); tests.len()];
    // Interleaved: contention, compression, contention, ... so that both see the same load.
    for r in 0..repeat {
        for (t, model) in models.iter().enumerate() {
            let mut solver = StaticSolver::new(model, SolverOptions::default()).expect("setup");
            let t0 = Instant::now();
            let solution = solver.solve(model).expect("solve");
            let solve_s = t0.elapsed().as_secs_f64();
            let mut dd = DirectSensitivity::new();
            let mut out = Vec::new();
            let t0 = Instant::now();
            let report = dd
                .compute(&mut solver, model, &solution.state, &parameters, &mut out)
                .expect("sensitivities");
            let sens_s = t0.elapsed().as_secs_f64();
            // Again with the buffers of the first call (as the identification calls it).
            let t0 = Instant::now();
            dd.compute(&mut solver, model, &solution.state, &parameters, &mut out)
                .expect("sensitivities");
            let warm_s = t0.elapsed().as_secs_f64();
            times[t].push((solve_s, sens_s));
            println!(
                "{} #{r}: solve {solve_s:.3} s ({} iterations, {} factorizations {:.3} s, assembly {:.3} s, {:?}), \
                 sensitivities {sens_s:.3} s = {:.1} % (again with warm buffers {warm_s:.3} s; {} back-substitutions, refactorized {}, \
                 residual {:.1e}, {} active; rate forces + rhs {:.3} s, factorization {:.3} s, \
                 triangular solves {:.3} s, residuals {:.3} s, {} refinement steps, rest {:.3} s)",
                tests[t].name(),
                solution.report.newton_iterations,
                solution.report.factorizations,
                solution.report.factorization_time_s,
                solution.report.assembly_time_s,
                solution.report.factorization,
                100.0 * sens_s / solve_s,
                report.back_substitutions,
                report.refactorized,
                report.max_relative_residual,
                report.active_constraints,
                report.assembly_time_s,
                report.factorization_time_s,
                report.triangular_solve_time_s,
                report.residual_time_s,
                report.refinement_steps,
                sens_s
                    - report.assembly_time_s
                    - report.factorization_time_s
                    - report.triangular_solve_time_s
                    - report.residual_time_s,
            );
        }
    }
    for (t, v) in times.iter().enumerate() {
        let best_solve = v.iter().map(|x| x.0).fold(f64::INFINITY, f64::min);
        let best_sens = v.iter().map(|x| x.1).fold(f64::INFINITY, f64::min);
        let mut ratios: Vec<f64> = v.iter().map(|x| x.1 / x.0).collect();
        ratios.sort_by(f64::total_cmp);
        println!(
            "{}: best solve {best_solve:.3} s, best sensitivities {best_sens:.3} s, ratio of bests {:.1} %, median ratio {:.1} %",
            tests[t].name(),
            100.0 * best_sens / best_solve,
            100.0 * ratios[ratios.len() / 2]
        );
    }
}
