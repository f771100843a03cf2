//! The speckle's lateral shift under shear in the measurement model (module `speckle`): its
//! Jacobian against finite differences with a fixed scale, the profiled (fitted) scale against
//! its definition, and an identification on a field that carries the shift.

use femu_identify::fit::{levenberg_marquardt, FreeParameter, LeastSquares, LmOptions, Problem};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_identify::speckle::{ShiftScale, SpeckleShift};
use femu_mech::{Model, SolverOptions};

mod common;

fn thigh() -> Model {
    common::compression_thigh(800)
}

fn free(model: &Model) -> (Vec<FreeParameter>, Vec<f64>) {
    common::named_free(
        model,
        &["C10_FAT", "D_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"],
    )
}

/// The pymust Hann frames' imaging (9 MHz, lateral FWHM 0.907 mm), the probe face on the
/// anterior skin, image rows going down.
fn shift(model: &Model, scale: ShiftScale) -> SpeckleShift {
    let top = model
        .mesh
        .nodes
        .iter()
        .fold(f64::NEG_INFINITY, |m, x| m.max(x[1]));
    SpeckleShift {
        frequency_mhz: 9.0,
        resolution_mm: 0.907,
        sound_speed_m_s: 1540.0,
        face: [0.0, top],
        lateral: [1.0, 0.0],
        axial: [0.0, -1.0],
        scale,
    }
}

/// A 2 mm grid under the probe (40 mm wide, 2-38 mm deep) in the tissue, measured values 0.
fn window(model: &Model) -> MeasuredField {
    let top = shift(model, ShiftScale::Fitted).face[1];
    let locator = femu_mesh::locate::PointLocator::new(&model.mesh);
    MeasuredField {
        points: (0..19)
            .flat_map(|j| {
                (0..21).map(move |i| [-20.0 + 2.0 * i as f64, top - 2.0 - 2.0 * j as f64])
            })
            .filter(|x| locator.locate(*x).is_some())
            .map(|x| MeasuredPoint {
                x,
                u: [0.0, 0.0],
                weight: [1.0, 1.0],
            })
            .collect(),
        comments: vec![],
    }
}

/// The model's field at `theta` seen through the speckle shift of scale `kappa`, as the
/// measured field of `field`'s points.
fn measured(model: &Model, free: &[FreeParameter], theta: &[f64], kappa: f64) -> MeasuredField {
    let mut field = window(model);
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &field,
        free.to_vec(),
    )
    .unwrap()
    .with_speckle_shift(shift(model, ShiftScale::Fixed(kappa)))
    .unwrap();
    let u = p.field_at(theta).unwrap();
    for (k, pt) in field.points.iter_mut().enumerate() {
        pt.u = [u[2 * k], u[2 * k + 1]];
    }
    field
}

/// With a fixed scale the shift is part of the projection, linear in the displacement: the
/// Jacobian columns (the sensitivities through the shift) against central differences of the
/// residuals (step 1e-4 in ln θ; agreement 1e-4 of the column's largest entry, as for the
/// actuator term: truncation ~h² and the solver's tolerance, 3e-5 here with or without the
/// shift), and the shift itself is
/// of the size the closed form says (the lateral field moves by a fifth of a millimetre or
/// more somewhere under the probe).
#[test]
fn fixed_scale_jacobian_matches_finite_differences() {
    let model = thigh();
    let (free, reference) = free(&model);
    let field = window(&model);
    let without = measured(&model, &free, &reference, 0.0);
    let with = measured(&model, &free, &reference, 1.0);
    let largest = without
        .points
        .iter()
        .zip(&with.points)
        .map(|(a, b)| (a.u[0] - b.u[0]).abs())
        .fold(0.0, f64::max);
    assert!(largest > 0.2, "largest lateral shift {largest} mm");
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        &field,
        free.clone(),
    )
    .unwrap()
    .with_speckle_shift(shift(&model, ShiftScale::Fixed(0.8)))
    .unwrap();
    let phi: Vec<f64> = reference.iter().map(|t| (t * 1.1).ln()).collect();
    let (_, j) = p.evaluate(&phi, true).unwrap();
    let j = j.unwrap();
    let h = 1e-4;
    for k in 0..free.len() {
        let mut q = phi.clone();
        q[k] += h;
        let (rp, _) = p.evaluate(&q, false).unwrap();
        q[k] = phi[k] - h;
        let (rm, _) = p.evaluate(&q, false).unwrap();
        let scale = j[k].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = (0..rp.len())
            .map(|i| ((rp[i] - rm[i]) / (2.0 * h) - j[k][i]).abs())
            .fold(0.0, f64::max);
        assert!(
            worst <= 1e-4 * scale,
            "{}: worst {worst:.3e} of {scale:.3e}",
            free[k].name
        );
    }
}

