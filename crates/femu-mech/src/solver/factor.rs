//! The factorization of the tangent, shared by the Newton iterations and the sensitivities:
//! [`femu_sparse::SparseSolver`] (LDLᵀ for symmetric tangents, by halves for large models; LU
//! otherwise) with the kind of the last successful factorization and the time spent.

use super::assembly::DofMap;
use femu_sparse::{CscPattern, DofSplit, Factorization, LinearSolveError, NodeGraph, SparseSolver};
use std::time::Instant;

/// Largest separator (equations) for which the tangent is factorized by halves: its dense
/// Schur complement costs `s³` per factorization and `8 s²` bytes (2 000: 32 MB, a few
/// hundredths of a second, while the separator of a 25 000-quad thigh is about 250).
const MAX_SEPARATOR_EQUATIONS: usize = 2000;

/// How the equations are factorized: whole in a fill-reducing order, or by halves.
pub(crate) enum EquationPlan {
    Whole(Vec<usize>),
    Split(DofSplit),
}

impl EquationPlan {
    /// A model with at least `split_min_equations` free node equations is split in two halves
    /// factorized in parallel ([`femu_sparse::SplitLdlt`]); a small one, or one whose separator
    /// would be too large for a dense Schur complement, is ordered whole by AMD.
    pub fn new(
        graph: &NodeGraph,
        dofs: &DofMap,
        split_min_equations: usize,
    ) -> Result<Self, LinearSolveError> {
        let node_eq = &dofs.eq[..2 * (graph.ptr.len() - 1)];
        if dofs.n_eq_nodes >= split_min_equations {
            if let Some(split) = graph.split_by_elimination_tree(node_eq)? {
                if split.separator.len() <= MAX_SEPARATOR_EQUATIONS {
                    return Ok(EquationPlan::Split(split));
                }
            }
        }
        Ok(EquationPlan::Whole(
            graph.fill_reducing_dof_order(node_eq, dofs.n_eq_nodes)?,
        ))
    }

    /// The plan with the border equations (`(equation, rows)`) eliminated last.
    pub fn with_borders(mut self, borders: &[(usize, Vec<usize>)]) -> Self {
        match &mut self {
            EquationPlan::Whole(ordering) => ordering.extend(borders.iter().map(|b| b.0)),
            EquationPlan::Split(split) => split.separator.extend(borders.iter().map(|b| b.0)),
        }
        self
    }

    /// The symbolic analysis of `pattern` in this plan.
    pub fn analyse(&self, pattern: &CscPattern) -> Result<SparseSolver, LinearSolveError> {
        match self {
            EquationPlan::Whole(ordering) => SparseSolver::new(pattern, Some(ordering)),
            EquationPlan::Split(split) => SparseSolver::new_split(pattern, split),
        }
    }
}

/// The tangent's factors and their bookkeeping.
#[derive(Debug)]
pub(crate) struct TangentFactor {
    solver: SparseSolver,
    /// The kind of the last successful factorization (kept when a later one fails).
    last: Option<Factorization>,
    /// Time in numeric factorizations since the last reset (s).
    pub factorization_time_s: f64,
    /// Time in triangular solves since the last reset (s).
    pub solve_time_s: f64,
}

impl TangentFactor {
    pub fn new(solver: SparseSolver) -> Self {
        TangentFactor {
            solver,
            last: None,
            factorization_time_s: 0.0,
            solve_time_s: 0.0,
        }
    }

    /// Zero timers (at the start of a solve).
    pub fn reset_timers(&mut self) {
        self.factorization_time_s = 0.0;
        self.solve_time_s = 0.0;
    }

    /// Factorizes the tangent `values` on `pattern`.
    pub fn factorize(
        &mut self,
        pattern: &CscPattern,
        values: &[f64],
    ) -> Result<Factorization, LinearSolveError> {
        let t = Instant::now();
        let kind = self.solver.factorize(pattern, values)?;
        self.last = Some(kind);
        self.factorization_time_s += t.elapsed().as_secs_f64();
        Ok(kind)
    }

    /// The kind of the last successful factorization.
    pub fn last(&self) -> Option<Factorization> {
        self.last
    }

    /// Whether the factors are usable: the last factorization succeeded.
    pub fn has_factors(&self) -> bool {
        self.solver.last().is_some()
    }

    /// Solves `K X = B` in place for `columns` (≤ [`femu_sparse::MAX_RHS`]) right-hand sides
    /// stored one after the other, with the factors of the last factorization.
    pub fn solve_many(&mut self, rhs: &mut [f64], columns: usize) {
        let t = Instant::now();
        self.solver.solve_many_in_place(rhs, columns);
        self.solve_time_s += t.elapsed().as_secs_f64();
    }

    /// `Y = K X` for `cols` interleaved vectors (see
    /// [`SparseSolver::mul_many_interleaved`]), `values` on `pattern`.
    pub fn mul_many_interleaved(
        &self,
        pattern: &CscPattern,
        values: &[f64],
        x: &[f64],
        y: &mut [f64],
        cols: usize,
    ) {
        self.solver
            .mul_many_interleaved(pattern, values, x, y, cols);
    }
}
