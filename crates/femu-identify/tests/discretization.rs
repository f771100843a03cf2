//! The model's own error in the intervals (issue 27): data made by CalculiX on a fine mesh of
//! the built-in thigh (contention, dead loads, CPE4), identified by femu on a coarse mesh of the
//! same geometry (the shapes sampled on one raster), as the 23 608 / 3 802-element case.
//! The coarse mesh biases the parameters by many standard deviations while the fit residual stays
//! below the noise; the discretization check (refined meshes of the same geometry, one
//! Gauss–Newton step, Richardson) must either cover the truth with its widened intervals or warn
//! with an estimated bias within a factor 2 of the actual shift. Skips with a message when ccx is
//! absent.

use femu_geometry::{
    contention_deck, parametric_thigh_on_raster, table1_materials, ThighParams, CONTENTION_MPA,
};
use femu_identify::discretization::{self, Level};
use femu_identify::fisher::{self, Tied};
use femu_identify::fit::{levenberg_marquardt, FreeParameter, LmOptions, Problem};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_mech::{Model, SolverOptions};
use femu_mesh::locate::PointLocator;
use femu_mesh::{Deck, ElementKind};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

mod common;
#[path = "../../../scripts/guide/measure.rs"]
mod measure;
use common::{ccx_displacements, ccx_installed, ccx_ready, free_parameters};

/// The shapes' raster shared by every mesh (the default for elements of 1 mm and more).
const RASTER_MM: f64 = 0.25;

/// The contention deck (dead loads) of the built-in thigh with CPE4 elements of `h` mm.
fn deck(h: f64) -> Deck {
    let t = parametric_thigh_on_raster(
        &ThighParams {
            element_size_mm: Some(h),
            ..Default::default()
        },
        ElementKind::Cpe4,
        Some(RASTER_MM),
    )
    .unwrap();
    let mut deck = contention_deck(&t, &table1_materials(), CONTENTION_MPA).unwrap();
    deck.pressures_to_dead_loads();
    // Four increments: in one, ccx 2.20 accepts the state after two Newton iterations, 2.7e-3
    // of the largest displacement away from femu's on the fine mesh; in four, 4.9e-7.
    deck.step.initial_increment = 0.25;
    deck.step.max_increment = 0.25;
    ccx_ready(&mut deck);
    deck
}

/// The identified parameters and their relative sds (whitened residuals).
fn fit(
    model: &Model,
    field: &MeasuredField,
    free: &[FreeParameter],
    start: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        field,
        free.to_vec(),
    )
    .unwrap();
    let r = levenberg_marquardt(&mut p, start, &LmOptions::default()).unwrap();
    eprintln!(
        "  {} elements: cost {:.3e} over {} data, {} forward solves ({})",
        model.mesh.elements.len(),
        r.cost,
        r.data,
        r.forward_solves,
        r.reason
    );
    let names: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
    let info = fisher::information(&r.jacobian, 1.0, &Tied::none(&names)).unwrap();
    (r.theta, fisher::identifiability(&info, &names).relative_sd)
}

