//! The Newton driver: load increments with a linear predictor, Newton–Raphson iterations with
//! a contact step limit, a backtracking line search and active-set cycle detection, automatic
//! cut-back and growth of the increments, the augmented-Lagrangian updates of the last
//! increment, and the reports of all of it ([`SolveReport`]). Written once for the plane-strain
//! and the 3D problems, through [`NewtonSystem`].

use super::assembly::AssemblyError;
use super::contact_state::ActiveSet;
use super::report::{IncrementRecord, IterationRecord, Solution, SolveReport};
use super::system::{NewtonSystem, Plane};
use super::{SolveError, SolverOptions, StaticSolver};
use crate::model::Model;
use femu_mesh::StepDef;
use femu_sparse::LinearSolveError;
use std::time::Instant;

/// Relative residual below which the last increment's Newton iterations make the contact
/// multipliers' Uzawa update (see [`Newton::newton`]): 1e-3 is past the active-set
/// changes and inside the quadratic regime on the seed's tests, so the gaps the update uses are
/// those of the converged state to a few digits.
const EARLY_AUGMENTATION: f64 = 1e-3;

/// With rigid bodies, the residual that the first Newton correction of an increment should
/// leave, as a fraction of the full load: the next increment is sized for it (see
/// [`Stepping::converged`]). The first correction starts from the last converged state, so
/// its residual is the second-order error of the tangent over the increment, growing as the
/// increment squared. On the thigh's indentation an increment whose first correction left
/// 0.05–0.12 of the load converged in two iterations, one that left 0.14–0.22 in three to six,
/// and 0.5–1 failed (the contact zone outgrew the linear step); the flat plate's compression
/// stays below 0.05 with the increments doubling.
const FIRST_CORRECTION_RESIDUAL: f64 = 0.1;

/// The smallest force scale the residual is compared with (N): keeps the relative tests
/// defined for an unloaded body.
const FLOOR: f64 = 1e-300;

