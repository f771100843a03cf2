//! Point location and interpolation of nodal fields at arbitrary points.
//!
//! Comparing meshes, or a mesh with a measurement, needs the field at the same physical points:
//! the seed projects its FE displacements onto the regular DIC grid (seed §2.4.1, 64 x 64 points
//! 16 px apart) and validates its mesh by the change of the displacement (§2.1.2.1). Both are
//! the same operation: find the element that contains the point, invert the isoparametric map to
//! get its natural coordinates, and weight the element's nodal values by the shape functions
//! there. The weights form the rows of a sparse projection operator (nodal vector → point
//! values), [`PointInterpolation::projection_triplets`].
//!
//! ```text
//!   quad (CPE4, CPE4H): x(ξ, η) = Σ N_a(ξ, η) x_a,    (ξ, η) ∈ [-1, 1]²,
//!                       N_a = (1 ± ξ)(1 ± η) / 4       (nodes 1..4 counter-clockwise,
//!                                                      node 1 at (-1, -1));
//!   triangle (CPE3):    x(ξ, η) = (1 - ξ - η) x_1 + ξ x_2 + η x_3,   ξ, η ≥ 0, ξ + η ≤ 1.
//! ```
//!
//! The bilinear map of a convex quad is one-to-one, so a point inside the quad (tested on its
//! straight edges) has exactly one preimage, found by Newton's method from the centre. A point
//! in no element (outside the skin, in the femur hole, between a curved outline and a coarse
//! mesh's chords) is *masked*: it gets `None`, and callers count it.

use crate::mesh::{ElementKind, Mesh};

/// Where a point lies in a mesh: the element and the shape-function weights of its nodes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLocation {
    /// Element index (into [`Mesh::elements`]).
    pub element: usize,
    /// Natural coordinates of the point in the element (see the module drawing).
    pub xi: [f64; 2],
    /// Node indices of the element; the first `n_nodes` are used.
    pub nodes: [usize; 4],
    /// Shape-function values at the point (they sum to 1); the first `n_nodes` are used.
    pub weights: [f64; 4],
    /// 4 for quads, 3 for triangles.
    pub n_nodes: usize,
}

impl PointLocation {
    /// Interpolates a field with `components` values per node (`values[components * node + c]`).
    pub fn interpolate(&self, values: &[f64], components: usize, c: usize) -> f64 {
        (0..self.n_nodes)
            .map(|a| self.weights[a] * values[components * self.nodes[a] + c])
            .sum()
    }

    /// The shape functions' gradients `∂N_a/∂X` (reference configuration, per mm) at the point
    /// in `mesh` (the mesh it was located in): `∇N = J⁻ᵀ ∂N/∂ξ` with the isoparametric map's
    /// Jacobian `J = ∂X/∂ξ` of the module drawing; zero beyond `n_nodes`. With
    /// [`PointLocation::gradient`], the displacement gradient at the point.
    pub fn shape_gradients(&self, mesh: &Mesh) -> [[f64; 2]; 4] {
        let (x, n) = mesh.element_coords(self.element);
        let [xi, eta] = self.xi;
        let dn: [[f64; 2]; 4] = if n == 3 {
            [[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]
        } else {
            [
                [-0.25 * (1.0 - eta), -0.25 * (1.0 - xi)],
                [0.25 * (1.0 - eta), -0.25 * (1.0 + xi)],
                [0.25 * (1.0 + eta), 0.25 * (1.0 + xi)],
                [-0.25 * (1.0 + eta), 0.25 * (1.0 - xi)],
            ]
        };
        let mut j = [[0.0; 2]; 2];
        for a in 0..n {
            for r in 0..2 {
                for c in 0..2 {
                    j[r][c] += x[a][r] * dn[a][c];
                }
            }
        }
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        let mut g = [[0.0; 2]; 4];
        for a in 0..n {
            // J⁻ᵀ ∂N_a/∂ξ.
            g[a][0] = (j[1][1] * dn[a][0] - j[1][0] * dn[a][1]) / det;
            g[a][1] = (-j[0][1] * dn[a][0] + j[0][0] * dn[a][1]) / det;
        }
        g
    }

    /// The gradient `∂v_c/∂X_d` of a field with `components` values per node at the point, from
    /// [`PointLocation::shape_gradients`] `grads`.
    pub fn gradient(
        &self,
        values: &[f64],
        components: usize,
        grads: &[[f64; 2]; 4],
    ) -> [[f64; 2]; 2] {
        let mut out = [[0.0; 2]; 2];
        for a in 0..self.n_nodes {
            for c in 0..components.min(2) {
                let v = values[components * self.nodes[a] + c];
                out[c][0] += v * grads[a][0];
                out[c][1] += v * grads[a][1];
            }
        }
        out
    }
}

/// Relative tolerance of the inside test (of the element size): points on a shared edge or node
/// belong to one of its elements, points on the mesh outline are inside.
const INSIDE_TOLERANCE: f64 = 1e-9;

/// Finds the element that contains a point, fast: a uniform bucket grid over the element
/// bounding boxes (about one element per bucket), then an exact test in the candidates.
#[derive(Debug, Clone)]
pub struct PointLocator<'a> {
    mesh: &'a Mesh,
    origin: [f64; 2],
    cell: f64,
    nx: usize,
    ny: usize,
    /// CSR storage of the element indices per bucket.
    start: Vec<usize>,
    items: Vec<usize>,
}

