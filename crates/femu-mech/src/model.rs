//! A mechanical model ready to solve: mesh, precomputed element geometry, materials per
//! element, prescribed displacements and loads of one static step.
//!
//! A model is described by a [`ModelSpec`] (the program's own terms: typed materials from the
//! registry, named surfaces) and checked into a [`Model`] by [`Model::new`]. An Abaqus/CalculiX
//! deck is a file format at the edges: read into a spec ([`ModelSpec::from_deck`]) and written
//! from a model ([`Model::to_deck`]).

use crate::contact::RigidContact;
use crate::element::{ElementGeometry, MAX_NODES};
use crate::interface::Interface;
use crate::load::PressureFace;
use crate::material::{material_def, material_from_def, Material, MaterialError};
use femu_mesh::{BoundaryCondition, Deck, FacePressure, MaterialDef, Mesh, PointLoad, StepDef};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Problems found while building a model.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("element {label}: the reference element is inverted or degenerate (det J = {det_j:.3e} at Gauss point {gauss_point})")]
    InvertedElement {
        label: i64,
        gauss_point: usize,
        det_j: f64,
    },
    /// The law's message is part of this one (not a separate source, which `{:#}` would print a
    /// second time).
    #[error("material '{name}'{}: {problem}", line.map(|l| format!(" (deck line {l})")).unwrap_or_default())]
    BadMaterial {
        name: String,
        /// The deck line of the material's data, when it came from a file.
        line: Option<usize>,
        problem: Box<MaterialError>,
    },
    #[error("element {label}: no material assigned")]
    NoMaterial { label: i64 },
    #[error("pressure on element {label}: face {face} does not exist")]
    BadFace { label: i64, face: usize },
    #[error("node {0}: prescribed dof must be 0 (x) or 1 (y)")]
    BadDof(i64),
    #[error("the model has no prescribed displacement: rigid-body motion is not restrained")]
    Unrestrained,
    #[error("node {0}: a point load on a node no element uses (nothing would carry it)")]
    LoadOnUnusedNode(i64),
    #[error("region {0}: no element set of that name in the mesh")]
    NoRegionSet(String),
    #[error("element {0} belongs to no region")]
    NoRegion(i64),
    #[error("surface {name}: element index {element} does not exist")]
    BadSurface { name: String, element: usize },
}

/// A named material of the model: any registered law ([`crate::material::LAWS`]).
#[derive(Debug, Clone)]
pub struct NamedMaterial {
    pub name: String,
    pub law: Box<dyn Material>,
}

impl PartialEq for NamedMaterial {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name && *self.law == *other.law
    }
}

impl NamedMaterial {
    /// A compressible Neo-Hookean material (seed Eq. 1; C10 in MPa, D in MPa⁻¹).
    pub fn neo_hookean(name: &str, c10: f64, d: f64) -> NamedMaterial {
        NamedMaterial {
            name: name.to_string(),
            law: Box::new(crate::material::NeoHookean { c10, d }),
        }
    }

    /// The material of a deck, through the registry (errors name the deck line).
    pub fn from_def(def: &MaterialDef) -> Result<NamedMaterial, ModelError> {
        let law = material_from_def(def).map_err(|problem| ModelError::BadMaterial {
            name: def.name.clone(),
            line: def.line,
            problem: Box::new(problem),
        })?;
        Ok(NamedMaterial {
            name: def.name.clone(),
            law,
        })
    }

    /// Its deck form: `*MATERIAL, NAME=` with the law's `*HYPERELASTIC` keyword and data line.
    pub fn to_def(&self) -> MaterialDef {
        material_def(&self.name, &*self.law)
    }
}

/// A model as the program describes it, before the checks of [`Model::new`]: the mesh with its
/// named sets, named surfaces, typed materials and where they apply, supports and loads of one
/// static step. Deck files are read into it ([`ModelSpec::from_deck`]); the built-in and
/// label-image thighs are built into it directly ([`ModelSpec::with_regions`]).
#[derive(Debug, Clone, Default)]
pub struct ModelSpec {
    pub mesh: Mesh,
    /// Named surfaces as `(element, face)` lists, `face` 0-based ([`femu_mesh::Element::face_nodes`]):
    /// the skin the loading tests act on, the femur edge.
    pub surfaces: BTreeMap<String, Vec<(usize, usize)>>,
    pub materials: Vec<NamedMaterial>,
    /// Index into `materials` for each element.
    pub element_material: Vec<usize>,
    pub region_names: Vec<String>,
    /// Index into `region_names` for each element.
    pub element_region: Vec<usize>,
    pub supports: Vec<BoundaryCondition>,
    pub pressures: Vec<FacePressure>,
    pub point_loads: Vec<PointLoad>,
    pub step: StepDef,
}

