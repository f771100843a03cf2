//! The 3D mesh model: nodes `[x, y, z]` (mm), solid elements C3D8, C3D8H, C3D4 and C3D10 in the
//! Abaqus node orders, named element sets (tissue regions), node sets and element-face
//! surfaces.
//!
//! Node orders (Abaqus Analysis User's Manual §28.1.4, "Three-dimensional solid element
//! library"):
//!
//! ```text
//!   C3D8, C3D8H                       C3D4, C3D10
//!        8 -------- 7                       4
//!       /|         /|                      /|\
//!      5 -------- 6 |                   8 / | \ 10
//!      | 4 -------|-3                    /  9  \
//!      |/         |/                    1 --|-7-- 3
//!      1 -------- 2                      5 \|  / 6
//!                                           2
//! ```
//!
//! Hexahedron: nodes 1–4 the face `ζ = -1`, counter-clockwise seen from `+ζ`, nodes 5–8 above
//! them. Tetrahedron: corners 1–4 with 4 on the positive side of the face 1-2-3; the C3D10
//! mid-edge nodes 5 (1–2), 6 (2–3), 7 (3–1), 8 (1–4), 9 (2–4), 10 (3–4).
//!
//! Faces, as Abaqus numbers them (`S1`..`S6` in `*SURFACE`, `P1`..`P6` in `*DLOAD`):
//! hexahedron S1 1-2-3-4, S2 5-8-7-6, S3 1-5-6-2, S4 2-6-7-3, S5 3-7-8-4, S6 4-8-5-1;
//! tetrahedron S1 1-2-3, S2 1-4-2, S3 2-4-3, S4 3-4-1. Those lists turn about the inward
//! normal; [`Element3::face_nodes`] returns each face in the opposite order, whose normal (right
//! hand) points out of the element, corners first and then the mid-edge nodes of a C3D10 face
//! in corner order, the order of the follower pressure of `femu_mech::solid3d::pressure`.

use std::collections::BTreeMap;

use crate::mesh::MeshError;

/// 3D element formulation, named as in Abaqus/CalculiX decks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ElementKind3 {
    /// 8-node trilinear hexahedron, full 2x2x2 Gauss integration.
    C3d8,
    /// 8-node hexahedron, hybrid with a constant pressure (mean dilatation).
    C3d8h,
    /// 4-node linear tetrahedron.
    C3d4,
    /// 10-node quadratic tetrahedron.
    C3d10,
}

/// Outward faces of the hexahedron (0-based local nodes), S1..S6.
const HEX_FACES: [[usize; 4]; 6] = [
    [0, 3, 2, 1],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
];

/// Outward faces of the tetrahedra (0-based local nodes), S1..S4: corners, then the mid-edge
/// nodes of the C3D10 between consecutive corners.
const TET_FACES: [[usize; 6]; 4] = [
    [0, 2, 1, 6, 5, 4],
    [0, 1, 3, 4, 8, 7],
    [1, 2, 3, 5, 9, 8],
    [0, 3, 2, 7, 9, 6],
];

impl ElementKind3 {
    /// Every type.
    pub const ALL: [ElementKind3; 4] = [
        ElementKind3::C3d8,
        ElementKind3::C3d8h,
        ElementKind3::C3d4,
        ElementKind3::C3d10,
    ];

    /// Number of nodes of the element.
    pub fn node_count(self) -> usize {
        match self {
            ElementKind3::C3d8 | ElementKind3::C3d8h => 8,
            ElementKind3::C3d4 => 4,
            ElementKind3::C3d10 => 10,
        }
    }

    /// Number of faces (6 for a hexahedron, 4 for a tetrahedron).
    pub fn face_count(self) -> usize {
        match self {
            ElementKind3::C3d8 | ElementKind3::C3d8h => 6,
            ElementKind3::C3d4 | ElementKind3::C3d10 => 4,
        }
    }

