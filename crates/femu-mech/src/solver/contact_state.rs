//! The state of the rigid bodies' contact during a solve (see [`crate::contact`] for the
//! augmented-Lagrangian formulation): each body's automatic penalty ε, the multiplier estimates
//! λ̂ of its candidate nodes and their Uzawa updates, the active set of the last assembly (for
//! Newton's cycle detection), the contact terms of the residual and tangent, and the step limit
//! that keeps a Newton step from driving free nodes deep into a body.

use super::active_set::{Along, Candidate};
use super::assembly::{DofMap, System, NONE};
use super::interface_state::InterfaceState;
use crate::contact::BodyState;
use crate::contact::TravelControl;
use crate::model::Model;
use femu_sparse::CscPattern;

/// A node in contact with a rigid body at a converged state (see
/// [`crate::solver::Linearization::active_constraints`]): its contact force and the gap
/// gradient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveConstraint {
    pub body: usize,
    pub node: usize,
    /// Contact force λ (N per mm, > 0).
    pub force: f64,
    pub dg_dx: [f64; 2],
    pub dg_dt: f64,
}

/// The contact nodes active at an assembly: their count and a fingerprint of which they are
/// (equal sets give equal fingerprints; Newton compares the sets of successive iterations).
pub(crate) type ActiveSet = (usize, u64);

/// Whether a node with trial force `trial = λ̂ - ε g` counts as in contact: touching within
/// round-off counts (the first-contact node starts at `g = 0` up to rounding), so that the
/// travel has stiffness from the start.
fn in_contact(trial: f64, eps: f64, element_size: f64) -> bool {
    trial >= -eps * 1e-12 * element_size
}

/// The gap (a fraction of the body's element size) within which a candidate node of a warm
/// start counts as touching when its multiplier is estimated from equilibrium
/// ([`ContactState::estimate_multipliers`]): a converged state's nodes touch within round-off,
/// a state carried from another mesh of the same outline within its chords' sag.
pub(crate) const WARM_GAP_FRACTION: f64 = 0.05;

/// Contact state of every rigid body of a model.
#[derive(Debug)]
pub(crate) struct ContactState {
    /// Per rigid body and candidate node: positions in the tangent values of
    /// (xx, xy, yx, yy, xt, yt, tx, ty) (`NONE` for a prescribed row or column).
    slots: Vec<Vec<[usize; 8]>>,
    /// Per rigid body: position of (t, t) (`NONE` under displacement control).
    tt: Vec<usize>,
    /// Per rigid body: the multiplier estimates λ̂ of its candidate nodes.
    multipliers: Vec<Vec<f64>>,
    /// Per rigid body: the penalty ε (set at the start of each solve).
    penalties: Vec<f64>,
    /// Per rigid body: Uzawa updates made in this solve.
    augmentations: Vec<usize>,
    /// Per rigid body: the complementarity error allowed at the last update check.
    limits: Vec<f64>,
    /// The active set of the last assembly.
    active_set: ActiveSet,
    /// The sliding interfaces between regions.
    pub interfaces: InterfaceState,
}

