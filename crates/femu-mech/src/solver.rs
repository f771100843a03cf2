//! Static nonlinear solver: load increments, Newton–Raphson with line search and automatic
//! cut-back, sparse factorization whose pattern and symbolic analysis are built once per model.
//!
//! Residual `R(u, λ) = f_int(u) - λ f_ext(u)` on the free dofs; prescribed displacements are set
//! to `λ ū` and eliminated. One increment converges when both
//! `‖R‖₂ ≤ rtol · max(‖λ f_ext‖₂, ‖reactions‖₂)` and the energy norm
//! `|δu · R| ≤ etol · |δu₀ · R₀|` hold (δu: the correction just applied, δu₀, R₀: first
//! iteration of the increment); the increments before the last only need
//! `‖R‖₂ ≤ itol · max(...)` (see [`SolverOptions::intermediate_tolerance`]).
//!
//! [`StaticSolver`] is made of four parts, one file each:
//! - `assembly`: dof numbering, sparse pattern, element slots and the gathers that sum
//!   element results in element order, point loads and follower pressure;
//! - `contact_state`: the rigid bodies' penalties, multipliers, active sets and step limit;
//! - `factor`: the tangent's factorization ([`femu_sparse::SparseSolver`]) and its timers;
//! - `newton`: the driver (increments, Newton, line search, cut-back) and its reports, written
//!   once for any problem through `system::NewtonSystem` (assemble the residual and the tangent
//!   at a state, their norms, the correction, the contact hooks): the plane-strain problem
//!   (`system::Plane`, the parts above) and the 3D solve of [`crate::solid3d`] implement it.
//!
//! The sensitivities read a converged state through [`Linearization`] (`linearization`):
//! the state, its tangent, the factors and the active contact constraints.

mod active_set;
pub(crate) mod assembly;
mod contact_state;
pub(crate) mod factor;
mod interface_state;
mod linearization;
pub(crate) mod newton;
pub(crate) mod report;
pub(crate) mod system;

pub use active_set::eigen3 as symmetric_eigen3;
pub use assembly::AssemblyError;
pub use contact_state::ActiveConstraint;
pub use linearization::Linearization;
pub use report::{IncrementRecord, IterationRecord, Solution, SolveReport};

use crate::model::Model;
use assembly::{Assembly, DofMap, Layout};
use contact_state::ContactState;
use factor::{EquationPlan, TangentFactor};
use femu_sparse::{CscPattern, LinearSolveError, NodeGraph};
use newton::NewtonWork;
use serde::{Deserialize, Serialize};
use std::time::Instant;
use system::{NewtonSystem, Plane};

/// Newton and increment settings.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct SolverOptions {
    /// Relative force-residual tolerance.
    pub residual_tolerance: f64,
    /// Relative energy-norm tolerance: the energy `|δu·R|` of the last applied correction over
    /// that of the first. Newton converges quadratically, so when the correction of energy ratio
    /// 1e-9 has been applied the remaining error is far smaller still (the next ratio is
    /// typically below 1e-17).
    pub energy_tolerance: f64,
    /// Relative force-residual tolerance of the increments before the last one. A hyperelastic
    /// body in frictionless contact has a path-independent solution: the intermediate
    /// increments only lead Newton to the final load, so they stop at this looser residual (no
    /// energy test) and the last increment is converged to [`Self::residual_tolerance`] and
    /// [`Self::energy_tolerance`]. The default 2e-2 (of the 2-norm of the load) sits near
    /// Abaqus's default (5e-3 of the time-averaged force, in the max-norm, applied to every
    /// increment): on the paper-scale compression test it lets most increments stop after
    /// two or three iterations, 25 in all against 32 with 1e-3, for the same final state. Set
    /// it equal to `residual_tolerance` to converge every increment fully.
    pub intermediate_tolerance: f64,
    /// Newton iterations per increment before a cut-back.
    pub max_iterations: usize,
    /// Backtracking line search on the directional residual.
    pub line_search: bool,
    /// Increment growth factor after an easy increment (≤ 4 iterations; the increment doubles
    /// after ≤ 2 whatever this is). Counted with the looser [`Self::intermediate_tolerance`],
    /// which saves one or two iterations per increment. An increment that grew too far is
    /// cut back (see [`Self::cutback`]); one whose Newton crawls is cut back early.
    pub growth: f64,
    /// Increment reduction factor on a cut-back (Abaqus uses 0.25).
    pub cutback: f64,
    /// Models with at least this many free node equations are bisected and the symmetric
    /// tangent factorized by halves in parallel ([`femu_sparse::SplitLdlt`]); smaller ones
    /// whole. Both are exact direct solves.
    pub split_min_equations: usize,
    /// Whether the last iteration of the last increment assembles the tangent at the
    /// converged state too. [`crate::sensitivity::DirectSensitivity`] reuses that tangent (it
    /// assembles it itself when it is not there); a solve whose tangent nobody reads (`femu
    /// solve`) saves one tangent assembly with `false`. Either way the state is the same: the
    /// tangent of an iteration is left out only when the iteration's correction already passes
    /// the energy test, and if its residual then fails, the tangent is assembled before the
    /// next one.
    pub final_tangent: bool,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            residual_tolerance: 1e-8,
            energy_tolerance: 1e-9,
            intermediate_tolerance: 2e-2,
            max_iterations: 20,
            line_search: true,
            growth: 2.0,
            cutback: 0.25,
            split_min_equations: 10_000,
            final_tangent: true,
        }
    }
}

