//! Sliding interfaces between deformable regions (node-to-segment contact, frictionless and
//! with Coulomb friction): the tangent against central differences of the residual, the
//! frictionless residual against differences of the contact energy, the contact patch test on
//! a non-matching interface, the closed form of a block sheared on a block (sticks below the
//! tangential traction μp, slides at μp), and Hertz's line contact of two deformable bodies.

use femu_mech::build::DeckBuilder;
use femu_mech::interface::{Interface, InterfaceKind, Penalty};
use femu_mech::loading::Loading;
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::generate::{self, GeneratedMesh};
use femu_mesh::ElementKind;
use rand::{Rng, SeedableRng};

mod common;
#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// Two blocks of width `w`, the lower `[0, w] x [0, 1]` of `nx_low x 2` quads (element set
/// `LOW`, surface `LOW_TOP`, node sets `LOW_BOTTOM`, `LOW_LEFT`, `LOW_ALL`), the upper `[0, w] x
/// [1, 2]` of `nx_high x 2` quads (`HIGH`, surfaces `HIGH_BOTTOM`, `HIGH_TOP`, node sets
/// `HIGH_TOP`, `HIGH_LEFT`), with their own nodes along `y = 1`.
fn two_blocks(w: f64, nx_low: usize, nx_high: usize) -> GeneratedMesh {
    two_blocks_with_margin(w, nx_low, nx_high, 0.0)
}

/// As [`two_blocks`], the lower block wider by `margin` on each side (`[-margin, w + margin]`).
fn two_blocks_with_margin(w: f64, nx_low: usize, nx_high: usize, margin: f64) -> GeneratedMesh {
    let mut low = generate::rectangle(w + 2.0 * margin, 1.0, nx_low, 2, ElementKind::Cpe4);
    low.mesh.nodes.iter_mut().for_each(|x| x[0] -= margin);
    let high = generate::rectangle(w, 1.0, nx_high, 2, ElementKind::Cpe4);
    stacked(&low, &high, 1.0)
}

/// The bodies `low` and `high` (shifted up by `dy`) in one mesh, each with its own nodes: their
/// element sets `LOW`, `HIGH`, their node sets and surfaces prefixed `LOW_`, `HIGH_`.
fn stacked(low: &GeneratedMesh, high: &GeneratedMesh, dy: f64) -> GeneratedMesh {
    let mut g = GeneratedMesh::default();
    let m = &mut g.mesh;
    let mut add = |part: &GeneratedMesh,
                   dy: f64,
                   name: &str,
                   g_surfaces: &mut Vec<(String, Vec<(usize, usize)>)>| {
        let n0 = m.nodes.len();
        let e0 = m.elements.len();
        for x in &part.mesh.nodes {
            m.add_node([x[0], x[1] + dy]);
        }
        for el in &part.mesh.elements {
            let mut el = *el;
            for c in el.conn.iter_mut().take(el.kind.node_count()) {
                *c += n0;
            }
            m.add_element(el);
        }
        m.element_sets
            .insert(name.into(), (e0..m.elements.len()).collect());
        for (set, nodes) in &part.mesh.node_sets {
            m.node_sets.insert(
                format!("{name}_{set}"),
                nodes.iter().map(|n| n + n0).collect(),
            );
        }
        for (s, faces) in &part.surfaces {
            g_surfaces.push((
                format!("{name}_{s}"),
                faces.iter().map(|&(e, f)| (e + e0, f)).collect(),
            ));
        }
    };
    let mut surfaces = Vec::new();
    add(low, 0.0, "LOW", &mut surfaces);
    add(high, dy, "HIGH", &mut surfaces);
    g.surfaces = surfaces.into_iter().collect();
    g
}

/// The upper block's bottom (slave) on the lower block's top (master).
fn interface(g: &GeneratedMesh, kind: InterfaceKind) -> Interface {
    Interface::new(
        "HIGH_ON_LOW",
        &g.mesh,
        &g.surfaces["HIGH_BOTTOM"],
        &g.surfaces["LOW_TOP"],
        kind,
        0.75,
    )
    .unwrap()
}

