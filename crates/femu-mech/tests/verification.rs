//! Verification against closed-form and independently computed solutions:
//! patch tests on distorted meshes, homogeneous finite deformations against the closed-form
//! Neo-Hookean Cauchy stress, and mesh convergence of the thick-walled cylinder (annulus) under
//! outer follower pressure against the radial ODE of [`femu_mech::reference`].

use femu_mech::build::DeckBuilder;
use femu_mech::element::formulation;
use femu_mech::reference::{Layer, ThickCylinder};
use femu_mech::{Model, Solution, SolverOptions, StaticSolver};
use femu_mesh::generate::{self, GeneratedMesh};
use femu_mesh::{Deck, ElementKind, StepDef};

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

const KINDS: [ElementKind; 3] = [ElementKind::Cpe4, ElementKind::Cpe4h, ElementKind::Cpe3];

/// Solves with Newton tolerances far below the assertions' (residual 1e-12, energy 1e-20), so
/// that what is tested is the discretisation, not where Newton stopped.
fn solve(deck: Deck) -> (Model, Solution) {
    let model = Model::from_deck(deck).expect("valid model");
    let options = SolverOptions {
        residual_tolerance: 1e-12,
        energy_tolerance: 1e-20,
        ..Default::default()
    };
    let mut solver = StaticSolver::new(&model, options).unwrap();
    let sol = solver.solve(&model).expect("converges");
    (model, sol)
}

fn rectangle(kind: ElementKind, nx: usize, ny: usize) -> GeneratedMesh {
    let quad_kind = if kind == ElementKind::Cpe3 {
        ElementKind::Cpe4
    } else {
        kind
    };
    let g = generate::rectangle(2.0, 1.0, nx, ny, quad_kind);
    if kind == ElementKind::Cpe3 {
        generate::split_into_triangles(&g)
    } else {
        g
    }
}

/// Closed-form Cauchy stress of the Abaqus Neo-Hookean law for `F = [[a, b], [c, d]]`, F33 = 1:
/// `σ = 2 C10 J^(-5/3) (b - I1/3 I) + (2/D)(J - 1) I` with the 3D left Cauchy–Green tensor b.
fn closed_form_cauchy(c10: f64, d: f64, f: [f64; 4]) -> [f64; 4] {
    let j = f[0] * f[3] - f[1] * f[2];
    let bxx = f[0] * f[0] + f[1] * f[1];
    let byy = f[2] * f[2] + f[3] * f[3];
    let bxy = f[0] * f[2] + f[1] * f[3];
    let i1 = bxx + byy + 1.0;
    let s = 2.0 * c10 * j.powf(-5.0 / 3.0);
    let p = 2.0 / d * (j - 1.0);
    [
        s * (bxx - i1 / 3.0) + p,
        s * (byy - i1 / 3.0) + p,
        s * (1.0 - i1 / 3.0) + p,
        s * bxy,
    ]
}

