//! Integrated DIC (I-DIC) on images with a known answer: a speckle pattern (the DIC's virtual
//! lab, `femu_dic::lab`) in a 40 x 30 mm window on the anterior skin of the built-in thigh,
//! warped by the finite-element displacement of the compression test on a **finer** mesh than
//! the one identified (no inverse crime), at two load steps.
//!
//! - The Jacobian of the grey-level residuals (the exact sensitivities chained with the image
//!   gradients, the probe pose and pixel size, and the brightness projection) against central
//!   finite differences of the residuals themselves.
//! - The parameters under the window recovered from the images, with intervals that hold them.

mod common;
#[path = "../../../scripts/guide/measure.rs"]
mod measure;

use femu_dic::lab::{self, Speckle};
use femu_dic::GreyImage;
use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_identify::fit::{FreeParameter, LeastSquares};
use femu_identify::idic::{
    self, IdicOptions, IdicProblem, IdicSettings, ImageFrame, Pairing, PixelOptions,
};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::locate::PointLocator;
use femu_mesh::ElementKind;

/// Px per mm of the test images.
const PX_PER_MM: f64 = 4.0;
/// The compression force of the full load (N/mm): a fifth of the seed's, so that the
/// analytic warp of the speckle (a fixed point of `X + u(X) = x`) converges everywhere.
const FORCE: f64 = 0.02;

/// The built-in thigh of about `elements` CPE4H quads under `fraction` of the compression.
fn thigh(elements: usize, fraction: f64) -> Model {
    let t = parametric_thigh(
        &ThighParams {
            target_elements: Some(elements),
            ..Default::default()
        },
        ElementKind::Cpe4h,
    )
    .unwrap();
    let skin = t.mesh.surfaces["SKIN"].clone();
    let mut deck = contention_deck(&t, &table1_materials(), 0.0).unwrap();
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).unwrap();
    let full = Loading::seed_compression().scaled(FORCE / 0.1);
    apply_loading(&mut model, &skin, &full.scaled(fraction)).unwrap();
    model
}

/// The window: 160 x 120 px at 4 px/mm, its top edge 1 mm above the anterior skin (y = 60).
fn window() -> (ImageFrame, usize, usize) {
    let s = 1.0 / PX_PER_MM;
    let frame = ImageFrame::new(
        [-20.0 + 0.5 * s, 61.0 - 0.5 * s],
        s,
        [1.0, 0.0],
        [0.0, -1.0],
    )
    .unwrap();
    (frame, 160, 120)
}

