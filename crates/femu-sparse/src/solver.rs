//! [`SparseSolver`] checks the symmetry of every matrix: a symmetric one (in femu-mech:
//! hyperelastic elements, dead loads, follower pressure on closed outlines, which is
//! conservative, rigid bodies with their bordered force equation) is factorized by supernodal
//! LDLᵀ with an AMD ordering ([`SparseLdlt`]), by halves on two cores for large models
//! ([`SplitLdlt`]); an unsymmetric one (pressure on part of an outline) by sparse LU with
//! partial pivoting ([`SparseLu`]), or, when [`SparseSolver::refine_on_symmetric_part`] is set,
//! by iterative refinement on the LDLᵀ of its symmetric part, with LU as the fallback.

use crate::factor::{Factor, Factorization};
use crate::factor::{LinearSolveError, MAX_RHS};
use crate::linear::{SparseLdlt, SparseLu};
use crate::pattern::CscPattern;
use crate::split::{DofSplit, SplitLdlt};

/// Position of the transposed entry of each stored entry of `pattern` (rows sorted in each
/// column), or `None` if the pattern is not structurally symmetric.
///
/// One sweep instead of a binary search per entry: visiting the columns in increasing order,
/// the entries `(r, c)` of row `r` come in increasing `c`, which is exactly the order of the
/// rows of column `r`; so the transposed entry of the k-th visited entry of row `r` is the k-th
/// entry of column `r`, and checking that its row is `c` verifies the symmetry.
fn transpose_positions(pattern: &CscPattern) -> Option<Vec<u32>> {
    debug_assert!(pattern.nnz() <= u32::MAX as usize, "checked by the caller");
    let mut next: Vec<usize> = pattern.col_ptr[..pattern.n].to_vec();
    let mut transpose = Vec::with_capacity(pattern.nnz());
    for c in 0..pattern.n {
        for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
            let t = next[r];
            if t >= pattern.col_ptr[r + 1] || pattern.row_idx[t] != c {
                return None;
            }
            next[r] += 1;
            transpose.push(t as u32);
        }
    }
    Some(transpose)
}

/// Factorizes matrices on one pattern (Newton tangents in femu-mech), choosing LDLᵀ for
/// symmetric values and LU otherwise; both symbolic analyses are made at most once.
pub struct SparseSolver {
    /// Position of the transposed entry of each stored entry (32 bits: half the memory
    /// traffic of the asymmetry check before every factorization).
    transpose: Vec<u32>,
    /// The factorization tried first, for symmetric matrices ([`SparseLdlt`] or [`SplitLdlt`]).
    ldlt: Box<dyn Factor>,
    /// Analysed at the first unsymmetric (or not LDLᵀ-factorizable) matrix.
    lu: Option<SparseLu>,
    last: Option<Factorization>,
    /// Relative asymmetry above which LU is used.
    pub symmetry_tolerance: f64,
    /// Solve an unsymmetric matrix `A = S + N` (`S` its symmetric part) by GMRES preconditioned
    /// by the LDLᵀ of `S` instead of an LU of `A`: from `x₀ = S⁻¹ b` until `‖b − A x‖∞ ≤ 1e-13
    /// ‖b‖∞` (the transposed system alike with `Aᵀ`). It converges in a few iterations when
    /// `S⁻¹ N` is small — a follower pressure's load stiffness on part of a stiff body's
    /// outline is a small unsymmetric part — and costs an LDLᵀ (several times cheaper than LU
    /// on 3D meshes) and a few triangular solves and products. A solve that does not converge in a few GMRES cycles (or stalls) falls back
    /// to an LU of `A` for it and every later solve until the next factorization. Off by
    /// default.
    pub refine_on_symmetric_part: bool,
    /// The matrix of the last factorization and work space, kept for the refinement.
    refinement: Option<Refinement>,
}

/// Krylov dimension of a GMRES cycle on the symmetric part's preconditioner.
const REFINEMENT_KRYLOV: usize = 40;

