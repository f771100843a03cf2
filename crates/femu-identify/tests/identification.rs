//! Identification on a virtual experiment (seed §2.4): the compression test on the built-in
//! thigh with the Table 1 parameters, the field projected on a 64 x 64 grid over the thigh, and
//! the ten parameters identified back by Levenberg–Marquardt with the exact Jacobian from five
//! Latin-hypercube starts.

use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_identify::fit::{
    latin_hypercube, levenberg_marquardt, FreeParameter, LeastSquares, LmOptions, Problem,
};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::{Model, SolverOptions};
use femu_mesh::ElementKind;

mod common;
use rayon::prelude::*;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

fn compression_thigh(elements: usize) -> Model {
    compression_thigh_with(elements, table1_materials())
}

/// [`compression_thigh`] with the given deck materials (named by region).
fn compression_thigh_with(elements: usize, materials: Vec<femu_mesh::MaterialDef>) -> Model {
    let t = parametric_thigh(
        &ThighParams {
            target_elements: Some(elements),
            ..Default::default()
        },
        ElementKind::Cpe4h,
    )
    .unwrap();
    let skin = t.mesh.surfaces["SKIN"].clone();
    let mut deck = contention_deck(&t, &materials, 0.0).unwrap();
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).unwrap();
    apply_loading(&mut model, &skin, &Loading::seed_compression()).unwrap();
    model
}

/// The seed's 64 x 64 grid over the thigh's bounding box.
fn grid(model: &Model) -> Vec<[f64; 2]> {
    let (lo, hi) = model.mesh.bounding_box();
    let h = (hi[0] - lo[0]).max(hi[1] - lo[1]) / 63.0;
    let c = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    (0..64)
        .flat_map(|j| {
            (0..64).map(move |i| [c[0] + (i as f64 - 31.5) * h, c[1] + (j as f64 - 31.5) * h])
        })
        .collect()
}

/// Ten free parameters, bounds a factor 4 either side of Table 1.
fn free_parameters(model: &Model) -> Vec<FreeParameter> {
    common::free_parameters(model).0
}

/// The virtual measurement: the reference field at the grid points inside the tissue.
fn virtual_field(model: &Model, free: &[FreeParameter]) -> (MeasuredField, Vec<f64>) {
    let pts = grid(model);
    let all = MeasuredField {
        points: pts
            .iter()
            .map(|&x| MeasuredPoint {
                x,
                u: [0.0, 0.0],
                weight: [1.0, 1.0],
            })
            .collect(),
        comments: vec![],
    };
    let reference: Vec<f64> = free.iter().map(|f| f.members[0].value(model)).collect();
    let mut p = Problem::new(model.clone(), SolverOptions::default(), &all, free.to_vec()).unwrap();
    let u = p.field_at(&reference).unwrap();
    let locator = femu_mesh::locate::PointLocator::new(&model.mesh);
    let inside: Vec<[f64; 2]> = pts
        .into_iter()
        .filter(|x| locator.locate(*x).is_some())
        .collect();
    assert_eq!(2 * inside.len(), u.len());
    let field = MeasuredField {
        points: inside
            .iter()
            .enumerate()
            .map(|(k, &x)| MeasuredPoint {
                x,
                u: [u[2 * k], u[2 * k + 1]],
                weight: [1.0, 1.0],
            })
            .collect(),
        comments: vec!["virtual experiment: compression, Table 1".into()],
    };
    (field, reference)
}

/// Noise-free: every parameter recovered to 0.1 % (the requirement) from each of the five
/// starts, with few forward solves.
#[test]
fn noise_free_compression_recovers_table1_from_five_starts() {
    let model = compression_thigh(800);
    let free = free_parameters(&model);
    let (field, reference) = virtual_field(&model, &free);
    let starts = latin_hypercube(&free, 5, 2024);
    let results: Vec<_> = starts
        .par_iter()
        .map(|s| {
            let mut p = Problem::new(
                model.clone(),
                SolverOptions::default(),
                &field,
                free.clone(),
            )
            .unwrap();
            levenberg_marquardt(&mut p, s, &LmOptions::default()).unwrap()
        })
        .collect();
    for (k, r) in results.iter().enumerate() {
        let worst = r
            .theta
            .iter()
            .zip(&reference)
            .map(|(t, t0)| ((t - t0) / t0).abs())
            .fold(0.0f64, f64::max);
        eprintln!(
            "start {k}: worst relative error {worst:.2e}, cost {:.3e}, {} iterations, {} forward solves, {:.1} s ({})",
            r.cost, r.iterations, r.forward_solves, r.wall_time_s, r.reason
        );
        measure::record(
            &format!("start {k}: worst relative error of the ten parameters"),
            worst,
            "< 1e-3",
            "",
        );
        measure::record(
            &format!("start {k}: forward solves"),
            r.forward_solves as f64,
            "not asserted",
            "",
        );
        for ((f, t), t0) in free.iter().zip(&r.theta).zip(&reference) {
            assert!(
                ((t - t0) / t0).abs() < 1e-3,
                "start {k}: {} = {t:.6e}, reference {t0:.6e}",
                f.name
            );
        }
    }
}