    /// Local nodes (0-based) of face `face` (0-based: `S1` is 0), in the order whose normal
    /// points out of the element.
    pub fn face_local_nodes(self, face: usize) -> &'static [usize] {
        match self {
            ElementKind3::C3d8 | ElementKind3::C3d8h => &HEX_FACES[face],
            ElementKind3::C3d4 => &TET_FACES[face][..3],
            ElementKind3::C3d10 => &TET_FACES[face],
        }
    }

    /// The deck name of the element type (`C3D8`, `C3D8H`, `C3D4`, `C3D10`).
    pub fn deck_name(self) -> &'static str {
        match self {
            ElementKind3::C3d8 => "C3D8",
            ElementKind3::C3d8h => "C3D8H",
            ElementKind3::C3d4 => "C3D4",
            ElementKind3::C3d10 => "C3D10",
        }
    }

    /// Parses a deck element type name (case-insensitive).
    pub fn from_deck_name(name: &str) -> Option<Self> {
        let name = name.trim();
        ElementKind3::ALL
            .into_iter()
            .find(|k| k.deck_name().eq_ignore_ascii_case(name))
    }

    /// VTK cell type (12 = VTK_HEXAHEDRON, 10 = VTK_TETRA, 24 = VTK_QUADRATIC_TETRA; the VTK
    /// node orders are the Abaqus ones for these three).
    pub fn vtk_cell_type(self) -> u8 {
        match self {
            ElementKind3::C3d8 | ElementKind3::C3d8h => 12,
            ElementKind3::C3d4 => 10,
            ElementKind3::C3d10 => 24,
        }
    }
}

/// One 3D element: its formulation and its node indices (0-based indices into
/// [`Mesh3::nodes`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Element3 {
    pub kind: ElementKind3,
    /// Node indices; only the first `kind.node_count()` entries are used.
    pub conn: [usize; 10],
}

impl Element3 {
    /// An element of `kind` on `nodes` (exactly `kind.node_count()` of them).
    pub fn new(kind: ElementKind3, nodes: &[usize]) -> Self {
        assert_eq!(nodes.len(), kind.node_count(), "{}", kind.deck_name());
        let mut conn = [usize::MAX; 10];
        conn[..nodes.len()].copy_from_slice(nodes);
        Element3 { kind, conn }
    }

    /// The node indices of the element.
    pub fn nodes(&self) -> &[usize] {
        &self.conn[..self.kind.node_count()]
    }

    /// The node indices of face `face` (0-based), in the outward order (module documentation).
    pub fn face_nodes(&self, face: usize) -> Vec<usize> {
        self.kind
            .face_local_nodes(face)
            .iter()
            .map(|&a| self.conn[a])
            .collect()
    }
}

/// A 3D mesh: nodes (mm), elements, named element sets, node sets and surfaces.
///
/// Deck labels are kept so that outputs use the user's own numbering.
#[derive(Debug, Clone, Default)]
pub struct Mesh3 {
    /// Reference coordinates (mm).
    pub nodes: Vec<[f64; 3]>,
    /// The deck label of each node (same length as `nodes`).
    pub node_labels: Vec<i64>,
    pub elements: Vec<Element3>,
    /// The deck label of each element (same length as `elements`).
    pub element_labels: Vec<i64>,
    /// Named element sets (e.g. tissue regions), as element indices.
    pub element_sets: BTreeMap<String, Vec<usize>>,
    /// Named node sets (e.g. the femur surface), as node indices.
    pub node_sets: BTreeMap<String, Vec<usize>>,
    /// Named element-face surfaces, as `(element, face)` (0-based face: `S1` is 0).
    pub surfaces: BTreeMap<String, Vec<(usize, usize)>>,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn det(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    dot(a, cross(b, c))
}

/// Local coordinates of the hexahedron's corners (Abaqus order).
const HEX_SIGNS: [[f64; 3]; 8] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

impl Mesh3 {
    /// Adds a node with label `index + 1` and returns its index.
    pub fn add_node(&mut self, x: [f64; 3]) -> usize {
        self.nodes.push(x);
        self.node_labels.push(self.nodes.len() as i64);
        self.nodes.len() - 1
    }

