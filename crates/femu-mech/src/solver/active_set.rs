//! The Newton correction with the contact active set of its own end point.
//!
//! The tangent of an iteration holds the penalty stiffness `ε ∇g ∇gᵀ` of the nodes in contact
//! at the iterate only: the correction it gives sees no rigid body at the nodes that are free
//! now, and drives them through it (in the indentation, the skin bulging around the indenter
//! is pushed deep into it), while nodes that carry force now may come free. Newton then learns
//! the contact set one node per iteration under a step limit.
//!
//! Here the correction solves the linearized penalty problem with every candidate node instead:
//! the force of node `k` along the correction `δ` is `ℓ_k(δ) = λ̂_k - ε (g_k + ∇g_kᵀ δ)`, acting
//! when positive. Primal-dual active-set iterations (Hintermüller, Ito & Kunisch, SIAM J. Optim.
//! 13, 2002) find the set `S = {k : ℓ_k(δ) > 0}` consistent with its own correction:
//!
//! ```text
//! (K + Σ_{k ∈ S∖A} ε a_k a_kᵀ - Σ_{k ∈ A∖S} (ε a_k a_kᵀ - λ_k ∇²g_k)) δ
//!     = -R + Σ_{k ∈ S∖A} ℓ_k a_k - Σ_{k ∈ A∖S} λ_k a_k
//! ```
//!
//! (`A`: the nodes in contact at the iterate, with force `λ_k`; `a_k = ∇g_k` over the node's
//! dofs and its body's travel; a node leaving takes its whole stiffness with it, the gap's
//! curvature term included). The changed nodes `S Δ A` are a low-rank update of the factorized
//! tangent `K` (one rank-one term per added node, two per removed node on a curved body),
//! solved by Sherman–Morrison–Woodbury: one triangular solve per term, kept across the
//! active-set iterations of the correction, and a dense system of the terms' size, with no new
//! factorization. The tangent itself is unchanged (it is the exact derivative of the residual
//! at the iterate); only the correction sees the contact set it leads to.

use super::assembly::NONE;
use super::factor::TangentFactor;
use femu_sparse::MAX_RHS;

/// Most rank-one terms in the update of one active-set iteration.
const MAX_TERMS: usize = 48;

/// Most columns `K⁻¹ v` kept over the active-set iterations of one correction (52 MB at the
/// paper scale's 51 569 equations; the first correction of a compression increment there
/// needs up to 37).
const MAX_COLUMNS: usize = 64;

/// Most active-set iterations per correction.
const MAX_SWEEPS: usize = 12;

/// A candidate contact node linearized at the iterate.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Candidate {
    /// Equations of the node's x and y and of its body's travel (`NONE` if prescribed).
    pub eqs: [usize; 3],
    /// The gap gradient over those dofs.
    pub grad: [f64; 3],
    /// The gap's second derivatives over those dofs.
    pub hess: [[f64; 3]; 3],
    /// Trial force `λ̂ - ε g` at the iterate.
    pub trial: f64,
    /// The body's penalty ε.
    pub eps: f64,
    /// Whether the tangent holds the node's penalty stiffness (in contact at the iterate).
    pub active: bool,
    /// The node, its body, and its gap at the iterate.
    pub node: usize,
    pub body: usize,
    pub gap: f64,
}

fn dot3(eqs: &[usize; 3], v: &[f64; 3], x: &[f64]) -> f64 {
    eqs.iter()
        .zip(v)
        .filter(|(&q, _)| q != NONE)
        .map(|(&q, g)| g * x[q])
        .sum()
}

impl Candidate {
    fn dot(&self, v: &[f64]) -> f64 {
        dot3(&self.eqs, &self.grad, v)
    }

    /// The rank-one terms `c v vᵀ` that change the tangent when the node's status flips, with
    /// the coefficient `w` of `K⁻¹ v` in the right-hand side's change: an added node brings
    /// `ε a aᵀ` and the force `ℓ a`; a removed one takes its stiffness `ε a aᵀ - λ ∇²g`
    /// (eigenvectors) and its force `-λ a` away.
    fn terms(&self, out: &mut Vec<Term>) {
        let mut grad = self.grad;
        let mut hess = self.hess;
        for (i, &q) in self.eqs.iter().enumerate() {
            if q == NONE {
                grad[i] = 0.0;
                hess[i] = [0.0; 3];
                (0..3).for_each(|j| hess[j][i] = 0.0);
            }
        }
        if !self.active {
            out.push(Term {
                v: grad,
                c: self.eps,
                w: self.trial,
            });
            return;
        }
        let lam = self.trial.max(0.0);
        let mut c = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] = self.eps * grad[i] * grad[j] - lam * hess[i][j];
            }
        }
        let (mu, vecs) = eigen3(c);
        let tol = 1e-12 * self.eps * grad.iter().map(|g| g * g).sum::<f64>();
        for (m, v) in mu.iter().zip(vecs) {
            if m.abs() > tol {
                let av = grad[0] * v[0] + grad[1] * v[1] + grad[2] * v[2];
                out.push(Term {
                    v,
                    c: -m,
                    w: -lam * av,
                });
            }
        }
    }
}

