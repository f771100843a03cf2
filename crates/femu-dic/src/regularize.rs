//! Regularization of the correlation: a quadratic penalty `λ aᵀ K a` on the nodal values `a`
//! added to the grey-level cost (module [`crate::solver`], eq. 1), so that the Gauss–Newton
//! system becomes `(M + λK) δa = b − λ K a`.
//!
//! A [`Regularizer`] gives the solver what that system needs: the entries of `K` (its pattern
//! and its values over the equations `2 node + component`) and the weight `λ` against the
//! image term `M`. The penalty itself, `aᵀKa`, is [`Regularizer::energy`]. [`regularizer_for`]
//! picks the implementation from the options of the correlation ([`Laplacian`] when a
//! regularization length is set).

use crate::mesh::DicMesh;
use crate::sparse::{quadratic_form, CscPattern};

/// A quadratic penalty `aᵀKa` on the nodal values of one mesh, with its weight.
pub trait Regularizer: Send + Sync {
    /// A short name for reports.
    fn name(&self) -> &'static str;

    /// Pushes the equation pairs `(row, column)` where `K` may be non-zero (the system's
    /// pattern must hold them).
    fn pattern_pairs(&self, pairs: &mut Vec<(usize, usize)>);

    /// `K` on `pattern` (which holds [`Self::pattern_pairs`]), in full (both triangles).
    fn k_values(&self, pattern: &CscPattern) -> Vec<f64>;

    /// The weight `λ` of the penalty given the image term `M` (values on the same pattern),
    /// `None` when the penalty does not act (no rows, or nothing for the weight to measure).
    fn weight(&self, pattern: &CscPattern, m_values: &[f64], k_values: &[f64]) -> Option<f64>;

    /// The penalty `aᵀKa` (unweighted) at the nodal values `a`.
    fn energy(&self, pattern: &CscPattern, k_values: &[f64], a: &[f64]) -> f64 {
        quadratic_form(pattern, k_values, a)
    }
}

/// The regularizer the options ask for: the Laplacian of length `length` (pixels) when one is
/// set, none otherwise.
pub fn regularizer_for(mesh: &DicMesh, length: Option<f64>) -> Option<Box<dyn Regularizer>> {
    length.map(|ell| Box::new(Laplacian::new(mesh, ell)) as Box<dyn Regularizer>)
}

/// `K = LᵀL` with `L` the 5-point Laplacian of each displacement component (rows from
/// [`laplacian_rows`]), weighted as in Tomičević, Hild & Roux (2013): `λ = vᵀMv / vᵀKv` for a
/// plane wave `v` of wavelength `ℓ` (ux varying along x, uy along y), so that waves shorter
/// than `ℓ` are damped (as `(ℓ/λ_w)⁴`) and longer ones are left to the images. Rigid and
/// affine fields are not penalized.
#[derive(Debug, Clone)]
pub struct Laplacian {
    rows: Vec<Vec<(usize, f64)>>,
    nodes: Vec<[f64; 2]>,
    length: f64,
}

impl Laplacian {
    /// On `mesh`, with the regularization length `length` (pixels).
    pub fn new(mesh: &DicMesh, length: f64) -> Self {
        Laplacian {
            rows: laplacian_rows(mesh),
            nodes: mesh.nodes.clone(),
            length,
        }
    }

    /// The rows of `L` over the nodes: `(node, weight)`, each applied to both components.
    pub fn rows(&self) -> &[Vec<(usize, f64)>] {
        &self.rows
    }
}

impl Regularizer for Laplacian {
    fn name(&self) -> &'static str {
        "laplacian"
    }

    fn pattern_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        for row in &self.rows {
            for &(p, _) in row {
                for &(q, _) in row {
                    for c in 0..2 {
                        pairs.push((2 * p + c, 2 * q + c));
                    }
                }
            }
        }
    }

    fn k_values(&self, pattern: &CscPattern) -> Vec<f64> {
        let mut k_values = vec![0.0; pattern.nnz()];
        for row in &self.rows {
            for &(p, wp) in row {
                for &(q, wq) in row {
                    for c in 0..2 {
                        let pos = pattern
                            .position(2 * p + c, 2 * q + c)
                            .expect("Laplacian entry in the pattern");
                        k_values[pos] += wp * wq;
                    }
                }
            }
        }
        k_values
    }

    fn weight(&self, pattern: &CscPattern, m_values: &[f64], k_values: &[f64]) -> Option<f64> {
        let k = std::f64::consts::TAU / self.length;
        let v: Vec<f64> = (0..2 * self.nodes.len())
            .map(|q| (k * self.nodes[q / 2][q % 2]).sin())
            .collect();
        let vkv = quadratic_form(pattern, k_values, &v);
        let vmv = quadratic_form(pattern, m_values, &v);
        if self.rows.is_empty() || !(vkv > 0.0) {
            None
        } else {
            Some(vmv / vkv)
        }
    }
}

