//! Static nonlinear solver: load increments, Newton–Raphson with line search and automatic
//! cut-back, sparse LU whose pattern and symbolic analysis are built once per model.
//!
//! Residual `R(u, λ) = f_int(u) - λ f_ext(u)` on the free dofs; prescribed displacements are set
//! to `λ ū` and eliminated. One increment converges when both
//! `‖R‖₂ ≤ rtol · max(‖λ f_ext‖₂, ‖reactions‖₂)` and the energy norm
//! `|δu · R| ≤ etol · |δu₀ · R₀|` hold (δu: the correction just applied, δu₀, R₀: first
//! iteration of the increment); the increments before the last only need
//! `‖R‖₂ ≤ itol · max(...)` (see [`SolverOptions::intermediate_tolerance`]).

use crate::contact::{BodyState, TravelControl};
use crate::element::{ElementResult, MAX_DOFS};
use crate::linear::{CscPattern, Factorization, LinearSolveError, NodeGraph, TangentSolver};
use crate::model::Model;
use crate::split::DofSplit;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

const NONE: usize = usize::MAX;
const KE: usize = MAX_DOFS * MAX_DOFS;

/// Newton and increment settings.
#[derive(Debug, Clone, Copy, Serialize)]
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
    /// tangent factorized by halves in parallel ([`crate::split::SplitLdlt`]); smaller ones
    /// whole. Both are exact direct solves.
    pub split_min_equations: usize,
    /// Whether the last iteration of the last increment assembles the tangent at the
    /// converged state too. [`crate::DirectSensitivity`] reuses that tangent (it assembles it
    /// itself when it is not there); a solve whose tangent nobody reads (`femu solve`) saves
    /// one tangent assembly with `false`. Either way the state is the same: the tangent of an
    /// iteration is left out only when the iteration's correction already passes the energy
    /// test, and if its residual then fails, the tangent is assembled before the next one.
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

/// One Newton iteration, as printed in the Newton table.
#[derive(Debug, Clone, Copy, Serialize)]
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
#[derive(Debug, Clone, Serialize)]
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

/// Diagnostics of a solve.
#[derive(Debug, Clone, Serialize, Default)]
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
    /// Sum of reaction forces on the prescribed dofs (N per mm).
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
}

/// A converged (or partially converged, see [`SolveError`]) state.
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

/// A node in contact with a rigid body at a converged state (see
/// [`StaticSolver::active_constraints`]): its contact force and the gap gradient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveConstraint {
    pub body: usize,
    pub node: usize,
    /// Contact force λ (N per mm, > 0).
    pub force: f64,
    pub dg_dx: [f64; 2],
    pub dg_dt: f64,
}

/// Below this fraction of its largest secant stiffness over the step, a force-controlled
/// body's force–travel curve counts as flattening (a limit point ahead) when the increments
/// stall. Only a hint in the message of a solve that has already failed; a generous ratio
/// catches the stall just before the peak (a 600-quad thigh stalls at 20 %).
const LIMIT_POINT_STIFFNESS_RATIO: f64 = 0.25;

/// Explains a stalled force-controlled solve whose force–travel curve has flattened: at a
/// limit point the body's force cannot grow any further on this mesh (for example a coarse
/// skin folding around an indenter: the node-to-surface contact lets the facets between
/// contact nodes sag into the body), so there is no equilibrium at the requested force and
/// no Newton safeguard can find one. `None` if no force-controlled body's curve is flat.
///
/// The secant stiffness `ΔF/Δt` between consecutive converged increments is compared with the
/// largest over the step; the last one below [`LIMIT_POINT_STIFFNESS_RATIO`] of it is a limit
/// point.
fn limit_point_hint(model: &Model, report: &SolveReport) -> Option<String> {
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

/// Why a solve did not reach the end of the step.
#[derive(thiserror::Error)]
pub enum SolveError {
    #[error("Newton did not converge: {reason} (load factor reached {lambda:.4}, increment size {dlambda:.3e} below the minimum {min:.3e})")]
    NotConverged {
        reason: String,
        lambda: f64,
        dlambda: f64,
        min: f64,
        /// The last converged state and the full increment history.
        partial: Box<Solution>,
    },
    #[error("more than {max} increments needed (load factor reached {lambda:.4})")]
    TooManyIncrements {
        max: usize,
        lambda: f64,
        partial: Box<Solution>,
    },
    #[error("linear solver setup failed: {0}")]
    Setup(#[from] LinearSolveError),
}

impl std::fmt::Debug for SolveError {
    /// The message only: the partial solution inside would print every nodal value.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SolveError({self})")
    }
}

/// Why one Newton attempt failed (the increment is cut back).
#[derive(Debug, Clone)]
enum AttemptFailure {
    Inverted { element_label: i64, det: f64 },
    Singular(String),
    Diverged(String),
}

impl std::fmt::Display for AttemptFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AttemptFailure::Inverted { element_label, det } => {
                write!(f, "element {element_label} inverted (J = {det:.3e})")
            }
            AttemptFailure::Singular(s) => write!(f, "{s}"),
            AttemptFailure::Diverged(s) => write!(f, "{s}"),
        }
    }
}

/// The static solver of one model: dof numbering, sparse pattern, symbolic factorization and
/// every buffer, built once; [`StaticSolver::solve`] can then be called many times (e.g. with
/// other material parameters) without allocating inside Newton iterations.
pub struct StaticSolver {
    pub options: SolverOptions,
    /// Equation number of each dof (`usize::MAX` for prescribed dofs).
    eq: Vec<usize>,
    n_eq: usize,
    pattern: CscPattern,
    /// The element entries summed into each tangent value (see [`TangentGather`]).
    gather: TangentGather,
    /// Per pressure face of the model: the positions in `values` of its 4 x 4 load stiffness
    /// (`NO_SLOT` for a prescribed row or column).
    face_slots: Vec<[Slot; 16]>,
    /// Per node: the element force entries (`e * MAX_DOFS + 2a`) summed into its residual, in
    /// element order; `node_sources[node_ptr[n]..node_ptr[n + 1]]`.
    node_ptr: Vec<u32>,
    node_sources: Vec<u32>,
    /// Prescribed dofs and their end-of-step values.
    prescribed: Vec<(usize, f64)>,
    /// Dead nodal forces at λ = 1 (2 per node).
    point_force: Vec<f64>,
    ke: Vec<f64>,
    fe: Vec<f64>,
    /// Assembled tangent values on `pattern`.
    values: Vec<f64>,
    /// Full residual (2 per node): f_int - λ f_ext.
    residual: Vec<f64>,
    /// External force at the current state (2 per node), for the reference force.
    fext: Vec<f64>,
    rhs: Vec<f64>,
    du: Vec<f64>,
    u_trial: Vec<f64>,
    u_conv: Vec<f64>,
    u_prev: Vec<f64>,
    lu: TangentSolver,
    setup_time_s: f64,
    last_factorization: Option<Factorization>,
    timers: [f64; 3],
    /// Per rigid body and candidate node: positions of (xx, xy, yx, yy, xt, yt, tx, ty).
    contact_slots: Vec<Vec<[usize; 8]>>,
    /// Per rigid body: position of (t, t).
    contact_tt: Vec<usize>,
    /// Per rigid body: the multiplier estimates λ̂ of its candidate nodes.
    multipliers: Vec<Vec<f64>>,
    /// Per rigid body: the penalty ε (set at the start of each solve).
    penalties: Vec<f64>,
    augmentations: Vec<usize>,
    /// Count and fingerprint of the active contact nodes at the last assembly.
    active_set: (usize, u64),
    /// The state of the last assembly, if it was at λ = 1 with the tangent (empty otherwise).
    tangent_state: Vec<f64>,
}

impl std::fmt::Debug for StaticSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StaticSolver")
            .field("equations", &self.n_eq)
            .field("nonzeros", &self.pattern.nnz())
            .finish()
    }
}