/// The unloaded speckle and its images at the load fractions, warped by the displacement of
/// the `elements`-quad model, extended outside the tissue by that of the nearest node (so that
/// the warp stays continuous across the skin and its inversion converges there).
fn images(elements: usize, fractions: &[f64], seed: u64) -> Vec<GreyImage> {
    let (frame, w, h) = window();
    let speckle = Speckle::new(w, h, 1.5, seed);
    let mut out = vec![speckle.reference()];
    let mut warm: Option<Vec<f64>> = None;
    for &f in fractions {
        let m = thigh(elements, f);
        let mut solver = StaticSolver::new(&m, SolverOptions::default()).unwrap();
        let sol = solver.solve_with(&m, warm.as_deref(), &mut |_| {}).unwrap();
        let locator = PointLocator::new(&m.mesh);
        let u = sol.u.clone();
        let nodes = &m.mesh.nodes;
        let field = move |x: f64, y: f64| -> [f64; 2] {
            let p = frame.pixel_to_model([x, y]);
            let um = match locator.locate(p) {
                Some(l) => [l.interpolate(&u, 2, 0), l.interpolate(&u, 2, 1)],
                None => {
                    let d2 = |q: &[f64; 2]| (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                    let (n, _) = nodes
                        .iter()
                        .enumerate()
                        .min_by(|a, b| d2(a.1).total_cmp(&d2(b.1)))
                        .expect("nodes");
                    [u[2 * n], u[2 * n + 1]]
                }
            };
            frame.displacement_to_pixels(um)
        };
        out.push(lab::quantize_8bit(&lab::add_noise(
            &speckle.deformed(&field),
            2.0,
            seed + 7,
        )));
        warm = Some(sol.state);
    }
    out
}

/// C10 and D of fat and quadriceps free (bounds x/÷ 4), the others held.
fn free(model: &Model) -> (Vec<FreeParameter>, Vec<f64>) {
    common::named_free(
        model,
        &["C10_FAT", "D_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"],
    )
}

fn problem(
    elements: usize,
    imgs: Vec<GreyImage>,
    fractions: &[f64],
    pairing: Pairing,
    solver: SolverOptions,
    contact_tolerance: f64,
    local_normalization_px: Option<f64>,
) -> IdicProblem {
    let models: Vec<Model> = fractions
        .iter()
        .map(|&f| {
            let mut m = thigh(elements, f);
            for c in &mut m.contacts {
                c.penetration_tolerance = contact_tolerance;
            }
            m
        })
        .collect();
    let (f, _) = free(&models[0]);
    let (frame, _, _) = window();
    IdicProblem::new(
        models,
        imgs,
        frame,
        f,
        IdicOptions {
            pairing,
            brightness: true,
            pixels: PixelOptions {
                band_px: Some(40),
                block_px: 16,
                ..PixelOptions::default()
            },
            solver,
            local_normalization_px,
        },
    )
    .unwrap()
}

/// [`problem`] with the identification's solver settings (default Newton, contact 1e-8) and
/// the grey levels as recorded.
fn identification_problem(
    elements: usize,
    imgs: Vec<GreyImage>,
    fractions: &[f64],
    pairing: Pairing,
) -> IdicProblem {
    problem(
        elements,
        imgs,
        fractions,
        pairing,
        SolverOptions::default(),
        1e-8,
        None,
    )
}

/// `∂r/∂φ_j` against central differences of the residuals, both pairings, on the sharp images
/// and on smoothed ones, the frames as recorded and locally normalized, away from the optimum (parameters 10–30 % off). The states are
/// converged to a relative force residual of 1e-12 and the plate's contact to a penetration of
/// 1e-12 of the element size (the identification's 1e-8 moves the skin under the plate by
/// ~1e-8 mm between neighbouring solves, ~3e-3 of a column after division by 2h: measured).
/// Step 3e-4 in `φ = ln θ`: truncation O(h²) ~ 1e-7 of the column, measured worst 1.8e-6.
/// Asserted: the largest difference below 1e-5 of the column's largest entry.
#[test]
fn jacobian_matches_finite_differences() {
    let fractions = [0.5, 1.0];
    let imgs = images(1200, &fractions, 3);
    for (pairing, scale, local) in [
        (Pairing::Reference, 0.0, None),
        (Pairing::Consecutive, 2.0, None),
        (Pairing::Consecutive, 0.0, Some(3.0)),
        (Pairing::All, 0.0, Some(0.75)),
    ] {
        let tight = SolverOptions {
            residual_tolerance: 1e-12,
            energy_tolerance: 1e-20,
            ..SolverOptions::default()
        };
        let mut p = problem(700, imgs.clone(), &fractions, pairing, tight, 1e-12, local);
        p.set_scale(scale);
        let (_, reference) = free(p.model(0));
        let phi: Vec<f64> = reference
            .iter()
            .zip([1.1, 0.8, 1.3, 0.9])
            .map(|(v, k)| (v * k).ln())
            .collect();
        let (_, j) = p.evaluate(&phi, true).unwrap();
        let j = j.unwrap();
        let h = 3e-4;
        for (k, col) in j.iter().enumerate() {
            let mut q = phi.clone();
            q[k] = phi[k] + h;
            let (rp, _) = p.evaluate(&q, false).unwrap();
            q[k] = phi[k] - h;
            let (rm, _) = p.evaluate(&q, false).unwrap();
            let scale_col = col.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let worst = col
                .iter()
                .zip(rp.iter().zip(&rm))
                .map(|(a, (p, m))| (a - (p - m) / (2.0 * h)).abs())
                .fold(0.0f64, f64::max);
            measure::record(
                &format!(
                    "{pairing:?} pairing, smoothing {scale} px, local normalization {}, parameter {k}: Jacobian column against central differences, largest error / largest entry",
                    local.map_or("off".to_string(), |l| format!("{l} px"))
                ),
                worst / scale_col,
                "< 1e-5",
                "",
            );
            assert!(
                scale_col > 0.0,
                "{pairing:?}: parameter {k} has a zero column"
            );
            assert!(
                worst < 1e-5 * scale_col,
                "{pairing:?}, scale {scale}, local normalization {local:?}: parameter {k}: largest difference {worst:.3e}, column scale {scale_col:.3e}"
            );
        }
    }
}

/// C10 and D of fat and quadriceps from three Latin-hypercube starts (bounds x/÷ 4), coarse to
/// fine (Gaussian smoothing 3, 1, 0 px), from the speckle warped by a 4 000-quad solution and
/// identified on about 1 000 quads (2 elements across the fat): the coarse mesh's discretization
/// error dominates (measured: C10_FAT −7.9 %, D_FAT +42 %, C10_QUADRICEPS +2.7 %, D_QUADRICEPS
/// +56 %, against sandwich sd of 2.4, 21, 0.3, 6.9 %), and the shift that a 2 000-quad mesh
/// implies (+6.4, −34, −3.5, −34 % in ln θ) sees it. Asserted: every true value within the 95 %
/// interval of `sd² = sd_sandwich² + shift²`; where the error is over three sandwich sd the
/// shift has its sign and at least half its size; C10_QUADRICEPS (most of the window) within
/// 5 %. Against the same mesh (inverse crime, not asserted) the errors are 0.06, 0.9, 0.4 and
/// 12 % with sd 0.6, 5.3, 0.2, 6.3 %.
#[test]
fn parameters_under_the_window_come_back_from_speckle_images() {
    let fractions = [0.5, 1.0];
    let imgs = images(4000, &fractions, 5);
    let make = || {
        Ok(identification_problem(
            1000,
            imgs.clone(),
            &fractions,
            Pairing::Reference,
        ))
    };
    let settings = IdicSettings {
        starts: 3,
        scales_px: vec![3.0, 1.0, 0.0],
        ..IdicSettings::default()
    };
    let (p, out) = idic::identify(&make, &settings, &|_| {}).unwrap();
    let (_, reference) = free(&thigh(1000, 1.0));
    let shift = p
        .discretization_shift(
            fractions.iter().map(|&f| thigh(2000, f)).collect(),
            &[true; 4],
        )
        .unwrap();
    for (k, f) in p.free().iter().enumerate() {
        let e = (out.theta[k] / reference[k]).ln();
        let sd = out.covariance.sd[k];
        eprintln!(
            "{}: error {:+.3} %, sd {:.3} % (independent {:.3} %), shift {:+.3} %",
            f.name,
            100.0 * (out.theta[k] / reference[k] - 1.0),
            100.0 * sd,
            100.0 * out.covariance.sd_independent[k],
            100.0 * shift[k]
        );
        let total = sd.hypot(shift[k]);
        measure::record(
            &format!(
                "{}: |ln error| (sandwich sd {:.3}, discretization shift {:+.3}) / (1.96 sd with the shift)",
                f.name, sd, shift[k]
            ),
            e.abs() / (1.96 * total),
            "≤ 1",
            "",
        );
        assert!(
            e.abs() <= 1.96 * total,
            "{}: ln error {e:.4}, sd {total:.4}",
            f.name
        );
        if e.abs() > 3.0 * sd {
            // The identified value minus the shift's estimate of the truth: the shift points
            // from the estimate towards the refined mesh's optimum.
            assert!(
                -shift[k] * e > 0.0 && shift[k].abs() > 0.5 * e.abs(),
                "{}: error {e:.4} not seen by the shift {:.4}",
                f.name,
                shift[k]
            );
        }
    }
    let quad = (out.theta[2] / reference[2] - 1.0).abs();
    measure::record("C10_QUADRICEPS: |relative error|", quad, "< 0.05", "");
    assert!(quad < 0.05, "C10_QUADRICEPS {quad}");
}

/// No start (`starts = 0`, none given) is a returned error, not a panic.
#[test]
fn no_start_is_an_error() {
    let fractions = [1.0];
    let imgs = images(1000, &fractions, 3);
    let make = || {
        Ok(identification_problem(
            1000,
            imgs.clone(),
            &fractions,
            Pairing::Reference,
        ))
    };
    let settings = IdicSettings {
        starts: 0,
        ..IdicSettings::default()
    };
    match idic::identify(&make, &settings, &|_| {}) {
        Err(e) => assert!(e.to_string().contains("no start"), "{e}"),
        Ok(_) => panic!("identified without a start"),
    }
}

/// The pairs of each pairing on five frames; `All` ordered by the frames' distance, the last
/// `(0, 4)` as for `Reference` and `Both` (the residual maps show the last pair).
#[test]
fn pairings_compare_the_frames_they_name() {
    let fractions = [0.25, 0.5, 0.75, 1.0];
    let imgs = images(700, &fractions, 4);
    let pairs = |pairing| {
        identification_problem(700, imgs.clone(), &fractions, pairing)
            .pairs()
            .to_vec()
    };
    assert_eq!(pairs(Pairing::Reference), [(0, 1), (0, 2), (0, 3), (0, 4)]);
    assert_eq!(
        pairs(Pairing::Consecutive),
        [(0, 1), (1, 2), (2, 3), (3, 4)]
    );
    assert_eq!(
        pairs(Pairing::Both),
        [(0, 1), (1, 2), (2, 3), (3, 4), (0, 2), (0, 3), (0, 4)]
    );
    assert_eq!(
        pairs(Pairing::All),
        [
            (0, 1),
            (1, 2),
            (2, 3),
            (3, 4),
            (0, 2),
            (1, 3),
            (2, 4),
            (0, 3),
            (1, 4),
            (0, 4)
        ]
    );
}
