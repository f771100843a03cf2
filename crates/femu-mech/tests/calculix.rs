//! Verification of femu's static solver against CalculiX 2.20 (`ccx`, Debian package
//! `calculix-ccx`).
//!
//! Each comparison builds one [`Deck`], writes it with [`write_inp`] into a scratch directory
//! under `std::env::temp_dir()`, runs `ccx -i job` there, reads the displacements that ccx prints
//! into `job.dat` (`*NODE PRINT, NSET=NALL`), solves the very same `Deck` in-process with femu and
//! compares the nodal displacements by node label. The criterion is
//! `max_nodes |u_femu - u_ccx| <= 1e-4 * max_nodes |u_ccx|` (Euclidean norm per node): ccx prints
//! 7 significant digits, so 1e-4 leaves room for ccx's own Newton tolerance but is far below any
//! modelling difference (a wrong face, pressure sign, thickness or material constant changes the
//! field by percents). Every case prints the measured ratio and the wall times of ccx (as a
//! subprocess, including its file I/O) and of femu (`StaticSolver::new` + `solve`).
//! Without `ccx` on PATH each test prints `SKIPPED: ...` and returns.
//!
//! 1. [`annulus_two_layers_matches_ccx`]: annulus 14/40/60 mm, quadriceps-like inner layer and
//!    fat-like outer layer (Table 1), femur edge fixed, 20 mmHg follower pressure on the skin;
//!    CPE4 at 20 mmHg and at 5 x 20 mmHg (outer displacement about 5 mm), and CPE3 (the quads
//!    split in two) with 20 mmHg as dead nodal loads (`*CLOAD`). The radial ODE of
//!    [`femu_mech::reference`] is the arbiter of both codes' mean outer displacement.
//! 2. [`gmsh_thigh_three_regions_matches_ccx`]: an unstructured all-quad gmsh mesh
//!    (`tests/data/thigh_ccx.geo` / `.msh`: elliptical skin 70 x 60 mm, off-centre femur hole
//!    r = 14 mm, regions FAT, ANTERIOR, POSTERIOR; no triangles are left, so only CPE4), once
//!    with 20 mmHg as dead nodal loads (`*CLOAD`, the criterion 1e-4) and once as a follower
//!    pressure (see "ccx and follower pressure" below: looser, documented bound).
//! 3. [`cpe4h_indirect_check_on_annulus`]: CalculiX has no hybrid element and its CPE4 is the
//!    fully integrated element (checked here: it matches femu's CPE4, not CPE4H, in the nearly
//!    incompressible case). So CPE4H is checked indirectly: femu CPE4H on a mesh and CPE4 on the
//!    mesh refined twice (ccx-verified) must agree at the outer radius within
//!    `1.5 (ê_H + ê_4)`, the Richardson estimates of their O(h²) discretisation errors
//!    (`ê = |u_h - u_h/2| / 3` for the finer of two meshes, `4/3 |u_h - u_h/2|` for the coarser),
//!    and the radial reference must lie within those estimates of each. A nearly incompressible
//!    case (D / 1000) checks that CPE4 is the stiffer one (smaller outer displacement).
//! 4. [`mooney_rivlin_and_yeoh_match_ccx`]: the gmsh mesh of 2. with Mooney–Rivlin, Yeoh and
//!    mixed materials (`*HYPERELASTIC, MOONEY-RIVLIN` / `YEOH` as femu writes them), 20 mmHg as
//!    dead loads, within 1e-6 of max |u| (7 significant digits in ccx's `.dat`).
//!
//! # Findings that shaped the tests
//!
//! * **Number width in ccx decks.** ccx 2.20 reads a number field from its first 20
//!   characters only: `1.000000000000000e-15` (21 characters) is read as `0.1`, silently, and a
//!   longer exponent form is a fatal "ERROR reading *NODE". This test file found it;
//!   [`write_inp`] now writes every number in at most 20 characters. The tests still round
//!   the decks to 14 significant digits ([`ccx_ready`], the same deck goes to femu) and refuse a
//!   written deck with a numeric field longer than 20 characters ([`check_ccx_field_widths`]),
//!   which guards the writer.
//! * **ccx and zero D2, D3.** ccx 2.20 replaces every zero compressibility constant of a
//!   hyperelastic law by a default (a Poisson ratio of 0.475, with a warning), D2 and D3 of
//!   `YEOH` included, where Abaqus drops their terms; femu reads and writes Abaqus' meaning, so
//!   the Yeoh decks given to ccx carry D2 = D3 = 1e20 ([`yeoh_without_ccx_defaults`]).
//! * **ccx and follower pressure.** ccx 2.20 accepts every increment here after two Newton
//!   iterations (its largest residual force is printed as 0 in `job.cvg`, so the criterion on
//!   the estimated next correction passes); tightening `*CONTROLS, PARAMETERS=FIELD` (`R_n`,
//!   `C_n` = 1e-8) changes nothing, and forcing more iterations (`R_l` = -1) makes the
//!   corrections grow about 10x per iteration until ccx gives up; with increments limited to
//!   0.1 (a `thigh_like` mesh) or fixed at 0.05 (`*STATIC, DIRECT`, annulus at 5x) the accepted
//!   errors pile up from increment to increment until it diverges. That is Newton with an
//!   incomplete tangent, consistent with the CalculiX source (`e_c3d.f`) adding the
//!   distributed-load stiffness only in its `mass.eq.1` branch, not in a static step; the
//!   follower-pressure stiffness (about p = 2.7 kPa) is not small against the fat's shear
//!   stiffness (2 C10 = 1.6 kPa). With dead loads the same meshes agree to 4e-7. So ccx's
//!   follower-pressure answers depend on its increment sizes (by more than 1e-4 on
//!   non-axisymmetric meshes) while femu's do not (checked); no `*CONTROLS` is used since it
//!   cannot fix this.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

