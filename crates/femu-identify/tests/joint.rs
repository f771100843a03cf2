//! Joint identification (issue 27): several measurements — the contention and the compression
//! tests of the built-in thigh, each seen on its own point set — fitted together with the exact
//! Jacobian of the stacked residuals.
//!
//! - the stacked Jacobian against central finite differences of the stacked residuals;
//! - a joint identification of one measurement is the single-measurement identification;
//! - noise-free, the joint fit recovers all ten parameters from Latin-hypercube starts, which
//!   neither test alone identifies as well (each measurement's share of the information);
//! - a light Monte Carlo (8 noise realizations; `femu identify` with `--repeat 20` on the
//!   windows study is the full one, README): the 95 % intervals cover the truth.

use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_identify::campaign::{self, BlockSpec, CampaignOptions, Data, FieldBlock, Optimizer};
use femu_identify::fit::{levenberg_marquardt, FreeParameter, LeastSquares, LmOptions, Problem};
use femu_identify::joint::{block_free, information_shares, Block, JointProblem};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::{Model, SolverOptions};
use femu_mesh::ElementKind;

mod common;
use common::free_parameters;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// The built-in thigh (about `elements` CPE4H quads) unloaded, and its skin.
fn thigh(elements: usize) -> (Model, Vec<(usize, usize)>) {
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
    (Model::from_deck(deck).unwrap(), skin)
}

fn loaded(base: &Model, skin: &[(usize, usize)], test: &Loading) -> Model {
    let mut m = base.clone();
    apply_loading(&mut m, skin, test).unwrap();
    m
}

/// A regular grid of `n x n` points over the model's bounding box, those in the tissue kept; with
/// `half` only the anterior (`y > 0`) or the posterior half.
fn grid(model: &Model, n: usize, half: Option<bool>) -> Vec<[f64; 2]> {
    let (lo, hi) = model.mesh.bounding_box();
    let h = (hi[0] - lo[0]).max(hi[1] - lo[1]) / (n - 1) as f64;
    let pts: Vec<[f64; 2]> = (0..n)
        .flat_map(|j| (0..n).map(move |i| [lo[0] + i as f64 * h, lo[1] + j as f64 * h]))
        .filter(|x| half.is_none_or(|anterior| (x[1] > 0.0) == anterior))
        .collect();
    campaign::points_in_tissue(model, &pts)
}

/// The problem of one block from a field realized by the campaign.
fn problem(model: &Model, field: &MeasuredField, free: &[FreeParameter]) -> Problem {
    Problem::new(
        model.clone(),
        SolverOptions::default(),
        field,
        free.to_vec(),
    )
    .unwrap()
}

/// The stacked residuals' Jacobian (columns `θ ∂r/∂θ`) against central differences in the
/// log-parameters, step 1e-4: the forward solves are converged to 1e-8 of the load, so the
/// differences carry ~1e-8/1e-4 = 1e-4 of relative noise, and their truncation is ~1e-8; 2e-3
/// of the column norm is asserted.
#[test]
fn stacked_jacobian_matches_finite_differences() {
    let (base, skin) = thigh(700);
    let models = [
        loaded(&base, &skin, &Loading::seed_contention()),
        loaded(&base, &skin, &Loading::seed_compression()),
    ];
    let (free, reference) = free_parameters(&base);
    let points = [grid(&base, 24, Some(true)), grid(&base, 24, Some(false))];
    let blocks: Vec<BlockSpec> = models
        .iter()
        .zip(&points)
        .map(|(m, p)| {
            BlockSpec::Field(FieldBlock {
                name: "block".into(),
                warm: None,
                model: m,
                coarse: None,
                truth: None,
                segments: vec![(
                    "part".into(),
                    Data::Virtual {
                        points: p,
                        sigma: 0.01,
                    },
                )],
                travel: None,
            })
        })
        .collect();
    let fields = campaign::realized_fields(&base, &free, &reference, &blocks, 3, 0).unwrap();
    let make = || {
        let stacked = models
            .iter()
            .zip(&fields)
            .map(|(m, (f, _))| {
                let (bf, map) = block_free(&free, &base, m);
                Block {
                    name: "b".into(),
                    problem: Box::new(problem(m, f, &bf)),
                    map,
                    segments: vec![],
                }
            })
            .collect();
        JointProblem::new(free.clone(), stacked).unwrap()
    };
    let mut joint = make();
    let phi: Vec<f64> = reference.iter().map(|v| (v * 1.1).ln()).collect();
    let (r0, jac) = joint.evaluate(&phi, true).unwrap();
    let jac = jac.unwrap();
    let step = 1e-4;
    for k in 0..free.len() {
        let mut p = phi.clone();
        p[k] += step;
        let (rp, _) = make().evaluate(&p, false).unwrap();
        p[k] -= 2.0 * step;
        let (rm, _) = make().evaluate(&p, false).unwrap();
        let fd: Vec<f64> = rp
            .iter()
            .zip(&rm)
            .map(|(a, b)| (a - b) / (2.0 * step))
            .collect();
        let norm = jac[k].iter().map(|v| v * v).sum::<f64>().sqrt();
        let diff = jac[k]
            .iter()
            .zip(&fd)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        eprintln!("{}: |J - FD| / |J| = {:.2e}", free[k].name, diff / norm);
        measure::record(
            &format!("stacked Jacobian, column {}: |J - FD| / |J|", free[k].name),
            diff / norm,
            "≤ 2e-3",
            "",
        );
        assert!(
            diff <= 2e-3 * norm,
            "{}: {diff:.3e} of {norm:.3e}",
            free[k].name
        );
    }
    assert_eq!(r0.len(), jac[0].len());
}