/// Why a solve did not reach the end of the step; `S` is the solution of the last converged
/// state inside ([`Solution`] for the plane-strain solver, [`crate::solid3d::Solution3`] for the
/// 3D one).
#[derive(thiserror::Error)]
pub enum SolveError<S = Solution> {
    #[error("Newton did not converge: {reason} (load factor reached {lambda:.4}, increment size {dlambda:.3e} below the minimum {min:.3e})")]
    NotConverged {
        reason: String,
        lambda: f64,
        dlambda: f64,
        min: f64,
        /// The last converged state and the full increment history.
        partial: Box<S>,
    },
    #[error("more than {max} increments needed (load factor reached {lambda:.4})")]
    TooManyIncrements {
        max: usize,
        lambda: f64,
        partial: Box<S>,
    },
    #[error("linear solver setup failed: {0}")]
    Setup(#[from] LinearSolveError),
    #[error("the tangent has {entries} entries, more than this solver addresses (2^32)")]
    TooLarge { entries: usize },
    #[error("the undeformed state cannot be assembled: {0}")]
    Undeformed(#[source] AssemblyError),
    /// The user asked to stop ([`femu_mesh::stop`]): between two Newton iterations.
    #[error("solve interrupted")]
    Interrupted(#[source] femu_mesh::stop::Interrupted),
}

impl<S> std::fmt::Debug for SolveError<S> {
    /// The message only: the partial solution inside would print every nodal value.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SolveError({self})")
    }
}

/// The static solver of one model: dof numbering, sparse pattern, symbolic factorization and
/// every buffer, built once; [`StaticSolver::solve`] can then be called many times (e.g. with
/// other material parameters) without allocating inside Newton iterations.
pub struct StaticSolver {
    pub options: SolverOptions,
    assembly: Assembly,
    contact: ContactState,
    /// The contact set of each Newton correction (see [`active_set`]).
    active_set: active_set::ActiveSetSolver,
    factor: TangentFactor,
    work: NewtonWork,
    setup_time_s: f64,
}

impl std::fmt::Debug for StaticSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StaticSolver")
            .field("equations", &self.assembly.dofs.n_eq)
            .field("nonzeros", &self.assembly.pattern.nnz())
            .finish()
    }
}

impl StaticSolver {
    /// Numbers the dofs, builds the sparse pattern and the symbolic factorization.
    pub fn new(model: &Model, options: SolverOptions) -> Result<Self, SolveError> {
        let t0 = Instant::now();
        let dofs = DofMap::new(model);
        // Each slave node of an interface is coupled with the nodes of its candidate segments
        // (none without interfaces: the graph of the elements alone).
        let groups: Vec<Vec<usize>> = model
            .interfaces
            .iter()
            .flat_map(|i| i.coupled_nodes())
            .collect();
        let graph = NodeGraph::from_elements(
            model.node_count(),
            model
                .mesh
                .elements
                .iter()
                .map(|e| e.nodes())
                .chain(groups.iter().map(Vec::as_slice)),
        );
        // Bordered system: each force-controlled body couples its travel with the free dofs of
        // its candidate nodes; the travels are numbered and eliminated last.
        let borders = dofs.borders(model);
        // The ordering (the longest step) on one thread, the pattern and the element slots on
        // the other.
        let (plan, layout) = rayon::join(
            || EquationPlan::new(&graph, &dofs, options.split_min_equations),
            || Layout::new(model, &graph, &dofs, &borders),
        );
        let plan = plan?.with_borders(&borders);
        let layout = layout.map_err(|entries| SolveError::TooLarge { entries })?;
        // The symbolic analysis before the assembly's buffers are allocated, as their work
        // memories are not held at the same time (the peak memory of a solve).
        let factor = TangentFactor::new(plan.analyse(&layout.pattern)?);
        let contact = ContactState::new(model, &dofs, &layout.pattern);
        let assembly = Assembly::new(model, dofs, layout);
        Ok(StaticSolver {
            options,
            work: NewtonWork::new(assembly.dofs.n_eq, model.state_len()),
            assembly,
            contact,
            active_set: Default::default(),
            factor,
            setup_time_s: t0.elapsed().as_secs_f64(),
        })
    }

