//! The seam between the Newton driver ([`super::newton::Newton`]) and a discretized problem:
//! [`NewtonSystem`], what the driver asks of a problem (assemble the residual and the tangent
//! at a state, their norms, the Newton correction, the dof numbering, the contact hooks, the
//! solution handed back), implemented by the plane-strain solver ([`Plane`]) and by the 3D solve
//! ([`crate::solid3d::assembly`]). The driver is written once, for both dimensions.

use super::active_set::ActiveSetSolver;
use super::assembly::{Assembly, AssemblyError, DofMap};
use super::contact_state::{ActiveSet, ContactState};
use super::factor::TangentFactor;
use super::report::{limit_point_hint, Solution, SolveReport};
use crate::model::Model;
use femu_sparse::LinearSolveError;

/// A discretized static problem as the Newton driver sees it: a state vector numbered by
/// [`NewtonSystem::dofs`] (free dofs are equations, prescribed ones are set by the driver),
/// the residual `R(u, λ) = f_int(u) - λ f_ext(u)` and its tangent at a state, and the
/// rigid-body contact hooks (a problem without rigid bodies keeps the defaults).
pub(crate) trait NewtonSystem {
    /// What a solve hands back (also inside the errors, as the last converged state).
    type Solution;

    /// The dof numbering of the state.
    fn dofs(&self) -> &DofMap;
    /// Assembles the residual (always) and the tangent (if `with_tangent`) at `u`, load factor
    /// `lambda`.
    fn assemble(&mut self, u: &[f64], lambda: f64, with_tangent: bool)
        -> Result<(), AssemblyError>;
    /// ‖R‖₂ on the free dofs and the reference force scale `max(‖λ f_ext‖₂, ‖reactions‖₂)`, at
    /// the last assembly.
    fn norms(&self) -> (f64, f64);
    /// `-R` on the equations at the last assembly.
    fn rhs(&self) -> &[f64];
    /// Factorizes the tangent of the last assembly.
    fn factorize(&mut self) -> Result<(), LinearSolveError>;
    /// The Newton correction at `u`: `du` holds `-R` on entry and `K⁻¹ (-R)` on return, with
    /// the contact set of the correction solved for (see [`super::active_set`]).
    fn solve_correction(&mut self, u: &[f64], du: &mut [f64]);
    /// The solution at `u` (the last assembly was at `u`) with `report`.
    fn solution(&self, u: &[f64], report: SolveReport) -> Self::Solution;

    /// Whether the problem has rigid bodies.
    fn has_bodies(&self) -> bool {
        false
    }
    /// Sets the contact penalties for a solve from zero.
    fn init_contact(&mut self) -> Result<(), AssemblyError> {
        Ok(())
    }
    /// Whether the contact penalties are set (a warm start keeps them).
    fn has_penalties(&self) -> bool {
        false
    }
    /// Sets the contact multipliers that balance the residual at `u` (a warm start from a
    /// state this problem has not solved; the penalties are set); forces below
    /// `residual_tolerance` times the reference force are none.
    fn estimate_multipliers(
        &mut self,
        _u: &[f64],
        _residual_tolerance: f64,
    ) -> Result<(), AssemblyError> {
        Ok(())
    }
    /// The contact set of the last assembly.
    fn active_set(&self) -> ActiveSet {
        (0, 0)
    }
    /// The largest step in (0, 1] from `u` towards `full` (the full correction) that keeps
    /// every free contact node out of the bodies beyond a tenth of an element.
    fn step_limit(&self, _u: &[f64], _full: &[f64]) -> f64 {
        1.0
    }
    /// Moves the contact nodes that follow a curved body back onto it, at step `alpha`.
    fn second_order_correction(&self, _alpha: f64, _trial: &mut [f64]) {}
    /// An augmented-Lagrangian update of the contact multipliers at `u`; whether any changed.
    fn augment(&mut self, _u: &mut [f64], _force_tolerance: f64) -> bool {
        false
    }
    /// A copy of the contact multipliers.
    fn multipliers(&self) -> Vec<Vec<f64>> {
        Vec::new()
    }
    /// Restores multipliers copied by [`Self::multipliers`].
    fn restore_multipliers(&mut self, _saved: Vec<Vec<f64>>) {}
    /// Travel and contact force of each rigid body at `u`.
    fn body_records(&self, _u: &[f64]) -> Vec<[f64; 2]> {
        Vec::new()
    }
    /// Why increments may have stalled (a limit point), for the message of a failed solve.
    fn stall_hint(&self, _report: &SolveReport) -> Option<String> {
        None
    }
    /// Records the history of a converged increment at `u` (the friction stick points).
    fn commit(&mut self, _u: &[f64]) {}
}

