//! Splitting a conforming mesh along the interface between two regions, so that the regions can
//! slide on one another (a sliding interface of `femu_mech::interface`) instead of sharing
//! their nodes.
//!
//! The interface is the set of element edges with one element in each region. Every node on it
//! is duplicated, the copy going to the second region's elements, except the nodes where the
//! interface ends:
//!
//! - a node that also belongs to an element of a third region (a junction of three tissues),
//! - a node on the mesh's outer boundary (an edge with one element: the skin or the femur).
//!
//! Those stay shared by both regions: the interface is tied at its ends (the sliding surfaces
//! are pinned where they meet another tissue or the boundary, as a fascia pinned at a
//! junction), and the contact then acts between the duplicated nodes in between. The two
//! surfaces are returned as `(element, face)` lists ordered along their chains, with outward
//! normals; each side's faces follow its elements' counter-clockwise order, so the two sides
//! run in opposite directions.

use femu_mesh::Mesh;
use std::collections::{BTreeMap, BTreeSet};

/// Problems found while splitting an interface.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InterfaceSplitError {
    #[error("no element set named {0}")]
    NoRegion(String),
    #[error("regions {0} and {1} share no element edge")]
    NoInterface(String, String),
    #[error("an interface needs two different regions, got {0} twice")]
    SameRegion(String),
}

/// One side of a split interface.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InterfaceSide {
    /// The region (element-set name as given).
    pub region: String,
    /// Its faces on the interface, `(element, face)` with `face` 0-based as in
    /// [`femu_mesh::Element::face_nodes`], ordered along their chains (a face's second node is
    /// the next face's first, within a chain).
    pub faces: Vec<(usize, usize)>,
    /// Index in `faces` of the first face of each chain.
    pub chain_starts: Vec<usize>,
}

/// The result of [`split_interface`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SplitInterface {
    pub a: InterfaceSide,
    pub b: InterfaceSide,
    /// Each duplicated node: `(node of a, its copy in b)`.
    pub pairs: Vec<(usize, usize)>,
    /// The interface's nodes left shared (the ends: junctions with a third region and the
    /// outer boundary).
    pub tied: Vec<usize>,
}

/// Unit outward normal of each face of `faces` (counter-clockwise elements: the right of the
/// face's direction), in the reference configuration.
pub fn outward_normals(mesh: &Mesh, faces: &[(usize, usize)]) -> Vec<[f64; 2]> {
    faces
        .iter()
        .map(|&(e, f)| {
            let [a, b] = mesh.elements[e].face_nodes(f);
            let (xa, xb) = (mesh.nodes[a], mesh.nodes[b]);
            let l = [xb[0] - xa[0], xb[1] - xa[1]];
            let len = l[0].hypot(l[1]);
            [l[1] / len, -l[0] / len]
        })
        .collect()
}

/// Splits `mesh` along the interface between the element sets `a` and `b` (names compared
/// case-insensitively): see the module docs for which nodes are duplicated. A copy is added to
/// every node set that holds its original; element sets and `(element, face)` surfaces stay
/// valid (elements and faces keep their indices).
pub fn split_interface(
    mesh: &mut Mesh,
    a: &str,
    b: &str,
) -> Result<SplitInterface, InterfaceSplitError> {
    if a.eq_ignore_ascii_case(b) {
        return Err(InterfaceSplitError::SameRegion(a.to_string()));
    }
    let set = |name: &str| -> Result<BTreeSet<usize>, InterfaceSplitError> {
        mesh.element_set(name)
            .map(|s| s.iter().copied().collect())
            .ok_or_else(|| InterfaceSplitError::NoRegion(name.to_string()))
    };
    let (in_a, in_b) = (set(a)?, set(b)?);
    // Every edge and its (element, face) incidences.
    let mut edges: BTreeMap<(usize, usize), Vec<(usize, usize)>> = BTreeMap::new();
    for (e, el) in mesh.elements.iter().enumerate() {
        for f in 0..el.face_count() {
            let [p, q] = el.face_nodes(f);
            edges.entry((p.min(q), p.max(q))).or_default().push((e, f));
        }
    }
    let mut faces_a = Vec::new();
    let mut faces_b = Vec::new();
    let mut boundary_nodes = BTreeSet::new();
    for (&(p, q), inc) in &edges {
        match inc.as_slice() {
            [_] => {
                boundary_nodes.insert(p);
                boundary_nodes.insert(q);
            }
            [x, y] => {
                if in_a.contains(&x.0) && in_b.contains(&y.0) {
                    faces_a.push(*x);
                    faces_b.push(*y);
                } else if in_b.contains(&x.0) && in_a.contains(&y.0) {
                    faces_a.push(*y);
                    faces_b.push(*x);
                }
            }
            _ => {}
        }
    }
    if faces_a.is_empty() {
        return Err(InterfaceSplitError::NoInterface(
            a.to_string(),
            b.to_string(),
        ));
    }
    let interface_nodes: BTreeSet<usize> = faces_a
        .iter()
        .flat_map(|&(e, f)| mesh.elements[e].face_nodes(f))
        .collect();
    // Nodes touching an element of a third region.
    let mut third = BTreeSet::new();
    for (e, el) in mesh.elements.iter().enumerate() {
        if !in_a.contains(&e) && !in_b.contains(&e) {
            third.extend(el.nodes().iter().copied());
        }
    }
    let mut pairs = Vec::new();
    let mut tied = Vec::new();
    let mut copy_of = BTreeMap::new();
    let mut label = mesh.node_labels.iter().copied().max().unwrap_or(0);
    for &n in &interface_nodes {
        if third.contains(&n) || boundary_nodes.contains(&n) {
            tied.push(n);
            continue;
        }
        let x = mesh.nodes[n];
        let copy = mesh.nodes.len();
        mesh.nodes.push(x);
        label += 1;
        mesh.node_labels.push(label);
        copy_of.insert(n, copy);
        pairs.push((n, copy));
    }
    for &e in &in_b {
        let el = &mut mesh.elements[e];
        let count = el.kind.node_count();
        for node in el.conn[..count].iter_mut() {
            if let Some(&c) = copy_of.get(node) {
                *node = c;
            }
        }
    }
    for nodes in mesh.node_sets.values_mut() {
        let copies: Vec<usize> = nodes
            .iter()
            .filter_map(|n| copy_of.get(n).copied())
            .collect();
        nodes.extend(copies);
    }
    let side = |region: &str, faces: Vec<(usize, usize)>| {
        let (faces, chain_starts) = chain(mesh, faces);
        InterfaceSide {
            region: region.to_string(),
            faces,
            chain_starts,
        }
    };
    Ok(SplitInterface {
        a: side(a, faces_a),
        b: side(b, faces_b),
        pairs,
        tied,
    })
}

