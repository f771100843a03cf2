//! The state of the model's sliding interfaces during a solve (see [`crate::interface`] for the
//! formulation): each slave node's penalties, normal multiplier estimate and friction stick
//! point, the interface terms of the residual and the tangent, the Uzawa updates of the
//! multipliers and the stick points' update at each converged increment.

use super::assembly::{DofMap, System, NONE};
use crate::interface::smooth::N;
use crate::interface::{Interface, InterfaceKind, PairGap, Penalty, SlaveState};
use crate::model::Model;
use femu_sparse::CscPattern;
use std::collections::HashMap;

/// Whether a slave node with trial force `trial = λ̂ - ε g` counts as in contact: touching
/// within round-off counts (the nodes of a split interface start at `g = 0` up to rounding).
fn in_contact(trial: f64, eps: f64, element_size: f64) -> bool {
    trial >= -eps * 1e-12 * element_size
}

/// The state of one interface's slave nodes.
#[derive(Debug, Clone, Default)]
struct Slaves {
    /// Normal penalty ε and tangential penalty ε_T of each slave node.
    eps: Vec<f64>,
    eps_t: Vec<f64>,
    /// Normal multiplier estimate λ̂ of each slave node.
    multipliers: Vec<f64>,
    /// Stick point of each slave node as a reference arc coordinate on the master surface
    /// (NaN: none, the node was not in contact at the last converged increment).
    stick: Vec<f64>,
    /// The segment each slave node is paired with (`usize::MAX`: none): set at the start of a
    /// solve, kept through Newton's iterations, and moved to the closest segment at each
    /// converged increment and at the end of the step (see
    /// [`Interface::closest_preferring`]).
    segment: Vec<usize>,
    augmentations: usize,
    /// The complementarity error allowed at the last update check.
    limit: f64,
}

/// The state of every sliding interface of a model.
#[derive(Debug, Default)]
pub(crate) struct InterfaceState {
    slaves: Vec<Slaves>,
    /// Position in the tangent values of each (row, column) equation pair an interface couples.
    positions: HashMap<(usize, usize), usize>,
    /// Equation of each dof (empty without interfaces).
    eq: Vec<usize>,
    /// Slave nodes in contact at the last assembly, and a fingerprint of which.
    pub active: (usize, u64),
}

/// The residual and tangent of one slave node on its segment at `u`: the dofs `(x_s, x_a, x_b,
/// x_p, x_n)` (`NONE` for a missing neighbour) and the contributions.
struct SlaveTerms {
    dofs: [usize; N],
    force: [f64; N],
    stiffness: [[f64; N]; N],
    state: SlaveState,
    /// Whether the node is in contact (its terms count).
    active: bool,
    /// The node's convective coordinate on its segment.
    xi: f64,
}

/// The segment of slave `k` at `u` and its gap (see [`Interface::closest_preferring`]).
fn pairing(
    model: &Model,
    iface: &Interface,
    st: &Slaves,
    k: usize,
    u: &[f64],
) -> Option<(usize, PairGap)> {
    let preferred = (st.segment[k] != usize::MAX).then_some(st.segment[k]);
    iface.closest_preferring(k, |n| model.current_position(n, u), preferred)
}

/// The contribution of slave `k` of `iface` at `u` (`st`: its interface's state).
fn slave_terms(model: &Model, iface: &Interface, st: &Slaves, k: usize, u: &[f64]) -> SlaveTerms {
    let node = iface.slaves[k];
    let mut out = SlaveTerms {
        dofs: [NONE; N],
        force: [0.0; N],
        stiffness: [[0.0; N]; N],
        state: SlaveState {
            node,
            ..Default::default()
        },
        active: false,
        xi: f64::NAN,
    };
    let Some((s, gap)) = pairing(model, iface, st, k, u) else {
        return out;
    };
    for (i, m) in std::iter::once(node)
        .chain(iface.segment_nodes(s))
        .enumerate()
    {
        if m != usize::MAX {
            out.dofs[2 * i] = 2 * m;
            out.dofs[2 * i + 1] = 2 * m + 1;
        }
    }
    out.state.segment = Some(s);
    out.xi = gap.xi;
    out.state.gap = gap.g;
    out.state.arc = iface.arc(s, gap.xi);
    let eps = st.eps[k];
    let trial = st.multipliers[k] - eps * gap.g;
    if !in_contact(trial, eps, iface.element_size) {
        return out;
    }
    out.active = true;
    let n_force = trial.max(0.0);
    out.state.normal_force = n_force;
    for i in 0..N {
        out.force[i] = -n_force * gap.dg[i];
        for j in 0..N {
            out.stiffness[i][j] = eps * gap.dg[i] * gap.dg[j] - n_force * gap.d2g[i][j];
        }
    }
    let mu = iface.mu();
    let stick = st.stick[k];
    if mu > 0.0 && stick.is_finite() {
        friction(iface, st, k, s, &gap, n_force, &mut out);
    }
    out
}