/// A position in the tangent values, 32 bits: the element slots are read at every assembly and
/// half the size is half the memory traffic (a tangent with 2³² entries would need some 50 GB).
type Slot = u32;
/// No position: the entry's row or column is a prescribed dof.
const NO_SLOT: Slot = Slot::MAX;

/// Relative residual below which the last increment's Newton iterations make the contact
/// multipliers' Uzawa update (see [`StaticSolver::newton`]): 1e-3 is past the active-set
/// changes and inside the quadratic regime on the seed's tests, so the gaps the update uses are
/// those of the converged state to a few digits.
const EARLY_AUGMENTATION: f64 = 1e-3;

/// For each element `e`, `slots[e*KE + r*nd + c]` is the position in the values of `pattern` of
/// its local entry (row r, column c) (`NO_SLOT` if either dof is prescribed or beyond the
/// element's `nd` dofs), `eq` being the equation of each dof; `None` if the pattern has too
/// many entries for a [`Slot`].
///
/// One binary search per pair of element nodes instead of one per pair of dofs: the columns of
/// a node's two free dofs have the same rows (the free dofs of the node's neighbours, node by
/// node, then any border rows; see [`NodeGraph::dof_pattern`] and [`CscPattern::bordered`]), and
/// the free dofs of a neighbour are consecutive rows; so the offset of a neighbour within one
/// column gives its entries in both.
fn element_slots(model: &Model, eq: &[usize], pattern: &CscPattern) -> Option<Vec<Slot>> {
    if pattern.nnz() >= NO_SLOT as usize {
        return None;
    }
    let mut slots = vec![NO_SLOT; model.mesh.elements.len() * KE];
    slots.par_chunks_mut(KE).enumerate().for_each(|(e, slots)| {
        let nodes = model.mesh.elements[e].nodes();
        let nd = 2 * nodes.len();
        let mut dofs = [NONE; MAX_DOFS];
        for (a, &n) in nodes.iter().enumerate() {
            dofs[2 * a] = eq[2 * n];
            dofs[2 * a + 1] = eq[2 * n + 1];
        }
        let first_free = |a: usize| {
            [dofs[2 * a], dofs[2 * a + 1]]
                .into_iter()
                .find(|&q| q != NONE)
        };
        for a in 0..nodes.len() {
            let Some(ca) = first_free(a) else { continue };
            for b in 0..nodes.len() {
                let Some(rb) = first_free(b) else { continue };
                let offset =
                    pattern.position(rb, ca).expect("entry in pattern") - pattern.col_ptr[ca];
                for i in 0..2 {
                    let c = dofs[2 * a + i];
                    if c == NONE {
                        continue;
                    }
                    let mut pos = pattern.col_ptr[c] + offset;
                    for j in 0..2 {
                        let r = dofs[2 * b + j];
                        if r == NONE {
                            continue;
                        }
                        debug_assert_eq!(pattern.position(r, c), Some(pos));
                        slots[(2 * b + j) * nd + 2 * a + i] = pos as Slot;
                        pos += 1;
                    }
                }
            }
        }
    });
    Some(slots)
}

/// The element-matrix entries that add up to each tangent value: value `p` is the sum of
/// `ke[source[k]]` over `k` in `ptr[p]..ptr[p + 1]` (`ke[e * KE + r * nd + c]` being entry
/// (r, c) of element e), in element order, so the tangent is summed in the same order as a
/// scatter over the elements would, to the bit, but each value is written once and the values
/// can be shared between threads (no two write the same one). On the paper-scale thigh an
/// assembly with the tangent takes 0.014 s against 0.017 s with a serial scatter (best of 40,
/// the two alternated); the index costs 10 MB and about 0.01 s at setup.
#[derive(Debug, Default)]
struct TangentGather {
    ptr: Vec<u32>,
    source: Vec<u32>,
}

/// Values per parallel task of [`TangentGather::gather`].
const GATHER_CHUNK: usize = 16 * 1024;

/// Nodes per parallel task of the residual gather.
const GATHER_NODES: usize = 1024;

impl TangentGather {
    /// The transpose of the element slots (a counting sort by position); `None` if the element
    /// entries do not fit 32-bit indices.
    fn new(slots: &[Slot], nnz: usize) -> Option<Self> {
        if slots.len() >= u32::MAX as usize {
            return None;
        }
        let (ptr, source) = group_by_key(nnz, || {
            slots
                .iter()
                .enumerate()
                .filter(|(_, &p)| p != NO_SLOT)
                .map(|(k, &p)| (p as usize, k as u32))
        });
        Some(TangentGather { ptr, source })
    }

    /// `values[p] = Σ ke[source[k]]` for every position, in parallel blocks.
    fn gather(&self, ke: &[f64], values: &mut [f64]) {
        values
            .par_chunks_mut(GATHER_CHUNK)
            .enumerate()
            .for_each(|(c, block)| {
                let first = c * GATHER_CHUNK;
                for (i, v) in block.iter_mut().enumerate() {
                    let p = first + i;
                    let range = self.ptr[p] as usize..self.ptr[p + 1] as usize;
                    *v = self.source[range]
                        .iter()
                        .fold(0.0, |sum, &k| sum + ke[k as usize]);
                }
            });
    }
}

/// Per node, the element force entries `e * MAX_DOFS + 2a` of its element incidences, in
/// element order (CSR: pointers, sources).
fn node_sources(model: &Model) -> (Vec<u32>, Vec<u32>) {
    group_by_key(model.node_count(), || {
        model.mesh.elements.iter().enumerate().flat_map(|(e, el)| {
            el.nodes()
                .iter()
                .enumerate()
                .map(move |(a, &node)| (node, (e * MAX_DOFS + 2 * a) as u32))
        })
    })
}

/// Counting sort of `(key, value)` pairs by key (`key < n_keys`), keeping their order within a
/// key: CSR pointers (`n_keys + 1`) and the values. `pairs` is iterated twice (count, fill).
/// The counts of key q go to q + 2; their running sum puts the start of q at q + 1, which the
/// fill advances to the end of q, i.e. the start of q + 1: no second array of insertion points.
fn group_by_key<I: Iterator<Item = (usize, u32)>>(
    n_keys: usize,
    pairs: impl Fn() -> I,
) -> (Vec<u32>, Vec<u32>) {
    let mut ptr = vec![0u32; n_keys + 2];
    for (q, _) in pairs() {
        ptr[q + 2] += 1;
    }
    for k in 2..n_keys + 2 {
        ptr[k] += ptr[k - 1];
    }
    let mut values = vec![0u32; ptr[n_keys + 1] as usize];
    for (q, v) in pairs() {
        let at = &mut ptr[q + 1];
        values[*at as usize] = v;
        *at += 1;
    }
    ptr.truncate(n_keys + 1);
    (ptr, values)
}

/// Largest separator (equations) for which the tangent is factorized by halves: its dense
/// Schur complement costs `s³` per factorization and `8 s²` bytes (2 000: 32 MB, a few
/// hundredths of a second, while the separator of a 25 000-quad thigh is about 250).
const MAX_SEPARATOR_EQUATIONS: usize = 2000;

/// How the equations are factorized: whole in a fill-reducing order, or by halves.
enum EquationPlan {
    Whole(Vec<usize>),
    Split(DofSplit),
}

