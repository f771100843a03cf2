//! A mechanical model ready to solve: mesh, precomputed element geometry, materials per
//! element, prescribed displacements and loads of one static step.

use crate::contact::RigidContact;
use crate::element::{ElementGeometry, MAX_NODES};
use crate::load::PressureFace;
use crate::material::{material_def, material_from_def, Material, MaterialError};
use femu_mesh::{BoundaryCondition, Deck, MaterialDef, Mesh, PointLoad, StepDef};
use rayon::prelude::*;

/// Problems found while building a model.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("element {label}: the reference element is inverted or degenerate (det J = {det_j:.3e} at Gauss point {gauss_point})")]
    InvertedElement {
        label: i64,
        gauss_point: usize,
        det_j: f64,
    },
    #[error("material '{name}'{}: {source}", line.map(|l| format!(" (deck line {l})")).unwrap_or_default())]
    BadMaterial {
        name: String,
        /// The deck line of the material's data, when it came from a file.
        line: Option<usize>,
        source: Box<MaterialError>,
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
    /// The material of a deck, through the registry (errors name the deck line).
    pub fn from_def(def: &MaterialDef) -> Result<NamedMaterial, ModelError> {
        let law = material_from_def(def).map_err(|source| ModelError::BadMaterial {
            name: def.name.clone(),
            line: def.line,
            source: Box::new(source),
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

/// Everything the static solver needs.
#[derive(Debug, Clone)]
pub struct Model {
    pub mesh: Mesh,
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
    pub step: StepDef,
}

impl Model {
    /// Builds and checks a model from a resolved deck.
    pub fn from_deck(deck: Deck) -> Result<Model, ModelError> {
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
        Ok(Model {
            mesh,
            geometry,
            materials,
            element_material,
            region_names,
            element_region,
            constraints: boundaries,
            pressures: faces,
            point_loads,
            contacts: Vec::new(),
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