use femu_mech::build::DeckBuilder;
use femu_mech::material::{material_def, Material, MooneyRivlin, NeoHookean, Yeoh};
use femu_mech::reference::{Layer, ThickCylinder};
use femu_mech::{Model, Solution, SolverOptions, StaticSolver};
use femu_mesh::generate::{self, GeneratedMesh};
use femu_mesh::inp::{read_ccx_dat_displacements, write_inp};
use femu_mesh::{read_msh, BoundaryCondition, Deck, ElementKind, FacePressure, StepDef};

/// Contention load: 20 mmHg in MPa.
const P20: f64 = 2.666e-3;
/// The criterion: max nodal error over max nodal displacement.
const TOL: f64 = 1e-4;
/// Table 1 (C10 in MPa, D in 1/MPa).
const FAT: (f64, f64) = (0.8e-3, 30.8);
const QUADRICEPS: (f64, f64) = (1.75e-3, 18.0);
const ISCHIO: (f64, f64) = (3e-3, 18.0);

// ---------------------------------------------------------------------------------------------
// Running ccx.

fn ccx_installed() -> bool {
    // `ccx -v` prints the version and exits with a non-zero status; only spawning matters.
    let found = Command::new("ccx").arg("-v").output().is_ok();
    if !found {
        println!("SKIPPED: ccx not installed (apt-get install calculix-ccx)");
    }
    found
}

/// What one ccx run gave.
struct CcxRun {
    /// `(node label, [ux, uy])` from `job.dat`.
    u: Vec<(i64, [f64; 2])>,
    wall_s: f64,
    /// Newton iterations of each converged increment (from `job.sta`).
    iterations: Vec<usize>,
}

/// Rounds every number of the deck to 14 significant digits so that [`write_inp`] writes at
/// most 20 characters per field, all ccx 2.20 reads (see the module documentation). The same
/// rounded deck is solved by both codes.
fn ccx_ready(deck: &mut Deck) {
    let r = |v: &mut f64| *v = format!("{v:.13e}").parse().unwrap();
    deck.mesh.nodes.iter_mut().flatten().for_each(r);
    for m in &mut deck.materials {
        m.constants.iter_mut().for_each(r);
    }
    deck.boundaries.iter_mut().for_each(|b| r(&mut b.value));
    deck.pressures.iter_mut().for_each(|p| r(&mut p.magnitude));
    deck.point_loads
        .iter_mut()
        .for_each(|p| r(&mut p.magnitude));
}

/// Panics if a numeric field of a data line is longer than the 20 characters ccx reads.
fn check_ccx_field_widths(text: &str) {
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('*') {
            continue;
        }
        for field in line.split(',').map(str::trim) {
            let numeric = field.parse::<f64>().is_ok();
            assert!(
                !numeric || field.len() <= 20,
                "deck line {}: '{field}' has {} characters; ccx 2.20 reads only the first 20 of a number",
                i + 1,
                field.len()
            );
        }
    }
}

/// Writes `deck` with [`write_inp`] into a fresh scratch directory, runs `ccx -i job` there and
/// reads `job.dat`. The directory is removed after a successful run and kept (and named in the
/// panic message) otherwise.
fn run_ccx(deck: &Deck, case: &str) -> CcxRun {
    run_ccx_with(deck, case, |text| text)
}