/// Adds the Coulomb friction of slave `k` on segment `s` (module docs of
/// [`crate::interface`]: stick spring or slip at `μ N`, return mapping).
fn friction(
    iface: &Interface,
    st: &Slaves,
    k: usize,
    s: usize,
    gap: &PairGap,
    n_force: f64,
    out: &mut SlaveTerms,
) {
    let mu = iface.mu();
    let (eps, eps_t) = (st.eps[k], st.eps_t[k]);
    let xi_bar = iface.xi_of_arc(s, st.stick[k]);
    let (gt, dgt, d2gt) = gap.slip(xi_bar);
    let trial_t = eps_t * gt;
    if trial_t.abs() <= mu * n_force {
        for i in 0..N {
            out.force[i] += trial_t * dgt[i];
            for j in 0..N {
                out.stiffness[i][j] += eps_t * (dgt[i] * dgt[j] + gt * d2gt[i][j]);
            }
        }
        out.state.tangential_force = trial_t;
        // On the cone (as after the return mapping of a converged slipping increment) the
        // node counts as slipping: both branches give the same force there.
        out.state.slipping = trial_t.abs() >= mu * n_force * (1.0 - 1e-9);
    } else {
        let sign = gt.signum();
        let t = mu * n_force * sign;
        // N = λ̂ - ε g_N while in contact: ∂N = -ε ∂g_N.
        for i in 0..N {
            out.force[i] += t * dgt[i];
            for j in 0..N {
                out.stiffness[i][j] += -mu * sign * eps * dgt[i] * gap.dg[j] + t * d2gt[i][j];
            }
        }
        out.state.tangential_force = t;
        out.state.slipping = true;
    }
}

impl InterfaceState {
    /// The tangent positions of every interface's couplings in `pattern` (whose node graph
    /// holds [`Interface::coupled_nodes`]); penalties, multipliers and stick points zero.
    pub fn new(model: &Model, dofs: &DofMap, pattern: &CscPattern) -> Self {
        let eq = &dofs.eq;
        let mut positions = HashMap::new();
        for iface in &model.interfaces {
            for group in iface.coupled_nodes() {
                let eqs: Vec<usize> = group
                    .iter()
                    .flat_map(|&n| [eq[2 * n], eq[2 * n + 1]])
                    .filter(|&q| q != NONE)
                    .collect();
                for &r in &eqs {
                    for &c in &eqs {
                        positions.entry((r, c)).or_insert_with(|| {
                            pattern.position(r, c).expect("interface entry in pattern")
                        });
                    }
                }
            }
        }
        let slaves = model
            .interfaces
            .iter()
            .map(|i| {
                let n = i.slaves.len();
                Slaves {
                    eps: vec![0.0; n],
                    eps_t: vec![0.0; n],
                    multipliers: vec![0.0; n],
                    stick: vec![f64::NAN; n],
                    segment: vec![usize::MAX; n],
                    augmentations: 0,
                    limit: i.penetration_tolerance * i.element_size,
                }
            })
            .collect();
        InterfaceState {
            slaves,
            positions,
            eq: if model.interfaces.is_empty() {
                Vec::new()
            } else {
                eq.clone()
            },
            active: (0, 0),
        }
    }

    /// Whether every interface has its penalties (set by a solve).
    pub fn has_penalties(&self) -> bool {
        self.slaves
            .iter()
            .all(|s| s.eps.iter().all(|&e| e > 0.0) || s.eps.is_empty())
    }

    /// Zero penalties: the interface terms vanish.
    pub fn clear_penalties(&mut self) {
        for s in &mut self.slaves {
            s.eps.iter_mut().for_each(|e| *e = 0.0);
            s.eps_t.iter_mut().for_each(|e| *e = 0.0);
        }
    }

