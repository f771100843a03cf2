//! A 3D thigh: the 2D cross-section's all-quad mesh ([`ThighModel`]) swept along the femur
//! axis `z` into hexahedra (C3D8H by default), with a linear taper: the section at height `z`
//! is the reference section scaled about the skin centre by
//! `s(z) = 1 + (end_scale - 1) z / L`, `L` the length.
//!
//! Quad `[a, b, c, d]` (counter-clockwise seen from `+z`) between the levels `z_k` and
//! `z_{k+1}` becomes the hexahedron `[a_k, b_k, c_k, d_k, a_{k+1}, b_{k+1}, c_{k+1}, d_{k+1}]`,
//! so that the quad's face `Pn` (joining its local nodes n and n + 1) is the hexahedron's face
//! `S(n + 2)` ([`femu_mesh::mesh3d`]). Element `k · n_quads + q` is quad q in layer k.
//!
//! Sets of the swept mesh: the region element sets of the section (same names, so that the
//! Table 1 materials apply by name), node sets `FEMUR` and `SKIN` (their nodes on every level),
//! `END0` (`z = 0`) and `END1` (`z = L`), surfaces `SKIN`, `FEMUR`, `END0`, `END1` (outward
//! faces).
//!
//! Every side face of a swept hexahedron is planar (its four corners lie on two lines through
//! the apex of the taper's cone), so the mesh is a polyhedron of volume `A L (1 + s + s²) / 3`
//! (the frustum of the section area `A` and the end scale `s`), which
//! [`Thigh3::frustum_volume`] gives for the checks.

use std::collections::BTreeMap;

use femu_mesh::deck::{BoundaryCondition, FacePressure, MaterialDef, StepDef};
use femu_mesh::mesh3d::{Element3, ElementKind3, Mesh3};
use femu_mesh::Deck3;

use crate::error::GeometryError;
use crate::mesher::ThighModel;

/// How the section is swept: the levels of the layers and the taper.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// The levels `0 = z_0 < z_1 < … < z_n = L` (mm) between the layers of hexahedra.
    pub levels: Vec<f64>,
    /// Scale of the section at `z = L` relative to `z = 0` (1 = a prism), in (0, 2].
    pub end_scale: f64,
    /// C3D8H (mean dilatation, the 3D CPE4H) or C3D8.
    pub kind: ElementKind3,
}

impl Sweep {
    /// `layers` equal layers over `length_mm`, no taper, C3D8H.
    pub fn uniform(length_mm: f64, layers: usize) -> Sweep {
        Sweep {
            levels: (0..=layers)
                .map(|k| length_mm * k as f64 / layers.max(1) as f64)
                .collect(),
            end_scale: 1.0,
            kind: ElementKind3::C3d8h,
        }
    }

    /// Layers of `fine_mm` over `[z0 - half, z0 + half]` (`half` a multiple of `fine_mm`
    /// within the length), growing by the factor `growth` per layer away from it, the last
    /// layer on each side stretched or shrunk to end at 0 and `length_mm`.
    pub fn graded(length_mm: f64, z0: f64, half: f64, fine_mm: f64, growth: f64) -> Sweep {
        let mut levels = vec![z0 - half];
        let mut z = z0 - half;
        while z < z0 + half - 0.5 * fine_mm {
            z += fine_mm;
            levels.push(z);
        }
        let mut h = fine_mm;
        let mut up = z;
        let mut above = Vec::new();
        while up < length_mm - 0.5 * h * growth {
            h *= growth;
            up += h;
            above.push(up.min(length_mm));
        }
        if above.last().is_none_or(|&v| v < length_mm) {
            match above.last_mut() {
                Some(v) if length_mm - *v < 0.5 * h => *v = length_mm,
                _ => above.push(length_mm),
            }
        }
        let mut h = fine_mm;
        let mut down = z0 - half;
        let mut below = Vec::new();
        while down > 0.5 * h * growth {
            h *= growth;
            down -= h;
            below.push(down.max(0.0));
        }
        match below.last_mut() {
            Some(v) if *v < 0.5 * h => *v = 0.0,
            _ => below.push(0.0),
        }
        below.dedup();
        below.reverse();
        below.retain(|&v| v < z0 - half);
        let mut all = below;
        all.extend(levels);
        all.extend(above.into_iter().filter(|&v| v > z));
        all.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        Sweep {
            levels: all,
            end_scale: 1.0,
            kind: ElementKind3::C3d8h,
        }
    }

    fn scale(&self, z: f64) -> f64 {
        let length = *self.levels.last().expect("levels");
        1.0 + (self.end_scale - 1.0) * z / length
    }
}

/// The swept thigh.
#[derive(Debug, Clone)]
pub struct Thigh3 {
    pub mesh: Mesh3,
    /// Region (element-set) names, in the order of the section's.
    pub regions: Vec<String>,
    /// The sweep that made it.
    pub sweep: Sweep,
    /// The number of quads of the section (elements per layer).
    pub quads: usize,
    /// Meshed area of each region of the section at `z = 0` (mm²).
    pub section_areas_mm2: BTreeMap<String, f64>,
}

