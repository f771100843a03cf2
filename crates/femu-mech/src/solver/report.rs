//! What a solve reports ([`SolveReport`], [`IncrementRecord`], [`IterationRecord`]) and
//! returns ([`Solution`]), and the hint a stalled force-controlled solve gives
//! ([`limit_point_hint`]): shared by the Newton driver ([`super::newton`]) and the problems it
//! drives ([`super::system`]).

use crate::contact::{BodyState, TravelControl};
use crate::model::Model;
use femu_sparse::Factorization;
use serde::{Deserialize, Serialize};

/// Below this fraction of its largest secant stiffness over the step, a force-controlled
/// body's force–travel curve counts as flattening (a limit point ahead) when the increments
/// stall. Only a hint in the message of a solve that has already failed; a generous ratio
/// catches the stall just before the peak (a 600-quad thigh stalls at 20 %; a 1 200-quad one
/// at 34 %, 99 % of the peak force, since the contact set of each Newton correction is
/// solved for).
const LIMIT_POINT_STIFFNESS_RATIO: f64 = 0.4;

/// One Newton iteration, as printed in the Newton table.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct IterationRecord {
    pub iteration: usize,
    /// ‖R‖₂ on the free dofs after the iteration's update (N).
    pub residual_norm: f64,
    /// The force scale the residual is compared with (N).
    pub reference_force: f64,
    /// |δu · R| before the update (N·mm).
    pub energy_norm: f64,
    /// Line-search step length α.
    pub step_length: f64,
    /// max |δu| (mm).
    pub max_correction: f64,
}

/// One attempted increment.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IncrementRecord {
    pub increment: usize,
    /// Load factor at the end of the increment (if converged).
    pub lambda: f64,
    pub dlambda: f64,
    pub converged: bool,
    /// Why the attempt was cut back, if it was.
    pub failure: Option<String>,
    pub iterations: Vec<IterationRecord>,
    /// Travel (mm) and contact force (N/mm) of each rigid body at the end of a converged
    /// increment: the force–displacement curve.
    pub bodies: Vec<[f64; 2]>,
}

impl IncrementRecord {
    /// An attempt, not yet made, of increment `increment` to the load factor `lambda`.
    pub(crate) fn attempt(increment: usize, lambda: f64, dlambda: f64) -> Self {
        IncrementRecord {
            increment,
            lambda,
            dlambda,
            converged: false,
            failure: None,
            iterations: Vec::new(),
            bodies: Vec::new(),
        }
    }
}

/// Diagnostics of a solve.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct SolveReport {
    pub increments: Vec<IncrementRecord>,
    pub converged_increments: usize,
    pub cutbacks: usize,
    pub newton_iterations: usize,
    pub factorizations: usize,
    pub equations: usize,
    pub matrix_nonzeros: usize,
    /// Load factor reached (1 when the step completed).
    pub lambda: f64,
    /// Sum of reaction forces on the prescribed dofs, x and y (N per mm in plane strain, N for
    /// a 3D body).
    pub reaction_total: [f64; 2],
    pub wall_time_s: f64,
    /// Pattern, dof numbering and symbolic factorization (once per model).
    pub setup_time_s: f64,
    /// Time in element loops and scatter.
    pub assembly_time_s: f64,
    /// Time in numeric factorizations.
    pub factorization_time_s: f64,
    /// Time in triangular solves.
    pub triangular_solve_time_s: f64,
    /// Whether the solve started from a given displacement.
    pub warm_start: bool,
    /// The factorization of the last Newton iteration (LDLT for symmetric tangents, LU otherwise).
    pub factorization: Option<Factorization>,
}

impl SolveReport {
    /// The force–travel curve of rigid body `body`: `[travel (mm), force (N/mm)]` at the end of
    /// every converged increment.
    pub fn force_travel(&self, body: usize) -> Vec<[f64; 2]> {
        self.increments
            .iter()
            .filter(|r| r.converged)
            .filter_map(|r| r.bodies.get(body).copied())
            .collect()
    }

    /// Counts the Newton iterations (one factorization each) of an attempt.
    pub(crate) fn count(&mut self, record: &IncrementRecord) {
        self.newton_iterations += record.iterations.len();
        self.factorizations += record.iterations.len();
    }
}

/// A converged (or partially converged, see [`crate::SolveError`]) state.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Nodal displacements, `[ux0, uy0, ux1, uy1, ...]` (mm).
    pub u: Vec<f64>,
    /// The whole state: `u` followed by the travel of each rigid body beyond first contact (mm).
    pub state: Vec<f64>,
    /// Contact results per rigid body.
    pub bodies: Vec<BodyState>,
    /// Reaction forces at prescribed dofs (zero elsewhere), same layout (N per mm).
    pub reactions: Vec<f64>,
    pub report: SolveReport,
}

/// Explains a stalled force-controlled solve whose force–travel curve has flattened: at a
/// limit point the body's force cannot grow any further on this mesh (for example a coarse
/// skin folding around an indenter: the node-to-surface contact lets the facets between
/// contact nodes sag into the body), so there is no equilibrium at the requested force and
/// no Newton safeguard can find one. `None` if no force-controlled body's curve is flat.
///
/// The secant stiffness `ΔF/Δt` between consecutive converged increments is compared with the
/// largest over the step; the last one below [`LIMIT_POINT_STIFFNESS_RATIO`] of it is a limit
/// point.
pub(crate) fn limit_point_hint(model: &Model, report: &SolveReport) -> Option<String> {
    for (b, c) in model.contacts.iter().enumerate() {
        let TravelControl::Force(target) = c.control else {
            continue;
        };
        let curve = report.force_travel(b);
        let secants: Vec<f64> = curve
            .windows(2)
            .filter(|w| (w[1][0] - w[0][0]).abs() > 1e-12)
            .map(|w| (w[1][1] - w[0][1]) / (w[1][0] - w[0][0]))
            .collect();
        let (Some(&last), Some(&[travel, force])) = (secants.last(), curve.last()) else {
            continue;
        };
        let largest = secants.iter().fold(0.0f64, |m, &k| m.max(k));
        if largest > 0.0 && last < LIMIT_POINT_STIFFNESS_RATIO * largest {
            let trend = if last <= 0.0 {
                "turned down".to_string()
            } else {
                format!(
                    "flattened to {:.0} % of its largest stiffness",
                    100.0 * last / largest
                )
            };
            return Some(format!(
                "the force–travel curve of rigid body '{}' {trend} at travel {travel:.3} mm, \
                 force {force:.4} N/mm of the {target} requested: most likely a limit point, \
                 beyond which this model cannot carry more force (on a coarse mesh the skin \
                 facets fold around a rigid body); refine the mesh under the body, lower the \
                 force, or prescribe the travel instead",
                c.name
            ));
        }
    }
    None
}