/// GMRES cycles before falling back to LU.
const REFINEMENT_RESTARTS: usize = 4;

/// Relative residual (∞-norm) at which a refined solve stops.
const REFINEMENT_TOLERANCE: f64 = 1e-13;

/// What iterative refinement on the symmetric part keeps: the pattern and values of `A`, the
/// symmetric part's values, and the iterate and residual vectors (allocated once).
struct Refinement {
    pattern: CscPattern,
    values: Vec<f64>,
    symmetric: Vec<f64>,
    residual: Vec<f64>,
    iterate: Vec<f64>,
    /// The Krylov basis of a GMRES cycle (`REFINEMENT_KRYLOV + 1` vectors) and the product's
    /// output.
    basis: Vec<Vec<f64>>,
    product_out: Vec<f64>,
    /// Set when a solve did not converge and LU of `values` took over.
    fell_back: bool,
    /// Refinement steps taken since the factorization (for the reports).
    steps: usize,
}

impl std::fmt::Debug for SparseSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseSolver")
            .field("last", &self.last)
            .finish()
    }
}

impl SparseSolver {
    /// Symbolic analysis for `pattern` (structurally symmetric), with an optional elimination
    /// order for the LDLᵀ (see [`SparseLdlt::new`]).
    pub fn new(pattern: &CscPattern, order: Option<&[usize]>) -> Result<Self, LinearSolveError> {
        Self::with_symmetric_factor(pattern, || {
            SparseLdlt::new(pattern, order).map(|f| Box::new(f) as Box<dyn Factor>)
        })
    }

    /// As [`Self::new`], with symmetric matrices factorized by halves of `split` in parallel
    /// ([`SplitLdlt`]).
    pub fn new_split(pattern: &CscPattern, split: &DofSplit) -> Result<Self, LinearSolveError> {
        Self::with_symmetric_factor(pattern, || {
            SplitLdlt::new(pattern, split).map(|f| Box::new(f) as Box<dyn Factor>)
        })
    }

    /// The transposed positions and the symbolic analysis (`factor`) are independent: one
    /// thread each.
    fn with_symmetric_factor(
        pattern: &CscPattern,
        factor: impl FnOnce() -> Result<Box<dyn Factor>, LinearSolveError> + Send,
    ) -> Result<Self, LinearSolveError> {
        if pattern.nnz() > u32::MAX as usize {
            return Err(LinearSolveError::Other(format!(
                "the tangent has {} entries, more than this solver addresses (2^32)",
                pattern.nnz()
            )));
        }
        let (transpose, ldlt) = rayon::join(|| transpose_positions(pattern), factor);
        let transpose = transpose.ok_or_else(|| {
            LinearSolveError::Other("pattern is not structurally symmetric".into())
        })?;
        Ok(SparseSolver {
            transpose,
            ldlt: ldlt?,
            lu: None,
            last: None,
            symmetry_tolerance: 1e-12,
            refine_on_symmetric_part: false,
            refinement: None,
        })
    }

    /// max |A - Aᵀ| / max |A| (in parallel over the entries: it runs before every
    /// factorization; maxima do not depend on the order).
    pub fn asymmetry(&self, values: &[f64]) -> f64 {
        use rayon::prelude::*;
        let (amax, dmax) = self
            .transpose
            .par_iter()
            .with_min_len(1 << 14)
            .enumerate()
            .map(|(k, &t)| (values[k].abs(), (values[k] - values[t as usize]).abs()))
            .reduce(|| (0.0f64, 0.0f64), |a, b| (a.0.max(b.0), a.1.max(b.1)));
        if amax > 0.0 {
            dmax / amax
        } else {
            0.0
        }
    }