/// Tied parameters of any registered law: the quadriceps and the ischio Mooney–Rivlin with one
/// C01 (tied, as the seed ties D of three muscles), identified with the quadriceps' C10 from
/// starts 50 % and 30 % off on the noise-free compression field; the tie moves both materials
/// together and both are recovered to 0.1 %.
#[test]
fn tied_mooney_rivlin_parameters_are_identified() {
    use femu_mech::material::{material_def, MooneyRivlin};
    use femu_mech::sensitivity::Parameter;
    let mut materials = table1_materials();
    for m in &mut materials {
        let (c10, c01) = match m.name.as_str() {
            "QUADRICEPS" => (0.75e-3, 1.0e-3),
            "ISCHIO" => (2.0e-3, 1.0e-3),
            _ => continue,
        };
        *m = material_def(&m.name, &MooneyRivlin { c10, c01, d: 18.0 });
    }
    let model = compression_thigh_with(700, materials);
    let named = |n: &str| Parameter::named(&model, n).unwrap();
    let tied = vec![named("C01_QUADRICEPS"), named("C01_ISCHIO")];
    assert_eq!(tied[0].spec().name, "C01");
    let free = vec![
        FreeParameter {
            name: "C01_QUADRICEPS+C01_ISCHIO".into(),
            members: tied.clone(),
            lower: 0.25e-3,
            upper: 4e-3,
        },
        FreeParameter {
            name: "C10_QUADRICEPS".into(),
            members: vec![named("C10_QUADRICEPS")],
            lower: 0.2e-3,
            upper: 3e-3,
        },
    ];
    let (field, reference) = virtual_field(&model, &free);
    assert_eq!(reference, vec![1.0e-3, 0.75e-3]);
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &field,
        free.clone(),
    )
    .unwrap();
    let r = levenberg_marquardt(&mut p, &[1.5e-3, 0.525e-3], &LmOptions::default()).unwrap();
    for ((f, t), t0) in free.iter().zip(&r.theta).zip(&reference) {
        assert!(
            ((t - t0) / t0).abs() < 1e-3,
            "{} = {t:.6e}, reference {t0:.6e}",
            f.name
        );
    }
    let fitted = p.model();
    assert_eq!(tied[0].value(fitted), tied[1].value(fitted));
}

/// A Yeoh fat (`C10, C20, C30, D1`) identified back from the noise-free compression field
/// (issue 26: every registered law's parameters identified): C10, C20 and D of the fat free
/// (C30, whose term is of third order in `I1bar - 3`, held), from starts 40 % off; all three
/// recovered to 0.1 %.
#[test]
fn yeoh_parameters_are_identified() {
    use femu_mech::material::{material_def, Yeoh};
    use femu_mech::sensitivity::Parameter;
    let mut materials = table1_materials();
    let fat = materials.iter_mut().find(|m| m.name == "FAT").unwrap();
    *fat = material_def(
        "FAT",
        &Yeoh {
            c10: 0.8e-3,
            c20: 0.3e-3,
            c30: 0.1e-3,
            d: 30.8,
        },
    );
    let model = compression_thigh_with(700, materials);
    let free: Vec<FreeParameter> = ["C10_FAT", "C20_FAT", "D_FAT"]
        .iter()
        .map(|n| {
            let p = Parameter::named(&model, n).unwrap();
            let v = p.value(&model);
            FreeParameter {
                name: n.to_string(),
                members: vec![p],
                lower: v / 4.0,
                upper: v * 4.0,
            }
        })
        .collect();
    let (field, reference) = virtual_field(&model, &free);
    assert_eq!(reference, vec![0.8e-3, 0.3e-3, 30.8]);
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &field,
        free.clone(),
    )
    .unwrap();
    let start: Vec<f64> = reference
        .iter()
        .zip([1.4, 0.6, 1.4])
        .map(|(r, f)| r * f)
        .collect();
    let r = levenberg_marquardt(&mut p, &start, &LmOptions::default()).unwrap();
    for ((f, t), t0) in free.iter().zip(&r.theta).zip(&reference) {
        assert!(
            ((t - t0) / t0).abs() < 1e-3,
            "{} = {t:.6e}, reference {t0:.6e}",
            f.name
        );
    }
}

#[test]
fn bad_problems_are_refused() {
    let model = compression_thigh(700);
    let free = free_parameters(&model);
    let outside = MeasuredField {
        points: vec![MeasuredPoint {
            x: [1e4, 1e4],
            u: [0.0, 0.0],
            weight: [1.0, 1.0],
        }],
        comments: vec![],
    };
    let e = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &outside,
        free.clone(),
    );
    assert!(e.err().unwrap().to_string().contains("no measured point"));
    let few = MeasuredField {
        points: vec![MeasuredPoint {
            x: [0.0, 40.0],
            u: [0.0, 0.0],
            weight: [1.0, 1.0],
        }],
        comments: vec![],
    };
    let e = Problem::new(model.clone(), SolverOptions::default(), &few, free.clone());
    assert!(e.err().unwrap().to_string().contains("not enough data"));
    let (field, reference) = virtual_field(&model, &free);
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &field,
        free.clone(),
    )
    .unwrap();
    let mut start = reference.clone();
    start[0] *= 10.0;
    let e = levenberg_marquardt(&mut p, &start, &LmOptions::default());
    assert!(e.err().unwrap().to_string().contains("outside its bounds"));
}