/// Patch test: every node on the boundary of a distorted mesh follows `u = (F - I) X`; the
/// interior nodes must follow it too, to round-off, for every element type.
#[test]
fn patch_test_on_distorted_mesh() {
    let f = [1.2, 0.1, -0.05, 0.9];
    for kind in KINDS {
        let mut g = rectangle(kind, 4, 3);
        // Move interior nodes by a fixed pseudo-random pattern (up to 30 % of the spacing).
        for (k, x) in g.mesh.nodes.iter_mut().enumerate() {
            let interior = x[0] > 1e-9 && x[0] < 2.0 - 1e-9 && x[1] > 1e-9 && x[1] < 1.0 - 1e-9;
            if interior {
                x[0] += 0.15 * ((k as f64 * 1.7).sin());
                x[1] += 0.1 * ((k as f64 * 2.3).cos());
            }
        }
        let affine = move |x: [f64; 2]| {
            [
                (f[0] - 1.0) * x[0] + f[1] * x[1],
                f[2] * x[0] + (f[3] - 1.0) * x[1],
            ]
        };
        let deck = DeckBuilder::new(g)
            .material_everywhere(1.75e-3, 18.0)
            .displacement_field("LEFT", affine)
            .displacement_field("RIGHT", affine)
            .displacement_field("BOTTOM", affine)
            .displacement_field("TOP", affine)
            .build();
        let (model, sol) = solve(deck);
        let mut max_err = 0.0f64;
        for (n, x) in model.mesh.nodes.iter().enumerate() {
            let e = affine(*x);
            max_err = max_err
                .max((sol.u[2 * n] - e[0]).abs())
                .max((sol.u[2 * n + 1] - e[1]).abs());
        }
        measure::record(
            &format!(
                "{} patch test, largest nodal error",
                format!("{kind:?}").to_uppercase()
            ),
            max_err,
            "< 1e-10",
            "mm",
        );
        assert!(
            max_err < 1e-10,
            "{kind:?}: patch test error {max_err:.3e} mm"
        );
        // Constant stress equal to the closed form.
        let sc = closed_form_cauchy(1.75e-3, 18.0, f);
        for e in 0..model.mesh.elements.len() {
            let geo = &model.geometry[e];
            let s = formulation(geo.kind)
                .cauchy_stress(
                    geo,
                    &*model.materials[0].law,
                    &model.gather(e, &sol.u)[..geo.n_nodes],
                )
                .unwrap();
            for k in 0..4 {
                assert!(
                    (s[k] - sc[k]).abs() < 1e-9 * 1.75e-3,
                    "{kind:?} element {e}: {s:?} vs {sc:?}"
                );
            }
        }
    }
}

/// Uniaxial plane-strain stretch λ1 = 1.3 with free lateral edge: the lateral stretch λ2 solves
/// σyy = 0; compare λ2, σxx, σzz and the reaction force P11 H.
#[test]
fn uniaxial_plane_strain_stretch_matches_closed_form() {
    let (c10, d) = (1.75e-3, 18.0);
    let l1 = 1.3;
    // Bisection for σyy(λ2) = 0 (σyy increases with λ2).
    let (mut lo, mut hi) = (0.3, 1.5);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if closed_form_cauchy(c10, d, [l1, 0.0, 0.0, mid])[1] > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let l2 = 0.5 * (lo + hi);
    let sc = closed_form_cauchy(c10, d, [l1, 0.0, 0.0, l2]);
    for kind in KINDS {
        let deck = DeckBuilder::new(rectangle(kind, 4, 2))
            .material_everywhere(c10, d)
            .displacement("LEFT", 0, 0.0)
            .displacement("BOTTOM", 1, 0.0)
            .displacement("RIGHT", 0, (l1 - 1.0) * 2.0)
            .step(StepDef {
                initial_increment: 0.25,
                ..Default::default()
            })
            .build();
        let (model, sol) = solve(deck);
        let top = &model.mesh.node_sets["TOP"];
        for &n in top {
            assert!(
                (sol.u[2 * n + 1] - (l2 - 1.0)).abs() < 1e-9,
                "{kind:?}: uy at top"
            );
        }
        let right = &model.mesh.node_sets["RIGHT"];
        let force: f64 = right.iter().map(|&n| sol.reactions[2 * n]).sum();
        let p11 = sc[0] * l2; // P = σ J F^-T: P11 = σxx λ1 λ2 / λ1
        measure::record(
            &format!(
                "{} uniaxial stretch 1.3, reaction against the closed form, relative error",
                format!("{kind:?}").to_uppercase()
            ),
            (force - p11).abs() / p11.abs(),
            "< 1e-8",
            "",
        );
        assert!(
            (force - p11 * 1.0).abs() < 1e-8 * p11.abs(),
            "{kind:?}: reaction {force} vs {p11}"
        );
        let geo = &model.geometry[0];
        let s = formulation(kind)
            .cauchy_stress(
                geo,
                &*model.materials[0].law,
                &model.gather(0, &sol.u)[..geo.n_nodes],
            )
            .unwrap();
        for k in 0..4 {
            assert!(
                (s[k] - sc[k]).abs() < 1e-8 * sc[0].abs(),
                "{kind:?}: stress {s:?} vs {sc:?}"
            );
        }
    }
}