    /// Factorizes `values`: LDLᵀ if symmetric and it succeeds, LU otherwise.
    pub fn factorize(
        &mut self,
        pattern: &CscPattern,
        values: &[f64],
    ) -> Result<Factorization, LinearSolveError> {
        self.last = None;
        let asymmetry = self.asymmetry(values);
        if asymmetry <= self.symmetry_tolerance && self.ldlt.factorize(pattern, values).is_ok() {
            self.last = Some(self.ldlt.kind());
            return Ok(self.ldlt.kind());
        }
        if self.refine_on_symmetric_part && asymmetry > self.symmetry_tolerance {
            let r = self.refinement.get_or_insert_with(|| Refinement {
                pattern: pattern.clone(),
                values: Vec::new(),
                symmetric: Vec::new(),
                residual: vec![0.0; pattern.n],
                iterate: vec![0.0; pattern.n],
                basis: vec![vec![0.0; pattern.n]; REFINEMENT_KRYLOV + 1],
                product_out: vec![0.0; pattern.n],
                fell_back: false,
                steps: 0,
            });
            r.fell_back = false;
            r.steps = 0;
            r.values.clear();
            r.values.extend_from_slice(values);
            r.symmetric.clear();
            r.symmetric.extend(
                self.transpose
                    .iter()
                    .enumerate()
                    .map(|(k, &t)| 0.5 * (values[k] + values[t as usize])),
            );
            if self.ldlt.factorize(pattern, &r.symmetric).is_ok() {
                self.last = Some(Factorization::LdltOfSymmetricPart);
                return Ok(Factorization::LdltOfSymmetricPart);
            }
        }
        let lu = match &mut self.lu {
            Some(lu) => lu,
            None => self.lu.insert(SparseLu::new(pattern)?),
        };
        lu.factorize(pattern, values)?;
        self.last = Some(Factorization::Lu);
        Ok(Factorization::Lu)
    }

    /// The factorization used last, through which the solves go.
    fn factor(&mut self) -> &mut dyn Factor {
        match self.last {
            Some(Factorization::Lu) => self.lu.as_mut().expect("factorized"),
            Some(_) => self.ldlt.as_mut(),
            None => panic!("solve before factorize"),
        }
    }

    /// Whether solves go through the refinement on the symmetric part (it has not fallen
    /// back to LU).
    fn refining(&self) -> bool {
        self.last == Some(Factorization::LdltOfSymmetricPart)
            && self.refinement.as_ref().is_some_and(|r| !r.fell_back)
    }

    /// Solves `A x = rhs` (`Aᵀ x = rhs` with `transpose`) by GMRES preconditioned on the right
    /// by the LDLᵀ of the symmetric part `S`, from `x₀ = S⁻¹ b`; falls back to LU when it
    /// does not reach the tolerance.
    fn refined_solve(&mut self, rhs: &mut [f64], transpose: bool) {
        let b_inf = rhs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if b_inf == 0.0 {
            return;
        }
        let r = self.refinement.as_mut().expect("refinement state");
        let mut x = std::mem::take(&mut r.iterate);
        x.copy_from_slice(rhs);
        self.ldlt.solve_in_place(&mut x);
        let mut converged = false;
        for _restart in 0..REFINEMENT_RESTARTS {
            let r = self.refinement.as_mut().expect("refinement state");
            // residual = b − A x (or b − Aᵀ x).
            r.product(&x, transpose);
            let mut inf = 0.0f64;
            for ((res, ax), b) in r.residual.iter_mut().zip(&r.product_out).zip(rhs.iter()) {
                *res = b - ax;
                inf = inf.max(res.abs());
            }
            if std::env::var_os("FEMU_DEBUG_REFINE").is_some() {
                eprintln!(
                    "refine: |r|/|b| = {:.3e} after {} steps",
                    inf / b_inf,
                    r.steps
                );
            }
            if inf <= REFINEMENT_TOLERANCE * b_inf {
                converged = true;
                break;
            }
            if !self.gmres_cycle(&mut x, transpose, REFINEMENT_TOLERANCE * b_inf) {
                break;
            }
        }
        let r = self.refinement.as_mut().expect("refinement state");
        if converged {
            rhs.copy_from_slice(&x);
            r.iterate = x;
            return;
        }
        r.iterate = x;
        // Fall back to LU of A for this solve and the later ones of this factorization.
        r.fell_back = true;
        let values = std::mem::take(&mut r.values);
        let pattern = r.pattern.clone();
        let lu = match &mut self.lu {
            Some(lu) => lu,
            None => self
                .lu
                .insert(SparseLu::new(&pattern).expect("LU of a pattern LDLT analysed")),
        };
        let ok = lu.factorize(&pattern, &values).is_ok();
        self.refinement.as_mut().expect("state").values = values;
        assert!(ok, "LU of the matrix whose symmetric part factorized");
        self.last = Some(Factorization::Lu);
        if transpose {
            self.lu
                .as_mut()
                .expect("factorized")
                .solve_transpose_in_place(rhs);
        } else {
            self.lu.as_mut().expect("factorized").solve_in_place(rhs);
        }
    }