#[test]
fn coarse_mesh_bias_is_covered_or_estimated_within_a_factor_two() {
    if !ccx_installed() {
        return;
    }
    // Coarse 3 mm (about 1 500 quads), fine 1.2 mm (about 9 000): the ratio of six.
    let (h_coarse, h_fine) = (3.0, 1.2);
    let fine_deck = deck(h_fine);
    let u = ccx_displacements(&fine_deck, "discretization");
    let fine = Model::from_deck(fine_deck.clone()).unwrap();
    // The data are CalculiX's, and exact: femu on the same fine deck agrees to 1e-6 of the
    // largest displacement (measured 4.7e-7; ccx prints 7 digits).
    let femu_fine = femu_mech::StaticSolver::new(&fine, SolverOptions::default())
        .unwrap()
        .solve(&fine)
        .unwrap();
    let dmax = femu_fine
        .u
        .iter()
        .zip(&u)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let umax = u.iter().map(|a| a.abs()).fold(0.0, f64::max);
    eprintln!(
        "femu vs ccx on the fine deck: {:.2e} of the largest displacement",
        dmax / umax
    );
    measure::record(
        "femu against ccx on the fine deck (1.2 mm), largest difference / largest displacement",
        dmax / umax,
        "< 1e-6",
        "",
    );
    assert!(dmax < 1e-6 * umax);
    let levels: Vec<Model> = [1.0, std::f64::consts::SQRT_2, 2.0]
        .iter()
        .map(|r| Model::from_deck(deck(h_coarse / r)).unwrap())
        .collect();
    // The ccx field at a 64 x 64 grid, the points inside every mesh, with seeded noise of
    // 2e-4 mm: the contention C10 then have sds of about 1 % (the case: 0.6 %).
    let sigma = 2e-4;
    let (lo, hi) = fine.mesh.bounding_box();
    let step = (hi[0] - lo[0]).max(hi[1] - lo[1]) / 63.0;
    let on_fine = PointLocator::new(&fine.mesh);
    let others: Vec<PointLocator> = levels.iter().map(|m| PointLocator::new(&m.mesh)).collect();
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(27);
    let mut field = MeasuredField::default();
    for j in 0..64 {
        for i in 0..64 {
            let x = [lo[0] + i as f64 * step, lo[1] + j as f64 * step];
            let Some(loc) = on_fine.locate(x) else {
                continue;
            };
            if others.iter().any(|l| l.locate(x).is_none()) {
                continue;
            }
            field.points.push(MeasuredPoint {
                x,
                u: [
                    loc.interpolate(&u, 2, 0) + noise.sample(&mut rng),
                    loc.interpolate(&u, 2, 1) + noise.sample(&mut rng),
                ],
                weight: [1.0 / (sigma * sigma); 2],
            });
        }
    }
    let (free, reference) = free_parameters(&levels[0]);
    let n = free.len();
    eprintln!(
        "ccx on {} elements, {} points; identification:",
        fine.mesh.elements.len(),
        field.points.len()
    );
    // The fine deck identifies its own data (the same ccx field, the same noise): the truth up
    // to the noise; the coarse one is biased.
    let (on_fine_fit, _) = fit(&fine, &field, &free, &reference);
    let (theta, sd) = fit(&levels[0], &field, &free, &reference);
    let mut problems: Vec<Problem> = levels
        .iter()
        .map(|m| Problem::new(m.clone(), SolverOptions::default(), &field, free.clone()).unwrap())
        .collect();
    let mut check_levels: Vec<Level> = problems
        .iter_mut()
        .zip([1.0, std::f64::consts::SQRT_2, 2.0])
        .zip(&levels)
        .map(|((p, ratio), m)| Level {
            ratio,
            elements: m.mesh.elements.len(),
            problem: p,
        })
        .collect();
    let check = discretization::check(&theta, &sd, &mut check_levels, false).unwrap();
    eprintln!("{}", check.message);
    eprintln!(
        "{:<16} {:>9} {:>9} {:>9} {:>9} {:>7} {:>8}",
        "parameter", "coarse", "fine", "actual", "estimate", "sd", "covered"
    );
    let mut worst_shift_sd = 0.0f64;
    for k in 0..n {
        // The shift of the log-parameter the coarse mesh causes: against the fine deck's
        // identification from the same data, and against the truth.
        let actual = (theta[k] / on_fine_fit[k]).ln();
        let truth = (theta[k] / reference[k]).ln();
        let b = check.bias[k];
        let lo = theta[k].min(theta[k] * (-b).exp()) * (-1.96 * sd[k]).exp();
        let hi = theta[k].max(theta[k] * (-b).exp()) * (1.96 * sd[k]).exp();
        let covered = lo <= reference[k] && reference[k] <= hi;
        worst_shift_sd = worst_shift_sd.max(actual.abs() / sd[k]);
        eprintln!(
            "{:<16} {:>8.3}% {:>8.3}% {:>8.3}% {:>8.3}% {:>6.3}% {:>8}",
            free[k].name,
            100.0 * truth,
            100.0 * (on_fine_fit[k] / reference[k]).ln(),
            100.0 * actual,
            100.0 * b,
            100.0 * sd[k],
            covered
        );
        // Covered, or warned with the bias within a factor 2 (where the shift stands out of
        // the noise by 2 sd: below that its sign and size are the noise's).
        let within = check.flagged() && b / actual >= 0.5 && b / actual <= 2.0;
        measure::record(
            &format!(
                "{}, 3 mm mesh: estimated over actual shift of ln θ (shift {:.1} sd, truth {} the widened 95 % interval)",
                free[k].name,
                actual.abs() / sd[k],
                if covered { "inside" } else { "outside" }
            ),
            b / actual,
            "in [0.5, 2], unless the truth is inside or the shift is < 2 sd",
            "",
        );
        assert!(
            covered || within || actual.abs() < 2.0 * sd[k],
            "{}: not covered, and the estimate {b:.4} is not within a factor 2 of {actual:.4}",
            free[k].name
        );
    }
    // The case is the issue's: the coarse mesh moves some parameter by many sds.
    measure::record(
        "3 mm mesh: largest shift of a parameter from the fine deck's fit, in its sd",
        worst_shift_sd,
        "> 5, and the check warns",
        "",
    );
    assert!(
        worst_shift_sd > 5.0,
        "the coarse mesh is not biased: {worst_shift_sd:.2} sd"
    );
    assert!(check.flagged(), "the check did not warn");
}