/// Largest |analytic - central difference| of the tangent over the free dofs, and the largest
/// tangent entry, at the state `u`.
fn tangent_error(model: &Model, solver: &mut StaticSolver, u: &[f64]) -> (f64, f64) {
    solver.assemble_at(model, u).unwrap();
    let k = solver.tangent_values().to_vec();
    let pattern = solver.pattern().clone();
    let n_dof = u.len();
    let h = 1e-7;
    let mut max_err = 0.0f64;
    let kmax = k.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for d in 0..n_dof {
        let Some(c) = solver.equation_of(d) else {
            continue;
        };
        let mut up = u.to_vec();
        up[d] += h;
        let rp = solver.residual_at(model, &up).unwrap().to_vec();
        let mut um = u.to_vec();
        um[d] -= h;
        let rm = solver.residual_at(model, &um).unwrap().to_vec();
        for dd in 0..n_dof {
            if let Some(r) = solver.equation_of(dd) {
                let fd = (rp[dd] - rm[dd]) / (2.0 * h);
                let kv = pattern.position(r, c).map_or(0.0, |p| k[p]);
                max_err = max_err.max((kv - fd).abs());
            }
        }
    }
    (max_err, kmax)
}

/// A perturbed state of the two blocks: the upper block pressed 0.02 into the lower one and
/// slid by `slide` (x), plus random noise of ±0.01 on every free dof.
fn pressed_state(model: &Model, solver: &StaticSolver, slide: f64, seed: u64) -> Vec<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let high = model.mesh.element_set("HIGH").unwrap();
    let mut in_high = vec![false; model.node_count()];
    for &e in high {
        for &n in model.mesh.elements[e].nodes() {
            in_high[n] = true;
        }
    }
    let mut u = vec![0.0; model.state_len()];
    for n in 0..model.node_count() {
        for i in 0..2 {
            if solver.equation_of(2 * n + i).is_none() {
                continue;
            }
            let base = if in_high[n] { [slide, -0.02][i] } else { 0.0 };
            u[2 * n + i] = base + rng.gen_range(-0.01..0.01);
        }
    }
    u
}

fn blocks_model(nx_low: usize, nx_high: usize, kind: InterfaceKind, penalty: Penalty) -> Model {
    let g = two_blocks(2.0, nx_low, nx_high);
    let iface = Interface {
        penalty,
        ..interface(&g, kind)
    };
    let deck = DeckBuilder::new(g)
        .material("LOW", 0.01, 1.0)
        .material("HIGH", 0.01, 1.0)
        .fix("LOW_BOTTOM")
        .displacement("HIGH_TOP", 0, 0.0)
        .build();
    let mut model = Model::from_deck(deck).unwrap();
    model.interfaces.push(iface);
    model
}

/// The assembled tangent with a frictionless and a frictional interface (stick and slip nodes,
/// slave nodes on several master segments) equals central differences of the residual.
#[test]
fn interface_tangent_matches_finite_differences_of_the_residual() {
    for (kind, slide) in [
        (InterfaceKind::Frictionless, 0.3),
        (InterfaceKind::Friction { mu: 0.3 }, 0.004),
        (InterfaceKind::Friction { mu: 0.3 }, 0.3),
    ] {
        let model = blocks_model(
            7,
            5,
            kind,
            Penalty::Fixed {
                k: 2.0,
                stick_slope: 1.0,
            },
        );
        let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
        solver.prepare_contact(&model).unwrap();
        let u = pressed_state(&model, &solver, slide, 11);
        let states = solver.interface_states(&model, &u);
        let in_contact = states[0].iter().filter(|s| s.normal_force > 0.0).count();
        let slipping = states[0].iter().filter(|s| s.slipping).count();
        assert!(
            in_contact >= 3,
            "{kind:?}: {in_contact} slave nodes in contact"
        );
        let (err, kmax) = tangent_error(&model, &mut solver, &u);
        println!("{kind:?} slide {slide}: {in_contact} in contact, {slipping} slipping, tangent error {:.2e} of largest entry", err / kmax);
        // Central differences of step 1e-7 on forces of order 1e-2 (entries of order 1):
        // truncation ~h² ‖R'''‖ and round-off ~1e-16 ‖R‖ / h ≈ 1e-10; 1e-6 relative leaves room
        // and still catches any missing term (the smallest, N ∂²g, is ~1e-3 of the largest).
        let label = match kind {
            InterfaceKind::Frictionless => "frictionless".to_string(),
            InterfaceKind::Friction { mu } => format!("Coulomb μ = {mu}"),
        };
        measure::record(
            &format!("{label}, slide {slide} mm ({in_contact} in contact, {slipping} slipping): interface tangent against finite differences, largest error / largest entry"),
            err / kmax,
            "< 1e-6",
            "",
        );
        assert!(
            err < 1e-6 * kmax,
            "{kind:?}: error {err:.3e}, largest entry {kmax:.3e}"
        );
        if slide > 0.1 && matches!(kind, InterfaceKind::Friction { .. }) {
            assert!(slipping >= 3, "{slipping} slipping");
        }
        if slide < 0.01 {
            assert!(slipping < in_contact, "some nodes stick");
        }
    }
}