impl<'a> PointLocator<'a> {
    /// Builds the bucket grid of `mesh` (linear in the number of elements).
    pub fn new(mesh: &'a Mesh) -> Self {
        let (lo, hi) = mesh.bounding_box();
        let n = mesh.elements.len().max(1);
        let (w, h) = ((hi[0] - lo[0]).max(0.0), (hi[1] - lo[1]).max(0.0));
        let cell = if mesh.elements.is_empty() || !(w * h > 0.0) {
            1.0
        } else {
            (w * h / n as f64).sqrt()
        };
        let nx = ((w / cell).ceil() as usize).clamp(1, 4096);
        let ny = ((h / cell).ceil() as usize).clamp(1, 4096);
        let cell = (w / nx as f64).max(h / ny as f64).max(f64::MIN_POSITIVE);
        let mut loc = PointLocator {
            mesh,
            origin: lo,
            cell,
            nx,
            ny,
            start: vec![0; nx * ny + 1],
            items: Vec::new(),
        };
        if mesh.elements.is_empty() || !lo[0].is_finite() {
            return loc;
        }
        let ranges: Vec<[usize; 4]> = (0..mesh.elements.len())
            .map(|e| {
                let (elo, ehi) = element_box(mesh, e);
                let (i0, j0) = loc.cell_of(elo);
                let (i1, j1) = loc.cell_of(ehi);
                [i0, i1, j0, j1]
            })
            .collect();
        for r in &ranges {
            for j in r[2]..=r[3] {
                for i in r[0]..=r[1] {
                    loc.start[j * nx + i + 1] += 1;
                }
            }
        }
        for k in 0..nx * ny {
            loc.start[k + 1] += loc.start[k];
        }
        let mut fill = loc.start.clone();
        loc.items = vec![0; loc.start[nx * ny]];
        for (e, r) in ranges.iter().enumerate() {
            for j in r[2]..=r[3] {
                for i in r[0]..=r[1] {
                    let b = j * nx + i;
                    loc.items[fill[b]] = e;
                    fill[b] += 1;
                }
            }
        }
        loc
    }

    fn cell_of(&self, p: [f64; 2]) -> (usize, usize) {
        let f =
            |v: f64, o: f64, n: usize| (((v - o) / self.cell).floor().max(0.0) as usize).min(n - 1);
        (
            f(p[0], self.origin[0], self.nx),
            f(p[1], self.origin[1], self.ny),
        )
    }

