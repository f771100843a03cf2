//! Building decks and models in code (tests, benchmarks, generated meshes), without a file.
//!
//! Unknown set names panic: the builder is for programs, whose set names are fixed in code;
//! user input goes through the deck reader and its errors.

use crate::material::{material_def, Material, NeoHookean};
use femu_mesh::generate::GeneratedMesh;
use femu_mesh::{BoundaryCondition, Deck, FacePressure, StepDef};

/// Assembles a [`Deck`] from a generated mesh: one material per element set (in the order
/// given), node sets fixed in both directions, follower pressure on named surfaces.
#[derive(Debug, Clone)]
pub struct DeckBuilder {
    deck: Deck,
    surfaces: std::collections::BTreeMap<String, Vec<(usize, usize)>>,
}

impl DeckBuilder {
    /// Starts from a generated mesh (no materials, no loads).
    pub fn new(g: GeneratedMesh) -> Self {
        let n = g.mesh.elements.len();
        DeckBuilder {
            deck: Deck {
                mesh: g.mesh,
                element_material: vec![usize::MAX; n],
                element_region: vec![usize::MAX; n],
                step: StepDef::default(),
                ..Default::default()
            },
            surfaces: g.surfaces,
        }
    }

    /// Assigns a Neo-Hookean material (C10 in MPa, D in MPa^-1) to element set `elset` (the
    /// seed's law; [`DeckBuilder::law`] for any law).
    pub fn material(self, elset: &str, c10: f64, d: f64) -> Self {
        self.law(elset, NeoHookean { c10, d })
    }

    /// The same Neo-Hookean material on every element (region `ALL`).
    pub fn material_everywhere(self, c10: f64, d: f64) -> Self {
        self.law_everywhere(NeoHookean { c10, d })
    }

    /// Assigns a material of any registered law (e.g. `MooneyRivlin { c10, c01, d }`, internal
    /// units) to element set `elset`; the set becomes a region of the same name. Its values
    /// are checked when the model is built.
    pub fn law(mut self, elset: &str, law: impl Material) -> Self {
        let m = self.deck.materials.len();
        self.deck.materials.push(material_def(elset, &law));
        self.deck.region_names.push(elset.to_string());
        let set = self
            .deck
            .mesh
            .element_set(elset)
            .unwrap_or_else(|| panic!("DeckBuilder: unknown element set '{elset}'"))
            .to_vec();
        for e in set {
            self.deck.element_material[e] = m;
            self.deck.element_region[e] = m;
        }
        self
    }

    /// The same material of any law on every element (region `ALL`).
    pub fn law_everywhere(mut self, law: impl Material) -> Self {
        let n = self.deck.mesh.elements.len();
        self.deck
            .mesh
            .element_sets
            .insert("ALL".into(), (0..n).collect());
        self.law("ALL", law)
    }

    /// The nodes of a set; an unknown name is a programming error of the caller.
    fn node_set(&self, nset: &str) -> Vec<usize> {
        self.deck
            .mesh
            .node_set(nset)
            .unwrap_or_else(|| panic!("DeckBuilder: unknown node set '{nset}'"))
            .to_vec()
    }

    /// Prescribes displacement `value` on dof `dof` (0 = x, 1 = y) of every node of `nset`.
    pub fn displacement(mut self, nset: &str, dof: usize, value: f64) -> Self {
        for node in self.node_set(nset) {
            self.deck
                .boundaries
                .push(BoundaryCondition { node, dof, value });
        }
        self
    }

    /// Prescribes a displacement computed from the reference position on every node of `nset`.
    pub fn displacement_field(mut self, nset: &str, f: impl Fn([f64; 2]) -> [f64; 2]) -> Self {
        for node in self.node_set(nset) {
            let u = f(self.deck.mesh.nodes[node]);
            for (dof, value) in u.into_iter().enumerate() {
                self.deck
                    .boundaries
                    .push(BoundaryCondition { node, dof, value });
            }
        }
        self
    }

    /// Fixes both dofs of every node of `nset`.
    pub fn fix(self, nset: &str) -> Self {
        self.displacement(nset, 0, 0.0).displacement(nset, 1, 0.0)
    }

    /// Follower pressure `p` (MPa) on every face of surface `surface`.
    pub fn pressure(mut self, surface: &str, p: f64) -> Self {
        let faces = self
            .surfaces
            .get(surface)
            .unwrap_or_else(|| panic!("DeckBuilder: unknown surface '{surface}'"))
            .clone();
        for (element, face) in faces {
            self.deck.pressures.push(FacePressure {
                element,
                face,
                magnitude: p,
            });
        }
        self
    }

    /// Step settings.
    pub fn step(mut self, step: StepDef) -> Self {
        self.deck.step = step;
        self
    }

    /// The deck.
    pub fn build(self) -> Deck {
        self.deck
    }
}

/// Material of one region of a Gmsh model: any registered law.
#[derive(Debug, Clone)]
pub struct RegionMaterial {
    pub region: String,
    pub law: Box<dyn Material>,
}

impl PartialEq for RegionMaterial {
    fn eq(&self, other: &Self) -> bool {
        self.region == other.region && *self.law == *other.law
    }
}

/// Prescribed displacement of every node of a physical curve (dofs 0 = x, 1 = y).
#[derive(Debug, Clone, PartialEq)]
pub struct CurveDisplacement {
    pub curve: String,
    pub dofs: Vec<usize>,
    pub value: f64,
}

