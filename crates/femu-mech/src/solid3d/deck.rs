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

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mesh::deck::{BoundaryCondition, FacePressure, MaterialDef};
    use femu_mesh::mesh3d::generate::block;

    fn block_deck(kind: ElementKind3) -> Deck3 {
        let mesh = block([2.0, 1.0, 1.0], [2, 1, 1], kind);
        let n = mesh.elements.len();
        // The faces on x = 2 (outward +x), found by their area vectors.
        let pressures = mesh
            .boundary_faces()
            .into_iter()
            .filter(|&(e, f)| mesh.face_area_vector(e, f)[0] > 0.0)
            .map(|(element, face)| FacePressure {
                element,
                face,
                magnitude: 0.25,
            })
            .collect();
        let boundaries = mesh.node_set("X0").unwrap().iter().flat_map(|&node| {
            (0..3).map(move |dof| BoundaryCondition {
                node,
                dof,
                value: 0.0,
            })
        });
        Deck3 {
            boundaries: boundaries.collect(),
            mesh,
            materials: vec![MaterialDef {
                name: "M".into(),
                keyword: "NEO HOOKE".into(),
                constants: vec![0.5, 0.1],
                line: None,
            }],
            element_material: vec![0; n],
            element_region: vec![0; n],
            region_names: vec!["ALL".into()],
            pressures,
            ..Default::default()
        }
    }

    /// The dead loads of a pressure on the face x = 2 (area 1 mm²) add up to -p along x, for
    /// every element type (their faces' consistent loads; exact for flat faces up to round-off).
    #[test]
    fn dead_loads_add_up_to_the_pressure_force() {
        for kind in ElementKind3::ALL {
            let mut deck = block_deck(kind);
            let body = Body3::from_deck3(&deck).unwrap();
            assert_eq!(body.pressures.len(), deck.pressures.len());
            pressures_to_dead_loads(&mut deck);
            assert!(deck.pressures.is_empty());
            let mut total = [0.0; 3];
            for l in &deck.point_loads {
                total[l.dof] += l.magnitude;
            }
            assert!((total[0] + 0.25).abs() < 1e-14, "{kind:?}: {total:?}");
            assert!(
                total[1].abs() < 1e-14 && total[2].abs() < 1e-14,
                "{total:?}"
            );
            // At rest the element stresses vanish.
            let rest = vec![[0.0; 3]; body.nodes.len()];
            for a in body.element_averages(&rest) {
                let a = a.unwrap();
                assert!(a.cauchy_stress.iter().all(|s| s.abs() < 1e-14));
                assert!((a.volume_ratio - 1.0).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn bad_decks_are_refused() {
        let mut deck = block_deck(ElementKind3::C3d8);
        deck.pressures[0].face = 6;
        assert!(matches!(
            Body3::from_deck3(&deck),
            Err(ModelError::BadFace { face: 6, .. })
        ));
        let mut deck = block_deck(ElementKind3::C3d4);
        deck.element_material[1] = 3;
        assert!(matches!(
            Body3::from_deck3(&deck),
            Err(ModelError::NoMaterial { label: 2 })
        ));
        let mut deck = block_deck(ElementKind3::C3d8h);
        deck.boundaries.clear();
        assert!(matches!(
            Body3::from_deck3(&deck),
            Err(ModelError::Unrestrained)
        ));
        let mut deck = block_deck(ElementKind3::C3d10);
        deck.materials[0].constants = vec![-1.0, 0.1];
        assert!(matches!(
            Body3::from_deck3(&deck),
            Err(ModelError::BadMaterial { .. })
        ));
    }
}