impl StaticSolver {
    /// Numbers the dofs, builds the sparse pattern and its symbolic LU.
    pub fn new(model: &Model, options: SolverOptions) -> Result<Self, SolveError> {
        let t0 = Instant::now();
        let n_nodes_dof = 2 * model.node_count();
        let n_dof = model.state_len();
        let mut eq = vec![NONE; n_dof];
        let mut prescribed: Vec<(usize, f64)> = Vec::with_capacity(model.constraints.len());
        for bc in &model.constraints {
            let d = 2 * bc.node + bc.dof;
            if eq[d] != NONE {
                // `eq` temporarily holds the index into `prescribed` of a prescribed dof.
                prescribed[eq[d]].1 = bc.value; // a repeated condition: the last value wins
                continue;
            }
            eq[d] = prescribed.len();
            prescribed.push((d, bc.value));
        }
        for (b, c) in model.contacts.iter().enumerate() {
            if let TravelControl::Displacement(t) = c.control {
                prescribed.push((n_nodes_dof + b, t));
            }
        }
        let mut is_prescribed = vec![false; n_dof];
        for &(d, _) in &prescribed {
            is_prescribed[d] = true;
        }
        let mut n_eq = 0;
        for (e, &fixed) in eq.iter_mut().zip(&is_prescribed) {
            if fixed {
                *e = NONE;
            } else {
                *e = n_eq;
                n_eq += 1;
            }
        }
        let n_el = model.mesh.elements.len();
        let graph = NodeGraph::from_elements(
            model.node_count(),
            model.mesh.elements.iter().map(|e| e.nodes()),
        );
        let n_eq_nodes = eq[..n_nodes_dof].iter().filter(|&&q| q != NONE).count();
        // Bordered system: each force-controlled body couples its travel with the free dofs of
        // its candidate nodes; the travels are numbered and eliminated last.
        let borders: Vec<(usize, Vec<usize>)> = model
            .contacts
            .iter()
            .enumerate()
            .filter(|(b, _)| eq[n_nodes_dof + b] != NONE)
            .map(|(b, c)| {
                let mut rows: Vec<usize> = c
                    .nodes
                    .iter()
                    .flat_map(|&n| [eq[2 * n], eq[2 * n + 1]])
                    .filter(|&q| q != NONE)
                    .collect();
                rows.sort_unstable();
                (eq[n_nodes_dof + b], rows)
            })
            .collect();
        // The ordering (the longest step) on one thread, the pattern and the element slots on
        // the other. A large model is split in two halves factorized in parallel (`SplitLdlt`);
        // a small one, or one whose separator would be too large for a dense Schur complement,
        // is ordered whole by AMD.
        let (plan, (pattern, slots)) = rayon::join(
            || -> Result<EquationPlan, SolveError> {
                if n_eq_nodes >= options.split_min_equations {
                    if let Some(split) = graph.split_by_elimination_tree(&eq[..n_nodes_dof])? {
                        if split.separator.len() <= MAX_SEPARATOR_EQUATIONS {
                            return Ok(EquationPlan::Split(split));
                        }
                    }
                }
                Ok(EquationPlan::Whole(
                    graph.fill_reducing_dof_order(&eq[..n_nodes_dof], n_eq_nodes)?,
                ))
            },
            || {
                let pattern = graph
                    .dof_pattern(&eq[..n_nodes_dof], n_eq_nodes)
                    .bordered(n_eq, &borders);
                let slots = element_slots(model, &eq, &pattern);
                let face_slots: Option<Vec<[Slot; 16]>> = slots.as_ref().map(|slots| {
                    model
                        .pressures
                        .iter()
                        .map(|face| {
                            let [la, lb] = face.local;
                            let local = [2 * la, 2 * la + 1, 2 * lb, 2 * lb + 1];
                            let nd = 2 * model.mesh.elements[face.element].kind.node_count();
                            let slots = &slots[face.element * KE..];
                            std::array::from_fn(|k| slots[local[k / 4] * nd + local[k % 4]])
                        })
                        .collect()
                });
                let gather = slots
                    .as_deref()
                    .and_then(|slots| TangentGather::new(slots, pattern.nnz()));
                (pattern, gather.zip(face_slots))
            },
        );
        let mut plan = plan?;
        let (gather, face_slots) = slots.ok_or_else(|| {
            SolveError::Setup(LinearSolveError::Other(format!(
                "the tangent has {} entries, more than this solver addresses (2^32)",
                pattern.nnz()
            )))
        })?;
        let (node_ptr, node_sources) = node_sources(model);
        match &mut plan {
            EquationPlan::Whole(ordering) => ordering.extend(borders.iter().map(|b| b.0)),
            EquationPlan::Split(split) => split.separator.extend(borders.iter().map(|b| b.0)),
        }
        let lu = match &plan {
            EquationPlan::Whole(ordering) => TangentSolver::new(&pattern, Some(ordering)),
            EquationPlan::Split(split) => TangentSolver::new_split(&pattern, split),
        };
        let lu = lu?;
        let contact_slots: Vec<Vec<[usize; 8]>> = model
            .contacts
            .iter()
            .enumerate()
            .map(|(b, c)| {
                let qt = eq[n_nodes_dof + b];
                c.nodes
                    .iter()
                    .map(|&n| {
                        let (qx, qy) = (eq[2 * n], eq[2 * n + 1]);
                        let pos = |r: usize, col: usize| {
                            if r == NONE || col == NONE {
                                NONE
                            } else {
                                pattern.position(r, col).expect("contact entry in pattern")
                            }
                        };
                        [
                            pos(qx, qx),
                            pos(qx, qy),
                            pos(qy, qx),
                            pos(qy, qy),
                            pos(qx, qt),
                            pos(qy, qt),
                            pos(qt, qx),
                            pos(qt, qy),
                        ]
                    })
                    .collect()
            })
            .collect();
        let contact_tt: Vec<usize> = (0..model.contacts.len())
            .map(|b| {
                let qt = eq[n_nodes_dof + b];
                if qt == NONE {
                    NONE
                } else {
                    pattern.position(qt, qt).expect("(t, t) in pattern")
                }
            })
            .collect();
        let mut point_force = vec![0.0; n_dof];
        for p in &model.point_loads {
            point_force[2 * p.node + p.dof] += p.magnitude;
        }
        let nnz = pattern.nnz();
        Ok(StaticSolver {
            options,
            eq,
            n_eq,
            pattern,
            gather,
            face_slots,
            node_ptr,
            node_sources,
            prescribed,
            point_force,
            ke: vec![0.0; n_el * KE],
            fe: vec![0.0; n_el * MAX_DOFS],
            values: vec![0.0; nnz],
            residual: vec![0.0; n_dof],
            fext: vec![0.0; n_dof],
            rhs: vec![0.0; n_eq],
            du: vec![0.0; n_eq],
            u_trial: vec![0.0; n_dof],
            u_conv: vec![0.0; n_dof],
            u_prev: vec![0.0; n_dof],
            lu,
            setup_time_s: t0.elapsed().as_secs_f64(),
            last_factorization: None,
            timers: [0.0; 3],
            multipliers: model
                .contacts
                .iter()
                .map(|c| vec![0.0; c.nodes.len()])
                .collect(),
            penalties: vec![0.0; model.contacts.len()],
            augmentations: vec![0; model.contacts.len()],
            active_set: (0, 0),
            tangent_state: Vec::with_capacity(n_dof),
            contact_slots,
            contact_tt,
        })
    }

    /// Number of equations (free dofs).
    pub fn equations(&self) -> usize {
        self.n_eq
    }

    /// Equation number of each dof (`None` for a prescribed dof).
    pub fn equation_of(&self, dof: usize) -> Option<usize> {
        (self.eq[dof] != NONE).then_some(self.eq[dof])
    }

    /// The sparse pattern of the tangent on the free dofs.
    pub fn pattern(&self) -> &CscPattern {
        &self.pattern
    }

    /// Assembles the residual (always) and the tangent (if `with_tangent`) at `u`, load factor
    /// `lambda`. Element loop in parallel; scatter serial.
    fn assemble(
        &mut self,
        model: &Model,
        u: &[f64],
        lambda: f64,
        with_tangent: bool,
    ) -> Result<(), AttemptFailure> {
        let t0 = Instant::now();
        let result = self.assemble_untimed(model, u, lambda, with_tangent);
        self.timers[0] += t0.elapsed().as_secs_f64();
        self.tangent_state.clear();
        if result.is_ok() && with_tangent && lambda == 1.0 {
            self.tangent_state.extend_from_slice(u);
        }
        result
    }