    /// The element containing `p` and its shape-function weights there, or `None` if `p` lies
    /// in no element (or is not finite). On a shared edge the element found first is returned.
    pub fn locate(&self, p: [f64; 2]) -> Option<PointLocation> {
        if !(p[0].is_finite() && p[1].is_finite()) || self.items.is_empty() {
            return None;
        }
        let margin = self.cell * 1e-9;
        let hi = [
            self.origin[0] + self.nx as f64 * self.cell,
            self.origin[1] + self.ny as f64 * self.cell,
        ];
        if p[0] < self.origin[0] - margin
            || p[1] < self.origin[1] - margin
            || p[0] > hi[0] + margin
            || p[1] > hi[1] + margin
        {
            return None;
        }
        let (i, j) = self.cell_of(p);
        let b = j * self.nx + i;
        self.items[self.start[b]..self.start[b + 1]]
            .iter()
            .find_map(|&e| locate_in_element(self.mesh, e, p))
    }
}

/// Bounding box of element `e`.
fn element_box(mesh: &Mesh, e: usize) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for &n in mesh.elements[e].nodes() {
        for k in 0..2 {
            lo[k] = lo[k].min(mesh.nodes[n][k]);
            hi[k] = hi[k].max(mesh.nodes[n][k]);
        }
    }
    (lo, hi)
}

/// Bilinear shape functions of the quad at `(ξ, η)`.
fn quad_shape(xi: f64, eta: f64) -> [f64; 4] {
    [
        0.25 * (1.0 - xi) * (1.0 - eta),
        0.25 * (1.0 + xi) * (1.0 - eta),
        0.25 * (1.0 + xi) * (1.0 + eta),
        0.25 * (1.0 - xi) * (1.0 + eta),
    ]
}

/// The point `p` in element `e`, or `None` if it lies outside (beyond the tolerance).
pub fn locate_in_element(mesh: &Mesh, e: usize, p: [f64; 2]) -> Option<PointLocation> {
    let el = &mesh.elements[e];
    let (x, n) = mesh.element_coords(e);
    // Size of the element for the tolerances: its longest bounding-box side.
    let (lo, hi) = element_box(mesh, e);
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if !(size > 0.0) {
        return None;
    }
    let tol = INSIDE_TOLERANCE * size;
    if p[0] < lo[0] - tol || p[0] > hi[0] + tol || p[1] < lo[1] - tol || p[1] > hi[1] + tol {
        return None;
    }
    // Inside test on the straight edges (counter-clockwise elements: p left of every edge).
    for a in 0..n {
        let (q, r) = (x[a], x[(a + 1) % n]);
        let (ex, ey) = (r[0] - q[0], r[1] - q[1]);
        let len = ex.hypot(ey);
        let cross = ex * (p[1] - q[1]) - ey * (p[0] - q[0]);
        if cross < -tol * len {
            return None;
        }
    }
    let mut loc = PointLocation {
        element: e,
        xi: [0.0; 2],
        nodes: el.conn,
        weights: [0.0; 4],
        n_nodes: n,
    };
    match el.kind {
        ElementKind::Cpe3 => {
            let (d1, d2) = (
                [x[1][0] - x[0][0], x[1][1] - x[0][1]],
                [x[2][0] - x[0][0], x[2][1] - x[0][1]],
            );
            let det = d1[0] * d2[1] - d1[1] * d2[0];
            let (rx, ry) = (p[0] - x[0][0], p[1] - x[0][1]);
            let xi = (rx * d2[1] - ry * d2[0]) / det;
            let eta = (d1[0] * ry - d1[1] * rx) / det;
            loc.xi = [xi, eta];
            loc.weights = [1.0 - xi - eta, xi, eta, 0.0];
        }
        ElementKind::Cpe4 | ElementKind::Cpe4h => {
            // Newton on x(ξ, η) = p from the centre; the map is bilinear, so a few iterations
            // reach round-off for any reasonably shaped quad.
            let (mut xi, mut eta) = (0.0f64, 0.0f64);
            for _ in 0..50 {
                let nn = quad_shape(xi, eta);
                let mut f = [-p[0], -p[1]];
                for a in 0..4 {
                    f[0] += nn[a] * x[a][0];
                    f[1] += nn[a] * x[a][1];
                }
                let dn = [
                    [-0.25 * (1.0 - eta), -0.25 * (1.0 - xi)],
                    [0.25 * (1.0 - eta), -0.25 * (1.0 + xi)],
                    [0.25 * (1.0 + eta), 0.25 * (1.0 + xi)],
                    [-0.25 * (1.0 + eta), 0.25 * (1.0 - xi)],
                ];
                let mut j = [[0.0; 2]; 2];
                for a in 0..4 {
                    for r in 0..2 {
                        for c in 0..2 {
                            j[r][c] += x[a][r] * dn[a][c];
                        }
                    }
                }
                let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
                if !(det.abs() > 0.0) {
                    return None;
                }
                let dxi = (j[1][1] * f[0] - j[0][1] * f[1]) / det;
                let deta = (-j[1][0] * f[0] + j[0][0] * f[1]) / det;
                xi -= dxi;
                eta -= deta;
                if dxi.abs().max(deta.abs()) < 1e-14 {
                    break;
                }
            }
            // The edge test already decided inside; clamp round-off beyond the edges.
            if !(xi.abs() <= 1.0 + 1e-6 && eta.abs() <= 1.0 + 1e-6) {
                return None;
            }
            let (xi, eta) = (xi.clamp(-1.0, 1.0), eta.clamp(-1.0, 1.0));
            loc.xi = [xi, eta];
            loc.weights = quad_shape(xi, eta);
        }
    }
    Some(loc)
}