    /// Adds an element with label `index + 1` and returns its index.
    pub fn add_element(&mut self, e: Element3) -> usize {
        self.elements.push(e);
        self.element_labels.push(self.elements.len() as i64);
        self.elements.len() - 1
    }

    /// The Jacobian determinant of each corner's map (local nodes 1..), times the reference
    /// volume of the element's parent (8 for the hexahedron's `[-1, 1]³`, 1/6 for the
    /// tetrahedron's unit simplex): for a hexahedron, `det J` at corner a is
    /// `⅛ det(e_ξ, e_η, e_ζ)` with `e` the three edges through a oriented along `+ξ, +η, +ζ`;
    /// for a tetrahedron the signed volume of its corners (the straight-sided C3D10 map).
    /// All must be positive for a valid element.
    fn corner_volumes(&self, el: &Element3) -> Vec<f64> {
        let x = |a: usize| self.nodes[el.conn[a]];
        match el.kind {
            ElementKind3::C3d8 | ElementKind3::C3d8h => (0..8)
                .map(|a| {
                    let s = HEX_SIGNS[a];
                    let edge = |axis: usize| {
                        let mut t = s;
                        t[axis] = -t[axis];
                        let b = HEX_SIGNS.iter().position(|q| *q == t).expect("a corner");
                        let e = sub(x(a), x(b));
                        [e[0] * s[axis], e[1] * s[axis], e[2] * s[axis]]
                    };
                    det(edge(0), edge(1), edge(2))
                })
                .collect(),
            ElementKind3::C3d4 | ElementKind3::C3d10 => {
                vec![det(sub(x(1), x(0)), sub(x(2), x(0)), sub(x(3), x(0))) / 6.0]
            }
        }
    }

    /// Checks that every node index exists and every element has positive corner volumes
    /// (a hexahedron at each of its 8 corners, a tetrahedron by its corners): an inverted,
    /// flat or self-crossing element is named by its label.
    pub fn check_orientation(&self) -> Result<(), MeshError> {
        for (e, el) in self.elements.iter().enumerate() {
            if let Some(&node) = el.nodes().iter().find(|&&n| n >= self.nodes.len()) {
                return Err(MeshError::MissingNode {
                    label: self.element_labels[e],
                    node,
                });
            }
            for (c, v) in self.corner_volumes(el).into_iter().enumerate() {
                if v.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return Err(MeshError::InvertedSolid {
                        label: self.element_labels[e],
                        volume: v,
                        corner: c + 1,
                    });
                }
            }
        }
        Ok(())
    }

    /// The volume of element `e` (mm³): the hexahedron by the divergence theorem on its
    /// faces split into triangles about their centroids (exact for a trilinear hexahedron
    /// whose faces are planar, within the face warping otherwise), the tetrahedra by their
    /// corners (exact for a straight-sided C3D10).
    pub fn element_volume(&self, e: usize) -> f64 {
        let el = &self.elements[e];
        let x = |a: usize| self.nodes[el.conn[a]];
        match el.kind {
            ElementKind3::C3d4 | ElementKind3::C3d10 => {
                det(sub(x(1), x(0)), sub(x(2), x(0)), sub(x(3), x(0))) / 6.0
            }
            ElementKind3::C3d8 | ElementKind3::C3d8h => {
                // V = Σ_faces Σ_triangles (1/6) (c, p, q) with c the face centroid: the
                // volume of the polyhedron of these triangles (Gauss's theorem).
                let mut v = 0.0;
                for f in &HEX_FACES {
                    let p: Vec<[f64; 3]> = f.iter().map(|&a| x(a)).collect();
                    let c = [0, 1, 2].map(|i| p.iter().map(|q| q[i]).sum::<f64>() / 4.0);
                    for k in 0..4 {
                        v += det(c, p[k], p[(k + 1) % 4]) / 6.0;
                    }
                }
                v
            }
        }
    }