/// A rank-one change `c v vᵀ` of the tangent (over a candidate's equations), and the weight
/// `w` of `v` in the change of the right-hand side.
#[derive(Debug, Clone, Copy)]
struct Term {
    v: [f64; 3],
    c: f64,
    w: f64,
}

/// Eigenvalues and orthonormal eigenvectors (`vectors[k]` belongs to `values[k]`, in no particular
/// order) of a symmetric 3 x 3 matrix, by cyclic Jacobi rotations (Golub & Van Loan, Matrix
/// Computations, §8.5).
pub fn eigen3(mut a: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..30 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = cs * akp - sn * akq;
                a[k][q] = sn * akp + cs * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = cs * apk - sn * aqk;
                a[q][k] = sn * apk + cs * aqk;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = cs * vp - sn * vq;
                row[q] = sn * vp + cs * vq;
            }
        }
    }
    let vecs = [0, 1, 2].map(|j| [v[0][j], v[1][j], v[2][j]]);
    ([a[0][0], a[1][1], a[2][2]], vecs)
}

/// What the active-set iterations of one correction did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ActiveSetOutcome {
    /// Active-set iterations made (0: the plain correction was consistent already).
    pub sweeps: usize,
    /// Nodes whose contact status the correction changes.
    pub changes: usize,
    /// Triangular solves made for the update's columns.
    pub columns: usize,
    /// Whether a consistent set was found (otherwise the plain correction is kept).
    pub consistent: bool,
}

/// A candidate node along the accepted correction: whether it is in contact at the
/// correction's end point, and the slope `∇gᵀ δ` of its linearized gap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Along {
    pub in_contact: bool,
    pub slope: f64,
}

/// The low-rank update of the factorized tangent: the rank-one terms of the changed nodes,
/// the columns `K⁻¹ v` (kept per candidate across the active-set iterations of one
/// correction) and the capacitance system.
#[derive(Debug, Default)]
struct Woodbury {
    terms: Vec<Term>,
    /// Per term: its candidate and its column in the column store.
    owners: Vec<usize>,
    term_columns: Vec<usize>,
    /// Per candidate: the column of its first term (`NONE`: not solved yet).
    column_of: Vec<usize>,
    /// Columns solved so far (`K⁻¹ v`, one of `n_eq` after the other, in the store lent to
    /// [`ActiveSetSolver::correct`]).
    columns: usize,
    /// The capacitance matrix (row-major) and its right-hand side.
    m: Vec<f64>,
    y: Vec<f64>,
}

/// The buffers of the active-set iterations, allocated on first use and kept.
#[derive(Debug, Default)]
pub(crate) struct ActiveSetSolver {
    /// The candidate nodes linearized at the iterate (filled by the contact state).
    pub candidates: Vec<Candidate>,
    in_set: Vec<bool>,
    woodbury: Woodbury,
    /// `K_S⁻¹ b`: the correction of the current set.
    x: Vec<f64>,
    scratch: Vec<Term>,
    pending: Vec<usize>,
    along: Vec<Along>,
}

impl ActiveSetSolver {
    /// Replaces the plain Newton correction `du` (`K du = -R`, `K` factorized in `factor`) by
    /// the correction of the active set consistent with it, if the iterations find one within
    /// [`MAX_SWEEPS`], [`MAX_TERMS`] and [`MAX_COLUMNS`]; otherwise `du` is left as it is.
    ///
    /// `store` holds the columns `K⁻¹ v`: the solver's element-matrix buffer, idle between
    /// assemblies (13 MB at the paper scale, 31 columns), lengthened if more are needed and
    /// given back at its length, its values spent.
    pub fn correct(
        &mut self,
        factor: &mut TangentFactor,
        du: &mut [f64],
        store: &mut Vec<f64>,
    ) -> ActiveSetOutcome {
        let length = store.len();
        let out = self.iterate(factor, du, store);
        store.truncate(length);
        out
    }