/// The frictionless interface's residual is the gradient of its energy
/// `Σ ε ⟨-g⟩₊² / 2` (no multipliers before any Uzawa update): the interface's part of the
/// residual against central differences of that energy.
#[test]
fn frictionless_residual_is_the_gradient_of_the_contact_energy() {
    let k_pen = 2.0;
    let model = blocks_model(
        5,
        3,
        InterfaceKind::Frictionless,
        Penalty::Fixed {
            k: k_pen,
            stick_slope: 0.0,
        },
    );
    let mut plain = model.clone();
    plain.interfaces.clear();
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
    let mut plain_solver = StaticSolver::new(&plain, SolverOptions::default()).unwrap();
    solver.prepare_contact(&model).unwrap();
    let u = pressed_state(&model, &solver, 0.3, 5);
    let iface = &model.interfaces[0];
    // Each slave node keeps the segment it was paired with at the start (the solver's pairing
    // through an increment's iterations).
    let zero = vec![0.0; model.state_len()];
    let paired: Vec<Option<usize>> = (0..iface.slaves.len())
        .map(|k| {
            iface
                .closest(k, |n| model.current_position(n, &zero))
                .map(|(s, _)| s)
        })
        .collect();
    let energy = |u: &[f64]| -> f64 {
        (0..iface.slaves.len())
            .filter_map(|k| {
                let (_, g) =
                    iface.closest_preferring(k, |n| model.current_position(n, u), paired[k])?;
                let eps = k_pen * iface.tributary[k];
                Some(0.5 * eps * (-g.g).max(0.0).powi(2))
            })
            .sum()
    };
    let r = solver.residual_at(&model, &u).unwrap().to_vec();
    let r0 = plain_solver.residual_at(&plain, &u).unwrap().to_vec();
    let h = 1e-7;
    let (mut err, mut scale) = (0.0f64, 0.0f64);
    for d in 0..u.len() {
        let mut up = u.clone();
        up[d] += h;
        let mut um = u.clone();
        um[d] -= h;
        let fd = (energy(&up) - energy(&um)) / (2.0 * h);
        err = err.max((r[d] - r0[d] - fd).abs());
        scale = scale.max(fd.abs());
    }
    println!(
        "interface residual vs energy differences: {:.2e} of {scale:.2e}",
        err / scale
    );
    // Central differences of a C¹ piecewise-quadratic energy of order 1e-4 with h = 1e-7:
    // round-off ~1e-16 · 1e-4 / 1e-7 = 1e-13 absolute, far below 1e-7 of forces ~1e-2.
    measure::record(
        "frictionless residual against differences of the contact energy, largest error / largest entry",
        err / scale,
        "< 1e-7",
        "",
    );
    assert!(scale > 1e-3);
    assert!(err < 1e-7 * scale, "error {err:.3e} of {scale:.3e}");
}

/// Two blocks of one material under uniform pressure `p` on top, rollers on their left edges
/// and under the lower block: the exact solution is homogeneous. Returns the largest distance
/// of the nodal displacements from the homogeneous field fitted to the top-right corner, over
/// the largest displacement, and the largest penetration left.
fn patch_error(nx_low: usize, nx_high: usize, p: f64) -> (f64, f64) {
    let g = two_blocks(2.0, nx_low, nx_high);
    let iface = interface(&g, InterfaceKind::Frictionless);
    let deck = DeckBuilder::new(g)
        .material("LOW", 0.01, 1.0)
        .material("HIGH", 0.01, 1.0)
        .displacement("LOW_BOTTOM", 1, 0.0)
        .displacement("LOW_LEFT", 0, 0.0)
        .displacement("HIGH_LEFT", 0, 0.0)
        .pressure("HIGH_TOP", p)
        .build();
    let mut model = Model::from_deck(deck).unwrap();
    model.interfaces.push(iface);
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
    let sol = solver.solve(&model).unwrap();
    // Homogeneous field u = (a x, b y) through the upper block's top-right corner (2, 2).
    let corner = (0..model.node_count())
        .find(|&n| model.mesh.nodes[n] == [2.0, 2.0])
        .unwrap();
    let (a, b) = (sol.u[2 * corner] / 2.0, sol.u[2 * corner + 1] / 2.0);
    let (mut err, mut umax) = (0.0f64, 0.0f64);
    for (n, x) in model.mesh.nodes.iter().enumerate() {
        let (ux, uy) = (sol.u[2 * n], sol.u[2 * n + 1]);
        err = err.max((ux - a * x[0]).abs()).max((uy - b * x[1]).abs());
        umax = umax.max(ux.hypot(uy));
    }
    let states = solver.interface_states(&model, &sol.state);
    let pen = states[0].iter().fold(0.0f64, |m, s| m.max(-s.gap));
    (err / umax, pen)
}