    fn assemble_untimed(
        &mut self,
        model: &Model,
        u: &[f64],
        lambda: f64,
        with_tangent: bool,
    ) -> Result<(), AttemptFailure> {
        let ke_len = model.mesh.elements.len() * KE;
        if self.ke.len() != ke_len {
            // Borrowed through `element_scratch` and not given back.
            self.ke.clear();
            self.ke.resize(ke_len, 0.0);
        }
        let failed = self
            .fe
            .par_chunks_mut(MAX_DOFS)
            .zip(self.ke.par_chunks_mut(KE))
            .enumerate()
            .map(|(e, (fe, ke))| {
                let geo = &model.geometry[e];
                let ue = model.gather(e, u);
                let mat = &model.materials[model.element_material[e]].law;
                let mut out = ElementResult {
                    energy: 0.0,
                    force: fe,
                    stiffness: with_tangent.then_some(ke),
                };
                if let Err(j) = mat.evaluate_element(geo, &ue[..geo.n_nodes], &mut out) {
                    return Some((e, j.0));
                }
                None
            })
            .find_any(|r| r.is_some())
            .flatten();
        if let Some((e, det)) = failed {
            return Err(AttemptFailure::Inverted {
                element_label: model.mesh.element_labels[e],
                det,
            });
        }
        self.fext.fill(0.0);
        for (fx, p) in self.fext.iter_mut().zip(&self.point_force) {
            *fx += lambda * p;
        }
        // Residual and tangent gathered from the element results (each entry summed in
        // element order, as a scatter would), node blocks and value blocks in parallel.
        let (fe, node_ptr, node_sources, point_force) = (
            &self.fe,
            &self.node_ptr,
            &self.node_sources,
            &self.point_force,
        );
        let n_node_dofs = 2 * model.node_count();
        let (node_residual, body_residual) = self.residual.split_at_mut(n_node_dofs);
        let mut gather_residual = || {
            node_residual
                .par_chunks_mut(2 * GATHER_NODES)
                .enumerate()
                .for_each(|(c, block)| {
                    for (i, r) in block.chunks_exact_mut(2).enumerate() {
                        let n = c * GATHER_NODES + i;
                        let (mut rx, mut ry) = (
                            -lambda * point_force[2 * n],
                            -lambda * point_force[2 * n + 1],
                        );
                        for &k in &node_sources[node_ptr[n] as usize..node_ptr[n + 1] as usize] {
                            rx += fe[k as usize];
                            ry += fe[k as usize + 1];
                        }
                        r[0] = rx;
                        r[1] = ry;
                    }
                });
        };
        if with_tangent {
            let (gather, ke, values) = (&self.gather, &self.ke, &mut self.values);
            rayon::join(&mut gather_residual, || gather.gather(ke, values));
        } else {
            gather_residual();
        }
        for (r, p) in body_residual.iter_mut().zip(&point_force[n_node_dofs..]) {
            *r = -lambda * p;
        }
        self.add_pressure(model, u, lambda, with_tangent);
        self.add_contact(model, u, lambda, with_tangent);
        for (d, &q) in self.eq.iter().enumerate() {
            if q != NONE {
                self.rhs[q] = -self.residual[d];
            }
        }
        Ok(())
    }

    /// Adds the follower-pressure loads: `-f_ext` to the residual, `f_ext` to the reference
    /// force, and the load stiffness through the face's slots.
    fn add_pressure(&mut self, model: &Model, u: &[f64], lambda: f64, with_tangent: bool) {
        for (face_index, face) in model.pressures.iter().enumerate() {
            let [na, nb] = face.nodes;
            let f = face.external_force(
                model.current_position(na, u),
                model.current_position(nb, u),
                lambda,
            );
            let dofs = [2 * na, 2 * na + 1, 2 * nb, 2 * nb + 1];
            for (&d, fi) in dofs.iter().zip(f) {
                self.residual[d] -= fi;
                self.fext[d] += fi;
            }
            if with_tangent {
                let kl = face.load_stiffness(lambda);
                for (k, &pos) in self.face_slots[face_index].iter().enumerate() {
                    if pos != NO_SLOT {
                        self.values[pos as usize] += kl[k / 4][k % 4];
                    }
                }
            }
        }
    }

    /// Adds the rigid-body contact terms (see [`crate::contact`]) and, under force control,
    /// the applied force on the travel equation.
    fn add_contact(&mut self, model: &Model, u: &[f64], lambda: f64, with_tangent: bool) {
        let base = 2 * model.node_count();
        self.active_set = (0, 0);
        for (b, c) in model.contacts.iter().enumerate() {
            let tdof = base + b;
            let t = c.first_contact + u[tdof];
            if let TravelControl::Force(f) = c.control {
                self.residual[tdof] -= lambda * f;
                self.fext[tdof] += lambda * f;
            }
            let eps = self.penalties[b];
            for (k, &n) in c.nodes.iter().enumerate() {
                let x = [
                    model.mesh.nodes[n][0] + u[2 * n],
                    model.mesh.nodes[n][1] + u[2 * n + 1],
                ];
                let gap = c.body.gap(x, t);
                let trial = self.multipliers[b][k] - eps * gap.g;
                // Touching within round-off counts as active (the first-contact node starts at
                // g = 0 up to rounding), so that the travel has stiffness from the start.
                if trial < -eps * 1e-12 * c.element_size {
                    continue;
                }
                let lam = trial.max(0.0);
                self.active_set.0 += 1;
                self.active_set.1 = self
                    .active_set
                    .1
                    .wrapping_mul(31)
                    .wrapping_add(k as u64 + 1);
                self.residual[2 * n] -= lam * gap.dg_dx[0];
                self.residual[2 * n + 1] -= lam * gap.dg_dx[1];
                self.residual[tdof] -= lam * gap.dg_dt;
                if with_tangent {
                    let s = &self.contact_slots[b][k];
                    let kxx = [
                        eps * gap.dg_dx[0] * gap.dg_dx[0] - lam * gap.d2g_dxdx[0][0],
                        eps * gap.dg_dx[0] * gap.dg_dx[1] - lam * gap.d2g_dxdx[0][1],
                        eps * gap.dg_dx[1] * gap.dg_dx[0] - lam * gap.d2g_dxdx[1][0],
                        eps * gap.dg_dx[1] * gap.dg_dx[1] - lam * gap.d2g_dxdx[1][1],
                    ];
                    let kxt = [
                        eps * gap.dg_dx[0] * gap.dg_dt - lam * gap.d2g_dxdt[0],
                        eps * gap.dg_dx[1] * gap.dg_dt - lam * gap.d2g_dxdt[1],
                    ];
                    let vals = [
                        kxx[0], kxx[1], kxx[2], kxx[3], kxt[0], kxt[1], kxt[0], kxt[1],
                    ];
                    for (pos, v) in s.iter().zip(vals) {
                        if *pos != NONE {
                            self.values[*pos] += v;
                        }
                    }
                    if self.contact_tt[b] != NONE {
                        self.values[self.contact_tt[b]] +=
                            eps * gap.dg_dt * gap.dg_dt - lam * gap.d2g_dtdt;
                    }
                }
            }
        }
    }

    /// Contact results of every body at state `u`.
    fn body_states(&self, model: &Model, u: &[f64]) -> Vec<BodyState> {
        let base = 2 * model.node_count();
        model
            .contacts
            .iter()
            .enumerate()
            .map(|(b, c)| {
                let t = c.first_contact + u[base + b];
                let eps = self.penalties[b];
                let mut st = BodyState {
                    name: c.name.clone(),
                    travel: u[base + b],
                    penalty: eps,
                    penetration_limit: c.penetration_tolerance * c.element_size,
                    augmentations: self.augmentations[b],
                    ..Default::default()
                };
                for (k, &n) in c.nodes.iter().enumerate() {
                    let x = [
                        model.mesh.nodes[n][0] + u[2 * n],
                        model.mesh.nodes[n][1] + u[2 * n + 1],
                    ];
                    let gap = c.body.gap(x, t);
                    let lam = (self.multipliers[b][k] - eps * gap.g).max(0.0);
                    st.force -= lam * gap.dg_dt;
                    if lam > 0.0 {
                        st.active_nodes += 1;
                    }
                    st.max_penetration = st.max_penetration.max(-gap.g);
                    st.node_forces.push(lam);
                    st.node_gaps.push(gap.g);
                }
                st
            })
            .collect()
    }

