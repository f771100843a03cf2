//! A static 3D solve of the elements of [`crate::solid3d`]: global assembly on a sparse
//! pattern of [`femu_sparse`] (the same [`CscPattern`] and [`SparseSolver`], LDLᵀ or LU, as the
//! plane-strain solver), for prescribed displacements, dead nodal loads and follower pressures
//! on faces ([`super::pressure`]), solved by the plane-strain solver's Newton driver (load
//! increments with a linear predictor, Newton–Raphson with its convergence tests, line search
//! and cut-back, [`crate::solver::SolveReport`]) through `NewtonSystem` (in the solver's
//! `system` module); and the exact parameter sensitivities of a solution ([`sensitivities`]).
//!
//! No contact yet. Dof `3 n + i` is component i of node n; the free dofs are numbered in
//! increasing dof order.

use super::kernel::{evaluate, Geometry3, MAX_DOFS_3D, MAX_NODES_3D};
use super::pressure::{face_pressure, MAX_FACE_DOFS, MAX_FACE_NODES};
use super::shape::Kind3;
use crate::element::{BadReferenceGeometry, ElementResult};
use crate::material::Material;
use crate::solver::assembly::{AssemblyError, DofMap, System as Assembled, NONE};
use crate::solver::factor::TangentFactor;
use crate::solver::newton::{Newton, NewtonWork};
use crate::solver::system::NewtonSystem;
use crate::solver::{SolveError, SolveReport, SolverOptions};
use femu_mesh::StepDef;
use femu_sparse::{CscPattern, LinearSolveError, SparseSolver};
use std::time::Instant;

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
    /// The Newton driver did not reach the end of the load path (with the last converged
    /// state).
    #[error(transparent)]
    Newton(#[from] Box<SolveError<Solution3>>),
    #[error(transparent)]
    Linear(#[from] LinearSolveError),
}

/// Options of [`solve`].
#[derive(Debug, Clone, Copy)]
pub struct Options3 {
    /// The load increments: the step starts with increments of `1 / increments` and never
    /// takes larger ones (the driver cuts them back when Newton fails).
    pub increments: usize,
    /// Newton iterations allowed per increment (before a cut-back).
    pub max_iterations: usize,
    /// Relative force-residual tolerance of the last increment, as
    /// [`SolverOptions::residual_tolerance`]: `‖R‖₂ ≤ tolerance · max(‖λ f_ext‖₂,
    /// ‖reactions‖₂)` on the free dofs, with the energy test of the plane-strain solver.
    pub tolerance: f64,
}

impl Options3 {
    /// The Newton options of the plane-strain solver with these iterations and tolerance.
    fn solver_options(&self) -> SolverOptions {
        SolverOptions {
            residual_tolerance: self.tolerance,
            max_iterations: self.max_iterations,
            ..SolverOptions::default()
        }
    }

    /// The step: increments of `1 / increments`, at most that, at least 1e-5 of it.
    fn step(&self) -> StepDef {
        let size = 1.0 / self.increments.max(1) as f64;
        StepDef {
            initial_increment: size,
            max_increment: size,
            min_increment: 1e-5 * size,
            max_increments: 100 * self.increments.max(1),
            ..StepDef::default()
        }
    }
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
    /// Newton iterations of each converged increment.
    pub iterations: Vec<usize>,
    /// The Newton driver's report (increments, iterations, cut-backs, timings);
    /// `reaction_total` holds the x and y sums of the reactions.
    pub report: SolveReport,
}

/// The assembled system: equation numbers, sparse pattern, and each element's matrix slots.
struct System {
    /// The equation of each dof ([`NONE`] for a prescribed one) and the prescribed values.
    dofs: DofMap,
    pattern: CscPattern,
    /// Per element, the value position of each entry (r, c) of its matrix (row-major), or
    /// `usize::MAX` when a dof is prescribed.
    slots: Vec<Vec<usize>>,
    /// The same for each pressure face (`Body3::pressures`).
    face_slots: Vec<Vec<usize>>,
    geometries: Vec<Geometry3>,
}

impl System {
    fn new(body: &Body3) -> Result<Self, Solve3Error> {
        let n_dof = 3 * body.nodes.len();
        // A condition repeated on one dof keeps its last value (as in the plane-strain
        // numbering).
        let mut value: Vec<Option<f64>> = vec![None; n_dof];
        for &(node, i, v) in &body.prescribed {
            value[3 * node + i] = Some(v);
        }
        let mut eq = vec![NONE; n_dof];
        let mut n_eq = 0;
        let mut prescribed = Vec::new();
        for (d, v) in value.iter().enumerate() {
            match v {
                Some(v) => prescribed.push((d, *v)),
                None => {
                    eq[d] = n_eq;
                    n_eq += 1;
                }
            }
        }
        let node_eqs = |nodes: &[usize]| -> Vec<usize> {
            nodes
                .iter()
                .flat_map(|&n| [eq[3 * n], eq[3 * n + 1], eq[3 * n + 2]])
                .collect()
        };
        let mut pairs = Vec::new();
        for e in &body.elements {
            let eqs = node_eqs(&e.nodes);
            for &r in eqs.iter().filter(|&&r| r != usize::MAX) {
                for &c in eqs.iter().filter(|&&c| c != usize::MAX) {
                    pairs.push((r, c));
                }
            }
        }
        let pattern = CscPattern::from_pairs(n_eq, &mut pairs);
        // The value position of each entry of the matrix of `nodes` (row-major).
        let slots_of = |nodes: &[usize]| -> Vec<usize> {
            let eqs = node_eqs(nodes);
            eqs.iter()
                .flat_map(|&r| eqs.iter().map(move |&c| (r, c)))
                .map(|(r, c)| {
                    if r == usize::MAX || c == usize::MAX {
                        usize::MAX
                    } else {
                        pattern.position(r, c).expect("a face of an element")
                    }
                })
                .collect()
        };
        let slots = body.elements.iter().map(|e| slots_of(&e.nodes)).collect();
        let face_slots = body
            .pressures
            .iter()
            .map(|(nodes, _)| slots_of(nodes))
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
            dofs: DofMap {
                eq,
                n_eq,
                n_eq_nodes: n_eq,
                prescribed,
            },
            pattern,
            slots,
            face_slots,
            geometries,
        })
    }

    /// At the state `u` (3 per node): the internal force minus the pressure loads at `lambda`
    /// (`force`) and the pressure loads alone (`pressure`) at every dof, and (with `values`)
    /// the tangent's values on the pattern, the elements' minus the pressures' load stiffness.
    /// `Err((element, J))` for an inverted element.
    fn assemble(
        &self,
        body: &Body3,
        u: &[f64],
        values: Option<&mut [f64]>,
        force: &mut [f64],
        pressure: &mut [f64],
        lambda: f64,
    ) -> Result<(), (usize, f64)> {
        let mut values = values;
        if let Some(v) = values.as_deref_mut() {
            v.fill(0.0);
        }
        force.fill(0.0);
        pressure.fill(0.0);
        let node = |n: usize| [u[3 * n], u[3 * n + 1], u[3 * n + 2]];
        let mut fe = [0.0; MAX_DOFS_3D];
        let mut ke = vec![0.0; MAX_DOFS_3D * MAX_DOFS_3D];
        let mut ue = [[0.0; 3]; MAX_NODES_3D];
        for (k, e) in body.elements.iter().enumerate() {
            let ue = &mut ue[..e.nodes.len()];
            for (x, &n) in ue.iter_mut().zip(&e.nodes) {
                *x = node(n);
            }
            let mut out = ElementResult {
                energy: 0.0,
                force: &mut fe,
                stiffness: values.is_some().then_some(&mut ke[..]),
            };
            evaluate(
                &self.geometries[k],
                &*body.materials[e.material],
                ue,
                &mut out,
            )
            .map_err(|j| (k, j.0))?;
            let nd = 3 * e.nodes.len();
            for (r, &f) in fe[..nd].iter().enumerate() {
                force[3 * e.nodes[r / 3] + r % 3] += f;
            }
            if let Some(v) = values.as_deref_mut() {
                for (slot, k) in self.slots[k].iter().zip(&ke[..nd * nd]) {
                    if *slot != usize::MAX {
                        v[*slot] += k;
                    }
                }
            }
        }
        let (mut ff, mut kf) = ([0.0; MAX_FACE_DOFS], [0.0; MAX_FACE_DOFS * MAX_FACE_DOFS]);
        let mut x = [[0.0; 3]; MAX_FACE_NODES];
        for ((nodes, p), slots) in body.pressures.iter().zip(&self.face_slots) {
            let x = &mut x[..nodes.len()];
            for (x, &n) in x.iter_mut().zip(nodes) {
                *x = std::array::from_fn(|i| body.nodes[n][i] + u[3 * n + i]);
            }
            let with_tangent = values.is_some();
            face_pressure(x, lambda * p, &mut ff, with_tangent.then_some(&mut kf));
            let nd = 3 * nodes.len();
            let dof = |r: usize| 3 * nodes[r / 3] + r % 3;
            for r in 0..nd {
                force[dof(r)] -= ff[r];
                pressure[dof(r)] += ff[r];
            }
            if let Some(v) = values.as_deref_mut() {
                for (slot, k) in slots.iter().zip(&kf[..nd * nd]) {
                    if *slot != usize::MAX {
                        v[*slot] -= k;
                    }
                }
            }
        }
        Ok(())
    }
}