    /// One cycle of GMRES(m) on `A S⁻¹ y = r` with `r` the refinement's residual, then
    /// `x += S⁻¹ V y` (Saad, *Iterative Methods for Sparse Linear Systems*, 2nd ed., Alg. 9.5:
    /// modified Gram–Schmidt Arnoldi, Givens rotations). Stops when the estimated residual's
    /// 2-norm falls below `tolerance` (the caller checks the true residual's ∞-norm). Returns
    /// false when the cycle reduced the residual by less than half (a stall: LU takes over).
    fn gmres_cycle(&mut self, x: &mut [f64], transpose: bool, tolerance: f64) -> bool {
        let r = self.refinement.as_mut().expect("refinement state");
        let m = REFINEMENT_KRYLOV;
        let beta = r.residual.iter().map(|v| v * v).sum::<f64>().sqrt();
        if beta == 0.0 {
            return true;
        }
        r.basis[0]
            .iter_mut()
            .zip(&r.residual)
            .for_each(|(v, res)| *v = res / beta);
        let mut h = [[0.0f64; REFINEMENT_KRYLOV + 1]; REFINEMENT_KRYLOV];
        let (mut cs, mut sn) = ([0.0f64; REFINEMENT_KRYLOV], [0.0f64; REFINEMENT_KRYLOV]);
        let mut g = [0.0f64; REFINEMENT_KRYLOV + 1];
        g[0] = beta;
        let mut k = 0;
        while k < m {
            // w = A S⁻¹ v_k.
            r.residual.copy_from_slice(&r.basis[k]);
            self.ldlt.solve_in_place(&mut r.residual);
            let z = std::mem::take(&mut r.residual);
            r.product(&z, transpose);
            r.residual = z;
            let mut w = std::mem::take(&mut r.product_out);
            for i in 0..=k {
                let hik: f64 = w.iter().zip(&r.basis[i]).map(|(a, b)| a * b).sum();
                h[k][i] = hik;
                w.iter_mut()
                    .zip(&r.basis[i])
                    .for_each(|(a, b)| *a -= hik * b);
            }
            let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
            h[k][k + 1] = norm;
            if norm > 0.0 {
                r.basis[k + 1]
                    .iter_mut()
                    .zip(&w)
                    .for_each(|(v, a)| *v = a / norm);
            }
            r.product_out = w;
            // Apply the earlier rotations to column k, then make the new one.
            for i in 0..k {
                let (a, b) = (h[k][i], h[k][i + 1]);
                h[k][i] = cs[i] * a + sn[i] * b;
                h[k][i + 1] = -sn[i] * a + cs[i] * b;
            }
            let (a, b) = (h[k][k], h[k][k + 1]);
            let d = a.hypot(b);
            (cs[k], sn[k]) = if d > 0.0 { (a / d, b / d) } else { (1.0, 0.0) };
            h[k][k] = d;
            h[k][k + 1] = 0.0;
            g[k + 1] = -sn[k] * g[k];
            g[k] *= cs[k];
            r.steps += 1;
            k += 1;
            if g[k].abs() <= tolerance || norm == 0.0 {
                break;
            }
        }
        // y from the triangular system H y = g, then x += S⁻¹ (V y).
        let mut y = [0.0f64; REFINEMENT_KRYLOV];
        for i in (0..k).rev() {
            let mut acc = g[i];
            for j in i + 1..k {
                acc -= h[j][i] * y[j];
            }
            y[i] = acc / h[i][i];
        }
        r.residual.fill(0.0);
        for (j, yj) in y.iter().enumerate().take(k) {
            r.residual
                .iter_mut()
                .zip(&r.basis[j])
                .for_each(|(a, v)| *a += yj * v);
        }
        self.ldlt.solve_in_place(&mut r.residual);
        x.iter_mut().zip(&r.residual).for_each(|(a, d)| *a += d);
        g[k].abs() <= 0.5 * beta
    }

