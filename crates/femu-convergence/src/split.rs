//! A deck refined by splitting its elements: the refined meshes of a deck (an Abaqus/CalculiX
//! input from another mesher), whose geometry femu cannot mesh again; the study's
//! discretization check of a deck uses them. The split meshes converge to the solution on the
//! deck's own (smoothed) geometry, not on the geometry between its nodes, which the deck does
//! not record: on cross-mesh cases of the built-in thigh under contention C10 differs by some
//! 40 % between that geometry and the traced one meshed again (the contention field is nearly
//! hydrostatic, the C10 carry about 1.4 % of it, and the coarse deck cuts the thin sartorius'
//! tips, 2 % of its area), so a check on the splits alone estimates a third to a half of a
//! coarse deck's shift there (`femu-identify/examples/deck_check.rs` measures both).
//!
//! Each quadrilateral becomes four (new nodes at its edges' midpoints and at its centre), each
//! triangle four (at its edges' midpoints): the element size halves. Splitting along straight
//! edges would keep the coarse deck's polygonal outline, and the refined meshes would then
//! converge to the polygon's solution, not the thigh's: the check would miss the part of the
//! mesh's error that is its geometry. So the midpoints of the edges on a curve — the outline
//! (edges of one element) and the interfaces between regions (edges whose two elements lie in
//! different regions) — are placed on a smooth curve through the deck's nodes of that curve,
//! by the four-point interpolatory subdivision rule (Dubuc; Deslauriers and Dubuc, *Constr.
//! Approx.* 5, 1989): `m = (9 (a + b) − (p + q)) / 16` for the edge `a b` between its curve
//! neighbours `p` and `q`, exact for cubics, so a circle sampled every `h` is met to `O(h⁴)`
//! where the straight midpoint is off by `h² / 8R`. At a curve's end, a junction of three
//! curves or a corner (a turn of more than [`CORNER_DEG`]) the rule takes the three points on
//! one side (exact for parabolas), or the straight midpoint when neither side continues. A
//! quadrilateral's centre is placed by the serendipity blend of its edge midpoints and
//! corners (`c = Σ m / 2 − Σ n / 4`), the centre of its bilinear image for straight edges.
//!
//! Everything a deck says of its nodes and elements follows: regions, materials and element
//! sets to the children; node sets and prescribed displacements to a new edge node when both
//! ends of its edge have them (the mean of the two values), to a centre when all four corners
//! do; pressures to both halves of a loaded face; point loads stay on their nodes.

use std::collections::BTreeMap;

use femu_mesh::deck::{BoundaryCondition, FacePressure};
use femu_mesh::{Deck, Element, ElementKind, Mesh, MeshError};

/// A turn of the outline or of an interface sharper than this (degrees) is a corner: the
/// smooth curve is not continued through it.
pub const CORNER_DEG: f64 = 35.0;

