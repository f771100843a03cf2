//! Checks of the 3D solid elements (C3D8, C3D8H, C3D4, C3D10) with the registered laws:
//! tangents, forces and parameter forces against central finite differences, the plane-strain
//! restriction of the 3D law against the 2D one, patch tests on distorted meshes, and
//! homogeneous finite deformations against the closed-form Neo-Hookean Cauchy stress.
//!
//! The meshes here are solved by a small dense Newton written in this file (a few hundred dofs
//! at most), so that the checks depend on the element kernels only.

use femu_mech::element::ElementResult;
use femu_mech::material::{
    cauchy_3d, det3, Hyperelastic, Material, MaterialLaw, MooneyRivlin, NeoHookean, Yeoh, LAWS,
};
use femu_mech::solid3d::{self, Geometry3, Kind3, MAX_DOFS_3D};
use rand::{Rng, SeedableRng};
use std::collections::HashMap;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// The largest value of each label (first-seen order), for the guide's recorded values.
fn keep_worst(acc: &mut Vec<(String, f64)>, label: String, value: f64) {
    match acc.iter_mut().find(|(l, _)| *l == label) {
        Some((_, w)) => *w = w.max(value),
        None => acc.push((label, value)),
    }
}

/// Energy, force and dense tangent of one element.
fn evaluate<M: Hyperelastic + ?Sized>(
    geo: &Geometry3,
    mat: &M,
    u: &[[f64; 3]],
) -> (f64, Vec<f64>, Vec<f64>) {
    let nd = 3 * geo.n_nodes;
    let (mut force, mut k) = (vec![0.0; nd], vec![0.0; nd * nd]);
    let mut out = ElementResult {
        energy: 0.0,
        force: &mut force,
        stiffness: Some(&mut k),
    };
    solid3d::evaluate(geo, mat, u, &mut out).expect("a valid deformation");
    (out.energy, force, k)
}

/// A distorted reference element of each type (edge length about 1 mm; the C3D10 mid-edge
/// nodes off the straight edges, so that its map is curved).
fn reference_element(kind: Kind3) -> Vec<[f64; 3]> {
    let tet = [
        [0.0, 0.0, 0.0],
        [1.1, 0.1, -0.05],
        [0.2, 1.0, 0.1],
        [0.1, 0.2, 0.9],
    ];
    match kind {
        Kind3::C3d8 | Kind3::C3d8h => {
            let offsets = [
                [0.02, -0.03, 0.01],
                [0.1, 0.05, -0.04],
                [0.15, 0.1, 0.03],
                [-0.05, 0.08, 0.0],
                [0.04, 0.0, 0.1],
                [0.07, -0.06, 0.2],
                [0.12, 0.14, 0.05],
                [-0.1, 0.02, 0.12],
            ];
            solid3d::shape::HEX_CORNERS
                .iter()
                .zip(offsets)
                .map(|(c, o)| std::array::from_fn(|r| 0.5 * (c[r] + 1.0) + o[r]))
                .collect()
        }
        Kind3::C3d4 => tet.to_vec(),
        Kind3::C3d10 => {
            let mut x = tet.to_vec();
            let bumps = [0.03, -0.02, 0.025, -0.03, 0.02, 0.015];
            for ([i, j], b) in solid3d::shape::TET10_EDGES.iter().zip(bumps) {
                x.push(std::array::from_fn(|r| 0.5 * (tet[*i][r] + tet[*j][r]) + b));
            }
            x
        }
    }
}

/// Random nodal displacements of size up to `scale` (seeded).
fn random_displacements(n: usize, scale: f64, rng: &mut impl Rng) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| std::array::from_fn(|_| scale * rng.gen_range(-1.0..1.0)))
        .collect()
}

/// Random nodal displacements as [`random_displacements`], drawn again until J lies in
/// `[0.5, 2]` at every Gauss point: finite strains, away from the near-inverted states where
/// the forces grow without bound and differences of them lose every digit.
fn random_state(geo: &Geometry3, scale: f64, rng: &mut impl Rng) -> Vec<[f64; 3]> {
    loop {
        let u = random_displacements(geo.n_nodes, scale, rng);
        let fine = (0..geo.n_gauss).all(|g| {
            let j = det3(&geo.deformation_gradient(g, &u));
            (0.5..=2.0).contains(&j)
        });
        if fine {
            return u;
        }
    }
}

/// Every registered law at its typical parameters.
fn registered_laws() -> Vec<Box<dyn Material>> {
    LAWS.iter()
        .map(|entry| {
            let typical: Vec<f64> = entry.spec.parameters.iter().map(|p| p.typical).collect();
            entry.build(&typical).unwrap()
        })
        .collect()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

// Central differences of step h (relative to the element size 1 mm or to the parameter) have a
// truncation error of order h² |f'''| ≈ 1e-12 relative and a round-off error of order
// ε |f| / h ≈ 1e-10 relative at h = 1e-6; 1e-6 leaves room for both.
const FD_STEP: f64 = 1e-6;
const FD_TOLERANCE: f64 = 1e-6;

/// The tangent is the derivative of the force (and symmetric), for every element type and
/// every registered law, at random finite deformations (up to 30 % strains).
#[test]
fn tangent_is_the_derivative_of_the_force() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(31);
    let mut recorded = Vec::new();
    for law in registered_laws() {
        for kind in Kind3::ALL {
            let geo = Geometry3::new(kind, &reference_element(kind)).unwrap();
            let nd = 3 * geo.n_nodes;
            for _ in 0..3 {
                let u = random_state(&geo, 0.15, &mut rng);
                let (_, _, k) = evaluate(&geo, &*law, &u);
                let scale = max_abs(&k);
                let mut worst = 0.0f64;
                for c in 0..nd {
                    let (mut up, mut um) = (u.clone(), u.clone());
                    up[c / 3][c % 3] += FD_STEP;
                    um[c / 3][c % 3] -= FD_STEP;
                    let (_, fp, _) = evaluate(&geo, &*law, &up);
                    let (_, fm, _) = evaluate(&geo, &*law, &um);
                    for r in 0..nd {
                        let fd = (fp[r] - fm[r]) / (2.0 * FD_STEP);
                        worst = worst.max((fd - k[r * nd + c]).abs() / scale);
                    }
                }
                let name = law.spec().name;
                println!("{name} {kind:?}: tangent vs FD {worst:.1e}");
                keep_worst(&mut recorded, kind.abaqus_name().to_string(), worst);
                assert!(
                    worst < FD_TOLERANCE,
                    "{name} {kind:?}: tangent vs FD {worst:e}"
                );
                for r in 0..nd {
                    for c in 0..r {
                        let d = (k[r * nd + c] - k[c * nd + r]).abs();
                        assert!(d <= 1e-12 * scale, "{name} {kind:?}: K not symmetric");
                    }
                }
            }
        }
    }
    for (kind, worst) in recorded {
        measure::record(
            &format!("{kind} tangent against finite differences of the force, worst over the laws, / largest entry"),
            worst,
            "< 1e-6",
            "",
        );
    }
}

/// The force is the derivative of the energy, for every element type and law.
#[test]
fn force_is_the_derivative_of_the_energy() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(32);
    let mut recorded = Vec::new();
    for law in registered_laws() {
        for kind in Kind3::ALL {
            let geo = Geometry3::new(kind, &reference_element(kind)).unwrap();
            let nd = 3 * geo.n_nodes;
            let u = random_state(&geo, 0.15, &mut rng);
            let (_, f, _) = evaluate(&geo, &*law, &u);
            let scale = max_abs(&f);
            assert!(scale > 0.0);
            let mut worst = 0.0f64;
            for c in 0..nd {
                let (mut up, mut um) = (u.clone(), u.clone());
                up[c / 3][c % 3] += FD_STEP;
                um[c / 3][c % 3] -= FD_STEP;
                let fd =
                    (evaluate(&geo, &*law, &up).0 - evaluate(&geo, &*law, &um).0) / (2.0 * FD_STEP);
                let err = (fd - f[c]).abs() / scale;
                worst = worst.max(err);
                let name = law.spec().name;
                assert!(
                    err < FD_TOLERANCE,
                    "{name} {kind:?} dof {c}: {fd} vs {}",
                    f[c]
                );
            }
            println!(
                "{} {kind:?}: force vs FD of the energy {worst:.1e}",
                law.spec().name
            );
            keep_worst(&mut recorded, kind.abaqus_name().to_string(), worst);
        }
    }
    for (kind, worst) in recorded {
        measure::record(
            &format!("{kind} force against finite differences of the energy, worst over the laws, / largest entry"),
            worst,
            "< 1e-6",
            "",
        );
    }
}

