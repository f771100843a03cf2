//! The rigid-body loading tests on the built-in thigh (the seed's compression: flat plate,
//! 0.1 N/mm, anterior; indentation: cylinder R = 10 mm, 0.1 N/mm, anterior; femur fixed) with
//! their Newton history, for studying the contact algorithm and the increment settings:
//!
//! ```text
//! cargo run --release -p femu-mech --example contact_cost -- \
//!     [indentation|compression] [elements 25000] [cpe4h|cpe4] [KEY=VALUE ...]
//! ```
//!
//! Keys: `intermediate_tolerance`, `growth`, `residual_tolerance`, `energy_tolerance` (the
//! solver options), `penalty_factor`, `penetration_tolerance` (the body), `initial_increment`
//! (the step), `repeat` (solves timed, a fresh solver each), `write=FILE` (the final state, one
//! value per line, full precision) and `compare=FILE` (the largest difference from a state
//! written before, relative to its largest nodal displacement).
//!
//! Prints, per increment, the load factor, the number of Newton iterations and after each
//! iteration the relative residual `‖R‖/‖f_ref‖` with the step length taken (`residual@step`);
//! then the body's travel, force, Uzawa updates, the time of setup + solve and where it went.

use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::{Model, Solution, SolverOptions, StaticSolver};
use femu_mesh::ElementKind;
use std::time::Instant;

struct Args {
    test: String,
    elements: usize,
    kind: ElementKind,
    keys: Vec<(String, String)>,
}

impl Args {
    fn parse() -> Args {
        let mut a = Args {
            test: "indentation".into(),
            elements: 25_000,
            kind: ElementKind::Cpe4h,
            keys: Vec::new(),
        };
        for arg in std::env::args().skip(1) {
            if let Some((k, v)) = arg.split_once('=') {
                a.keys.push((k.to_string(), v.to_string()));
            } else if let Ok(n) = arg.parse() {
                a.elements = n;
            } else if arg == "cpe4" {
                a.kind = ElementKind::Cpe4;
            } else if arg == "cpe4h" {
                a.kind = ElementKind::Cpe4h;
            } else {
                a.test = arg;
            }
        }
        a
    }

    fn text(&self, key: &str) -> Option<&str> {
        self.keys
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn num<T: std::str::FromStr>(&self, key: &str, default: T) -> T {
        match self.text(key) {
            Some(v) => v
                .parse()
                .unwrap_or_else(|_| panic!("{key}={v}: not a number")),
            None => default,
        }
    }
}

fn model(args: &Args) -> Model {
    let thigh = parametric_thigh(
        &ThighParams {
            target_elements: Some(args.elements),
            ..Default::default()
        },
        args.kind,
    )
    .expect("built-in thigh");
    let skin = thigh.mesh.surfaces["SKIN"].clone();
    let mut deck = contention_deck(&thigh, &table1_materials(), 0.0).expect("deck");
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).expect("model");
    let loading = match args.test.as_str() {
        "compression" => Loading::seed_compression(),
        "indentation" => Loading::anterior_indentation(0.1),
        other => panic!("unknown test {other}: compression or indentation"),
    };
    apply_loading(&mut model, &skin, &loading).expect("loading");
    let c = &mut model.contacts[0];
    c.penalty_factor = args.num("penalty_factor", c.penalty_factor);
    c.penetration_tolerance = args.num("penetration_tolerance", c.penetration_tolerance);
    if let Some(t) = args.text("travel") {
        c.control = femu_mech::contact::TravelControl::Displacement(t.parse().expect("travel"));
    }
    model.step.max_increment = args.num("max_increment", model.step.max_increment);
    model.step.initial_increment = args.num("initial_increment", model.step.initial_increment);
    model
}

fn print_history(solution: &Solution) {
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
            match &inc.failure {
                Some(f) => format!(" (cut back: {f})"),
                None => String::new(),
            }
        );
    }
}

/// The largest difference of `state` from the state in `path`, relative to the latter's
/// largest nodal displacement, and that displacement.
fn compare(state: &[f64], path: &str, nodal: usize) -> (f64, f64) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let reference: Vec<f64> = text.lines().map(|l| l.parse().expect("number")).collect();
    assert_eq!(reference.len(), state.len(), "{path}: another model");
    let scale = reference[..nodal]
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = state[..nodal]
        .iter()
        .zip(&reference)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    (diff / scale, scale)
}

fn main() {
    let args = Args::parse();
    let defaults = SolverOptions::default();
    let options = SolverOptions {
        intermediate_tolerance: args.num("intermediate_tolerance", defaults.intermediate_tolerance),
        growth: args.num("growth", defaults.growth),
        residual_tolerance: args.num("residual_tolerance", defaults.residual_tolerance),
        energy_tolerance: args.num("energy_tolerance", defaults.energy_tolerance),
        ..defaults
    };
    let model = model(&args);
    let c = &model.contacts[0];
    println!(
        "{}: {} elements ({:?}), penalty factor {}, penetration tolerance {:e}, \
         intermediate tolerance {:e}, growth {}",
        c.name,
        model.mesh.elements.len(),
        args.kind,
        c.penalty_factor,
        c.penetration_tolerance,
        options.intermediate_tolerance,
        options.growth,
    );
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..args.num("repeat", 1usize) {
        let t0 = Instant::now();
        let solution = StaticSolver::new(&model, options).and_then(|mut s| s.solve(&model));
        let seconds = t0.elapsed().as_secs_f64();
        match solution {
            Ok(s) => {
                times.push(seconds);
                last = Some(s);
            }
            Err(e) => {
                if let femu_mech::SolveError::NotConverged { partial, .. } = &e {
                    print_history(partial);
                    for [t, f] in partial.report.force_travel(0) {
                        println!("  travel {t:.4} mm, force {f:.5} N/mm");
                    }
                }
                eprintln!("{} failed after {seconds:.3} s: {e}", c.name);
                std::process::exit(1);
            }
        }
    }
    let solution = last.expect("one solve");
    print_history(&solution);
    let b = &solution.bodies[0];
    println!(
        "travel {:.6} mm for {:.6e} N/mm, {} nodes in contact, penetration {:.2e} mm \
         (limit {:.2e}), {} Uzawa updates",
        b.travel, b.force, b.active_nodes, b.max_penetration, b.penetration_limit, b.augmentations
    );
    let r = &solution.report;
    println!(
        "{} increments, {} cut-backs, {} Newton iterations; setup + solve {}",
        r.converged_increments,
        r.cutbacks,
        r.newton_iterations,
        times
            .iter()
            .map(|t| format!("{t:.3} s"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "  last solve: setup {:.3} s, assembly {:.3} s, factorization {:.3} s, triangular solves \
         {:.3} s",
        r.setup_time_s, r.assembly_time_s, r.factorization_time_s, r.triangular_solve_time_s,
    );
    let nodal = 2 * model.node_count();
    if let Some(path) = args.text("compare") {
        let (rel, scale) = compare(&solution.state, path, nodal);
        println!("largest difference from {path}: {rel:.3e} of {scale:.6} mm");
    }
    if let Some(path) = args.text("write") {
        let text: String = solution.state.iter().map(|v| format!("{v:e}\n")).collect();
        std::fs::write(path, text).unwrap_or_else(|e| panic!("{path}: {e}"));
    }
}