    /// Sets the penalties (automatic: from the largest diagonal stiffness of the slave node's
    /// dofs in `values`, the tangent at the undeformed state), clears the multipliers, and puts
    /// the stick point of every slave node touching its master surface at the undeformed state
    /// (`g ≤ 1e-9` of the element size) where it touches.
    pub fn set_penalties(&mut self, model: &Model, values: &[f64]) {
        let zero = vec![0.0; model.state_len()];
        for (iface, st) in model.interfaces.iter().zip(&mut self.slaves) {
            for (k, &n) in iface.slaves.iter().enumerate() {
                let (eps, eps_t) = match iface.penalty {
                    Penalty::Automatic { factor } => {
                        let mut kmax = 0.0f64;
                        for d in [2 * n, 2 * n + 1] {
                            let q = self.eq[d];
                            if q != NONE {
                                kmax = kmax.max(values[self.positions[&(q, q)]].abs());
                            }
                        }
                        let e = factor * kmax.max(1e-12);
                        (e, e)
                    }
                    Penalty::Fixed { k: kn, stick_slope } => {
                        (kn * iface.tributary[k], stick_slope * iface.tributary[k])
                    }
                };
                st.eps[k] = eps;
                st.eps_t[k] = eps_t;
                st.multipliers[k] = 0.0;
                let closest = iface.closest(k, |m| model.current_position(m, &zero));
                st.segment[k] = closest.as_ref().map_or(usize::MAX, |(s, _)| *s);
                st.stick[k] = match closest {
                    Some((s, g)) if g.g <= 1e-9 * iface.element_size => iface.arc(s, g.xi),
                    _ => f64::NAN,
                };
            }
            st.augmentations = 0;
            st.limit = iface.penetration_tolerance * iface.element_size;
        }
    }

    /// Adds the interface terms at `u` to `system` (residual, and the tangent if
    /// `with_tangent`); records the slave nodes in contact.
    pub fn add_terms(&mut self, model: &Model, u: &[f64], with_tangent: bool, system: &mut System) {
        self.active = (0, 0);
        for (iface, st) in model.interfaces.iter().zip(&self.slaves) {
            for k in 0..iface.slaves.len() {
                let t = slave_terms(model, iface, st, k, u);
                if !t.active {
                    continue;
                }
                self.active.0 += 1;
                self.active.1 = self.active.1.wrapping_mul(31).wrapping_add(k as u64 + 1);
                for i in 0..N {
                    if t.dofs[i] != NONE {
                        system.residual[t.dofs[i]] += t.force[i];
                    }
                }
                if !with_tangent {
                    continue;
                }
                let eqs = t.dofs.map(|d| if d == NONE { NONE } else { self.eq[d] });
                for i in 0..N {
                    if eqs[i] == NONE {
                        continue;
                    }
                    for j in 0..N {
                        if eqs[j] != NONE {
                            system.values[self.positions[&(eqs[i], eqs[j])]] += t.stiffness[i][j];
                        }
                    }
                }
            }
        }
    }

    /// The outer updates at a converged state `u`: the slave nodes whose projection left their
    /// segment are paired with their closest one; otherwise, the Uzawa update
    /// `λ̂ ← ⟨λ̂ - ε g⟩₊` of the interfaces with automatic penalties whose complementarity error
    /// exceeds their limit (as for the rigid contact, see `ContactState::augment`), each slave
    /// node that keeps a force moved onto its segment along the normal, which keeps its force
    /// as it was. Returns whether anything was updated (Newton then converges again).
    pub fn augment(&mut self, model: &Model, u: &mut [f64], force_tolerance: f64) -> bool {
        let mut updated = false;
        for (iface, st) in model.interfaces.iter().zip(&mut self.slaves) {
            let gaps: Vec<Option<PairGap>> = (0..iface.slaves.len())
                .map(|k| pairing(model, iface, st, k, u).map(|(_, g)| g))
                .collect();
            // Re-pairing first: the nodes whose projection left their segment take their
            // closest one, and Newton converges again with it before any multiplier update.
            let mut repaired = false;
            for (k, gap) in gaps.iter().enumerate() {
                if gap
                    .as_ref()
                    .is_some_and(|g| (-1e-3..=1.0 + 1e-3).contains(&g.xi))
                {
                    continue;
                }
                if let Some((s, g)) = iface.closest(k, |n| model.current_position(n, u)) {
                    if s != st.segment[k] && (-1e-3..=1.0 + 1e-3).contains(&g.xi) {
                        st.segment[k] = s;
                        repaired = true;
                    }
                }
            }
            if repaired {
                updated = true;
                continue;
            }
            if !matches!(iface.penalty, Penalty::Automatic { .. }) {
                continue;
            }
            let eps_max = st.eps.iter().fold(0.0f64, |m, &e| m.max(e));
            let geometric = iface.penetration_tolerance * iface.element_size;
            st.limit = if force_tolerance > 0.0 && eps_max > 0.0 {
                geometric.min(force_tolerance / eps_max)
            } else {
                geometric
            };
            let violation = gaps.iter().enumerate().fold(0.0f64, |m, (k, g)| match g {
                Some(g) if g.g < 0.0 => m.max(-g.g),
                Some(g) if st.multipliers[k] - st.eps[k] * g.g > 0.0 => m.max(g.g),
                _ => m,
            });
            if violation <= st.limit {
                continue;
            }
            for (k, g) in gaps.iter().enumerate() {
                let Some(g) = g else { continue };
                let m = &mut st.multipliers[k];
                *m = (*m - st.eps[k] * g.g).max(0.0);
                let n = iface.slaves[k];
                if *m > 0.0 && self.eq[2 * n] != NONE && self.eq[2 * n + 1] != NONE {
                    u[2 * n] -= g.g * g.dg[0];
                    u[2 * n + 1] -= g.g * g.dg[1];
                }
            }
            st.augmentations += 1;
            updated = true;
        }
        updated
    }

