//! 3D decks: [`Deck3`] (a [`Mesh3`] with materials, supports and loads) written by
//! [`write_inp3`] in the layout of the plane-strain writer ([`super::write_inp`]: the same
//! writer, with three coordinates and dofs 1–3, no thickness line, and the mesh's surfaces as
//! `*SURFACE, NAME=, TYPE=ELEMENT` blocks), and the 3D displacements of a CalculiX `.dat` file.

use std::io::{self, Write};
use std::path::Path;

use super::{write_deck, DeckParts, InpError, Result, WriteElement, ALL_NODES_SET};
use crate::deck::{BoundaryCondition, FacePressure, MaterialDef, PointLoad, StepDef};
use crate::mesh3d::Mesh3;

/// A 3D deck resolved to indices: mesh, materials, one material per element, one static step.
/// The fields mean what they mean in [`crate::Deck`], with dof 2 the z component and faces
/// numbered as in [`crate::mesh3d`] (`P1`..`P6`).
#[derive(Debug, Clone, Default)]
pub struct Deck3 {
    pub mesh: Mesh3,
    pub materials: Vec<MaterialDef>,
    /// Index into `materials` for each element.
    pub element_material: Vec<usize>,
    /// Region (the `*SOLID SECTION` ELSET) of each element, an index into `region_names`.
    pub element_region: Vec<usize>,
    pub region_names: Vec<String>,
    pub step: StepDef,
    /// Prescribed displacements (dof 0, 1, 2 = x, y, z).
    pub boundaries: Vec<BoundaryCondition>,
    /// Pressures on element faces (`*DLOAD`, label, `Pn`, value).
    pub pressures: Vec<FacePressure>,
    /// Concentrated forces (N).
    pub point_loads: Vec<PointLoad>,
}

/// Writes `deck` as an input deck that CalculiX 2.20 and [`super::read_inp3`] accept: the
/// layout of [`super::write_inp`] with `*NODE` lines `label, x, y, z`, no thickness line in
/// `*SOLID SECTION`, and the mesh's surfaces (`*SURFACE, NAME=, TYPE=ELEMENT`, `label, Sn`)
/// before the step.
pub fn write_inp3(deck: &Deck3, w: &mut impl Write) -> io::Result<()> {
    let mesh = &deck.mesh;
    let elements: Vec<WriteElement> = mesh
        .elements
        .iter()
        .map(|el| WriteElement {
            order: el.kind as usize,
            name: el.kind.deck_name(),
            nodes: el.nodes(),
            faces: el.kind.face_count(),
        })
        .collect();
    write_deck(
        &DeckParts {
            dim: 3,
            coordinates: mesh.nodes.as_flattened(),
            node_labels: &mesh.node_labels,
            elements: &elements,
            element_labels: &mesh.element_labels,
            element_sets: &mesh.element_sets,
            node_sets: &mesh.node_sets,
            surfaces: Some(&mesh.surfaces),
            materials: &deck.materials,
            element_material: &deck.element_material,
            element_region: &deck.element_region,
            region_names: &deck.region_names,
            step: &deck.step,
            boundaries: &deck.boundaries,
            pressures: &deck.pressures,
            point_loads: &deck.point_loads,
        },
        w,
    )
}

/// Writes `deck` to the file `path` with [`write_inp3`].
pub fn write_inp3_file(deck: &Deck3, path: &Path) -> io::Result<()> {
    crate::atomic::write_with(path, |w| write_inp3(deck, w))
}

/// The displacements `(node label, [ux, uy, uz])` of the last `displacements (vx,vy,vz) for set
/// NALL` block of a CalculiX `.dat` file (as [`super::parse_ccx_dat_displacements`], with the
/// third component; ccx prints 7 significant digits).
pub fn parse_ccx_dat_displacements3(text: &str, file_name: &str) -> Result<Vec<(i64, [f64; 3])>> {
    let header = format!("displacements (vx,vy,vz) for set {ALL_NODES_SET} and time");
    let lines: Vec<&str> = text.lines().collect();
    let Some(start) = lines
        .iter()
        .rposition(|l| l.trim_start().starts_with(&header))
    else {
        return Err(InpError::Deck {
            file: file_name.to_string(),
            message: format!("no '{header} ...' block"),
        });
    };
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate().skip(start + 1) {
        let t = l.trim();
        if t.is_empty() {
            if out.is_empty() {
                continue;
            }
            break;
        }
        let cols: Vec<&str> = t.split_whitespace().collect();
        let parsed = (|| {
            let label = cols.first()?.parse::<i64>().ok()?;
            let u: Vec<f64> = cols
                .get(1..4)?
                .iter()
                .map(|c| super::fortran_float(c))
                .collect::<Option<_>>()?;
            Some((label, [u[0], u[1], u[2]]))
        })();
        match parsed {
            Some(row) => out.push(row),
            None if out.is_empty() => {
                return Err(InpError::Line {
                    file: file_name.to_string(),
                    line: i + 1,
                    message: format!("cannot read '{t}' as 'node ux uy uz'"),
                })
            }
            None => break,
        }
    }
    Ok(out)
}