impl ModelSpec {
    /// A deck's content with its materials read through the registry (errors name the deck
    /// line); a deck names no surfaces (its `*DLOAD` faces are loads).
    pub fn from_deck(deck: Deck) -> Result<ModelSpec, ModelError> {
        let Deck {
            mesh,
            materials,
            element_material,
            element_region,
            region_names,
            step,
            boundaries,
            pressures,
            point_loads,
        } = deck;
        let materials = materials
            .iter()
            .map(NamedMaterial::from_def)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ModelSpec {
            mesh,
            surfaces: BTreeMap::new(),
            materials,
            element_material,
            region_names,
            element_region,
            supports: boundaries,
            pressures,
            point_loads,
            step,
        })
    }

    /// A meshed body with one material per region (`regions`: the name of an element set of
    /// `mesh` and its material, in order) and every node of the node set `fixed` held in both
    /// directions; no load. Every element must belong to a region.
    pub fn with_regions(
        mesh: Mesh,
        surfaces: BTreeMap<String, Vec<(usize, usize)>>,
        regions: Vec<NamedMaterial>,
        fixed: &str,
    ) -> Result<ModelSpec, ModelError> {
        let n = mesh.elements.len();
        let mut element_material = vec![usize::MAX; n];
        for (r, m) in regions.iter().enumerate() {
            let set = mesh
                .element_set(&m.name)
                .ok_or_else(|| ModelError::NoRegionSet(m.name.clone()))?;
            for &e in set {
                element_material[e] = r;
            }
        }
        if let Some(e) = element_material.iter().position(|&r| r == usize::MAX) {
            return Err(ModelError::NoRegion(mesh.element_labels[e]));
        }
        let supports = mesh
            .node_set(fixed)
            .unwrap_or(&[])
            .iter()
            .flat_map(|&node| {
                (0..2).map(move |dof| BoundaryCondition {
                    node,
                    dof,
                    value: 0.0,
                })
            })
            .collect();
        Ok(ModelSpec {
            mesh,
            surfaces,
            region_names: regions.iter().map(|m| m.name.clone()).collect(),
            element_region: element_material.clone(),
            element_material,
            materials: regions,
            supports,
            pressures: Vec::new(),
            point_loads: Vec::new(),
            step: StepDef::default(),
        })
    }
}

/// Everything the static solver needs.
#[derive(Debug, Clone)]
pub struct Model {
    pub mesh: Mesh,
    /// Named surfaces (`(element, face)`, `face` 0-based), e.g. `SKIN`.
    pub surfaces: BTreeMap<String, Vec<(usize, usize)>>,
    pub geometry: Vec<ElementGeometry>,
    pub materials: Vec<NamedMaterial>,
    pub element_material: Vec<usize>,
    pub region_names: Vec<String>,
    pub element_region: Vec<usize>,
    pub constraints: Vec<BoundaryCondition>,
    pub pressures: Vec<PressureFace>,
    pub point_loads: Vec<PointLoad>,
    /// Rigid bodies in frictionless contact (plate, indenter); each adds its travel to the
    /// unknowns of the state (after the nodal displacements).
    pub contacts: Vec<RigidContact>,
    /// Sliding interfaces between regions (contact of slave nodes with master segments, see
    /// [`crate::interface`]); none by default (regions sharing nodes are tied).
    pub interfaces: Vec<Interface>,
    pub step: StepDef,
}

impl Model {
    /// Builds and checks a model from a resolved deck.
    pub fn from_deck(deck: Deck) -> Result<Model, ModelError> {
        Model::new(ModelSpec::from_deck(deck)?)
    }

