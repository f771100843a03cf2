//! Gmsh MSH 4.1 (ASCII) volume meshes: [`parse_msh3`] reads 8-node hexahedra (Gmsh type 5),
//! 4-node tetrahedra (4) and 10-node tetrahedra (11) into a [`Mesh3`] (C3D8, C3D4, C3D10; the
//! caller may switch hexahedra to C3D8H), with the file's nodes, sections and errors as the 2D
//! reader ([`super::parse_msh`]).
//!
//! - Node orders: Gmsh's hexahedron and 4-node tetrahedron are the Abaqus ones; its 10-node
//!   tetrahedron numbers the edges 0–1, 1–2, 2–0, 3–0, 3–2, 3–1, Abaqus 1–2, 2–3, 3–1, 1–4,
//!   2–4, 3–4, so the last two nodes swap (Gmsh reference manual, "Node ordering").
//!   An element whose corners turn the wrong way (negative volume) is mirrored (nodes 2 and 4
//!   of a tetrahedron, the two faces of a hexahedron swapped) as the 2D reader turns
//!   clockwise elements.
//! - Physical volumes become [`Mesh3::element_sets`]; physical surfaces become
//!   [`Mesh3::node_sets`] (the nodes of their triangles and quadrangles, types 2, 3 and 9) and
//!   [`Mesh3::surfaces`] (each surface element matched to the face of a volume element with the
//!   same corners); names from `$PhysicalNames`, else `volume_<tag>` / `surface_<tag>`.
//! - Nodes used by no volume element are dropped; lines and points are ignored.

use std::collections::{BTreeMap, HashMap};

use super::{Front, MshError, Reader, Result};
use crate::mesh::MeshError;
use crate::mesh3d::{Element3, ElementKind3, Mesh3};

/// Parses the text of a Gmsh MSH 4.1 ASCII volume mesh; `file_name` is used in messages.
pub fn parse_msh3(text: &str, file_name: &str) -> Result<Mesh3> {
    let reader = Reader {
        file: file_name,
        lines: text.lines().collect(),
    };
    read3(&reader)
}

/// Reads a Gmsh MSH 4.1 ASCII volume mesh ([`parse_msh3`]).
pub fn read_msh3(path: &std::path::Path) -> Result<Mesh3> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| MshError::Io {
        file: file.clone(),
        source,
    })?;
    parse_msh3(&String::from_utf8_lossy(&bytes), &file)
}

struct Raw {
    tag: i64,
    ty: i64,
    nodes: Vec<i64>,
    entity: i64,
    line: usize,
}

fn nodes_of_type(ty: i64) -> Option<usize> {
    match ty {
        1 => Some(2),
        2 => Some(3),
        3 => Some(4),
        4 => Some(4),
        5 => Some(8),
        8 => Some(3),
        9 => Some(6),
        11 => Some(10),
        15 => Some(1),
        _ => None,
    }
}