/// [`run_ccx`] with the written deck's text passed through `edit` before ccx reads it.
fn run_ccx_with(deck: &Deck, case: &str, edit: impl Fn(String) -> String) -> CcxRun {
    let dir: PathBuf = std::env::temp_dir().join(format!(
        "femu-ccx-test-{}-{}",
        std::process::id(),
        case.replace(|c: char| !c.is_ascii_alphanumeric(), "_")
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut text = Vec::new();
    write_inp(deck, &mut text).unwrap();
    let text = edit(String::from_utf8(text).unwrap());
    check_ccx_field_widths(&text);
    std::fs::write(dir.join("job.inp"), &text).unwrap();

    let start = Instant::now();
    let out = Command::new("ccx")
        .args(["-i", "job"])
        .current_dir(&dir)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .expect("ccx runs");
    let wall_s = start.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&out.stdout);
    std::fs::write(dir.join("ccx_stdout.txt"), stdout.as_bytes()).unwrap();
    let failed = !out.status.success() || stdout.contains("*ERROR");
    let tail: Vec<&str> = stdout.lines().rev().take(15).collect();
    assert!(
        !failed,
        "{case}: ccx failed (status {}); deck and output kept in {}; last lines:\n{}",
        out.status,
        dir.display(),
        tail.into_iter().rev().collect::<Vec<_>>().join("\n")
    );
    let u = read_ccx_dat_displacements(&dir.join("job.dat")).unwrap();
    let sta = std::fs::read_to_string(dir.join("job.sta")).unwrap_or_default();
    let iterations = sta
        .lines()
        .filter_map(|l| {
            let cols: Vec<&str> = l.split_whitespace().collect();
            (cols.len() >= 7 && cols[0].parse::<usize>().is_ok())
                .then(|| cols[3].parse().ok())
                .flatten()
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    CcxRun {
        u,
        wall_s,
        iterations,
    }
}

// ---------------------------------------------------------------------------------------------
// femu and comparisons.

fn femu_solve(deck: Deck) -> (Model, Solution, f64) {
    let model = Model::from_deck(deck).expect("valid model");
    let start = Instant::now();
    let mut solver = StaticSolver::new(&model, SolverOptions::default()).expect("solver");
    let sol = solver.solve(&model).expect("femu converges");
    (model, sol, start.elapsed().as_secs_f64())
}

/// ccx displacements in femu's dof order (`[ux0, uy0, ux1, ...]` by node index).
fn ccx_field(model: &Model, ccx: &CcxRun) -> Vec<f64> {
    assert_eq!(
        ccx.u.len(),
        model.mesh.nodes.len(),
        "ccx printed one row per node"
    );
    let index: HashMap<i64, usize> = model
        .mesh
        .node_labels
        .iter()
        .enumerate()
        .map(|(i, &l)| (l, i))
        .collect();
    let mut u = vec![f64::NAN; 2 * model.mesh.nodes.len()];
    for &(label, d) in &ccx.u {
        let i = index[&label];
        u[2 * i] = d[0];
        u[2 * i + 1] = d[1];
    }
    assert!(
        u.iter().all(|v| v.is_finite()),
        "every node has a ccx value"
    );
    u
}

/// `max |a - b| / max |b|` over nodes (Euclidean norm per node).
fn max_ratio(a: &[f64], b: &[f64]) -> f64 {
    let (mut err, mut umax) = (0.0_f64, 0.0_f64);
    for (pa, pb) in a.chunks(2).zip(b.chunks(2)) {
        err = err.max((pa[0] - pb[0]).hypot(pa[1] - pb[1]));
        umax = umax.max(pb[0].hypot(pb[1]));
    }
    err / umax
}

/// Solves `deck` with both codes and prints the comparison; returns the femu model and
/// solution, ccx's displacements in femu's order, and the error ratio.
fn compare_with_ccx(case: &str, deck: Deck) -> (Model, Solution, Vec<f64>, f64) {
    compare_with_ccx_with(case, deck, |text| text)
}

/// [`compare_with_ccx`] with the deck's text edited for ccx (see [`run_ccx_with`]).
fn compare_with_ccx_with(
    case: &str,
    deck: Deck,
    edit: impl Fn(String) -> String,
) -> (Model, Solution, Vec<f64>, f64) {
    let ccx = run_ccx_with(&deck, case, edit);
    let (model, sol, femu_s) = femu_solve(deck);
    let u_ccx = ccx_field(&model, &ccx);
    let ratio = max_ratio(&sol.u, &u_ccx);
    let umax = u_ccx
        .chunks(2)
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0, f64::max);
    let femu_its: Vec<usize> = sol
        .report
        .increments
        .iter()
        .filter(|i| i.converged)
        .map(|i| i.iterations.len())
        .collect();
    println!(
        "{case}: {} nodes, {} elements; max|u_ccx| = {umax:.5} mm; max error / max|u| = {ratio:.3e}; \
         wall time ccx {:.3} s (iterations per increment {:?}), femu {femu_s:.3} s ({femu_its:?})",
        model.mesh.nodes.len(),
        model.mesh.elements.len(),
        ccx.wall_s,
        ccx.iterations,
    );
    (model, sol, u_ccx, ratio)
}

/// Mean radial displacement (about the origin) of the nodes of `nset`.
fn mean_radial(model: &Model, u: &[f64], nset: &str) -> f64 {
    let nodes = model.mesh.node_set(nset).unwrap();
    nodes
        .iter()
        .map(|&n| {
            let x = model.mesh.nodes[n];
            (u[2 * n] * x[0] + u[2 * n + 1] * x[1]) / x[0].hypot(x[1])
        })
        .sum::<f64>()
        / nodes.len() as f64
}

fn step(initial_increment: f64) -> StepDef {
    StepDef {
        initial_increment,
        ..StepDef::default()
    }
}

// ---------------------------------------------------------------------------------------------
// 1. Annulus.

const R_IN: f64 = 14.0;
const R_MID: f64 = 40.0;
const R_OUT: f64 = 60.0;

/// Two-layer annulus, `32k x (3k + 2k)` quads; CPE3 splits each quad in two.
fn annulus(kind: ElementKind, k: usize) -> GeneratedMesh {
    let quad = if kind == ElementKind::Cpe3 {
        ElementKind::Cpe4
    } else {
        kind
    };
    let g = generate::annulus(R_IN, R_MID, R_OUT, 32 * k, 3 * k, 2 * k, quad);
    if kind == ElementKind::Cpe3 {
        generate::split_into_triangles(&g)
    } else {
        g
    }
}

/// The annulus deck: C10 from Table 1, D scaled by `d_scale`, femur edge fixed, follower
/// pressure `p` on the skin, ccx-style *STATIC with initial increment `inc`.
fn annulus_deck(kind: ElementKind, k: usize, d_scale: f64, p: f64, inc: f64) -> Deck {
    let mut deck = DeckBuilder::new(annulus(kind, k))
        .material("INNER_LAYER", QUADRICEPS.0, QUADRICEPS.1 * d_scale)
        .material("OUTER_LAYER", FAT.0, FAT.1 * d_scale)
        .fix("INNER")
        .pressure("OUTER", p)
        .step(step(inc))
        .build();
    ccx_ready(&mut deck);
    deck
}

fn cylinder(d_scale: f64, p: f64) -> ThickCylinder {
    ThickCylinder {
        r_in: R_IN,
        layers: vec![
            Layer {
                r_to: R_MID,
                c10: QUADRICEPS.0,
                d: QUADRICEPS.1 * d_scale,
            },
            Layer {
                r_to: R_OUT,
                c10: FAT.0,
                d: FAT.1 * d_scale,
            },
        ],
        pressure: p,
    }
}

/// Annulus: CPE4 under follower pressure at 20 and 100 mmHg and CPE3 (quads split, so the mesh
/// is no longer axisymmetric) under 20 mmHg as dead loads, each within 1e-4 of ccx; the mean outer
/// radial displacement near the radial reference; femu's answer independent of the increment
/// size, ccx's not. CPE3 under follower pressure is only printed: ccx's answer there moves by
/// 0.2 % to 8 % with its increment size (module documentation).
#[test]
fn annulus_two_layers_matches_ccx() {
    if !ccx_installed() {
        return;
    }
    for (kind, factor, dead) in [
        (ElementKind::Cpe4, 1.0, false),
        (ElementKind::Cpe4, 5.0, false),
        (ElementKind::Cpe3, 1.0, true),
        (ElementKind::Cpe3, 1.0, false),
    ] {
        let p = factor * P20;
        let load = if dead { "dead loads" } else { "follower" };
        let case = format!("annulus {kind:?} {factor} x 20 mmHg {load}");
        let mut deck = annulus_deck(kind, 2, 1.0, p, 0.25);
        if dead {
            deck.pressures_to_dead_loads();
            ccx_ready(&mut deck);
        }
        let (model, sol, u_ccx, ratio) = compare_with_ccx(&case, deck);
        let checked_by_ccx = kind == ElementKind::Cpe4 || dead;
        measure::record(
            &format!("{case}: largest difference from ccx / largest displacement"),
            ratio,
            &if checked_by_ccx {
                format!("≤ {TOL:e}")
            } else {
                "not asserted (ccx does not converge)".into()
            },
            "",
        );
        if checked_by_ccx {
            assert!(ratio <= TOL, "{case}: femu vs ccx {ratio:.3e} > {TOL:e}");
        } else {
            println!("  (not asserted: ccx does not converge for follower pressure on this mesh)");
        }
        if !dead {
            let reference = cylinder(1.0, p).outer_displacement();
            let e_femu = mean_radial(&model, &sol.u, "OUTER") / reference - 1.0;
            let e_ccx = mean_radial(&model, &u_ccx, "OUTER") / reference - 1.0;
            println!(
                "  radial reference u_r(R_out) = {reference:.6} mm; relative error of the mean over the skin: femu {e_femu:.2e}, ccx {e_ccx:.2e}"
            );
            // Discretisation error of this mesh (64 x 10 quads): 2e-4 (CPE4), 6e-4 (CPE3) at
            // 20 mmHg; a wrong load or material would be off by far more.
            assert!(
                e_femu.abs() < 3e-3,
                "{case}: femu vs reference {e_femu:.2e}"
            );
        }
        if factor > 1.0 {
            // femu's answer does not depend on the increments (one increment vs 0.25) ...
            let (_, one, _) = femu_solve(annulus_deck(kind, 2, 1.0, p, 1.0));
            let femu_spread = max_ratio(&one.u, &sol.u);
            // ... ccx's does: with a single increment it stops after three iterations.
            let ccx_one = run_ccx(&annulus_deck(kind, 2, 1.0, p, 1.0), "annulus one increment");
            let ccx_spread = max_ratio(&ccx_field(&model, &ccx_one), &u_ccx);
            println!(
                "  one increment instead of 0.25: femu changes by {femu_spread:.1e}, ccx by {ccx_spread:.1e} \
                 (ccx iterations {:?})",
                ccx_one.iterations
            );
            measure::record(
                &format!("{case}: femu, one increment against 0.25, change / largest displacement"),
                femu_spread,
                "< 1e-6",
                "",
            );
            measure::record(
                &format!("{case}: ccx, one increment against 0.25, change / largest displacement"),
                ccx_spread,
                "not asserted",
                "",
            );
            assert!(
                femu_spread < 1e-6,
                "femu depends on the increments: {femu_spread:.2e}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 2. Unstructured gmsh mesh.

/// The committed gmsh mesh with its physical groups: materials per region, femur nodes fixed,
/// follower pressure `p` on the skin edges.
fn gmsh_thigh_deck(p: f64, inc: f64) -> Deck {
    let laws: [Box<dyn Material>; 3] = [FAT, QUADRICEPS, ISCHIO].map(|(c10, d)| {
        let law: Box<dyn Material> = Box::new(NeoHookean { c10, d });
        law
    });
    gmsh_thigh_deck_with(p, inc, laws)
}

/// [`gmsh_thigh_deck`] with the materials of FAT, ANTERIOR and POSTERIOR given.
fn gmsh_thigh_deck_with(p: f64, inc: f64, laws: [Box<dyn Material>; 3]) -> Deck {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/thigh_ccx.msh");
    let msh = read_msh(&path).expect("tests/data/thigh_ccx.msh");
    let mesh = msh.mesh;
    assert!(
        mesh.elements.iter().all(|e| e.kind == ElementKind::Cpe4),
        "the committed mesh is all-quad"
    );
    let n = mesh.elements.len();
    let mut deck = Deck {
        element_material: vec![usize::MAX; n],
        element_region: vec![usize::MAX; n],
        step: step(inc),
        ..Default::default()
    };
    for (m, (name, law)) in ["FAT", "ANTERIOR", "POSTERIOR"]
        .into_iter()
        .zip(laws)
        .enumerate()
    {
        deck.materials.push(material_def(name, &*law));
        deck.region_names.push(name.into());
        for &e in mesh.element_set(name).expect("physical surface") {
            deck.element_material[e] = m;
            deck.element_region[e] = m;
        }
    }
    for &node in mesh.node_set("FEMUR").expect("physical curve FEMUR") {
        for dof in 0..2 {
            deck.boundaries.push(BoundaryCondition {
                node,
                dof,
                value: 0.0,
            });
        }
    }
    for &[a, b] in &msh.edge_sets["SKIN"] {
        let (element, face) = mesh.find_face(a, b).expect("skin edge is an element face");
        deck.pressures.push(FacePressure {
            element,
            face,
            magnitude: p,
        });
    }
    deck.mesh = mesh;
    ccx_ready(&mut deck);
    deck
}

/// Unstructured all-quad thigh-like mesh with three regions. With 20 mmHg as dead nodal loads
/// the two codes agree within 1e-4. With the follower pressure ccx's answer is limited by its
/// incomplete Newton tangent (module documentation): the bound there is 2e-3, and the test
/// shows that ccx's own answers at two increment sizes differ by as much as ccx and femu do,
/// while femu's do not.
#[test]
fn gmsh_thigh_three_regions_matches_ccx() {
    if !ccx_installed() {
        return;
    }
    let mut dead = gmsh_thigh_deck(P20, 0.25);
    dead.pressures_to_dead_loads();
    ccx_ready(&mut dead);
    let (_, _, _, ratio) = compare_with_ccx("gmsh thigh, 20 mmHg as dead loads", dead);
    measure::record(
        "gmsh thigh, 20 mmHg as dead loads: largest difference from ccx / largest displacement",
        ratio,
        &format!("≤ {TOL:e}"),
        "",
    );
    assert!(
        ratio <= TOL,
        "dead loads: femu vs ccx {ratio:.3e} > {TOL:e}"
    );

    let (model, sol, u_ccx, ratio) =
        compare_with_ccx("gmsh thigh, 20 mmHg follower", gmsh_thigh_deck(P20, 0.25));
    let ccx_small = run_ccx(&gmsh_thigh_deck(P20, 0.1), "gmsh thigh increments 0.1");
    let ccx_spread = max_ratio(&ccx_field(&model, &ccx_small), &u_ccx);
    let (_, femu_small, _) = femu_solve(gmsh_thigh_deck(P20, 0.1));
    let femu_spread = max_ratio(&femu_small.u, &sol.u);
    println!(
        "  initial increment 0.1 instead of 0.25 changes ccx by {ccx_spread:.1e} (iterations {:?}), femu by {femu_spread:.1e}",
        ccx_small.iterations
    );
    measure::record(
        "gmsh thigh, 20 mmHg follower: largest difference from ccx / largest displacement",
        ratio,
        "≤ 2e-3",
        "",
    );
    measure::record(
        "gmsh thigh, 20 mmHg follower: ccx, increment 0.1 against 0.25, change / largest displacement",
        ccx_spread,
        "not asserted",
        "",
    );
    measure::record(
        "gmsh thigh, 20 mmHg follower: femu, increment 0.1 against 0.25, change / largest displacement",
        femu_spread,
        "< 1e-6",
        "",
    );
    assert!(ratio <= 2e-3, "follower: femu vs ccx {ratio:.3e}");
    assert!(
        femu_spread < 1e-6,
        "femu depends on the increments: {femu_spread:.2e}"
    );
}

// ---------------------------------------------------------------------------------------------
// 3. CPE4H, indirectly.

/// Mean outer radial displacement of the annulus (mesh level `k`) by femu.
fn femu_outer(kind: ElementKind, k: usize, d_scale: f64) -> f64 {
    let (model, sol, _) = femu_solve(annulus_deck(kind, k, d_scale, P20, 0.25));
    mean_radial(&model, &sol.u, "OUTER")
}

/// CPE4H vs refined CPE4 (itself checked against ccx) vs the radial reference, Table 1 D and
/// D / 1000 (see the module documentation for the tolerance).
#[test]
fn cpe4h_indirect_check_on_annulus() {
    if !ccx_installed() {
        return;
    }
    // Table 1 compressibility: CPE4H on k = 2 (64 x 10 quads) against CPE4 on k = 4.
    let reference = cylinder(1.0, P20).outer_displacement();
    let (h2, h4) = (
        femu_outer(ElementKind::Cpe4h, 2, 1.0),
        femu_outer(ElementKind::Cpe4h, 4, 1.0),
    );
    let q2 = femu_outer(ElementKind::Cpe4, 2, 1.0);
    let (model, sol, u_ccx, ratio) = compare_with_ccx(
        "annulus CPE4 k=4 (refined), 20 mmHg",
        annulus_deck(ElementKind::Cpe4, 4, 1.0, P20, 0.25),
    );
    assert!(ratio <= TOL, "refined CPE4: femu vs ccx {ratio:.3e}");
    let q4 = mean_radial(&model, &sol.u, "OUTER");
    let q4_ccx = mean_radial(&model, &u_ccx, "OUTER");
    // Richardson estimates of the O(h^2) errors of u_H(k=2) and u_CPE4(k=4).
    let est_h = 4.0 / 3.0 * (h2 - h4).abs();
    let est_q = (q2 - q4).abs() / 3.0;
    let tol = 1.5 * (est_h + est_q);
    println!(
        "  reference {reference:.8} mm; CPE4H k=2 {h2:.8} (error {:.2e}, estimate {:.2e}); \
         CPE4 k=4 femu {q4:.8} / ccx {q4_ccx:.8} (error {:.2e}, estimate {:.2e}); \
         |CPE4H - CPE4 ccx| = {:.2e} mm, tolerance {tol:.2e} mm",
        (h2 - reference).abs(),
        est_h,
        (q4 - reference).abs(),
        est_q,
        (h2 - q4_ccx).abs(),
    );
    measure::record(
        "annulus CPE4H k=2 against ccx's refined CPE4, |difference| of the mean outer u_r",
        (h2 - q4_ccx).abs(),
        &format!("≤ {tol:.2e} (1.5 x the Richardson estimates)"),
        "mm",
    );
    assert!((h2 - q4_ccx).abs() <= tol, "CPE4H vs ccx CPE4 (refined)");
    assert!((h2 - q4).abs() <= tol, "CPE4H vs femu CPE4 (refined)");
    // The reference arbitrates: the estimates are honest for both elements.
    assert!((h2 - reference).abs() <= 1.5 * est_h, "CPE4H vs reference");
    assert!((q4 - reference).abs() <= 1.5 * est_q, "CPE4 vs reference");

    // Nearly incompressible (D / 1000): ccx's CPE4 is the fully integrated element (it matches
    // femu's CPE4, which differs from CPE4H by 2e-4 here), CPE4 is stiffer than CPE4H and the
    // reference, and CPE4H matches the reference. With the femur fixed the radial deformation is
    // almost purely volumetric (u_r ~ p r / K), so CPE4 has little to lock on: its error is the
    // same 2e-4 as with Table 1 D.
    let d_scale = 1e-3;
    let reference = cylinder(d_scale, P20).outer_displacement();
    let (model, sol, u_ccx, ratio) = compare_with_ccx(
        "annulus CPE4 k=2, D / 1000",
        annulus_deck(ElementKind::Cpe4, 2, d_scale, P20, 0.25),
    );
    assert!(
        ratio <= TOL,
        "nearly incompressible CPE4: femu vs ccx {ratio:.3e}"
    );
    let q = mean_radial(&model, &sol.u, "OUTER");
    let q_ccx = mean_radial(&model, &u_ccx, "OUTER");
    let h = femu_outer(ElementKind::Cpe4h, 2, d_scale);
    println!(
        "  D / 1000: reference {reference:.6e} mm; CPE4H {h:.6e} (error {:.1e}); CPE4 femu {q:.6e} / ccx {q_ccx:.6e} (error {:.1e})",
        h / reference - 1.0,
        q / reference - 1.0
    );
    assert!(
        q.abs() < h.abs() && q_ccx.abs() < h.abs(),
        "CPE4 is stiffer than CPE4H"
    );
    assert!(
        q.abs() < reference.abs(),
        "CPE4 is stiffer than the reference"
    );
    assert!(
        (h / reference - 1.0).abs() < 1e-6,
        "CPE4H matches the reference"
    );
    assert!((q - reference).abs() > 10.0 * (h - reference).abs());
}

// ---------------------------------------------------------------------------------------------
// 4. Mooney–Rivlin and Yeoh.

/// ccx's `.dat` prints 7 significant digits, so a node's displacement is known to about 5e-7 of
/// itself: 1e-6 of the largest displacement is what the two codes can agree to when both solve
/// the same problem.
const LAW_TOL: f64 = 1e-6;

/// The deck text for ccx with the Yeoh constants D2 and D3 (0 in femu's deck, as in Abaqus:
/// no `(J - 1)^4`, `(J - 1)^6` terms) written as 1e20. ccx 2.20 replaces a zero compressibility
/// constant by a default ("default value was used for compressibility coefficients", D2 = 2500,
/// D3 = 1.25e5 MPa⁻¹ for these materials), which adds a pressure `4 (J - 1)³ / D2` (measured on
/// one element: ccx's YEOH with C20 = C30 = 0 differs from its NEO HOOKE by exactly that, and
/// by nothing with D2 = D3 = 1e20). With 1e20 the extra terms are below 1e-19 of the D1 term
/// for |J - 1| < 1: beneath double precision, so both codes solve the same energy.
fn yeoh_without_ccx_defaults(text: String) -> String {
    let mut out = String::with_capacity(text.len());
    let mut yeoh_data = false;
    for line in text.lines() {
        if yeoh_data {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            assert_eq!(fields.len(), 6, "a Yeoh data line: {line}");
            assert!(
                fields[4..].iter().all(|f| f.parse::<f64>() == Ok(0.0)),
                "{line}"
            );
            out.push_str(&format!("{}, 1e20, 1e20\n", fields[..4].join(", ")));
        } else {
            out.push_str(line);
            out.push('\n');
        }
        yeoh_data = line.trim().eq_ignore_ascii_case("*HYPERELASTIC, YEOH");
    }
    out
}

/// Mooney–Rivlin and Yeoh materials on the three regions of the unstructured gmsh thigh, loaded
/// by 20 mmHg as dead nodal loads (`*CLOAD`; ccx's follower pressure stops early, see the
/// module documentation), written by femu's deck writer as `*HYPERELASTIC, MOONEY-RIVLIN` /
/// `*HYPERELASTIC, YEOH` and solved by both codes: the displacements agree within 1e-6 of the
/// largest (measured: 2.5e-7 Mooney–Rivlin, 4.9e-7 Yeoh, 4.2e-7 for a deck mixing the three
/// laws). The parameters put a large share of the stiffness in the terms beyond Neo-Hookean
/// (C01, C20, C30), so that each solution differs from the Neo-Hookean one with the same
/// small-strain moduli by more than a hundred times the tolerance (measured 5e-4 to 1.5e-3 of
/// max |u|). Larger dead loads were tried and not kept: at twice 20 mmHg ccx accepts every
/// increment after two iterations with its residual printed as 0 (as with follower pressure,
/// module documentation) and ends 1.5e-5 of max |u| away, whatever `*CONTROLS, PARAMETERS=FIELD`
/// says; at three times ccx stops near 2.7 times 20 mmHg, and femu with its increments limited
/// to 0.025 stopped near 1.6 times while it converged with larger increments (dead loads on the
/// soft fat, not the seed's follower pressure; not pursued here).
#[test]
fn mooney_rivlin_and_yeoh_match_ccx() {
    if !ccx_installed() {
        return;
    }
    let mr = |c10: f64, c01: f64, d: f64| -> Box<dyn Material> {
        Box::new(MooneyRivlin { c10, c01, d })
    };
    let yeoh = |c10: f64, c20: f64, c30: f64, d: f64| -> Box<dyn Material> {
        Box::new(Yeoh { c10, c20, c30, d })
    };
    let nh = |c10: f64, d: f64| -> Box<dyn Material> { Box::new(NeoHookean { c10, d }) };
    // Table 1's shear moduli split between C10 and C01, or with stiffening higher Yeoh terms.
    let cases: [(&str, [Box<dyn Material>; 3]); 3] = [
        (
            "Mooney-Rivlin",
            [
                mr(0.2e-3, 0.6e-3, FAT.1),
                mr(0.5e-3, 1.25e-3, QUADRICEPS.1),
                mr(1.0e-3, 2.0e-3, ISCHIO.1),
            ],
        ),
        (
            "Yeoh",
            [
                yeoh(0.8e-3, 8e-3, 40e-3, FAT.1),
                yeoh(1.75e-3, -5e-3, 40e-3, QUADRICEPS.1),
                yeoh(3e-3, 10e-3, 20e-3, ISCHIO.1),
            ],
        ),
        (
            "mixed",
            [
                yeoh(0.8e-3, 8e-3, 40e-3, FAT.1),
                mr(0.5e-3, 1.25e-3, QUADRICEPS.1),
                nh(ISCHIO.0, ISCHIO.1),
            ],
        ),
    ];
    for (name, laws) in cases {
        // The Neo-Hookean material of the same small-strain moduli (μ = 2 C10).
        let same_moduli = laws
            .each_ref()
            .map(|l| nh(0.5 * l.shear_modulus(), 2.0 / l.bulk_modulus()));
        let deck = |laws: [Box<dyn Material>; 3]| {
            let mut deck = gmsh_thigh_deck_with(P20, 0.25, laws);
            deck.pressures_to_dead_loads();
            ccx_ready(&mut deck);
            deck
        };
        let law_deck = deck(laws);
        let mut text = Vec::new();
        write_inp(&law_deck, &mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        for keyword in ["MOONEY-RIVLIN", "YEOH"] {
            let expected = name == "mixed" || name.eq_ignore_ascii_case(keyword);
            assert_eq!(
                text.contains(&format!("*HYPERELASTIC, {keyword}\n")),
                expected
            );
        }
        let case = format!("gmsh thigh, {name}, 20 mmHg as dead loads");
        let (_, sol, _, ratio) = compare_with_ccx_with(&case, law_deck, yeoh_without_ccx_defaults);
        let (_, neo_hookean, _) = femu_solve(deck(same_moduli));
        let beyond = max_ratio(&neo_hookean.u, &sol.u);
        measure::record(
            &format!("{case}: largest difference from ccx / largest displacement"),
            ratio,
            &format!("≤ {LAW_TOL:e}"),
            "",
        );
        println!("  differs from Neo-Hookean with the same moduli by {beyond:.2e} of max |u|");
        assert!(
            ratio <= LAW_TOL,
            "{case}: femu vs ccx {ratio:.3e} > {LAW_TOL:e}"
        );
        assert!(
            beyond > 1e2 * LAW_TOL,
            "{case}: the law barely matters ({beyond:.2e})"
        );
    }
}