/// Why a deck cannot be split.
#[derive(Debug, thiserror::Error)]
pub enum SplitError {
    /// A child element came out inverted (a curve bent more than the element is deep).
    #[error("splitting the deck's element {label} along its curved outline inverts it; refine that part of the deck in its mesher")]
    Inverted { label: i64 },
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

/// The edges of a mesh: for each edge `(min node, max node)`, its elements and faces.
type Edges = BTreeMap<(usize, usize), Vec<(usize, usize)>>;

fn edges(mesh: &Mesh) -> Edges {
    let mut edges: Edges = BTreeMap::new();
    for (e, el) in mesh.elements.iter().enumerate() {
        for f in 0..el.face_count() {
            let [a, b] = el.face_nodes(f);
            edges.entry((a.min(b), a.max(b))).or_default().push((e, f));
        }
    }
    edges
}

/// The curve an edge lies on: the outline (`(usize::MAX, usize::MAX)`, whatever region is
/// inside it), the interface of two regions (`(lower, higher)`), or none (an edge inside one
/// region).
fn curve_of(owners: &[(usize, usize)], region: &[usize]) -> Option<(usize, usize)> {
    match owners {
        [_] => Some((usize::MAX, usize::MAX)),
        [(e, _), (g, _)] if region[*e] != region[*g] => {
            let (r, s) = (region[*e], region[*g]);
            Some((r.min(s), r.max(s)))
        }
        _ => None,
    }
}

/// The positions of the new edge nodes (module documentation), in the order of `edges`.
fn edge_midpoints(mesh: &Mesh, edges: &Edges, region: &[usize]) -> Vec<[f64; 2]> {
    // Each node's neighbours along each curve through it.
    let mut along: BTreeMap<(usize, (usize, usize)), Vec<usize>> = BTreeMap::new();
    for (&(a, b), owners) in edges {
        if let Some(c) = curve_of(owners, region) {
            along.entry((a, c)).or_default().push(b);
            along.entry((b, c)).or_default().push(a);
        }
    }
    let x = &mesh.nodes;
    let cos_corner = CORNER_DEG.to_radians().cos();
    // The neighbour of `a` on curve `c` beyond `a` from `b`, if the curve runs on smoothly.
    let beyond = |a: usize, b: usize, c: (usize, usize)| -> Option<usize> {
        let n = along.get(&(a, c))?;
        if n.len() != 2 {
            return None;
        }
        let p = if n[0] == b { n[1] } else { n[0] };
        let (u, v) = (sub(x[a], x[p]), sub(x[b], x[a]));
        let cos = dot(u, v) / (norm(u) * norm(v));
        (cos >= cos_corner).then_some(p)
    };
    edges
        .iter()
        .map(|(&(a, b), owners)| {
            let (xa, xb) = (x[a], x[b]);
            let Some(c) = curve_of(owners, region) else {
                return lerp(&[(xa, 0.5), (xb, 0.5)]);
            };
            match (beyond(a, b, c), beyond(b, a, c)) {
                (Some(p), Some(q)) => lerp(&[
                    (x[p], -1.0 / 16.0),
                    (xa, 9.0 / 16.0),
                    (xb, 9.0 / 16.0),
                    (x[q], -1.0 / 16.0),
                ]),
                (Some(p), None) => lerp(&[(x[p], -1.0 / 8.0), (xa, 0.75), (xb, 0.375)]),
                (None, Some(q)) => lerp(&[(xa, 0.375), (xb, 0.75), (x[q], -1.0 / 8.0)]),
                (None, None) => lerp(&[(xa, 0.5), (xb, 0.5)]),
            }
        })
        .collect()
}

/// Where a split puts the new nodes of the outline and the interfaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Curves {
    /// On smooth curves through the deck's nodes (module documentation).
    Smooth,
    /// At the straight midpoints: the deck's polygons kept.
    Straight,
}

/// `deck` with every element split in four (module documentation): the element size halved.
pub fn split_deck(deck: &Deck) -> Result<Deck, SplitError> {
    split_deck_with(deck, Curves::Smooth)
}

