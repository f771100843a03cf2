//! Sliding interfaces between deformable regions: node-to-segment contact, frictionless or with
//! Coulomb friction, with an augmented-Lagrangian penalty (Wriggers, Computational Contact
//! Mechanics, 2nd ed., 2006, §9.1–9.3 for the 2D node-to-segment element; Laursen & Simo,
//! IJNME 36, 1993, for the return mapping of the friction law).
//!
//! The nodes along the interface are duplicated (see `femu_geometry::interface_split`): one
//! side's surface carries the *slave* nodes, the other side's faces are the *master* segments.
//! For a slave node at `x_s` and a master segment from `x_a` to `x_b` (in the counter-clockwise
//! order of its element, so that its outward normal points to the right of `l = x_b - x_a`):
//!
//! ```text
//! L = |l|,   t = l / L,   n = (t_y, -t_x)
//! ξ = (x_s - x_a)·l / L²                     (closest point, convective coordinate)
//! g_N = (x_s - x_a)·n                         (normal gap, negative when penetrating)
//! g_T = (ξ - ξ̄) L = (x_s - x_a)·t - ξ̄ L      (tangential slip since the stick point ξ̄)
//! ```
//!
//! The normal part stores the energy of the rigid contact ([`crate::contact`]):
//! `ψ_N = ⟨λ̂ - ε g_N⟩₊² / (2ε)`, normal force `N = ⟨λ̂ - ε g_N⟩₊`, residual `-N ∂g_N`, tangent
//! `ε ∂g_N ∂g_Nᵀ - N ∂²g_N` (while `N > 0`), with Uzawa updates of `λ̂`. Friction is a
//! tangential penalty spring `ε_T` with a return mapping to the Coulomb cone:
//!
//! ```text
//! T_trial = ε_T g_T;   stick (|T_trial| ≤ μ N):  T = T_trial,  tangent ε_T (∂g_T ∂g_Tᵀ + g_T ∂²g_T)
//!                      slip  (|T_trial| > μ N):  T = μ N s,    s = sign(g_T),
//!                                                tangent -μ ε s ∂g_T ∂g_Nᵀ + μ N s ∂²g_T
//! ```
//!
//! with residual `T ∂g_T`. The slip tangent is not symmetric (the solver then factorizes by
//! LU). The stick point is history: it is moved at each converged increment to where the
//! spring holds exactly `μ N` (slip) and kept otherwise (stick). Stick points are stored as
//! reference arc lengths along the master surface, so that a slave node may pass from one
//! segment to the next (finite sliding): on segment `k` from reference arc `S_k` of reference
//! length `L⁰_k`, `ξ̄ = (s̄ - S_k) / L⁰_k`.
//!
//! By default ([`Interface::smooth`]) the master surface is smoothed: the quantities above are
//! taken on a C1 cubic Hermite curve through the master nodes ([`smooth`]; Padmanabhan &
//! Laursen, Finite Elem. Anal. Des. 37, 2001), so that a slave node's normal and force are
//! continuous when it passes from one segment to the next, and a pairing depends on ten dofs
//! ([`PairGap`]): the slave node, the segment's nodes and the master nodes on either side.
//!
//! Each slave node is paired with one of its candidate segments (the master segments within a
//! search radius of it in the reference configuration): the closest at the start of a solve,
//! kept through an increment's Newton iterations, moved to the closest when the node's
//! projection has left it at a converged increment and at the end of the step
//! ([`Interface::closest_preferring`]). The tangent's pattern holds the coupling of the slave
//! node with every node of its candidates, so that switching segments needs no new pattern.

use std::collections::BTreeMap;

pub mod smooth;

/// The kind of an interface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InterfaceKind {
    /// Normal contact only: the surfaces slide freely and may separate.
    Frictionless,
    /// Coulomb friction with coefficient `mu` (stick below `μ N`, slip at `μ N`).
    Friction { mu: f64 },
}

/// How the penalty of each slave node is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Penalty {
    /// `factor` times the largest diagonal stiffness of the slave dofs at the undeformed state
    /// (as the rigid contact's automatic penalty); the multipliers are updated (Uzawa) until
    /// the penetration is converged as tightly as the equilibrium.
    Automatic { factor: f64 },
    /// A fixed pressure-per-overclosure slope `k` (MPa/mm) times each slave node's tributary
    /// length, without Uzawa updates: a pure penalty, as CalculiX's linear pressure-overclosure
    /// law (`*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR`), for comparisons with it. The
    /// friction spring is `stick_slope` (MPa/mm, CalculiX's `*FRICTION` second value) times the
    /// tributary length.
    Fixed { k: f64, stick_slope: f64 },
}