/// The contact patch test (Taylor & Papadopoulos, IJNME 31, 1991): a uniform pressure is
/// transmitted across the interface. Matching meshes pass exactly (to the solver's tolerance);
/// non-matching ones pass to the node-to-segment element's known error, which lumps the slave
/// nodes' forces at points of the master segments.
#[test]
fn uniform_pressure_crosses_the_interface() {
    let p = 2e-3;
    let (matching, pen) = patch_error(4, 4, p);
    println!(
        "matching 4/4: displacement error {matching:.2e} of max |u|, penetration {pen:.2e} mm"
    );
    // The solver's residual tolerance (1e-8 relative) and the Uzawa updates' penetration
    // limit (the gap at which ε g is the force tolerance) bound the error near 1e-8.
    measure::record(
        "contact patch test, matching 4/4 elements: displacement error / largest displacement",
        matching,
        "< 1e-6",
        "",
    );
    assert!(matching < 1e-6, "{matching:.3e}");
    for (low, high) in [(5, 3), (3, 5), (7, 4)] {
        let (e, pen) = patch_error(low, high, p);
        println!("non-matching {low}/{high}: displacement error {e:.2e} of max |u|, penetration {pen:.2e} mm");
        // Measured (see the guide's sliding-interfaces page): a few percent at most on these
        // coarse meshes, the point-load error of the single-pass node-to-segment element.
        measure::record(
            &format!("contact patch test, non-matching {low}/{high} elements: displacement error / largest displacement"),
            e,
            "< 5e-2",
            "",
        );
        assert!(e < 5e-2, "{low}/{high}: {e:.3e}");
    }
}