/// Sweeps the quads of `model` along `z` (module documentation).
pub fn sweep_thigh(model: &ThighModel, sweep: &Sweep) -> Result<Thigh3, GeometryError> {
    let levels = &sweep.levels;
    if levels.len() < 2
        || levels[0] != 0.0
        || levels.windows(2).any(|w| !(w[1] > w[0]))
        || !levels.iter().all(|z| z.is_finite())
    {
        return Err(GeometryError::param(
            "levels",
            format!("{levels:?}"),
            "must start at 0 and increase (at least one layer)",
        ));
    }
    if !(sweep.end_scale > 0.0 && sweep.end_scale <= 2.0) {
        return Err(GeometryError::param(
            "end_scale",
            sweep.end_scale,
            "must be in (0, 2]",
        ));
    }
    if !matches!(sweep.kind, ElementKind3::C3d8 | ElementKind3::C3d8h) {
        return Err(GeometryError::param(
            "kind",
            sweep.kind.deck_name(),
            "a swept quad mesh is made of hexahedra (C3D8 or C3D8H)",
        ));
    }
    let m2 = &model.mesh.mesh;
    let (nn, nq) = (m2.nodes.len(), m2.elements.len());
    if m2.elements.iter().any(|e| e.kind.node_count() != 4) {
        return Err(GeometryError::Meshing(
            "the section must be all quads to be swept into hexahedra".into(),
        ));
    }
    let mut mesh = Mesh3::default();
    for &z in levels {
        let s = sweep.scale(z);
        for p in &m2.nodes {
            mesh.add_node([s * p[0], s * p[1], z]);
        }
    }
    let layers = levels.len() - 1;
    for k in 0..layers {
        for el in &m2.elements {
            let c = el.nodes();
            let (lo, hi) = (k * nn, (k + 1) * nn);
            let nodes = [
                c[0] + lo,
                c[1] + lo,
                c[2] + lo,
                c[3] + lo,
                c[0] + hi,
                c[1] + hi,
                c[2] + hi,
                c[3] + hi,
            ];
            mesh.add_element(Element3::new(sweep.kind, &nodes));
        }
    }
    for (name, set) in &m2.element_sets {
        mesh.element_sets.insert(
            name.clone(),
            (0..layers)
                .flat_map(|k| set.iter().map(move |&q| k * nq + q))
                .collect(),
        );
    }
    for name in ["FEMUR", "SKIN"] {
        if let Some(set) = m2.node_set(name) {
            mesh.node_sets.insert(
                name.into(),
                (0..=layers)
                    .flat_map(|k| set.iter().map(move |&n| k * nn + n))
                    .collect(),
            );
        }
        if let Some(faces) = model.mesh.surfaces.get(name) {
            mesh.surfaces.insert(
                name.into(),
                (0..layers)
                    .flat_map(|k| faces.iter().map(move |&(q, f)| (k * nq + q, f + 2)))
                    .collect(),
            );
        }
    }
    mesh.node_sets.insert("END0".into(), (0..nn).collect());
    mesh.node_sets
        .insert("END1".into(), (layers * nn..(layers + 1) * nn).collect());
    mesh.surfaces
        .insert("END0".into(), (0..nq).map(|q| (q, 0)).collect());
    mesh.surfaces.insert(
        "END1".into(),
        (0..nq).map(|q| ((layers - 1) * nq + q, 1)).collect(),
    );
    mesh.check_orientation()
        .map_err(|e| GeometryError::Meshing(e.to_string()))?;
    Ok(Thigh3 {
        mesh,
        regions: model.regions.clone(),
        sweep: sweep.clone(),
        quads: nq,
        section_areas_mm2: model.region_areas(),
    })
}

/// The skin faces `(element, face)` of the section `model` whose midpoints lie within
/// `width_mm / 2` (straight distance) of the skin point in the direction `angle_deg` from the
/// skin centre (0 = lateral, 90 = anterior): a probe footprint's width on the section.
pub fn skin_patch_2d(model: &ThighModel, angle_deg: f64, width_mm: f64) -> Vec<(usize, usize)> {
    let m = &model.mesh.mesh;
    let faces = model
        .mesh
        .surfaces
        .get("SKIN")
        .map_or(&[][..], Vec::as_slice);
    let mid = |&(e, f): &(usize, usize)| {
        let [a, b] = m.elements[e].face_nodes(f);
        [
            0.5 * (m.nodes[a][0] + m.nodes[b][0]),
            0.5 * (m.nodes[a][1] + m.nodes[b][1]),
        ]
    };
    let (sin, cos) = angle_deg.to_radians().sin_cos();
    // The skin point: the face midpoint farthest along the direction among those nearest to it
    // in angle.
    let Some(centre) = faces.iter().map(mid).min_by(|p, q| {
        let ang = |p: &[f64; 2]| {
            (p[1] * cos - p[0] * sin)
                .atan2(p[0] * cos + p[1] * sin)
                .abs()
        };
        ang(p).total_cmp(&ang(q))
    }) else {
        return Vec::new();
    };
    faces
        .iter()
        .filter(|f| {
            let p = mid(f);
            (p[0] - centre[0]).hypot(p[1] - centre[1]) <= 0.5 * width_mm
        })
        .copied()
        .collect()
}