    /// See [`Self::correct`].
    fn iterate(
        &mut self,
        factor: &mut TangentFactor,
        du: &mut [f64],
        store: &mut Vec<f64>,
    ) -> ActiveSetOutcome {
        let n = du.len();
        let nc = self.candidates.len();
        self.in_set.clear();
        self.in_set.extend(self.candidates.iter().map(|c| c.active));
        let w = &mut self.woodbury;
        w.column_of.clear();
        w.column_of.resize(nc, NONE);
        w.columns = 0;
        self.x.resize(n, 0.0);
        self.along.clear();
        let mut out = ActiveSetOutcome::default();
        let mut plain = true;
        for sweep in 0..=MAX_SWEEPS {
            let step: &[f64] = if plain { du } else { &self.x };
            let mut same = true;
            for (c, on) in self.candidates.iter().zip(self.in_set.iter_mut()) {
                let force = c.trial - c.eps * c.dot(step);
                let now = force > 0.0 || (c.active && force >= 0.0);
                same &= now == *on;
                *on = now;
            }
            if same {
                out.consistent = true;
                out.sweeps = sweep;
                break;
            }
            if sweep == MAX_SWEEPS || !self.collect_terms() || !self.solve_columns(factor, n, store)
            {
                return out;
            }
            if !self.woodbury(du, store) {
                return out;
            }
            plain = false;
            out.columns = self.woodbury.columns;
        }
        if !plain {
            du.copy_from_slice(&self.x);
        }
        out.changes = (0..nc)
            .filter(|&k| self.in_set[k] != self.candidates[k].active)
            .count();
        self.along.extend(
            self.candidates
                .iter()
                .zip(&self.in_set)
                .map(|(c, &in_contact)| Along {
                    in_contact,
                    slope: c.dot(du),
                }),
        );
        out
    }

    /// The candidates along the last correction that [`Self::correct`] made consistent (in the
    /// order of [`Self::candidates`]); empty if it kept the plain correction.
    pub fn along(&self) -> &[Along] {
        &self.along
    }

    /// The terms of the candidates whose status differs from the iterate's; false if there are
    /// more than [`MAX_TERMS`].
    fn collect_terms(&mut self) -> bool {
        let w = &mut self.woodbury;
        w.terms.clear();
        w.owners.clear();
        w.term_columns.clear();
        for (k, c) in self.candidates.iter().enumerate() {
            if self.in_set[k] == c.active {
                continue;
            }
            self.scratch.clear();
            c.terms(&mut self.scratch);
            let first = w.column_of[k];
            for (i, t) in self.scratch.iter().enumerate() {
                w.terms.push(*t);
                w.owners.push(k);
                w.term_columns
                    .push(if first == NONE { NONE } else { first + i });
            }
        }
        w.terms.len() <= MAX_TERMS
    }

    /// Solves `K z = v` for the terms without a column, [`MAX_RHS`] at a time.
    fn solve_columns(&mut self, factor: &mut TangentFactor, n: usize, z: &mut Vec<f64>) -> bool {
        let w = &mut self.woodbury;
        self.pending.clear();
        self.pending
            .extend((0..w.terms.len()).filter(|&t| w.term_columns[t] == NONE));
        if w.columns + self.pending.len() > MAX_COLUMNS {
            return false;
        }
        let need = (w.columns + self.pending.len()) * n;
        if z.len() < need {
            z.resize(need, 0.0);
        }
        for chunk in self.pending.chunks(MAX_RHS) {
            let first = w.columns;
            let block = &mut z[first * n..(first + chunk.len()) * n];
            block.fill(0.0);
            for (j, &t) in chunk.iter().enumerate() {
                let k = w.owners[t];
                let column = &mut block[j * n..(j + 1) * n];
                for (&q, &v) in self.candidates[k].eqs.iter().zip(&w.terms[t].v) {
                    if q != NONE {
                        column[q] = v;
                    }
                }
                if w.column_of[k] == NONE {
                    w.column_of[k] = first + j;
                }
                w.term_columns[t] = first + j;
            }
            factor.solve_many(block, chunk.len());
            w.columns += chunk.len();
        }
        true
    }