/// A fitted scale is profiled out: the residual is the fixed-scale residual at the optimal
/// κ (orthogonal to the weighted shift v), and the Jacobian is the fixed-scale Jacobian at
/// that κ with its component along v removed (Kaufman's variable projection). Round-off
/// agreement (1e-9 of the largest entry: the same solve, a few dot products).
#[test]
fn fitted_scale_is_profiled_out() {
    let model = thigh();
    let (free, reference) = free(&model);
    let data = measured(&model, &free, &reference, 0.7);
    let phi: Vec<f64> = reference.iter().map(|t| (t * 0.9).ln()).collect();
    let problem = |scale| {
        Problem::new(model.clone(), SolverOptions::default(), &data, free.clone())
            .unwrap()
            .with_speckle_shift(shift(&model, scale))
            .unwrap()
    };
    let mut fitted = problem(ShiftScale::Fitted);
    let (r, j) = fitted.evaluate(&phi, true).unwrap();
    let j = j.unwrap();
    let kappa = fitted.speckle_scale().unwrap();
    let (rk, jk) = problem(ShiftScale::Fixed(kappa))
        .evaluate(&phi, true)
        .unwrap();
    let jk = jk.unwrap();
    let (r1, _) = problem(ShiftScale::Fixed(kappa + 1.0))
        .evaluate(&phi, false)
        .unwrap();
    let v: Vec<f64> = r1.iter().zip(&rk).map(|(a, b)| a - b).collect();
    let vv: f64 = v.iter().map(|x| x * x).sum();
    let big = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(vv > 0.0);
    let along: f64 = v.iter().zip(&rk).map(|(a, b)| a * b).sum::<f64>() / vv.sqrt();
    assert!(
        along.abs() <= 1e-9 * big(&rk) * (r.len() as f64).sqrt(),
        "residual along v: {along}"
    );
    for (a, b) in r.iter().zip(&rk) {
        assert!((a - b).abs() <= 1e-9 * big(&rk));
    }
    for k in 0..free.len() {
        let a: f64 = v.iter().zip(&jk[k]).map(|(x, y)| x * y).sum::<f64>() / vv;
        for i in 0..r.len() {
            let want = jk[k][i] - a * v[i];
            assert!(
                (j[k][i] - want).abs() <= 1e-9 * big(&jk[k]),
                "{} row {i}",
                free[k].name
            );
        }
    }
}

/// A field measured through the shift (scale 0.85, as a point-spread function whose shift
/// is below the closed form's): without the term the fat's parameters are biased; with a
/// fitted scale every parameter comes back to 0.1 % from a start 30 % off, and so does κ.
#[test]
fn identification_with_a_fitted_scale_recovers_the_parameters_and_the_scale() {
    let model = thigh();
    let (free, reference) = free(&model);
    let data = measured(&model, &free, &reference, 0.85);
    let start: Vec<f64> = reference
        .iter()
        .enumerate()
        .map(|(k, t)| t * if k % 2 == 0 { 1.3 } else { 0.7 })
        .collect();
    let errors = |scale: Option<ShiftScale>| {
        let mut p =
            Problem::new(model.clone(), SolverOptions::default(), &data, free.clone()).unwrap();
        if let Some(s) = scale {
            p = p.with_speckle_shift(shift(&model, s)).unwrap();
        }
        let r = levenberg_marquardt(&mut p, &start, &LmOptions::default()).unwrap();
        let e: Vec<f64> = r
            .theta
            .iter()
            .zip(&reference)
            .map(|(t, t0)| 100.0 * (t / t0 - 1.0))
            .collect();
        (e, p.speckle_scale())
    };
    let (biased, _) = errors(None);
    assert!(
        biased[1].abs() > 5.0,
        "D_FAT without the term: {biased:?} %"
    );
    let (e, kappa) = errors(Some(ShiftScale::Fitted));
    for (k, v) in e.iter().enumerate() {
        assert!(v.abs() < 0.1, "{}: {v:+.3} %", free[k].name);
    }
    let kappa = kappa.unwrap();
    assert!((kappa - 0.85).abs() < 1e-3, "kappa {kappa}");
}

/// The scale's standard deviation is its spread over noise: 24 seeded realizations of Gaussian
/// noise (σ = 0.02 mm, weights 1/σ²) on a field measured through the shift (scale 0.85), each
/// fitted with the scale fitted. The sample sd of 24 draws is within ±30 % of the true one in
/// about 95 % of cases (its relative standard error is 1/√46); the bound is 40 %. The mean is
/// within three standard errors of 0.85.
#[test]
fn the_scale_sd_is_its_spread_over_noise() {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let model = thigh();
    let (free, reference) = free(&model);
    let exact = measured(&model, &free, &reference, 0.85);
    let sigma = 0.02;
    let mut estimates = Vec::new();
    let mut predicted = Vec::new();
    for seed in 0..24u64 {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let mut data = exact.clone();
        for p in &mut data.points {
            p.u = [
                p.u[0] + noise.sample(&mut rng),
                p.u[1] + noise.sample(&mut rng),
            ];
            p.weight = [1.0 / (sigma * sigma); 2];
        }
        let mut p = Problem::new(model.clone(), SolverOptions::default(), &data, free.clone())
            .unwrap()
            .with_speckle_shift(shift(&model, ShiftScale::Fitted))
            .unwrap();
        let r = levenberg_marquardt(&mut p, &reference, &LmOptions::default()).unwrap();
        let phi: Vec<f64> = r.theta.iter().map(|t| t.ln()).collect();
        let (kappa, sd) = femu_identify::misfit_intervals::speckle_scale_sd(&mut p, &phi)
            .unwrap()
            .unwrap();
        estimates.push(kappa);
        predicted.push(sd);
    }
    let n = estimates.len() as f64;
    let mean = estimates.iter().sum::<f64>() / n;
    let spread = (estimates.iter().map(|k| (k - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let sd = predicted.iter().sum::<f64>() / n;
    println!("scale: mean {mean:.4}, spread {spread:.4}, predicted sd {sd:.4}");
    assert!(
        (spread / sd - 1.0).abs() < 0.4,
        "spread {spread} vs predicted {sd}"
    );
    assert!((mean - 0.85).abs() < 3.0 * sd / n.sqrt(), "mean {mean}");
}