/// A block sheared on a fixed block under a uniform pressure `p` on its top (top displaced by
/// `s` along x): it sticks, with an average tangential traction below `μ p`, for a small `s`,
/// and slides with the traction `μ p` exactly (every slave node at `|T| = μ N`) for a large
/// one. The master block is held, so its surface stays flat and `Σ N = p w`.
#[test]
fn block_on_block_sticks_below_mu_p_and_slides_at_mu_p() {
    let (p, w) = (2e-3, 2.0);
    let run = |s: f64, mu: f64, d: f64| {
        // The lower block overhangs, so that the upper block's ends stay on it as they slide.
        let g = two_blocks_with_margin(w, 9, 5, 0.5);
        let iface = interface(&g, InterfaceKind::Friction { mu });
        let deck = DeckBuilder::new(g)
            .material("LOW", 0.01, d)
            .material("HIGH", 0.01, d)
            .fix("LOW_ALL")
            .displacement("HIGH_TOP", 0, s)
            .pressure("HIGH_TOP", p)
            .step(femu_mesh::StepDef {
                initial_increment: 0.1,
                max_increment: 0.1,
                ..Default::default()
            })
            .build();
        let mut model = Model::from_deck(deck).unwrap();
        model.interfaces.push(iface);
        let options = SolverOptions {
            // Friction is path dependent: every increment converged fully.
            intermediate_tolerance: 1e-8,
            ..SolverOptions::default()
        };
        let mut solver = StaticSolver::new(&model, options).unwrap();
        let sol = solver.solve(&model).unwrap();
        let states = solver.interface_states(&model, &sol.state).remove(0);
        let n_total: f64 = states.iter().map(|s| s.normal_force).sum();
        let t_total: f64 = states.iter().map(|s| s.tangential_force).sum();
        let slipping = states.iter().filter(|s| s.slipping).count();
        let slip_law = states.iter().filter(|s| s.slipping).fold(0.0f64, |m, s| {
            m.max((s.tangential_force.abs() - mu * s.normal_force).abs())
        });
        (n_total, t_total, slipping, states.len(), slip_law)
    };
    // Stick: a shear of 5e-3 mm over a 1 mm block (a traction near G s / h = 1e-4 MPa, a sixth
    // of μ p = 6e-4 MPa).
    // D = 3 / G = 150 MPa⁻¹: Poisson's ratio 0 at small strain, so the pressed block hardly
    // widens (by a second-order term) and any slip is the shear's.
    let (mu, d) = (0.3, 150.0);
    let (n, t, slipping, count, _) = run(5e-3, mu, d);
    println!(
        "s = 5e-3: ΣN/(p w) = {:.6}, |ΣT|/(μ p w) = {:.4}, {slipping} of {count} slipping",
        n / (p * w),
        t.abs() / (mu * p * w)
    );
    measure::record(
        "block on block, shear 5e-3 mm (sticks): |ΣT| / (μ p w)",
        t.abs() / (mu * p * w),
        "in (0.05, 0.5), no node slipping",
        "",
    );
    measure::record(
        "block on block, shear 5e-3 mm: |ΣN / (p w) - 1|",
        (n / (p * w) - 1.0).abs(),
        "< 1e-6",
        "",
    );
    assert!((n / (p * w) - 1.0).abs() < 1e-6);
    assert!(t.abs() < 0.5 * mu * p * w);
    assert!(t.abs() > 0.05 * mu * p * w);
    assert_eq!(slipping, 0);
    // Slide: 0.2 mm.
    let (n, t, slipping, count, law) = run(0.2, mu, d);
    println!("s = 0.2: ΣN/(p w) = {:.8}, |ΣT|/(μ p w) = {:.8}, {slipping} of {count} slipping, largest ||T| - μN| = {law:.2e}", n / (p * w), t.abs() / (mu * p * w));
    measure::record(
        "block on block, shear 0.2 mm (slides): |ΣN / (p w) - 1|",
        (n / (p * w) - 1.0).abs(),
        "< 1e-6",
        "",
    );
    measure::record(
        "block on block, shear 0.2 mm: ||ΣT| / (μ p w) - 1|",
        (t.abs() / (mu * p * w) - 1.0).abs(),
        "< 1e-6, every node slipping",
        "",
    );
    measure::record(
        "block on block, shear 0.2 mm: largest ||T| - μN| at a slave node",
        law,
        "< 1e-12",
        "N/mm",
    );
    assert_eq!(slipping, count);
    // The normal forces balance the pressure (flat master, vertical reactions) and the
    // tangential traction is μ p: both to the residual tolerance (1e-8 of the load).
    assert!((n / (p * w) - 1.0).abs() < 1e-6, "{}", n / (p * w));
    assert!(
        (t.abs() / (mu * p * w) - 1.0).abs() < 1e-6,
        "{}",
        t.abs() / (mu * p * w)
    );
    assert!(law < 1e-12);
}

/// The built-in thigh (about 1 500 quads) under the seed's contention, compression (rigid
/// plate) and indentation tests, the quadriceps free to slide on the hamstrings (a frictionless
/// QUADRICEPS–ISCHIO interface, the nodes split along it, its ends tied), against the tied
/// thigh: the solve converges, the surfaces do not interpenetrate beyond the penetration limit,
/// the muscles slide on one another, and the displacement field differs from the tied one by
/// less than the largest displacement; under contention (the skin's follower pressure) too,
/// which the smoothed master surface makes converge (with straight segments it stalled at a
/// quarter of the load).
#[test]
fn thigh_with_a_sliding_quadriceps_under_the_seed_tests() {
    for (name, loading) in [
        ("contention", Loading::seed_contention()),
        ("compression", Loading::seed_compression()),
        ("indentation", Loading::anterior_indentation(0.1)),
    ] {
        sliding_thigh(name, &loading);
    }
}

