//! Shape functions and integration rules of the 3D solid elements (Abaqus node orders; Abaqus
//! Theory Manual §3.2.4 for the hexahedron, §3.2.6 for the tetrahedra).
//!
//! - C3D8, C3D8H: nodes 1–4 the face `ζ = -1` counter-clockwise seen from `+ζ`, nodes 5–8 the
//!   face `ζ = +1` above them; `N_a = ⅛ (1 + ξ ξ_a)(1 + η η_a)(1 + ζ ζ_a)`, 2x2x2 Gauss points
//!   `±1/√3` (weight 1).
//! - C3D4: `N = (1 - ξ - η - ζ, ξ, η, ζ)`, one point at the centroid (weight 1/6).
//! - C3D10: corners 1–4 as C3D4, then the mid-edge nodes 5 (1–2), 6 (2–3), 7 (3–1), 8 (1–4),
//!   9 (2–4), 10 (3–4); with the volume coordinates `L = (1 - ξ - η - ζ, ξ, η, ζ)`,
//!   `N_corner = L (2L - 1)` and `N_edge(i, j) = 4 L_i L_j`; the 4-point rule of degree 2 at
//!   the permutations of `(a, b, b, b)`, `a = (5 + 3√5)/20`, `b = (5 - √5)/20`, weight 1/24
//!   (Zienkiewicz & Taylor, *The Finite Element Method* vol. 1, Table 6.4).

/// A 3D element type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind3 {
    /// 8-node hexahedron, full 2x2x2 integration.
    C3d8,
    /// 8-node hexahedron with a constant pressure (mean dilatation, the 3D CPE4H).
    C3d8h,
    /// 4-node tetrahedron, one point.
    C3d4,
    /// 10-node tetrahedron, four points.
    C3d10,
}

impl Kind3 {
    /// Number of nodes.
    pub fn node_count(self) -> usize {
        match self {
            Kind3::C3d8 | Kind3::C3d8h => 8,
            Kind3::C3d4 => 4,
            Kind3::C3d10 => 10,
        }
    }

    /// The Abaqus/CalculiX name.
    pub fn abaqus_name(self) -> &'static str {
        match self {
            Kind3::C3d8 => "C3D8",
            Kind3::C3d8h => "C3D8H",
            Kind3::C3d4 => "C3D4",
            Kind3::C3d10 => "C3D10",
        }
    }

    /// Every type.
    pub const ALL: [Kind3; 4] = [Kind3::C3d8, Kind3::C3d8h, Kind3::C3d4, Kind3::C3d10];

    /// The integration points `(ξ, η, ζ)` and weights.
    pub fn rule(self) -> &'static [([f64; 3], f64)] {
        match self {
            Kind3::C3d8 | Kind3::C3d8h => &HEX_RULE,
            Kind3::C3d4 => &TET1_RULE,
            Kind3::C3d10 => &TET4_RULE,
        }
    }

    /// Shape functions at `(ξ, η, ζ)`, the first [`Kind3::node_count`] entries.
    pub fn shape(self, p: [f64; 3]) -> [f64; 10] {
        let mut n = [0.0; 10];
        match self {
            Kind3::C3d8 | Kind3::C3d8h => {
                for (a, s) in HEX_CORNERS.iter().enumerate() {
                    n[a] = 0.125 * (1.0 + s[0] * p[0]) * (1.0 + s[1] * p[1]) * (1.0 + s[2] * p[2]);
                }
            }
            Kind3::C3d4 => n[..4].copy_from_slice(&volume_coordinates(p)),
            Kind3::C3d10 => {
                let l = volume_coordinates(p);
                for a in 0..4 {
                    n[a] = l[a] * (2.0 * l[a] - 1.0);
                }
                for (e, [i, j]) in TET10_EDGES.iter().enumerate() {
                    n[4 + e] = 4.0 * l[*i] * l[*j];
                }
            }
        }
        n
    }

    /// Shape-function derivatives `∂N_a/∂(ξ, η, ζ)` at a point, the first
    /// [`Kind3::node_count`] entries.
    pub fn shape_derivatives(self, p: [f64; 3]) -> [[f64; 3]; 10] {
        let mut dn = [[0.0; 3]; 10];
        match self {
            Kind3::C3d8 | Kind3::C3d8h => {
                for (a, s) in HEX_CORNERS.iter().enumerate() {
                    let f = [1.0 + s[0] * p[0], 1.0 + s[1] * p[1], 1.0 + s[2] * p[2]];
                    dn[a] = [
                        0.125 * s[0] * f[1] * f[2],
                        0.125 * s[1] * f[0] * f[2],
                        0.125 * s[2] * f[0] * f[1],
                    ];
                }
            }
            Kind3::C3d4 => dn[..4].copy_from_slice(&VOLUME_COORDINATE_GRADIENTS),
            Kind3::C3d10 => {
                let l = volume_coordinates(p);
                let dl = VOLUME_COORDINATE_GRADIENTS;
                for a in 0..4 {
                    dn[a] = dl[a].map(|v| (4.0 * l[a] - 1.0) * v);
                }
                for (e, [i, j]) in TET10_EDGES.iter().enumerate() {
                    dn[4 + e] =
                        std::array::from_fn(|r| 4.0 * (l[*i] * dl[*j][r] + l[*j] * dl[*i][r]));
                }
            }
        }
        dn
    }
}