    /// Refinement steps taken since the last factorization on the symmetric part (0 when the
    /// last factorization was LDLᵀ or LU of the matrix itself).
    pub fn refinement_steps(&self) -> usize {
        self.refinement.as_ref().map_or(0, |r| r.steps)
    }

    /// Solves `A x = rhs` in place with the last factorization.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) {
        if self.refining() {
            return self.refined_solve(rhs, false);
        }
        self.factor().solve_in_place(rhs);
    }

    /// Solves `A X = B` in place for `columns` (≤ [`MAX_RHS`]) right-hand sides stored one
    /// after the other: one pass over the factors for all of them.
    pub fn solve_many_in_place(&mut self, rhs: &mut [f64], columns: usize) {
        if self.refining() {
            let n = rhs.len() / columns.max(1);
            for column in rhs.chunks_exact_mut(n) {
                self.solve_in_place(column);
            }
            return;
        }
        self.factor().solve_many_in_place(rhs, columns);
    }

    /// Solves `Aᵀ x = rhs` in place with the last factorization.
    pub fn solve_transpose_in_place(&mut self, rhs: &mut [f64]) {
        if self.refining() {
            return self.refined_solve(rhs, true);
        }
        self.factor().solve_transpose_in_place(rhs);
    }

    /// `Y = A X` for `cols` vectors stored interleaved (as [`CscPattern::mul_many_interleaved`]),
    /// by rows in parallel: row `r` of `A` is column `r` read through the transposed positions,
    /// so each output row is a gather owned by one thread (no scatter, no reduction).
    pub fn mul_many_interleaved(
        &self,
        pattern: &CscPattern,
        values: &[f64],
        x: &[f64],
        y: &mut [f64],
        cols: usize,
    ) {
        assert!(cols > 0 && x.len() == pattern.n * cols && y.len() == pattern.n * cols);
        assert_eq!(values.len(), pattern.nnz());
        /// The product with the number of columns known at compile time (registers, no
        /// bounds checks in the inner loop).
        fn rows<const C: usize>(
            pattern: &CscPattern,
            transpose: &[u32],
            values: &[f64],
            x: &[f64],
            y: &mut [f64],
        ) {
            use rayon::prelude::*;
            y.par_chunks_exact_mut(C)
                .with_min_len(256)
                .enumerate()
                .for_each(|(r, yr)| {
                    let mut acc = [0.0; C];
                    for k in pattern.col_ptr[r]..pattern.col_ptr[r + 1] {
                        let a = values[transpose[k] as usize];
                        let c = pattern.row_idx[k];
                        let xr: &[f64; C] = x[c * C..(c + 1) * C].try_into().expect("C values");
                        for j in 0..C {
                            acc[j] += a * xr[j];
                        }
                    }
                    yr.copy_from_slice(&acc);
                });
        }
        macro_rules! dispatch {
            ($($c:literal)*) => {
                match cols {
                    $($c => rows::<$c>(pattern, &self.transpose, values, x, y),)*
                    _ => unreachable!("at most MAX_RHS columns"),
                }
            };
        }
        assert!(cols <= MAX_RHS);
        dispatch!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16);
    }

    /// The factorization used last.
    pub fn last(&self) -> Option<Factorization> {
        self.last
    }
}