/// Biaxial stretch (λ1, λ2) = (1.2, 0.85) and simple shear γ = 0.4: element stresses and edge
/// reactions against the closed form.
#[test]
fn biaxial_and_simple_shear_match_closed_form() {
    let (c10, d) = (3.0e-3, 18.0);
    let (l1, l2) = (1.2, 0.85);
    let gamma = 0.4;
    for kind in KINDS {
        let deck = DeckBuilder::new(rectangle(kind, 3, 3))
            .material_everywhere(c10, d)
            .displacement("LEFT", 0, 0.0)
            .displacement("BOTTOM", 1, 0.0)
            .displacement("RIGHT", 0, (l1 - 1.0) * 2.0)
            .displacement("TOP", 1, l2 - 1.0)
            .build();
        let (model, sol) = solve(deck);
        let sc = closed_form_cauchy(c10, d, [l1, 0.0, 0.0, l2]);
        let fx: f64 = model.mesh.node_sets["RIGHT"]
            .iter()
            .map(|&n| sol.reactions[2 * n])
            .sum();
        let fy: f64 = model.mesh.node_sets["TOP"]
            .iter()
            .map(|&n| sol.reactions[2 * n + 1])
            .sum();
        // P11 = σxx λ2, P22 = σyy λ1; edges of reference length H = 1 and W = 2.
        assert!(
            (fx - sc[0] * l2).abs() < 1e-8 * sc[0].abs().max(sc[1].abs()),
            "{kind:?} biaxial fx"
        );
        assert!(
            (fy - sc[1] * l1 * 2.0).abs() < 1e-8 * sc[0].abs().max(sc[1].abs()),
            "{kind:?} biaxial fy"
        );

        let shear = move |x: [f64; 2]| [gamma * x[1], 0.0];
        let deck = DeckBuilder::new(rectangle(kind, 3, 3))
            .material_everywhere(c10, d)
            .displacement_field("LEFT", shear)
            .displacement_field("RIGHT", shear)
            .displacement_field("BOTTOM", shear)
            .displacement_field("TOP", shear)
            .build();
        let (model, sol) = solve(deck);
        let sc = closed_form_cauchy(c10, d, [1.0, gamma, 0.0, 1.0]);
        assert!(
            (sc[3] - 2.0 * c10 * gamma).abs() < 1e-15,
            "closed form σxy = μ γ"
        );
        for e in 0..model.mesh.elements.len() {
            let geo = &model.geometry[e];
            let s = formulation(kind)
                .cauchy_stress(
                    geo,
                    &*model.materials[0].law,
                    &model.gather(e, &sol.u)[..geo.n_nodes],
                )
                .unwrap();
            for k in 0..4 {
                assert!(
                    (s[k] - sc[k]).abs() < 1e-9 * c10,
                    "{kind:?} shear stress {s:?} vs {sc:?}"
                );
            }
        }
        // x-reaction on the top edge: P12 W = σxy W (J = 1, corner terms cancel).
        let fx: f64 = model.mesh.node_sets["TOP"]
            .iter()
            .map(|&n| sol.reactions[2 * n])
            .sum();
        assert!(
            (fx - sc[3] * 2.0).abs() < 1e-9 * c10,
            "{kind:?} shear reaction {fx} vs {}",
            sc[3] * 2.0
        );
    }
}

fn cylinder() -> ThickCylinder {
    // Femur radius 14 mm, quadriceps-like inner layer to 40 mm, fat-like outer layer to 60 mm,
    // 20 mmHg contention pressure (Table 1 parameters).
    ThickCylinder {
        r_in: 14.0,
        layers: vec![
            Layer {
                r_to: 40.0,
                c10: 1.75e-3,
                d: 18.0,
            },
            Layer {
                r_to: 60.0,
                c10: 0.8e-3,
                d: 30.8,
            },
        ],
        pressure: 2.666e-3,
    }
}