/// LM and BFGS (exact gradient, and the seed's finite-difference gradient) reach the same optimum
/// on the noise-free virtual experiment; the forward solves each needed are printed (measured on
/// 700 quads (798 made), four free parameters: LM 8, BFGS 37, FD-BFGS 369).
#[test]
fn lm_and_bfgs_reach_the_same_optimum() {
    use femu_identify::fit::{bfgs, Gradient};
    let model = compression_thigh(700);
    // Four parameters (fat and quadriceps), the others fixed at Table 1: keeps FD-BFGS short.
    let free: Vec<FreeParameter> = free_parameters(&model).into_iter().take(4).collect();
    let (field, reference) = virtual_field(&model, &free);
    let start: Vec<f64> = reference
        .iter()
        .enumerate()
        .map(|(k, v)| v * if k % 2 == 0 { 1.6 } else { 0.7 })
        .collect();
    let mut runs = Vec::new();
    for method in ["LM", "BFGS exact", "BFGS FD"] {
        let mut p = Problem::new(
            model.clone(),
            SolverOptions::default(),
            &field,
            free.clone(),
        )
        .unwrap();
        let opts = LmOptions::default();
        let r = match method {
            "LM" => levenberg_marquardt(&mut p, &start, &opts).unwrap(),
            "BFGS exact" => bfgs(&mut p, &start, Gradient::Exact, &opts, 200).unwrap(),
            _ => bfgs(&mut p, &start, Gradient::FiniteDifference(5e-4), &opts, 200).unwrap(),
        };
        let worst = r
            .theta
            .iter()
            .zip(&reference)
            .map(|(t, t0)| ((t - t0) / t0).abs())
            .fold(0.0f64, f64::max);
        eprintln!(
            "{method}: worst relative error {worst:.2e}, cost {:.2e}, {} iterations, {} forward solves ({})",
            r.cost, r.iterations, r.forward_solves, r.reason
        );
        measure::record(
            &format!("{method}: worst relative error of the four parameters"),
            worst,
            "< 1e-3",
            "",
        );
        measure::record(
            &format!("{method}: forward solves"),
            r.forward_solves as f64,
            "LM fewer than BFGS FD",
            "",
        );
        runs.push((method, worst, r.forward_solves));
    }
    // All three reach the reference to 0.1 % (measured: 5e-9, 2e-8, 1e-5; with forward
    // differences FD-BFGS stalled at 24 %, hence central differences).
    assert!(runs.iter().all(|r| r.1 < 1e-3), "{runs:?}");
    assert!(
        runs[0].2 < runs[2].2,
        "LM should need fewer solves than FD-BFGS: {runs:?}"
    );
}

/// The actuator term (the plate's measured travel): its Jacobian row is the travel component of
/// the exact sensitivities — checked against central finite differences of the residual (step
/// 1e-4 in ln θ; agreement 1e-4 relative to the row's largest entry, the finite differences'
/// own truncation and the solver tolerance) — and it is refused without a force-controlled body.
#[test]
fn actuator_travel_term_has_the_exact_derivative() {
    let model = compression_thigh(700);
    let free = free_parameters(&model);
    let (field, reference) = virtual_field(&model, &free);
    let phi: Vec<f64> = reference.iter().map(|t| (t * 1.1).ln()).collect();
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &field,
        free.clone(),
    )
    .unwrap()
    .with_travel(7.0, 0.01)
    .unwrap();
    let (r, j) = p.evaluate(&phi, true).unwrap();
    let j = j.unwrap();
    let last = r.len() - 1;
    assert_eq!(r.len(), 2 * field.points.len() + 1);
    let row: Vec<f64> = j.iter().map(|c| c[last]).collect();
    let scale = row.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    let h = 1e-4;
    for k in 0..free.len() {
        let mut q = phi.clone();
        q[k] += h;
        let (rp, _) = p.evaluate(&q, false).unwrap();
        q[k] = phi[k] - h;
        let (rm, _) = p.evaluate(&q, false).unwrap();
        let fd = (rp[last] - rm[last]) / (2.0 * h);
        assert!(
            (fd - row[k]).abs() <= 1e-4 * scale,
            "{}: exact {} vs finite difference {fd}",
            free[k].name,
            row[k]
        );
    }
    // Contention has no rigid body: the term is refused with a message.
    let t = parametric_thigh(
        &ThighParams {
            target_elements: Some(700),
            ..Default::default()
        },
        ElementKind::Cpe4h,
    )
    .unwrap();
    let deck = contention_deck(&t, &table1_materials(), 2.666e-3).unwrap();
    let m = Model::from_deck(deck).unwrap();
    let f2 = free_parameters(&m);
    let e = Problem::new(m, SolverOptions::default(), &field, f2)
        .unwrap()
        .with_travel(1.0, 0.01)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("force-controlled"), "{e}");
}