/// Follower pressure (MPa) on every edge of a physical curve.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvePressure {
    pub curve: String,
    pub pressure: f64,
}

/// What a Gmsh mesh needs to become a deck: materials per physical surface, conditions and
/// loads per physical curve.
#[derive(Debug, Clone, PartialEq)]
pub struct MshSetup {
    /// Element type given to the quadrilaterals (CPE4 or CPE4H); triangles stay CPE3.
    pub quad_kind: femu_mesh::ElementKind,
    pub materials: Vec<RegionMaterial>,
    pub displacements: Vec<CurveDisplacement>,
    pub pressures: Vec<CurvePressure>,
    pub step: StepDef,
}

/// A Gmsh model that cannot be set up as described.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SetupError {
    #[error("region '{name}' is not a physical surface of the mesh (available: {available})")]
    UnknownRegion { name: String, available: String },
    #[error("curve '{name}' is not a physical curve of the mesh (available: {available})")]
    UnknownCurve { name: String, available: String },
    #[error("element {label} belongs to no region with a material")]
    NoMaterial { label: i64 },
    #[error("curve '{curve}': edge between nodes {a} and {b} is not on the boundary of the mesh")]
    NotABoundaryEdge { curve: String, a: i64, b: i64 },
    #[error("dof {0} does not exist (plane strain has dofs 1 and 2)")]
    BadDof(usize),
}

/// The boundary faces `(element, face)` along the edges `edges` (node pairs) of curve `name`.
fn faces_of_edges(
    mesh: &femu_mesh::Mesh,
    name: &str,
    edges: &[[usize; 2]],
) -> Result<Vec<(usize, usize)>, SetupError> {
    let boundary: std::collections::HashMap<(usize, usize), (usize, usize)> = mesh
        .boundary_faces()
        .into_iter()
        .map(|(e, f)| {
            let [a, b] = mesh.elements[e].face_nodes(f);
            ((a.min(b), a.max(b)), (e, f))
        })
        .collect();
    edges
        .iter()
        .map(|&[a, b]| {
            boundary
                .get(&(a.min(b), a.max(b)))
                .copied()
                .ok_or(SetupError::NotABoundaryEdge {
                    curve: name.to_string(),
                    a: mesh.node_labels[a],
                    b: mesh.node_labels[b],
                })
        })
        .collect()
}

/// The boundary faces `(element, face)` of physical curve `name` of a Gmsh model (e.g. the
/// skin, for a rigid body's contact surface).
pub fn curve_faces(
    msh: &femu_mesh::MshModel,
    name: &str,
) -> Result<Vec<(usize, usize)>, SetupError> {
    let edges = msh
        .edge_sets
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case(name))
        .map(|(_, v)| v)
        .ok_or_else(|| SetupError::UnknownCurve {
            name: name.to_string(),
            available: msh.edge_sets.keys().cloned().collect::<Vec<_>>().join(", "),
        })?;
    faces_of_edges(&msh.mesh, name, edges)
}

/// Turns a Gmsh model and its setup into a deck.
pub fn deck_from_msh(msh: femu_mesh::MshModel, setup: &MshSetup) -> Result<Deck, SetupError> {
    let femu_mesh::MshModel {
        mut mesh,
        edge_sets,
    } = msh;
    for el in mesh.elements.iter_mut() {
        if el.kind.node_count() == 4 {
            el.kind = setup.quad_kind;
        }
    }
    let n = mesh.elements.len();
    let names = |keys: Vec<&String>| keys.into_iter().cloned().collect::<Vec<_>>().join(", ");
    let mut deck = Deck {
        element_material: vec![usize::MAX; n],
        element_region: vec![usize::MAX; n],
        step: setup.step,
        ..Default::default()
    };
    for (m, rm) in setup.materials.iter().enumerate() {
        let set = mesh
            .element_set(&rm.region)
            .ok_or_else(|| SetupError::UnknownRegion {
                name: rm.region.clone(),
                available: names(mesh.element_sets.keys().collect()),
            })?
            .to_vec();
        deck.materials.push(material_def(&rm.region, &*rm.law));
        deck.region_names.push(rm.region.clone());
        for e in set {
            deck.element_material[e] = m;
            deck.element_region[e] = m;
        }
    }
    if let Some(e) = deck.element_material.iter().position(|&m| m == usize::MAX) {
        return Err(SetupError::NoMaterial {
            label: mesh.element_labels[e],
        });
    }
    let curve = |name: &str| {
        edge_sets
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v)
            .ok_or_else(|| SetupError::UnknownCurve {
                name: name.to_string(),
                available: names(edge_sets.keys().collect()),
            })
    };
    for d in &setup.displacements {
        let edges = curve(&d.curve)?;
        let mut nodes: Vec<usize> = edges.iter().flatten().copied().collect();
        nodes.sort_unstable();
        nodes.dedup();
        for &dof in &d.dofs {
            if dof > 1 {
                return Err(SetupError::BadDof(dof + 1));
            }
            for &node in &nodes {
                deck.boundaries.push(BoundaryCondition {
                    node,
                    dof,
                    value: d.value,
                });
            }
        }
    }
    for p in &setup.pressures {
        for (element, face) in faces_of_edges(&mesh, &p.curve, curve(&p.curve)?)? {
            deck.pressures.push(FacePressure {
                element,
                face,
                magnitude: p.pressure,
            });
        }
    }
    deck.mesh = mesh;
    Ok(deck)
}