/// Orders `faces` along their chains (a face's second node is the next face's first): open
/// chains from their first face, then closed loops; returns the faces and each chain's start.
fn chain(mesh: &Mesh, faces: Vec<(usize, usize)>) -> (Vec<(usize, usize)>, Vec<usize>) {
    let ends: Vec<[usize; 2]> = faces
        .iter()
        .map(|&(e, f)| mesh.elements[e].face_nodes(f))
        .collect();
    let starting_at: BTreeMap<usize, usize> =
        ends.iter().enumerate().map(|(k, s)| (s[0], k)).collect();
    let has_previous: BTreeSet<usize> = ends
        .iter()
        .filter_map(|s| starting_at.get(&s[1]).copied())
        .collect();
    let mut done = vec![false; faces.len()];
    let mut ordered = Vec::with_capacity(faces.len());
    let mut starts = Vec::new();
    let firsts = (0..faces.len())
        .filter(|k| !has_previous.contains(k))
        .chain(0..faces.len());
    for first in firsts.collect::<Vec<_>>() {
        if done[first] {
            continue;
        }
        starts.push(ordered.len());
        let mut k = first;
        while !done[k] {
            done[k] = true;
            ordered.push(faces[k]);
            match starting_at.get(&ends[k][1]) {
                Some(&j) => k = j,
                None => break,
            }
        }
    }
    (ordered, starts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mesh::generate;
    use femu_mesh::ElementKind;

    /// A 4 x 4 square of quads: the lower two rows region `LOW`, the upper two `HIGH`, and the
    /// right column of the upper rows a third region `SIDE`.
    fn three_regions() -> Mesh {
        let mut g = generate::rectangle(4.0, 4.0, 4, 4, ElementKind::Cpe4).mesh;
        let (mut low, mut high, mut side) = (vec![], vec![], vec![]);
        for e in 0..16 {
            let (i, j) = (e % 4, e / 4);
            if j < 2 {
                low.push(e);
            } else if i == 3 {
                side.push(e);
            } else {
                high.push(e);
            }
        }
        g.element_sets.insert("LOW".into(), low);
        g.element_sets.insert("HIGH".into(), high);
        g.element_sets.insert("SIDE".into(), side);
        g
    }

    #[test]
    fn splits_the_shared_edge_and_ties_its_ends() {
        let mut mesh = three_regions();
        let before = mesh.nodes.len();
        let split = split_interface(&mut mesh, "LOW", "HIGH").unwrap();
        // The interface is y = 2 from x = 0 to 3: nodes at x = 0 (outer boundary) and x = 3
        // (junction with SIDE) stay shared, x = 1 and 2 are duplicated.
        let at = |n: usize| mesh.nodes[n];
        let tied: Vec<[f64; 2]> = split.tied.iter().map(|&n| at(n)).collect();
        assert_eq!(tied, vec![[0.0, 2.0], [3.0, 2.0]]);
        assert_eq!(split.pairs.len(), 2);
        assert_eq!(mesh.nodes.len(), before + 2);
        for &(n, c) in &split.pairs {
            assert_eq!(at(n), at(c));
            assert!(at(n)[1] == 2.0 && (at(n)[0] == 1.0 || at(n)[0] == 2.0));
            // The copy is used by HIGH's elements only, the original by LOW's only.
            for (e, el) in mesh.elements.iter().enumerate() {
                let high = mesh.element_sets["HIGH"].contains(&e);
                assert!(!el.nodes().contains(&c) || high);
                assert!(!el.nodes().contains(&n) || !high);
            }
            // Node sets holding the original hold the copy.
            assert!(mesh.node_sets["ALL"].contains(&c));
        }
        assert_eq!(split.a.faces.len(), 3);
        assert_eq!(split.b.faces.len(), 3);
        assert_eq!(split.a.chain_starts, vec![0]);
        // Ordered chains running in opposite directions, normals facing each other.
        for side in [&split.a, &split.b] {
            for w in side.faces.windows(2) {
                let p = mesh.elements[w[0].0].face_nodes(w[0].1);
                let q = mesh.elements[w[1].0].face_nodes(w[1].1);
                assert_eq!(at(p[1]), at(q[0]));
            }
        }
        for n in outward_normals(&mesh, &split.a.faces) {
            assert_eq!(n, [0.0, 1.0]);
        }
        for n in outward_normals(&mesh, &split.b.faces) {
            assert_eq!(n, [0.0, -1.0]);
        }
    }

    /// The built-in thigh split between the quadriceps and the hamstrings (ISCHIO): the copies
    /// sit on their originals, each side's faces form chains whose normals face the other
    /// side's, the ends are tied, and the regions' areas and the other regions are unchanged.
    #[test]
    fn splits_the_built_in_thigh_between_quadriceps_and_ischio() {
        let thigh =
            crate::parametric_thigh(&crate::ThighParams::coarse(), ElementKind::Cpe4).unwrap();
        let mut mesh = thigh.mesh.mesh.clone();
        let split = split_interface(&mut mesh, "QUADRICEPS", "ISCHIO").unwrap();
        let (na, nb) = (split.a.faces.len(), split.b.faces.len());
        println!(
            "QUADRICEPS-ISCHIO: {na} faces per side in {} chain(s), {} nodes duplicated, {} tied",
            split.a.chain_starts.len(),
            split.pairs.len(),
            split.tied.len()
        );
        assert_eq!(na, nb);
        assert!(na >= 5, "{na} faces");
        assert_eq!(
            split.pairs.len() + split.tied.len(),
            na + split.a.chain_starts.len()
        );
        assert!(!split.tied.is_empty());
        for &(n, c) in &split.pairs {
            assert_eq!(mesh.nodes[n], mesh.nodes[c]);
        }
        // Each face of a has a face of b on the same two positions, with the opposite normal.
        let na_ = outward_normals(&mesh, &split.a.faces);
        let nb_ = outward_normals(&mesh, &split.b.faces);
        for (fa, n) in split.a.faces.iter().zip(&na_) {
            let [p, q] = mesh.elements[fa.0].face_nodes(fa.1);
            let k = split
                .b
                .faces
                .iter()
                .position(|fb| {
                    let [r, s] = mesh.elements[fb.0].face_nodes(fb.1);
                    mesh.nodes[r] == mesh.nodes[q] && mesh.nodes[s] == mesh.nodes[p]
                })
                .expect("a matching face on the other side");
            assert!((n[0] + nb_[k][0]).abs() < 1e-12 && (n[1] + nb_[k][1]).abs() < 1e-12);
        }
        // No element uses both a node and its copy; the other regions keep their nodes.
        for el in &mesh.elements {
            for &(n, c) in &split.pairs {
                assert!(!(el.nodes().contains(&n) && el.nodes().contains(&c)));
            }
        }
        for (e, el) in mesh.elements.iter().enumerate() {
            assert!(
                el.nodes().iter().all(|&n| n < thigh.mesh.mesh.nodes.len())
                    || mesh.element_sets["ISCHIO"].contains(&e)
            );
        }
    }

    #[test]
    fn errors_name_the_problem() {
        let mut mesh = three_regions();
        mesh.element_sets.insert("TOP_ROW".into(), vec![12, 13, 14]);
        assert_eq!(
            split_interface(&mut mesh, "LOW", "NONE"),
            Err(InterfaceSplitError::NoRegion("NONE".into()))
        );
        assert_eq!(
            split_interface(&mut mesh, "LOW", "low"),
            Err(InterfaceSplitError::SameRegion("LOW".into()))
        );
        assert_eq!(
            split_interface(&mut mesh, "LOW", "TOP_ROW"),
            Err(InterfaceSplitError::NoInterface(
                "LOW".into(),
                "TOP_ROW".into()
            ))
        );
    }
}