fn read3(r: &Reader) -> Result<Mesh3> {
    let Front {
        sections,
        names,
        physicals,
        node_tags,
        coords,
        node_of_tag,
    } = r.front()?;
    let Some(&(name, start, end)) = sections.iter().find(|s| s.0 == "Elements") else {
        return Err(r.file_err("no $Elements section"));
    };
    let mut t = r.tokens(name, start, end);
    let blocks = t.count("a number of element blocks")?;
    t.count("a number of elements")?;
    t.int("the minimum element tag")?;
    t.int("the maximum element tag")?;
    let mut volumes: Vec<Raw> = Vec::new();
    let mut faces: Vec<Raw> = Vec::new();
    for _ in 0..blocks {
        let (dim, _) = t.int("an entity dimension")?;
        let (entity, _) = t.int("an entity tag")?;
        let (ty, ty_line) = t.int("an element type")?;
        let n = t.count("a number of elements in the block")?;
        let nn = match (dim, nodes_of_type(ty)) {
            (3, Some(nn)) if matches!(ty, 4 | 5 | 11) => nn,
            (0..=2, Some(nn)) => nn,
            _ => {
                return Err(r.err(
                    ty_line,
                    format!(
                        "Gmsh element {} in an entity of dimension {dim} is not supported: femu reads 8-node hexahedra and 4- and 10-node tetrahedra",
                        super::gmsh_type_name(ty)
                    ),
                ))
            }
        };
        for _ in 0..n {
            let (tag, line) = t.int("an element tag")?;
            let nodes = (0..nn)
                .map(|_| t.int("a node tag").map(|v| v.0))
                .collect::<Result<Vec<i64>>>()?;
            let raw = Raw {
                tag,
                ty,
                nodes,
                entity,
                line,
            };
            match dim {
                3 => volumes.push(raw),
                2 => faces.push(raw),
                _ => {}
            }
        }
    }
    if volumes.is_empty() {
        return Err(r.file_err(
            "no hexahedra or tetrahedra: this is not a volume mesh (read 2D meshes with read_msh)",
        ));
    }
    let file_index = |el: &Raw, tag: i64| -> Result<usize> {
        node_of_tag.get(&tag).copied().ok_or_else(|| {
            r.err(
                el.line,
                format!(
                    "element {} refers to node {tag}, which is not in $Nodes",
                    el.tag
                ),
            )
        })
    };
    let mut used = vec![false; node_tags.len()];
    for el in &volumes {
        for &tag in &el.nodes {
            used[file_index(el, tag)?] = true;
        }
    }
    let mut mesh = Mesh3::default();
    let mut index = vec![usize::MAX; node_tags.len()];
    for (i, &(tag, line)) in node_tags.iter().enumerate() {
        if used[i] {
            for &v in &coords[i] {
                crate::mesh::check_coordinate(v).map_err(|m| r.err(line, m))?;
            }
            index[i] = mesh.nodes.len();
            mesh.nodes.push(coords[i]);
            mesh.node_labels.push(tag);
        }
    }
    let mut element_line: HashMap<i64, usize> = HashMap::new();
    for el in &volumes {
        let mut conn: Vec<usize> = el
            .nodes
            .iter()
            .map(|&tag| index[node_of_tag[&tag]])
            .collect();
        let kind = match el.ty {
            5 => ElementKind3::C3d8,
            4 => ElementKind3::C3d4,
            _ => {
                conn.swap(8, 9);
                ElementKind3::C3d10
            }
        };
        let mut element = Element3::new(kind, &conn);
        let x = |a: usize| mesh.nodes[element.conn[a]];
        let e = |a: usize, b: usize| std::array::from_fn::<f64, 3, _>(|i| x(b)[i] - x(a)[i]);
        // The corner volume at node 1 (for a hexahedron, of its edges to 2, 4 and 5).
        let (p, q, s) = match kind {
            ElementKind3::C3d8 => (e(0, 1), e(0, 3), e(0, 4)),
            _ => (e(0, 1), e(0, 2), e(0, 3)),
        };
        let det = p[0] * (q[1] * s[2] - q[2] * s[1]) - p[1] * (q[0] * s[2] - q[2] * s[0])
            + p[2] * (q[0] * s[1] - q[1] * s[0]);
        if det < 0.0 {
            let c = element.conn;
            match kind {
                ElementKind3::C3d8 => element.conn[..8]
                    .copy_from_slice(&[c[4], c[5], c[6], c[7], c[0], c[1], c[2], c[3]]),
                // Swap corners 2 and 3 (0-based 1, 2), with the mid-edge nodes that follow them:
                // 1–2 ↔ 3–1 (4, 6), 2–4 ↔ 3–4 (8, 9).
                _ => {
                    element.conn.swap(1, 2);
                    if kind == ElementKind3::C3d10 {
                        element.conn.swap(4, 6);
                        element.conn.swap(8, 9);
                    }
                }
            }
        }
        if element_line.insert(el.tag, el.line).is_some() {
            return Err(r.err(el.line, format!("element tag {} appears twice", el.tag)));
        }
        let i = mesh.add_element(element);
        mesh.element_labels[i] = el.tag;
        for &p in physicals
            .get(&(3, el.entity))
            .map_or(&[][..], Vec::as_slice)
        {
            let name = names
                .get(&(3, p))
                .cloned()
                .unwrap_or_else(|| format!("volume_{p}"));
            mesh.element_sets.entry(name).or_default().push(i);
        }
    }
    // Physical surfaces: node sets and element faces.
    let mut face_of: HashMap<Vec<usize>, (usize, usize)> = HashMap::new();
    for (e, el) in mesh.elements.iter().enumerate() {
        for f in 0..el.kind.face_count() {
            let mut key = el.face_nodes(f);
            key.truncate(if key.len() == 6 { 3 } else { key.len() });
            key.sort_unstable();
            face_of.insert(key, (e, f));
        }
    }
    let mut surfaces: BTreeMap<String, Vec<(usize, usize)>> = BTreeMap::new();
    for el in &faces {
        for &p in physicals
            .get(&(2, el.entity))
            .map_or(&[][..], Vec::as_slice)
        {
            let name = names
                .get(&(2, p))
                .cloned()
                .unwrap_or_else(|| format!("surface_{p}"));
            let corners = if el.ty == 9 { 3 } else { el.nodes.len() };
            let mut key = Vec::with_capacity(corners);
            for &tag in &el.nodes[..corners] {
                match node_of_tag.get(&tag).map(|&i| index[i]) {
                    Some(i) if i != usize::MAX => key.push(i),
                    _ => {
                        return Err(r.err(
                            el.line,
                            format!(
                                "physical surface '{name}': element {} has node {tag}, which belongs to no volume element",
                                el.tag
                            ),
                        ))
                    }
                }
            }
            let set = mesh.node_sets.entry(name.clone()).or_default();
            for &tag in &el.nodes {
                set.push(index[node_of_tag[&tag]]);
            }
            key.sort_unstable();
            match face_of.get(&key) {
                Some(&face) => surfaces.entry(name).or_default().push(face),
                None => {
                    return Err(r.err(
                        el.line,
                        format!(
                        "physical surface '{name}': element {} is not a face of a volume element",
                        el.tag
                    ),
                    ))
                }
            }
        }
    }
    for set in mesh.node_sets.values_mut() {
        set.sort_unstable();
        set.dedup();
    }
    mesh.surfaces = surfaces;
    mesh.check_orientation().map_err(|e| match &e {
        MeshError::InvertedSolid { label, .. } | MeshError::MissingNode { label, .. } => {
            match element_line.get(label) {
                Some(&line) => r.err(line, e.to_string()),
                None => r.file_err(e.to_string()),
            }
        }
        _ => r.file_err(e.to_string()),
    })?;
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hexahedron listed upside down (volume 1), a 10-node tetrahedron in Gmsh's order and a
    /// 4-node one on the same corners, in two physical volumes; a physical surface on x = 0.
    const FILE: &str = r#"$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
3
2 7 "LEFT"
3 1 "FAT"
3 2 "MUSCLE"
$EndPhysicalNames
$Entities
0 0 1 2
1 0 0 0 0 1 1 1 7 0
1 0 0 0 1 1 1 1 1 0
2 1 0 0 2 1 1 1 2 0
$EndEntities
$Nodes
1 15 1 15
3 1 0 15
1
2
3
4
5
6
7
8
9
10
11
12
13
14
15
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
1 0 1
1 1 1
0 1 1
2 0 0
1.5 0 0
1.5 0.5 0
1 0.5 0
1 0 0.5
1 0.5 0.5
1.5 0 0.5
$EndNodes
$Elements
4 4 1 4
2 1 3 1
1 1 5 8 4
3 1 5 1
2 5 6 7 8 1 2 3 4
3 2 11 1
3 2 9 3 6 10 11 12 13 14 15
3 2 4 1
4 2 9 3 6
$EndElements
"#;

    #[test]
    fn reads_hexahedra_tetrahedra_and_physical_groups() {
        let m = parse_msh3(FILE, "t.msh").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.elements.len(), 3);
        assert_eq!(m.element_labels, vec![2, 3, 4]);
        // The upside-down hexahedron is turned back: nodes 1..8 in order.
        assert_eq!(m.elements[0].kind, ElementKind3::C3d8);
        assert_eq!(m.elements[0].nodes(), &[0, 1, 2, 3, 4, 5, 6, 7]);
        assert!((m.element_volume(0) - 1.0).abs() < 1e-14);
        // Each mid-edge node of the C3D10 sits at the middle of its Abaqus edge.
        let t = &m.elements[1];
        assert_eq!(t.kind, ElementKind3::C3d10);
        for (k, [a, b]) in [[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]]
            .iter()
            .enumerate()
        {
            let (xa, xb, xm) = (
                m.nodes[t.conn[*a]],
                m.nodes[t.conn[*b]],
                m.nodes[t.conn[4 + k]],
            );
            for i in 0..3 {
                assert_eq!(xm[i], 0.5 * (xa[i] + xb[i]), "edge {k}");
            }
        }
        assert_eq!(m.elements[2].kind, ElementKind3::C3d4);
        assert_eq!(m.element_set("FAT"), Some(&[0][..]));
        assert_eq!(m.element_set("MUSCLE"), Some(&[1, 2][..]));
        // The x = 0 face of the hexahedron is its S6.
        assert_eq!(m.surface("LEFT"), Some(&[(0, 5)][..]));
        assert_eq!(m.node_set("LEFT"), Some(&[0, 3, 4, 7][..]));
        m.check_orientation().unwrap();
        // A 2D mesh is not a volume mesh.
        let flat = FILE.replace("3 1 5 1\n2 5 6 7 8 1 2 3 4\n3 2 11 1\n3 2 9 3 6 10 11 12 13 14 15\n3 2 4 1\n4 2 9 3 6\n", "")
            .replace("4 4 1 4", "1 1 1 1");
        let err = parse_msh3(&flat, "t.msh").unwrap_err().to_string();
        assert!(err.contains("not a volume mesh"), "{err}");
    }
}