/// Problems with an interface, found before any solve.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum InterfaceError {
    #[error("interface {0}: a surface is empty")]
    EmptySurface(String),
    #[error("interface {name}: face {face} of element {element} does not exist")]
    BadFace {
        name: String,
        element: usize,
        face: usize,
    },
    #[error("interface {name}: the friction coefficient must be finite and ≥ 0, got {mu}")]
    BadFriction { name: String, mu: f64 },
    #[error("interface {name}: slave node {node} has no master segment within {radius:.3} mm")]
    NoCandidate {
        name: String,
        node: i64,
        radius: f64,
    },
}

/// A sliding interface of the model: slave nodes against master segments.
#[derive(Debug, Clone)]
pub struct Interface {
    pub name: String,
    pub kind: InterfaceKind,
    pub penalty: Penalty,
    /// Slave nodes (the slave surface's nodes that are not also master nodes: the ends of an
    /// interface, where the two sides still share a node, carry no contact).
    pub slaves: Vec<usize>,
    /// Reference tributary length of each slave node on the slave surface (mm).
    pub tributary: Vec<f64>,
    /// Master segments: node pairs in their element's counter-clockwise order.
    pub segments: Vec<[usize; 2]>,
    /// Reference arc coordinate of each segment's first node along its master chain (chains
    /// follow one another with a gap of ten times the surface's length between them).
    pub arc_start: Vec<f64>,
    /// Reference length of each segment (mm).
    pub arc_length: Vec<f64>,
    /// Per slave node: the candidate segments (indices into `segments`).
    pub candidates: Vec<Vec<usize>>,
    /// Mean reference length of the master segments (mm).
    pub element_size: f64,
    /// Per master segment: the master node before its first node and after its second along
    /// the chain (`usize::MAX` at a chain's end).
    pub neighbours: Vec<[usize; 2]>,
    /// Whether the master surface is smoothed ([`smooth`]: a C1 Hermite curve through the
    /// master nodes, on by default) rather than the straight segments.
    pub smooth: bool,
    /// Allowed penetration at convergence as a fraction of `element_size` (an upper bound, as
    /// for the rigid contact; the Uzawa updates also converge the multipliers to the residual
    /// tolerance).
    pub penetration_tolerance: f64,
}

