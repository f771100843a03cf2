//! A static 3D solve of the elements of [`crate::solid3d`]: global assembly on a sparse
//! pattern of [`femu_sparse`] (the same [`CscPattern`] and [`SparseSolver`], LDLᵀ or LU, as the
//! plane-strain solver) and Newton–Raphson over load increments, for prescribed
//! displacements, dead nodal loads and follower pressures on faces ([`super::pressure`]); and
//! the exact parameter sensitivities of a solution ([`sensitivities`]).
//!
//! This is the first slice of 3D solving: no contact, no line search or cut-back (the
//! plane-strain [`crate::solver`] has them, written for two dofs per node). Dof `3 n + i` is
//! component i of node n; the free dofs are numbered in increasing dof order.

use super::kernel::{evaluate, Geometry3, MAX_DOFS_3D};
use super::pressure::{face_pressure, MAX_FACE_DOFS};
use super::shape::Kind3;
use crate::element::{BadReferenceGeometry, ElementResult};
use crate::material::Material;
use femu_sparse::{CscPattern, LinearSolveError, SparseSolver};

/// One element: its type, its nodes (in the type's node order) and its material (an index
/// into [`Body3::materials`]).
#[derive(Debug, Clone)]
pub struct Element3 {
    pub kind: Kind3,
    pub nodes: Vec<usize>,
    pub material: usize,
}

/// A 3D body: nodes (mm), elements, materials, prescribed displacements, dead nodal loads and
/// follower pressures.
#[derive(Debug, Clone)]
pub struct Body3 {
    pub nodes: Vec<[f64; 3]>,
    pub elements: Vec<Element3>,
    pub materials: Vec<Box<dyn Material>>,
    /// `(node, component, displacement)` (mm), reached at the end of the load path.
    pub prescribed: Vec<(usize, usize, f64)>,
    /// `(node, component, force)` (N), dead loads, reached at the end of the load path.
    pub loads: Vec<(usize, usize, f64)>,
    /// `(face nodes, pressure)` (MPa): follower pressures on element faces (3, 4 or 6 nodes, in
    /// the order whose normal points out of the body), reached at the end of the load path.
    pub pressures: Vec<(Vec<usize>, f64)>,
}