fn sliding_thigh(name: &str, loading: &femu_mech::loading::Loading) {
    use femu_geometry::interface_split::split_interface;
    use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
    use femu_mech::loading::apply_loading;
    let t = parametric_thigh(&ThighParams::coarse(), ElementKind::Cpe4).unwrap();
    let skin = t.mesh.surfaces["SKIN"].clone();
    let model_of = |thigh: &femu_geometry::ThighModel| {
        let mut deck = contention_deck(thigh, &table1_materials(), 0.0).unwrap();
        deck.pressures.clear();
        let mut model = Model::from_deck(deck).unwrap();
        apply_loading(&mut model, &skin, loading).unwrap();
        model
    };
    let tied = model_of(&t);
    let mut split_thigh = t.clone();
    let split = split_interface(&mut split_thigh.mesh.mesh, "QUADRICEPS", "ISCHIO").unwrap();
    let mut sliding = model_of(&split_thigh);
    let iface = Interface::new(
        "QUADRICEPS_ISCHIO",
        &sliding.mesh,
        &split.a.faces,
        &split.b.faces,
        InterfaceKind::Frictionless,
        2.0 * t.element_size_mm,
    )
    .unwrap();
    sliding.interfaces.push(iface);
    let mut tied_solver = StaticSolver::new(&tied, SolverOptions::default()).unwrap();
    let tied_sol = tied_solver.solve(&tied).unwrap();
    let mut solver = StaticSolver::new(&sliding, SolverOptions::default()).unwrap();
    let sol = solver.solve(&sliding).unwrap();
    // The original nodes keep their indices: compare them.
    let n = tied.node_count();
    let (mut du, mut umax) = (0.0f64, 0.0f64);
    for k in 0..n {
        let d = (sol.u[2 * k] - tied_sol.u[2 * k]).hypot(sol.u[2 * k + 1] - tied_sol.u[2 * k + 1]);
        du = du.max(d);
        umax = umax.max(tied_sol.u[2 * k].hypot(tied_sol.u[2 * k + 1]));
    }
    let states = solver.interface_states(&sliding, &sol.state).remove(0);
    let iface = &sliding.interfaces[0];
    let zero = vec![0.0; sliding.state_len()];
    let slips: Vec<f64> = states
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let (seg, g) = iface
                .closest(k, |m| sliding.current_position(m, &zero))
                .unwrap();
            s.arc - iface.arc(seg, g.xi)
        })
        .collect();
    let max_slip = slips.iter().fold(0.0f64, |m, s| m.max(s.abs()));
    let pen = states.iter().fold(0.0f64, |m, s| m.max(-s.gap));
    let open = states.iter().filter(|s| s.normal_force == 0.0).count();
    println!(
        "{name}: tied max |u| {umax:.4} mm, sliding - tied max |Δu| {du:.4} mm, max slip \
         {max_slip:.4} mm, max penetration {pen:.2e} mm, {open} of {} slave nodes open, \
         {} increments, {} Uzawa updates",
        states.len(),
        sol.report.increments.len(),
        solver.interface_augmentations()[0]
    );
    // The slip along the interface, in the order of the master surface's arc.
    let mut along: Vec<(f64, f64, f64, f64)> = states
        .iter()
        .zip(&slips)
        .map(|(s, &slip)| (s.arc, slip, s.normal_force, s.gap))
        .collect();
    along.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (arc, slip, force, gap) in along {
        println!("  arc {arc:8.3} mm  slip {slip:+.4} mm  N {force:.3e} N/mm  gap {gap:+.2e} mm");
    }
    measure::record(
        &format!("{name}, sliding quadriceps: largest penetration / element size"),
        pen / iface.element_size,
        "≤ 1e-3",
        "",
    );
    measure::record(
        &format!("{name}, sliding quadriceps: largest slip / tied largest displacement"),
        max_slip / umax,
        "> 1e-3",
        "",
    );
    measure::record(
        &format!(
            "{name}, sliding quadriceps: largest |u_sliding - u_tied| / tied largest displacement"
        ),
        du / umax,
        "in (0, 1)",
        "",
    );
    assert!(
        pen <= 1e-3 * iface.element_size,
        "{name}: penetration {pen:.3e}"
    );
    assert!(max_slip > 1e-3 * umax, "{name}: no slip: {max_slip:.3e}");
    assert!(du > 0.0 && du < umax, "{name}: {du:.3e} vs {umax:.3e}");
}

