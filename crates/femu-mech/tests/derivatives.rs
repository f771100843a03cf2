//! Every analytic derivative against central finite differences (FEBio's tangent diagnostic):
//! material stress and tangent, element force and stiffness for CPE4, CPE4H and CPE3, and the
//! assembled global tangent including the follower-pressure load stiffness.

use femu_mech::build::DeckBuilder;
use femu_mech::element::{formulation, ElementGeometry, ElementResult};
use femu_mech::material::{Hyperelastic, NeoHookean, Tensor2};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::generate;
use femu_mesh::ElementKind;
use rand::{Rng, SeedableRng};

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// Table 1 quadriceps (C10 = 1.75 kPa, D = 18 MPa^-1) and a stiffer-bulk variant.
fn materials() -> [NeoHookean; 2] {
    [
        NeoHookean::new(1.75e-3, 18.0).unwrap(),
        NeoHookean::new(0.8e-3, 0.5).unwrap(),
    ]
}

fn random_f(rng: &mut impl Rng) -> Tensor2 {
    loop {
        let f = [
            1.0 + rng.gen_range(-0.3..0.3),
            rng.gen_range(-0.3..0.3),
            rng.gen_range(-0.3..0.3),
            1.0 + rng.gen_range(-0.3..0.3),
        ];
        if f[0] * f[3] - f[1] * f[2] > 0.3 {
            return f;
        }
    }
}

/// Relative error of `a` against `b`, scaled by the largest entry of `b`.
fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

#[test]
fn material_stress_and_tangent_match_finite_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    // Central differences with h = 1e-6 on quantities of order C10: truncation ~h², round-off
    // ~1e-16/h, so 1e-7 relative is a safe bound.
    let h = 1e-6;
    let (mut worst_p, mut worst_a) = (0.0f64, 0.0f64);
    for mat in materials() {
        for _ in 0..50 {
            let f = random_f(&mut rng);
            for iso in [false, true] {
                let eval = |f: &Tensor2| {
                    if iso {
                        mat.response_isochoric(f, true)
                    } else {
                        mat.response(f, true)
                    }
                    .unwrap()
                };
                let r = eval(&f);
                let mut p_fd = [0.0; 4];
                let mut a_fd = [[0.0; 4]; 4];
                for b in 0..4 {
                    let mut fp = f;
                    let mut fm = f;
                    fp[b] += h;
                    fm[b] -= h;
                    let (rp, rm) = (eval(&fp), eval(&fm));
                    p_fd[b] = (rp.energy - rm.energy) / (2.0 * h);
                    for a in 0..4 {
                        a_fd[a][b] = (rp.pk1[a] - rm.pk1[a]) / (2.0 * h);
                    }
                }
                worst_p = worst_p.max(rel_err(&r.pk1, &p_fd));
                assert!(
                    rel_err(&r.pk1, &p_fd) < 1e-7,
                    "P vs dW/dF: {:?} {:?}",
                    r.pk1,
                    p_fd
                );
                let a: Vec<f64> = r.tangent.iter().flatten().copied().collect();
                let afd: Vec<f64> = a_fd.iter().flatten().copied().collect();
                worst_a = worst_a.max(rel_err(&a, &afd));
                assert!(rel_err(&a, &afd) < 1e-7, "A vs dP/dF (iso={iso})");
            }
        }
    }
    measure::record(
        "stress P against dW/dF, worst relative error",
        worst_p,
        "< 1e-7",
        "",
    );
    measure::record(
        "tangent A against dP/dF, worst relative error",
        worst_a,
        "< 1e-7",
        "",
    );
}

