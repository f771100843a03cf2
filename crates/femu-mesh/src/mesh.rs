//! The mesh model: nodes, elements, named element sets (tissue regions) and node sets.

use std::collections::BTreeMap;

/// Element formulation, named as in Abaqus/CalculiX decks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ElementKind {
    /// 4-node plane-strain quadrilateral, full 2x2 Gauss integration.
    Cpe4,
    /// 4-node plane-strain quadrilateral, hybrid with constant pressure (mean dilatation).
    Cpe4h,
    /// 3-node plane-strain triangle, one integration point.
    Cpe3,
}

impl ElementKind {
    /// Number of nodes of the element.
    pub fn node_count(self) -> usize {
        match self {
            ElementKind::Cpe4 | ElementKind::Cpe4h => 4,
            ElementKind::Cpe3 => 3,
        }
    }

    /// The deck name of the element type (`CPE4`, `CPE4H`, `CPE3`).
    pub fn deck_name(self) -> &'static str {
        match self {
            ElementKind::Cpe4 => "CPE4",
            ElementKind::Cpe4h => "CPE4H",
            ElementKind::Cpe3 => "CPE3",
        }
    }

    /// Parses a deck element type name (case-insensitive).
    pub fn from_deck_name(name: &str) -> Option<Self> {
        match name.trim().to_ascii_uppercase().as_str() {
            "CPE4" => Some(ElementKind::Cpe4),
            "CPE4H" => Some(ElementKind::Cpe4h),
            "CPE3" => Some(ElementKind::Cpe3),
            _ => None,
        }
    }

    /// VTK cell type (9 = VTK_QUAD, 5 = VTK_TRIANGLE).
    pub fn vtk_cell_type(self) -> u8 {
        match self {
            ElementKind::Cpe4 | ElementKind::Cpe4h => 9,
            ElementKind::Cpe3 => 5,
        }
    }
}

/// One element: its formulation and its node indices (0-based indices into [`Mesh::nodes`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Element {
    pub kind: ElementKind,
    /// Node indices; only the first `kind.node_count()` entries are used.
    pub conn: [usize; 4],
}

impl Element {
    /// A quadrilateral of the given kind.
    pub fn quad(kind: ElementKind, conn: [usize; 4]) -> Self {
        debug_assert_eq!(kind.node_count(), 4);
        Element { kind, conn }
    }

    /// A CPE3 triangle.
    pub fn tri(conn: [usize; 3]) -> Self {
        Element {
            kind: ElementKind::Cpe3,
            conn: [conn[0], conn[1], conn[2], usize::MAX],
        }
    }

    /// The node indices of the element.
    pub fn nodes(&self) -> &[usize] {
        &self.conn[..self.kind.node_count()]
    }

    /// Number of faces (edges) of the element.
    pub fn face_count(&self) -> usize {
        self.kind.node_count()
    }

    /// The two node indices of face `face` (0-based: face 0 is the deck's `P1`, joining local
    /// nodes 1 and 2).
    pub fn face_nodes(&self, face: usize) -> [usize; 2] {
        let n = self.kind.node_count();
        [self.conn[face % n], self.conn[(face + 1) % n]]
    }
}

/// Errors found while checking or building a mesh.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    #[error("element {label}: node index {node} does not exist")]
    MissingNode { label: i64, node: usize },
    #[error("element {label} is inverted or degenerate (signed area {area:.3e} mm^2 at its corner {corner})")]
    Inverted {
        label: i64,
        area: f64,
        corner: usize,
    },
    /// A 3D element with a non-positive corner volume (see `Mesh3::check_orientation`).
    #[error("element {label} is inverted or degenerate (signed volume {volume:.3e} mm^3 at its corner {corner})")]
    InvertedSolid {
        label: i64,
        volume: f64,
        corner: usize,
    },
    #[error("element set '{0}' is not defined")]
    UnknownElementSet(String),
    #[error("node set '{0}' is not defined")]
    UnknownNodeSet(String),
}

/// The largest node coordinate a model may have (mm): 1 km. A thigh is about 150 mm across; a
/// coordinate beyond this is a unit or export mistake, and near `f64::MAX` (1e308) areas and
/// stiffnesses overflow to infinity, so that a solve would "converge" at zero displacement.
pub const MAX_COORDINATE_MM: f64 = 1e6;

/// Checks a node coordinate against [`MAX_COORDINATE_MM`]; the error says what is valid.
pub fn check_coordinate(v: f64) -> Result<(), String> {
    if v.abs() <= MAX_COORDINATE_MM {
        Ok(())
    } else {
        Err(format!(
            "coordinate {v:e} is beyond ±{MAX_COORDINATE_MM:e} mm (femu reads mm; a thigh is about 150 mm across)"
        ))
    }
}

/// A 2D mesh: nodes (mm), elements, named element sets and node sets.
///
/// Deck labels are kept so that outputs use the user's own numbering.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    /// Reference coordinates (mm).
    pub nodes: Vec<[f64; 2]>,
    /// The deck label of each node (same length as `nodes`).
    pub node_labels: Vec<i64>,
    pub elements: Vec<Element>,
    /// The deck label of each element (same length as `elements`).
    pub element_labels: Vec<i64>,
    /// Named element sets (e.g. tissue regions), as element indices.
    pub element_sets: BTreeMap<String, Vec<usize>>,
    /// Named node sets (e.g. the femur edge), as node indices.
    pub node_sets: BTreeMap<String, Vec<usize>>,
}