/// A joint identification of one measurement is the identification of that measurement: the
/// same residuals and Jacobian as the single problem, and `campaign::run` (a joint of one) finds
/// the same optimum as LM on the single problem from the same start.
#[test]
fn a_joint_of_one_is_the_single_identification() {
    let (base, skin) = thigh(700);
    let model = loaded(&base, &skin, &Loading::seed_compression());
    let (free, reference) = free_parameters(&base);
    let points = grid(&base, 40, None);
    let field = campaign::virtual_field(&model, &free, &reference, &points, 0.02, 5).unwrap();
    let phi: Vec<f64> = reference.iter().map(|v| (v * 0.9).ln()).collect();
    let (r1, j1) = problem(&model, &field, &free).evaluate(&phi, true).unwrap();
    let mut joint = JointProblem::new(
        free.clone(),
        vec![Block {
            name: "one".into(),
            problem: Box::new(problem(&model, &field, &free)),
            map: (0..free.len()).collect(),
            segments: vec![],
        }],
    )
    .unwrap();
    let (r2, j2) = joint.evaluate(&phi, true).unwrap();
    assert_eq!(r1, r2);
    assert_eq!(j1, j2);
    let options = CampaignOptions {
        optimizer: Optimizer::LevenbergMarquardt,
        starts: 1,
        seed: 5,
        repeats: 1,
        travel: None,
        stop: None,
        covariance: None,
        speckle_shift: None,
        loss: Default::default(),
    };
    let c = campaign::run(
        &model,
        None,
        &free,
        &reference,
        Data::Measured(&field),
        &options,
        &|_| {},
    )
    .unwrap();
    let start = &c.starts[0].theta_start;
    let single = levenberg_marquardt(
        &mut problem(&model, &field, &free),
        start,
        &LmOptions::default(),
    )
    .unwrap();
    assert_eq!(c.best[0].theta, single.theta);
    assert_eq!(c.best[0].forward_solves, single.forward_solves);
}

