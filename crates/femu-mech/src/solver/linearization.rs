//! The linearized equilibrium at a converged state, as the sensitivities need it
//! ([`crate::sensitivity`]): the state, the tangent `K_T` there, factors of `K_T` (or of the
//! tangent of the last Newton iterate, one tiny correction away, which iterative refinement
//! corrects), the contact constraints active there, and the equation numbering.
//!
//! Obtained from a solver with [`StaticSolver::linearize`]; it borrows the solver's tangent and
//! factors (no copy), so that the solver cannot change them while it lives.

use super::assembly::{AssemblyError, DofMap};
use super::contact_state::ActiveConstraint;
use super::factor::TangentFactor;
use super::StaticSolver;
use crate::model::Model;
use femu_sparse::{CscPattern, Factorization, LinearSolveError};

/// The linearized equilibrium `K_T δu = -δR` at a state (see the module docs).
#[derive(Debug)]
pub struct Linearization<'s> {
    state: &'s [f64],
    dofs: &'s DofMap,
    pattern: &'s CscPattern,
    /// `K_T` at `state`, values on `pattern`.
    tangent: &'s [f64],
    factor: &'s mut TangentFactor,
    active: Vec<ActiveConstraint>,
    /// The gap gradients of the frictionless interfaces' slave nodes in contact.
    interface_active: Vec<Vec<(usize, f64)>>,
    residual_tolerance: f64,
    /// The solver's element-matrix buffer, idle until its next assembly.
    scratch: &'s mut Vec<f64>,
}

impl StaticSolver {
    /// The linearization at `state` (length [`Model::state_len`]), a converged state of the last
    /// solve of `model` (its contact multipliers define the active set). The tangent is
    /// assembled at `state` unless the last assembly already was (a successful solve ends with
    /// it, see [`super::SolverOptions::final_tangent`]); the factors are those of the last
    /// factorization, if any (see [`Linearization::has_factors`]).
    pub fn linearize<'s>(
        &'s mut self,
        model: &Model,
        state: &'s [f64],
    ) -> Result<Linearization<'s>, AssemblyError> {
        if !self.assembly.tangent_is_at(state) {
            self.assemble(model, state, 1.0, true)?;
        }
        let active = self.contact.active_constraints(model, state);
        let interface_active = self.contact.interfaces.active_gradients(model, state);
        let assembly = &mut self.assembly;
        Ok(Linearization {
            state,
            dofs: &assembly.dofs,
            pattern: &assembly.pattern,
            tangent: &assembly.system.values,
            factor: &mut self.factor,
            active,
            interface_active,
            residual_tolerance: self.options.residual_tolerance,
            scratch: &mut assembly.ke,
        })
    }
}

impl Linearization<'_> {
    /// The state linearized about.
    pub fn state(&self) -> &[f64] {
        self.state
    }

    /// Number of equations (free dofs).
    pub fn equations(&self) -> usize {
        self.dofs.n_eq
    }

    /// Equation number of each state dof (`None` for a prescribed dof).
    pub fn equation_of(&self, dof: usize) -> Option<usize> {
        self.dofs.equation_of(dof)
    }

    /// The contact constraints active at the state: every candidate node whose contact force
    /// `⟨λ̂ - ε g⟩₊` is positive.
    pub fn active_constraints(&self) -> &[ActiveConstraint] {
        &self.active
    }

    /// The constraints of the frictionless sliding interfaces active at the state: for each
    /// slave node with a positive contact force, its gap gradient as `(state dof, value)` over
    /// the node and its master segment's two nodes ([`crate::interface::SegmentGap`]).
    pub fn interface_constraints(&self) -> &[Vec<(usize, f64)>] {
        &self.interface_active
    }

    /// The relative force-residual tolerance the state was converged to
    /// ([`super::SolverOptions::residual_tolerance`]).
    pub fn residual_tolerance(&self) -> f64 {
        self.residual_tolerance
    }

    /// Whether factors are available: of `K_T` itself after [`Self::factorize`], otherwise of
    /// the tangent the solver factorized last (the last Newton iterate's).
    pub fn has_factors(&self) -> bool {
        self.factor.has_factors()
    }

    /// Factorizes `K_T` at the state.
    pub fn factorize(&mut self) -> Result<Factorization, LinearSolveError> {
        self.factor.factorize(self.pattern, self.tangent)
    }

    /// Solves with the current factors (see [`Self::has_factors`]) for `columns` (≤
    /// [`femu_sparse::MAX_RHS`]) right-hand sides stored one after the other, in one pass over
    /// the factors.
    pub fn solve_many(&mut self, rhs: &mut [f64], columns: usize) {
        self.factor.solve_many(rhs, columns);
    }

    /// `Y = K_T X` on the free dofs for `cols` vectors stored interleaved (`x[i * cols + j]`
    /// is equation `i` of vector `j`): one pass over the matrix.
    pub fn tangent_mul_many_interleaved(&self, x: &[f64], y: &mut [f64], cols: usize) {
        self.factor
            .mul_many_interleaved(self.pattern, self.tangent, x, y, cols);
    }

    /// Work memory (the solver's element-matrix buffer, `64` values per element, idle until its
    /// next assembly): swap it out and back. If it is not given back, the next assembly
    /// allocates it again.
    pub fn scratch(&mut self) -> &mut Vec<f64> {
        self.scratch
    }
}