/// The material parameters' direct sensitivities of the thigh with a frictionless
/// QUADRICEPS–ISCHIO interface under compression, against central differences of re-solves.
/// The interface's slave nodes in contact are exact constraints of the sensitivity problem, as
/// the rigid plate's nodes are (the limit the Uzawa updates converge to): linearized through
/// the penalty tangent alone, the sensitivities were off by up to 1.1e-3.
#[test]
fn material_sensitivities_with_a_sliding_interface() {
    use femu_geometry::interface_split::split_interface;
    use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
    use femu_mech::loading::{apply_loading, Loading};
    use femu_mech::sensitivity::{all_parameters, DirectSensitivity};
    let mut t = parametric_thigh(&ThighParams::coarse(), ElementKind::Cpe4).unwrap();
    let skin = t.mesh.surfaces["SKIN"].clone();
    let split = split_interface(&mut t.mesh.mesh, "QUADRICEPS", "ISCHIO").unwrap();
    let mut deck = contention_deck(&t, &table1_materials(), 0.0).unwrap();
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).unwrap();
    apply_loading(&mut model, &skin, &Loading::seed_compression()).unwrap();
    let mut iface = Interface::new(
        "QUADRICEPS_ISCHIO",
        &model.mesh,
        &split.a.faces,
        &split.b.faces,
        InterfaceKind::Frictionless,
        2.0 * t.element_size_mm,
    )
    .unwrap();
    iface.penetration_tolerance = 1e-13;
    model.interfaces.push(iface);
    for c in &mut model.contacts {
        c.penetration_tolerance = 1e-13;
    }
    let options = SolverOptions {
        residual_tolerance: 1e-12,
        energy_tolerance: 1e-24,
        ..Default::default()
    };
    let mut solver = StaticSolver::new(&model, options).unwrap();
    let solve = |model: &Model, solver: &mut StaticSolver, warm: Option<&[f64]>| {
        solver.solve_with(model, warm, &mut |_| {}).unwrap().state
    };
    let state = solve(&model, &mut solver, None);
    let params = all_parameters(&model);
    let mut du = Vec::new();
    DirectSensitivity::new()
        .compute(&mut solver, &model, &state, &params, &mut du)
        .unwrap();
    let h = 5e-4;
    let mut worst = 0.0f64;
    for (k, p) in params.iter().enumerate() {
        let theta = p.value(&model);
        p.set(&mut model, theta * (1.0 + h));
        let plus = solve(&model, &mut solver, Some(&state));
        p.set(&mut model, theta * (1.0 - h));
        let minus = solve(&model, &mut solver, Some(&state));
        p.set(&mut model, theta);
        let fd: Vec<f64> = plus
            .iter()
            .zip(&minus)
            .map(|(a, b)| (a - b) / (2.0 * h * theta))
            .collect();
        let n = 2 * model.node_count();
        let scale = fd[..n].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = du[k][..n]
            .iter()
            .zip(&fd[..n])
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
            / scale;
        println!(
            "{:<16} relative difference to central differences {err:.2e}",
            p.name(&model)
        );
        worst = worst.max(err);
    }
    println!("worst {worst:.2e}");
    measure::record(
        "thigh with a sliding quadriceps, compression: material sensitivities against central differences, worst relative difference",
        worst,
        "< 1e-5",
        "",
    );
    // As the rigid contact's check (tests/sensitivity.rs): central differences with a 5e-4
    // step are accurate to ~1e-7 here, the converged states to ~1e-9 after division by it.
    assert!(worst < 1e-5, "{worst:.3e}");
}