#[test]
fn element_force_and_stiffness_match_finite_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let h = 1e-7;
    for kind in [ElementKind::Cpe4, ElementKind::Cpe4h, ElementKind::Cpe3] {
        let (mut worst_f, mut worst_k) = (0.0f64, 0.0f64);
        for mat in materials() {
            for _ in 0..20 {
                // A distorted reference element and a moderate random displacement.
                let mut x = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.5], [0.0, 1.5]];
                for p in x.iter_mut() {
                    p[0] += rng.gen_range(-0.25..0.25);
                    p[1] += rng.gen_range(-0.25..0.25);
                }
                let geo = ElementGeometry::new(kind, &x).unwrap();
                let n = geo.n_nodes;
                let nd = 2 * n;
                let mut u = [[0.0; 2]; 4];
                for a in u.iter_mut().take(n) {
                    *a = [rng.gen_range(-0.15..0.15), rng.gen_range(-0.15..0.15)];
                }
                let el = formulation(kind);
                let eval = |u: &[[f64; 2]; 4]| {
                    let mut f = [0.0; 8];
                    let mut k = [0.0; 64];
                    let mut out = ElementResult {
                        energy: 0.0,
                        force: &mut f,
                        stiffness: Some(&mut k),
                    };
                    el.evaluate(&geo, &mat, &u[..n], &mut out).unwrap();
                    (out.energy, f, k)
                };
                let (_, f0, k0) = eval(&u);
                let mut f_fd = vec![0.0; nd];
                let mut k_fd = vec![0.0; nd * nd];
                for c in 0..nd {
                    let mut up = u;
                    let mut um = u;
                    up[c / 2][c % 2] += h;
                    um[c / 2][c % 2] -= h;
                    let (ep, fp, _) = eval(&up);
                    let (em, fm, _) = eval(&um);
                    f_fd[c] = (ep - em) / (2.0 * h);
                    for r in 0..nd {
                        k_fd[r * nd + c] = (fp[r] - fm[r]) / (2.0 * h);
                    }
                }
                worst_f = worst_f.max(rel_err(&f0[..nd], &f_fd));
                worst_k = worst_k.max(rel_err(&k0[..nd * nd], &k_fd));
                assert!(rel_err(&f0[..nd], &f_fd) < 1e-6, "{kind:?}: force vs dΠ/du");
                assert!(
                    rel_err(&k0[..nd * nd], &k_fd) < 1e-6,
                    "{kind:?}: stiffness vs df/du"
                );
                // Energy-derived tangent is symmetric.
                for r in 0..nd {
                    for c in 0..nd {
                        assert!(
                            (k0[r * nd + c] - k0[c * nd + r]).abs()
                                < 1e-12 * k0.iter().fold(0.0f64, |m, v| m.max(v.abs()))
                        );
                    }
                }
            }
        }
        let name = format!("{kind:?}").to_uppercase();
        measure::record(
            &format!("{name} force against dΠ/du, worst relative error"),
            worst_f,
            "< 1e-6",
            "",
        );
        measure::record(
            &format!("{name} stiffness against df/du, worst relative error"),
            worst_k,
            "< 1e-6",
            "",
        );
    }
}

#[test]
fn global_tangent_with_follower_pressure_matches_finite_differences() {
    // A small annulus sector loaded by an outer follower pressure; pressure on the outer surface
    // only, so the load stiffness is unsymmetric near nothing but still checked entry by entry.
    for kind in [ElementKind::Cpe4, ElementKind::Cpe4h] {
        let g = generate::annulus(5.0, 7.0, 9.0, 12, 2, 2, kind);
        let deck = DeckBuilder::new(g)
            .material("INNER_LAYER", 1.75e-3, 18.0)
            .material("OUTER_LAYER", 0.8e-3, 30.8)
            .fix("INNER")
            .pressure("OUTER", 2.666e-3)
            .build();
        let model = Model::from_deck(deck).unwrap();
        let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let n_dof = 2 * model.node_count();
        let mut u = vec![0.0; n_dof];
        for (d, v) in u.iter_mut().enumerate() {
            if solver.equation_of(d).is_some() {
                *v = rng.gen_range(-0.2..0.2);
            }
        }
        solver.assemble_at(&model, &u).unwrap();
        let k = solver.tangent_values().to_vec();
        let pattern = solver.pattern().clone();
        let h = 1e-6;
        let mut max_err = 0.0f64;
        let kmax = k.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for d in 0..n_dof {
            let Some(c) = solver.equation_of(d) else {
                continue;
            };
            let mut up = u.clone();
            up[d] += h;
            let rp = solver.residual_at(&model, &up).unwrap().to_vec();
            let mut um = u.clone();
            um[d] -= h;
            let rm = solver.residual_at(&model, &um).unwrap().to_vec();
            let mut col = vec![0.0; solver.equations()];
            for dd in 0..n_dof {
                if let Some(r) = solver.equation_of(dd) {
                    col[r] = (rp[dd] - rm[dd]) / (2.0 * h);
                }
            }
            for r in 0..solver.equations() {
                let kv = pattern.position(r, c).map_or(0.0, |p| k[p]);
                max_err = max_err.max((kv - col[r]).abs());
            }
        }
        measure::record(
            &format!(
                "{} global tangent with follower pressure, largest error / largest entry",
                format!("{kind:?}").to_uppercase()
            ),
            max_err / kmax,
            "< 1e-6",
            "",
        );
        assert!(
            max_err < 1e-6 * kmax,
            "{kind:?}: global tangent error {max_err:.3e} (max entry {kmax:.3e})"
        );
    }
}
