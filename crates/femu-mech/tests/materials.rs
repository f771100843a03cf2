//! The material registry: every registered law (whatever it is: these tests iterate over
//! [`LAWS`], so a new law is covered by registering it) against finite differences of its own
//! energy — stress and tangent, element force and stiffness through the solver's kernel,
//! parameter rates — its declared small-strain moduli, its deck data line and study keys; then
//! the closed forms of the Mooney–Rivlin and Yeoh laws and the errors a user sees.

use femu_mech::element::{ElementGeometry, ElementResult, MAX_DOFS};
use femu_mech::material::{
    cauchy_from_pk1, law, material_def, material_from_def, material_from_keys, set_from_keys,
    Material, MaterialError, MooneyRivlin, Tensor2, Yeoh, LAWS,
};
use femu_mech::sensitivity::all_parameters;
use femu_mech::Model;
use femu_mesh::{ElementKind, MaterialDef};
use rand::{Rng, SeedableRng};

/// Each registered law at its typical parameters and at a second set (every parameter scaled
/// by 1.7, or moved by 0.7 typical values when its typical value is not positive), both valid.
fn every_law() -> Vec<Box<dyn Material>> {
    let mut laws = Vec::new();
    for entry in LAWS {
        let typical: Vec<f64> = entry.spec.parameters.iter().map(|p| p.typical).collect();
        laws.push(entry.build(&typical).expect("typical values are valid"));
        let other: Vec<f64> = typical
            .iter()
            .map(|&t| if t > 0.0 { 1.7 * t } else { 0.3 * t })
            .collect();
        laws.push(entry.build(&other).expect("the second set is valid"));
    }
    laws
}

fn random_f(rng: &mut impl Rng) -> Tensor2 {
    loop {
        let f = [
            1.0 + rng.gen_range(-0.4..0.4),
            rng.gen_range(-0.4..0.4),
            rng.gen_range(-0.4..0.4),
            1.0 + rng.gen_range(-0.4..0.4),
        ];
        if f[0] * f[3] - f[1] * f[2] > 0.3 {
            return f;
        }
    }
}

/// Largest difference of `a` and `b`, relative to the largest entry of `b`.
fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// P = ∂W/∂F and A = ∂P/∂F by central differences (h = 1e-6 on F of order 1: truncation
/// ~h² ≈ 1e-12, round-off ~1e-16/h ≈ 1e-10 relative, so 1e-7 is a safe bound), whole energy
/// and isochoric part, on random deformations up to 40 % strain.
#[test]
fn stress_and_tangent_of_every_law_match_finite_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    let h = 1e-6;
    for mat in every_law() {
        let name = mat.spec().name;
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
                let (mut p_fd, mut a_fd) = ([0.0; 4], [0.0; 16]);
                for b in 0..4 {
                    let (mut fp, mut fm) = (f, f);
                    fp[b] += h;
                    fm[b] -= h;
                    let (rp, rm) = (eval(&fp), eval(&fm));
                    p_fd[b] = (rp.energy - rm.energy) / (2.0 * h);
                    for a in 0..4 {
                        a_fd[4 * a + b] = (rp.pk1[a] - rm.pk1[a]) / (2.0 * h);
                    }
                }
                assert!(rel_err(&r.pk1, &p_fd) < 1e-7, "{name}: P vs dW/dF");
                let a: Vec<f64> = r.tangent.iter().flatten().copied().collect();
                assert!(rel_err(&a, &a_fd) < 1e-7, "{name}: A vs dP/dF (iso={iso})");
            }
        }
    }
}

/// A distorted reference element of `kind` and a random displacement of up to `amplitude`
/// (the element is about 2 x 1.5), not inverting it.
fn random_element(
    kind: ElementKind,
    amplitude: f64,
    rng: &mut impl Rng,
) -> (ElementGeometry, [[f64; 2]; 4]) {
    let mut x = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.5], [0.0, 1.5]];
    for p in x.iter_mut() {
        p[0] += rng.gen_range(-0.25..0.25);
        p[1] += rng.gen_range(-0.25..0.25);
    }
    let geo = ElementGeometry::new(kind, &x).unwrap();
    loop {
        let mut u = [[0.0; 2]; 4];
        for a in u.iter_mut().take(geo.n_nodes) {
            *a = [
                rng.gen_range(-amplitude..amplitude),
                rng.gen_range(-amplitude..amplitude),
            ];
        }
        let inverted = (0..geo.n_gauss).any(|g| {
            let f = geo.deformation_gradient(g, &u);
            f[0] * f[3] - f[1] * f[2] < 0.3
        });
        if !inverted {
            return (geo, u);
        }
    }
}