/// Noise-free data of both tests (each on half of a 40 x 40 grid): the joint fit recovers every
/// parameter to 1e-3 from each of three Latin-hypercube starts; compression carries most of the
/// information on C10 of the quadriceps and contention most of it on D of the fat (the seed's
/// finding, §3.2).
#[test]
fn noise_free_joint_fit_recovers_every_parameter() {
    let (base, skin) = thigh(700);
    let contention = loaded(&base, &skin, &Loading::seed_contention());
    let compression = loaded(&base, &skin, &Loading::seed_compression());
    let (free, reference) = free_parameters(&base);
    let (front, back) = (grid(&base, 40, Some(true)), grid(&base, 40, Some(false)));
    // No noise: the model field itself, weighted as with the seed's noise.
    let part = |pts: &[[f64; 2]], m: &Model| {
        let mut f = MeasuredField {
            points: pts
                .iter()
                .map(|&x| MeasuredPoint {
                    x,
                    u: [0.0; 2],
                    weight: [1.0 / 0.0176f64.powi(2); 2],
                })
                .collect(),
            comments: vec![],
        };
        let u = problem(m, &f, &free).field_at(&reference).unwrap();
        for (k, pt) in f.points.iter_mut().enumerate() {
            pt.u = [u[2 * k], u[2 * k + 1]];
        }
        f
    };
    let fields = [
        part(&front, &contention),
        part(&back, &contention),
        part(&front, &compression),
    ];
    let blocks = vec![
        BlockSpec::Field(FieldBlock {
            name: "contention".into(),
            warm: None,
            model: &contention,
            coarse: None,
            truth: None,
            segments: vec![
                ("contention front".into(), Data::Measured(&fields[0])),
                ("contention back".into(), Data::Measured(&fields[1])),
            ],
            travel: None,
        }),
        BlockSpec::Field(FieldBlock {
            name: "compression".into(),
            warm: None,
            model: &compression,
            coarse: None,
            truth: None,
            segments: vec![("compression front".into(), Data::Measured(&fields[2]))],
            travel: None,
        }),
    ];
    let options = CampaignOptions {
        optimizer: Optimizer::LevenbergMarquardt,
        starts: 3,
        seed: 11,
        repeats: 1,
        travel: None,
        stop: None,
        covariance: None,
        speckle_shift: None,
        loss: Default::default(),
    };
    let c = campaign::run_joint(&base, &free, &reference, &blocks, &options, &|_| {}).unwrap();
    for s in &c.starts {
        let r = s.result.as_ref().expect("every start converges");
        for ((f, t), t0) in free.iter().zip(&r.theta).zip(&reference) {
            assert!(
                ((t - t0) / t0).abs() < 1e-3,
                "start {}: {} = {t:.6e}, reference {t0:.6e}",
                s.start,
                f.name
            );
        }
        eprintln!(
            "start {}: {} forward solves, cost {:.2e}",
            s.start, r.forward_solves, r.cost
        );
        measure::record(
            &format!(
                "noise-free joint fit, start {}: worst relative error",
                s.start
            ),
            free.iter()
                .zip(&r.theta)
                .zip(&reference)
                .map(|((_, t), t0)| ((t - t0) / t0).abs())
                .fold(0.0f64, f64::max),
            "< 1e-3",
            "",
        );
    }
    let names: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
    let segment_names: Vec<&str> = c.layout.iter().map(|s| s.0.as_str()).collect();
    assert_eq!(
        segment_names,
        ["contention front", "contention back", "compression front"]
    );
    let shares = information_shares(&c.best[0].jacobian, &c.layout, &names);
    let k = |n: &str| names.iter().position(|m| m == n).unwrap();
    let contention_share = |p: usize| shares[0].share[p] + shares[1].share[p];
    eprintln!(
        "share of compression on C10_QUADRICEPS {:.3}, of contention on D_FAT {:.3}",
        shares[2].share[k("C10_QUADRICEPS")],
        contention_share(k("D_FAT"))
    );
    assert!(shares[2].share[k("C10_QUADRICEPS")] > 0.5);
    assert!(contention_share(k("D_FAT")) > 0.5);
}