/// Why one Newton attempt failed (the increment is cut back). The message goes to
/// [`IncrementRecord::failure`].
#[derive(Debug, Clone, thiserror::Error)]
pub(crate) enum AttemptFailure {
    #[error(transparent)]
    Assembly(#[from] AssemblyError),
    #[error(transparent)]
    Singular(#[from] LinearSolveError),
    #[error("non-finite Newton correction")]
    NonFiniteCorrection,
    #[error("line search failed at iteration {iteration} (|R| = {residual:.3e})")]
    LineSearch { iteration: usize, residual: f64 },
    #[error("crawling after {iterations} iterations (|R|/f = {relative:.3e}, four iterations before {before:.3e})")]
    Crawling {
        iterations: usize,
        relative: f64,
        before: f64,
    },
    #[error("no progress after {iterations} iterations (|R| = {residual:.3e}, first {first:.3e})")]
    NoProgress {
        iterations: usize,
        residual: f64,
        first: f64,
    },
    #[error("residual blew up to {residual:.3e}")]
    BlewUp { residual: f64 },
    /// The user asked to stop ([`femu_mesh::stop`]).
    #[error(transparent)]
    Interrupted(#[from] femu_mesh::stop::Interrupted),
    #[error("{iterations} iterations without convergence (|R| = {residual:.3e}, reference force {reference:.3e})")]
    IterationLimit {
        iterations: usize,
        residual: f64,
        reference: f64,
    },
}

/// The state vectors of the Newton driver, allocated once.
#[derive(Debug)]
pub(crate) struct NewtonWork {
    /// The Newton correction on the equations.
    du: Vec<f64>,
    /// The line search's trial state.
    u_trial: Vec<f64>,
    /// The converged states of the last two increments (the predictor's).
    u_conv: Vec<f64>,
    u_prev: Vec<f64>,
}

impl NewtonWork {
    pub fn new(n_eq: usize, n_dof: usize) -> Self {
        NewtonWork {
            du: vec![0.0; n_eq],
            u_trial: vec![0.0; n_dof],
            u_conv: vec![0.0; n_dof],
            u_prev: vec![0.0; n_dof],
        }
    }
}

/// The increment sizes over the step: load factor reached, next increment, last converged
/// increment, and the bounds from the deck's `*STATIC` line.
struct Stepping {
    lambda: f64,
    dlambda: f64,
    last_dlambda: f64,
    min: f64,
    max: f64,
}

impl Stepping {
    fn new(step: &StepDef) -> Self {
        let period = if step.period > 0.0 { step.period } else { 1.0 };
        let min = (step.min_increment / period).max(1e-12);
        let max = (step.max_increment / period).clamp(min, 1.0);
        Stepping {
            lambda: 0.0,
            dlambda: (step.initial_increment / period).clamp(min, max),
            last_dlambda: 0.0,
            min,
            max,
        }
    }

    /// The load factor of the next increment. An increment that would leave a sliver of the
    /// load (under a quarter of itself) for a last increment of its own takes the sliver too:
    /// the last increment is the one converged fully, and a separate tiny one would cost a
    /// whole Newton solve.
    fn target(&self) -> f64 {
        if self.lambda + 1.25 * self.dlambda >= 1.0 {
            1.0
        } else {
            self.lambda + self.dlambda
        }
    }

    /// The increment to `target` converged in `iterations`: the next one doubles after ≤ 2
    /// iterations, grows by `growth` after ≤ 4, stays otherwise. With `first_residual` (the
    /// residual the increment's first correction left, as a fraction of the full load; given
    /// for models with rigid bodies) it is also scaled by `sqrt(FIRST_CORRECTION_RESIDUAL /
    /// first_residual)`, at most halved: the size whose first correction leaves
    /// [`FIRST_CORRECTION_RESIDUAL`] of the load.
    fn converged(
        &mut self,
        target: f64,
        iterations: usize,
        growth: f64,
        first_residual: Option<f64>,
    ) {
        let dl = target - self.lambda;
        self.lambda = target;
        self.last_dlambda = dl;
        let mut factor = if iterations <= 2 {
            2.0
        } else if iterations <= 4 {
            growth
        } else {
            1.0
        };
        if let Some(r) = first_residual.filter(|r| *r > 0.0) {
            factor = factor.min((FIRST_CORRECTION_RESIDUAL / r).sqrt().max(0.5));
        }
        self.dlambda = (dl * factor).clamp(self.min, self.max);
    }
}

/// The Newton correction of one iteration.
struct Correction {
    /// `δu · R` at the start of the iteration (negative for a descent direction).
    s0: f64,
    /// `|δu · R|`.
    energy: f64,
    /// `max |δu|`.
    max_du: f64,
}

/// What the line search needs of the iteration.
struct LineSearch {
    iteration: usize,
    lambda: f64,
    last_increment: bool,
    correction: Correction,
    /// The energy of the increment's first correction.
    energy0: f64,
    /// Whether the correction is at round-off level (see [`Newton::newton`]).
    at_round_off: bool,
    /// ‖R‖ at the start of the iteration.
    rnorm: f64,
}

/// The step the line search accepted.
struct AcceptedStep {
    alpha: f64,
    rnorm: f64,
    fref: f64,
    /// Whether the tangent was assembled at the new state.
    tangent_at_u: bool,
    /// The active set at the start of the iteration.
    active_before: ActiveSet,
}

/// `δu · R(u)` with `rhs = -R` on the equations.
fn directional(du: &[f64], rhs: &[f64]) -> f64 {
    -du.iter().zip(rhs).map(|(a, b)| a * b).sum::<f64>()
}

/// The Newton driver of one solve: load increments, Newton iterations, line search, cut-back
/// and reports, on any [`NewtonSystem`] (the plane-strain [`Plane`] and the 3D solve of
/// [`crate::solid3d`]).
pub(crate) struct Newton<'w, S> {
    pub options: SolverOptions,
    pub work: &'w mut NewtonWork,
    pub system: S,
}

impl StaticSolver {
    /// Solves the step of `model` from zero displacement.
    pub fn solve(&mut self, model: &Model) -> Result<Solution, SolveError> {
        self.solve_with(model, None, &mut |_| {})
    }

    /// Solves the step; `initial` (2 per node) is a warm start tried at the full load first
    /// (the identification calls the solver many times with nearby parameters); `on_increment`
    /// is called after every attempted increment (progress lines).
    pub fn solve_with(
        &mut self,
        model: &Model,
        initial: Option<&[f64]>,
        on_increment: &mut dyn FnMut(&IncrementRecord),
    ) -> Result<Solution, SolveError> {
        let t0 = Instant::now();
        self.assembly.time_s = 0.0;
        self.factor.reset_timers();
        let report = SolveReport {
            equations: self.assembly.dofs.n_eq,
            matrix_nonzeros: self.assembly.pattern.nnz(),
            setup_time_s: self.setup_time_s,
            ..Default::default()
        };
        let system = Plane {
            model,
            assembly: &mut self.assembly,
            contact: &mut self.contact,
            active_set: &mut self.active_set,
            factor: &mut self.factor,
        };
        Newton {
            options: self.options,
            work: &mut self.work,
            system,
        }
        .solve_with(&model.step, initial, report, on_increment, t0)
    }
}

impl<S: NewtonSystem> Newton<'_, S> {
    /// Solves the step from zero or (`initial`, the state or its leading part) from a warm
    /// start tried at the full load first; `report` has the setup fields, `t0` the start time.
    pub fn solve_with(
        &mut self,
        step: &StepDef,
        initial: Option<&[f64]>,
        report: SolveReport,
        on_increment: &mut dyn FnMut(&IncrementRecord),
        t0: Instant,
    ) -> Result<S::Solution, SolveError<S::Solution>> {
        let mut report = report;
        let mut u = vec![0.0; self.system.dofs().eq.len()];
        // A warm start keeps the contact penalties and multipliers of the previous solve (the
        // contact forces of a nearby state), so that few augmentations remain.
        let keep_contact = initial.is_some() && self.system.has_penalties();
        if !keep_contact {
            self.system.init_contact().map_err(SolveError::Undeformed)?;
        }
        if let Some(u0) = initial {
            if self.warm_start(u0, &mut u, &mut report, on_increment, !keep_contact) {
                report.lambda = 1.0;
                report.wall_time_s = t0.elapsed().as_secs_f64();
                return Ok(self.system.solution(&u, report));
            }
            u.fill(0.0);
            self.system.init_contact().map_err(SolveError::Undeformed)?;
        }
        self.increments(step, &mut u, &mut report, on_increment, t0)?;
        report.lambda = 1.0;
        report.wall_time_s = t0.elapsed().as_secs_f64();
        Ok(self.system.solution(&u, report))
    }

    /// Newton at the full load from `u0` (2 per node, or the whole state); whether it
    /// converged (`u` then holds the solution). A failure counts as a cut-back. With
    /// `estimate_multipliers` (penalties just set, multipliers zero) the contact multipliers
    /// are first estimated from equilibrium at `u0`.
    fn warm_start(
        &mut self,
        u0: &[f64],
        u: &mut Vec<f64>,
        report: &mut SolveReport,
        on_increment: &mut dyn FnMut(&IncrementRecord),
        estimate_multipliers: bool,
    ) -> bool {
        report.warm_start = true;
        let k = u0.len().min(u.len());
        u[..k].copy_from_slice(&u0[..k]);
        self.system.dofs().set_prescribed(u, 1.0);
        // A state solved elsewhere: its contact forces are in no multiplier of this solve yet.
        if estimate_multipliers
            && self
                .system
                .estimate_multipliers(u, self.options.residual_tolerance)
                .is_err()
        {
            report.cutbacks += 1;
            return false;
        }
        let mut rec = IncrementRecord::attempt(1, 1.0, 1.0);
        let outcome = self.newton_augmented(u, 1.0, &mut rec);
        rec.converged = outcome.is_ok();
        rec.failure = outcome.as_ref().err().map(|e| format!("warm start: {e}"));
        report.count(&rec);
        on_increment(&rec);
        report.increments.push(rec);
        if outcome.is_ok() {
            self.system.commit(u);
            report.converged_increments = 1;
        } else {
            report.cutbacks += 1;
        }
        outcome.is_ok()
    }

    /// The load increments from λ = 0 to 1 (`u` zero), cut back on failure; on success `u`
    /// holds the solution.
    fn increments(
        &mut self,
        step: &StepDef,
        u: &mut Vec<f64>,
        report: &mut SolveReport,
        on_increment: &mut dyn FnMut(&IncrementRecord),
        t0: Instant,
    ) -> Result<(), SolveError<S::Solution>> {
        let mut stepping = Stepping::new(step);
        self.work.u_conv.fill(0.0);
        self.work.u_prev.fill(0.0);
        let mut increment = 0;
        let mut attempts = 0;
        while stepping.lambda < 1.0 - 1e-12 {
            attempts += 1;
            let max = step.max_increments.max(1);
            if report.converged_increments >= max || attempts > 10 * max {
                report.lambda = stepping.lambda;
                report.wall_time_s = t0.elapsed().as_secs_f64();
                let u_conv = self.work.u_conv.clone();
                let partial = Box::new(self.system.solution(&u_conv, std::mem::take(report)));
                return Err(SolveError::TooManyIncrements {
                    max: step.max_increments,
                    lambda: stepping.lambda,
                    partial,
                });
            }
            increment += 1;
            let target = stepping.target();
            let dl = target - stepping.lambda;
            let extrapolated = self.predict(u, dl, stepping.last_dlambda, target);
            let mut rec = IncrementRecord::attempt(increment, target, dl);
            let mut outcome = self.newton_augmented(u, target, &mut rec);
            if outcome.is_err() && extrapolated && rec.iterations.is_empty() {
                // The extrapolated predictor inverted an element: retry from the last state.
                u.copy_from_slice(&self.work.u_conv);
                self.system.dofs().set_prescribed(u, target);
                outcome = self.newton_augmented(u, target, &mut rec);
            }
            report.count(&rec);
            match outcome {
                Ok(()) => {
                    rec.converged = true;
                    let iterations = rec.iterations.len();
                    on_increment(&rec);
                    report.increments.push(rec);
                    report.converged_increments += 1;
                    std::mem::swap(&mut self.work.u_prev, &mut self.work.u_conv);
                    self.work.u_conv.copy_from_slice(u);
                    self.system.commit(u);
                    // The first correction's residual as a fraction of the full load (the
                    // reference force scales with the load factor).
                    let first_residual = self
                        .system
                        .has_bodies()
                        .then(|| first_correction_residual(&report.increments, target))
                        .flatten();
                    stepping.converged(target, iterations, self.options.growth, first_residual);
                }
                Err(AttemptFailure::Interrupted(stop)) => {
                    return Err(SolveError::Interrupted(stop))
                }
                Err(failure) => {
                    rec.failure = Some(failure.to_string());
                    on_increment(&rec);
                    report.increments.push(rec);
                    report.cutbacks += 1;
                    stepping.dlambda = dl * self.options.cutback;
                    if stepping.dlambda < stepping.min {
                        return Err(self.stalled(&stepping, failure, report, t0));
                    }
                }
            }
        }
        Ok(())
    }

    /// The predictor of an increment `dl` to `target`: the last converged state, extrapolated
    /// linearly along the last converged increment `last_dl` (if any) unless the model has
    /// rigid bodies; prescribed dofs set. Returns whether it extrapolated.
    ///
    /// With rigid bodies the first Newton correction from the converged state is the
    /// predictor: the tangent step, whose contact set is found by the active-set iterations
    /// (see [`super::active_set`]). An extrapolated state knows nothing of the bodies: the
    /// skin nodes about to touch are carried through them (0.3–0.7 mm on the 4 000-quad
    /// indentation, contact forces 10–70 times the load), and Newton spends its first
    /// iterations pushing them back.
    fn predict(&self, u: &mut [f64], dl: f64, last_dl: f64, target: f64) -> bool {
        let work = &self.work;
        u.copy_from_slice(&work.u_conv);
        let extrapolate = last_dl > 0.0 && !self.system.has_bodies();
        if extrapolate {
            let s = dl / last_dl;
            for d in 0..u.len() {
                u[d] += s * (work.u_conv[d] - work.u_prev[d]);
            }
        }
        self.system.dofs().set_prescribed(u, target);
        extrapolate
    }

    /// The error of a solve whose increment fell below the minimum: the last converged state
    /// (re-assembled, so that the reactions are consistent), with a limit-point hint.
    fn stalled(
        &mut self,
        stepping: &Stepping,
        failure: AttemptFailure,
        report: &mut SolveReport,
        t0: Instant,
    ) -> SolveError<S::Solution> {
        let uc = self.work.u_conv.clone();
        let _ = self.system.assemble(&uc, stepping.lambda, false);
        report.lambda = stepping.lambda;
        report.wall_time_s = t0.elapsed().as_secs_f64();
        let mut reason = failure.to_string();
        if let Some(hint) = self.system.stall_hint(report) {
            reason.push_str("; ");
            reason.push_str(&hint);
        }
        let partial = Box::new(self.system.solution(&uc, std::mem::take(report)));
        SolveError::NotConverged {
            reason,
            lambda: stepping.lambda,
            dlambda: stepping.dlambda,
            min: stepping.min,
            partial,
        }
    }

    /// Newton at load factor `lambda`, then (at the end of the step) augmented-Lagrangian
    /// updates of the contact multipliers and Newton again until every body's penetration is
    /// within its limit (at most 20 updates). Records the bodies' travel and force on success;
    /// restores the multipliers on failure.
    fn newton_augmented(
        &mut self,
        u: &mut Vec<f64>,
        lambda: f64,
        record: &mut IncrementRecord,
    ) -> Result<(), AttemptFailure> {
        let saved: Vec<Vec<f64>> = self.system.multipliers();
        match self.newton_then_augment(u, lambda, record) {
            Ok(()) => {
                record.bodies = self.system.body_records(u);
                Ok(())
            }
            Err(e) => {
                self.system.restore_multipliers(saved);
                Err(e)
            }
        }
    }

    /// See [`Self::newton_augmented`]. The penetration limit is enforced on the final state
    /// only: intermediate increments carry the penalty's own (small) penetration, which saves
    /// the Uzawa re-solves there.
    fn newton_then_augment(
        &mut self,
        u: &mut Vec<f64>,
        lambda: f64,
        record: &mut IncrementRecord,
    ) -> Result<(), AttemptFailure> {
        self.newton(u, lambda, record)?;
        if lambda < 1.0 - 1e-12 {
            return Ok(());
        }
        for _ in 0..20 {
            // The last assembly was at `u` (Newton's accepted state).
            let force_tolerance = self.options.residual_tolerance * self.system.norms().1;
            if !self.system.augment(u, force_tolerance) {
                break;
            }
            self.newton(u, lambda, record)?;
        }
        Ok(())
    }

    /// Newton iterations at load factor `lambda` starting from `u` (prescribed dofs already
    /// set).
    fn newton(
        &mut self,
        u: &mut Vec<f64>,
        lambda: f64,
        record: &mut IncrementRecord,
    ) -> Result<(), AttemptFailure> {
        let opt = self.options;
        let last_increment = lambda >= 1.0 - 1e-12;
        self.system.assemble(u, lambda, true)?;
        let (mut rnorm, mut fref) = self.system.norms();
        let mut energy0 = 0.0;
        let mut first_residual = f64::INFINITY;
        // Active sets of the states the accepted steps started from (cycle detection).
        let mut set_history: Vec<ActiveSet> = Vec::new();
        // Whether the tangent values are at `u` (see `SolverOptions::final_tangent`).
        let mut tangent_at_u = true;
        for it in 0..opt.max_iterations {
            femu_mesh::stop::check()?;
            if it == 0 && rnorm <= opt.residual_tolerance * fref.max(FLOOR) * 1e-3 {
                return Ok(()); // already in equilibrium (e.g. a warm start at the solution)
            }
            if !tangent_at_u {
                self.system.assemble(u, lambda, true)?;
            }
            let correction = self.correction(u, it, fref, record)?;
            let energy = correction.energy;
            if it == 0 {
                energy0 = energy.max(FLOOR);
            }
            let max_du = correction.max_du;
            // A correction whose energy is at round-off level (1e-15 of the first) cannot
            // improve the state: the residual has reached the floor of floating-point
            // arithmetic for this problem (e.g. small forces on stiff penalty contact).
            let at_round_off = it > 0 && energy <= 1e-15 * energy0;
            let search = LineSearch {
                iteration: it,
                lambda,
                last_increment,
                correction,
                energy0,
                at_round_off,
                rnorm,
            };
            let step = self.line_search(u, &search, &set_history)?;
            (rnorm, fref, tangent_at_u) = (step.rnorm, step.fref, step.tangent_at_u);
            std::mem::swap(u, &mut self.work.u_trial);
            set_history.push(step.active_before);
            let last = record
                .iterations
                .last_mut()
                .expect("pushed by `correction`");
            last.residual_norm = rnorm;
            last.reference_force = fref;
            last.energy_norm = energy;
            last.step_length = step.alpha;
            last.max_correction = step.alpha * max_du;
            let res_ok = rnorm <= opt.residual_tolerance * fref.max(FLOOR);
            // The last increment's augmented-Lagrangian updates are made inside its Newton
            // iterations, as soon as the iterate is close to equilibrium (the quadratic regime,
            // contact set settled): the iterations that follow then converge the state and the
            // multipliers together, instead of converging the state, updating, and converging
            // again (two iterations fewer per update). `newton_augmented` still checks the
            // penetration of the converged state.
            if last_increment
                && !res_ok
                && rnorm <= EARLY_AUGMENTATION * fref.max(FLOOR)
                && self.system.augment(u, opt.residual_tolerance * fref)
            {
                self.system.assemble(u, lambda, true)?;
                (rnorm, fref) = self.system.norms();
                if it == 0 {
                    first_residual = rnorm;
                }
                continue;
            }
            let energy_ok =
                energy * step.alpha <= opt.energy_tolerance * energy0 || it == 0 && res_ok;
            let intermediate_ok = !last_increment
                && rnorm
                    <= opt.intermediate_tolerance.max(opt.residual_tolerance) * fref.max(FLOOR);
            let stagnated =
                rnorm <= 1e-3 * opt.residual_tolerance * fref.max(FLOOR) || at_round_off;
            if (res_ok && energy_ok) || stagnated || intermediate_ok {
                return Ok(());
            }
            if it == 0 {
                first_residual = rnorm;
            }
            check_progress(it, rnorm, fref, first_residual, record)?;
        }
        Err(AttemptFailure::IterationLimit {
            iterations: opt.max_iterations,
            residual: rnorm,
            reference: fref,
        })
    }

    /// Factorizes the tangent assembled last and solves for the Newton correction `δu` (into
    /// the work vector); records the iteration (its results are filled in after the step).
    fn correction(
        &mut self,
        u: &[f64],
        it: usize,
        fref: f64,
        record: &mut IncrementRecord,
    ) -> Result<Correction, AttemptFailure> {
        self.system.factorize()?;
        record.iterations.push(IterationRecord {
            iteration: it + 1,
            residual_norm: f64::NAN,
            reference_force: fref,
            energy_norm: 0.0,
            step_length: 1.0,
            max_correction: 0.0,
        });
        let work = &mut *self.work;
        work.du.copy_from_slice(self.system.rhs());
        self.system.solve_correction(u, &mut work.du);
        let s0 = directional(&work.du, self.system.rhs());
        let max_du = work.du.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if !max_du.is_finite() {
            return Err(AttemptFailure::NonFiniteCorrection);
        }
        Ok(Correction {
            s0,
            energy: s0.abs(),
            max_du,
        })
    }

    /// The step along the correction: from the contact step limit, halved on an inverted
    /// element or an active-set 2-cycle, and (with [`super::SolverOptions::line_search`])
    /// shortened until the directional residual has dropped enough (Crisfield's 0.8). The
    /// accepted state is left in the trial work vector.
    fn line_search(
        &mut self,
        u: &[f64],
        search: &LineSearch,
        set_history: &[ActiveSet],
    ) -> Result<AcceptedStep, AttemptFailure> {
        let opt = self.options;
        let correction = &search.correction;
        // A full step that drives a free skin node deep into a rigid body meets the stiff
        // penalty there with a huge residual, and the next step swings back (active-set
        // chattering on coarse meshes). Cap the step so that no node that is free now ends
        // deeper than a tenth of the element size (gaps linear along the step).
        let alpha_cap = self.contact_step_limit(u);
        let mut alpha = alpha_cap;
        let active_before = self.system.active_set();
        let mut halved_cycle = false;
        for _ in 0..8 {
            let mut trial = std::mem::take(&mut self.work.u_trial);
            self.system
                .dofs()
                .add_free(u, alpha, &self.work.du, &mut trial);
            self.system.second_order_correction(alpha, &mut trial);
            // A step that passes the energy test ends the increment if its residual passes
            // too: its tangent is then only needed at the end of the last increment, and
            // only if asked for.
            let may_end = search.iteration > 0
                && correction.energy * alpha <= opt.energy_tolerance * search.energy0;
            let with_tangent = !may_end || (search.last_increment && opt.final_tangent);
            let res = self.system.assemble(&trial, search.lambda, with_tangent);
            self.work.u_trial = trial;
            match res {
                Err(AssemblyError::Inverted { .. }) if opt.line_search => {
                    alpha *= 0.5;
                    continue;
                }
                Err(e) => return Err(e.into()),
                Ok(()) => {}
            }
            let (rnorm, fref) = self.system.norms();
            let active = self.system.active_set();
            let step = AcceptedStep {
                alpha,
                rnorm,
                fref,
                tangent_at_u: with_tangent,
                active_before,
            };
            // In the first iterations a full step that changes the contact active set is
            // taken as it is: the residual jump comes from the new contacts, whose stiffness
            // the next tangent includes (semi-smooth Newton); damping it would creep in tiny
            // steps. Later, the line search applies again, which breaks active-set cycles.
            // A full step that returns to the active set of two iterations ago is a
            // semismooth-Newton 2-cycle (one node toggling between contact and free): take
            // half the step instead, which lands near the kink the cycle jumps over.
            let cycling = !halved_cycle
                && active != active_before
                && set_history.len() >= 2
                && set_history[set_history.len() - 2] == active;
            if cycling {
                halved_cycle = true;
                alpha *= 0.5;
                continue;
            }
            let new_contacts =
                search.iteration < 4 && alpha == alpha_cap && active != active_before;
            if !opt.line_search
                || rnorm < search.rnorm
                || !rnorm.is_finite()
                || search.at_round_off
                || new_contacts
            {
                if rnorm.is_finite() {
                    return Ok(step);
                }
                break;
            }
            // s(α) = δu · R(u + α δu); accept when it dropped enough (Crisfield 0.8).
            let s = directional(&self.work.du, self.system.rhs());
            if s.abs() <= 0.8 * correction.s0.abs() || alpha < 0.02 {
                return Ok(step);
            }
            let ratio = if (correction.s0 - s).abs() > 0.0 {
                correction.s0 / (correction.s0 - s)
            } else {
                0.5
            };
            alpha *= ratio.clamp(0.1, 0.9);
        }
        Err(AttemptFailure::LineSearch {
            iteration: search.iteration + 1,
            residual: search.rnorm,
        })
    }

    /// The largest step length in (0, 1] along the current correction for which no contact
    /// node that is free at `u` penetrates its body deeper than 0.1 element size; 1 without
    /// contact. The full step is formed in the trial work vector.
    fn contact_step_limit(&mut self, u: &[f64]) -> f64 {
        if !self.system.has_bodies() {
            return 1.0;
        }
        let work = &mut *self.work;
        self.system
            .dofs()
            .add_free(u, 1.0, &work.du, &mut work.u_trial);
        self.system.step_limit(u, &work.u_trial)
    }
}

/// The residual left by the first Newton correction of the last increment in `increments`
/// (converged to `target`), as a fraction of the full load.
fn first_correction_residual(increments: &[IncrementRecord], target: f64) -> Option<f64> {
    let first = increments.last()?.iterations.first()?;
    (first.reference_force > 0.0).then(|| first.residual_norm / first.reference_force * target)
}

/// Gives up on an iteration that makes no headway: crawling (nine or more iterations and the
/// relative residual not halved over the last four), no progress over the first residual after
/// eight, or a residual blowing up.
///
/// A Newton that has found its basin converges quadratically; one that crawls (a nearly
/// singular tangent in a region the load step jumped into, e.g. a fold forming at a plate's
/// edge under a large increment) rarely recovers in the iterations left, and a cut-back is
/// cheaper than waiting for the limit.
fn check_progress(
    it: usize,
    rnorm: f64,
    fref: f64,
    first_residual: f64,
    record: &IncrementRecord,
) -> Result<(), AttemptFailure> {
    let n_it = record.iterations.len();
    if it >= 8 && n_it >= 5 {
        let old = &record.iterations[n_it - 5];
        let then = old.residual_norm / old.reference_force.max(FLOOR);
        if rnorm / fref.max(FLOOR) > 0.5 * then {
            return Err(AttemptFailure::Crawling {
                iterations: it + 1,
                relative: rnorm / fref.max(FLOOR),
                before: then,
            });
        }
    }
    if it >= 7 && rnorm > first_residual {
        return Err(AttemptFailure::NoProgress {
            iterations: it + 1,
            residual: rnorm,
            first: first_residual,
        });
    }
    if !rnorm.is_finite() || rnorm > 1e10 * fref.max(1e-12) {
        return Err(AttemptFailure::BlewUp { residual: rnorm });
    }
    Ok(())
}