/// Energy, force and stiffness of an element through the solver's kernel.
fn element(mat: &dyn Material, geo: &ElementGeometry, u: &[[f64; 2]]) -> (f64, Vec<f64>, Vec<f64>) {
    let (mut f, mut k) = ([0.0; MAX_DOFS], [0.0; MAX_DOFS * MAX_DOFS]);
    let mut out = ElementResult {
        energy: 0.0,
        force: &mut f,
        stiffness: Some(&mut k),
    };
    mat.evaluate_element(geo, &u[..geo.n_nodes], &mut out)
        .unwrap();
    let nd = 2 * geo.n_nodes;
    (out.energy, f[..nd].to_vec(), k[..nd * nd].to_vec())
}

/// Force = ∂Π/∂u and stiffness = ∂f/∂u by central differences (h = 1e-7 on displacements of
/// order 0.1: 1e-6 relative), and a symmetric stiffness, for CPE4, CPE4H and CPE3.
#[test]
fn element_force_and_stiffness_of_every_law_match_finite_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(23);
    let h = 1e-7;
    for mat in every_law() {
        let name = mat.spec().name;
        for kind in [ElementKind::Cpe4, ElementKind::Cpe4h, ElementKind::Cpe3] {
            for _ in 0..10 {
                let (geo, u) = random_element(kind, 0.25, &mut rng);
                let nd = 2 * geo.n_nodes;
                let (_, f0, k0) = element(&*mat, &geo, &u);
                let (mut f_fd, mut k_fd) = (vec![0.0; nd], vec![0.0; nd * nd]);
                for c in 0..nd {
                    let (mut up, mut um) = (u, u);
                    up[c / 2][c % 2] += h;
                    um[c / 2][c % 2] -= h;
                    let (ep, fp, _) = element(&*mat, &geo, &up);
                    let (em, fm, _) = element(&*mat, &geo, &um);
                    f_fd[c] = (ep - em) / (2.0 * h);
                    for r in 0..nd {
                        k_fd[r * nd + c] = (fp[r] - fm[r]) / (2.0 * h);
                    }
                }
                assert!(rel_err(&f0, &f_fd) < 1e-6, "{name} {kind:?}: force");
                assert!(rel_err(&k0, &k_fd) < 1e-6, "{name} {kind:?}: stiffness");
                let kmax = k0.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for r in 0..nd {
                    for c in 0..nd {
                        assert!((k0[r * nd + c] - k0[c * nd + r]).abs() < 1e-12 * kmax);
                    }
                }
            }
        }
    }
}

/// `∂f_e/∂θ_k` ([`Material::rate_forces`]) against central differences of the element force in
/// θ_k, for every parameter of every law and every element type. The force is linear in the
/// C's (no truncation error) and in 1/D: the fourth-order stencil with a step of 1e-2 of the
/// parameter's size leaves ~1e-8 truncation for D. The displacements reach half the element's
/// size (strains up to about 50 %, elements kept uninverted) so that the weakest term (C30,
/// cubic in I1bar - 3) moves the force well above round-off: with displacements of a quarter
/// it did not (errors up to 1.3e-7 on a C30 rate of 1e-6). This also checks each parameter's
/// declared energy part, which the CPE4H rate uses.
#[test]
fn parameter_rates_of_every_law_match_finite_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(29);
    for mat in every_law() {
        let name = mat.spec().name;
        let count = mat.spec().parameters.len();
        for kind in [ElementKind::Cpe4, ElementKind::Cpe4h, ElementKind::Cpe3] {
            for _ in 0..5 {
                // Large enough for the cubic Yeoh term (see above).
                let (geo, u) = random_element(kind, 0.5, &mut rng);
                let nd = 2 * geo.n_nodes;
                let mut rates = vec![f64::NAN; count * MAX_DOFS];
                mat.rate_forces(&geo, &u[..geo.n_nodes], &mut rates)
                    .unwrap();
                for k in 0..count {
                    let theta = mat.parameter(k);
                    let size = mat.spec().parameters[k].typical.abs();
                    let step = 1e-2 * theta.abs().max(size);
                    let mut moved = mat.clone();
                    let mut force_at = |s: f64| {
                        moved.set_parameter(k, theta + s * step);
                        element(&*moved, &geo, &u).1
                    };
                    let (f1, f_1, f2, f_2) =
                        (force_at(1.0), force_at(-1.0), force_at(2.0), force_at(-2.0));
                    let fd: Vec<f64> = (0..nd)
                        .map(|r| (8.0 * (f1[r] - f_1[r]) - (f2[r] - f_2[r])) / (12.0 * step))
                        .collect();
                    let got = &rates[k * MAX_DOFS..k * MAX_DOFS + nd];
                    let p = mat.spec().parameters[k].name;
                    assert!(
                        rel_err(got, &fd) < 1e-7,
                        "{name} {kind:?} {p}: {got:?} vs {fd:?}"
                    );
                }
            }
        }
    }
}