/// Why a 3D solve failed.
#[derive(Debug, thiserror::Error)]
pub enum Solve3Error {
    #[error("element {element}: its reference map is singular or inverted (det J = {det_j} at integration point {gauss_point})")]
    BadElement {
        element: usize,
        gauss_point: usize,
        det_j: f64,
    },
    #[error("element {element} inverted (J = {j}) at load factor {load_factor}")]
    Inverted {
        element: usize,
        j: f64,
        load_factor: f64,
    },
    #[error("no convergence at load factor {load_factor}: residual {residual:e} after {iterations} iterations")]
    NotConverged {
        load_factor: f64,
        residual: f64,
        iterations: usize,
    },
    #[error(transparent)]
    Linear(#[from] LinearSolveError),
}

/// Options of [`solve`].
#[derive(Debug, Clone, Copy)]
pub struct Options3 {
    /// Equal load increments from 0 to 1.
    pub increments: usize,
    /// Newton iterations allowed per increment.
    pub max_iterations: usize,
    /// Convergence: the largest free residual at most this fraction of the largest internal
    /// force (or of the largest load).
    pub tolerance: f64,
}

impl Default for Options3 {
    fn default() -> Self {
        Options3 {
            increments: 4,
            max_iterations: 25,
            tolerance: 1e-10,
        }
    }
}

/// The equilibrium state.
#[derive(Debug, Clone)]
pub struct Solution3 {
    /// Nodal displacements (mm).
    pub u: Vec<[f64; 3]>,
    /// Internal force minus the pressure loads at every dof (N): the reactions at the
    /// prescribed dofs.
    pub internal_force: Vec<f64>,
    /// Newton iterations of each increment.
    pub iterations: Vec<usize>,
}

/// The assembled system: equation numbers, sparse pattern, and each element's matrix slots.
struct System {
    /// `eq[dof]`: the equation of a free dof, `usize::MAX` for a prescribed one.
    eq: Vec<usize>,
    n_eq: usize,
    pattern: CscPattern,
    /// Per element, the value position of each entry (r, c) of its matrix (row-major), or
    /// `usize::MAX` when a dof is prescribed.
    slots: Vec<Vec<usize>>,
    geometries: Vec<Geometry3>,
}

impl System {
    fn new(body: &Body3) -> Result<Self, Solve3Error> {
        let n_dof = 3 * body.nodes.len();
        let mut prescribed = vec![false; n_dof];
        for &(node, i, _) in &body.prescribed {
            prescribed[3 * node + i] = true;
        }
        let mut eq = vec![usize::MAX; n_dof];
        let mut n_eq = 0;
        for (d, p) in prescribed.iter().enumerate() {
            if !p {
                eq[d] = n_eq;
                n_eq += 1;
            }
        }
        let element_eqs = |e: &Element3| -> Vec<usize> {
            e.nodes
                .iter()
                .flat_map(|&n| [eq[3 * n], eq[3 * n + 1], eq[3 * n + 2]])
                .collect()
        };
        let mut pairs = Vec::new();
        for e in &body.elements {
            let eqs = element_eqs(e);
            for &r in eqs.iter().filter(|&&r| r != usize::MAX) {
                for &c in eqs.iter().filter(|&&c| c != usize::MAX) {
                    pairs.push((r, c));
                }
            }
        }
        let pattern = CscPattern::from_pairs(n_eq, &mut pairs);
        let slots = body
            .elements
            .iter()
            .map(|e| {
                let eqs = element_eqs(e);
                eqs.iter()
                    .flat_map(|&r| eqs.iter().map(move |&c| (r, c)))
                    .map(|(r, c)| {
                        if r == usize::MAX || c == usize::MAX {
                            usize::MAX
                        } else {
                            pattern.position(r, c).expect("in the pattern")
                        }
                    })
                    .collect()
            })
            .collect();
        let geometries = body
            .elements
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let x: Vec<[f64; 3]> = e.nodes.iter().map(|&n| body.nodes[n]).collect();
                Geometry3::new(e.kind, &x).map_err(|BadReferenceGeometry { gauss_point, det_j }| {
                    Solve3Error::BadElement {
                        element: k,
                        gauss_point,
                        det_j,
                    }
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(System {
            eq,
            n_eq,
            pattern,
            slots,
            geometries,
        })
    }

    /// The internal force minus the pressure loads at `lambda` at every dof, and the tangent's
    /// values (the elements' minus the pressures' load stiffness) on the pattern at `u`; with
    /// `step` (a displacement increment of the prescribed dofs, zero elsewhere) also
    /// `K step` at every dof, the linearized force of the prescribed increment, in `coupling`.
    fn assemble(
        &self,
        body: &Body3,
        u: &[[f64; 3]],
        values: &mut [f64],
        force: &mut [f64],
        lambda: f64,
        step: Option<(&[f64], &mut [f64])>,
    ) -> Result<(), (usize, f64)> {
        values.fill(0.0);
        force.fill(0.0);
        let mut step = step;
        if let Some((_, coupling)) = step.as_mut() {
            coupling.fill(0.0);
        }
        let mut fe = [0.0; MAX_DOFS_3D];
        let mut ke = vec![0.0; MAX_DOFS_3D * MAX_DOFS_3D];
        for (k, e) in body.elements.iter().enumerate() {
            let ue: Vec<[f64; 3]> = e.nodes.iter().map(|&n| u[n]).collect();
            let mut out = ElementResult {
                energy: 0.0,
                force: &mut fe,
                stiffness: Some(&mut ke),
            };
            evaluate(
                &self.geometries[k],
                &*body.materials[e.material],
                &ue,
                &mut out,
            )
            .map_err(|j| (k, j.0))?;
            let nd = 3 * e.nodes.len();
            for (r, &f) in fe[..nd].iter().enumerate() {
                force[3 * e.nodes[r / 3] + r % 3] += f;
            }
            for (slot, v) in self.slots[k].iter().zip(&ke[..nd * nd]) {
                if *slot != usize::MAX {
                    values[*slot] += v;
                }
            }
            if let Some((dp, coupling)) = step.as_mut() {
                let dof = |r: usize| 3 * e.nodes[r / 3] + r % 3;
                for r in 0..nd {
                    let s: f64 = (0..nd).map(|c| ke[r * nd + c] * dp[dof(c)]).sum();
                    coupling[dof(r)] += s;
                }
            }
        }
        let (mut ff, mut kf) = ([0.0; MAX_FACE_DOFS], [0.0; MAX_FACE_DOFS * MAX_FACE_DOFS]);
        for (nodes, p) in &body.pressures {
            let x: Vec<[f64; 3]> = nodes
                .iter()
                .map(|&n| std::array::from_fn(|i| body.nodes[n][i] + u[n][i]))
                .collect();
            face_pressure(&x, lambda * p, &mut ff, Some(&mut kf));
            let nd = 3 * nodes.len();
            let dof = |r: usize| 3 * nodes[r / 3] + r % 3;
            for r in 0..nd {
                force[dof(r)] -= ff[r];
                let row = self.eq[dof(r)];
                for c in 0..nd {
                    let col = self.eq[dof(c)];
                    if row != usize::MAX && col != usize::MAX {
                        let pos = self
                            .pattern
                            .position(row, col)
                            .expect("a face of an element");
                        values[pos] -= kf[r * nd + c];
                    }
                }
                if let Some((dp, coupling)) = step.as_mut() {
                    let s: f64 = (0..nd).map(|c| kf[r * nd + c] * dp[dof(c)]).sum();
                    coupling[dof(r)] -= s;
                }
            }
        }
        Ok(())
    }
}

/// Solves `body` for equilibrium: the prescribed displacements and the loads applied in
/// [`Options3::increments`] equal steps, full Newton–Raphson in each. The first iteration of
/// an increment starts from the converged state of the last one and moves the prescribed dofs
/// through the tangent (`K_ff du_f = r_f - K_fp Δu_p`), so that a prescribed increment does not
/// distort the elements next to it.
pub fn solve(body: &Body3, options: &Options3) -> Result<Solution3, Solve3Error> {
    let system = System::new(body)?;
    let n_dof = 3 * body.nodes.len();
    let mut solver = SparseSolver::new(&system.pattern, None)?;
    let mut values = vec![0.0; system.pattern.nnz()];
    let mut force = vec![0.0; n_dof];
    let mut load = vec![0.0; n_dof];
    for &(node, i, f) in &body.loads {
        load[3 * node + i] += f;
    }
    let load_scale = load.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut u = vec![[0.0; 3]; body.nodes.len()];
    let mut iterations = Vec::with_capacity(options.increments);
    let mut rhs = vec![0.0; system.n_eq];
    let mut dp = vec![0.0; n_dof];
    let mut coupling = vec![0.0; n_dof];
    for step in 1..=options.increments {
        let lambda = step as f64 / options.increments as f64;
        for &(node, i, value) in &body.prescribed {
            dp[3 * node + i] = lambda * value - u[node][i];
        }
        let mut converged = None;
        let mut residual = f64::INFINITY;
        for iteration in 0..=options.max_iterations {
            let first = iteration == 0;
            let predictor = first.then_some((&dp[..], &mut coupling[..]));
            system
                .assemble(body, &u, &mut values, &mut force, lambda, predictor)
                .map_err(|(element, j)| Solve3Error::Inverted {
                    element,
                    j,
                    load_factor: lambda,
                })?;
            let scale = force
                .iter()
                .fold(lambda * load_scale, |m, v| m.max(v.abs()));
            residual = 0.0;
            for (d, &q) in system.eq.iter().enumerate() {
                if q != usize::MAX {
                    rhs[q] = lambda * load[d] - force[d];
                    residual = residual.max(rhs[q].abs());
                    if first {
                        rhs[q] -= coupling[d];
                    }
                }
            }
            if !first && residual <= options.tolerance * scale {
                converged = Some(iteration);
                break;
            }
            if iteration == options.max_iterations {
                break;
            }
            solver.factorize(&system.pattern, &values)?;
            solver.solve_in_place(&mut rhs);
            for (d, &q) in system.eq.iter().enumerate() {
                if q != usize::MAX {
                    u[d / 3][d % 3] += rhs[q];
                }
            }
            if first {
                for &(node, i, _) in &body.prescribed {
                    u[node][i] += dp[3 * node + i];
                }
            }
        }
        match converged {
            Some(k) => iterations.push(k),
            None => {
                return Err(Solve3Error::NotConverged {
                    load_factor: lambda,
                    residual,
                    iterations: options.max_iterations,
                })
            }
        }
    }
    Ok(Solution3 {
        u,
        internal_force: force,
        iterations,
    })
}

/// The exact parameter sensitivities of a solved body (direct differentiation, as the
/// plane-strain [`crate::sensitivity`]): for material m and parameter k of its law,
/// `du/dθ` at every node from `K_ff du_f = -∂f_int,f/∂θ` at the solution, K the tangent with
/// the pressures' load stiffness (the prescribed displacements and the loads do not depend on
/// θ). Returned as `[m][k][node]`.
pub fn sensitivities(
    body: &Body3,
    solution: &Solution3,
) -> Result<Vec<Vec<Vec<[f64; 3]>>>, Solve3Error> {
    let system = System::new(body)?;
    let n_dof = 3 * body.nodes.len();
    let mut values = vec![0.0; system.pattern.nnz()];
    let mut force = vec![0.0; n_dof];
    system
        .assemble(body, &solution.u, &mut values, &mut force, 1.0, None)
        .map_err(|(element, j)| Solve3Error::Inverted {
            element,
            j,
            load_factor: 1.0,
        })?;
    let mut solver = SparseSolver::new(&system.pattern, None)?;
    solver.factorize(&system.pattern, &values)?;
    let mut out = Vec::with_capacity(body.materials.len());
    for (m, material) in body.materials.iter().enumerate() {
        let count = material.spec().parameters.len();
        let mut rhs = vec![vec![0.0; system.n_eq]; count];
        let mut rates = vec![0.0; count * MAX_DOFS_3D];
        for (e, element) in body.elements.iter().enumerate() {
            if element.material != m {
                continue;
            }
            let ue: Vec<[f64; 3]> = element.nodes.iter().map(|&n| solution.u[n]).collect();
            material
                .rate_forces_3d(&system.geometries[e], &ue, &mut rates)
                .map_err(|j| Solve3Error::Inverted {
                    element: e,
                    j: j.0,
                    load_factor: 1.0,
                })?;
            for (k, column) in rhs.iter_mut().enumerate() {
                for (r, v) in rates[k * MAX_DOFS_3D..][..3 * element.nodes.len()]
                    .iter()
                    .enumerate()
                {
                    let q = system.eq[3 * element.nodes[r / 3] + r % 3];
                    if q != usize::MAX {
                        column[q] -= v;
                    }
                }
            }
        }
        let mut per_parameter = Vec::with_capacity(count);
        for mut column in rhs {
            solver.solve_in_place(&mut column);
            let mut du = vec![[0.0; 3]; body.nodes.len()];
            for (d, &q) in system.eq.iter().enumerate() {
                if q != usize::MAX {
                    du[d / 3][d % 3] = column[q];
                }
            }
            per_parameter.push(du);
        }
        out.push(per_parameter);
    }
    Ok(out)
}