    /// Checks `spec` (every element with a material and a non-inverted reference shape, loads
    /// on existing faces, supports on x or y, at least one support) and precomputes the
    /// element geometry.
    pub fn new(spec: ModelSpec) -> Result<Model, ModelError> {
        let ModelSpec {
            mesh,
            surfaces,
            materials,
            element_material,
            region_names,
            element_region,
            supports: boundaries,
            pressures,
            point_loads,
            step,
        } = spec;
        // Element geometry in parallel; the errors are then reported in element order (the
        // first bad element, as a serial loop would).
        let geometry: Vec<Result<ElementGeometry, ModelError>> = (0..mesh.elements.len())
            .into_par_iter()
            .map(|e| {
                if element_material
                    .get(e)
                    .is_none_or(|&m| m >= materials.len())
                {
                    return Err(ModelError::NoMaterial {
                        label: mesh.element_labels[e],
                    });
                }
                let (x, _) = mesh.element_coords(e);
                ElementGeometry::new(mesh.elements[e].kind, &x).map_err(|b| {
                    ModelError::InvertedElement {
                        label: mesh.element_labels[e],
                        gauss_point: b.gauss_point + 1,
                        det_j: b.det_j,
                    }
                })
            })
            .collect();
        let geometry = geometry.into_iter().collect::<Result<Vec<_>, _>>()?;
        let mut faces = Vec::with_capacity(pressures.len());
        for p in &pressures {
            let el = &mesh.elements[p.element];
            if p.face >= el.face_count() {
                return Err(ModelError::BadFace {
                    label: mesh.element_labels[p.element],
                    face: p.face + 1,
                });
            }
            let n = el.kind.node_count();
            let local = [p.face, (p.face + 1) % n];
            faces.push(PressureFace {
                element: p.element,
                local,
                nodes: [el.conn[local[0]], el.conn[local[1]]],
                pressure: p.magnitude,
            });
        }
        for b in &boundaries {
            if b.dof > 1 {
                return Err(ModelError::BadDof(mesh.node_labels[b.node]));
            }
        }
        let used = nodes_used(&mesh);
        if let Some(p) = point_loads.iter().find(|p| !used[p.node]) {
            return Err(ModelError::LoadOnUnusedNode(mesh.node_labels[p.node]));
        }
        if boundaries.is_empty() {
            return Err(ModelError::Unrestrained);
        }
        // (A model with only rigid-body supports would be restrained by contact; the thigh is
        // always held by its femur, so an unrestrained deck is an input error.)
        for (name, faces) in &surfaces {
            if let Some(&(element, _)) = faces.iter().find(|(e, _)| *e >= mesh.elements.len()) {
                return Err(ModelError::BadSurface {
                    name: name.clone(),
                    element,
                });
            }
        }
        Ok(Model {
            mesh,
            surfaces,
            geometry,
            materials,
            element_material,
            region_names,
            element_region,
            constraints: boundaries,
            pressures: faces,
            point_loads,
            contacts: Vec::new(),
            interfaces: Vec::new(),
            step,
        })
    }

    /// The nodes no element uses (an Abaqus reference point, a node left over from a cut
    /// mesh): they have no stiffness, so the solver holds them at zero displacement (or at
    /// their prescribed value); a point load on one is refused when the model is built.
    pub fn unused_nodes(&self) -> Vec<usize> {
        let used = nodes_used(&self.mesh);
        (0..used.len()).filter(|&n| !used[n]).collect()
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.mesh.nodes.len()
    }

    /// The faces of the named surface (`None` if the model has none of that name).
    pub fn surface(&self, name: &str) -> Option<&[(usize, usize)]> {
        self.surfaces.get(name).map(Vec::as_slice)
    }

    /// The model as a deck, to write as an Abaqus/CalculiX input file (the rigid bodies and the
    /// named surfaces are not part of it).
    pub fn to_deck(&self) -> Deck {
        Deck {
            mesh: self.mesh.clone(),
            materials: self.materials.iter().map(NamedMaterial::to_def).collect(),
            element_material: self.element_material.clone(),
            element_region: self.element_region.clone(),
            region_names: self.region_names.clone(),
            step: self.step,
            boundaries: self.constraints.clone(),
            pressures: self
                .pressures
                .iter()
                .map(|p| FacePressure {
                    element: p.element,
                    face: p.local[0],
                    magnitude: p.pressure,
                })
                .collect(),
            point_loads: self.point_loads.clone(),
        }
    }

    /// Length of the state vector: two displacements per node, then one travel per rigid body.
    pub fn state_len(&self) -> usize {
        2 * self.mesh.nodes.len() + self.contacts.len()
    }

    /// Local displacements of element `e` gathered from the global vector `u` (2 per node).
    #[inline]
    pub fn gather(&self, e: usize, u: &[f64]) -> [[f64; 2]; MAX_NODES] {
        let mut ue = [[0.0; 2]; MAX_NODES];
        for (a, &n) in self.mesh.elements[e].nodes().iter().enumerate() {
            ue[a] = [u[2 * n], u[2 * n + 1]];
        }
        ue
    }

    /// Current position of node `n` for the state `u`.
    #[inline]
    pub fn current_position(&self, n: usize, u: &[f64]) -> [f64; 2] {
        [
            self.mesh.nodes[n][0] + u[2 * n],
            self.mesh.nodes[n][1] + u[2 * n + 1],
        ]
    }
}

/// Whether each node of `mesh` belongs to an element.
fn nodes_used(mesh: &Mesh) -> Vec<bool> {
    let mut used = vec![false; mesh.nodes.len()];
    for el in &mesh.elements {
        for &n in el.nodes() {
            used[n] = true;
        }
    }
    used
}