/// The parameter forces (`∂f/∂θ_k` from the unit energies) are the derivative of the force in
/// each parameter, for every element type and law.
#[test]
fn parameter_forces_are_the_derivative_of_the_force() {
    fn check<L: MaterialLaw>(rng: &mut impl Rng) {
        let mut recorded = Vec::new();
        let typical: Vec<f64> = L::SPEC.parameters.iter().map(|p| p.typical).collect();
        let law = L::with_parameters(&typical);
        for kind in Kind3::ALL {
            let geo = Geometry3::new(kind, &reference_element(kind)).unwrap();
            let nd = 3 * geo.n_nodes;
            // Large enough for the Yeoh law's cubic term (I1bar - 3 of order 0.1).
            let u = random_state(&geo, 0.2, rng);
            let count = L::SPEC.parameters.len();
            let mut rates = vec![0.0; count * MAX_DOFS_3D];
            solid3d::rate_forces(&law, &geo, &u, &mut rates).unwrap();
            for k in 0..count {
                let theta = law.parameter_value(k);
                // The force is linear in each coefficient (C10, C01, C20, C30) and in 1/D, so
                // the truncation error is nil or of order (h/D)² = 1e-8, while the round-off
                // (ε |f| / h) asks for a step larger than FD_STEP.
                let h = 1e-4 * theta.abs().max(1e-3);
                let (mut lp, mut lm) = (law, law);
                *lp.parameter_value_mut(k) += h;
                *lm.parameter_value_mut(k) -= h;
                let (fp, fm) = (evaluate(&geo, &lp, &u).1, evaluate(&geo, &lm, &u).1);
                let got = &rates[k * MAX_DOFS_3D..k * MAX_DOFS_3D + nd];
                let scale = max_abs(got);
                assert!(scale > 0.0, "{} {kind:?} parameter {k}", L::SPEC.name);
                let worst = (0..nd)
                    .map(|r| ((fp[r] - fm[r]) / (2.0 * h) - got[r]).abs() / scale)
                    .fold(0.0, f64::max);
                println!("{} {kind:?} parameter {k}: vs FD {worst:.1e}", L::SPEC.name);
                keep_worst(&mut recorded, String::new(), worst);
                for r in 0..nd {
                    let fd = (fp[r] - fm[r]) / (2.0 * h);
                    assert!(
                        (fd - got[r]).abs() < FD_TOLERANCE * scale,
                        "{} {kind:?} parameter {k} dof {r}: {fd} vs {}",
                        L::SPEC.name,
                        got[r]
                    );
                }
            }
        }
        measure::record(
            &format!("{} parameter forces against finite differences of the force, worst over the parameters and element types, / largest entry", L::SPEC.name),
            recorded[0].1,
            "< 1e-6",
            "",
        );
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(33);
    check::<NeoHookean>(&mut rng);
    check::<MooneyRivlin>(&mut rng);
    check::<Yeoh>(&mut rng);
}

/// The 3D law restricted to plane strain (`F33 = 1`, no out-of-plane shear) is the 2D law of
/// the plane-strain elements: energy, in-plane P, `P33 = τ33` and the in-plane tangent, for
/// every registered law (Mooney–Rivlin through its 3D `I2`, the others through `(I1, J)`).
#[test]
fn plane_strain_restriction_is_the_2d_law() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(34);
    for law in registered_laws() {
        for _ in 0..50 {
            let f2: [f64; 4] = [
                1.0 + rng.gen_range(-0.3..0.3),
                rng.gen_range(-0.3..0.3),
                rng.gen_range(-0.3..0.3),
                1.0 + rng.gen_range(-0.3..0.3),
            ];
            let f3 = [f2[0], f2[1], 0.0, f2[2], f2[3], 0.0, 0.0, 0.0, 1.0];
            let r2 = law.response(&f2, true).unwrap();
            let d3 = law.derivatives_3d(&f3).unwrap();
            let p3 = femu_mech::material::pk1_3d(&f3, &d3);
            let a3 = femu_mech::material::tangent_3d(&f3, &d3);
            let name = law.spec().name;
            // The same quantities by different sums: round-off of the largest term.
            let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-13 * scale;
            assert!(
                close(d3.w, r2.energy, r2.energy.abs().max(1e-6)),
                "{name} W"
            );
            let in_plane = [0, 1, 3, 4];
            let ps = max_abs(&r2.pk1).max(r2.tau33.abs());
            for (a, &r) in in_plane.iter().enumerate() {
                assert!(close(p3[r], r2.pk1[a], ps), "{name} P {r}");
            }
            // P33 = τ33 (F33 = 1), Mooney–Rivlin's through the I2 term the plane-strain
            // identity I2 = J² + I1 - 1 misses (Hyperelastic::plane_strain_i2_tau33).
            let tau33 = r2.tau33;
            assert!(close(p3[8], tau33, ps), "{name} P33: {} vs {tau33}", p3[8]);
            assert!(p3[2].abs() + p3[5].abs() + p3[6].abs() + p3[7].abs() <= 1e-13 * ps);
            let ts = r2
                .tangent
                .iter()
                .flatten()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            for (a, &r) in in_plane.iter().enumerate() {
                for (b, &c) in in_plane.iter().enumerate() {
                    assert!(close(a3[r][c], r2.tangent[a][b], ts), "{name} A {r} {c}");
                }
            }
        }
    }
}

/// The 3D Mooney–Rivlin energy at a general F against `I2 = ½ (I1² - tr C²)` computed here,
/// and with C01 = 0 the Neo-Hookean one.
#[test]
fn mooney_rivlin_uses_the_second_invariant_in_3d() {
    let mr = MooneyRivlin {
        c10: 1.0e-3,
        c01: 0.75e-3,
        d: 18.0,
    };
    let f = [1.2, 0.1, -0.05, 0.08, 0.9, 0.12, -0.1, 0.03, 1.1];
    let c: [f64; 9] =
        std::array::from_fn(|r| (0..3).map(|m| f[3 * m + r / 3] * f[3 * m + r % 3]).sum());
    let i1 = c[0] + c[4] + c[8];
    let i2 = 0.5 * (i1 * i1 - c.iter().map(|v| v * v).sum::<f64>());
    let j = det3(&f);
    let want = mr.c10 * (j.powf(-2.0 / 3.0) * i1 - 3.0)
        + mr.c01 * (j.powf(-4.0 / 3.0) * i2 - 3.0)
        + (j - 1.0).powi(2) / mr.d;
    let got = mr.derivatives_3d(&f).unwrap().w;
    assert!((got - want).abs() < 1e-15, "{got} vs {want}");
    let nh = NeoHookean {
        c10: 1.0e-3,
        d: 18.0,
    };
    let mr0 = MooneyRivlin { c01: 0.0, ..mr };
    let (a, b) = (
        mr0.derivatives_3d(&f).unwrap(),
        nh.derivatives_3d(&f).unwrap(),
    );
    assert!((a.w - b.w).abs() < 1e-17 && (a.w_j - b.w_j).abs() < 1e-17);
}

/// A mesh of 3D elements.
struct Mesh {
    nodes: Vec<[f64; 3]>,
    elements: Vec<(Kind3, Vec<usize>)>,
}

/// The `n³` grid of hexahedra on `[0, l]³`, interior grid nodes moved by up to `distortion`
/// times the spacing (seeded).
fn hex_mesh(n: usize, l: f64, kind: Kind3, distortion: f64, seed: u64) -> Mesh {
    let nodes = grid_nodes(n, l, distortion, seed);
    let id = |i: usize, j: usize, k: usize| i + (n + 1) * (j + (n + 1) * k);
    let mut elements = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let c = solid3d::shape::HEX_CORNERS;
                let conn = c
                    .iter()
                    .map(|s| {
                        let o = s.map(|v| usize::from(v > 0.0));
                        id(i + o[0], j + o[1], k + o[2])
                    })
                    .collect();
                elements.push((kind, conn));
            }
        }
    }
    Mesh { nodes, elements }
}