impl Thigh3 {
    /// The length `L` (mm).
    pub fn length(&self) -> f64 {
        *self.sweep.levels.last().expect("levels")
    }

    /// The volume of the frustum of the section's area `area_mm2` over the length:
    /// `A L (1 + s + s²) / 3` (`s` the end scale; `A L` for a prism).
    pub fn frustum_volume(&self, area_mm2: f64) -> f64 {
        let s = self.sweep.end_scale;
        area_mm2 * self.length() * (1.0 + s + s * s) / 3.0
    }

    /// The skin faces of a probe footprint: the section's patch of `width_mm`
    /// ([`skin_patch_2d`]) on the layers whose mid-height lies within `length_mm / 2` of
    /// `z_centre`.
    pub fn skin_patch(
        &self,
        model: &ThighModel,
        angle_deg: f64,
        width_mm: f64,
        z_centre: f64,
        length_mm: f64,
    ) -> Vec<(usize, usize)> {
        let patch = skin_patch_2d(model, angle_deg, width_mm);
        let levels = &self.sweep.levels;
        (0..levels.len() - 1)
            .filter(|&k| (0.5 * (levels[k] + levels[k + 1]) - z_centre).abs() <= 0.5 * length_mm)
            .flat_map(|k| patch.iter().map(move |&(q, f)| (k * self.quads + q, f + 2)))
            .collect()
    }

    /// A deck of the thigh: `materials` by region name (e.g. [`crate::table1_materials`]),
    /// the femur's nodes fixed in x, y and z, a pressure `pressure_mpa` on `faces`, and with
    /// `plane_strain` the end faces held along the axis (u_z = 0 on `END0` and `END1`).
    pub fn deck(
        &self,
        materials: &[MaterialDef],
        faces: &[(usize, usize)],
        pressure_mpa: f64,
        plane_strain: bool,
    ) -> Result<Deck3, GeometryError> {
        let mesh = &self.mesh;
        let n = mesh.elements.len();
        let mut deck = Deck3 {
            mesh: mesh.clone(),
            element_material: vec![usize::MAX; n],
            element_region: vec![usize::MAX; n],
            step: StepDef::default(),
            ..Default::default()
        };
        for (r, name) in self.regions.iter().enumerate() {
            let m = materials
                .iter()
                .find(|m| m.name.eq_ignore_ascii_case(name))
                .ok_or_else(|| GeometryError::NoMaterial(name.clone()))?;
            deck.materials.push(MaterialDef {
                name: name.clone(),
                ..m.clone()
            });
            deck.region_names.push(name.clone());
            for &e in mesh.element_set(name).unwrap_or(&[]) {
                deck.element_material[e] = r;
                deck.element_region[e] = r;
            }
        }
        if let Some(e) = deck.element_region.iter().position(|&r| r == usize::MAX) {
            return Err(GeometryError::Meshing(format!(
                "element {} belongs to no region",
                mesh.element_labels[e]
            )));
        }
        let femur = mesh.node_set("FEMUR").unwrap_or(&[]);
        for &node in femur {
            for dof in 0..3 {
                deck.boundaries.push(BoundaryCondition {
                    node,
                    dof,
                    value: 0.0,
                });
            }
        }
        if plane_strain {
            let on_femur: std::collections::HashSet<usize> = femur.iter().copied().collect();
            for end in ["END0", "END1"] {
                for &node in mesh.node_set(end).unwrap_or(&[]) {
                    if !on_femur.contains(&node) {
                        deck.boundaries.push(BoundaryCondition {
                            node,
                            dof: 2,
                            value: 0.0,
                        });
                    }
                }
            }
        }
        deck.pressures = faces
            .iter()
            .map(|&(element, face)| FacePressure {
                element,
                face,
                magnitude: pressure_mpa,
            })
            .collect();
        Ok(deck)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_levels_cover_the_length_with_the_fine_window() {
        let s = Sweep::graded(120.0, 60.0, 20.0, 4.0, 1.5);
        let l = &s.levels;
        assert_eq!(l[0], 0.0);
        assert_eq!(*l.last().unwrap(), 120.0);
        assert!(l.windows(2).all(|w| w[1] > w[0]), "{l:?}");
        for z in [40.0, 44.0, 60.0, 76.0, 80.0] {
            assert!(l.iter().any(|&v| (v - z).abs() < 1e-9), "{z} in {l:?}");
        }
        let u = Sweep::uniform(10.0, 4);
        assert_eq!(u.levels, vec![0.0, 2.5, 5.0, 7.5, 10.0]);
    }
}