    /// Total volume (mm³).
    pub fn volume(&self) -> f64 {
        (0..self.elements.len())
            .map(|e| self.element_volume(e))
            .sum()
    }

    /// Volume of the elements of the element set `name` (mm³), `None` if there is no such set.
    pub fn set_volume(&self, name: &str) -> Option<f64> {
        self.element_set(name)
            .map(|s| s.iter().map(|&e| self.element_volume(e)).sum())
    }

    /// Boundary faces: `(element, face)` pairs whose face belongs to one element only (faces
    /// are matched by their sorted corner nodes).
    pub fn boundary_faces(&self) -> Vec<(usize, usize)> {
        let mut count: BTreeMap<Vec<usize>, (usize, usize, usize)> = BTreeMap::new();
        for (e, el) in self.elements.iter().enumerate() {
            for f in 0..el.kind.face_count() {
                let mut key = el.face_nodes(f);
                key.truncate(if key.len() == 6 { 3 } else { key.len() });
                key.sort_unstable();
                count
                    .entry(key)
                    .and_modify(|v| v.2 += 1)
                    .or_insert((e, f, 1));
            }
        }
        let mut faces: Vec<(usize, usize)> = count
            .values()
            .filter(|v| v.2 == 1)
            .map(|v| (v.0, v.1))
            .collect();
        faces.sort_unstable();
        faces
    }

    /// Area vector of face `face` of element `e` (mm², along its outward normal): half the
    /// cross product of the diagonals for a quadrilateral (exact for a planar one), the
    /// corners' cross product for a triangle.
    pub fn face_area_vector(&self, e: usize, face: usize) -> [f64; 3] {
        let n = self.elements[e].face_nodes(face);
        let x = |k: usize| self.nodes[n[k]];
        let c = if n.len() == 4 {
            cross(sub(x(2), x(0)), sub(x(3), x(1)))
        } else {
            cross(sub(x(1), x(0)), sub(x(2), x(0)))
        };
        c.map(|v| 0.5 * v)
    }

    /// The centroid of the corners of face `face` of element `e`.
    pub fn face_centroid(&self, e: usize, face: usize) -> [f64; 3] {
        let n = self.elements[e].face_nodes(face);
        let corners = if n.len() == 6 { 3 } else { n.len() };
        let mut c = [0.0; 3];
        for &a in &n[..corners] {
            for (ci, xi) in c.iter_mut().zip(self.nodes[a]) {
                *ci += xi / corners as f64;
            }
        }
        c
    }

    /// Axis-aligned bounding box `([xmin, ymin, zmin], [xmax, ymax, zmax])` of the nodes.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.nodes {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// The node set `name`, compared case-insensitively as set names are in Abaqus decks.
    pub fn node_set(&self, name: &str) -> Option<&[usize]> {
        find(&self.node_sets, name).map(Vec::as_slice)
    }

    /// The element set `name`, compared case-insensitively.
    pub fn element_set(&self, name: &str) -> Option<&[usize]> {
        find(&self.element_sets, name).map(Vec::as_slice)
    }

    /// The surface `name`, compared case-insensitively.
    pub fn surface(&self, name: &str) -> Option<&[(usize, usize)]> {
        find(&self.surfaces, name).map(Vec::as_slice)
    }
}

fn find<'a, T>(sets: &'a BTreeMap<String, T>, name: &str) -> Option<&'a T> {
    sets.get(name).or_else(|| {
        sets.iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v)
    })
}

/// Test and example meshes.
pub mod generate {
    use super::{Element3, ElementKind3, Mesh3, HEX_SIGNS};