/// The 3D body as the Newton driver sees it ([`NewtonSystem`]): the residual
/// `R = f_int - f_pressure - λ f_dead` and its tangent at a state, on the body's sparse pattern.
struct Solid<'b> {
    body: &'b Body3,
    system: &'b System,
    factor: TangentFactor,
    /// `f_int - f_pressure` and `f_pressure` at every dof, at the last assembly.
    force: Vec<f64>,
    pressure: Vec<f64>,
    /// Dead nodal loads at λ = 1.
    load: Vec<f64>,
    /// Tangent values, residual, external force and right-hand side of the last assembly.
    assembled: Assembled,
    /// Time spent assembling (s).
    assembly_time_s: f64,
}

impl NewtonSystem for Solid<'_> {
    type Solution = Solution3;

    fn dofs(&self) -> &DofMap {
        &self.system.dofs
    }

    fn assemble(
        &mut self,
        u: &[f64],
        lambda: f64,
        with_tangent: bool,
    ) -> Result<(), AssemblyError> {
        let t = Instant::now();
        let a = &mut self.assembled;
        let values = with_tangent.then_some(&mut a.values[..]);
        self.system
            .assemble(
                self.body,
                u,
                values,
                &mut self.force,
                &mut self.pressure,
                lambda,
            )
            // The 3D body has no element labels: its element index.
            .map_err(|(element, det)| AssemblyError::Inverted {
                element_label: element as i64,
                det,
            })?;
        for (d, &q) in self.system.dofs.eq.iter().enumerate() {
            a.residual[d] = self.force[d] - lambda * self.load[d];
            a.fext[d] = self.pressure[d] + lambda * self.load[d];
            if q != NONE {
                a.rhs[q] = -a.residual[d];
            }
        }
        self.assembly_time_s += t.elapsed().as_secs_f64();
        Ok(())
    }

    fn norms(&self) -> (f64, f64) {
        self.assembled.norms(&self.system.dofs)
    }

    fn rhs(&self) -> &[f64] {
        &self.assembled.rhs
    }

    fn factorize(&mut self) -> Result<(), LinearSolveError> {
        self.factor
            .factorize(&self.system.pattern, &self.assembled.values)
            .map(|_| ())
    }

    fn solve_correction(&mut self, _u: &[f64], du: &mut [f64]) {
        self.factor.solve_many(du, 1);
    }

    fn solution(&self, u: &[f64], report: SolveReport) -> Solution3 {
        let reactions = self.assembled.reactions(&self.system.dofs);
        let mut report = report;
        report.factorization = self.factor.last();
        report.assembly_time_s = self.assembly_time_s;
        report.factorization_time_s = self.factor.factorization_time_s;
        report.triangular_solve_time_s = self.factor.solve_time_s;
        report.reaction_total = [
            reactions.iter().step_by(3).sum(),
            reactions.iter().skip(1).step_by(3).sum(),
        ];
        Solution3 {
            u: u.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            internal_force: self.force.clone(),
            iterations: report
                .increments
                .iter()
                .filter(|r| r.converged)
                .map(|r| r.iterations.len())
                .collect(),
            report,
        }
    }
}