    /// `x = K_S⁻¹ b` by Sherman–Morrison–Woodbury from the plain correction `du = K⁻¹(-R)`:
    /// `K⁻¹ b = du + Σ w_j z_j`, `x = K⁻¹ b - Z (C⁻¹ + Vᵀ Z)⁻¹ Vᵀ K⁻¹ b` with `C` the terms'
    /// coefficients. False if the capacitance matrix is singular (e.g. a force-controlled body
    /// left with no contact).
    fn woodbury(&mut self, du: &[f64], z: &[f64]) -> bool {
        let n = du.len();
        let Woodbury {
            terms,
            owners,
            term_columns,
            m,
            y,
            ..
        } = &mut self.woodbury;
        let r = terms.len();
        let column = |j: usize| &z[term_columns[j] * n..(term_columns[j] + 1) * n];
        self.x.copy_from_slice(du);
        for (j, t) in terms.iter().enumerate() {
            for (x, zj) in self.x.iter_mut().zip(column(j)) {
                *x += t.w * zj;
            }
        }
        m.clear();
        m.resize(r * r, 0.0);
        y.clear();
        for i in 0..r {
            let (t, eqs) = (terms[i], &self.candidates[owners[i]].eqs);
            for j in 0..r {
                m[i * r + j] = dot3(eqs, &t.v, column(j));
            }
            m[i * r + i] += 1.0 / t.c;
            y.push(dot3(eqs, &t.v, &self.x));
        }
        if !solve_dense(m, y, r) {
            return false;
        }
        for (j, &yj) in y.iter().enumerate() {
            for (x, zj) in self.x.iter_mut().zip(column(j)) {
                *x -= yj * zj;
            }
        }
        true
    }
}