    /// The box `[0, l[0]] x [0, l[1]] x [0, l[2]]` of `n[0] x n[1] x n[2]` hexahedra of `kind`
    /// (C3D8 or C3D8H), or of the same cells each split into six tetrahedra about the diagonal
    /// from their corner 1 to 7 (C3D4, or C3D10 with straight mid-edge nodes). Node sets `X0`,
    /// `X1`, `Y0`, `Y1`, `Z0`, `Z1` (the nodes on each side) and element set `ALL`.
    pub fn block(l: [f64; 3], n: [usize; 3], kind: ElementKind3) -> Mesh3 {
        let mut m = Mesh3::default();
        let id = |i: usize, j: usize, k: usize| i + (n[0] + 1) * (j + (n[1] + 1) * k);
        for k in 0..=n[2] {
            for j in 0..=n[1] {
                for i in 0..=n[0] {
                    m.add_node([
                        l[0] * i as f64 / n[0] as f64,
                        l[1] * j as f64 / n[1] as f64,
                        l[2] * k as f64 / n[2] as f64,
                    ]);
                }
            }
        }
        // Mid-edge nodes of C3D10, shared between elements through their end nodes.
        let mut mid: std::collections::HashMap<(usize, usize), usize> = Default::default();
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let corner = HEX_SIGNS.map(|s| {
                        let o = s.map(|v| usize::from(v > 0.0));
                        id(i + o[0], j + o[1], k + o[2])
                    });
                    match kind {
                        ElementKind3::C3d8 | ElementKind3::C3d8h => {
                            m.add_element(Element3::new(kind, &corner));
                        }
                        ElementKind3::C3d4 | ElementKind3::C3d10 => {
                            // Six tetrahedra about the diagonal 1–7 (0-based 0–6), each
                            // positively oriented.
                            for [a, b] in [[1, 2], [2, 3], [3, 7], [7, 4], [4, 5], [5, 1]] {
                                let mut t = [corner[0], corner[a], corner[b], corner[6]];
                                if signed_volume(&m, t) < 0.0 {
                                    t.swap(1, 2);
                                }
                                if kind == ElementKind3::C3d4 {
                                    m.add_element(Element3::new(kind, &t));
                                    continue;
                                }
                                let mut nodes = t.to_vec();
                                for [p, q] in [[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]] {
                                    let key = (t[p].min(t[q]), t[p].max(t[q]));
                                    let node = *mid.entry(key).or_insert_with(|| {
                                        let (xa, xb) = (m.nodes[t[p]], m.nodes[t[q]]);
                                        m.add_node(std::array::from_fn(|i| 0.5 * (xa[i] + xb[i])))
                                    });
                                    nodes.push(node);
                                }
                                m.add_element(Element3::new(kind, &nodes));
                            }
                        }
                    }
                }
            }
        }
        for (axis, name) in ["X", "Y", "Z"].iter().enumerate() {
            for (side, end) in [(0, 0.0), (1, l[axis])] {
                let set: Vec<usize> = (0..m.nodes.len())
                    .filter(|&a| (m.nodes[a][axis] - end).abs() <= 1e-9 * l[axis])
                    .collect();
                m.node_sets.insert(format!("{name}{side}"), set);
            }
        }
        m.element_sets
            .insert("ALL".into(), (0..m.elements.len()).collect());
        m
    }

    fn signed_volume(m: &Mesh3, t: [usize; 4]) -> f64 {
        let x = |a: usize| m.nodes[t[a]];
        let e = |a: usize| std::array::from_fn::<f64, 3, _>(|i| x(a)[i] - x(0)[i]);
        super::det(e(1), e(2), e(3))
    }
}

#[cfg(test)]
mod tests {
    use super::generate::block;
    use super::*;

    #[test]
    fn deck_names_round_trip() {
        for k in ElementKind3::ALL {
            assert_eq!(
                ElementKind3::from_deck_name(&k.deck_name().to_lowercase()),
                Some(k)
            );
        }
        assert_eq!(ElementKind3::from_deck_name("CPE4"), None);
    }

