//! Fixtures shared by the femu-mech integration tests.

use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::Model;
use femu_mesh::ElementKind;

/// The built-in thigh with about `elements` quads of `kind`, Table 1 materials, femur fixed,
/// under `loading`.
pub fn thigh_model(elements: usize, kind: ElementKind, loading: &Loading) -> Model {
    let t = parametric_thigh(
        &ThighParams {
            target_elements: Some(elements),
            ..Default::default()
        },
        kind,
    )
    .unwrap();
    let skin = t.mesh.surfaces["SKIN"].clone();
    let mut deck = contention_deck(&t, &table1_materials(), 0.0).unwrap();
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).unwrap();
    apply_loading(&mut model, &skin, loading).unwrap();
    model
}