impl ContactState {
    /// The tangent positions of every body's contact entries in `pattern`; penalties and
    /// multipliers zero.
    pub fn new(model: &Model, dofs: &DofMap, pattern: &CscPattern) -> Self {
        let eq = &dofs.eq;
        let n_nodes_dof = 2 * model.node_count();
        let pos = |r: usize, col: usize| {
            if r == NONE || col == NONE {
                NONE
            } else {
                pattern.position(r, col).expect("contact entry in pattern")
            }
        };
        let slots = model
            .contacts
            .iter()
            .enumerate()
            .map(|(b, c)| {
                let qt = eq[n_nodes_dof + b];
                c.nodes
                    .iter()
                    .map(|&n| {
                        let (qx, qy) = (eq[2 * n], eq[2 * n + 1]);
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
        let tt = (0..model.contacts.len())
            .map(|b| pos(eq[n_nodes_dof + b], eq[n_nodes_dof + b]))
            .collect();
        ContactState {
            slots,
            tt,
            multipliers: model
                .contacts
                .iter()
                .map(|c| vec![0.0; c.nodes.len()])
                .collect(),
            penalties: vec![0.0; model.contacts.len()],
            augmentations: vec![0; model.contacts.len()],
            limits: model
                .contacts
                .iter()
                .map(|c| c.penetration_tolerance * c.element_size)
                .collect(),
            active_set: (0, 0),
            interfaces: InterfaceState::new(model, dofs, pattern),
        }
    }

    /// The active set of the last assembly.
    pub fn active_set(&self) -> ActiveSet {
        self.active_set
    }

    /// Whether every body has its penalty (set by a solve), so that a warm start can keep it.
    pub fn has_penalties(&self) -> bool {
        self.penalties.iter().all(|&p| p > 0.0)
    }

    /// The multiplier estimates of every body (to restore them after a failed attempt).
    pub fn multipliers(&self) -> &[Vec<f64>] {
        &self.multipliers
    }

    /// Restores multiplier estimates saved by [`Self::multipliers`].
    pub fn restore_multipliers(&mut self, saved: Vec<Vec<f64>>) {
        self.multipliers = saved;
    }

    /// Zero penalties: the contact terms vanish (for the assembly the penalties are taken from).
    pub fn clear_penalties(&mut self) {
        self.penalties.iter_mut().for_each(|p| *p = 0.0);
    }

    /// Sets each body's penalty from the largest diagonal stiffness of its candidate dofs in
    /// `values` (the tangent at the undeformed state: the "automatic penalty") and clears the
    /// multipliers and the augmentation counts.
    pub fn set_penalties(&mut self, model: &Model, values: &[f64]) {
        for (b, c) in model.contacts.iter().enumerate() {
            let mut kmax = 0.0f64;
            for s in &self.slots[b] {
                for pos in [s[0], s[3]] {
                    if pos != NONE {
                        kmax = kmax.max(values[pos].abs());
                    }
                }
            }
            self.penalties[b] = c.penalty_factor * kmax.max(1e-12);
            self.multipliers[b].iter_mut().for_each(|m| *m = 0.0);
            self.augmentations[b] = 0;
            self.limits[b] = c.penetration_tolerance * c.element_size;
        }
    }

    /// Adds the rigid-body contact terms at `u` to `system` (residual, and the tangent if
    /// `with_tangent`) and, under force control, the applied force `λ F` on the travel
    /// equation; records the active set.
    pub fn add_terms(
        &mut self,
        model: &Model,
        u: &[f64],
        lambda: f64,
        with_tangent: bool,
        system: &mut System,
    ) {
        let base = 2 * model.node_count();
        self.active_set = (0, 0);
        for (b, c) in model.contacts.iter().enumerate() {
            let tdof = base + b;
            let t = c.first_contact + u[tdof];
            if let TravelControl::Force(f) = c.control {
                system.residual[tdof] -= lambda * f;
                system.fext[tdof] += lambda * f;
            }
            let eps = self.penalties[b];
            for (k, &n) in c.nodes.iter().enumerate() {
                let gap = c.body.gap(model.current_position(n, u), t);
                let trial = self.multipliers[b][k] - eps * gap.g;
                if !in_contact(trial, eps, c.element_size) {
                    continue;
                }
                let lam = trial.max(0.0);
                self.active_set.0 += 1;
                self.active_set.1 = self
                    .active_set
                    .1
                    .wrapping_mul(31)
                    .wrapping_add(k as u64 + 1);
                system.residual[2 * n] -= lam * gap.dg_dx[0];
                system.residual[2 * n + 1] -= lam * gap.dg_dx[1];
                system.residual[tdof] -= lam * gap.dg_dt;
                if with_tangent {
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
                    for (pos, v) in self.slots[b][k].iter().zip(vals) {
                        if *pos != NONE {
                            system.values[*pos] += v;
                        }
                    }
                    if self.tt[b] != NONE {
                        system.values[self.tt[b]] +=
                            eps * gap.dg_dt * gap.dg_dt - lam * gap.d2g_dtdt;
                    }
                }
            }
        }
    }

    /// Multiplier estimates from equilibrium at a state `u` solved elsewhere (a warm start in
    /// a solver that has not solved this model: its multipliers are zero), given the residual
    /// `residual` assembled at `u` with the current multipliers (dof layout).
    ///
    /// At a converged augmented-Lagrangian state the penalty carries almost none of the
    /// contact force (the penetration is below the force tolerance over ε); the multipliers
    /// carry it. Zero multipliers leave the whole contact force in the residual (on the
    /// thigh's indentation the warm start then began at `|R|` ≈ the applied force and failed,
    /// and the solve followed the load increments from zero). Each free candidate node within
    /// [`WARM_GAP_FRACTION`] of an element of its body takes the force that balances the
    /// normal part of the tissue's residual there, `λ = (R_el · ∇g) / |∇g|²` with
    /// `R_el = R + λ_cur ∇g` (the residual without this node's current contact force), when
    /// that force pushes the node against the body by more than `force_tolerance` (the residual
    /// tolerance times the reference force: a node beside the contact zone is balanced to
    /// within it, and made active with a force of nothing Newton would move it); `λ̂ = λ + ε g`,
    /// so that `⟨λ̂ - ε g⟩₊ = λ`.
    pub fn estimate_multipliers(
        &mut self,
        model: &Model,
        u: &[f64],
        residual: &[f64],
        force_tolerance: f64,
    ) {
        let base = 2 * model.node_count();
        for (b, c) in model.contacts.iter().enumerate() {
            let t = c.first_contact + u[base + b];
            let eps = self.penalties[b];
            let reach = WARM_GAP_FRACTION * c.element_size;
            for (k, &n) in c.nodes.iter().enumerate() {
                let [sx, _, _, sy, ..] = self.slots[b][k];
                if sx == NONE || sy == NONE {
                    continue;
                }
                let gap = c.body.gap(model.current_position(n, u), t);
                let norm2 = gap.dg_dx[0] * gap.dg_dx[0] + gap.dg_dx[1] * gap.dg_dx[1];
                if gap.g > reach || norm2 <= 0.0 {
                    continue;
                }
                let m = &mut self.multipliers[b][k];
                let current = (*m - eps * gap.g).max(0.0);
                let tissue = [
                    residual[2 * n] + current * gap.dg_dx[0],
                    residual[2 * n + 1] + current * gap.dg_dx[1],
                ];
                let lam = (tissue[0] * gap.dg_dx[0] + tissue[1] * gap.dg_dx[1]) / norm2;
                if lam > force_tolerance {
                    *m = (lam + eps * gap.g).max(0.0);
                }
            }
        }
    }

    /// Uzawa update `λ̂ ← ⟨λ̂ - ε g⟩₊` for the bodies whose complementarity error (a
    /// penetration, or an open gap under a contact force) exceeds their limit (see
    /// [`Self::limit`]), each node that keeps a force moved onto the body's surface; returns
    /// whether any body was updated.
    ///
    /// The update alone doubles the contact forces at the state it is made at (the multiplier
    /// takes over the force `-ε g` and the penalty still adds it): a load as large as the whole
    /// contact force, pushing the tissue in, with the curvature term `-λ ∇²g` of the tangent
    /// doubled too, which on the 10 000-quad CPE4 indentation turned the tangent indefinite and
    /// Newton away. Closing each node's gap with the update (`x ← x - g ∇g / |∇g|²`) keeps
    /// every contact force as it was: the state is then off equilibrium only by the tissue's
    /// response to nodes moved by their penetration (hundredths of a millimetre).
    pub fn augment(&mut self, model: &Model, u: &mut [f64], force_tolerance: f64) -> bool {
        let base = 2 * model.node_count();
        let mut updated = false;
        for (b, c) in model.contacts.iter().enumerate() {
            let t = c.first_contact + u[base + b];
            let eps = self.penalties[b];
            self.limits[b] = self.limit(model, b, force_tolerance);
            // Complementarity error: a penetration, or a gap at a node that still carries a
            // contact force (the multiplier overshot).
            let violation =
                c.nodes
                    .iter()
                    .zip(&self.multipliers[b])
                    .fold(0.0f64, |m, (&n, &lam)| {
                        let g = c.body.gap(model.current_position(n, u), t).g;
                        if g < 0.0 {
                            m.max(-g)
                        } else if lam - eps * g > 0.0 {
                            m.max(g)
                        } else {
                            m
                        }
                    });
            if violation <= self.limits[b] {
                continue;
            }
            for (k, &n) in c.nodes.iter().enumerate() {
                let gap = c.body.gap(model.current_position(n, u), t);
                let m = &mut self.multipliers[b][k];
                *m = (*m - eps * gap.g).max(0.0);
                let [sx, _, _, sy, ..] = self.slots[b][k];
                let norm2 = gap.dg_dx[0] * gap.dg_dx[0] + gap.dg_dx[1] * gap.dg_dx[1];
                if *m > 0.0 && sx != NONE && sy != NONE && norm2 > 0.0 {
                    u[2 * n] -= gap.g * gap.dg_dx[0] / norm2;
                    u[2 * n + 1] -= gap.g * gap.dg_dx[1] / norm2;
                }
            }
            self.augmentations[b] += 1;
            updated = true;
        }
        updated
    }

    /// The complementarity error allowed at the end of a solve for body `b`: the body's
    /// penetration tolerance (a fraction of its element size), and at most the gap at which
    /// the penalty's force `ε g` is `force_tolerance` (the residual tolerance times the
    /// reference force): another Uzawa update would then change the contact forces by less
    /// than the equilibrium residual allowed, so the multipliers are converged as tightly as
    /// the equilibrium and the state is that of exact contact to the solve's own precision
    /// (the penalty alone leaves it off by the penetration, about 1e-4 of the displacements
    /// after one update on the thigh's indentation).
    fn limit(&self, model: &Model, b: usize, force_tolerance: f64) -> f64 {
        let c = &model.contacts[b];
        let geometric = c.penetration_tolerance * c.element_size;
        if force_tolerance > 0.0 {
            geometric.min(force_tolerance / self.penalties[b])
        } else {
            geometric
        }
    }

    /// The candidate nodes of every body linearized at `u` (equations from `eq`), into `out`
    /// (see [`super::active_set`]).
    pub fn linearize(&self, model: &Model, u: &[f64], eq: &[usize], out: &mut Vec<Candidate>) {
        out.clear();
        let base = 2 * model.node_count();
        for (b, c) in model.contacts.iter().enumerate() {
            let t = c.first_contact + u[base + b];
            let eps = self.penalties[b];
            let qt = eq[base + b];
            for (k, &n) in c.nodes.iter().enumerate() {
                let gap = c.body.gap(model.current_position(n, u), t);
                let trial = self.multipliers[b][k] - eps * gap.g;
                let (xx, xt) = (gap.d2g_dxdx, gap.d2g_dxdt);
                out.push(Candidate {
                    eqs: [eq[2 * n], eq[2 * n + 1], qt],
                    grad: [gap.dg_dx[0], gap.dg_dx[1], gap.dg_dt],
                    hess: [
                        [xx[0][0], xx[0][1], xt[0]],
                        [xx[1][0], xx[1][1], xt[1]],
                        [xt[0], xt[1], gap.d2g_dtdt],
                    ],
                    trial,
                    eps,
                    active: in_contact(trial, eps, c.element_size),
                    node: n,
                    body: b,
                    gap: gap.g,
                });
            }
        }
    }

    /// The second-order correction of a trial state `u + α δ` (Nocedal & Wright, Numerical
    /// Optimization, §15.6): each free node that the correction `δ` brings or keeps in contact
    /// is moved along its gap gradient until its gap is the linearized one, `g + α ∇gᵀ δ`.
    ///
    /// The correction's linear model slides a node in contact along the tangent of a curved
    /// body; the true gap then opens by the curvature term (`s²/2R` for a slip `s` on a
    /// cylinder), which the stiff penalty turns into a force error of `ε s²/2R`, easily the
    /// whole contact force: the full step would be refused, or leave the node free. Moved back
    /// onto the surface, the node follows the body as the model meant it to.
    pub fn second_order_correction(
        &self,
        model: &Model,
        candidates: &[Candidate],
        along: &[Along],
        alpha: f64,
        trial: &mut [f64],
    ) {
        let base = 2 * model.node_count();
        for (c, a) in candidates.iter().zip(along) {
            if !a.in_contact || c.eqs[0] == NONE || c.eqs[1] == NONE {
                continue;
            }
            let body = &model.contacts[c.body];
            let t = body.first_contact + trial[base + c.body];
            let gap = body.body.gap(model.current_position(c.node, trial), t);
            let d = c.gap + alpha * a.slope - gap.g;
            trial[2 * c.node] += d * gap.dg_dx[0];
            trial[2 * c.node + 1] += d * gap.dg_dx[1];
        }
    }

    /// The largest step length in (0, 1] from `u` towards `full` (the state after the full
    /// correction) for which no contact node that is free at `u`, and that the correction does
    /// not bring into contact (`along`, see [`super::active_set`]), penetrates its body deeper
    /// than 0.1 element size (gaps taken linear in the step).
    pub fn step_limit(&self, model: &Model, u: &[f64], full: &[f64], along: &[Along]) -> f64 {
        let base = 2 * model.node_count();
        let mut cap = 1.0f64;
        let mut index = 0;
        for (b, c) in model.contacts.iter().enumerate() {
            let depth = 0.1 * c.element_size;
            let eps = self.penalties[b];
            let t0 = c.first_contact + u[base + b];
            let t1 = c.first_contact + full[base + b];
            for (k, &n) in c.nodes.iter().enumerate() {
                let brought = along.get(index).is_some_and(|a| a.in_contact);
                index += 1;
                if brought {
                    continue; // the correction put it in contact (see `second_order_correction`)
                }
                let g0 = c.body.gap(model.current_position(n, u), t0).g;
                if self.multipliers[b][k] - eps * g0 > 0.0 || g0 <= 0.0 {
                    continue; // in contact already
                }
                let g1 = c.body.gap(model.current_position(n, full), t1).g;
                if g1 < -depth {
                    cap = cap.min((g0 + depth) / (g0 - g1));
                }
            }
        }
        cap.clamp(1e-3, 1.0)
    }

    /// Contact results of every body at state `u`.
    pub fn body_states(&self, model: &Model, u: &[f64]) -> Vec<BodyState> {
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
                    penetration_limit: self.limits[b],
                    augmentations: self.augmentations[b],
                    ..Default::default()
                };
                for (k, &n) in c.nodes.iter().enumerate() {
                    let gap = c.body.gap(model.current_position(n, u), t);
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

    /// The contact constraints active at the state `u` with the current multipliers: every
    /// candidate node whose contact force `⟨λ̂ - ε g⟩₊` is positive.
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
}
