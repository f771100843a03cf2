//! The cost of a 3D solve of the swept thigh against its size: the factorization used (LDLᵀ
//! for a symmetric tangent, LU when the follower pressure's load stiffness makes it
//! unsymmetric), its time per factorization, and the peak memory, for the probe's pressure as a
//! follower load and as dead nodal loads equal to it on the reference geometry (a symmetric
//! tangent: what CalculiX's symmetric solver factorizes).
//!
//! Run with `cargo run --release -p femu-mech --example solve3_cost [-- SIZE_MM LENGTH_MM]`
//! (defaults 4.5 mm and 120 mm: the defaults of `femu mesh thigh3d`).

use femu_geometry::thigh3d::{sweep_thigh, Sweep};
use femu_geometry::{parametric_thigh, table1_materials, ThighParams};
use femu_mech::solid3d::{self, deck::pressures_to_dead_loads, Body3, Options3};
use femu_mesh::{ElementKind, ElementKind3};
use std::time::Instant;

fn main() {
    let mut args = std::env::args()
        .skip(1)
        .map(|a| a.parse::<f64>().expect("a number"));
    let size = args.next().unwrap_or(4.5);
    let length = args.next().unwrap_or(120.0);
    let section = parametric_thigh(
        &ThighParams {
            element_size_mm: Some(size),
            ..ThighParams::default()
        },
        ElementKind::Cpe4h,
    )
    .expect("section");
    println!("| elements | loading | equations | factorization | factorizations | s per factorization | solve (s) |");
    println!("|---|---|---|---|---|---|---|");
    for kind in [ElementKind3::C3d8h, ElementKind3::C3d8] {
        let mut sweep = Sweep::graded(length, 0.5 * length, 20.0, 5.0, 1.6);
        sweep.kind = kind;
        let thigh = sweep_thigh(&section, &sweep).expect("sweep");
        let faces = thigh.skin_patch(&section, 90.0, 10.0, 0.5 * length, 40.0);
        let deck = thigh
            .deck(&table1_materials(), &faces, 2.67e-3, false)
            .expect("deck");
        for follower in [true, false] {
            let mut d = deck.clone();
            if !follower {
                pressures_to_dead_loads(&mut d);
            }
            let body = Body3::from_deck3(&d).expect("body");
            let t = Instant::now();
            let sol = solid3d::solve(&body, &Options3::default()).expect("3D solve");
            let wall = t.elapsed().as_secs_f64();
            let r = &sol.report;
            println!(
                "| {} {} | {} | {} | {:?} | {} | {:.2} | {wall:.1} |",
                thigh.mesh.elements.len(),
                kind.deck_name(),
                if follower {
                    "follower pressure"
                } else {
                    "dead loads"
                },
                r.equations,
                r.factorization,
                r.factorizations,
                r.factorization_time_s / r.factorizations.max(1) as f64,
            );
        }
    }
}