/// The reference is stress-free, and the small-strain response is the declared moduli: simple
/// shear γ = 1e-6 gives σxy = μ γ, equibiaxial in-plane strain e = 1e-7 (plane strain: volume
/// strain 2e) gives the mean stress K · 2e (relative 1e-5: second-order terms ~γ, e).
#[test]
fn every_law_has_its_declared_small_strain_moduli() {
    for mat in every_law() {
        let name = mat.spec().name;
        let r = mat.response(&[1.0, 0.0, 0.0, 1.0], true).unwrap();
        assert!(r.energy.abs() < 1e-15, "{name}");
        assert!(r.pk1.iter().all(|v| v.abs() < 1e-15), "{name}");
        assert!(r.tau33.abs() < 1e-15, "{name}");
        let g = 1e-6;
        let f = [1.0, g, 0.0, 1.0];
        let r = mat.response(&f, false).unwrap();
        let s = cauchy_from_pk1(&f, &r.pk1, r.tau33);
        let mu = mat.shear_modulus();
        assert!(
            (s[3] / g - mu).abs() < 1e-5 * mu,
            "{name}: μ {} vs {mu}",
            s[3] / g
        );
        let e = 1e-7;
        let f = [1.0 + e, 0.0, 0.0, 1.0 + e];
        let r = mat.response(&f, false).unwrap();
        let s = cauchy_from_pk1(&f, &r.pk1, r.tau33);
        let p = (s[0] + s[1] + s[2]) / 3.0;
        let k = mat.bulk_modulus();
        assert!((p / (2.0 * e) - k).abs() < 1e-5 * k, "{name}: K");
    }
}

/// The closed forms of the small-strain moduli: μ = 2 (C10 + C01) for Mooney–Rivlin, 2 C10 for
/// Yeoh (whatever C20, C30), K = 2/D.
#[test]
fn mooney_rivlin_and_yeoh_moduli() {
    let mr = MooneyRivlin {
        c10: 1.1e-3,
        c01: 0.4e-3,
        d: 20.0,
    };
    assert_eq!(mr.shear_modulus(), 2.0 * (1.1e-3 + 0.4e-3));
    assert_eq!(mr.bulk_modulus(), 2.0 / 20.0);
    let yeoh = Yeoh {
        c10: 1.1e-3,
        c20: -0.2e-3,
        c30: 0.3e-3,
        d: 20.0,
    };
    assert_eq!(yeoh.shear_modulus(), 2.0 * 1.1e-3);
    assert_eq!(yeoh.bulk_modulus(), 2.0 / 20.0);
    // The measured moduli are those (as in the generic test, on these values).
    for mat in [&mr as &dyn Material, &yeoh] {
        let g = 1e-6;
        let f = [1.0, g, 0.0, 1.0];
        let r = mat.response(&f, false).unwrap();
        let s = cauchy_from_pk1(&f, &r.pk1, r.tau33);
        assert!((s[3] / g - mat.shear_modulus()).abs() < 1e-5 * mat.shear_modulus());
    }
}