fn annulus_outer_displacement(kind: ElementKind, k: usize) -> f64 {
    let g = generate::annulus(14.0, 40.0, 60.0, 32 * k, 3 * k, 2 * k, kind);
    let deck = DeckBuilder::new(g)
        .material("INNER_LAYER", 1.75e-3, 18.0)
        .material("OUTER_LAYER", 0.8e-3, 30.8)
        .fix("INNER")
        .pressure("OUTER", 2.666e-3)
        .build();
    let (model, sol) = solve(deck);
    let outer = &model.mesh.node_sets["OUTER"];
    outer
        .iter()
        .map(|&n| {
            let x = model.mesh.nodes[n];
            let r = (x[0] * x[0] + x[1] * x[1]).sqrt();
            (sol.u[2 * n] * x[0] + sol.u[2 * n + 1] * x[1]) / r
        })
        .sum::<f64>()
        / outer.len() as f64
}

/// Thick-walled two-layer cylinder under 20 mmHg outer follower pressure: the outer radial
/// displacement converges to the ODE reference at the rate of bilinear elements (2 for the
/// displacement; the polygonal outline of the circle also converges at 2). The observed rate
/// must lie in [1.7, 2.3] on the last two refinements and the finest error be below 1e-3.
#[test]
fn thick_cylinder_converges_to_radial_reference() {
    let reference = cylinder().outer_displacement();
    assert!(reference < 0.0, "pressure pushes the skin inward");
    for kind in [ElementKind::Cpe4, ElementKind::Cpe4h] {
        let errors: Vec<f64> = [1, 2, 4, 8]
            .iter()
            .map(|&k| (annulus_outer_displacement(kind, k) - reference).abs() / reference.abs())
            .collect();
        let rates: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        println!("{kind:?}: reference u_r(R_out) = {reference:.8e} mm; relative errors {errors:?}; observed rates {rates:.3?}");
        let last = *rates.last().unwrap();
        let name = format!("{kind:?}").to_uppercase();
        measure::record(
            &format!("{name} thick cylinder, observed rate on the last refinement"),
            last,
            "in [1.7, 2.3]",
            "",
        );
        measure::record(
            &format!("{name} thick cylinder, finest relative error of u_r(R_out)"),
            *errors.last().unwrap(),
            "< 1e-3",
            "",
        );
        assert!(
            (1.7..2.3).contains(&last),
            "{kind:?}: observed rate {last:.3}"
        );
        assert!(
            *errors.last().unwrap() < 1e-3,
            "{kind:?}: finest error {:.3e}",
            errors.last().unwrap()
        );
    }
}

/// Warm start (used by identification: many solves with nearby parameters): after changing C10
/// of one layer by 1 %, the solve started from the previous displacement takes the whole load in
/// one increment with at most 3 Newton iterations and lands on the cold-start answer.
#[test]
fn warm_start_from_a_nearby_solution() {
    let g = generate::annulus(14.0, 40.0, 60.0, 64, 6, 4, ElementKind::Cpe4h);
    let deck = DeckBuilder::new(g)
        .material("INNER_LAYER", 1.75e-3, 18.0)
        .material("OUTER_LAYER", 0.8e-3, 30.8)
        .fix("INNER")
        .pressure("OUTER", 2.666e-3)
        .build();
    let mut model = Model::from_deck(deck).unwrap();
    let options = SolverOptions {
        residual_tolerance: 1e-12,
        energy_tolerance: 1e-20,
        ..Default::default()
    };
    let mut solver = StaticSolver::new(&model, options).unwrap();
    let first = solver.solve(&model).unwrap();
    let c10 = model.materials[0].law.parameter(0);
    model.materials[0].law.set_parameter(0, c10 * 1.01);
    let warm = solver
        .solve_with(&model, Some(&first.u), &mut |_| {})
        .unwrap();
    assert!(warm.report.warm_start && warm.report.converged_increments == 1);
    assert!(
        warm.report.newton_iterations <= 3,
        "{} iterations",
        warm.report.newton_iterations
    );
    let cold = solver.solve(&model).unwrap();
    let umax = cold.u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = warm
        .u
        .iter()
        .zip(&cold.u)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        diff < 1e-9 * umax,
        "warm and cold answers differ by {diff:.3e}"
    );
    assert!(
        (warm.u[2 * model.mesh.node_sets["OUTER"][0]]
            - first.u[2 * model.mesh.node_sets["OUTER"][0]])
            .abs()
            > 0.0
    );
}