impl Refinement {
    /// `product_out = A x` (or `Aᵀ x`).
    fn product(&mut self, x: &[f64], transpose: bool) {
        let out = &mut self.product_out;
        if transpose {
            mul_transpose(&self.pattern, &self.values, x, out);
        } else {
            self.pattern.mul_vec(&self.values, x, out);
        }
    }
}

/// `y = Aᵀ x`: entry `y_c` is column `c` of `A` dotted with `x`.
fn mul_transpose(pattern: &CscPattern, values: &[f64], x: &[f64], y: &mut [f64]) {
    for (c, yc) in y.iter_mut().enumerate() {
        let mut acc = 0.0;
        for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
            acc += values[k] * x[pattern.row_idx[k]];
        }
        *yc = acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::NodeGraph;

    #[test]
    fn transpose_positions_match_a_search_per_entry() {
        let graph =
            NodeGraph::from_elements(6, [[0usize, 1, 4, 3], [1, 2, 5, 4]].iter().map(|e| &e[..]));
        // Node 3 fully prescribed, node 5 x only.
        let eq = [
            0,
            1,
            2,
            3,
            4,
            5,
            usize::MAX,
            usize::MAX,
            6,
            7,
            usize::MAX,
            8,
        ];
        let base = graph.dof_pattern(&eq, 9);
        let p = base.bordered(10, &[(9, vec![0, 4, 8])]);
        let t = transpose_positions(&p).unwrap();
        for c in 0..p.n {
            for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                assert_eq!(Some(t[k] as usize), p.position(c, p.row_idx[k]));
            }
        }
        let mut pairs = vec![(0, 0), (1, 0), (1, 1), (2, 1), (2, 2), (1, 2)];
        assert!(transpose_positions(&CscPattern::from_pairs(3, &mut pairs)).is_none());
        let mut pairs = vec![(0, 0), (1, 0), (1, 1), (2, 2), (0, 2)];
        assert!(transpose_positions(&CscPattern::from_pairs(3, &mut pairs)).is_none());
    }

    /// Adjacency of two quads sharing an edge: sorted, self included.
    #[test]
    fn solves_small_unsymmetric_system() {
        // [[4, 1, 0], [2, 5, 1], [0, 1, 3]]
        let mut pairs = vec![(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2)];
        let p = CscPattern::from_pairs(3, &mut pairs);
        let mut v = vec![0.0; p.nnz()];
        for &(r, c, x) in &[
            (0, 0, 4.0),
            (0, 1, 1.0),
            (1, 0, 2.0),
            (1, 1, 5.0),
            (1, 2, 1.0),
            (2, 1, 1.0),
            (2, 2, 3.0),
        ] {
            v[p.position(r, c).unwrap()] = x;
        }
        let mut lu = SparseLu::new(&p).unwrap();
        lu.factorize(&p, &v).unwrap();
        let x = [1.0, -2.0, 0.5];
        let mut b = [0.0; 3];
        p.mul_vec(&v, &x, &mut b);
        lu.solve_in_place(&mut b);
        for k in 0..3 {
            assert!((b[k] - x[k]).abs() < 1e-13);
        }
        // Three vectors at once, interleaved, as three products.
        let xs = [1.0, -2.0, 0.5, 0.25, 3.0, -1.0, 2.0, 0.0, 4.0];
        let mut interleaved = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                interleaved[i * 3 + j] = xs[j * 3 + i];
            }
        }
        let mut y = [0.0; 9];
        p.mul_many_interleaved(&v, &interleaved, &mut y, 3);
        for j in 0..3 {
            p.mul_vec(&v, &xs[j * 3..(j + 1) * 3], &mut b);
            for i in 0..3 {
                assert_eq!(y[i * 3 + j], b[i]);
            }
        }
        let mut ts = SparseSolver::new(&p, None).unwrap();
        // The parallel row-wise product equals the column-wise one (unsymmetric values).
        let mut y_rows = [0.0; 9];
        ts.mul_many_interleaved(&p, &v, &interleaved, &mut y_rows, 3);
        assert_eq!(y_rows, y);
        assert_eq!(ts.factorize(&p, &v).unwrap(), Factorization::Lu);
        p.mul_vec(&v, &x, &mut b);
        ts.solve_in_place(&mut b);
        assert!(b.iter().zip(&x).all(|(a, e)| (a - e).abs() < 1e-13));
        // Symmetrize: LDLT is chosen.
        v[p.position(1, 0).unwrap()] = 1.0;
        v[p.position(2, 1).unwrap()] = 1.0;
        assert_eq!(ts.factorize(&p, &v).unwrap(), Factorization::Ldlt);
        p.mul_vec(&v, &x, &mut b);
        ts.solve_in_place(&mut b);
        assert!(b.iter().zip(&x).all(|(a, e)| (a - e).abs() < 1e-13));
    }

    /// A tridiagonal matrix `[-1 - e, 2.5, -1 + e]` (SPD for e = 0): with a small unsymmetric
    /// part (e = 0.05) the solves go through GMRES on the symmetric part's LDLᵀ and
    /// agree with LU; with a large one (e = 30) GMRES stalls and LU takes over, with the
    /// same accuracy.
    #[test]
    fn refinement_on_the_symmetric_part_solves_unsymmetric_systems() {
        let n = 3000;
        let mut pairs = Vec::new();
        for i in 0..n {
            pairs.push((i, i));
            if i > 0 {
                pairs.push((i, i - 1));
                pairs.push((i - 1, i));
            }
        }
        let p = CscPattern::from_pairs(n, &mut pairs);
        for (e, expected) in [
            (0.05, Factorization::LdltOfSymmetricPart),
            (30.0, Factorization::Lu),
        ] {
            let mut v = vec![0.0; p.nnz()];
            for i in 0..n {
                v[p.position(i, i).unwrap()] = 2.5;
                if i > 0 {
                    v[p.position(i, i - 1).unwrap()] = -1.0 - e;
                    v[p.position(i - 1, i).unwrap()] = -1.0 + e;
                }
            }
            let mut solver = SparseSolver::new(&p, None).unwrap();
            solver.refine_on_symmetric_part = true;
            assert_eq!(
                solver.factorize(&p, &v).unwrap(),
                Factorization::LdltOfSymmetricPart
            );
            let x: Vec<f64> = (0..n).map(|i| ((i * 7 % 11) as f64 - 5.0) / 3.0).collect();
            let mut b = vec![0.0; n];
            p.mul_vec(&v, &x, &mut b);
            let mut y = b.clone();
            solver.solve_in_place(&mut y);
            let err = y
                .iter()
                .zip(&x)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(err < 1e-12, "e = {e}: error {err}");
            assert_eq!(solver.last(), Some(expected), "e = {e}");
            if expected == Factorization::LdltOfSymmetricPart {
                assert!(solver.refinement_steps() > 0);
            }
            // The transposed system and several columns at once.
            let mut bt = vec![0.0; n];
            mul_transpose(&p, &v, &x, &mut bt);
            let mut yt = bt.clone();
            solver.solve_transpose_in_place(&mut yt);
            let err = yt
                .iter()
                .zip(&x)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(err < 1e-12, "e = {e}: transposed error {err}");
            let mut many: Vec<f64> = b
                .iter()
                .chain(b.iter().map(|v| 2.0 * v).collect::<Vec<_>>().iter())
                .copied()
                .collect();
            solver.solve_many_in_place(&mut many, 2);
            for (k, (a, xk)) in many[n..].iter().zip(&x).enumerate() {
                assert!((a - 2.0 * xk).abs() < 1e-12, "column 2, row {k}");
            }
        }
    }
}
