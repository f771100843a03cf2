//! Bit-for-bit fingerprints of plane-strain solves: the displacement, the Newton iteration
//! count and the exact parameter sensitivities of six problems that go through every branch of
//! the Newton driver (dead follower pressure, prescribed displacements, a rigid plate under
//! displacement and under force control, an indenter under force control, a Mooney–Rivlin
//! body), and the element-average in-plane stresses of the Mooney–Rivlin one.
//!
//! The solver's arithmetic is deterministic on one machine (the parallel gathers sum in
//! element order, the factorizations are serial below 10 000 equations), so a refactoring of
//! the solver that keeps the order of its floating-point operations keeps these hashes to the
//! bit. A deliberate change of the arithmetic changes them: the values printed by
//! `cargo test -p femu-mech --test solver_fingerprint -- --nocapture` are then recorded here.

use femu_mech::build::DeckBuilder;
use femu_mech::contact::{RigidContact, RigidPlate, TravelControl};
use femu_mech::loading::Loading;
use femu_mech::output::element_fields;
use femu_mech::sensitivity::{all_parameters, DirectSensitivity};
use femu_mech::{Material, Model, MooneyRivlin, NeoHookean, SolverOptions, StaticSolver, Yeoh};
use femu_mesh::generate;
use femu_mesh::ElementKind;
use std::sync::Arc;

mod common;

/// FNV-1a over the bits of `values`.
fn hash(values: impl IntoIterator<Item = f64>) -> u64 {
    values.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, v| {
        (h ^ v.to_bits()).wrapping_mul(0x0100_0000_01b3)
    })
}

/// What a solve is pinned by.
#[derive(Debug, PartialEq)]
struct Fingerprint {
    /// Hash of the whole state (displacements and rigid-body travels).
    state: u64,
    /// Newton iterations of the whole solve.
    iterations: usize,
    /// Hash of every parameter's sensitivity of the state.
    sensitivities: u64,
}

fn fingerprint(name: &str, model: &Model) -> Fingerprint {
    let mut solver = StaticSolver::new(model, SolverOptions::default()).unwrap();
    let sol = solver
        .solve(model)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let mut du = Vec::new();
    DirectSensitivity::new()
        .compute(
            &mut solver,
            model,
            &sol.state,
            &all_parameters(model),
            &mut du,
        )
        .unwrap();
    let max_u = sol.u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let f = Fingerprint {
        state: hash(sol.state.iter().copied()),
        iterations: sol.report.newton_iterations,
        sensitivities: hash(du.iter().flatten().copied()),
    };
    println!(
        "{name}: state {:#018x}, {} iterations, sensitivities {:#018x}, max |u| {max_u:.6e} mm",
        f.state, f.iterations, f.sensitivities
    );
    f
}

fn thigh(loading: &Loading) -> Model {
    common::thigh_model(700, ElementKind::Cpe4h, loading)
}

/// A 40 x 20 mm CPE4H block, bottom fixed, under a flat plate above its top pushed by
/// `control`.
fn plate_on_block(control: TravelControl) -> Model {
    let g = generate::rectangle(40.0, 20.0, 20, 10, ElementKind::Cpe4h);
    let top = g.surfaces["TOP"].clone();
    let deck = DeckBuilder::new(g)
        .material_everywhere(1.75e-3, 18.0)
        .fix("BOTTOM")
        .build();
    let mut model = Model::from_deck(deck).unwrap();
    let plate = RigidPlate::new([20.0, 21.0], [0.0, -1.0]).unwrap();
    model
        .contacts
        .push(RigidContact::new("plate", &model.mesh, &top, Arc::new(plate), control).unwrap());
    model
}

/// A CPE4 block of `law`, bottom fixed, under a follower pressure on its top.
fn block_under_pressure(law: impl Material) -> Model {
    let g = generate::rectangle(10.0, 5.0, 8, 4, ElementKind::Cpe4);
    let deck = DeckBuilder::new(g)
        .law_everywhere(law)
        .fix("BOTTOM")
        .pressure("TOP", 2.0e-4)
        .build();
    Model::from_deck(deck).unwrap()
}

const MOONEY_RIVLIN: MooneyRivlin = MooneyRivlin {
    c10: 1.0e-3,
    c01: 0.75e-3,
    d: 18.0,
};