    /// Sets each body's penalty from the largest diagonal stiffness of its candidate dofs at
    /// the undeformed state (the "automatic penalty") and clears the multipliers.
    fn init_contact(&mut self, model: &Model) -> Result<(), AttemptFailure> {
        if model.contacts.is_empty() {
            return Ok(());
        }
        let zero = vec![0.0; model.state_len()];
        self.penalties.iter_mut().for_each(|p| *p = 0.0);
        self.assemble(model, &zero, 0.0, true)?;
        for (b, c) in model.contacts.iter().enumerate() {
            let mut kmax = 0.0f64;
            for s in &self.contact_slots[b] {
                for pos in [s[0], s[3]] {
                    if pos != NONE {
                        kmax = kmax.max(self.values[pos].abs());
                    }
                }
            }
            self.penalties[b] = c.penalty_factor * kmax.max(1e-12);
            self.multipliers[b].iter_mut().for_each(|m| *m = 0.0);
            self.augmentations[b] = 0;
        }
        Ok(())
    }

    /// Uzawa update `λ̂ ← ⟨λ̂ - ε g⟩₊` for the bodies whose complementarity error (a
    /// penetration, or an open gap under a contact force) exceeds their limit; returns whether
    /// any was updated.
    fn augment(&mut self, model: &Model, u: &[f64]) -> bool {
        let base = 2 * model.node_count();
        let mut updated = false;
        for (b, c) in model.contacts.iter().enumerate() {
            let t = c.first_contact + u[base + b];
            let eps = self.penalties[b];
            let limit = c.penetration_tolerance * c.element_size;
            let gap = |n: usize| {
                let x = model.mesh.nodes[n];
                c.body.gap([x[0] + u[2 * n], x[1] + u[2 * n + 1]], t).g
            };
            // Complementarity error: a penetration, or a gap at a node that still carries a
            // contact force (the multiplier overshot).
            let violation =
                c.nodes
                    .iter()
                    .zip(&self.multipliers[b])
                    .fold(0.0f64, |m, (&n, &lam)| {
                        let g = gap(n);
                        if g < 0.0 {
                            m.max(-g)
                        } else if lam - eps * g > 0.0 {
                            m.max(g)
                        } else {
                            m
                        }
                    });
            if violation > limit {
                for (m, &n) in self.multipliers[b].iter_mut().zip(&c.nodes) {
                    *m = (*m - eps * gap(n)).max(0.0);
                }
                self.augmentations[b] += 1;
                updated = true;
            }
        }
        updated
    }

    /// ‖R‖ on free dofs and the reference force scale.
    fn norms(&self) -> (f64, f64) {
        let mut r2 = 0.0;
        let mut f2 = 0.0;
        let mut reac2 = 0.0;
        for (d, &q) in self.eq.iter().enumerate() {
            if q != NONE {
                r2 += self.residual[d] * self.residual[d];
                f2 += self.fext[d] * self.fext[d];
            } else {
                reac2 += self.residual[d] * self.residual[d];
            }
        }
        (r2.sqrt(), f2.sqrt().max(reac2.sqrt()))
    }

    fn set_prescribed(&self, u: &mut [f64], lambda: f64) {
        for &(d, v) in &self.prescribed {
            u[d] = lambda * v;
        }
    }

    /// The largest step length in (0, 1] along the current correction `du` for which no
    /// contact node that is free at `u` penetrates its body deeper than 0.1 element size (gaps
    /// taken linear in the step); 1 without contact.
    fn contact_step_limit(&mut self, model: &Model, u: &[f64]) -> f64 {
        if model.contacts.is_empty() {
            return 1.0;
        }
        let mut full = std::mem::take(&mut self.u_trial);
        self.add_free(u, 1.0, &mut full);
        let base = 2 * model.node_count();
        let mut cap = 1.0f64;
        for (b, c) in model.contacts.iter().enumerate() {
            let depth = 0.1 * c.element_size;
            let eps = self.penalties[b];
            let t0 = c.first_contact + u[base + b];
            let t1 = c.first_contact + full[base + b];
            for (k, &n) in c.nodes.iter().enumerate() {
                let x0 = [
                    model.mesh.nodes[n][0] + u[2 * n],
                    model.mesh.nodes[n][1] + u[2 * n + 1],
                ];
                let g0 = c.body.gap(x0, t0).g;
                if self.multipliers[b][k] - eps * g0 > 0.0 || g0 <= 0.0 {
                    continue; // in contact already
                }
                let x1 = [
                    model.mesh.nodes[n][0] + full[2 * n],
                    model.mesh.nodes[n][1] + full[2 * n + 1],
                ];
                let g1 = c.body.gap(x1, t1).g;
                if g1 < -depth {
                    cap = cap.min((g0 + depth) / (g0 - g1));
                }
            }
        }
        self.u_trial = full;
        cap.clamp(1e-3, 1.0)
    }

    fn add_free(&self, u: &[f64], alpha: f64, out: &mut [f64]) {
        out.copy_from_slice(u);
        for (d, &q) in self.eq.iter().enumerate() {
            if q != NONE {
                out[d] += alpha * self.du[q];
            }
        }
    }