fn grid_nodes(n: usize, l: f64, distortion: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let h = l / n as f64;
    let mut nodes = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                let interior = [i, j, k].iter().all(|&v| v > 0 && v < n);
                let mut x = [i as f64 * h, j as f64 * h, k as f64 * h];
                if interior {
                    for v in &mut x {
                        *v += distortion * h * rng.gen_range(-1.0..1.0);
                    }
                }
                nodes.push(x);
            }
        }
    }
    nodes
}

/// The `n³` grid on `[0, l]³`, each cube split into the six tetrahedra of its main diagonal
/// (Kuhn's split, conforming across cubes), interior grid nodes moved as in [`hex_mesh`]; C3D10
/// with its mid-edge nodes on the straight edges.
fn tet_mesh(n: usize, l: f64, kind: Kind3, distortion: f64, seed: u64) -> Mesh {
    let mut nodes = grid_nodes(n, l, distortion, seed);
    let id = |i: usize, j: usize, k: usize| i + (n + 1) * (j + (n + 1) * k);
    let paths = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut elements = Vec::new();
    let mut edges: HashMap<(usize, usize), usize> = HashMap::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                for path in paths {
                    let mut o = [0; 3];
                    let mut conn = vec![id(i, j, k)];
                    for axis in path {
                        o[axis] = 1;
                        conn.push(id(i + o[0], j + o[1], k + o[2]));
                    }
                    let x: Vec<[f64; 3]> = conn.iter().map(|&a| nodes[a]).collect();
                    let e = |a: usize| -> [f64; 3] { std::array::from_fn(|r| x[a][r] - x[0][r]) };
                    let m = [e(1), e(2), e(3)];
                    let volume6 = det3(&[
                        m[0][0], m[1][0], m[2][0], m[0][1], m[1][1], m[2][1], m[0][2], m[1][2],
                        m[2][2],
                    ]);
                    if volume6 < 0.0 {
                        conn.swap(1, 2);
                    }
                    if kind == Kind3::C3d10 {
                        for [a, b] in solid3d::shape::TET10_EDGES {
                            let key = (conn[a].min(conn[b]), conn[a].max(conn[b]));
                            let mid = *edges.entry(key).or_insert_with(|| {
                                let (p, q) = (nodes[key.0], nodes[key.1]);
                                nodes.push(std::array::from_fn(|r| 0.5 * (p[r] + q[r])));
                                nodes.len() - 1
                            });
                            conn.push(mid);
                        }
                    }
                    elements.push((kind, conn));
                }
            }
        }
    }
    Mesh { nodes, elements }
}

/// Internal force and dense tangent of a mesh at displacements `u`.
fn assemble<M: Hyperelastic + ?Sized>(
    mesh: &Mesh,
    geos: &[Geometry3],
    mat: &M,
    u: &[[f64; 3]],
) -> (Vec<f64>, Vec<f64>) {
    let n = 3 * mesh.nodes.len();
    let (mut force, mut k) = (vec![0.0; n], vec![0.0; n * n]);
    for ((_, conn), geo) in mesh.elements.iter().zip(geos) {
        let ue: Vec<[f64; 3]> = conn.iter().map(|&a| u[a]).collect();
        let (_, fe, ke) = evaluate(geo, mat, &ue);
        let nd = 3 * conn.len();
        let dof = |r: usize| 3 * conn[r / 3] + r % 3;
        for r in 0..nd {
            force[dof(r)] += fe[r];
            for c in 0..nd {
                k[dof(r) * n + dof(c)] += ke[r * nd + c];
            }
        }
    }
    (force, k)
}

/// Solves `A x = b` (dense, partial pivoting).
fn dense_solve(mut a: Vec<f64>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&p, &q| a[p * n + col].abs().total_cmp(&a[q * n + col].abs()))
            .unwrap();
        if pivot != col {
            for c in 0..n {
                a.swap(pivot * n + c, col * n + c);
            }
            b.swap(pivot, col);
        }
        let d = a[col * n + col];
        for r in col + 1..n {
            let m = a[r * n + col] / d;
            if m != 0.0 {
                for c in col..n {
                    a[r * n + c] -= m * a[col * n + c];
                }
                b[r] -= m * b[col];
            }
        }
    }
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|c| a[r * n + c] * b[c]).sum();
        b[r] = (b[r] - s) / a[r * n + r];
    }
    b
}

/// Newton on the free dofs (`free[dof]`) with no external load: the free nodes in equilibrium
/// with the prescribed displacements of the others. Returns the internal force (the
/// reactions at the fixed dofs) at convergence.
fn solve<M: Hyperelastic + ?Sized>(
    mesh: &Mesh,
    mat: &M,
    u: &mut [[f64; 3]],
    free: &[bool],
) -> Vec<f64> {
    let geos: Vec<Geometry3> = mesh
        .elements
        .iter()
        .map(|(kind, conn)| {
            let x: Vec<[f64; 3]> = conn.iter().map(|&a| mesh.nodes[a]).collect();
            Geometry3::new(*kind, &x).unwrap()
        })
        .collect();
    let map: Vec<usize> = (0..free.len()).filter(|&d| free[d]).collect();
    let n = free.len();
    let mut reference = 0.0;
    for iteration in 0..30 {
        let (force, k) = assemble(mesh, &geos, mat, u);
        reference = f64::max(reference, max_abs(&force));
        let residual: Vec<f64> = map.iter().map(|&d| -force[d]).collect();
        // Round-off of the assembled forces: ε times the largest force, times a few hundred
        // terms summed.
        if max_abs(&residual) <= 1e-13 * reference {
            return force;
        }
        let kf: Vec<f64> = map
            .iter()
            .flat_map(|&r| map.iter().map(move |&c| (r, c)))
            .map(|(r, c)| k[r * n + c])
            .collect();
        let du = dense_solve(kf, residual);
        for (&d, v) in map.iter().zip(du) {
            u[d / 3][d % 3] += v;
        }
        assert!(iteration < 29, "Newton did not converge");
    }
    unreachable!()
}

fn on_boundary(x: &[f64; 3], l: f64) -> bool {
    x.iter().any(|&v| v.abs() < 1e-12 || (v - l).abs() < 1e-12)
}

/// The Cauchy stress of the law at a homogeneous F.
fn stress_at<M: Hyperelastic + ?Sized>(mat: &M, f: &[f64; 9]) -> [f64; 6] {
    cauchy_3d(f, &mat.derivatives_3d(f).unwrap())
}

/// Patch test: distorted meshes of each element type, the boundary nodes displaced by an
/// affine field of finite strain, the interior nodes solved from a perturbed start; the
/// solution is the affine field and every element's stress the constant one, for every law.
#[test]
fn patch_tests_reproduce_affine_deformations() {
    let fa = [1.2, 0.1, 0.05, -0.05, 0.9, 0.1, 0.02, 0.03, 1.1];
    let l = 3.0;
    let affine = |x: &[f64; 3]| -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|j| fa[3 * i + j] * x[j]).sum::<f64>() - x[i] + 0.1)
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(35);
    let mut recorded = Vec::new();
    for law in registered_laws() {
        for kind in Kind3::ALL {
            let mesh = match kind {
                Kind3::C3d8 | Kind3::C3d8h => hex_mesh(3, l, kind, 0.2, 7),
                Kind3::C3d4 => tet_mesh(3, l, kind, 0.2, 7),
                Kind3::C3d10 => tet_mesh(2, l, kind, 0.15, 7),
            };
            let free: Vec<bool> = mesh
                .nodes
                .iter()
                .flat_map(|x| [!on_boundary(x, l); 3])
                .collect();
            let n_free = free.iter().filter(|&&f| f).count();
            assert!(n_free >= 3, "{kind:?}: an interior node");
            let mut u: Vec<[f64; 3]> = mesh.nodes.iter().map(affine).collect();
            for (a, x) in mesh.nodes.iter().enumerate() {
                if !on_boundary(x, l) {
                    for v in &mut u[a] {
                        *v += 0.05 * rng.gen_range(-1.0..1.0);
                    }
                }
            }
            solve(&mesh, &*law, &mut u, &free);
            let name = law.spec().name;
            let (mut worst_u, mut worst_s) = (0.0f64, 0.0f64);
            for (a, x) in mesh.nodes.iter().enumerate() {
                let want = affine(x);
                for i in 0..3 {
                    worst_u = worst_u.max((u[a][i] - want[i]).abs());
                    // The Newton tolerance (1e-13 of the forces) over a stiffness of order
                    // the shear modulus gives displacements to about 1e-11 mm.
                    assert!(
                        (u[a][i] - want[i]).abs() < 1e-10,
                        "{name} {kind:?} node {a}: {:?} vs {want:?}",
                        u[a]
                    );
                }
            }
            let sigma = stress_at(&*law, &fa);
            let scale = max_abs(&sigma);
            for (kind, conn) in &mesh.elements {
                let x: Vec<[f64; 3]> = conn.iter().map(|&a| mesh.nodes[a]).collect();
                let ue: Vec<[f64; 3]> = conn.iter().map(|&a| u[a]).collect();
                let geo = Geometry3::new(*kind, &x).unwrap();
                let avg = solid3d::averages(&geo, &*law, &ue).unwrap();
                for (s, w) in avg.cauchy_stress.iter().zip(&sigma) {
                    worst_s = worst_s.max((s - w).abs() / scale);
                    assert!((s - w).abs() < 1e-10 * scale, "{name} {kind:?}: {s} vs {w}");
                }
                assert!((avg.volume_ratio - det3(&fa)).abs() < 1e-10);
            }
            println!(
                "{name} {kind:?} patch ({} elements, {n_free} free dofs): |u - u_affine| \
                 {worst_u:.1e} mm, stress {worst_s:.1e}",
                mesh.elements.len()
            );
            keep_worst(&mut recorded, kind.abaqus_name().to_string(), worst_u);
            keep_worst(
                &mut recorded,
                format!("{} stress", kind.abaqus_name()),
                worst_s,
            );
        }
    }
    for (label, worst) in recorded {
        if let Some(kind) = label.strip_suffix(" stress") {
            measure::record(
                &format!("{kind} patch test, worst over the laws: element stress against the affine one / largest component"),
                worst,
                "< 1e-10",
                "",
            );
        } else {
            measure::record(
                &format!("{label} patch test, worst over the laws: largest nodal error"),
                worst,
                "< 1e-10",
                "mm",
            );
        }
    }
}