#[test]
fn plane_strain_solves_keep_their_bits() {
    let cases: Vec<(&str, Model, Fingerprint)> = vec![
        (
            "contention (follower pressure)",
            thigh(&Loading::seed_contention()),
            Fingerprint {
                state: 0xfe4d_4bc2_a234_f636,
                iterations: 3,
                sensitivities: 0x9907_a19d_ab27_8f32,
            },
        ),
        (
            "compression (plate, force control)",
            thigh(&Loading::seed_compression()),
            Fingerprint {
                state: 0x0326_eef6_6e75_7252,
                iterations: 17,
                sensitivities: 0xc1e4_94f4_25b9_2c1e,
            },
        ),
        (
            "indentation (cylinder, force control)",
            thigh(&Loading::anterior_indentation(0.04)),
            Fingerprint {
                state: 0xbf0e_8857_d835_1757,
                iterations: 23,
                sensitivities: 0xda99_38a6_7a07_597c,
            },
        ),
        (
            "plate on block (displacement control)",
            plate_on_block(TravelControl::Displacement(3.0)),
            Fingerprint {
                state: 0x3ec0_ab6b_b1fa_2f8b,
                iterations: 8,
                sensitivities: 0x4b18_591f_9ba4_0749,
            },
        ),
        (
            "block (prescribed displacement)",
            Model::from_deck(
                DeckBuilder::new(generate::rectangle(2.0, 1.0, 8, 4, ElementKind::Cpe4))
                    .material_everywhere(0.01, 1.0)
                    .fix("BOTTOM")
                    .displacement("TOP", 1, -0.2)
                    .build(),
            )
            .unwrap(),
            Fingerprint {
                state: 0x19b1_bbb2_d63d_d351,
                iterations: 19,
                sensitivities: 0x6892_c179_2f28_69fe,
            },
        ),
        (
            "Mooney-Rivlin block (follower pressure)",
            block_under_pressure(MOONEY_RIVLIN),
            Fingerprint {
                state: 0x6384_e7c3_296a_3564,
                iterations: 3,
                sensitivities: 0xe875_953b_f27c_619a,
            },
        ),
    ];
    let mut failed = Vec::new();
    for (name, model, expected) in &cases {
        let got = fingerprint(name, model);
        if got != *expected {
            failed.push(format!("{name}: {got:?}, recorded {expected:?}"));
        }
    }
    assert!(failed.is_empty(), "changed:\n{}", failed.join("\n"));
}

/// Hashes of the element-average in-plane Cauchy stress (σxx, σyy, σxy), of σzz and of the
/// logarithmic strain of the pressurized block of `law`.
fn stress_hashes(law: impl Material) -> [u64; 3] {
    let model = block_under_pressure(law);
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
    let sol = solver.solve(&model).unwrap();
    let fields = element_fields(&model, &sol.state);
    let in_plane = hash(fields.cauchy_stress.iter().flat_map(|s| [s[0], s[1], s[3]]));
    let zz = hash(fields.cauchy_stress.iter().map(|s| s[2]));
    let strain = hash(fields.log_strain.iter().flatten().copied());
    println!("in-plane stress {in_plane:#018x}, σzz {zz:#018x}, log strain {strain:#018x}");
    [in_plane, zz, strain]
}

/// The element stresses and strains of the pressurized block to the bit: all of them for the
/// laws of `(I1, J)`; for Mooney–Rivlin the in-plane stresses and the strains (its σzz, through
/// the `I2` term, is checked against the 3D law in `tests/mooney_rivlin_sigma_zz.rs`).
#[test]
fn element_stresses_keep_their_bits() {
    let [in_plane, _, strain] = stress_hashes(MOONEY_RIVLIN);
    let neo_hookean = stress_hashes(NeoHookean {
        c10: 1.75e-3,
        d: 18.0,
    });
    let yeoh = stress_hashes(Yeoh {
        c10: 1.0e-3,
        c20: 2.0e-4,
        c30: 3.0e-5,
        d: 18.0,
    });
    assert_eq!(
        (in_plane, strain),
        (0x3243_acbf_7c0d_dacc, 0x588e_3258_bfb0_19c7)
    );
    assert_eq!(
        neo_hookean,
        [
            0x05e5_7c3e_df54_1f51,
            0x3742_22dd_1bc2_4f4d,
            0xa943_1621_c6bb_7aeb
        ]
    );
    assert_eq!(
        yeoh,
        [
            0xec16_6137_59aa_476e,
            0x2add_facc_d268_4602,
            0x603b_38b9_0dc8_12a2
        ]
    );
}