/// The plane-strain problem: a model and the parts of its [`super::StaticSolver`].
pub(crate) struct Plane<'a> {
    pub model: &'a Model,
    pub assembly: &'a mut Assembly,
    pub contact: &'a mut ContactState,
    pub active_set: &'a mut ActiveSetSolver,
    pub factor: &'a mut TangentFactor,
}

/// Assembles the residual (always) and the tangent (if `with_tangent`) of `model` at `u`, load
/// factor `lambda`, with the contact terms (rigid bodies, then sliding interfaces).
pub(crate) fn assemble_plane(
    assembly: &mut Assembly,
    contact: &mut ContactState,
    model: &Model,
    u: &[f64],
    lambda: f64,
    with_tangent: bool,
) -> Result<(), AssemblyError> {
    assembly.assemble(model, u, lambda, with_tangent, |system| {
        contact.add_terms(model, u, lambda, with_tangent, system);
        if !model.interfaces.is_empty() {
            contact.interfaces.add_terms(model, u, with_tangent, system);
        }
    })
}

impl NewtonSystem for Plane<'_> {
    type Solution = Solution;

    fn dofs(&self) -> &DofMap {
        &self.assembly.dofs
    }

    fn assemble(
        &mut self,
        u: &[f64],
        lambda: f64,
        with_tangent: bool,
    ) -> Result<(), AssemblyError> {
        assemble_plane(
            self.assembly,
            self.contact,
            self.model,
            u,
            lambda,
            with_tangent,
        )
    }

    fn norms(&self) -> (f64, f64) {
        self.assembly.system.norms(&self.assembly.dofs)
    }

    fn rhs(&self) -> &[f64] {
        &self.assembly.system.rhs
    }

    fn factorize(&mut self) -> Result<(), LinearSolveError> {
        self.factor
            .factorize(&self.assembly.pattern, &self.assembly.system.values)
            .map(|_| ())
    }

    fn solve_correction(&mut self, u: &[f64], du: &mut [f64]) {
        self.factor.solve_many(du, 1);
        if !self.model.contacts.is_empty() {
            self.contact.linearize(
                self.model,
                u,
                &self.assembly.dofs.eq,
                &mut self.active_set.candidates,
            );
            let store = &mut self.assembly.ke;
            self.active_set.correct(self.factor, du, store);
        }
    }

    /// The solution at `u` with the reactions of the last assembly and the solver's timers.
    fn solution(&self, u: &[f64], report: SolveReport) -> Solution {
        let n = 2 * self.model.node_count();
        let reactions = self.assembly.system.reactions(&self.assembly.dofs);
        let mut report = report;
        report.factorization = self.factor.last();
        report.assembly_time_s = self.assembly.time_s;
        report.factorization_time_s = self.factor.factorization_time_s;
        report.triangular_solve_time_s = self.factor.solve_time_s;
        report.reaction_total = [
            reactions[..n].iter().step_by(2).sum(),
            reactions[..n].iter().skip(1).step_by(2).sum(),
        ];
        Solution {
            u: u[..n].to_vec(),
            state: u.to_vec(),
            bodies: self.contact.body_states(self.model, u),
            reactions: reactions[..n].to_vec(),
            report,
        }
    }

    fn has_bodies(&self) -> bool {
        !self.model.contacts.is_empty()
    }

    /// Sets each body's penalty from the largest diagonal stiffness of its candidate dofs at
    /// the undeformed state (the "automatic penalty") and clears the multipliers.
    fn init_contact(&mut self) -> Result<(), AssemblyError> {
        if self.model.contacts.is_empty() && self.model.interfaces.is_empty() {
            return Ok(());
        }
        let zero = vec![0.0; self.model.state_len()];
        self.contact.clear_penalties();
        self.contact.interfaces.clear_penalties();
        self.assemble(&zero, 0.0, true)?;
        self.contact
            .set_penalties(self.model, &self.assembly.system.values);
        self.contact
            .interfaces
            .set_penalties(self.model, &self.assembly.system.values);
        Ok(())
    }

    fn has_penalties(&self) -> bool {
        self.contact.has_penalties() && self.contact.interfaces.has_penalties()
    }

    /// See [`ContactState::estimate_multipliers`] (the rigid bodies; the sliding interfaces'
    /// multipliers stay zero).
    fn estimate_multipliers(
        &mut self,
        u: &[f64],
        residual_tolerance: f64,
    ) -> Result<(), AssemblyError> {
        if self.model.contacts.is_empty() {
            return Ok(());
        }
        self.assemble(u, 1.0, false)?;
        let force_tolerance = residual_tolerance * self.norms().1;
        self.contact.estimate_multipliers(
            self.model,
            u,
            &self.assembly.system.residual,
            force_tolerance,
        );
        Ok(())
    }

    fn active_set(&self) -> ActiveSet {
        let (n, print) = self.contact.active_set();
        let (ni, printi) = self.contact.interfaces.active;
        if ni == 0 {
            (n, print)
        } else {
            (n + ni, print.wrapping_mul(0x9e37_79b9).wrapping_add(printi))
        }
    }

    fn step_limit(&self, u: &[f64], full: &[f64]) -> f64 {
        self.contact
            .step_limit(self.model, u, full, self.active_set.along())
    }

    fn second_order_correction(&self, alpha: f64, trial: &mut [f64]) {
        let along = self.active_set.along();
        if !along.is_empty() {
            let candidates = &self.active_set.candidates;
            self.contact
                .second_order_correction(self.model, candidates, along, alpha, trial);
        }
    }

    fn augment(&mut self, u: &mut [f64], force_tolerance: f64) -> bool {
        let bodies = self.contact.augment(self.model, u, force_tolerance);
        if self.model.interfaces.is_empty() {
            return bodies;
        }
        let interfaces = self
            .contact
            .interfaces
            .augment(self.model, u, force_tolerance);
        bodies || interfaces
    }

    /// The multipliers of the rigid bodies, then those of the interfaces.
    fn multipliers(&self) -> Vec<Vec<f64>> {
        let mut all = self.contact.multipliers().to_vec();
        all.extend(self.contact.interfaces.multipliers());
        all
    }

    fn restore_multipliers(&mut self, saved: Vec<Vec<f64>>) {
        let mut saved = saved;
        let interfaces = saved.split_off(self.model.contacts.len());
        self.contact.restore_multipliers(saved);
        self.contact
            .interfaces
            .restore_multipliers(interfaces.into_iter());
    }

    fn commit(&mut self, u: &[f64]) {
        if !self.model.interfaces.is_empty() {
            self.contact.interfaces.commit(self.model, u);
        }
    }

    fn body_records(&self, u: &[f64]) -> Vec<[f64; 2]> {
        self.contact
            .body_states(self.model, u)
            .iter()
            .map(|b| [b.travel, b.force])
            .collect()
    }

    fn stall_hint(&self, report: &SolveReport) -> Option<String> {
        limit_point_hint(self.model, report)
    }
}