/// Solves `body` for equilibrium with the Newton driver of the plane-strain solver
/// ([`crate::solver::StaticSolver`]): the prescribed displacements and the loads applied over
/// load increments of at most `1 / increments` ([`Options3`]), each predicted by extrapolating
/// the last two converged states with the prescribed dofs set, then Newton–Raphson with the
/// line search, and cut back when Newton fails (e.g. an element inverted by the predictor);
/// the last increment is converged to [`Options3::tolerance`].
pub fn solve(body: &Body3, options: &Options3) -> Result<Solution3, Solve3Error> {
    let t0 = Instant::now();
    let system = System::new(body)?;
    let n_dof = 3 * body.nodes.len();
    // A follower pressure on part of the skin makes the tangent unsymmetric by a small part:
    // refinement on the LDLᵀ of its symmetric part is several times cheaper than an LU on a
    // 3D mesh (`examples/solve3_cost.rs`), and falls back to LU where it does not converge.
    let mut sparse = SparseSolver::new(&system.pattern, None)?;
    sparse.refine_on_symmetric_part = true;
    let factor = TangentFactor::new(sparse);
    let mut load = vec![0.0; n_dof];
    for &(node, i, f) in &body.loads {
        load[3 * node + i] += f;
    }
    let n_eq = system.dofs.n_eq;
    let report = SolveReport {
        equations: n_eq,
        matrix_nonzeros: system.pattern.nnz(),
        setup_time_s: t0.elapsed().as_secs_f64(),
        ..Default::default()
    };
    let solid = Solid {
        body,
        system: &system,
        factor,
        force: vec![0.0; n_dof],
        pressure: vec![0.0; n_dof],
        load,
        assembled: Assembled {
            values: vec![0.0; system.pattern.nnz()],
            residual: vec![0.0; n_dof],
            fext: vec![0.0; n_dof],
            rhs: vec![0.0; n_eq],
        },
        assembly_time_s: 0.0,
    };
    let mut work = NewtonWork::new(n_eq, n_dof);
    Newton {
        options: options.solver_options(),
        work: &mut work,
        system: solid,
    }
    .solve_with(&options.step(), None, report, &mut |_| {}, t0)
    .map_err(|e| Solve3Error::Newton(Box::new(e)))
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
    let (mut force, mut pressure) = (vec![0.0; n_dof], vec![0.0; n_dof]);
    let u: Vec<f64> = solution.u.iter().flatten().copied().collect();
    system
        .assemble(body, &u, Some(&mut values), &mut force, &mut pressure, 1.0)
        .map_err(|(element, j)| Solve3Error::Inverted {
            element,
            j,
            load_factor: 1.0,
        })?;
    let mut solver = SparseSolver::new(&system.pattern, None)?;
    solver.refine_on_symmetric_part = true;
    solver.factorize(&system.pattern, &values)?;
    let mut out = Vec::with_capacity(body.materials.len());
    for (m, material) in body.materials.iter().enumerate() {
        let count = material.spec().parameters.len();
        let mut rhs = vec![vec![0.0; system.dofs.n_eq]; count];
        let mut rates = vec![0.0; count * MAX_DOFS_3D];
        let mut ue = [[0.0; 3]; MAX_NODES_3D];
        for (e, element) in body.elements.iter().enumerate() {
            if element.material != m {
                continue;
            }
            let ue = &mut ue[..element.nodes.len()];
            for (x, &n) in ue.iter_mut().zip(&element.nodes) {
                *x = solution.u[n];
            }
            material
                .rate_forces_3d(&system.geometries[e], ue, &mut rates)
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
                    let q = system.dofs.eq[3 * element.nodes[r / 3] + r % 3];
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
            for (d, &q) in system.dofs.eq.iter().enumerate() {
                if q != NONE {
                    du[d / 3][d % 3] = column[q];
                }
            }
            per_parameter.push(du);
        }
        out.push(per_parameter);
    }
    Ok(out)
}