    /// Number of equations (free dofs).
    pub fn equations(&self) -> usize {
        self.assembly.dofs.n_eq
    }

    /// Equation number of each dof (`None` for a prescribed dof).
    pub fn equation_of(&self, dof: usize) -> Option<usize> {
        self.assembly.dofs.equation_of(dof)
    }

    /// The sparse pattern of the tangent on the free dofs.
    pub fn pattern(&self) -> &CscPattern {
        &self.assembly.pattern
    }

    /// Assembles residual and tangent at the state `u` (length [`Model::state_len`]), λ = 1
    /// (for derivative checks).
    pub fn assemble_at(&mut self, model: &Model, u: &[f64]) -> Result<(), AssemblyError> {
        self.assemble(model, u, 1.0, true)
    }

    /// Assembles only the residual at the state `u` and λ = 1 and returns it (length
    /// [`Model::state_len`]: 2 per node, then one per rigid body).
    pub fn residual_at(&mut self, model: &Model, u: &[f64]) -> Result<&[f64], AssemblyError> {
        self.assemble(model, u, 1.0, false)?;
        Ok(&self.assembly.system.residual)
    }

    /// The tangent on the free dofs at the last assembly with tangent (values on
    /// [`Self::pattern`]).
    pub fn tangent_values(&self) -> &[f64] {
        &self.assembly.system.values
    }

    /// Sets the automatic contact penalties as a solve does (for derivative checks of
    /// [`Self::assemble_at`] with contact).
    pub fn prepare_contact(&mut self, model: &Model) -> Result<(), AssemblyError> {
        self.init_contact(model)
    }

    /// The state of every sliding interface's slave nodes at `u` (a state of this solver's
    /// last solve: its penalties, multipliers and stick points), one list per
    /// [`Model::interfaces`].
    pub fn interface_states(
        &self,
        model: &Model,
        u: &[f64],
    ) -> Vec<Vec<crate::interface::SlaveState>> {
        self.contact.interfaces.states(model, u)
    }

    /// Uzawa updates of each interface's multipliers in the last solve.
    pub fn interface_augmentations(&self) -> Vec<usize> {
        self.contact.interfaces.augmentations()
    }

    /// Whether the last assembly was of the tangent at `u` and λ = 1.
    #[cfg(test)]
    pub(crate) fn tangent_is_at(&self, u: &[f64]) -> bool {
        self.assembly.tangent_is_at(u)
    }

    /// Assembles the residual (always) and the tangent (if `with_tangent`) at `u`, load factor
    /// `lambda`, with the contact terms.
    fn assemble(
        &mut self,
        model: &Model,
        u: &[f64],
        lambda: f64,
        with_tangent: bool,
    ) -> Result<(), AssemblyError> {
        system::assemble_plane(
            &mut self.assembly,
            &mut self.contact,
            model,
            u,
            lambda,
            with_tangent,
        )
    }