    /// Newton iterations at load factor `lambda` starting from `u` (prescribed dofs already set).
    fn newton(
        &mut self,
        model: &Model,
        u: &mut Vec<f64>,
        lambda: f64,
        record: &mut IncrementRecord,
    ) -> Result<(), AttemptFailure> {
        let opt = self.options;
        let last_increment = lambda >= 1.0 - 1e-12;
        self.assemble(model, u, lambda, true)?;
        let (mut rnorm, mut fref) = self.norms();
        let floor = 1e-300;
        let mut energy0 = 0.0;
        let mut first_residual = f64::INFINITY;
        // Active sets of the states the accepted steps started from (cycle detection).
        let mut set_history: Vec<(usize, u64)> = Vec::new();
        // Whether `self.values` holds the tangent at `u` (see `SolverOptions::final_tangent`).
        let mut tangent_at_u = true;
        for it in 0..opt.max_iterations {
            if it == 0 && rnorm <= opt.residual_tolerance * fref.max(floor) * 1e-3 {
                return Ok(()); // already in equilibrium (e.g. a warm start at the solution)
            }
            if !tangent_at_u {
                self.assemble(model, u, lambda, true)?;
                tangent_at_u = true;
            }
            let t_fact = Instant::now();
            let kind = self
                .lu
                .factorize(&self.pattern, &self.values)
                .map_err(|e| AttemptFailure::Singular(e.to_string()))?;
            self.last_factorization = Some(kind);
            self.timers[1] += t_fact.elapsed().as_secs_f64();
            record.iterations.push(IterationRecord {
                iteration: it + 1,
                residual_norm: f64::NAN,
                reference_force: fref,
                energy_norm: 0.0,
                step_length: 1.0,
                max_correction: 0.0,
            });
            self.du.copy_from_slice(&self.rhs);
            let t_solve = Instant::now();
            self.lu.solve_in_place(&mut self.du);
            self.timers[2] += t_solve.elapsed().as_secs_f64();
            // s0 = δu · R (negative for a descent direction)
            let s0: f64 = -self
                .du
                .iter()
                .zip(&self.rhs)
                .map(|(a, b)| a * b)
                .sum::<f64>();
            let energy = s0.abs();
            if it == 0 {
                energy0 = energy.max(floor);
            }
            let max_du = self.du.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            // A correction whose energy is at round-off level (1e-15 of the first) cannot
            // improve the state: the residual has reached the floor of floating-point
            // arithmetic for this problem (e.g. small forces on stiff penalty contact).
            let at_round_off = it > 0 && energy <= 1e-15 * energy0;
            if !max_du.is_finite() {
                return Err(AttemptFailure::Diverged(
                    "non-finite Newton correction".into(),
                ));
            }
            // A full step that drives a free skin node deep into a rigid body meets the stiff
            // penalty there with a huge residual, and the next step swings back (active-set
            // chattering on coarse meshes). Cap the step so that no node that is free now ends
            // deeper than a tenth of the element size (gaps linear along the step).
            let alpha_cap = self.contact_step_limit(model, u);
            let mut alpha = alpha_cap;
            let mut accepted = false;
            let active_before = self.active_set;
            let mut halved_cycle = false;
            for _ in 0..8 {
                let mut trial = std::mem::take(&mut self.u_trial);
                self.add_free(u, alpha, &mut trial);
                // A step that passes the energy test ends the increment if its residual passes
                // too: its tangent is then only needed at the end of the last increment, and
                // only if asked for.
                let may_end = it > 0 && energy * alpha <= opt.energy_tolerance * energy0;
                let with_tangent = !may_end || (last_increment && opt.final_tangent);
                let res = self.assemble(model, &trial, lambda, with_tangent);
                tangent_at_u = with_tangent;
                self.u_trial = trial;
                match res {
                    Err(AttemptFailure::Inverted { .. }) if opt.line_search => {
                        alpha *= 0.5;
                        continue;
                    }
                    Err(e) => return Err(e),
                    Ok(()) => {}
                }
                let (rn, fr) = self.norms();
                // In the first iterations a full step that changes the contact active set is
                // taken as it is: the residual jump comes from the new contacts, whose stiffness
                // the next tangent includes (semi-smooth Newton); damping it would creep in tiny
                // steps. Later, the line search applies again, which breaks active-set cycles.
                // A full step that returns to the active set of two iterations ago is a
                // semismooth-Newton 2-cycle (one node toggling between contact and free): take
                // half the step instead, which lands near the kink the cycle jumps over.
                let cycling = !halved_cycle
                    && self.active_set != active_before
                    && set_history.len() >= 2
                    && set_history[set_history.len() - 2] == self.active_set;
                if cycling {
                    halved_cycle = true;
                    alpha *= 0.5;
                    continue;
                }
                let new_contacts = it < 4 && alpha == alpha_cap && self.active_set != active_before;
                if !opt.line_search || rn < rnorm || !rn.is_finite() || at_round_off || new_contacts
                {
                    accepted = rn.is_finite();
                    if accepted {
                        rnorm = rn;
                        fref = fr;
                    }
                    break;
                }
                // s(α) = δu · R(u + α δu); accept when it dropped enough (Crisfield 0.8).
                let s: f64 = -self
                    .du
                    .iter()
                    .zip(&self.rhs)
                    .map(|(a, b)| a * b)
                    .sum::<f64>();
                if s.abs() <= 0.8 * s0.abs() || alpha < 0.02 {
                    rnorm = rn;
                    fref = fr;
                    accepted = true;
                    break;
                }
                let ratio = if (s0 - s).abs() > 0.0 {
                    s0 / (s0 - s)
                } else {
                    0.5
                };
                alpha *= ratio.clamp(0.1, 0.9);
            }
            if !accepted {
                return Err(AttemptFailure::Diverged(format!(
                    "line search failed at iteration {} (|R| = {rnorm:.3e})",
                    it + 1
                )));
            }
            std::mem::swap(u, &mut self.u_trial);
            set_history.push(active_before);
            let last = record.iterations.last_mut().expect("pushed above");
            last.residual_norm = rnorm;
            last.reference_force = fref;
            last.energy_norm = energy;
            last.step_length = alpha;
            last.max_correction = alpha * max_du;
            let res_ok = rnorm <= opt.residual_tolerance * fref.max(floor);
            // The last increment's augmented-Lagrangian updates are made inside its Newton
            // iterations, as soon as the iterate is close to equilibrium (the quadratic regime,
            // contact set settled): the iterations that follow then converge the state and the
            // multipliers together, instead of converging the state, updating, and converging
            // again (two iterations fewer per update). `newton_augmented` still checks the
            // penetration of the converged state.
            if last_increment
                && !res_ok
                && rnorm <= EARLY_AUGMENTATION * fref.max(floor)
                && self.augment(model, u)
            {
                self.assemble(model, u, lambda, true)?;
                (rnorm, fref) = self.norms();
                if it == 0 {
                    first_residual = rnorm;
                }
                continue;
            }
            let energy_ok = energy * alpha <= opt.energy_tolerance * energy0 || it == 0 && res_ok;
            let intermediate_ok = !last_increment
                && rnorm
                    <= opt.intermediate_tolerance.max(opt.residual_tolerance) * fref.max(floor);
            let stagnated =
                rnorm <= 1e-3 * opt.residual_tolerance * fref.max(floor) || at_round_off;
            if (res_ok && energy_ok) || stagnated || intermediate_ok {
                return Ok(());
            }
            if it == 0 {
                first_residual = rnorm;
            }
            // Crawling: nine or more iterations and the relative residual not halved over
            // the last four. A Newton that has found its basin converges quadratically; one
            // that crawls (a nearly singular tangent in a region the load step jumped into,
            // e.g. a fold forming at a plate's edge under a large increment) rarely recovers
            // in the iterations left, and a cut-back is cheaper than waiting for the limit.
            let n_it = record.iterations.len();
            if it >= 8 && n_it >= 5 {
                let old = &record.iterations[n_it - 5];
                let then = old.residual_norm / old.reference_force.max(floor);
                if rnorm / fref.max(floor) > 0.5 * then {
                    return Err(AttemptFailure::Diverged(format!(
                        "crawling after {} iterations (|R|/f = {:.3e}, four iterations before {then:.3e})",
                        it + 1,
                        rnorm / fref.max(floor)
                    )));
                }
            }
            if it >= 7 && rnorm > first_residual {
                return Err(AttemptFailure::Diverged(format!(
                    "no progress after {} iterations (|R| = {rnorm:.3e}, first {first_residual:.3e})",
                    it + 1
                )));
            }
            if !rnorm.is_finite() || rnorm > 1e10 * fref.max(1e-12) {
                return Err(AttemptFailure::Diverged(format!(
                    "residual blew up to {rnorm:.3e}"
                )));
            }
        }
        Err(AttemptFailure::Diverged(format!(
            "{} iterations without convergence (|R| = {rnorm:.3e}, reference force {fref:.3e})",
            opt.max_iterations
        )))
    }

    /// Newton at load factor `lambda`, then (at the end of the step) augmented-Lagrangian
    /// updates of the contact multipliers and Newton again until every body's penetration is
    /// within its limit (at most 20 updates). Records the bodies' travel and force on success.
    fn newton_augmented(
        &mut self,
        model: &Model,
        u: &mut Vec<f64>,
        lambda: f64,
        record: &mut IncrementRecord,
    ) -> Result<(), AttemptFailure> {
        let saved: Vec<Vec<f64>> = self.multipliers.clone();
        let result = (|| {
            self.newton(model, u, lambda, record)?;
            // The penetration limit is enforced on the final state only: intermediate
            // increments carry the penalty's own (small) penetration, which saves the Uzawa
            // re-solves there.
            if lambda < 1.0 - 1e-12 {
                return Ok(());
            }
            for _ in 0..20 {
                if !self.augment(model, u) {
                    break;
                }
                self.newton(model, u, lambda, record)?;
            }
            Ok(())
        })();
        match result {
            Ok(()) => {
                record.bodies = self
                    .body_states(model, u)
                    .iter()
                    .map(|b| [b.travel, b.force])
                    .collect();
                Ok(())
            }
            Err(e) => {
                self.multipliers = saved;
                Err(e)
            }
        }
    }

    /// Reaction forces (prescribed dofs) from the last assembly.
    fn reactions(&self) -> Vec<f64> {
        let mut r = vec![0.0; self.residual.len()];
        for &(d, _) in &self.prescribed {
            r[d] = self.residual[d];
        }
        r
    }