/// Deck form: the registry's data line is read back as the same material; left-out trailing
/// constants read as 0 (Yeoh's D2, D3); Abaqus keywords match whatever the case and blanks.
#[test]
fn deck_data_lines_round_trip() {
    for mat in every_law() {
        let def = material_def("TISSUE", &*mat);
        assert_eq!(def.keyword, mat.spec().abaqus_keyword);
        assert_eq!(def.constants.len(), mat.spec().abaqus_fields.len());
        let back = material_from_def(&def).unwrap();
        assert!(*back == *mat, "{}", mat.spec().name);
        let squashed = MaterialDef {
            keyword: def.keyword.to_ascii_lowercase().replace(' ', ""),
            ..def.clone()
        };
        assert!(*material_from_def(&squashed).unwrap() == *mat);
    }
    let yeoh = MaterialDef {
        name: "FAT".into(),
        keyword: "YEOH".into(),
        constants: vec![1e-3, -0.1e-3, 0.2e-3, 30.0],
        line: Some(7),
    };
    let m = material_from_def(&yeoh).unwrap();
    assert_eq!(m.parameters(), vec![1e-3, -0.1e-3, 0.2e-3, 30.0]);
}

fn def(keyword: &str, constants: &[f64]) -> MaterialDef {
    MaterialDef {
        name: "FAT".into(),
        keyword: keyword.into(),
        constants: constants.to_vec(),
        line: Some(12),
    }
}

/// What a user sees for a bad deck material: the law, the constant and what is valid.
#[test]
fn deck_material_errors_say_what_is_valid() {
    let err = |d: MaterialDef| material_from_def(&d).unwrap_err().to_string();
    let e = err(def("OGDEN", &[1.0, 2.0]));
    assert!(
        e.contains("OGDEN") && e.contains("NEO HOOKE, MOONEY-RIVLIN, YEOH"),
        "{e}"
    );
    let e = err(def("YEOH", &[1e-3, 0.0, 0.0, 30.0, 0.5, 0.0]));
    assert!(e.contains("D2 = 0.5 is not supported"), "{e}");
    let e = err(def("MOONEY-RIVLIN", &[1e-3, 1e-3, 1.0, 0.0]));
    assert!(
        e.contains("4 constants") && e.contains("C10, C01, D1"),
        "{e}"
    );
    let e = err(def("NEO HOOKE", &[-1e-3, 1.0]));
    assert!(
        e.contains("C10 = -0.001 MPa is out of range: it must be > 0"),
        "{e}"
    );
    let e = err(def("NEO HOOKE", &[1e-3]));
    assert!(
        e.contains("D1 = 0 (or left out)") && e.contains("incompressible"),
        "{e}"
    );
    let e = err(def("MOONEY-RIVLIN", &[1e-3, -1e-4, 1.0]));
    assert!(
        e.contains("C01 = -0.0001 MPa is out of range: it must be ≥ 0"),
        "{e}"
    );
    let e = err(def("YEOH", &[1e-3, -1e-3, 0.0, 30.0]));
    assert!(e.contains("C20²"), "{e}");
    // Through a model: the material's name and its deck line.
    let text = std::fs::read_to_string(deck_path()).unwrap();
    let bad = text.replace("0.0008, 30.8", "0.0008, 0");
    let deck = femu_mesh::inp::parse_inp(&bad, "two.inp").unwrap();
    let e = Model::from_deck(deck).unwrap_err().to_string();
    assert!(
        e.starts_with(
            "material 'FAT' (deck line 21): D1 = 0 MPa⁻¹ is out of range: it must be ≥ 0.000001"
        ),
        "{e}"
    );
}

fn deck_path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/three_laws.inp")
}