/// [`split_deck`] with the curves placed as `curves` says.
pub fn split_deck_with(deck: &Deck, curves: Curves) -> Result<Deck, SplitError> {
    let mesh = &deck.mesh;
    let edges = edges(mesh);
    let n0 = mesh.nodes.len();
    let edge_node: BTreeMap<(usize, usize), usize> = edges
        .keys()
        .enumerate()
        .map(|(k, &key)| (key, n0 + k))
        .collect();
    let mut nodes = mesh.nodes.clone();
    match curves {
        Curves::Smooth => nodes.extend(edge_midpoints(mesh, &edges, &deck.element_region)),
        Curves::Straight => nodes.extend(
            edges
                .keys()
                .map(|&(a, b)| lerp(&[(mesh.nodes[a], 0.5), (mesh.nodes[b], 0.5)])),
        ),
    }
    let mid = |a: usize, b: usize| edge_node[&(a.min(b), a.max(b))];

    let mut elements = Vec::with_capacity(4 * mesh.elements.len());
    let mut parent = Vec::with_capacity(4 * mesh.elements.len());
    let mut centre_of: Vec<Option<usize>> = vec![None; mesh.elements.len()];
    for (e, el) in mesh.elements.iter().enumerate() {
        let n = el.kind.node_count();
        let c = &el.conn;
        let m: Vec<usize> = (0..n).map(|f| mid(c[f], c[(f + 1) % n])).collect();
        // Children in the order of the parent's corners: child `f` holds corner `f`; a parent
        // face `f` (corner f → f+1) is face `f` of children `f` and `f + 1`.
        match el.kind {
            ElementKind::Cpe3 => {
                for conn in [
                    [c[0], m[0], m[2]],
                    [m[0], c[1], m[1]],
                    [m[2], m[1], c[2]],
                    [m[0], m[1], m[2]],
                ] {
                    elements.push(Element {
                        kind: el.kind,
                        conn: [conn[0], conn[1], conn[2], 0],
                    });
                    parent.push(e);
                }
            }
            ElementKind::Cpe4 | ElementKind::Cpe4h => {
                let centre = lerp(&[
                    (nodes[m[0]], 0.5),
                    (nodes[m[1]], 0.5),
                    (nodes[m[2]], 0.5),
                    (nodes[m[3]], 0.5),
                    (nodes[c[0]], -0.25),
                    (nodes[c[1]], -0.25),
                    (nodes[c[2]], -0.25),
                    (nodes[c[3]], -0.25),
                ]);
                nodes.push(centre);
                let z = nodes.len() - 1;
                centre_of[e] = Some(z);
                for conn in [
                    [c[0], m[0], z, m[3]],
                    [m[0], c[1], m[1], z],
                    [z, m[1], c[2], m[2]],
                    [m[3], z, m[2], c[3]],
                ] {
                    elements.push(Element::quad(el.kind, conn));
                    parent.push(e);
                }
            }
        }
    }

    // Node labels: the deck's own, then new ones above them.
    let top = mesh.node_labels.iter().copied().max().unwrap_or(0);
    let node_labels: Vec<i64> = mesh
        .node_labels
        .iter()
        .copied()
        .chain((1..).map(|k| top + k).take(nodes.len() - n0))
        .collect();
    let children = |e: usize| 4 * e..4 * e + 4;
    let element_sets = mesh
        .element_sets
        .iter()
        .map(|(name, set)| {
            (
                name.clone(),
                set.iter().flat_map(|&e| children(e)).collect(),
            )
        })
        .collect();
    // A new node belongs to what both ends of its edge (all corners of its quad) belong to.
    let inherits = |has: &dyn Fn(usize) -> bool| -> Vec<usize> {
        let mut new = Vec::new();
        for (&(a, b), &k) in &edge_node {
            if has(a) && has(b) {
                new.push(k);
            }
        }
        for (e, z) in centre_of.iter().enumerate() {
            if let Some(z) = z {
                if mesh.elements[e].nodes().iter().all(|&n| has(n)) {
                    new.push(*z);
                }
            }
        }
        new
    };
    let node_sets = mesh
        .node_sets
        .iter()
        .map(|(name, set)| {
            let mut member = vec![false; n0];
            for &n in set {
                member[n] = true;
            }
            let mut all = set.clone();
            all.extend(inherits(&|n| member[n]));
            (name.clone(), all)
        })
        .collect();
    let boundaries = split_boundaries(deck, &edge_node, &centre_of);
    let pressures = deck
        .pressures
        .iter()
        .flat_map(|p| {
            let n = mesh.elements[p.element].kind.node_count();
            [p.face, (p.face + 1) % n].map(|child| FacePressure {
                element: 4 * p.element + child,
                face: p.face,
                magnitude: p.magnitude,
            })
        })
        .collect();
    let refined = Mesh {
        nodes,
        node_labels,
        element_labels: (1..=elements.len() as i64).collect(),
        elements,
        element_sets,
        node_sets,
    };
    match refined.check_orientation() {
        Err(MeshError::Inverted { label, .. }) => {
            return Err(SplitError::Inverted {
                label: mesh.element_labels[parent[(label - 1) as usize]],
            })
        }
        other => other?,
    }
    Ok(Deck {
        mesh: refined,
        materials: deck.materials.clone(),
        element_material: parent.iter().map(|&e| deck.element_material[e]).collect(),
        element_region: parent.iter().map(|&e| deck.element_region[e]).collect(),
        region_names: deck.region_names.clone(),
        step: deck.step,
        boundaries,
        pressures,
        point_loads: deck.point_loads.clone(),
    })
}