    fn solution(&self, model: &Model, u: &[f64], report: SolveReport) -> Solution {
        let n = 2 * model.node_count();
        let reactions = self.reactions();
        let mut report = report;
        report.factorization = self.last_factorization;
        report.assembly_time_s = self.timers[0];
        report.factorization_time_s = self.timers[1];
        report.triangular_solve_time_s = self.timers[2];
        report.reaction_total = [
            reactions[..n].iter().step_by(2).sum(),
            reactions[..n].iter().skip(1).step_by(2).sum(),
        ];
        Solution {
            u: u[..n].to_vec(),
            state: u.to_vec(),
            bodies: self.body_states(model, u),
            reactions: reactions[..n].to_vec(),
            report,
        }
    }

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
        self.timers = [0.0; 3];
        let n_dof = model.state_len();
        let mut report = SolveReport {
            equations: self.n_eq,
            matrix_nonzeros: self.pattern.nnz(),
            setup_time_s: self.setup_time_s,
            ..Default::default()
        };
        let mut u = vec![0.0; n_dof];
        // A warm start keeps the contact penalties and multipliers of the previous solve (the
        // contact forces of a nearby state), so that few augmentations remain.
        let keep_contact = initial.is_some() && self.penalties.iter().all(|&p| p > 0.0);
        if !keep_contact {
            if let Err(e) = self.init_contact(model) {
                return Err(SolveError::Setup(LinearSolveError::Other(format!(
                    "the undeformed state cannot be assembled: {e}"
                ))));
            }
        }
        if let Some(u0) = initial {
            report.warm_start = true;
            let k = u0.len().min(n_dof);
            u[..k].copy_from_slice(&u0[..k]);
            self.set_prescribed(&mut u, 1.0);
            let mut rec = IncrementRecord {
                increment: 1,
                lambda: 1.0,
                dlambda: 1.0,
                converged: false,
                failure: None,
                iterations: Vec::new(),
                bodies: Vec::new(),
            };
            let outcome = self.newton_augmented(model, &mut u, 1.0, &mut rec);
            rec.converged = outcome.is_ok();
            rec.failure = outcome.as_ref().err().map(|e| format!("warm start: {e}"));
            report.newton_iterations += rec.iterations.len();
            report.factorizations += rec.iterations.len();
            on_increment(&rec);
            report.increments.push(rec);
            if outcome.is_ok() {
                report.converged_increments = 1;
                report.lambda = 1.0;
                report.wall_time_s = t0.elapsed().as_secs_f64();
                return Ok(self.solution(model, &u, report));
            }
            report.cutbacks += 1;
            u.fill(0.0);
            if let Err(e) = self.init_contact(model) {
                return Err(SolveError::Setup(LinearSolveError::Other(format!(
                    "the undeformed state cannot be assembled: {e}"
                ))));
            }
        }
        let step = model.step;
        let period = if step.period > 0.0 { step.period } else { 1.0 };
        let min_inc = (step.min_increment / period).max(1e-12);
        let max_inc = (step.max_increment / period).clamp(min_inc, 1.0);
        let mut dlambda = (step.initial_increment / period).clamp(min_inc, max_inc);
        let mut lambda = 0.0;
        let mut last_dlambda = 0.0;
        self.u_conv.fill(0.0);
        self.u_prev.fill(0.0);
        let mut increment = 0;
        let mut attempts = 0;
        while lambda < 1.0 - 1e-12 {
            attempts += 1;
            if report.converged_increments >= step.max_increments.max(1)
                || attempts > 10 * step.max_increments.max(1)
            {
                report.lambda = lambda;
                report.wall_time_s = t0.elapsed().as_secs_f64();
                let partial = Box::new(self.solution(model, &self.u_conv.clone(), report));
                return Err(SolveError::TooManyIncrements {
                    max: step.max_increments,
                    lambda,
                    partial,
                });
            }
            increment += 1;
            // An increment that would leave a sliver of the load (under a quarter of itself)
            // for a last increment of its own takes the sliver too: the last increment is the
            // one converged fully, and a separate tiny one would cost a whole Newton solve.
            let target = if lambda + 1.25 * dlambda >= 1.0 {
                1.0
            } else {
                lambda + dlambda
            };
            let dl = target - lambda;
            // Predictor: linear extrapolation of the last converged increment.
            u.copy_from_slice(&self.u_conv);
            if last_dlambda > 0.0 {
                let s = dl / last_dlambda;
                for d in 0..n_dof {
                    u[d] += s * (self.u_conv[d] - self.u_prev[d]);
                }
            }
            self.set_prescribed(&mut u, target);
            let mut rec = IncrementRecord {
                increment,
                lambda: target,
                dlambda: dl,
                converged: false,
                failure: None,
                iterations: Vec::new(),
                bodies: Vec::new(),
            };
            let mut outcome = self.newton_augmented(model, &mut u, target, &mut rec);
            if outcome.is_err() && last_dlambda > 0.0 && rec.iterations.is_empty() {
                // The extrapolated predictor inverted an element: retry from the last state.
                u.copy_from_slice(&self.u_conv);
                self.set_prescribed(&mut u, target);
                outcome = self.newton_augmented(model, &mut u, target, &mut rec);
            }
            report.newton_iterations += rec.iterations.len();
            report.factorizations += rec.iterations.len();
            match outcome {
                Ok(()) => {
                    rec.converged = true;
                    let iters = rec.iterations.len();
                    on_increment(&rec);
                    report.increments.push(rec);
                    report.converged_increments += 1;
                    std::mem::swap(&mut self.u_prev, &mut self.u_conv);
                    self.u_conv.copy_from_slice(&u);
                    lambda = target;
                    last_dlambda = dl;
                    if iters <= 2 {
                        dlambda = (2.0 * dl).min(max_inc);
                    } else if iters <= 4 {
                        dlambda = (dl * self.options.growth).min(max_inc);
                    } else {
                        dlambda = dl;
                    }
                }
                Err(failure) => {
                    rec.failure = Some(failure.to_string());
                    on_increment(&rec);
                    report.increments.push(rec);
                    report.cutbacks += 1;
                    dlambda = dl * self.options.cutback;
                    if dlambda < min_inc {
                        // Re-assemble at the last converged state so reactions are consistent.
                        let uc = self.u_conv.clone();
                        let _ = self.assemble(model, &uc, lambda, false);
                        report.lambda = lambda;
                        report.wall_time_s = t0.elapsed().as_secs_f64();
                        let mut reason = failure.to_string();
                        if let Some(hint) = limit_point_hint(model, &report) {
                            reason.push_str("; ");
                            reason.push_str(&hint);
                        }
                        let partial = Box::new(self.solution(model, &uc, report));
                        return Err(SolveError::NotConverged {
                            reason,
                            lambda,
                            dlambda,
                            min: min_inc,
                            partial,
                        });
                    }
                }
            }
        }
        report.lambda = 1.0;
        report.wall_time_s = t0.elapsed().as_secs_f64();
        Ok(self.solution(model, &u, report))
    }

    /// Assembles residual and tangent at a given state (λ = 1) and factorizes the tangent, so
    /// that [`StaticSolver::solve_tangent`] can be used (sensitivities).
    pub fn factorize_at(&mut self, model: &Model, u: &[f64]) -> Result<(), String> {
        self.assemble(model, u, 1.0, true)
            .map_err(|e| e.to_string())?;
        self.lu
            .factorize(&self.pattern, &self.values)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }

    /// Solves `K_T x = rhs` on the free dofs with the last factorized tangent.
    pub fn solve_tangent(&mut self, rhs: &mut [f64]) {
        self.lu.solve_in_place(rhs);
    }

    /// Solves `K_T X = B` for `columns` (≤ [`crate::linear::MAX_RHS`]) right-hand sides stored
    /// one after the other, in one pass over the factors.
    pub fn solve_tangent_many(&mut self, rhs: &mut [f64], columns: usize) {
        self.lu.solve_many_in_place(rhs, columns);
    }

    /// The full residual `f_int - λ f_ext` (2 per node) at the last assembled state.
    pub fn residual(&self) -> &[f64] {
        &self.residual
    }

    /// Assembles only the residual at the state `u` and λ = 1 and returns it (length
    /// [`Model::state_len`]: 2 per node, then one per rigid body).
    pub fn residual_at(&mut self, model: &Model, u: &[f64]) -> Result<&[f64], String> {
        self.assemble(model, u, 1.0, false)
            .map_err(|e| e.to_string())?;
        Ok(&self.residual)
    }

    /// The tangent on the free dofs at the last assembly with tangent (values on [`Self::pattern`]).
    pub fn tangent_values(&self) -> &[f64] {
        &self.values
    }

    /// Sets the automatic contact penalties as a solve does (for derivative checks of
    /// [`Self::assemble_at`] with contact).
    pub fn prepare_contact(&mut self, model: &Model) -> Result<(), String> {
        self.init_contact(model).map_err(|e| e.to_string())
    }

    /// The penalty ε of each rigid body (after a solve or [`Self::prepare_contact`]).
    pub fn penalties(&self) -> &[f64] {
        &self.penalties
    }

    /// Factorizes the tangent assembled last (e.g. by [`Self::assemble_at`]) without
    /// re-assembling it.
    pub fn refactorize(&mut self) -> Result<(), String> {
        let kind = self
            .lu
            .factorize(&self.pattern, &self.values)
            .map_err(|e| e.to_string())?;
        self.last_factorization = Some(kind);
        Ok(())
    }

    /// Whether the last assembly was of the tangent at `u` and λ = 1 (as at the end of a
    /// successful solve), so that [`Self::tangent_values`] are those at `u`.
    pub fn tangent_is_at(&self, u: &[f64]) -> bool {
        self.tangent_state.as_slice() == u
    }

    /// Whether a tangent has been factorized (by a solve or [`Self::factorize_at`]), so that
    /// [`Self::solve_tangent`] can be called.
    pub fn has_factorization(&self) -> bool {
        self.lu.last().is_some()
    }

    /// `y = K_T x` on the free dofs, with the tangent assembled last.
    pub fn tangent_mul(&self, x: &[f64], y: &mut [f64]) {
        self.pattern.mul_vec(&self.values, x, y);
    }

    /// The element-matrix buffer (`64` values per element), idle between assemblies: work
    /// memory another computation may borrow between two assemblies and swap back. If it is
    /// not given back, the next assembly allocates it again.
    pub fn element_scratch(&mut self) -> &mut Vec<f64> {
        &mut self.ke
    }

    /// `Y = K_T X` on the free dofs for `cols` vectors stored interleaved (`x[i * cols + j]`
    /// is equation `i` of vector `j`), with the tangent assembled last: one pass over
    /// the matrix (see [`CscPattern::mul_many_interleaved`]).
    pub fn tangent_mul_many_interleaved(&self, x: &[f64], y: &mut [f64], cols: usize) {
        self.lu
            .mul_many_interleaved(&self.pattern, &self.values, x, y, cols);
    }

    /// The contact constraints active at the state `u` with the multipliers of the last solve:
    /// every candidate node whose contact force `⟨λ̂ - ε g⟩₊` is positive.
    pub fn active_constraints(&self, model: &Model, u: &[f64]) -> Vec<ActiveConstraint> {
        let base = 2 * model.node_count();
        let mut out = Vec::new();
        for (b, c) in model.contacts.iter().enumerate() {
            let t = c.first_contact + u[base + b];
            let eps = self.penalties[b];
            for (k, &n) in c.nodes.iter().enumerate() {
                let gap = c.body.gap(model.current_position(n, u), t);
                let force = self.multipliers[b][k] - eps * gap.g;
                if force > 0.0 {
                    out.push(ActiveConstraint {
                        body: b,
                        node: n,
                        force,
                        dg_dx: gap.dg_dx,
                        dg_dt: gap.dg_dt,
                    });
                }
            }
        }
        out
    }

    /// Assembles residual and tangent at the state `u` (length [`Model::state_len`]), λ = 1
    /// (for derivative checks).
    pub fn assemble_at(&mut self, model: &Model, u: &[f64]) -> Result<(), String> {
        self.assemble(model, u, 1.0, true)
            .map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::DeckBuilder;
    use femu_mesh::generate;
    use femu_mesh::ElementKind;

    /// A solve whose element-matrix buffer was borrowed and not given back allocates it again
    /// and gives the same state.
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
        let first = solver.solve(&model).unwrap().u;
        let taken = std::mem::take(solver.element_scratch());
        assert_eq!(taken.len(), model.mesh.elements.len() * KE);
        let again = solver.solve(&model).unwrap().u;
        assert_eq!(first, again);
        assert_eq!(solver.element_scratch().len(), taken.len());
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

    /// [`TangentGather`] sums each tangent value in element order, as a serial scatter of the
    /// element matrices does: the same values to the bit, on quads and triangles.
    #[test]
    fn tangent_gather_equals_a_serial_scatter_to_the_bit() {
        let quads = generate::rectangle(2.0, 1.0, 6, 4, ElementKind::Cpe4);
        for g in [generate::split_into_triangles(&quads), quads] {
            let deck = DeckBuilder::new(g)
                .material_everywhere(0.01, 1.0)
                .fix("BOTTOM")
                .build();
            let model = Model::from_deck(deck).unwrap();
            let solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
            let slots = element_slots(&model, &solver.eq, &solver.pattern).unwrap();
            let nnz = solver.pattern.nnz();
            let gather = TangentGather::new(&slots, nnz).unwrap();
            // Element matrices of irregular values, so that the summation order shows.
            let ke: Vec<f64> = (0..slots.len())
                .map(|k| ((k * 7919) % 1013) as f64 / 97.0 - 5.0 + 1e-9 * k as f64)
                .collect();
            let mut scattered = vec![0.0; nnz];
            for (k, &p) in slots.iter().enumerate() {
                if p != NO_SLOT {
                    scattered[p as usize] += ke[k];
                }
            }
            let mut gathered = vec![f64::NAN; nnz];
            gather.gather(&ke, &mut gathered);
            assert_eq!(gathered, scattered);
        }
    }

    /// [`element_slots`] equals a binary search per (row, column) dof pair, on quads and
    /// triangles with fully, x-only and y-only prescribed nodes.
    #[test]
    fn element_slots_match_a_search_per_entry() {
        let quads = generate::rectangle(2.0, 1.0, 5, 3, ElementKind::Cpe4);
        for g in [generate::split_into_triangles(&quads), quads] {
            let deck = DeckBuilder::new(g)
                .material_everywhere(0.01, 1.0)
                .fix("BOTTOM")
                .displacement("LEFT", 0, 0.0)
                .displacement("TOP", 1, 0.1)
                .build();
            let model = Model::from_deck(deck).unwrap();
            let solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
            let slots = element_slots(&model, &solver.eq, &solver.pattern).unwrap();
            for (e, el) in model.mesh.elements.iter().enumerate() {
                let nd = 2 * el.kind.node_count();
                let dofs: Vec<usize> = el
                    .nodes()
                    .iter()
                    .flat_map(|&n| [solver.eq[2 * n], solver.eq[2 * n + 1]])
                    .collect();
                for r in 0..MAX_DOFS {
                    for c in 0..MAX_DOFS {
                        let expected = if r < nd && c < nd && dofs[r] != NONE && dofs[c] != NONE {
                            solver.pattern.position(dofs[r], dofs[c]).unwrap() as Slot
                        } else {
                            NO_SLOT
                        };
                        if r < nd && c < nd {
                            assert_eq!(
                                slots[e * KE + r * nd + c],
                                expected,
                                "element {e} ({r}, {c})"
                            );
                        }
                    }
                }
            }
        }
    }
}
