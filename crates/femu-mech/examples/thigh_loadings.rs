//! The seed's three loading tests on the thigh-like section: `cargo run --release -p femu-mech
//! --example thigh_loadings -- [n_theta]` prints iterations, timings and the rigid bodies' state.

use femu_mech::build::DeckBuilder;
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::generate::{thigh_like, ThighLikeParams};
use femu_mesh::ElementKind;
use std::time::Instant;

fn main() {
    let n_theta: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(480);
    let d = ThighLikeParams::default();
    let s = n_theta as f64 / d.n_theta as f64;
    let p = ThighLikeParams {
        n_theta,
        muscle_rows: ((d.muscle_rows as f64 * s).round() as usize).max(4),
        fat_rows: ((d.fat_rows as f64 * s).round() as usize).max(2),
        kind: ElementKind::Cpe4h,
        ..d
    };
    let g = thigh_like(&p);
    let skin = g.surfaces["OUTER"].clone();
    let deck = DeckBuilder::new(g)
        .material("FAT", 0.8e-3, 30.8)
        .material("QUADRICEPS", 1.75e-3, 18.0)
        .material("ISCHIO", 3.0e-3, 18.0)
        .material("GRACILIS", 2.2e-3, 18.0)
        .material("SARTORIUS", 3.75e-3, 18.0)
        .fix("INNER")
        .build();
    let base = Model::from_deck(deck).unwrap();
    let force: f64 = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(3.0);
    let indentation = Loading::anterior_indentation(force);
    for loading in [
        Loading::seed_contention(),
        Loading::seed_compression(),
        indentation,
    ] {
        let mut model = base.clone();
        apply_loading(&mut model, &skin, &loading).unwrap();
        let t0 = Instant::now();
        let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
        let sol = solver.solve(&model);
        let dt = t0.elapsed().as_secs_f64();
        match sol {
            Ok(sol) => {
                let umax = sol
                    .u
                    .chunks(2)
                    .map(|c| c[0].hypot(c[1]))
                    .fold(0.0, f64::max);
                println!(
                    "{}: {} elements, {:.3} s, {} increments, {} iterations, {} cut-backs, max|u| {:.3} mm, reaction {:?}",
                    loading.name(), model.mesh.elements.len(), dt, sol.report.converged_increments, sol.report.newton_iterations, sol.report.cutbacks, umax, sol.report.reaction_total
                );
                if std::env::var("TRACE").is_ok() {
                    for inc in &sol.report.increments {
                        println!(
                            "  inc {} λ {:.4} conv {} {:?}",
                            inc.increment,
                            inc.lambda,
                            inc.converged,
                            inc.iterations
                                .iter()
                                .map(|i| format!("{:.1e}/{:.2}", i.residual_norm, i.step_length))
                                .collect::<Vec<_>>()
                        );
                    }
                }
                for b in &sol.bodies {
                    println!("   {}: travel {:.4} mm, force {:.4e}, active {}, penetration {:.2e} (limit {:.2e}), augmentations {}", b.name, b.travel, b.force, b.active_nodes, b.max_penetration, b.penetration_limit, b.augmentations);
                }
            }
            Err(e) => println!("{}: FAILED after {dt:.3} s: {e}", loading.name()),
        }
    }
}