/// Study-file keys: every unit suffix of every parameter gives the same material; errors name
/// the key and the valid keys.
#[test]
fn study_keys_build_materials() {
    let a = material_from_keys(
        "mooney-rivlin",
        [("c10_kpa", 1.0), ("c01_kpa", 0.75), ("d_per_mpa", 18.0)],
    )
    .unwrap();
    let b = material_from_keys(
        "Mooney_Rivlin",
        [
            ("C10_MPA", 1e-3),
            ("c01_mpa", 0.75e-3),
            ("d_per_kpa", 0.018),
        ],
    )
    .unwrap();
    assert_eq!(a.spec().name, "mooney-rivlin");
    for k in 0..3 {
        assert!((a.parameter(k) - b.parameter(k)).abs() <= 1e-15 * a.parameter(k));
    }
    for entry in LAWS {
        // Every parameter by its first key, at its typical value.
        let keys: Vec<(String, f64)> = entry
            .spec
            .parameters
            .iter()
            .map(|p| {
                let (suffix, factor) = p.unit.key_suffixes()[0];
                (
                    format!("{}_{suffix}", p.name.to_ascii_lowercase()),
                    p.typical / factor,
                )
            })
            .collect();
        let m = material_from_keys(entry.spec.name, keys.iter().map(|(k, v)| (k.as_str(), *v)))
            .unwrap();
        for (k, p) in entry.spec.parameters.iter().enumerate() {
            assert!((m.parameter(k) - p.typical).abs() <= 1e-15 * p.typical.abs());
        }
    }
    let err = |law: &str, keys: &[(&str, f64)]| {
        material_from_keys(law, keys.iter().copied())
            .unwrap_err()
            .to_string()
    };
    let e = err("ogden", &[]);
    assert_eq!(
        e,
        "unknown material law 'ogden' (registered: neo-hookean, mooney-rivlin, yeoh)"
    );
    let e = err("yeoh", &[("c10_kpa", 1.0), ("c02_kpa", 1.0)]);
    assert!(
        e.starts_with("'c02_kpa' is not a parameter key of the yeoh law (valid keys: c10_kpa, c10_mpa, c20_kpa, c20_mpa, c30_kpa, c30_mpa, d_per_mpa, d_per_kpa)"),
        "{e}"
    );
    let e = err("neo-hookean", &[("c10_kpa", 1.0)]);
    assert_eq!(
        e,
        "the neo-hookean law needs D: give one of d_per_mpa or d_per_kpa"
    );
    let e = err("neo-hookean", &[("c10_kpa", 1.0), ("c10_mpa", 1e-3)]);
    assert!(
        e.contains("C10 is given twice (c10_kpa and c10_mpa)"),
        "{e}"
    );
    let e = err("neo-hookean", &[("c10_kpa", -0.8), ("d_per_mpa", 30.0)]);
    assert!(
        e.starts_with("c10_kpa = -0.8 is out of range: it must be > 0"),
        "{e}"
    );
    // Overrides keep the other parameters and leave the material unchanged on error.
    let mut m = a.clone();
    set_from_keys(&mut *m, [("c01_kpa", 0.5)]).unwrap();
    assert_eq!(m.parameters(), vec![1e-3, 0.5e-3, 18.0]);
    let before = m.parameters();
    let e = set_from_keys(&mut *m, [("c01_kpa", 0.1), ("d_per_mpa", -1.0)]).unwrap_err();
    assert!(matches!(e, MaterialError::OutOfRange { .. }));
    assert_eq!(m.parameters(), before);
    assert_eq!(law("NEO-HOOKEAN").unwrap().spec.abaqus_keyword, "NEO HOOKE");
}

/// The parameters of a model with one material of each law: every registered parameter, in
/// material order and each law's order, named `<parameter>_<material>`.
#[test]
fn parameters_of_a_three_law_model() {
    let deck = femu_mesh::read_inp(&deck_path()).unwrap();
    let model = Model::from_deck(deck).unwrap();
    let names: Vec<String> = all_parameters(&model)
        .iter()
        .map(|p| p.name(&model))
        .collect();
    assert_eq!(
        names,
        [
            "C10_FAT",
            "D_FAT",
            "C10_MUSCLE",
            "C01_MUSCLE",
            "D_MUSCLE",
            "C10_TENDON",
            "C20_TENDON",
            "C30_TENDON",
            "D_TENDON"
        ]
    );
    let p = all_parameters(&model)[6];
    assert_eq!(p.spec().name, "C20");
    assert_eq!(p.value(&model), -0.2e-3);
    assert_eq!(
        serde_json::to_string(&p).unwrap(),
        r#"{"material":2,"kind":"C20"}"#
    );
}
