//! The swept 3D thigh: volumes against the frustum formula, regions, surfaces and the deck.

use femu_geometry::thigh3d::{skin_patch_2d, sweep_thigh, Sweep};
use femu_geometry::{parametric_thigh, table1_materials, ThighParams};
use femu_mesh::ElementKind;

fn section() -> femu_geometry::ThighModel {
    parametric_thigh(&ThighParams::coarse(), ElementKind::Cpe4h).expect("coarse thigh")
}

/// A tapered sweep: no inverted element, the total and every region's volume equal the
/// frustum of the section's meshed area (the swept hexahedra are polyhedra with planar faces,
/// so the only error is round-off: 1e-12 relative), and the boundary is exactly the skin, the
/// femur and the two ends.
#[test]
fn tapered_sweep_has_the_frustum_volume_and_its_regions() {
    let model = section();
    let mut sweep = Sweep::uniform(60.0, 6);
    sweep.end_scale = 0.8;
    let t = sweep_thigh(&model, &sweep).unwrap();
    let m = &t.mesh;
    m.check_orientation().unwrap();
    assert_eq!(m.elements.len(), 6 * model.mesh.mesh.elements.len());
    assert_eq!(m.nodes.len(), 7 * model.mesh.mesh.nodes.len());
    let section_area: f64 = t.section_areas_mm2.values().sum();
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
    let expected = t.frustum_volume(section_area);
    // 60 (1 + 0.8 + 0.64) / 3 = 48.8 mm per mm² of section.
    assert!((expected / section_area - 48.8).abs() < 1e-12);
    assert!(
        rel(m.volume(), expected) < 1e-12,
        "{} vs {expected}",
        m.volume()
    );
    for (region, &area) in &t.section_areas_mm2 {
        let v = m.set_volume(region).unwrap();
        assert!(rel(v, t.frustum_volume(area)) < 1e-12, "{region}: {v}");
    }
    // Boundary faces: skin, femur and the two ends, and nothing else.
    let mut named: Vec<(usize, usize)> = ["SKIN", "FEMUR", "END0", "END1"]
        .iter()
        .flat_map(|s| m.surface(s).unwrap().iter().copied())
        .collect();
    named.sort_unstable();
    assert_eq!(named, m.boundary_faces());
    // The skin's faces point away from the axis; the ends along ∓z.
    for &(e, f) in m.surface("SKIN").unwrap() {
        let a = m.face_area_vector(e, f);
        let c = m.face_centroid(e, f);
        assert!(a[0] * c[0] + a[1] * c[1] > 0.0);
    }
    for (s, sign) in [("END0", -1.0), ("END1", 1.0)] {
        for &(e, f) in m.surface(s).unwrap() {
            assert!(sign * m.face_area_vector(e, f)[2] > 0.0);
        }
    }
}

/// A probe footprint on the skin: 40 mm along the axis by 10 mm across, its area close to
/// 400 mm² (the section's patch is the set of whole faces within 5 mm of the centre, so the
/// width is rounded to faces of about 3 mm: within 40 %), and a deck with the Table 1
/// materials, the femur fixed in 3 dofs and, in plane strain, the ends held along z.
#[test]
fn skin_patch_and_deck() {
    let model = section();
    let t = sweep_thigh(&model, &Sweep::uniform(80.0, 16)).unwrap();
    let patch = t.skin_patch(&model, 90.0, 10.0, 40.0, 40.0);
    let patch_2d = skin_patch_2d(&model, 90.0, 10.0);
    assert_eq!(patch.len(), 8 * patch_2d.len());
    let area: f64 = patch
        .iter()
        .map(|&(e, f)| {
            let a = t.mesh.face_area_vector(e, f);
            (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
        })
        .sum();
    assert!((area / 400.0 - 1.0).abs() < 0.4, "{area}");
    for &(e, f) in &patch {
        let c = t.mesh.face_centroid(e, f);
        assert!((20.0..=60.0).contains(&c[2]) && c[1] > 40.0, "{c:?}");
    }
    let deck = t.deck(&table1_materials(), &patch, 2e-3, true).unwrap();
    let femur = t.mesh.node_set("FEMUR").unwrap().len();
    let ends =
        2 * model.mesh.mesh.nodes.len() - 2 * model.mesh.mesh.node_set("FEMUR").unwrap().len();
    assert_eq!(deck.boundaries.len(), 3 * femur + ends);
    assert_eq!(deck.pressures.len(), patch.len());
    assert_eq!(deck.materials.len(), t.regions.len());
    let fat = deck.materials.iter().find(|m| m.name == "FAT").unwrap();
    assert_eq!(fat.constants, vec![0.8e-3, 30.8]);
}

#[test]
fn bad_sweeps_are_refused() {
    let model = section();
    let mut s = Sweep::uniform(10.0, 2);
    s.end_scale = 0.0;
    assert!(sweep_thigh(&model, &s)
        .unwrap_err()
        .to_string()
        .contains("end_scale"));
    let s = Sweep {
        levels: vec![0.0, 5.0, 5.0],
        ..Sweep::uniform(10.0, 2)
    };
    assert!(sweep_thigh(&model, &s)
        .unwrap_err()
        .to_string()
        .contains("levels"));
}