/// Solves the dense `r x r` system `m y = b` in place (Gaussian elimination with partial
/// pivoting); false if a pivot vanishes relative to the matrix.
fn solve_dense(m: &mut [f64], b: &mut [f64], r: usize) -> bool {
    let scale = m.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    for col in 0..r {
        let (piv, big) = (col..r)
            .map(|i| (i, m[i * r + col].abs()))
            .fold((col, -1.0), |a, b| if b.1 > a.1 { b } else { a });
        if !(big > 1e-13 * scale) {
            return false;
        }
        if piv != col {
            for j in 0..r {
                m.swap(col * r + j, piv * r + j);
            }
            b.swap(col, piv);
        }
        let p = m[col * r + col];
        for i in col + 1..r {
            let f = m[i * r + col] / p;
            if f != 0.0 {
                for j in col..r {
                    m[i * r + j] -= f * m[col * r + j];
                }
                b[i] -= f * b[col];
            }
        }
    }
    for col in (0..r).rev() {
        let s: f64 = (col + 1..r).map(|j| m[col * r + j] * b[j]).sum();
        b[col] = (b[col] - s) / m[col * r + col];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_sparse::{CscPattern, SparseSolver};
    use rand::{Rng, SeedableRng};

    /// Dense `n x n` matrix-vector product (row-major).
    fn mul(a: &[f64], x: &[f64]) -> Vec<f64> {
        let n = x.len();
        (0..n)
            .map(|i| (0..n).map(|j| a[i * n + j] * x[j]).sum())
            .collect()
    }

    /// Adds `c v vᵀ` over the equations `eqs` to the dense `a`.
    fn add_outer(a: &mut [f64], n: usize, eqs: &[usize; 3], v: &[f64; 3], c: f64) {
        for i in 0..3 {
            for j in 0..3 {
                a[eqs[i] * n + eqs[j]] += c * v[i] * v[j];
            }
        }
    }

    /// The correction of the active-set iterations solves the linearized penalty problem of
    /// the set it ends with, built explicitly here: `K_S δ = -R_S` with the stiffness and force
    /// of the nodes that join added and those of the nodes that leave (their curvature term
    /// included) taken away; and that set is the one of its own correction. The plain
    /// correction is made to push a free node 0.5 deep into its body and to pull a node in
    /// contact off, so that both kinds of change occur.
    #[test]
    fn correction_solves_the_system_of_its_own_contact_set() {
        let n = 7;
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let eps = 50.0;
        let travel = 6;
        let mut candidates: Vec<Candidate> = (0..3)
            .map(|k| {
                let angle: f64 = rng.gen_range(-0.5..0.5);
                let m = [angle.sin(), -angle.cos()];
                let tau = [-m[1], m[0]];
                let r = 10.0;
                let d = [0.0, -1.0];
                let b = [tau[0], tau[1], -(tau[0] * d[0] + tau[1] * d[1])];
                Candidate {
                    eqs: [2 * k, 2 * k + 1, travel],
                    grad: [m[0], m[1], -(m[0] * d[0] + m[1] * d[1])],
                    hess: std::array::from_fn(|i| std::array::from_fn(|j| b[i] * b[j] / r)),
                    trial: 0.0,
                    eps,
                    active: false,
                    node: k,
                    body: 0,
                    gap: 0.0,
                }
            })
            .collect();
        // Node 0 in contact with a small force, node 1 in contact firmly, node 2 free.
        candidates[0].trial = 0.02 * eps;
        candidates[0].active = true;
        candidates[1].trial = 0.5 * eps;
        candidates[1].active = true;
        candidates[2].trial = -0.01 * eps;
        // The tangent: an SPD matrix, weakly coupled, plus the stiffness of the nodes in
        // contact.
        let mut k_dense = vec![0.0; n * n];
        let g: Vec<f64> = (0..n * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        for i in 0..n {
            for j in 0..n {
                k_dense[i * n + j] =
                    0.05 * (0..n).map(|l| g[i * n + l] * g[j * n + l]).sum::<f64>();
            }
            k_dense[i * n + i] += 2.0;
        }
        // The travel held firmly (as by the body's other nodes in contact).
        k_dense[travel * n + travel] += 1e3;
        for c in candidates.iter().filter(|c| c.active) {
            add_outer(&mut k_dense, n, &c.eqs, &c.grad, c.eps);
            for i in 0..3 {
                for j in 0..3 {
                    k_dense[c.eqs[i] * n + c.eqs[j]] -= c.trial * c.hess[i][j];
                }
            }
        }
        // A plain correction that moves node 2 by 0.5 into its body and node 0 by 0.5 out.
        let mut target = vec![0.0; n];
        for (k, s) in [(0, 0.5), (2, -0.5)] {
            for i in 0..2 {
                target[2 * k + i] = s * candidates[k].grad[i];
            }
        }
        let rhs = mul(&k_dense, &target);

        let pattern = CscPattern {
            n,
            col_ptr: (0..=n).map(|c| c * n).collect(),
            row_idx: (0..n * n).map(|p| p % n).collect(),
        };
        let values: Vec<f64> = (0..n * n).map(|p| k_dense[(p % n) * n + p / n]).collect();
        let mut factor = TangentFactor::new(SparseSolver::new(&pattern, None).unwrap());
        factor.factorize(&pattern, &values).unwrap();
        let mut du = rhs.clone();
        factor.solve_many(&mut du, 1);

        let mut solver = ActiveSetSolver {
            candidates: candidates.clone(),
            ..Default::default()
        };
        let mut store = Vec::new();
        let outcome = solver.correct(&mut factor, &mut du, &mut store);
        assert!(store.is_empty(), "the store is given back at its length");
        assert!(outcome.consistent && outcome.sweeps >= 1, "{outcome:?}");
        let along = solver.along().to_vec();
        assert!(outcome.changes >= 2, "{outcome:?} {along:?}");
        assert!(!along[0].in_contact && along[1].in_contact && along[2].in_contact);

        // The explicit system of the final set.
        let mut ks = k_dense.clone();
        let mut bs = rhs.clone();
        for (c, a) in candidates.iter().zip(&along) {
            if a.in_contact && !c.active {
                add_outer(&mut ks, n, &c.eqs, &c.grad, c.eps);
                (0..3).for_each(|i| bs[c.eqs[i]] += c.trial * c.grad[i]);
            } else if !a.in_contact && c.active {
                add_outer(&mut ks, n, &c.eqs, &c.grad, -c.eps);
                for i in 0..3 {
                    for j in 0..3 {
                        ks[c.eqs[i] * n + c.eqs[j]] += c.trial * c.hess[i][j];
                    }
                    bs[c.eqs[i]] -= c.trial * c.grad[i];
                }
            }
        }
        let residual: f64 = mul(&ks, &du)
            .iter()
            .zip(&bs)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let scale = bs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        // Woodbury's formula in double precision on a well-conditioned 7 x 7 system.
        assert!(
            residual <= 1e-10 * scale,
            "residual {residual:e} of {scale:e}"
        );
        // The set is the one of the correction: positive linearized force exactly in contact.
        for (c, a) in candidates.iter().zip(&along) {
            let force = c.trial - c.eps * c.dot(&du);
            assert_eq!(force > 0.0, a.in_contact, "force {force}");
            assert!((a.slope - c.dot(&du)).abs() <= 1e-14 * c.dot(&du).abs().max(1.0));
        }
    }

    /// The eigenvectors of a symmetric 3 x 3 matrix rebuild it.
    #[test]
    fn eigen3_rebuilds_the_matrix() {
        let a = [[4.0, 1.0, -2.0], [1.0, 2.0, 0.5], [-2.0, 0.5, 3.0]];
        let (mu, v) = eigen3(a);
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..3).map(|k| mu[k] * v[k][i] * v[k][j]).sum();
                assert!((s - a[i][j]).abs() < 1e-13, "{i} {j}: {s} vs {}", a[i][j]);
            }
        }
    }
}