    /// The multiplier estimates of every interface (after those of the rigid bodies).
    pub fn multipliers(&self) -> impl Iterator<Item = Vec<f64>> + '_ {
        self.slaves.iter().map(|s| s.multipliers.clone())
    }

    /// Restores multipliers saved by [`Self::multipliers`].
    pub fn restore_multipliers(&mut self, saved: impl Iterator<Item = Vec<f64>>) {
        for (s, m) in self.slaves.iter_mut().zip(saved) {
            s.multipliers = m;
        }
    }

    /// The history at a converged increment `u`: each slave node's segment, and the friction
    /// stick points (a slave node out of contact loses its stick point, one coming into contact
    /// sticks where it touches, one slipping has its stick point moved to where its spring
    /// holds `μ N` exactly: the return mapping).
    pub fn commit(&mut self, model: &Model, u: &[f64]) {
        for (iface, st) in model.interfaces.iter().zip(&mut self.slaves) {
            let friction = matches!(iface.kind, InterfaceKind::Friction { .. });
            for k in 0..iface.slaves.len() {
                let t = slave_terms(model, iface, st, k, u);
                // A node whose projection left its segment starts the next increment on its
                // closest one (a node within its segment keeps it: at a master vertex, where
                // two segments are equally close, re-pairing would turn its force at every
                // increment, whatever the increment's size).
                let inside = t.state.segment.is_some() && (-1e-3..=1.0 + 1e-3).contains(&t.xi);
                if !inside {
                    let closest = iface.closest(k, |n| model.current_position(n, u));
                    st.segment[k] = closest.map_or(usize::MAX, |(s, _)| s);
                }
                if !friction {
                    continue;
                }
                let Some(s) = t.state.segment else {
                    st.stick[k] = f64::NAN;
                    continue;
                };
                if !t.active || t.state.normal_force <= 0.0 {
                    st.stick[k] = f64::NAN;
                } else if !st.stick[k].is_finite() {
                    st.stick[k] = t.state.arc;
                } else if t.state.slipping {
                    // g_T after the move: sign(g_T) μ N / ε_T, i.e. the stick point trails the
                    // node's closest point by that much (in the segment's length).
                    let len = {
                        let [a, b] = iface.segments[s];
                        let (xa, xb) = (model.current_position(a, u), model.current_position(b, u));
                        (xb[0] - xa[0]).hypot(xb[1] - xa[1])
                    };
                    let xi = iface.xi_of_arc(s, t.state.arc);
                    let back = t.state.tangential_force / (st.eps_t[k] * len);
                    st.stick[k] = iface.arc(s, xi - back);
                }
            }
        }
    }

    /// The state of every interface's slave nodes at `u`.
    pub fn states(&self, model: &Model, u: &[f64]) -> Vec<Vec<SlaveState>> {
        model
            .interfaces
            .iter()
            .zip(&self.slaves)
            .map(|(iface, st)| {
                (0..iface.slaves.len())
                    .map(|k| slave_terms(model, iface, st, k, u).state)
                    .collect()
            })
            .collect()
    }

    /// The gap gradient `(state dof, ∂g_N)` of every slave node of the frictionless interfaces
    /// with a positive contact force at `u`: the constraints `∂g_N·δu = 0` of the exactly
    /// constrained problem the Uzawa updates converge to (for the sensitivities).
    pub fn active_gradients(&self, model: &Model, u: &[f64]) -> Vec<Vec<(usize, f64)>> {
        let mut out = Vec::new();
        for (iface, st) in model.interfaces.iter().zip(&self.slaves) {
            if iface.kind != InterfaceKind::Frictionless {
                continue;
            }
            for k in 0..iface.slaves.len() {
                let Some((_, gap)) = pairing(model, iface, st, k, u) else {
                    continue;
                };
                let t = slave_terms(model, iface, st, k, u);
                if t.active && t.state.normal_force > 0.0 {
                    out.push(
                        t.dofs
                            .iter()
                            .copied()
                            .zip(gap.dg)
                            .filter(|&(d, _)| d != NONE)
                            .collect(),
                    );
                }
            }
        }
        out
    }

    /// Uzawa updates made in this solve, per interface.
    pub fn augmentations(&self) -> Vec<usize> {
        self.slaves.iter().map(|s| s.augmentations).collect()
    }
}