/// Rows of the regularization operator `L`: the 5-point Laplacian (weights `−4, 1, 1, 1, 1`)
/// at the nodes whose four neighbours are nodes, and at the other nodes the 1D second
/// difference (`1, −2, 1`) along each grid direction in which both neighbours exist (so edge
/// and corner nodes are regularized too). Affine fields are in the kernel of every row.
pub fn laplacian_rows(mesh: &DicMesh) -> Vec<Vec<(usize, f64)>> {
    let w = mesh.nx + 1;
    let at = |i: isize, j: isize| {
        if i < 0 || j < 0 || i > mesh.nx as isize || j > mesh.ny as isize {
            usize::MAX
        } else {
            mesh.grid_node[j as usize * w + i as usize]
        }
    };
    let mut rows = Vec::new();
    for (n, &(i, j)) in mesh.node_grid.iter().enumerate() {
        let (i, j) = (i as isize, j as isize);
        let (l, r, d, u) = (at(i - 1, j), at(i + 1, j), at(i, j - 1), at(i, j + 1));
        let ok = |q: usize| q != usize::MAX;
        if ok(l) && ok(r) && ok(d) && ok(u) {
            rows.push(vec![(n, -4.0), (l, 1.0), (r, 1.0), (d, 1.0), (u, 1.0)]);
            continue;
        }
        if ok(l) && ok(r) {
            rows.push(vec![(n, -2.0), (l, 1.0), (r, 1.0)]);
        }
        if ok(d) && ok(u) {
            rows.push(vec![(n, -2.0), (d, 1.0), (u, 1.0)]);
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Rect, Roi};

    /// A 2 x 2-element mesh (3 x 3 nodes, 8 px elements): the centre node has the 5-point
    /// row, each edge midpoint one 1D second difference along its edge, each corner none
    /// (no direction has both neighbours).
    fn mesh3() -> DicMesh {
        let roi = Roi::Rect(Rect {
            x: 0,
            y: 0,
            w: 16,
            h: 16,
        });
        DicMesh::new(&roi, 16, 16, 8).unwrap()
    }

    /// Node at grid position (i, j).
    fn node(m: &DicMesh, i: usize, j: usize) -> usize {
        m.grid_node[j * (m.nx + 1) + i]
    }

    /// `K = LᵀL` entries computed by hand on the 3 x 3 grid: rows are the centre
    /// `(−4 at c; 1 at the four edge midpoints)`, the bottom and top midpoints along x
    /// `(−2 at the midpoint; 1 at its two corners)`, the left and right midpoints along y.
    /// Exact: small integers, so equality (every sum is exact in floating point).
    #[test]
    fn laplacian_k_matches_hand_computed_small_grid() {
        let m = mesh3();
        let lap = Laplacian::new(&m, 32.0);
        assert_eq!(lap.rows().len(), 5, "centre + four edge midpoints");
        let mut pairs = Vec::new();
        lap.pattern_pairs(&mut pairs);
        let pattern = CscPattern::from_pairs(2 * m.n_nodes(), &mut pairs);
        let k = lap.k_values(&pattern);
        let entry = |a: usize, b: usize, c: usize| {
            pattern.position(2 * a + c, 2 * b + c).map_or(0.0, |p| k[p])
        };
        let c = node(&m, 1, 1);
        let (b, t, l, r) = (
            node(&m, 1, 0),
            node(&m, 1, 2),
            node(&m, 0, 1),
            node(&m, 2, 1),
        );
        let (c00, c20) = (node(&m, 0, 0), node(&m, 2, 0));
        for comp in 0..2 {
            // Centre: (−4)² from its own row only.
            assert_eq!(entry(c, c, comp), 16.0);
            // Bottom midpoint: 1² (centre row) + (−2)² (its own row).
            assert_eq!(entry(b, b, comp), 5.0);
            // Corner (0,0): 1² from the bottom row and 1² from the left row.
            assert_eq!(entry(c00, c00, comp), 2.0);
            // Centre–bottom: (−4)(1) in the centre row; the bottom row does not hold c.
            assert_eq!(entry(c, b, comp), -4.0);
            assert_eq!(entry(b, c, comp), -4.0);
            // Bottom–top: both in the centre row only, 1·1.
            assert_eq!(entry(b, t, comp), 1.0);
            // Left–right: 1·1 in the centre row.
            assert_eq!(entry(l, r, comp), 1.0);
            // Bottom–corner (0,0): (−2)(1) in the bottom row.
            assert_eq!(entry(b, c00, comp), -2.0);
            // Two corners of the bottom edge: 1·1 in the bottom row.
            assert_eq!(entry(c00, c20, comp), 1.0);
            // Centre–corner: never in one row.
            assert_eq!(entry(c, c00, comp), 0.0);
        }
        // The components do not couple.
        assert!(pattern.position(2 * c, 2 * c + 1).is_none());
    }

    /// Affine fields are in the kernel of `K` (zero energy); a checkerboard is not.
    #[test]
    fn laplacian_energy_vanishes_on_affine_fields() {
        let roi = Roi::Rect(Rect {
            x: 0,
            y: 0,
            w: 48,
            h: 40,
        });
        let m = DicMesh::new(&roi, 48, 40, 8).unwrap();
        let lap = Laplacian::new(&m, 32.0);
        let mut pairs = Vec::new();
        lap.pattern_pairs(&mut pairs);
        let pattern = CscPattern::from_pairs(2 * m.n_nodes(), &mut pairs);
        let k = lap.k_values(&pattern);
        let affine: Vec<f64> = m
            .nodes
            .iter()
            .flat_map(|p| {
                [
                    0.3 + 0.01 * p[0] - 0.02 * p[1],
                    -0.1 + 0.005 * p[0] + 0.03 * p[1],
                ]
            })
            .collect();
        // The exact energy is 0; the computed one is the rounding of a sum of nnz(K) terms,
        // each below |a_i| |K_ij| |a_j|: at most nnz · ε relative to the sum of their sizes
        // (nnz ~ 10³, ε ~ 1e-16, hence the 1e-12), against 1 for a field the penalty sees.
        let size = quadratic_form(
            &pattern,
            &k.iter().map(|v| v.abs()).collect::<Vec<_>>(),
            &affine.iter().map(|v| v.abs()).collect::<Vec<_>>(),
        );
        let e = lap.energy(&pattern, &k, &affine);
        assert!(e.abs() < 1e-12 * size, "{e} against {size}");
        let checker: Vec<f64> = m
            .node_grid
            .iter()
            .flat_map(|&(i, j)| {
                let s = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
                [s, s]
            })
            .collect();
        assert!(lap.energy(&pattern, &k, &checker) > 1.0);
    }

    /// The weight `λ = vᵀMv / vᵀKv`: with `M = K` on the pattern it is 1, with `M = 3K` it is 3;
    /// no rows (a single element: no node has both neighbours) gives no weight.
    #[test]
    fn weight_is_the_ratio_of_the_wave_energies() {
        let m = mesh3();
        let lap = Laplacian::new(&m, 32.0);
        let mut pairs = Vec::new();
        lap.pattern_pairs(&mut pairs);
        let pattern = CscPattern::from_pairs(2 * m.n_nodes(), &mut pairs);
        let k = lap.k_values(&pattern);
        // Two quadratic forms of the same vector with the values scaled: exact ratio up to the
        // rounding of one division and one scaling.
        let w1 = lap.weight(&pattern, &k, &k).unwrap();
        assert!((w1 - 1.0).abs() < 1e-14, "{w1}");
        let k3: Vec<f64> = k.iter().map(|v| 3.0 * v).collect();
        let w3 = lap.weight(&pattern, &k3, &k).unwrap();
        assert!((w3 - 3.0).abs() < 1e-14, "{w3}");
        let one = DicMesh::new(
            &Roi::Rect(Rect {
                x: 0,
                y: 0,
                w: 8,
                h: 8,
            }),
            8,
            8,
            8,
        )
        .unwrap();
        let lap1 = Laplacian::new(&one, 32.0);
        assert!(lap1.rows().is_empty());
        let mut pairs = vec![(0, 0)];
        lap1.pattern_pairs(&mut pairs);
        let p1 = CscPattern::from_pairs(2 * one.n_nodes(), &mut pairs);
        let k1 = lap1.k_values(&p1);
        assert!(lap1.weight(&p1, &k1, &k1).is_none());
    }
}
