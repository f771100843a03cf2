//! Exports of a meshed thigh: the contention deck (Abaqus/CalculiX `.inp`, runnable by `ccx`
//! as is), the ParaView file of the regions, and the default materials (the seed's Table 1, as
//! deck materials: this crate knows no mechanics, `femu-mech`'s registry interprets them).

use crate::mesher::ThighModel;
use crate::quality::scaled_jacobian;
use crate::GeometryError;
use femu_mesh::generate::GeneratedMesh;
use femu_mesh::{
    BoundaryCondition, Deck, FacePressure, FieldSet, FieldWriter, MaterialDef, StepDef, VtuField,
    VtuIntField, VtuWriter,
};
use std::collections::BTreeMap;
use std::path::Path;

/// The seed's Table 1: `(region, C10 in kPa, D in MPa^-1)`.
pub const TABLE1: [(&str, f64, f64); 5] = [
    ("FAT", 0.8, 30.8),
    ("ISCHIO", 3.0, 18.0),
    ("QUADRICEPS", 1.75, 18.0),
    ("GRACILIS", 2.2, 18.0),
    ("SARTORIUS", 3.75, 18.0),
];

/// The seed's Table 1 as deck materials named by region: compressible Neo-Hookean
/// (`*HYPERELASTIC, NEO HOOKE` with the data line `C10, D1` in MPa and MPa⁻¹).
pub fn table1_materials() -> Vec<MaterialDef> {
    TABLE1
        .iter()
        .map(|&(r, c10_kpa, d)| MaterialDef {
            name: r.to_string(),
            keyword: "NEO HOOKE".to_string(),
            constants: vec![c10_kpa * 1e-3, d],
            line: None,
        })
        .collect()
}

/// The contention test of the seed on a meshed thigh: one material per region (the material
/// of `materials` whose name is the region's, case-insensitively; any law, checked when a model
/// is built from the deck), every node of the node set `FEMUR` fixed, a follower
/// pressure `pressure_mpa` on every face of the surface `SKIN` (the seed: 20 mmHg,
/// [`crate::CONTENTION_MPA`]), one static step with NLGEOM.
pub fn contention_deck(
    model: &ThighModel,
    materials: &[MaterialDef],
    pressure_mpa: f64,
) -> Result<Deck, GeometryError> {
    if !pressure_mpa.is_finite() {
        return Err(GeometryError::param(
            "pressure",
            pressure_mpa,
            "must be finite",
        ));
    }
    let g: &GeneratedMesh = &model.mesh;
    let n = g.mesh.elements.len();
    let mut deck = Deck {
        mesh: g.mesh.clone(),
        element_material: vec![usize::MAX; n],
        element_region: vec![usize::MAX; n],
        step: StepDef::default(),
        ..Default::default()
    };
    for (r, name) in model.regions.iter().enumerate() {
        let m = materials
            .iter()
            .find(|m| m.name.eq_ignore_ascii_case(name))
            .ok_or_else(|| GeometryError::NoMaterial(name.clone()))?;
        deck.materials.push(MaterialDef {
            name: name.clone(),
            ..m.clone()
        });
        deck.region_names.push(name.clone());
        for &e in g.mesh.element_set(name).unwrap_or(&[]) {
            deck.element_material[e] = r;
            deck.element_region[e] = r;
        }
    }
    if let Some(e) = deck.element_region.iter().position(|&r| r == usize::MAX) {
        return Err(GeometryError::Meshing(format!(
            "element {} belongs to no region",
            g.mesh.element_labels[e]
        )));
    }
    for &node in g.mesh.node_set("FEMUR").unwrap_or(&[]) {
        for dof in 0..2 {
            deck.boundaries.push(BoundaryCondition {
                node,
                dof,
                value: 0.0,
            });
        }
    }
    for &(element, face) in g.surfaces.get("SKIN").map_or(&[][..], Vec::as_slice) {
        deck.pressures.push(FacePressure {
            element,
            face,
            magnitude: pressure_mpa,
        });
    }
    Ok(deck)
}

/// Writes `deck` with [`femu_mesh::write_inp`] and adds the named surfaces as
/// `*SURFACE, NAME=..., TYPE=ELEMENT` blocks (`element, Sn`, n = face + 1) before the step, so
/// that a user can load the skin or the femur edge in Abaqus/CalculiX by name.
pub fn write_inp_with_surfaces(
    deck: &Deck,
    surfaces: &BTreeMap<String, Vec<(usize, usize)>>,
    path: &Path,
) -> Result<(), GeometryError> {
    let io = |source: std::io::Error| GeometryError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut buf = Vec::new();
    femu_mesh::write_inp(deck, &mut buf).map_err(io)?;
    let text = String::from_utf8(buf).expect("the deck writer writes UTF-8");
    let mut block = String::new();
    for (name, faces) in surfaces {
        if faces.is_empty() {
            continue;
        }
        block.push_str(&format!("*SURFACE, NAME={name}, TYPE=ELEMENT\n"));
        for &(e, f) in faces {
            if e >= deck.mesh.elements.len() {
                return Err(GeometryError::Meshing(format!(
                    "surface {name} names element index {e}, which does not exist"
                )));
            }
            block.push_str(&format!("{}, S{}\n", deck.mesh.element_labels[e], f + 1));
        }
    }
    let at = text.find("\n*STEP").map(|k| k + 1).unwrap_or(text.len());
    let out = format!("{}{}{}", &text[..at], block, &text[at..]);
    femu_mesh::atomic::write(path, out).map_err(io)
}

/// Writes the mesh as a ParaView file ([`write_regions_fields`] with [`VtuWriter`]).
pub fn write_regions_vtu(model: &ThighModel, path: &Path) -> Result<(), GeometryError> {
    write_regions_fields(&VtuWriter, model, path)
}

/// Writes the mesh with `writer`, with the cell fields `region` (index into `model.regions`)
/// and `scaled_jacobian`.
pub fn write_regions_fields(
    writer: &dyn FieldWriter,
    model: &ThighModel,
    path: &Path,
) -> Result<(), GeometryError> {
    let m = &model.mesh.mesh;
    let mut region = vec![-1i32; m.elements.len()];
    for (r, name) in model.regions.iter().enumerate() {
        for &e in m.element_set(name).unwrap_or(&[]) {
            region[e] = r as i32;
        }
    }
    let sj: Vec<f64> = (0..m.elements.len())
        .map(|e| scaled_jacobian(&m.element_coords(e).0))
        .collect();
    writer
        .write(
            path,
            &FieldSet {
                mesh: m,
                displacement: None,
                point_fields: &[],
                cell_fields: &[VtuField {
                    name: "scaled_jacobian",
                    components: 1,
                    data: &sj,
                }],
                int_cell_fields: &[VtuIntField {
                    name: "region",
                    data: &region,
                }],
            },
        )
        .map_err(|source| GeometryError::Io {
            path: path.to_path_buf(),
            source,
        })
}