/// A light Monte Carlo: both tests on half grids with the seed's noise, 8 realizations from one
/// start each (on the model's own mesh, so that the intervals' statistics alone are tested; the
/// discretization's part is `tests/discretization.rs`). Of the 80 intervals the number outside
/// is binomial(80, 5 %), mean 4: at least 70 inside (87.5 %) fails with probability 0.2 % for
/// honest intervals; and the spread of the identified values matches the predicted sd within
/// the sampling error of 8 draws (a factor 3 either way: the sample sd of 8 normal draws falls
/// below a third of the true one with probability 0.2 %).
#[test]
fn light_monte_carlo_intervals_cover_the_truth() {
    let (base, skin) = thigh(700);
    let contention = loaded(&base, &skin, &Loading::seed_contention());
    let compression = loaded(&base, &skin, &Loading::seed_compression());
    let (free, reference) = free_parameters(&base);
    let (front, back) = (grid(&base, 48, Some(true)), grid(&base, 48, Some(false)));
    let sigma = 0.0176;
    let blocks = vec![
        BlockSpec::Field(FieldBlock {
            name: "contention".into(),
            warm: None,
            model: &contention,
            coarse: None,
            truth: None,
            segments: vec![
                (
                    "front".into(),
                    Data::Virtual {
                        points: &front,
                        sigma,
                    },
                ),
                (
                    "back".into(),
                    Data::Virtual {
                        points: &back,
                        sigma,
                    },
                ),
            ],
            travel: None,
        }),
        BlockSpec::Field(FieldBlock {
            name: "compression".into(),
            warm: None,
            model: &compression,
            coarse: None,
            truth: None,
            segments: vec![(
                "front".into(),
                Data::Virtual {
                    points: &front,
                    sigma,
                },
            )],
            travel: None,
        }),
    ];
    let options = CampaignOptions {
        optimizer: Optimizer::LevenbergMarquardt,
        starts: 1,
        seed: 2027,
        repeats: 8,
        travel: None,
        stop: None,
        covariance: None,
        speckle_shift: None,
        loss: Default::default(),
    };
    let c = campaign::run_joint(&base, &free, &reference, &blocks, &options, &|_| {}).unwrap();
    assert_eq!(c.best.len(), 8);
    let (est, _) = campaign::estimates(&c, &free, &reference, true, true).unwrap();
    let inside: f64 = est.iter().map(|e| e.coverage95.unwrap() * 8.0).sum();
    for e in &est {
        let spread = e.sd_identified_relative.unwrap();
        eprintln!(
            "{:<16} sd {:.3} % spread {:.3} % worst error {:.3} % coverage {:.0} %",
            e.name,
            100.0 * e.relative_sd,
            100.0 * spread,
            100.0 * e.max_relative_error.unwrap(),
            100.0 * e.coverage95.unwrap()
        );
        assert!(
            spread < 3.0 * e.relative_sd && spread > e.relative_sd / 3.0,
            "{}: spread {spread} vs sd {}",
            e.name,
            e.relative_sd
        );
    }
    eprintln!("{inside} of 80 intervals hold the truth");
    measure::record(
        "light Monte Carlo (8 realizations, the seed's noise): intervals holding the truth, of 80",
        inside,
        "≥ 70",
        "",
    );
    assert!(inside >= 70.0, "{inside} of 80 intervals hold the truth");
}

/// Virtual data made on a finer mesh of the same geometry (no inverse crime): the points of the
/// model's tissue that fall outside the finer mesh's outline (near the skin the two polygons
/// differ) have no data and are left out, the others keep their order and noise.
#[test]
fn virtual_data_on_a_finer_mesh_leave_out_the_points_it_lacks() {
    let mesh = |h: f64| {
        let t = femu_geometry::parametric_thigh_on_raster(
            &ThighParams {
                element_size_mm: Some(h),
                ..Default::default()
            },
            ElementKind::Cpe4h,
            Some(0.25),
        )
        .unwrap();
        let skin = t.mesh.surfaces["SKIN"].clone();
        let mut deck = contention_deck(&t, &table1_materials(), 0.0).unwrap();
        deck.pressures.clear();
        loaded(
            &Model::from_deck(deck).unwrap(),
            &skin,
            &Loading::seed_contention(),
        )
    };
    let (model, truth) = (mesh(4.0), mesh(2.0));
    let (free, reference) = free_parameters(&model);
    let points = grid(&model, 80, None);
    let outside = points
        .iter()
        .filter(|x| {
            femu_mesh::locate::PointLocator::new(&truth.mesh)
                .locate(**x)
                .is_none()
        })
        .count();
    let blocks = vec![BlockSpec::Field(FieldBlock {
        name: "contention".into(),
        warm: None,
        model: &model,
        coarse: None,
        truth: Some(&truth),
        segments: vec![
            (
                "a".into(),
                Data::Virtual {
                    points: &points[..2000],
                    sigma: 0.01,
                },
            ),
            (
                "b".into(),
                Data::Virtual {
                    points: &points[2000..],
                    sigma: 0.02,
                },
            ),
        ],
        travel: None,
    })];
    let fields = campaign::realized_fields(&model, &free, &reference, &blocks, 1, 0).unwrap();
    let (field, segments) = &fields[0];
    eprintln!(
        "{outside} of {} points outside the finer mesh",
        points.len()
    );
    assert!(
        outside > 0,
        "the case must have points the finer mesh lacks"
    );
    assert_eq!(field.points.len(), points.len() - outside);
    assert_eq!(segments[1].end, field.points.len());
    assert!(field.points[segments[1].clone()]
        .iter()
        .all(|p| p.weight[0] == 1.0 / 0.02f64.powi(2)));
}