/// The prescribed displacements of the split deck: the deck's, and a new node's dof where both
/// ends of its edge (all corners of its quad) have that dof prescribed, at their mean value.
fn split_boundaries(
    deck: &Deck,
    edge_node: &BTreeMap<(usize, usize), usize>,
    centre_of: &[Option<usize>],
) -> Vec<BoundaryCondition> {
    let mut value: BTreeMap<(usize, usize), f64> = BTreeMap::new();
    for b in &deck.boundaries {
        value.insert((b.node, b.dof), b.value);
    }
    let mut out = deck.boundaries.clone();
    for dof in 0..2 {
        for (&(a, b), &k) in edge_node {
            if let (Some(va), Some(vb)) = (value.get(&(a, dof)), value.get(&(b, dof))) {
                out.push(BoundaryCondition {
                    node: k,
                    dof,
                    value: 0.5 * (va + vb),
                });
            }
        }
        for (e, z) in centre_of.iter().enumerate() {
            let Some(z) = z else { continue };
            let v: Option<Vec<f64>> = deck.mesh.elements[e]
                .nodes()
                .iter()
                .map(|&n| value.get(&(n, dof)).copied())
                .collect();
            if let Some(v) = v {
                out.push(BoundaryCondition {
                    node: *z,
                    dof,
                    value: v.iter().sum::<f64>() / v.len() as f64,
                });
            }
        }
    }
    out
}

/// `deck` split `times` times: element size divided by `2^times`.
pub fn split_deck_times(deck: &Deck, times: usize) -> Result<Deck, SplitError> {
    let mut d = deck.clone();
    for _ in 0..times {
        d = split_deck(&d)?;
    }
    Ok(d)
}