/// The closed-form Cauchy stress of the compressible Neo-Hookean law
/// `W = C10 (I1bar - 3) + (J - 1)²/D` at F: `σ = (2 C10/J) dev(b̄) + (2/D)(J - 1) I` with
/// `b̄ = J^(-2/3) F Fᵀ` (Holzapfel 2000, §6.5), in Abaqus order.
fn neo_hookean_cauchy(c10: f64, d: f64, f: &[f64; 9]) -> [f64; 6] {
    let j = det3(f);
    let b = |p: usize, q: usize| (0..3).map(|m| f[3 * p + m] * f[3 * q + m]).sum::<f64>();
    let scale = 2.0 * c10 / j * j.powf(-2.0 / 3.0);
    let mean = (b(0, 0) + b(1, 1) + b(2, 2)) / 3.0;
    let p = 2.0 / d * (j - 1.0);
    [
        scale * (b(0, 0) - mean) + p,
        scale * (b(1, 1) - mean) + p,
        scale * (b(2, 2) - mean) + p,
        scale * b(0, 1),
        scale * b(0, 2),
        scale * b(1, 2),
    ]
}

/// The stretch `μ` of the free directions of `F = diag(λ, λ or μ, μ)` that makes their stress
/// vanish (uniaxial: one loaded direction; equibiaxial: two), by bisection on the closed form.
fn free_stretch(c10: f64, d: f64, lambda: f64, loaded: usize) -> f64 {
    let stress = |mu: f64| {
        let mut f = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        for i in 0..3 {
            f[4 * i] = if i < loaded { lambda } else { mu };
        }
        neo_hookean_cauchy(c10, d, &f)[2]
    };
    let (mut lo, mut hi) = (0.3, 2.0);
    assert!(stress(lo) < 0.0 && stress(hi) > 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if stress(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Uniaxial and equibiaxial stretch with free lateral faces, solved by Newton on a distorted
/// block of each element type (symmetry planes `x = 0`, `y = 0`, `z = 0`, the loaded faces
/// displaced, the others free): the free stretch and the reaction over the current area
/// against the closed-form Neo-Hookean stress; and simple shear, every element's stress
/// against the closed form.
#[test]
fn homogeneous_deformations_match_the_closed_form_neo_hookean_stress() {
    let (c10, d) = (1.75e-3, 18.0);
    let law = NeoHookean { c10, d };
    let l = 2.0;
    let lambda = 1.3;
    for kind in Kind3::ALL {
        let (mut worst_mu, mut worst_s11) = (0.0f64, 0.0f64);
        for loaded in [1, 2] {
            let mesh = match kind {
                Kind3::C3d8 | Kind3::C3d8h => hex_mesh(2, l, kind, 0.15, 11),
                _ => tet_mesh(2, l, kind, 0.15, 11),
            };
            let mu = free_stretch(c10, d, lambda, loaded);
            let mut free = vec![true; 3 * mesh.nodes.len()];
            let mut u = vec![[0.0; 3]; mesh.nodes.len()];
            for (a, x) in mesh.nodes.iter().enumerate() {
                for i in 0..3 {
                    if x[i].abs() < 1e-12 {
                        free[3 * a + i] = false;
                    } else if i < loaded && (x[i] - l).abs() < 1e-12 {
                        free[3 * a + i] = false;
                        u[a][i] = (lambda - 1.0) * l;
                    } else if i < loaded {
                        // The start: the loaded directions stretched, the others not.
                        u[a][i] = (lambda - 1.0) * x[i];
                    }
                }
            }
            let force = solve(&mesh, &law, &mut u, &free);
            let mut f = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
            for i in 0..3 {
                f[4 * i] = if i < loaded { lambda } else { mu };
            }
            let sigma = neo_hookean_cauchy(c10, d, &f);
            // The free stretch: a corner node on the free face z = l.
            let corner = mesh
                .nodes
                .iter()
                .position(|x| x.iter().all(|v| (v - l).abs() < 1e-12))
                .unwrap();
            let got_mu = 1.0 + u[corner][2] / l;
            // The bisection's closed form and the Newton solution, both to round-off.
            assert!(
                (got_mu - mu).abs() < 1e-10,
                "{kind:?} {loaded}: μ {got_mu} vs {mu}"
            );
            // The reaction on x = l over its current area (λ or μ times l, by μ l).
            let reaction: f64 = (0..mesh.nodes.len())
                .filter(|&a| (mesh.nodes[a][0] - l).abs() < 1e-12)
                .map(|a| force[3 * a])
                .sum();
            let area = (if loaded == 2 { lambda } else { mu }) * l * mu * l;
            let s11 = reaction / area;
            println!(
                "{kind:?} loaded {loaded}: μ {got_mu} (closed form {mu}, {:.1e}), σ11 {:.1e} rel",
                (got_mu - mu).abs(),
                (s11 - sigma[0]).abs() / sigma[0].abs()
            );
            worst_mu = worst_mu.max((got_mu - mu).abs());
            worst_s11 = worst_s11.max((s11 - sigma[0]).abs() / sigma[0].abs());
            assert!(
                (s11 - sigma[0]).abs() < 1e-9 * sigma[0].abs(),
                "{kind:?} {loaded}: σ11 {s11} vs {}",
                sigma[0]
            );
            // The closed form's uniaxial/equibiaxial value: 2 C10 J^(-5/3) (λ² - μ²).
            let j = det3(&f);
            let closed = 2.0 * c10 * j.powf(-5.0 / 3.0) * (lambda * lambda - mu * mu);
            assert!((sigma[0] - closed).abs() < 1e-12 * closed);
        }
        // Simple shear F = I + γ e1⊗e2 on every node: σ12 = 2 C10 γ, σ11 = 4/3 C10 γ²,
        // σ22 = σ33 = -2/3 C10 γ² (J = 1).
        let gamma = 0.4;
        let mesh = match kind {
            Kind3::C3d8 | Kind3::C3d8h => hex_mesh(2, l, kind, 0.15, 12),
            _ => tet_mesh(2, l, kind, 0.15, 12),
        };
        let want = [
            4.0 / 3.0 * c10 * gamma * gamma,
            -2.0 / 3.0 * c10 * gamma * gamma,
            -2.0 / 3.0 * c10 * gamma * gamma,
            2.0 * c10 * gamma,
            0.0,
            0.0,
        ];
        let mut worst_shear = 0.0f64;
        for (kind, conn) in &mesh.elements {
            let x: Vec<[f64; 3]> = conn.iter().map(|&a| mesh.nodes[a]).collect();
            let ue: Vec<[f64; 3]> = x.iter().map(|p| [gamma * p[1], 0.0, 0.0]).collect();
            let geo = Geometry3::new(*kind, &x).unwrap();
            let s = solid3d::averages(&geo, &law, &ue).unwrap().cauchy_stress;
            worst_shear = s
                .iter()
                .zip(want)
                .fold(worst_shear, |m, (a, b)| m.max((a - b).abs() / want[3]));
            for (a, b) in s.iter().zip(want) {
                assert!(
                    (a - b).abs() < 1e-12 * want[3],
                    "{kind:?} shear: {s:?} vs {want:?}"
                );
            }
        }
        println!("{kind:?} simple shear: stress {worst_shear:.1e} of σ12");
        measure::record(
            &format!("{} uniaxial and equibiaxial stretch 1.3: free stretch against the closed form, largest error", kind.abaqus_name()),
            worst_mu,
            "< 1e-10",
            "",
        );
        measure::record(
            &format!("{} uniaxial and equibiaxial stretch 1.3: σ11 against the closed form, relative error", kind.abaqus_name()),
            worst_s11,
            "< 1e-9",
            "",
        );
        measure::record(
            &format!(
                "{} simple shear γ = 0.4: element stress against the closed form / σ12",
                kind.abaqus_name()
            ),
            worst_shear,
            "< 1e-12",
            "",
        );
    }
}

/// The nominal stress `P11 = μ² σ11` of the Neo-Hookean law in uniaxial tension `λ` with free
/// lateral faces (`σ22 = σ33 = 0`), and the stretch at which it equals `t`, by bisection on
/// the closed form.
fn uniaxial_stretch_under_nominal_stress(c10: f64, d: f64, t: f64) -> (f64, f64) {
    let nominal = |lambda: f64| {
        let mu = free_stretch(c10, d, lambda, 1);
        let j = lambda * mu * mu;
        mu * mu * 2.0 * c10 * j.powf(-5.0 / 3.0) * (lambda * lambda - mu * mu)
    };
    let (mut lo, mut hi) = (1.0, 3.0);
    assert!(nominal(hi) > t);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if nominal(mid) < t {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let lambda = 0.5 * (lo + hi);
    (lambda, free_stretch(c10, d, lambda, 1))
}

/// A block on the symmetry planes `x = 0`, `y = 0`, `z = 0`: its [`solid3d::Body3`] with the
/// mesh's elements of material 0.
fn block_body(mesh: &Mesh, law: Box<dyn Material>) -> solid3d::Body3 {
    let mut prescribed = Vec::new();
    for (a, x) in mesh.nodes.iter().enumerate() {
        for i in 0..3 {
            if x[i].abs() < 1e-12 {
                prescribed.push((a, i, 0.0));
            }
        }
    }
    solid3d::Body3 {
        nodes: mesh.nodes.clone(),
        elements: mesh
            .elements
            .iter()
            .map(|(kind, nodes)| solid3d::Element3 {
                kind: *kind,
                nodes: nodes.clone(),
                material: 0,
            })
            .collect(),
        materials: vec![law],
        prescribed,
        loads: Vec::new(),
        pressures: Vec::new(),
    }
}

/// The sparse Newton of [`solid3d::solve`]: a Neo-Hookean block under a uniaxial dead load
/// (nominal traction t on `x = l`, consistent nodal forces, lateral faces free) on distorted
/// C3D8 and C3D8H meshes, and under a prescribed stretch on a C3D10 mesh: the stretches and the
/// nominal stress against the closed form.
#[test]
fn sparse_newton_solves_a_block_in_uniaxial_tension() {
    let (c10, d) = (1.75e-3, 18.0);
    let law = NeoHookean { c10, d };
    let l = 2.0;
    let t = 3e-3; // MPa: a stretch of about 1.4
    let (lambda, mu) = uniaxial_stretch_under_nominal_stress(c10, d, t);
    assert!(lambda > 1.3 && lambda < 1.6, "λ = {lambda}");
    let n = 3;
    let h = l / n as f64;
    for kind in [Kind3::C3d8, Kind3::C3d8h] {
        let mesh = hex_mesh(n, l, kind, 0.15, 13);
        let mut body = block_body(&mesh, Box::new(law));
        // ∫ N_a t dA over the face x = l: t h²/4 from each of the node's face quads.
        for (a, x) in mesh.nodes.iter().enumerate() {
            if (x[0] - l).abs() < 1e-12 {
                let share = |v: f64| {
                    if v.abs() < 1e-12 || (v - l).abs() < 1e-12 {
                        0.5
                    } else {
                        1.0
                    }
                };
                body.loads
                    .push((a, 0, t * h * h * share(x[1]) * share(x[2])));
            }
        }
        let options = solid3d::Options3 {
            increments: 4,
            ..Default::default()
        };
        let solution = solid3d::solve(&body, &options).unwrap();
        let corner = mesh
            .nodes
            .iter()
            .position(|x| x.iter().all(|v| (v - l).abs() < 1e-12))
            .unwrap();
        let got = [
            1.0 + solution.u[corner][0] / l,
            1.0 + solution.u[corner][2] / l,
        ];
        println!(
            "{kind:?} dead load: λ {} (closed form {lambda}), μ {} ({mu}), Newton iterations {:?}",
            got[0], got[1], solution.iterations
        );
        // The Newton tolerance (1e-10 of the forces) over the tangent stiffness: stretches to
        // about 1e-10.
        measure::record(
            &format!("{} block, uniaxial dead load 3e-3 MPa, sparse Newton: stretches λ and μ against the closed form, largest error", kind.abaqus_name()),
            (got[0] - lambda).abs().max((got[1] - mu).abs()),
            "< 1e-8",
            "",
        );
        measure::record(
            &format!(
                "{} block, uniaxial dead load: most Newton iterations in an increment",
                kind.abaqus_name()
            ),
            solution.iterations.iter().copied().max().unwrap_or(0) as f64,
            "≤ 8",
            "",
        );
        assert!(
            (got[0] - lambda).abs() < 1e-8,
            "{kind:?}: λ {} vs {lambda}",
            got[0]
        );
        assert!((got[1] - mu).abs() < 1e-8, "{kind:?}: μ {} vs {mu}", got[1]);
        // Quadratic convergence: a few iterations per increment.
        assert!(
            solution.iterations.iter().all(|&k| k <= 8),
            "{:?}",
            solution.iterations
        );
    }
    // Prescribed stretch λ on x = l, C3D10: the reaction is the closed-form nominal stress.
    let mesh = tet_mesh(2, l, Kind3::C3d10, 0.15, 14);
    let mut body = block_body(&mesh, Box::new(law));
    for (a, x) in mesh.nodes.iter().enumerate() {
        if (x[0] - l).abs() < 1e-12 {
            body.prescribed.push((a, 0, (lambda - 1.0) * l));
        }
    }
    let solution = solid3d::solve(&body, &solid3d::Options3::default()).unwrap();
    let reaction: f64 = (0..mesh.nodes.len())
        .filter(|&a| (mesh.nodes[a][0] - l).abs() < 1e-12)
        .map(|a| solution.internal_force[3 * a])
        .sum();
    let nominal = reaction / (l * l);
    println!(
        "C3d10 prescribed stretch: P11 {nominal} (closed form {t}), iterations {:?}",
        solution.iterations
    );
    measure::record(
        "C3D10 block, prescribed stretch: nominal stress P11 against the closed form, relative error",
        (nominal - t).abs() / t,
        "< 1e-8",
        "",
    );
    assert!((nominal - t).abs() < 1e-8 * t, "P11 {nominal} vs {t}");
}

/// The compressible Neo-Hookean thick-walled sphere (inner radius `a0`, outer `b0`) under an
/// inner follower pressure p: the deformed inner radius, from the radial equilibrium
/// `dP_rr/dR + (2/R)(P_rr - P_θθ) = 0` with `P_rr(a0) = -p λ_θ²` (σ_rr = -p) and
/// `P_rr(b0) = 0`, solved by shooting (RK4 on 4 000 steps, bisection on the inner radius).
/// The principal nominal stresses of `W = C10 (J^(-2/3) I1 - 3) + (J - 1)²/D` at the radial
/// and hoop stretches `(λ_r, λ_θ, λ_θ)`:
/// `P_rr = C10 J^(-2/3) (2 λ_r - 2/3 I1/λ_r) + 2 (J - 1)/D λ_θ²`,
/// `P_θθ = C10 J^(-2/3) (2 λ_θ - 2/3 I1/λ_θ) + 2 (J - 1)/D λ_r λ_θ`.
fn sphere_inner_radius(c10: f64, d: f64, a0: f64, b0: f64, p: f64) -> f64 {
    let stresses = |lr: f64, lt: f64| {
        let j = lr * lt * lt;
        let i1 = lr * lr + 2.0 * lt * lt;
        let jm23 = j.powf(-2.0 / 3.0);
        let vol = 2.0 * (j - 1.0) / d;
        (
            c10 * jm23 * (2.0 * lr - 2.0 / 3.0 * i1 / lr) + vol * lt * lt,
            c10 * jm23 * (2.0 * lt - 2.0 / 3.0 * i1 / lt) + vol * lr * lt,
        )
    };
    let p_rr = |lr: f64, lt: f64| stresses(lr, lt).0;
    // r'' from the equilibrium, the partial derivatives of P_rr by central differences (step
    // 1e-6: errors of 1e-10, far below the meshes' errors checked against this).
    let accel = |big_r: f64, r: f64, dr: f64| {
        let (lr, lt) = (dr, r / big_r);
        let h = 1e-6;
        let d_lr = (p_rr(lr + h, lt) - p_rr(lr - h, lt)) / (2.0 * h);
        let d_lt = (p_rr(lr, lt + h) - p_rr(lr, lt - h)) / (2.0 * h);
        let (prr, ptt) = stresses(lr, lt);
        (-2.0 / big_r * (prr - ptt) - d_lt * (dr - r / big_r) / big_r) / d_lr
    };
    // P_rr(b0) for the inner radius a.
    let outer_stress = |a: f64| {
        let lt = a / a0;
        // λ_r at the inner face from P_rr = -p λ_θ² (P_rr increases with λ_r).
        let (mut lo, mut hi) = (0.2, 5.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if p_rr(mid, lt) < -p * lt * lt {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (mut r, mut dr) = (a, 0.5 * (lo + hi));
        let steps = 4000;
        let h = (b0 - a0) / steps as f64;
        for k in 0..steps {
            let big_r = a0 + k as f64 * h;
            let f = |rr: f64, y: (f64, f64)| (y.1, accel(rr, y.0, y.1));
            let k1 = f(big_r, (r, dr));
            let k2 = f(big_r + h / 2.0, (r + h / 2.0 * k1.0, dr + h / 2.0 * k1.1));
            let k3 = f(big_r + h / 2.0, (r + h / 2.0 * k2.0, dr + h / 2.0 * k2.1));
            let k4 = f(big_r + h, (r + h * k3.0, dr + h * k3.1));
            r += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            dr += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        }
        p_rr(dr, r / b0)
    };
    let (mut lo, mut hi) = (a0, 1.6 * a0);
    let (slo, shi) = (outer_stress(lo), outer_stress(hi));
    assert!(slo * shi < 0.0, "bracket: {slo} {shi}");
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if outer_stress(mid) * slo > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// An octant of the thick-walled sphere `a0 ≤ R ≤ b0` in hexahedra: the octant of the unit
/// sphere in three quadrilateral patches (each joining an axis point, the midpoints of its two
/// edges and the octant's centre), each `n x n`, projected on the sphere and repeated on `m`
/// radial layers. Returns the mesh and its inner faces (ordered with the normal out of the
/// body, towards the centre).
fn sphere_octant(n: usize, m: usize, a0: f64, b0: f64, kind: Kind3) -> (Mesh, Vec<Vec<usize>>) {
    let e = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let centre = [1.0 / 3.0; 3];
    let mid =
        |i: usize, j: usize| -> [f64; 3] { std::array::from_fn(|r| 0.5 * (e[i][r] + e[j][r])) };
    let mut nodes: Vec<[f64; 3]> = Vec::new();
    let mut index: HashMap<[i64; 3], usize> = HashMap::new();
    fn node_at(
        nodes: &mut Vec<[f64; 3]>,
        index: &mut HashMap<[i64; 3], usize>,
        x: [f64; 3],
    ) -> usize {
        let key = x.map(|v| (v * 1e9).round() as i64);
        *index.entry(key).or_insert_with(|| {
            nodes.push(x);
            nodes.len() - 1
        })
    }
    let mut elements = Vec::new();
    let mut inner = Vec::new();
    for (i, j, k) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
        let corners = [e[i], mid(i, j), centre, mid(i, k)];
        let point = |s: f64, t: f64, radius: f64| -> [f64; 3] {
            let q: [f64; 3] = std::array::from_fn(|r| {
                (1.0 - s) * (1.0 - t) * corners[0][r]
                    + s * (1.0 - t) * corners[1][r]
                    + s * t * corners[2][r]
                    + (1.0 - s) * t * corners[3][r]
            });
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            q.map(|v| radius * v / norm)
        };
        let mut id = vec![vec![vec![0; m + 1]; n + 1]; n + 1];
        for (si, row) in id.iter_mut().enumerate() {
            for (ti, col) in row.iter_mut().enumerate() {
                for (layer, v) in col.iter_mut().enumerate() {
                    let radius = a0 + (b0 - a0) * layer as f64 / m as f64;
                    *v = node_at(
                        &mut nodes,
                        &mut index,
                        point(si as f64 / n as f64, ti as f64 / n as f64, radius),
                    );
                }
            }
        }
        for si in 0..n {
            for ti in 0..n {
                for layer in 0..m {
                    let quad = |l: usize| {
                        [
                            id[si][ti][l],
                            id[si + 1][ti][l],
                            id[si + 1][ti + 1][l],
                            id[si][ti + 1][l],
                        ]
                    };
                    let (mut bottom, mut top) = (quad(layer), quad(layer + 1));
                    let conn: Vec<usize> = bottom.iter().chain(&top).copied().collect();
                    let x: Vec<[f64; 3]> = conn.iter().map(|&a| nodes[a]).collect();
                    if Geometry3::new(kind, &x).is_err() {
                        bottom.reverse();
                        top.reverse();
                    }
                    let conn: Vec<usize> = bottom.iter().chain(&top).copied().collect();
                    elements.push((kind, conn));
                    if layer == 0 {
                        let mut face = bottom.to_vec();
                        let x: Vec<[f64; 3]> = face.iter().map(|&a| nodes[a]).collect();
                        let t1: [f64; 3] = std::array::from_fn(|r| x[1][r] - x[0][r]);
                        let t2: [f64; 3] = std::array::from_fn(|r| x[3][r] - x[0][r]);
                        let normal = [
                            t1[1] * t2[2] - t1[2] * t2[1],
                            t1[2] * t2[0] - t1[0] * t2[2],
                            t1[0] * t2[1] - t1[1] * t2[0],
                        ];
                        if (0..3).map(|r| normal[r] * x[0][r]).sum::<f64>() > 0.0 {
                            face.reverse();
                        }
                        inner.push(face);
                    }
                }
            }
        }
    }
    (Mesh { nodes, elements }, inner)
}

/// The pressurized thick-walled sphere of compressible Neo-Hookean material (inner radius 1,
/// outer 2, inner follower pressure of about 0.3 μ), an octant on its symmetry planes in C3D8
/// and C3D8H, solved by the sparse Newton: the inner radius against the shooting solution of
/// the radial equilibrium, on two meshes (second-order convergence of C3D8H; C3D8 locks).
#[test]
fn pressurized_thick_walled_sphere_matches_the_radial_solution() {
    let (c10, d) = (1.75e-3, 18.0);
    let law = NeoHookean { c10, d };
    let (a0, b0, p) = (1.0, 2.0, 1e-3);
    let a = sphere_inner_radius(c10, d, a0, b0, p);
    println!("sphere: reference inner radius {a}");
    assert!(a > 1.05 && a < 1.5, "a = {a}");
    let mut all = Vec::new();
    for kind in [Kind3::C3d8, Kind3::C3d8h] {
        let mut errors = Vec::new();
        for (n, m) in [(3, 3), (6, 6)] {
            let (mesh, inner) = sphere_octant(n, m, a0, b0, kind);
            let mut body = block_body(&mesh, Box::new(law));
            body.pressures = inner.iter().map(|f| (f.clone(), p)).collect();
            let solution = solid3d::solve(&body, &solid3d::Options3::default()).unwrap();
            // The mean deformed radius of the inner nodes.
            let radii: Vec<f64> = mesh
                .nodes
                .iter()
                .zip(&solution.u)
                .filter(|(x, _)| (x.iter().map(|v| v * v).sum::<f64>().sqrt() - a0).abs() < 1e-9)
                .map(|(x, u)| (0..3).map(|i| (x[i] + u[i]).powi(2)).sum::<f64>().sqrt())
                .collect();
            let mean = radii.iter().sum::<f64>() / radii.len() as f64;
            let error = (mean - a).abs() / (a - a0);
            println!(
                "{kind:?} {} elements: inner radius {mean} (spread {:.1e}), error {error:.2e} of \
                 the displacement, iterations {:?}",
                mesh.elements.len(),
                radii.iter().fold(0.0f64, |s, r| s.max((r - mean).abs())),
                solution.iterations
            );
            errors.push(error);
        }
        all.push(errors);
    }
    // C3D8H converges at second order (errors 3.0e-2, 7.7e-3 and, on 9 x 9 x 9 patches,
    // 3.4e-3: ratios 3.9 and 2.2 for mesh ratios 2 and 1.5), so halving the mesh divides the
    // error by about 4; C3D8 locks at this compressibility (ν ≈ 0.48: 3.9e-1, 1.3e-1, 6.2e-2),
    // converging, more slowly on coarse meshes.
    let (full, hybrid) = (&all[0], &all[1]);
    for (kind, errors, bound) in [
        ("C3D8", full, ["> 2 x the 6 x 6 mesh's", "> the C3D8H one"]),
        ("C3D8H", hybrid, ["> 3 x the 6 x 6 mesh's", "< 1e-2"]),
    ] {
        for (m, (error, bound)) in errors.iter().zip(bound).enumerate() {
            let n = [3, 6][m];
            measure::record(
                &format!("{kind} sphere under inner follower pressure, {n} x {n} patches: inner radius against the radial solution / its displacement"),
                *error,
                bound,
                "",
            );
        }
    }
    assert!(
        hybrid[1] < 1e-2 && hybrid[0] > 3.0 * hybrid[1],
        "C3D8H: {hybrid:?}"
    );
    assert!(
        full[0] > 2.0 * full[1] && hybrid[1] < full[1],
        "C3D8: {full:?}"
    );
}

/// The exact parameter sensitivities of a 3D solution against central differences of the
/// solve in each parameter: the pressurized sphere (C3D8H, follower pressure) and the block
/// under a prescribed stretch (C3D10), Mooney–Rivlin and Neo-Hookean.
#[test]
fn sensitivities_of_a_3d_solution_match_finite_differences() {
    let options = solid3d::Options3 {
        increments: 4,
        max_iterations: 30,
        // Tight (round-off leaves about 1e-13), so that differences of solutions resolve the
        // sensitivities.
        tolerance: 1e-12,
    };
    let (mesh, inner) = sphere_octant(2, 2, 1.0, 2.0, Kind3::C3d8h);
    let mut sphere = block_body(
        &mesh,
        Box::new(MooneyRivlin {
            c10: 1.0e-3,
            c01: 0.75e-3,
            d: 18.0,
        }),
    );
    sphere.pressures = inner.iter().map(|f| (f.clone(), 1e-3)).collect();
    let mesh = tet_mesh(2, 2.0, Kind3::C3d10, 0.15, 15);
    let mut block = block_body(
        &mesh,
        Box::new(NeoHookean {
            c10: 1.75e-3,
            d: 18.0,
        }),
    );
    for (a, x) in mesh.nodes.iter().enumerate() {
        if (x[0] - 2.0).abs() < 1e-12 {
            block.prescribed.push((a, 0, 0.6));
        }
    }
    for (name, body) in [("sphere", sphere), ("block", block)] {
        let solution = solid3d::solve(&body, &options).unwrap();
        let exact = solid3d::sensitivities(&body, &solution).unwrap();
        let law = &body.materials[0];
        for k in 0..law.spec().parameters.len() {
            let theta = law.parameter(k);
            let h = 1e-4 * theta;
            let solve_at = |value: f64| {
                let mut b = body.clone();
                b.materials[0].set_parameter(k, value);
                solid3d::solve(&b, &options).unwrap().u
            };
            let (up, um) = (solve_at(theta + h), solve_at(theta - h));
            let scale = exact[0][k]
                .iter()
                .flatten()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            let mut worst = 0.0f64;
            for a in 0..body.nodes.len() {
                for i in 0..3 {
                    let fd = (up[a][i] - um[a][i]) / (2.0 * h);
                    worst = worst.max((fd - exact[0][k][a][i]).abs() / scale);
                }
            }
            println!("{name} parameter {k}: du/dθ vs FD {worst:.1e} (max |du/dθ| {scale:.2e})");
            measure::record(
                &format!("{name} ({}), parameter {}: du/dθ against finite differences of the solve / largest entry", law.spec().name, law.spec().parameters[k].name),
                worst,
                "< 1e-6",
                "",
            );
            // Truncation (h/θ)² = 1e-8; the solves' residual tolerance (1e-12 of the forces)
            // over h/θ: 1e-8 of the sensitivity.
            assert!(
                scale > 0.0 && worst < 1e-6,
                "{name} parameter {k}: {worst:e}"
            );
        }
    }
}

/// The element faces of `mesh` whose corners all lie on the plane `x = l`, ordered with their
/// normal along +x (out of the block), C3D10 faces with their mid-edge nodes.
fn faces_on_x(mesh: &Mesh, l: f64) -> Vec<Vec<usize>> {
    let mut faces = Vec::new();
    for (kind, conn) in &mesh.elements {
        let corner_sets: Vec<Vec<usize>> = match kind {
            Kind3::C3d8 | Kind3::C3d8h => vec![
                vec![0, 1, 2, 3],
                vec![4, 5, 6, 7],
                vec![0, 1, 5, 4],
                vec![1, 2, 6, 5],
                vec![2, 3, 7, 6],
                vec![3, 0, 4, 7],
            ],
            _ => vec![vec![0, 1, 2], vec![0, 1, 3], vec![1, 2, 3], vec![0, 2, 3]],
        };
        for mut local in corner_sets {
            if !local
                .iter()
                .all(|&a| (mesh.nodes[conn[a]][0] - l).abs() < 1e-12)
            {
                continue;
            }
            let x: Vec<[f64; 3]> = local.iter().map(|&a| mesh.nodes[conn[a]]).collect();
            let last = local.len() - 1;
            // The x component of (x1 - x0) × (x_last - x0).
            let (t1, t2) = (
                [x[1][1] - x[0][1], x[1][2] - x[0][2]],
                [x[last][1] - x[0][1], x[last][2] - x[0][2]],
            );
            if t1[0] * t2[1] - t1[1] * t2[0] < 0.0 {
                local.reverse();
            }
            let mut face: Vec<usize> = local.iter().map(|&a| conn[a]).collect();
            if *kind == Kind3::C3d10 {
                for k in 0..3 {
                    let (a, b) = (local[k], local[(k + 1) % 3]);
                    let e = solid3d::shape::TET10_EDGES
                        .iter()
                        .position(|&[i, j]| (i, j) == (a, b) || (i, j) == (b, a))
                        .unwrap();
                    face.push(conn[4 + e]);
                }
            }
            faces.push(face);
        }
    }
    faces
}

/// A Neo-Hookean block compressed by a follower pressure on `x = l` (lateral faces free), on
/// every element type (the pressure on hexahedron, C3D4 and C3D10 faces): the stretches against
/// the closed form `σ11 = -p`, `σ22 = σ33 = 0`.
#[test]
fn follower_pressure_compresses_a_block_as_the_closed_form() {
    let (c10, d) = (1.75e-3, 18.0);
    let law = NeoHookean { c10, d };
    let (l, p) = (2.0, 1e-3);
    let sigma11 = |lambda: f64| {
        let mu = free_stretch(c10, d, lambda, 1);
        let j = lambda * mu * mu;
        2.0 * c10 * j.powf(-5.0 / 3.0) * (lambda * lambda - mu * mu)
    };
    let (mut lo, mut hi) = (0.5, 1.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if sigma11(mid) < -p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let lambda = 0.5 * (lo + hi);
    let mu = free_stretch(c10, d, lambda, 1);
    for kind in Kind3::ALL {
        let mesh = match kind {
            Kind3::C3d8 | Kind3::C3d8h => hex_mesh(2, l, kind, 0.15, 16),
            _ => tet_mesh(2, l, kind, 0.15, 16),
        };
        let mut body = block_body(&mesh, Box::new(law));
        body.pressures = faces_on_x(&mesh, l).into_iter().map(|f| (f, p)).collect();
        assert_eq!(
            body.pressures.len(),
            if matches!(kind, Kind3::C3d8 | Kind3::C3d8h) {
                4
            } else {
                8
            }
        );
        let solution = solid3d::solve(&body, &solid3d::Options3::default()).unwrap();
        let corner = mesh
            .nodes
            .iter()
            .position(|x| x.iter().all(|v| (v - l).abs() < 1e-12))
            .unwrap();
        let got = [
            1.0 + solution.u[corner][0] / l,
            1.0 + solution.u[corner][2] / l,
        ];
        println!(
            "{kind:?} follower pressure: λ {} (closed form {lambda}), μ {} ({mu}), iterations {:?}",
            got[0], got[1], solution.iterations
        );
        // The Newton tolerance (1e-10 of the forces) over the stiffness: about 1e-10.
        measure::record(
            &format!("{} block, follower pressure 1e-3 MPa: stretches λ and μ against the closed form, largest error", kind.abaqus_name()),
            (got[0] - lambda).abs().max((got[1] - mu).abs()),
            "< 1e-8",
            "",
        );
        assert!(
            (got[0] - lambda).abs() < 1e-8,
            "{kind:?}: λ {} vs {lambda}",
            got[0]
        );
        assert!((got[1] - mu).abs() < 1e-8, "{kind:?}: μ {} vs {mu}", got[1]);
    }
}

/// A number in at most 20 characters (all ccx 2.20 reads of a field) and the value it is read
/// as, so that both codes solve the same data.
fn ccx_number(v: f64) -> (String, f64) {
    let s = format!("{v:.12e}");
    let parsed = s.parse().unwrap();
    (s, parsed)
}

/// The displacements `(label, [ux, uy, uz])` of the last `displacements` block of a ccx `.dat`.
fn ccx_displacements(dat: &str) -> Vec<(usize, [f64; 3])> {
    let mut blocks: Vec<Vec<(usize, [f64; 3])>> = Vec::new();
    for line in dat.lines() {
        if line.trim_start().starts_with("displacements") {
            blocks.push(Vec::new());
            continue;
        }
        let cols: Vec<&str> = line.split_whitespace().collect();
        if let (Some(block), 4) = (blocks.last_mut(), cols.len()) {
            if let Ok(label) = cols[0].parse::<usize>() {
                let v: Vec<f64> = cols[1..].iter().map(|c| c.parse().unwrap()).collect();
                block.push((label, [v[0], v[1], v[2]]));
            }
        }
    }
    blocks.pop().expect("a displacements block")
}

/// femu's 3D solve against CalculiX 2.20 (`ccx`) on a distorted block of C3D8, C3D4 and C3D10
/// with each registered law (ccx's `*HYPERELASTIC, NEO HOOKE`, `MOONEY-RIVLIN` and `YEOH`, the
/// same Abaqus energies): symmetry planes `x = 0`, `y = 0`, `z = 0`, unequal dead nodal loads
/// (`*CLOAD`) along x and y on the face `x = l`, so that the deformation is not homogeneous
/// (strains of about 15 %). The displacements agree within 1e-6 of the largest (ccx prints 7
/// significant digits; measured 1.3e-7 to 2.1e-7). Without `ccx` on PATH the test prints
/// `SKIPPED` and returns.
#[test]
fn calculix_agrees_on_3d_blocks() {
    if std::process::Command::new("ccx")
        .arg("-v")
        .output()
        .is_err()
    {
        println!("SKIPPED: ccx not installed (apt-get install calculix-ccx)");
        return;
    }
    let l = 2.0;
    for law in registered_laws() {
        for kind in [Kind3::C3d8, Kind3::C3d4, Kind3::C3d10] {
            let mut mesh = match kind {
                Kind3::C3d8 => hex_mesh(2, l, kind, 0.15, 21),
                _ => tet_mesh(2, l, kind, 0.15, 21),
            };
            let mut deck = String::from("*HEADING\nfemu 3D comparison\n*NODE, NSET=NALL\n");
            for (a, x) in mesh.nodes.iter_mut().enumerate() {
                let c: Vec<String> = x
                    .iter_mut()
                    .map(|v| {
                        let (s, p) = ccx_number(*v);
                        *v = p;
                        s
                    })
                    .collect();
                deck.push_str(&format!("{}, {}\n", a + 1, c.join(", ")));
            }
            deck.push_str(&format!(
                "*ELEMENT, TYPE={}, ELSET=EALL\n",
                kind.abaqus_name()
            ));
            for (e, (_, conn)) in mesh.elements.iter().enumerate() {
                let labels: Vec<String> = conn.iter().map(|a| (a + 1).to_string()).collect();
                deck.push_str(&format!("{}, {}\n", e + 1, labels.join(", ")));
            }
            let values = law.parameters();
            let (keyword, data) = match law.spec().name {
                "neo-hookean" => ("NEO HOOKE", values.clone()),
                "mooney-rivlin" => ("MOONEY-RIVLIN", values.clone()),
                // ccx's default D2, D3 add volumetric terms; 1e20 removes them (see
                // tests/calculix.rs).
                _ => ("YEOH", [values.clone(), vec![1e20, 1e20]].concat()),
            };
            let data: Vec<String> = data.iter().map(|v| ccx_number(*v).0).collect();
            deck.push_str(&format!(
                "*MATERIAL, NAME=M1\n*HYPERELASTIC, {keyword}\n{}\n\
                 *SOLID SECTION, ELSET=EALL, MATERIAL=M1\n*BOUNDARY\n",
                data.join(", ")
            ));
            let mut body = block_body(&mesh, law.clone());
            for &(a, i, _) in &body.prescribed {
                deck.push_str(&format!("{}, {}, {}\n", a + 1, i + 1, i + 1));
            }
            deck.push_str("*STEP, NLGEOM, INC=1000\n*STATIC\n0.1, 1.0\n*CLOAD\n");
            let face: Vec<usize> = (0..mesh.nodes.len())
                .filter(|&a| (mesh.nodes[a][0] - l).abs() < 1e-12)
                .collect();
            for (k, &a) in face.iter().enumerate() {
                let w = 1.0 + 0.4 * (k as f64 * 1.7).sin();
                for (i, total) in [(0, 4e-3), (1, 1e-3)] {
                    let (s, f) = ccx_number(total * w / face.len() as f64);
                    deck.push_str(&format!("{}, {}, {s}\n", a + 1, i + 1));
                    body.loads.push((a, i, f));
                }
            }
            deck.push_str("*NODE PRINT, NSET=NALL\nU\n*END STEP\n");

            let dir = std::env::temp_dir().join(format!(
                "femu-ccx3d-{}-{}-{}",
                std::process::id(),
                law.spec().name,
                kind.abaqus_name()
            ));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join("job.inp"), &deck).unwrap();
            let out = std::process::Command::new("ccx")
                .args(["-i", "job"])
                .current_dir(&dir)
                .env("OMP_NUM_THREADS", "1")
                .output()
                .unwrap();
            let stdout = String::from_utf8_lossy(&out.stdout);
            assert!(
                out.status.success() && !stdout.contains("*ERROR"),
                "ccx failed; deck kept in {}",
                dir.display()
            );
            let ccx = ccx_displacements(&std::fs::read_to_string(dir.join("job.dat")).unwrap());
            let options = solid3d::Options3 {
                increments: 10,
                tolerance: 1e-12,
                ..Default::default()
            };
            let solution = solid3d::solve(&body, &options).unwrap();
            assert_eq!(ccx.len(), mesh.nodes.len());
            let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let scale = ccx.iter().fold(0.0f64, |m, (_, u)| m.max(norm(*u)));
            let worst = ccx.iter().fold(0.0f64, |m, (label, u)| {
                let v = solution.u[label - 1];
                m.max(norm(std::array::from_fn(|i| v[i] - u[i])))
            }) / scale;
            println!(
                "{} {kind:?}: max |u_femu - u_ccx| / max |u_ccx| = {worst:.1e} (max |u| {scale:.3} mm)",
                law.spec().name
            );
            measure::record(
                &format!("{} {} block under dead loads: largest difference from ccx / largest displacement", law.spec().name, kind.abaqus_name()),
                worst,
                "< 1e-6",
                "",
            );
            assert!(worst < 1e-6, "{} {kind:?}: {worst:e}", law.spec().name);
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}