impl Mesh {
    /// Adds a node with label `index + 1` and returns its index.
    pub fn add_node(&mut self, x: [f64; 2]) -> usize {
        self.nodes.push(x);
        self.node_labels.push(self.nodes.len() as i64);
        self.nodes.len() - 1
    }

    /// Adds an element with label `index + 1` and returns its index.
    pub fn add_element(&mut self, e: Element) -> usize {
        self.elements.push(e);
        self.element_labels.push(self.elements.len() as i64);
        self.elements.len() - 1
    }

    /// The reference coordinates of the nodes of element `e`.
    pub fn element_coords(&self, e: usize) -> ([[f64; 2]; 4], usize) {
        let el = &self.elements[e];
        let mut x = [[0.0; 2]; 4];
        for (k, &n) in el.nodes().iter().enumerate() {
            x[k] = self.nodes[n];
        }
        (x, el.kind.node_count())
    }

    /// Signed area of the corner triangle of element `e` at each corner; all must be positive for a
    /// valid counter-clockwise element. Returns an error naming the element otherwise.
    pub fn check_orientation(&self) -> Result<(), MeshError> {
        for (e, el) in self.elements.iter().enumerate() {
            let n = el.kind.node_count();
            for &node in el.nodes() {
                if node >= self.nodes.len() {
                    return Err(MeshError::MissingNode {
                        label: self.element_labels[e],
                        node,
                    });
                }
            }
            for c in 0..n {
                let p = self.nodes[el.conn[(c + n - 1) % n]];
                let q = self.nodes[el.conn[c]];
                let r = self.nodes[el.conn[(c + 1) % n]];
                let area = 0.5 * ((r[0] - q[0]) * (p[1] - q[1]) - (r[1] - q[1]) * (p[0] - q[0]));
                if area.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return Err(MeshError::Inverted {
                        label: self.element_labels[e],
                        area,
                        corner: c + 1,
                    });
                }
            }
        }
        Ok(())
    }

    /// Boundary faces: `(element, face)` pairs whose edge belongs to one element only.
    pub fn boundary_faces(&self) -> Vec<(usize, usize)> {
        let mut count: BTreeMap<(usize, usize), (usize, usize, usize)> = BTreeMap::new();
        for (e, el) in self.elements.iter().enumerate() {
            for f in 0..el.face_count() {
                let [a, b] = el.face_nodes(f);
                let key = (a.min(b), a.max(b));
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

    /// Finds the `(element, face)` whose edge joins nodes `a` and `b` (in either order).
    pub fn find_face(&self, a: usize, b: usize) -> Option<(usize, usize)> {
        self.elements.iter().enumerate().find_map(|(e, el)| {
            (0..el.face_count()).find_map(|f| {
                let [p, q] = el.face_nodes(f);
                ((p == a && q == b) || (p == b && q == a)).then_some((e, f))
            })
        })
    }

    /// Axis-aligned bounding box `([xmin, ymin], [xmax, ymax])` of the nodes.
    pub fn bounding_box(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in &self.nodes {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// The node set `name`, compared case-insensitively as set names are in Abaqus decks (the
    /// deck reader keys sets by the spelling of their first definition).
    pub fn node_set(&self, name: &str) -> Option<&[usize]> {
        find_set(&self.node_sets, name)
    }

    /// The element set `name`, compared case-insensitively (see [`Mesh::node_set`]).
    pub fn element_set(&self, name: &str) -> Option<&[usize]> {
        find_set(&self.element_sets, name)
    }

    /// Index of the node with deck label `label`.
    pub fn node_index(&self, label: i64) -> Option<usize> {
        self.node_labels.iter().position(|&l| l == label)
    }
}

fn find_set<'a>(sets: &'a BTreeMap<String, Vec<usize>>, name: &str) -> Option<&'a [usize]> {
    sets.get(name)
        .or_else(|| {
            sets.iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(name))
                .map(|(_, v)| v)
        })
        .map(Vec::as_slice)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_square() -> Mesh {
        let mut m = Mesh::default();
        for p in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
            m.add_node(p);
        }
        m.add_element(Element::quad(ElementKind::Cpe4, [0, 1, 2, 3]));
        m
    }

    #[test]
    fn orientation_and_faces() {
        let mut m = unit_square();
        assert!(m.check_orientation().is_ok());
        assert_eq!(m.boundary_faces().len(), 4);
        assert_eq!(m.find_face(3, 0), Some((0, 3)));
        m.node_sets.insert("Femur".into(), vec![0, 1]);
        assert_eq!(m.node_set("FEMUR"), Some(&[0, 1][..]));
        assert_eq!(m.element_set("femur"), None);
        m.elements[0].conn = [0, 3, 2, 1];
        assert!(matches!(
            m.check_orientation(),
            Err(MeshError::Inverted { label: 1, .. })
        ));
    }
}
