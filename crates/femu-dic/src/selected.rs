//! The sandwich `C = A⁻¹ M A⁻¹` of two symmetric matrices on one sparse pattern, restricted to
//! that pattern, without forming a column of `C`.
//!
//! `A⁻¹` restricted to the pattern of its Cholesky factor (the *selected inverse*) follows from
//! the factor alone by the recurrence of Takahashi, Fagan & Chen (1973): with `A = L D Lᵀ` (`L`
//! unit lower triangular) and `Z = A⁻¹`, for `j` from the last equation down,
//!
//! ```text
//! Z_ij = − Σ_{k ∈ L_j} Z_ik L_kj   (i ∈ L_j),      Z_jj = 1/D_j − Σ_{k ∈ L_j} L_kj Z_kj,      (1)
//! ```
//!
//! where `L_j` are the rows below the diagonal of column `j` of `L`; every `Z_ik` it reads lies
//! on the pattern of `L + Lᵀ`, which contains that of `A`. And `A⁻¹ M A⁻¹` is the derivative
//! `−d/dt (A + t M)⁻¹` at `t = 0`: `A + t M` keeps the pattern of `A`, so carrying the
//! derivative through the factorization and (1) (forward-mode differentiation: every number is
//! a pair, value and derivative, [`Dual`]) gives `C` on the pattern at the cost of about three
//! factorizations, exactly (to round-off), instead of two solves per equation.

use crate::error::DicError;
use crate::sparse::CscPattern;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::amd;
use faer::sparse::SymbolicSparseColMatRef;

/// A number with its derivative along one direction (`v + ε d`, `ε² = 0`).
#[derive(Debug, Clone, Copy, Default)]
struct Dual {
    v: f64,
    d: f64,
}

impl Dual {
    #[inline]
    fn div(self, o: Dual) -> Dual {
        let v = self.v / o.v;
        Dual {
            v,
            d: (self.d - v * o.d) / o.v,
        }
    }
    /// `self − a b`.
    #[inline]
    fn sub_mul(self, a: Dual, b: Dual) -> Dual {
        Dual {
            v: self.v - a.v * b.v,
            d: self.d - (a.d * b.v + a.v * b.d),
        }
    }
}

const NONE: usize = usize::MAX;

/// `C = A⁻¹ M A⁻¹` on `pattern` (values in the order of the pattern), for `A` (symmetric
/// positive definite) and `M` stored in full on `pattern`, which must be structurally
/// symmetric with its diagonal. `M` enters by its symmetric part `(M + Mᵀ)/2` (`C` is then the
/// symmetric part of `A⁻¹ M A⁻¹`, with the same diagonal): a noise matrix assembled from an
/// estimated correlation of the residual is symmetric only to the accuracy of that estimate.
pub fn sandwich_on_pattern(
    pattern: &CscPattern,
    a_values: &[f64],
    m_values: &[f64],
) -> Result<Vec<f64>, DicError> {
    let n = pattern.n;
    assert_eq!(a_values.len(), pattern.nnz());
    assert_eq!(m_values.len(), pattern.nnz());
    if n == 0 {
        return Ok(Vec::new());
    }
    // Fill-reducing ordering: `inv[old] = new`.
    let inv = amd_order(pattern)?;
    // The upper triangle (row <= column) of P (A + t M) Pᵀ by columns.
    let mut count = vec![0usize; n + 1];
    for c in 0..n {
        for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
            let (r, cc) = (inv[pattern.row_idx[k]], inv[c]);
            if r <= cc {
                count[cc + 1] += 1;
            }
        }
    }
    for c in 0..n {
        count[c + 1] += count[c];
    }
    let ap = count.clone();
    let mut next = count;
    let mut ai = vec![0usize; ap[n]];
    let mut ax = vec![Dual::default(); ap[n]];
    for c in 0..n {
        for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
            let (r, cc) = (inv[pattern.row_idx[k]], inv[c]);
            if r <= cc {
                ai[next[cc]] = r;
                let kt = pattern
                    .position(c, pattern.row_idx[k])
                    .expect("a structurally symmetric pattern");
                ax[next[cc]] = Dual {
                    v: a_values[k],
                    d: 0.5 * (m_values[k] + m_values[kt]),
                };
                next[cc] += 1;
            }
        }
    }
    let f = Ldl::factorize(n, &ap, &ai, &ax)?;
    let (zd, zl) = f.selected_inverse();
    // C = −dZ/dt, read back in the original numbering.
    let mut out = vec![0.0; pattern.nnz()];
    for c in 0..n {
        for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
            let (r, cc) = (inv[pattern.row_idx[k]], inv[c]);
            let (lo, hi) = (r.min(cc), r.max(cc));
            let z = if lo == hi {
                zd[lo]
            } else {
                let rows = &f.li[f.lp[lo]..f.lp[lo + 1]];
                let p = rows
                    .binary_search(&hi)
                    .expect("an entry of A lies on the pattern of its factor");
                zl[f.lp[lo] + p]
            };
            out[k] = -z.d;
        }
    }
    Ok(out)
}