fn face_of(
    name: &str,
    mesh: &femu_mesh::Mesh,
    &(e, f): &(usize, usize),
) -> Result<[usize; 2], InterfaceError> {
    let bad = || InterfaceError::BadFace {
        name: name.to_string(),
        element: e,
        face: f,
    };
    let el = mesh.elements.get(e).ok_or_else(bad)?;
    if f >= el.face_count() {
        return Err(bad());
    }
    Ok(el.face_nodes(f))
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

/// Distance of `x` to the segment `[a, b]`.
fn segment_distance(x: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let l = [b[0] - a[0], b[1] - a[1]];
    let l2 = l[0] * l[0] + l[1] * l[1];
    let xi = (((x[0] - a[0]) * l[0] + (x[1] - a[1]) * l[1]) / l2).clamp(0.0, 1.0);
    dist(x, [a[0] + xi * l[0], a[1] + xi * l[1]])
}

impl Interface {
    /// An interface of the faces `slave` against the faces `master` (`(element, face)`,
    /// 0-based) of `mesh`: each slave node's candidates are the master segments within
    /// `search_radius` (mm, reference configuration; it bounds the sliding), and at least one.
    pub fn new(
        name: &str,
        mesh: &femu_mesh::Mesh,
        slave: &[(usize, usize)],
        master: &[(usize, usize)],
        kind: InterfaceKind,
        search_radius: f64,
    ) -> Result<Self, InterfaceError> {
        if slave.is_empty() || master.is_empty() {
            return Err(InterfaceError::EmptySurface(name.to_string()));
        }
        if let InterfaceKind::Friction { mu } = kind {
            if !(mu >= 0.0 && mu.is_finite()) {
                return Err(InterfaceError::BadFriction {
                    name: name.to_string(),
                    mu,
                });
            }
        }
        let segments = master
            .iter()
            .map(|f| face_of(name, mesh, f))
            .collect::<Result<Vec<_>, _>>()?;
        let master_nodes: std::collections::BTreeSet<usize> =
            segments.iter().flatten().copied().collect();
        let mut trib = BTreeMap::<usize, f64>::new();
        for f in slave {
            let [a, b] = face_of(name, mesh, f)?;
            let len = dist(mesh.nodes[a], mesh.nodes[b]);
            *trib.entry(a).or_default() += 0.5 * len;
            *trib.entry(b).or_default() += 0.5 * len;
        }
        trib.retain(|n, _| !master_nodes.contains(n));
        let slaves: Vec<usize> = trib.keys().copied().collect();
        let tributary: Vec<f64> = trib.values().copied().collect();
        let arc_length: Vec<f64> = segments
            .iter()
            .map(|&[a, b]| dist(mesh.nodes[a], mesh.nodes[b]))
            .collect();
        let total: f64 = arc_length.iter().sum();
        let arc_start = chain_arcs(&segments, &arc_length, 10.0 * total);
        let mut candidates = Vec::with_capacity(slaves.len());
        for &n in &slaves {
            let x = mesh.nodes[n];
            let near: Vec<usize> = (0..segments.len())
                .filter(|&k| {
                    let [a, b] = segments[k];
                    segment_distance(x, mesh.nodes[a], mesh.nodes[b]) <= search_radius
                })
                .collect();
            if near.is_empty() {
                return Err(InterfaceError::NoCandidate {
                    name: name.to_string(),
                    node: mesh.node_labels[n],
                    radius: search_radius,
                });
            }
            candidates.push(near);
        }
        Ok(Interface {
            name: name.to_string(),
            kind,
            penalty: Penalty::Automatic { factor: 1e1 },
            slaves,
            tributary,
            arc_start,
            arc_length,
            candidates,
            element_size: total / master.len() as f64,
            penetration_tolerance: 1e-3,
            neighbours: chain_neighbours(&segments),
            smooth: true,
            segments,
        })
    }

    /// The friction coefficient (0 for a frictionless interface).
    pub fn mu(&self) -> f64 {
        match self.kind {
            InterfaceKind::Frictionless => 0.0,
            InterfaceKind::Friction { mu } => mu,
        }
    }

    /// The nodes a pairing with segment `s` depends on: `[a, b, p, n]`, the segment's nodes
    /// and (on a smoothed surface) the master nodes before and after it (`usize::MAX`: none).
    pub fn segment_nodes(&self, s: usize) -> [usize; 4] {
        let [a, b] = self.segments[s];
        let [p, n] = if self.smooth {
            self.neighbours[s]
        } else {
            [usize::MAX; 2]
        };
        [a, b, p, n]
    }

    /// The gap of slave `k` on segment `s` at the positions `position(node)`.
    pub fn pair_gap(&self, k: usize, s: usize, position: impl Fn(usize) -> [f64; 2]) -> PairGap {
        let [a, b, p, n] = self.segment_nodes(s);
        let xs = position(self.slaves[k]);
        let (xa, xb) = (position(a), position(b));
        let at = |m: usize| (m != usize::MAX).then(|| position(m));
        let (xp, xn) = (at(p), at(n));
        if self.smooth {
            if let Some((xi, _)) = smooth::project(xs, xa, xb, xp, xn) {
                let x = [xs, xa, xb, xp.unwrap_or([0.0; 2]), xn.unwrap_or([0.0; 2])];
                let (g, xi, len) = smooth::gap(x, xp.is_some(), xn.is_some(), xi);
                return PairGap {
                    g: g.v,
                    xi: xi.v,
                    dg: g.g,
                    d2g: g.h,
                    slip: Slip::Smooth(Box::new([xi, len])),
                };
            }
        }
        PairGap::straight(SegmentGap::new(xs, xa, xb))
    }

    /// The convective coordinate of slave `k`'s closest point on segment `s` and its distance
    /// (of the straight segment, clamped to it, when that point is beyond the ends).
    fn projection(&self, k: usize, s: usize, position: &impl Fn(usize) -> [f64; 2]) -> (f64, f64) {
        let [a, b, p, n] = self.segment_nodes(s);
        let xs = position(self.slaves[k]);
        let (xa, xb) = (position(a), position(b));
        let at = |m: usize| (m != usize::MAX).then(|| position(m));
        let straight = SegmentGap::new(xs, xa, xb).xi;
        let smooth = self
            .smooth
            .then(|| smooth::project(xs, xa, xb, at(p), at(n)))
            .flatten();
        match smooth {
            Some((xi, d)) if (0.0..=1.0).contains(&xi) => (xi, d),
            Some((xi, _)) => (xi, segment_distance(xs, xa, xb)),
            None => (straight, segment_distance(xs, xa, xb)),
        }
    }

    /// Node groups that the interface couples in the tangent: each slave node with the nodes
    /// of its candidate segments and their neighbours (the slave node first).
    pub fn coupled_nodes(&self) -> Vec<Vec<usize>> {
        self.slaves
            .iter()
            .zip(&self.candidates)
            .map(|(&n, cands)| {
                let mut group = vec![n];
                for &k in cands {
                    for m in self.segment_nodes(k) {
                        if m != usize::MAX && !group.contains(&m) {
                            group.push(m);
                        }
                    }
                }
                group
            })
            .collect()
    }

    /// The candidate segment of slave `k` closest to its current position (`position(node)`)
    /// and its gap. A node whose closest point lies on no candidate (beyond the ends of every
    /// segment: outside a convex master vertex) is paired with the nearest segment, its gap
    /// measured from that segment's line, as long as its projection lies within half a
    /// segment of it; otherwise (off the master surface) `None`.
    pub fn closest(
        &self,
        k: usize,
        position: impl Fn(usize) -> [f64; 2],
    ) -> Option<(usize, PairGap)> {
        let mut best: Option<(f64, usize)> = None;
        let mut nearest: Option<(f64, usize, f64)> = None;
        for &s in &self.candidates[k] {
            let (xi, d) = self.projection(k, s, &position);
            if nearest.as_ref().is_none_or(|(bd, _, _)| d < *bd) {
                nearest = Some((d, s, xi));
            }
            if !(-1e-3..=1.0 + 1e-3).contains(&xi) {
                continue;
            }
            if best.as_ref().is_none_or(|(bd, _)| d < *bd) {
                best = Some((d, s));
            }
        }
        let s = best.map(|(_, s)| s).or(nearest
            .filter(|(_, _, xi)| (-0.5..=1.5).contains(xi))
            .map(|(_, s, _)| s))?;
        Some((s, self.pair_gap(k, s, position)))
    }

    /// The gap of slave `k` on the segment `preferred` (its pairing, kept through the Newton
    /// iterations of an increment; see `solver::interface_state`) while the node's projection
    /// stays within half a segment of it, measured from the segment's line beyond its ends;
    /// otherwise, or without a pairing, [`Self::closest`].
    ///
    /// Re-pairing at every iterate would switch a node near a master vertex between two
    /// segments of different normals: its force turns by the angle between them, a jump Newton
    /// cannot converge through (every slave node of a split interface starts on a vertex).
    pub fn closest_preferring(
        &self,
        k: usize,
        position: impl Fn(usize) -> [f64; 2],
        preferred: Option<usize>,
    ) -> Option<(usize, PairGap)> {
        if let Some(s) = preferred {
            let gap = self.pair_gap(k, s, &position);
            if (-0.5..=1.5).contains(&gap.xi) {
                return Some((s, gap));
            }
        }
        self.closest(k, position)
    }

    /// The reference arc coordinate of the point `xi` of segment `s`.
    pub fn arc(&self, s: usize, xi: f64) -> f64 {
        self.arc_start[s] + xi * self.arc_length[s]
    }

    /// The convective coordinate on segment `s` of the reference arc coordinate `arc`.
    pub fn xi_of_arc(&self, s: usize, arc: f64) -> f64 {
        (arc - self.arc_start[s]) / self.arc_length[s]
    }
}

/// Per segment, the node before its first node and after its second along its chain
/// (`usize::MAX` at a chain's end).
fn chain_neighbours(segments: &[[usize; 2]]) -> Vec<[usize; 2]> {
    let mut by_first = BTreeMap::new();
    let mut by_second = BTreeMap::new();
    for s in segments {
        by_first.insert(s[0], s[1]);
        by_second.insert(s[1], s[0]);
    }
    segments
        .iter()
        .map(|s| {
            [
                by_second.get(&s[0]).copied().unwrap_or(usize::MAX),
                by_first.get(&s[1]).copied().unwrap_or(usize::MAX),
            ]
        })
        .collect()
}

/// The gap of a slave node paired with a master segment, with its derivatives over the ten
/// dofs `(x_s, x_a, x_b, x_p, x_n)` (slave node, segment, the master nodes before and after
/// it; the last two are zero on straight segments and at a chain's end).
#[derive(Debug, Clone)]
pub struct PairGap {
    /// Normal gap `g_N` (negative: penetration).
    pub g: f64,
    /// Convective coordinate of the closest point on the segment.
    pub xi: f64,
    pub dg: [f64; smooth::N],
    pub d2g: [[f64; smooth::N]; smooth::N],
    slip: Slip,
}

#[derive(Debug, Clone)]
enum Slip {
    Straight(Box<SegmentGap>),
    /// `ξ` and the chord length `L` with their derivatives.
    Smooth(Box<[smooth::Dual; 2]>),
}

impl PairGap {
    fn straight(gap: SegmentGap) -> Self {
        let mut dg = [0.0; smooth::N];
        let mut d2g = [[0.0; smooth::N]; smooth::N];
        for i in 0..6 {
            dg[i] = gap.dg[i];
            d2g[i][..6].copy_from_slice(&gap.d2g[i]);
        }
        PairGap {
            g: gap.g,
            xi: gap.xi,
            dg,
            d2g,
            slip: Slip::Straight(Box::new(gap)),
        }
    }

    /// The tangential slip `g_T = (ξ - ξ̄) L` from the stick point `xi_bar`, `L` the segment's
    /// chord, and its derivatives ([`SegmentGap::slip`] on a straight segment).
    pub fn slip(&self, xi_bar: f64) -> (f64, [f64; smooth::N], [[f64; smooth::N]; smooth::N]) {
        match &self.slip {
            Slip::Straight(gap) => {
                let (gt, d, h) = gap.slip(xi_bar);
                let mut dg = [0.0; smooth::N];
                let mut d2g = [[0.0; smooth::N]; smooth::N];
                for i in 0..6 {
                    dg[i] = d[i];
                    d2g[i][..6].copy_from_slice(&h[i]);
                }
                (gt, dg, d2g)
            }
            Slip::Smooth(xl) => {
                let [xi, len] = **xl;
                let gt = (xi - smooth::Dual::constant(xi_bar)) * len;
                (gt.v, gt.g, gt.h)
            }
        }
    }
}

/// Reference arc coordinates of the segments' first nodes along the chains they form (a
/// segment's second node is the next one's first); each new chain starts `gap` after the end of
/// the last one.
fn chain_arcs(segments: &[[usize; 2]], lengths: &[f64], gap: f64) -> Vec<f64> {
    let mut next = BTreeMap::new();
    let mut has_previous = vec![false; segments.len()];
    for (k, s) in segments.iter().enumerate() {
        next.insert(s[0], k);
    }
    for s in segments {
        if let Some(&j) = next.get(&s[1]) {
            has_previous[j] = true;
        }
    }
    let mut start = vec![f64::NAN; segments.len()];
    let mut arc = 0.0;
    // Open chains from their first segment, then any closed loop from its lowest segment.
    let firsts: Vec<usize> = (0..segments.len())
        .filter(|&k| !has_previous[k])
        .chain(0..segments.len())
        .collect();
    for first in firsts {
        if !start[first].is_nan() {
            continue;
        }
        let mut k = first;
        while start[k].is_nan() {
            start[k] = arc;
            arc += lengths[k];
            match next.get(&segments[k][1]) {
                Some(&j) => k = j,
                None => break,
            }
        }
        arc += gap;
    }
    start
}

/// 2D cross product `a_x b_y - a_y b_x`.
fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Maps the derivatives of a function of `d = x_s - x_a` and `l = x_b - x_a` (4 variables,
/// `(d_x, d_y, l_x, l_y)`) to the dofs `(x_s, x_a, x_b)` (6 variables).
fn to_dofs(grad4: [f64; 4], hess4: [[f64; 4]; 4]) -> ([f64; 6], [[f64; 6]; 6]) {
    // ∂(d, l)/∂(x_s, x_a, x_b): d = x_s - x_a, l = x_b - x_a.
    const J: [[f64; 3]; 2] = [[1.0, -1.0, 0.0], [0.0, -1.0, 1.0]];
    let mut g = [0.0; 6];
    let mut h = [[0.0; 6]; 6];
    for node in 0..3 {
        for i in 0..2 {
            g[2 * node + i] = J[0][node] * grad4[i] + J[1][node] * grad4[2 + i];
        }
    }
    for na in 0..3 {
        for nb in 0..3 {
            for i in 0..2 {
                for j in 0..2 {
                    let mut v = 0.0;
                    for p in 0..2 {
                        for q in 0..2 {
                            v += J[p][na] * J[q][nb] * hess4[2 * p + i][2 * q + j];
                        }
                    }
                    h[2 * na + i][2 * nb + j] = v;
                }
            }
        }
    }
    (g, h)
}

/// The normal gap of a slave node on a master segment and its derivatives over the dofs
/// `(x_s, x_a, x_b)` (module docs: `g_N = (x_s - x_a)·n`, `ξ`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentGap {
    pub g: f64,
    pub xi: f64,
    /// Current segment length.
    pub length: f64,
    pub dg: [f64; 6],
    pub d2g: [[f64; 6]; 6],
    /// `d = x_s - x_a`, `l = x_b - x_a`.
    pub d: [f64; 2],
    pub l: [f64; 2],
}

impl SegmentGap {
    /// `g_N = (d × l) / L` and its derivatives (d × l = d_x l_y - d_y l_x):
    /// `∂g/∂d = n`, `∂g/∂l = p / L - c l / L³` with `p = (-d_y, d_x)`, `c = d × l`;
    /// `∂²g/∂d_i∂l_j = C_ij / L - n_i l_j / L²` with `C = [[0, 1], [-1, 0]]`;
    /// `∂²g/∂l∂l = -(p lᵀ + l pᵀ) / L³ - c I / L³ + 3 c l lᵀ / L⁵`.
    pub fn new(xs: [f64; 2], xa: [f64; 2], xb: [f64; 2]) -> Self {
        let d = [xs[0] - xa[0], xs[1] - xa[1]];
        let l = [xb[0] - xa[0], xb[1] - xa[1]];
        let l2 = l[0] * l[0] + l[1] * l[1];
        let len = l2.sqrt();
        let (l3, l5) = (l2 * len, l2 * l2 * len);
        let c = cross(d, l);
        let n = [l[1] / len, -l[0] / len];
        let p = [-d[1], d[0]];
        let mut grad = [0.0; 4];
        let mut hess = [[0.0; 4]; 4];
        const C: [[f64; 2]; 2] = [[0.0, 1.0], [-1.0, 0.0]];
        for i in 0..2 {
            grad[i] = n[i];
            grad[2 + i] = p[i] / len - c * l[i] / l3;
            for j in 0..2 {
                let dl = C[i][j] / len - n[i] * l[j] / l2;
                hess[i][2 + j] = dl;
                hess[2 + j][i] = dl;
                let delta = if i == j { 1.0 } else { 0.0 };
                hess[2 + i][2 + j] =
                    -(p[i] * l[j] + l[i] * p[j]) / l3 - c * delta / l3 + 3.0 * c * l[i] * l[j] / l5;
            }
        }
        let (dg, d2g) = to_dofs(grad, hess);
        SegmentGap {
            g: c / len,
            xi: (d[0] * l[0] + d[1] * l[1]) / l2,
            length: len,
            dg,
            d2g,
            d,
            l,
        }
    }

    /// The tangential slip `g_T = (ξ - ξ̄) L = d·l / L - ξ̄ L` from the stick point `xi_bar` and
    /// its derivatives over `(x_s, x_a, x_b)`: with `a = d·l`,
    /// `∂g_T/∂d = l / L`, `∂g_T/∂l = d / L - a l / L³ - ξ̄ l / L`,
    /// `∂²g_T/∂d_i∂l_j = δ_ij / L - l_i l_j / L³`,
    /// `∂²g_T/∂l_i∂l_j = -(d_i l_j + l_i d_j) / L³ - a δ_ij / L³ + 3 a l_i l_j / L⁵
    ///  - ξ̄ (δ_ij / L - l_i l_j / L³)`.
    pub fn slip(&self, xi_bar: f64) -> (f64, [f64; 6], [[f64; 6]; 6]) {
        let (d, l, len) = (self.d, self.l, self.length);
        let l2 = len * len;
        let (l3, l5) = (l2 * len, l2 * l2 * len);
        let a = d[0] * l[0] + d[1] * l[1];
        let mut grad = [0.0; 4];
        let mut hess = [[0.0; 4]; 4];
        for i in 0..2 {
            grad[i] = l[i] / len;
            grad[2 + i] = d[i] / len - a * l[i] / l3 - xi_bar * l[i] / len;
            for j in 0..2 {
                let delta = if i == j { 1.0 } else { 0.0 };
                let dl = delta / len - l[i] * l[j] / l3;
                hess[i][2 + j] = dl;
                hess[2 + j][i] = dl;
                hess[2 + i][2 + j] = -(d[i] * l[j] + l[i] * d[j]) / l3 - a * delta / l3
                    + 3.0 * a * l[i] * l[j] / l5
                    - xi_bar * dl;
            }
        }
        let (dg, d2g) = to_dofs(grad, hess);
        (a / len - xi_bar * len, dg, d2g)
    }
}

/// The state of one slave node at a converged solution.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlaveState {
    pub node: usize,
    /// Its segment (`None`: off the master surface).
    pub segment: Option<usize>,
    /// Normal gap (mm, negative: penetration).
    pub gap: f64,
    /// Normal force N (N per mm of thickness, ≥ 0).
    pub normal_force: f64,
    /// Tangential force T along the master segment's direction (N per mm of thickness).
    pub tangential_force: f64,
    /// Whether the node slips (|T| = μ N) rather than sticks.
    pub slipping: bool,
    /// Reference arc coordinate of the node's closest point on the master surface (mm); its
    /// change from the reference state is the slip along the interface.
    pub arc: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of `f` (value, gradient) at `x` along each of 6 coordinates.
    fn check(f: impl Fn(&[f64; 6]) -> (f64, [f64; 6], [[f64; 6]; 6]), x: [f64; 6]) {
        let (_, g0, h0) = f(&x);
        let h = 1e-6;
        for k in 0..6 {
            let (mut xp, mut xm) = (x, x);
            xp[k] += h;
            xm[k] -= h;
            let (fp, gp, _) = f(&xp);
            let (fm, gm, _) = f(&xm);
            // Central differences of step 1e-6 on O(1) functions: error ~1e-12 h⁻¹·ε ≈ 1e-9.
            assert!(((fp - fm) / (2.0 * h) - g0[k]).abs() < 1e-8, "grad {k}");
            for j in 0..6 {
                let fd = (gp[j] - gm[j]) / (2.0 * h);
                assert!(
                    (fd - h0[j][k]).abs() < 1e-7,
                    "hess {j} {k}: {fd} vs {}",
                    h0[j][k]
                );
            }
        }
    }

    fn split(x: &[f64; 6]) -> ([f64; 2], [f64; 2], [f64; 2]) {
        ([x[0], x[1]], [x[2], x[3]], [x[4], x[5]])
    }

    #[test]
    fn gap_and_slip_derivatives_match_finite_differences() {
        for x in [
            [0.3, -0.05, 0.0, 0.0, 1.0, 0.0],
            [0.7, 0.2, -0.1, 0.05, 1.2, 0.4],
            [1.1, 2.0, 0.4, 1.5, 1.9, 1.6],
        ] {
            check(
                |x| {
                    let (s, a, b) = split(x);
                    let g = SegmentGap::new(s, a, b);
                    (g.g, g.dg, g.d2g)
                },
                x,
            );
            for xi_bar in [0.0, 0.4, -0.3] {
                check(
                    |x| {
                        let (s, a, b) = split(x);
                        SegmentGap::new(s, a, b).slip(xi_bar)
                    },
                    x,
                );
            }
        }
    }

    #[test]
    fn gap_is_signed_distance_to_the_segment_line() {
        // Segment along +x: the outward normal is -y (right of the direction).
        let g = SegmentGap::new([0.25, -0.5], [0.0, 0.0], [1.0, 0.0]);
        assert!((g.g - 0.5).abs() < 1e-15);
        assert!((g.xi - 0.25).abs() < 1e-15);
        let (gt, _, _) = g.slip(0.1);
        assert!((gt - 0.15).abs() < 1e-15);
    }

    #[test]
    fn chains_are_ordered_by_arc() {
        // Two chains: 5 -> 6 -> 7 and 1 -> 2, given out of order.
        let segs = [[6, 7], [1, 2], [5, 6]];
        let arcs = chain_arcs(&segs, &[1.0, 2.0, 3.0], 100.0);
        assert_eq!(arcs[1], 0.0);
        assert_eq!(arcs[2], 102.0);
        assert_eq!(arcs[0], 105.0);
    }
}