/// Interpolation of nodal fields at a fixed list of points: the projection operator from the
/// nodes of one mesh to the points (a DIC grid, another mesh's nodes, ...).
#[derive(Debug, Clone, PartialEq)]
pub struct PointInterpolation {
    /// The points (reference configuration, mm).
    pub points: Vec<[f64; 2]>,
    /// Where each point lies, or `None` if it is outside the mesh (masked).
    pub locations: Vec<Option<PointLocation>>,
}

impl PointInterpolation {
    /// Locates every point of `points` in `mesh` (reference configuration).
    pub fn new(mesh: &Mesh, points: &[[f64; 2]]) -> Self {
        let locator = PointLocator::new(mesh);
        PointInterpolation {
            points: points.to_vec(),
            locations: points.iter().map(|&p| locator.locate(p)).collect(),
        }
    }

    /// Number of points inside the mesh.
    pub fn inside(&self) -> usize {
        self.locations.iter().filter(|l| l.is_some()).count()
    }

    /// Number of masked points (outside the mesh).
    pub fn masked(&self) -> usize {
        self.points.len() - self.inside()
    }

    /// A vector field with two components per node (`u = [ux0, uy0, ux1, uy1, ...]`, the
    /// solver's layout) at every point; `None` at masked points.
    pub fn interpolate_vector(&self, u: &[f64]) -> Vec<Option<[f64; 2]>> {
        self.locations
            .iter()
            .map(|l| l.map(|l| [l.interpolate(u, 2, 0), l.interpolate(u, 2, 1)]))
            .collect()
    }

    /// A scalar field (one value per node) at every point; `None` at masked points.
    pub fn interpolate_scalar(&self, f: &[f64]) -> Vec<Option<f64>> {
        self.locations
            .iter()
            .map(|l| l.map(|l| l.interpolate(f, 1, 0)))
            .collect()
    }