    /// Sets each body's penalty from the largest diagonal stiffness of its candidate dofs at
    /// the undeformed state (the "automatic penalty") and clears the multipliers.
    fn init_contact(&mut self, model: &Model) -> Result<(), AssemblyError> {
        Plane {
            model,
            assembly: &mut self.assembly,
            contact: &mut self.contact,
            active_set: &mut self.active_set,
            factor: &mut self.factor,
        }
        .init_contact()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::DeckBuilder;
    use femu_mesh::generate;
    use femu_mesh::ElementKind;

    /// A solve whose element-matrix buffer was borrowed (through [`Linearization::scratch`])
    /// and not given back allocates it again and gives the same state.
    #[test]
    fn element_scratch_not_given_back_is_reallocated() {
        let g = generate::rectangle(2.0, 1.0, 5, 3, ElementKind::Cpe4);
        let deck = DeckBuilder::new(g)
            .material_everywhere(0.01, 1.0)
            .fix("BOTTOM")
            .displacement("TOP", 1, 0.1)
            .build();
        let model = Model::from_deck(deck).unwrap();
        let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
        let first = solver.solve(&model).unwrap();
        let taken = std::mem::take(solver.linearize(&model, &first.state).unwrap().scratch());
        assert_eq!(taken.len(), model.mesh.elements.len() * 64);
        let again = solver.solve(&model).unwrap();
        assert_eq!(first.u, again.u);
        let lin_again = solver
            .linearize(&model, &again.state)
            .unwrap()
            .scratch()
            .len();
        assert_eq!(lin_again, taken.len());
    }

    /// `final_tangent: false` leaves out the tangent of the converged state and nothing else:
    /// the same Newton path and state to the bit, the tangent not claimed to be at the
    /// solution, and the sensitivities (which then assemble it themselves) unchanged.
    #[test]
    fn final_tangent_left_out_changes_nothing_else() {
        let g = generate::rectangle(2.0, 1.0, 8, 4, ElementKind::Cpe4);
        let deck = DeckBuilder::new(g)
            .material_everywhere(0.01, 1.0)
            .fix("BOTTOM")
            .displacement("TOP", 1, -0.2)
            .build();
        let model = Model::from_deck(deck).unwrap();
        let params = crate::sensitivity::all_parameters(&model);
        let run = |final_tangent: bool| {
            let options = SolverOptions {
                final_tangent,
                ..SolverOptions::default()
            };
            let mut solver = StaticSolver::new(&model, options).unwrap();
            let sol = solver.solve(&model).unwrap();
            let at_solution = solver.tangent_is_at(&sol.state);
            let mut du = Vec::new();
            crate::sensitivity::DirectSensitivity::new()
                .compute(&mut solver, &model, &sol.state, &params, &mut du)
                .unwrap();
            (sol, at_solution, du)
        };
        let (with, with_at, du_with) = run(true);
        let (without, without_at, du_without) = run(false);
        assert!(with_at, "the default keeps the tangent at the solution");
        assert!(
            !without_at,
            "the tangent at the solution was assembled anyway"
        );
        assert_eq!(with.state, without.state);
        assert_eq!(
            with.report.newton_iterations,
            without.report.newton_iterations
        );
        // Both refine against the same factors to the same tolerance (1e-8 of the right-hand
        // sides): they agree to far better than that.
        let scale = du_with.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = du_with
            .iter()
            .flatten()
            .zip(du_without.iter().flatten())
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            diff <= 1e-10 * scale,
            "sensitivities differ by {diff:e} of {scale:e}"
        );
    }

    /// A node no element uses (an Abaqus reference point) is held at zero and changes nothing
    /// else (issue 32.1: it used to make a singular row, NaN in `displacements.csv` and a VTU
    /// writer error); a point load on it is refused when the model is built.
    #[test]
    fn a_node_no_element_uses_is_held_at_zero() {
        let deck = |extra_node: &str, extra_load: &str| {
            format!(
                "*NODE\n1, 0, 0\n2, 1, 0\n3, 1, 1\n4, 0, 1\n{extra_node}\
                 *ELEMENT, TYPE=CPE4, ELSET=A\n1, 1, 2, 3, 4\n\
                 *MATERIAL, NAME=M\n*HYPERELASTIC, NEO HOOKE\n0.01, 1.0\n\
                 *SOLID SECTION, ELSET=A, MATERIAL=M\n*BOUNDARY\n1, 1, 2\n2, 2, 2\n\
                 *STEP, NLGEOM\n*STATIC\n1.0, 1.0\n*CLOAD\n3, 1, 1e-3\n{extra_load}*END STEP\n"
            )
        };
        let solve = |text: &str| {
            let model =
                Model::from_deck(femu_mesh::inp::parse_inp(text, "t.inp").unwrap()).unwrap();
            let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
            let sol = solver.solve(&model).unwrap();
            (model, sol)
        };
        let (plain, without) = solve(&deck("", ""));
        let (model, with) = solve(&deck("9, 5, 5\n", ""));
        assert!(plain.unused_nodes().is_empty());
        assert_eq!(model.unused_nodes(), vec![4]);
        assert_eq!(&with.u[8..10], &[0.0, 0.0]);
        // The same equations in the same order: the same state to the bit.
        assert_eq!(&with.u[..8], &without.u[..]);
        let loaded =
            femu_mesh::inp::parse_inp(&deck("9, 5, 5\n", "9, 2, 1e-3\n"), "t.inp").unwrap();
        let e = Model::from_deck(loaded).unwrap_err();
        assert!(
            matches!(e, crate::model::ModelError::LoadOnUnusedNode(9)),
            "{e}"
        );
    }
}