    /// Each element type fills the box: volumes add up to the box, every element is valid,
    /// and the boundary faces' outward area vectors add up to zero and each points away from
    /// its element's centroid.
    #[test]
    fn blocks_have_the_box_volume_and_outward_faces() {
        for kind in ElementKind3::ALL {
            let m = block([2.0, 3.0, 1.5], [2, 3, 2], kind);
            m.check_orientation().unwrap();
            // Sums of exact element volumes: round-off only.
            assert!((m.volume() - 9.0).abs() < 1e-12, "{kind:?}: {}", m.volume());
            let faces = m.boundary_faces();
            // 2 (2·3 + 2·2 + 3·2) = 32 quads on the box; 2 triangles per quad for the tets.
            let per_quad = if kind.face_count() == 6 { 1 } else { 2 };
            assert_eq!(faces.len(), 32 * per_quad, "{kind:?}");
            let mut total = [0.0; 3];
            let mut area = 0.0;
            for &(e, f) in &faces {
                let a = m.face_area_vector(e, f);
                let c = m.face_centroid(e, f);
                let centroid: [f64; 3] = std::array::from_fn(|i| {
                    m.elements[e]
                        .nodes()
                        .iter()
                        .map(|&n| m.nodes[n][i])
                        .sum::<f64>()
                        / m.elements[e].kind.node_count() as f64
                });
                assert!(dot(a, sub(c, centroid)) > 0.0, "{kind:?} face {f}");
                for i in 0..3 {
                    total[i] += a[i];
                }
                area += dot(a, a).sqrt();
            }
            assert!(total.iter().all(|v| v.abs() < 1e-12), "{total:?}");
            // 2 (2·3 + 2·1.5 + 3·1.5) = 27 mm².
            assert!((area - 27.0).abs() < 1e-12, "{kind:?}: {area}");
        }
    }

    /// Each internal face of every element points out of it too: for every element, its faces'
    /// outward area vectors close (sum to zero).
    #[test]
    fn every_element_is_closed_by_its_faces() {
        for kind in ElementKind3::ALL {
            let m = block([1.0, 1.0, 1.0], [1, 1, 1], kind);
            for (e, el) in m.elements.iter().enumerate() {
                let mut s = [0.0; 3];
                for f in 0..el.kind.face_count() {
                    let a = m.face_area_vector(e, f);
                    for i in 0..3 {
                        s[i] += a[i];
                    }
                }
                assert!(s.iter().all(|v| v.abs() < 1e-14), "{kind:?}: {s:?}");
            }
        }
    }

    #[test]
    fn inverted_and_flat_elements_are_named() {
        let mut m = block([1.0, 1.0, 1.0], [2, 1, 1], ElementKind3::C3d8);
        m.element_labels = vec![10, 20];
        let c = m.elements[1].conn;
        // Top and bottom swapped: inside out.
        m.elements[1].conn[..8].copy_from_slice(&[c[4], c[5], c[6], c[7], c[0], c[1], c[2], c[3]]);
        assert!(matches!(
            m.check_orientation(),
            Err(MeshError::InvertedSolid { label: 20, .. })
        ));
        // One corner pushed through the opposite face: only that corner's volume is negative.
        let mut m = block([1.0, 1.0, 1.0], [1, 1, 1], ElementKind3::C3d8);
        m.nodes[6] = [0.2, 0.2, -0.5];
        let err = m.check_orientation().unwrap_err();
        assert!(err.to_string().contains("element 1"), "{err}");
        // A flat tetrahedron.
        let mut m = block([1.0, 1.0, 1.0], [1, 1, 1], ElementKind3::C3d4);
        let t = m.elements[3].conn;
        m.nodes[t[3]] = m.nodes[t[0]];
        assert!(matches!(
            m.check_orientation(),
            Err(MeshError::InvertedSolid { label: 1, .. })
        ));
        m.elements[0].conn[2] = 99;
        assert!(matches!(
            m.check_orientation(),
            Err(MeshError::MissingNode { label: 1, node: 99 })
        ));
    }
}