/// Approximate-minimum-degree ordering of `pattern` (faer's AMD): the new number of each
/// equation.
fn amd_order(pattern: &CscPattern) -> Result<Vec<usize>, DicError> {
    let n = pattern.n;
    let mut perm = vec![0usize; n];
    let mut inv = vec![0usize; n];
    let sym = SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx);
    let mut mem = MemBuffer::new(amd::order_scratch::<usize>(n, pattern.nnz()));
    amd::order(
        &mut perm,
        &mut inv,
        sym,
        amd::Control::default(),
        MemStack::new(&mut mem),
    )
    .map_err(|e| DicError::Linear(format!("AMD ordering: {e:?}")))?;
    Ok(inv)
}

/// `L D Lᵀ` (up-looking, simplicial; Davis's LDL) in dual numbers: `lp`, `li` the columns of
/// `L` below the diagonal (rows ascending), `lx` their values, `d` the pivots.
struct Ldl {
    lp: Vec<usize>,
    li: Vec<usize>,
    lx: Vec<Dual>,
    d: Vec<Dual>,
}

impl Ldl {
    /// Factorizes the matrix whose upper triangle is `(ap, ai, ax)` (column `k`: rows `<= k`).
    fn factorize(n: usize, ap: &[usize], ai: &[usize], ax: &[Dual]) -> Result<Self, DicError> {
        // Symbolic: elimination tree and column counts.
        let mut parent = vec![NONE; n];
        let mut flag = vec![NONE; n];
        let mut lnz = vec![0usize; n];
        for k in 0..n {
            flag[k] = k;
            for &i0 in &ai[ap[k]..ap[k + 1]] {
                let mut i = i0;
                while i < k && flag[i] != k {
                    if parent[i] == NONE {
                        parent[i] = k;
                    }
                    lnz[i] += 1;
                    flag[i] = k;
                    i = parent[i];
                }
            }
        }
        let mut lp = vec![0usize; n + 1];
        for k in 0..n {
            lp[k + 1] = lp[k] + lnz[k];
        }
        // Numeric.
        let mut li = vec![0usize; lp[n]];
        let mut lx = vec![Dual::default(); lp[n]];
        let mut d = vec![Dual::default(); n];
        let mut y = vec![Dual::default(); n];
        let mut pattern = vec![0usize; n];
        flag.fill(NONE);
        lnz.fill(0);
        for k in 0..n {
            let mut top = n;
            flag[k] = k;
            for (&i0, &v) in ai[ap[k]..ap[k + 1]].iter().zip(&ax[ap[k]..ap[k + 1]]) {
                y[i0].v += v.v;
                y[i0].d += v.d;
                let mut len = 0;
                let mut i = i0;
                while flag[i] != k {
                    pattern[len] = i;
                    len += 1;
                    flag[i] = k;
                    i = parent[i];
                }
                while len > 0 {
                    top -= 1;
                    len -= 1;
                    pattern[top] = pattern[len];
                }
            }
            let mut dk = y[k];
            y[k] = Dual::default();
            for &i in &pattern[top..n] {
                let yi = y[i];
                y[i] = Dual::default();
                let p2 = lp[i] + lnz[i];
                for p in lp[i]..p2 {
                    let r = li[p];
                    y[r] = y[r].sub_mul(lx[p], yi);
                }
                let l_ki = yi.div(d[i]);
                dk = dk.sub_mul(l_ki, yi);
                li[p2] = k;
                lx[p2] = l_ki;
                lnz[i] += 1;
            }
            if dk.v.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return Err(DicError::Linear(format!(
                    "the Gauss-Newton matrix is singular (pivot {k} of {n} is not positive)"
                )));
            }
            d[k] = dk;
        }
        Ok(Ldl { lp, li, lx, d })
    }

    /// The selected inverse (eq. 1): `Z` on the diagonal and on the pattern of `L` (aligned
    /// with `li`).
    fn selected_inverse(&self) -> (Vec<Dual>, Vec<Dual>) {
        let n = self.d.len();
        let (lp, li, lx) = (&self.lp, &self.li, &self.lx);
        let mut zd = vec![Dual::default(); n];
        let mut zl = vec![Dual::default(); li.len()];
        // w[r]: Z_rj being summed for the rows r of the current column j; mark[r] == j for them.
        let mut w = vec![Dual::default(); n];
        let mut l_of = vec![Dual::default(); n];
        let mut mark = vec![NONE; n];
        for j in (0..n).rev() {
            let rows = &li[lp[j]..lp[j + 1]];
            let ls = &lx[lp[j]..lp[j + 1]];
            for (&r, &l) in rows.iter().zip(ls) {
                mark[r] = j;
                w[r] = Dual::default();
                l_of[r] = l;
            }
            let last = rows.last().copied().unwrap_or(0);
            for (&k, &l_kj) in rows.iter().zip(ls) {
                // The diagonal term Z_kk L_kj of row k.
                w[k] = w[k].sub_mul(zd[k], l_kj);
                // Z_rk for r > k in L_j (all of them lie in L_k, rows ascending): rows r and k.
                for p in lp[k]..lp[k + 1] {
                    let r = li[p];
                    if r > last {
                        break;
                    }
                    if mark[r] == j {
                        let z = zl[p];
                        w[r] = w[r].sub_mul(z, l_kj);
                        w[k] = w[k].sub_mul(z, l_of[r]);
                    }
                }
            }
            let mut zjj = Dual { v: 1.0, d: 0.0 }.div(self.d[j]);
            for (p, (&r, &l)) in rows.iter().zip(ls).enumerate() {
                zl[lp[j] + p] = w[r];
                zjj = zjj.sub_mul(l, w[r]);
            }
            zd[j] = zjj;
        }
        (zd, zl)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dense `A⁻¹ M A⁻¹` by Gauss–Jordan elimination, for the reference.
    fn dense_sandwich(n: usize, a: &[f64], m: &[f64]) -> Vec<f64> {
        let mut aug = vec![0.0; n * 2 * n];
        for i in 0..n {
            for j in 0..n {
                aug[i * 2 * n + j] = a[i * n + j];
            }
            aug[i * 2 * n + n + i] = 1.0;
        }
        for c in 0..n {
            let piv = (c..n)
                .max_by(|&x, &y| {
                    aug[x * 2 * n + c]
                        .abs()
                        .total_cmp(&aug[y * 2 * n + c].abs())
                })
                .unwrap();
            for j in 0..2 * n {
                aug.swap(c * 2 * n + j, piv * 2 * n + j);
            }
            let d = aug[c * 2 * n + c];
            for j in 0..2 * n {
                aug[c * 2 * n + j] /= d;
            }
            for r in 0..n {
                if r != c {
                    let f = aug[r * 2 * n + c];
                    for j in 0..2 * n {
                        aug[r * 2 * n + j] -= f * aug[c * 2 * n + j];
                    }
                }
            }
        }
        let inv = |i: usize, j: usize| aug[i * 2 * n + n + j];
        let mut t = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                t[i * n + j] = (0..n).map(|k| m[i * n + k] * inv(k, j)).sum();
            }
        }
        let mut c = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                c[i * n + j] = (0..n).map(|k| inv(i, k) * t[k * n + j]).sum();
            }
        }
        c
    }

    /// A 2D grid Laplacian-like SPD matrix with two unknowns per node (a 9-point stencil), a
    /// symmetric indefinite-free `M` on the same pattern: the selected sandwich equals the
    /// dense one on every entry of the pattern.
    #[test]
    fn sandwich_matches_dense_reference() {
        let (nx, ny) = (6, 5);
        let nodes = nx * ny;
        let n = 2 * nodes;
        let mut pairs = Vec::new();
        let id = |x: usize, y: usize| y * nx + x;
        for y in 0..ny {
            for x in 0..nx {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (x2, y2) = (x as i64 + dx, y as i64 + dy);
                        if x2 < 0 || y2 < 0 || x2 >= nx as i64 || y2 >= ny as i64 {
                            continue;
                        }
                        let (a, b) = (id(x, y), id(x2 as usize, y2 as usize));
                        for ca in 0..2 {
                            for cb in 0..2 {
                                pairs.push((2 * a + ca, 2 * b + cb));
                            }
                        }
                    }
                }
            }
        }
        let p = femu_sparse::CscPattern::from_pairs(n, &mut pairs);
        // Deterministic pseudo-random symmetric values, A diagonally dominant.
        let val = |r: usize, c: usize, s: f64| {
            let (i, j) = (r.min(c) as f64, r.max(c) as f64);
            ((i * 12.9898 + j * 78.233 + s).sin() * 43_758.545).fract()
        };
        let mut a = vec![0.0; p.nnz()];
        let mut m = vec![0.0; p.nnz()];
        let mut da = vec![0.0; n * n];
        let mut dm = vec![0.0; n * n];
        for c in 0..n {
            for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                let r = p.row_idx[k];
                a[k] = if r == c { 20.0 } else { val(r, c, 1.0) };
                m[k] = if r == c {
                    5.0 + val(r, c, 2.0)
                } else {
                    val(r, c, 3.0)
                };
                da[r * n + c] = a[k];
                dm[r * n + c] = m[k];
            }
        }
        let c = sandwich_on_pattern(&p, &a, &m).unwrap();
        let reference = dense_sandwich(n, &da, &dm);
        let scale = reference.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        for col in 0..n {
            for k in p.col_ptr[col]..p.col_ptr[col + 1] {
                let r = p.row_idx[k];
                // Both sides are exact but for round-off on a well-conditioned 60 x 60 system
                // (condition number about 3): 1e-12 of the largest entry.
                assert!(
                    (c[k] - reference[r * n + col]).abs() <= 1e-12 * scale,
                    "({r}, {col}): {} against {}",
                    c[k],
                    reference[r * n + col]
                );
            }
        }
        // Not positive definite: refused with the pivot named.
        let z = vec![0.0; p.nnz()];
        assert!(matches!(
            sandwich_on_pattern(&p, &z, &m),
            Err(DicError::Linear(_))
        ));
    }
}