    /// The projection operator of a vector field with two components per node, as
    /// `(row, column, weight)` triplets: row `2 p + c` (point `p`, component `c`), column
    /// `2 n + c` (node `n`). Masked points have empty rows.
    pub fn projection_triplets(&self) -> Vec<(usize, usize, f64)> {
        let mut t = Vec::with_capacity(8 * self.points.len());
        for (p, l) in self.locations.iter().enumerate() {
            if let Some(l) = l {
                for c in 0..2 {
                    for a in 0..l.n_nodes {
                        t.push((2 * p + c, 2 * l.nodes[a] + c, l.weights[a]));
                    }
                }
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate;

    #[test]
    fn unit_square_corners_edges_and_outside() {
        let g = generate::rectangle(2.0, 1.0, 2, 1, ElementKind::Cpe4);
        let pts = [
            [0.0, 0.0],
            [1.0, 0.5],
            [2.0, 1.0],
            [0.5, 0.25],
            [2.0001, 0.5],
            [-1.0, 0.0],
        ];
        let ip = PointInterpolation::new(&g.mesh, &pts);
        assert_eq!(ip.inside(), 4);
        assert_eq!(ip.masked(), 2);
        let l = ip.locations[3].unwrap();
        assert!(
            (l.xi[0] + 0.0).abs() < 1e-14 && (l.xi[1] + 0.5).abs() < 1e-14,
            "{l:?}"
        );
        for l in ip.locations.iter().flatten() {
            assert!((l.weights.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        }
    }

    /// The displacement gradient at a point: exact for an affine field (which both element
    /// kinds reproduce), and the derivative of the interpolated field by central differences
    /// (step 1e-6 mm: truncation ~h² of a bilinear field, round-off ~1e-16/h) for a nodal field
    /// the elements do not reproduce, on distorted quads and on triangles.
    #[test]
    fn gradients_match_affine_fields_and_finite_differences() {
        for kind in [ElementKind::Cpe4, ElementKind::Cpe3] {
            let quads = generate::rectangle(3.0, 2.0, 3, 2, ElementKind::Cpe4);
            let mut g = match kind {
                ElementKind::Cpe3 => generate::split_into_triangles(&quads),
                _ => quads,
            };
            for (k, x) in g.mesh.nodes.iter_mut().enumerate() {
                let s = (k as f64 * 1.7).sin();
                if x[0] > 0.0 && x[0] < 3.0 && x[1] > 0.0 && x[1] < 2.0 {
                    x[0] += 0.2 * s;
                    x[1] -= 0.15 * s;
                }
            }
            let affine: Vec<f64> = g
                .mesh
                .nodes
                .iter()
                .flat_map(|x| [0.3 * x[0] - 0.7 * x[1] + 1.0, 1.1 * x[0] + 0.2 * x[1]])
                .collect();
            let wavy: Vec<f64> = g
                .mesh
                .nodes
                .iter()
                .flat_map(|x| [(x[0] * x[1]).sin(), x[0] * x[0] - x[1]])
                .collect();
            let locator = PointLocator::new(&g.mesh);
            for p in [[0.4, 0.3], [1.6, 1.1], [2.55, 1.7], [1.2, 0.45]] {
                let l = locator.locate(p).unwrap();
                let grads = l.shape_gradients(&g.mesh);
                let a = l.gradient(&affine, 2, &grads);
                let want = [[0.3, -0.7], [1.1, 0.2]];
                for (r, w) in a.iter().zip(&want) {
                    assert!(
                        (r[0] - w[0]).abs() < 1e-12 && (r[1] - w[1]).abs() < 1e-12,
                        "{kind:?} {p:?}: {a:?}"
                    );
                }
                let d = l.gradient(&wavy, 2, &grads);
                let h = 1e-6;
                for dim in 0..2 {
                    let at = |s: f64| {
                        let mut q = p;
                        q[dim] += s;
                        let m = locate_in_element(&g.mesh, l.element, q).unwrap();
                        [m.interpolate(&wavy, 2, 0), m.interpolate(&wavy, 2, 1)]
                    };
                    let (fp, fm) = (at(h), at(-h));
                    for c in 0..2 {
                        let fd = (fp[c] - fm[c]) / (2.0 * h);
                        assert!(
                            (d[c][dim] - fd).abs() < 1e-8,
                            "{kind:?} {p:?} d{c}/dX{dim}: {} vs {fd}",
                            d[c][dim]
                        );
                    }
                }
            }
        }
    }
}