fn lerp(terms: &[([f64; 2], f64)]) -> [f64; 2] {
    terms.iter().fold([0.0; 2], |acc, (x, w)| {
        [acc[0] + w * x[0], acc[1] + w * x[1]]
    })
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn norm(a: [f64; 2]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mesh::deck::{MaterialDef, StepDef};

    /// A deck of `mesh` with one region and material, nothing prescribed.
    fn deck_of(mesh: Mesh, regions: Vec<usize>) -> Deck {
        let n = mesh.elements.len();
        let names = (0..=regions.iter().copied().max().unwrap_or(0))
            .map(|r| format!("R{r}"))
            .collect();
        Deck {
            mesh,
            materials: vec![MaterialDef {
                name: "M".into(),
                keyword: "NEO HOOKE".into(),
                constants: vec![0.001, 10.0],
                line: None,
            }],
            element_material: vec![0; n],
            element_region: regions,
            region_names: names,
            step: StepDef::default(),
            boundaries: Vec::new(),
            pressures: Vec::new(),
            point_loads: Vec::new(),
        }
    }

    /// `nx` x `ny` unit quads over [0, nx] x [0, ny].
    fn grid(nx: usize, ny: usize) -> Mesh {
        let mut m = Mesh::default();
        for j in 0..=ny {
            for i in 0..=nx {
                m.add_node([i as f64, j as f64]);
            }
        }
        let id = |i: usize, j: usize| j * (nx + 1) + i;
        for j in 0..ny {
            for i in 0..nx {
                m.add_element(Element::quad(
                    ElementKind::Cpe4h,
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                ));
            }
        }
        m
    }

    fn area(mesh: &Mesh) -> f64 {
        mesh.elements
            .iter()
            .map(|el| {
                let p: Vec<[f64; 2]> = el.nodes().iter().map(|&n| mesh.nodes[n]).collect();
                0.5 * (0..p.len())
                    .map(|k| {
                        let (a, b) = (p[k], p[(k + 1) % p.len()]);
                        a[0] * b[1] - b[0] * a[1]
                    })
                    .sum::<f64>()
            })
            .sum()
    }

    #[test]
    fn a_straight_grid_splits_into_the_grid_of_half_the_size() {
        let mut mesh = grid(2, 2);
        mesh.node_sets.insert("LEFT".into(), vec![0, 3, 6]);
        mesh.element_sets.insert("E".into(), vec![3]);
        let mut deck = deck_of(mesh, vec![0, 0, 1, 1]);
        for n in [0, 3, 6] {
            deck.boundaries.push(BoundaryCondition {
                node: n,
                dof: 0,
                value: if n == 6 { 1.0 } else { 0.0 },
            });
        }
        // The top edge loaded: faces 2 of elements 2 and 3.
        for e in [2, 3] {
            deck.pressures.push(FacePressure {
                element: e,
                face: 2,
                magnitude: 0.5,
            });
        }
        let s = split_deck(&deck).unwrap();
        assert_eq!(s.mesh.elements.len(), 16);
        assert_eq!(s.mesh.nodes.len(), 25);
        // Straight outline and interface: every new node on the 0.5 lattice, area kept.
        for x in &s.mesh.nodes {
            for c in x {
                assert!((2.0 * c - (2.0 * c).round()).abs() < 1e-12, "{x:?}");
            }
        }
        assert!((area(&s.mesh) - 4.0).abs() < 1e-12);
        // The left edge: 5 nodes, the new ones at the mean of their ends' values.
        let left: Vec<[f64; 2]> = s.mesh.node_sets["LEFT"]
            .iter()
            .map(|&n| s.mesh.nodes[n])
            .collect();
        assert_eq!(left.len(), 5);
        assert!(left.iter().all(|x| x[0] == 0.0));
        let bc: BTreeMap<usize, f64> = s.boundaries.iter().map(|b| (b.node, b.value)).collect();
        assert_eq!(bc.len(), 5);
        for (&n, &v) in &bc {
            let y = s.mesh.nodes[n][1];
            let expected = if y <= 1.0 { 0.0 } else { y - 1.0 };
            assert!((v - expected).abs() < 1e-12, "node at y = {y}: {v}");
        }
        // The loaded faces: four halves along y = 2.
        assert_eq!(s.pressures.len(), 4);
        for p in &s.pressures {
            let [a, b] = s.mesh.elements[p.element].face_nodes(p.face);
            assert_eq!(s.mesh.nodes[a][1], 2.0);
            assert_eq!(s.mesh.nodes[b][1], 2.0);
            assert!((s.mesh.nodes[a][0] - s.mesh.nodes[b][0]).abs() == 0.5);
        }
        // Regions, materials and element sets follow.
        assert_eq!(s.element_region.iter().filter(|&&r| r == 1).count(), 8);
        assert_eq!(s.mesh.element_sets["E"], vec![12, 13, 14, 15]);
        s.mesh.check_orientation().unwrap();
    }

    /// A ring of `n` quads between radii 1 and 2 (one layer), inner and outer regions split at
    /// nothing: the outline is two circles sampled at `n` points.
    fn ring(n: usize) -> Deck {
        let mut m = Mesh::default();
        for k in 0..n {
            let t = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            m.add_node([t.cos(), t.sin()]);
            m.add_node([2.0 * t.cos(), 2.0 * t.sin()]);
        }
        for k in 0..n {
            let k1 = (k + 1) % n;
            m.add_element(Element::quad(
                ElementKind::Cpe4h,
                [2 * k, 2 * k + 1, 2 * k1 + 1, 2 * k1],
            ));
        }
        deck_of(m, vec![0; n])
    }

    /// The largest relative distance `|r − R| / R` of the outline's nodes from their circle.
    fn off_circle(d: &Deck) -> f64 {
        d.mesh
            .nodes
            .iter()
            .map(|x| {
                let r = norm(*x);
                ((r - 1.0).abs()).min((r - 2.0).abs() / 2.0)
            })
            .filter(|&e| e < 0.2)
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_sampled_circle_is_followed_to_fourth_order() {
        let mut errors = Vec::new();
        for n in [12, 24] {
            let d = ring(n);
            let s = split_deck(&d).unwrap();
            // The straight midpoint of a chord is R (1 − cos(π/n)) inside the circle of radius
            // R; the four-point rule's error is O(h⁴) (for n = 12: 1.7e-3 against 3.4e-2).
            let straight = 1.0 - (std::f64::consts::PI / n as f64).cos();
            let err = off_circle(&s);
            eprintln!("n = {n}: off the circle {err:.2e} R, straight midpoints {straight:.2e} R");
            assert!(
                err < straight / 15.0,
                "n = {n}: {err:.2e} vs {straight:.2e}"
            );
            // The area is that of the ring between the 2n-gons inscribed in the circles (what
            // straight splitting keeps is the n-gons' area).
            let m = 2.0 * n as f64;
            let inscribed = 0.5 * m * (2.0 * std::f64::consts::PI / m).sin() * 3.0;
            let (a, polygon) = (area(&s.mesh), area(&d.mesh));
            assert!(
                (a - inscribed).abs() < (polygon - inscribed).abs() / 10.0,
                "{a} vs {inscribed} ({polygon} split straight)"
            );
            s.mesh.check_orientation().unwrap();
            errors.push(err);
        }
        // Fourth order: halving h divides the error by 16 (12 allows for the rule's
        // higher terms at n = 12).
        assert!(errors[0] / errors[1] > 12.0, "{errors:?}");
    }

    #[test]
    fn an_interface_is_a_curve_and_a_corner_stays_a_corner() {
        // A 4 x 1 strip whose interior vertical lines are region interfaces: the outline's
        // corners (right angles) are not rounded off, the straight edges stay straight.
        let d = deck_of(grid(4, 1), vec![0, 1, 2, 3]);
        let s = split_deck_times(&d, 2).unwrap();
        assert_eq!(s.mesh.elements.len(), 64);
        assert!((area(&s.mesh) - 4.0).abs() < 1e-12);
        for x in &s.mesh.nodes {
            assert!(x[0] >= -1e-12 && x[0] <= 4.0 + 1e-12 && x[1] >= -1e-12 && x[1] <= 1.0 + 1e-12);
        }
    }

    #[test]
    fn triangles_split_in_four() {
        let mut m = Mesh::default();
        for x in [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]] {
            m.add_node(x);
        }
        m.add_element(Element {
            kind: ElementKind::Cpe3,
            conn: [0, 1, 2, 0],
        });
        m.add_element(Element {
            kind: ElementKind::Cpe3,
            conn: [1, 3, 2, 0],
        });
        let mut d = deck_of(m, vec![0, 0]);
        d.pressures.push(FacePressure {
            element: 1,
            face: 0,
            magnitude: 1.0,
        });
        let s = split_deck(&d).unwrap();
        assert_eq!(s.mesh.elements.len(), 8);
        assert_eq!(s.mesh.nodes.len(), 9);
        assert!((area(&s.mesh) - 1.0).abs() < 1e-12);
        // Face 0 of the second triangle runs 1 → 3 (x = 1): its halves too.
        for p in &s.pressures {
            let [a, b] = s.mesh.elements[p.element].face_nodes(p.face);
            assert_eq!((s.mesh.nodes[a][0], s.mesh.nodes[b][0]), (1.0, 1.0));
        }
        assert_eq!(s.pressures.len(), 2);
    }
}