/// The reference corners `(ξ_a, η_a, ζ_a)` of the hexahedron.
pub const HEX_CORNERS: [[f64; 3]; 8] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

/// The corner pairs of the C3D10 mid-edge nodes 5–10 (zero-based).
pub const TET10_EDGES: [[usize; 2]; 6] = [[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]];

const G: f64 = 0.577_350_269_189_625_8; // 1/sqrt(3)
const HEX_RULE: [([f64; 3], f64); 8] = [
    ([-G, -G, -G], 1.0),
    ([G, -G, -G], 1.0),
    ([G, G, -G], 1.0),
    ([-G, G, -G], 1.0),
    ([-G, -G, G], 1.0),
    ([G, -G, G], 1.0),
    ([G, G, G], 1.0),
    ([-G, G, G], 1.0),
];
const TET1_RULE: [([f64; 3], f64); 1] = [([0.25, 0.25, 0.25], 1.0 / 6.0)];
const TA: f64 = 0.585_410_196_624_968_5; // (5 + 3√5)/20
const TB: f64 = 0.138_196_601_125_010_5; // (5 - √5)/20
const TET4_RULE: [([f64; 3], f64); 4] = [
    ([TB, TB, TB], 1.0 / 24.0),
    ([TA, TB, TB], 1.0 / 24.0),
    ([TB, TA, TB], 1.0 / 24.0),
    ([TB, TB, TA], 1.0 / 24.0),
];

fn volume_coordinates(p: [f64; 3]) -> [f64; 4] {
    [1.0 - p[0] - p[1] - p[2], p[0], p[1], p[2]]
}

const VOLUME_COORDINATE_GRADIENTS: [[f64; 3]; 4] = [
    [-1.0, -1.0, -1.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
];

#[cfg(test)]
mod tests {
    use super::*;

    /// Partition of unity, nodal interpolation (`N_a(node b) = δ_ab`), derivatives against
    /// central differences of the shape functions, and the rules integrating the volume.
    #[test]
    fn shape_functions_and_rules() {
        let tet10_nodes: Vec<[f64; 3]> = {
            let corners = [
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ];
            let mut v = corners.to_vec();
            for [i, j] in TET10_EDGES {
                v.push(std::array::from_fn(|r| {
                    0.5 * (corners[i][r] + corners[j][r])
                }));
            }
            v
        };
        for kind in Kind3::ALL {
            let n = kind.node_count();
            let nodes: Vec<[f64; 3]> = match kind {
                Kind3::C3d8 | Kind3::C3d8h => HEX_CORNERS.to_vec(),
                _ => tet10_nodes[..n].to_vec(),
            };
            for (b, x) in nodes.iter().enumerate() {
                let s = kind.shape(*x);
                for a in 0..n {
                    let want = if a == b { 1.0 } else { 0.0 };
                    assert!((s[a] - want).abs() < 1e-15, "{kind:?} N_{a}(node {b})");
                }
            }
            let p = [0.21, 0.13, 0.32];
            assert!((kind.shape(p)[..n].iter().sum::<f64>() - 1.0).abs() < 1e-15);
            let dn = kind.shape_derivatives(p);
            // Central differences of quadratic functions are exact up to round-off (1e-6 / h).
            let h = 1e-5;
            for r in 0..3 {
                let (mut pp, mut pm) = (p, p);
                pp[r] += h;
                pm[r] -= h;
                let (sp, sm) = (kind.shape(pp), kind.shape(pm));
                for a in 0..n {
                    let fd = (sp[a] - sm[a]) / (2.0 * h);
                    assert!((fd - dn[a][r]).abs() < 1e-9, "{kind:?} dN_{a}/dξ_{r}");
                }
            }
            let volume: f64 = kind.rule().iter().map(|(_, w)| w).sum();
            let want = if matches!(kind, Kind3::C3d8 | Kind3::C3d8h) {
                8.0
            } else {
                1.0 / 6.0
            };
            assert!((volume - want).abs() < 1e-15, "{kind:?}");
        }
        // The 4-point rule integrates ξ² over the unit tetrahedron exactly (1/60).
        let xi2: f64 = Kind3::C3d10
            .rule()
            .iter()
            .map(|(p, w)| w * p[0] * p[0])
            .sum();
        assert!((xi2 - 1.0 / 60.0).abs() < 1e-15);
    }
}
