//! A [`Body3`] from a 3D deck ([`femu_mesh::Deck3`]: mesh, materials through the registry,
//! supports, point loads and face pressures), the element averages of a solution (Cauchy
//! stress and volume ratio per element, for output), and the dead nodal loads equal to a
//! deck's pressures on the reference geometry (what CalculiX 2.20 solves reliably, see the
//! plane-strain `Deck::pressures_to_dead_loads`).

use super::assembly::{Body3, Element3, Solution3};
use super::kernel::{averages, Averages3, Geometry3};
use super::pressure::face_pressure;
use super::shape::Kind3;
use crate::material::material_from_def;
use crate::model::ModelError;
use femu_mesh::{Deck3, ElementKind3, PointLoad};

/// The solver's element type of a mesh element type.
pub fn kind3(kind: ElementKind3) -> Kind3 {
    match kind {
        ElementKind3::C3d8 => Kind3::C3d8,
        ElementKind3::C3d8h => Kind3::C3d8h,
        ElementKind3::C3d4 => Kind3::C3d4,
        ElementKind3::C3d10 => Kind3::C3d10,
    }
}

impl Body3 {
    /// The body of a 3D deck: its nodes and elements, one material per deck material (through
    /// the registry, errors naming the deck line), its boundary conditions, point loads and
    /// pressures (the faces in their outward order, [`femu_mesh::mesh3d`]).
    pub fn from_deck3(deck: &Deck3) -> Result<Body3, ModelError> {
        let mesh = &deck.mesh;
        let materials = deck
            .materials
            .iter()
            .map(|def| {
                material_from_def(def).map_err(|problem| ModelError::BadMaterial {
                    name: def.name.clone(),
                    line: def.line,
                    problem: Box::new(problem),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut elements = Vec::with_capacity(mesh.elements.len());
        for (e, el) in mesh.elements.iter().enumerate() {
            let material = deck.element_material.get(e).copied().unwrap_or(usize::MAX);
            if material >= materials.len() {
                return Err(ModelError::NoMaterial {
                    label: mesh.element_labels[e],
                });
            }
            elements.push(Element3 {
                kind: kind3(el.kind),
                nodes: el.nodes().to_vec(),
                material,
            });
        }
        let mut pressures = Vec::with_capacity(deck.pressures.len());
        for p in &deck.pressures {
            let Some(el) = mesh.elements.get(p.element) else {
                return Err(ModelError::BadFace {
                    label: p.element as i64,
                    face: p.face,
                });
            };
            if p.face >= el.kind.face_count() {
                return Err(ModelError::BadFace {
                    label: mesh.element_labels[p.element],
                    face: p.face,
                });
            }
            pressures.push((el.face_nodes(p.face), p.magnitude));
        }
        if deck.boundaries.is_empty() {
            return Err(ModelError::Unrestrained);
        }
        Ok(Body3 {
            nodes: mesh.nodes.clone(),
            elements,
            materials,
            prescribed: deck
                .boundaries
                .iter()
                .map(|b| (b.node, b.dof, b.value))
                .collect(),
            loads: deck
                .point_loads
                .iter()
                .map(|l| (l.node, l.dof, l.magnitude))
                .collect(),
            pressures,
        })
    }

    /// Cauchy stress and volume ratio averaged over each element at the solution `u`
    /// ([`averages`]); `None` for an element whose reference map or current state is invalid.
    pub fn element_averages(&self, u: &[[f64; 3]]) -> Vec<Option<Averages3>> {
        self.elements
            .iter()
            .map(|el| {
                let x: Vec<[f64; 3]> = el.nodes.iter().map(|&n| self.nodes[n]).collect();
                let ue: Vec<[f64; 3]> = el.nodes.iter().map(|&n| u[n]).collect();
                let geo = Geometry3::new(el.kind, &x).ok()?;
                averages(&geo, self.materials[el.material].as_ref(), &ue).ok()
            })
            .collect()
    }
}

impl Solution3 {
    /// The displacements as `[ux0, uy0, uz0, ux1, ...]`.
    pub fn flat(&self) -> Vec<f64> {
        self.u.as_flattened().to_vec()
    }
}

/// Replaces the deck's pressures by dead nodal forces (`*CLOAD`) equal to them on the
/// reference geometry: the follower load of [`face_pressure`] at zero displacement, summed per
/// node dof. The deck's point loads are replaced.
pub fn pressures_to_dead_loads(deck: &mut Deck3) {
    let mesh = &deck.mesh;
    let mut f = vec![0.0; 3 * mesh.nodes.len()];
    for p in std::mem::take(&mut deck.pressures) {
        let nodes = mesh.elements[p.element].face_nodes(p.face);
        let x: Vec<[f64; 3]> = nodes.iter().map(|&n| mesh.nodes[n]).collect();
        let mut force = vec![0.0; 3 * nodes.len()];
        face_pressure(&x, p.magnitude, &mut force, None);
        for (k, &n) in nodes.iter().enumerate() {
            for i in 0..3 {
                f[3 * n + i] += force[3 * k + i];
            }
        }
    }
    deck.point_loads = f
        .iter()
        .enumerate()
        .filter(|(_, v)| **v != 0.0)
        .map(|(i, &magnitude)| PointLoad {
            node: i / 3,
            dof: i % 3,
            magnitude,
        })
        .collect();
}