/// Hertz line contact between two deformable bodies of one Neo-Hookean material (ν = 0.3, small
/// strain): a body whose bottom is the parabola `y = x²/(2R)` (R = 100 mm, Hertz's own profile
/// of a cylinder) pressed by a pressure on its top onto a flat block, both 60 x 30 mm and
/// graded towards the contact, the upper one's bottom the slave surface of a frictionless
/// interface. Hertz for two bodies of one material: `a = sqrt(4 P R / (π E*))`,
/// `E* = E / (2 (1 - ν²))`, with `P` the line load for `a` = 1 mm (a/R = 0.01, a spanning
/// about twenty elements). The contact's resultant equals the load; its half-width from the
/// second moment of the slave nodes' normal forces (`a²/4` for the elliptical profile) within
/// 5 % of Hertz, as the rigid-cylinder case of the contact tests.
#[test]
fn hertz_contact_between_two_deformable_bodies() {
    let (c10, nu) = (1.0e-3, 0.3);
    let e = 2.0 * (2.0 * c10) * (1.0 + nu);
    let d = 2.0 / (e / (3.0 * (1.0 - 2.0 * nu)));
    let e_star = e / (2.0 * (1.0 - nu * nu));
    let (r, a_target, w, h) = (100.0, 1.0, 60.0, 30.0);
    let force = a_target * a_target * std::f64::consts::PI * e_star / (4.0 * r);
    let a_hertz = (4.0 * force * r / (std::f64::consts::PI * e_star)).sqrt();
    let low = common::graded_block(w, h, 120, 60, 4.1, ElementKind::Cpe4h);
    // The same block turned upside down (a half turn keeps the elements counter-clockwise):
    // graded towards its bottom centre, its TOP surface now the bottom; then its bottom bent
    // to the parabola, fading out towards its top.
    let mut high = common::graded_block(w, h, 120, 60, 4.1, ElementKind::Cpe4h);
    for x in high.mesh.nodes.iter_mut() {
        let (xx, yy) = (-x[0], h - x[1]);
        *x = [xx, yy + (1.0 - yy / h) * xx * xx / (2.0 * r)];
    }
    let g = stacked(&low, &high, h);
    let iface = Interface::new(
        "HIGH_ON_LOW",
        &g.mesh,
        &g.surfaces["HIGH_TOP"],
        &g.surfaces["LOW_TOP"],
        InterfaceKind::Frictionless,
        5.0,
    )
    .unwrap();
    let deck = DeckBuilder::new(g)
        .material("LOW", c10, d)
        .material("HIGH", c10, d)
        .fix("LOW_BOTTOM")
        .displacement("HIGH_BOTTOM", 0, 0.0)
        .pressure("HIGH_BOTTOM", force / w)
        .build();
    let mut model = Model::from_deck(deck).unwrap();
    model.interfaces.push(iface);
    model.step.initial_increment = 0.2;
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
    let sol = solver.solve(&model).unwrap();
    let states = solver.interface_states(&model, &sol.state);
    let (mut m0, mut m2, mut active) = (0.0, 0.0, 0);
    for s in &states[0] {
        let x = model.mesh.nodes[s.node][0] + sol.u[2 * s.node];
        m0 += s.normal_force;
        m2 += s.normal_force * x * x;
        active += usize::from(s.normal_force > 0.0);
    }
    let a_fe = 2.0 * (m2 / m0).sqrt();
    println!(
        "two-body Hertz: P = {force:.4e} N/mm, resultant {m0:.4e}, a = {a_hertz:.4} mm, FE a = {a_fe:.4} mm ({:+.2} %), {active} active slave nodes",
        100.0 * (a_fe / a_hertz - 1.0)
    );
    // The pressure acts on the deformed top (a follower load) of a body that hardly rotates:
    // the resultant is the load to the solver's tolerance and the top's tilt.
    assert!(
        (m0 / force - 1.0).abs() < 1e-3,
        "resultant {m0} vs load {force}"
    );
    measure::record(
        "Hertz line contact of two deformable bodies (R = 100 mm, a/R = 0.01): half-width against Hertz, relative difference",
        (a_fe / a_hertz - 1.0).abs(),
        "< 0.05",
        "",
    );
    assert!(
        (a_fe / a_hertz - 1.0).abs() < 0.05,
        "half-width {a_fe} vs Hertz {a_hertz}"
    );
    // The pressure profile p0 sqrt(1 - x²/a²), p0 = 2P/(πa), from each slave node's force over
    // its tributary length, inside |x| < 0.8 a (its edge is resolved by a few elements only).
    let iface = &model.interfaces[0];
    let p0 = 2.0 * force / (std::f64::consts::PI * a_hertz);
    let mut worst = 0.0f64;
    for (k, s) in states[0].iter().enumerate() {
        assert_eq!(s.node, iface.slaves[k]);
        let x = model.mesh.nodes[s.node][0] + sol.u[2 * s.node];
        if x.abs() < 0.8 * a_hertz {
            let exact = p0 * (1.0 - (x / a_hertz).powi(2)).sqrt();
            worst = worst.max((s.normal_force / iface.tributary[k] - exact).abs() / p0);
        }
    }
    println!(
        "two-body Hertz: pressure within {:.2} % of p0 inside 0.8 a",
        100.0 * worst
    );
    measure::record(
        "Hertz line contact of two deformable bodies: pressure against the elliptical profile inside 0.8 a, largest difference / p0",
        worst,
        "< 0.1",
        "",
    );
    assert!(worst < 0.1, "pressure off by {worst} of p0");
}
