//! Fixtures shared by the femu-mech integration tests.

use femu_geometry::{contention_deck, parametric_thigh, table1_materials, ThighParams};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::Model;
use femu_mesh::generate::{self, GeneratedMesh};
use femu_mesh::ElementKind;

/// The built-in thigh with about `elements` quads of `kind`, Table 1 materials, femur fixed,
/// under `loading`.
#[allow(dead_code)] // not every test binary solves the thigh
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

/// A `w x h` block centred on x = 0 (x in [-w/2, w/2], y in [0, h]), graded towards the top
/// centre with `sinh` stretching (smallest spacing at x = 0 and y = h).
#[allow(dead_code)] // not every test binary meshes a block
pub fn graded_block(
    w: f64,
    h: f64,
    nx: usize,
    ny: usize,
    beta: f64,
    kind: ElementKind,
) -> GeneratedMesh {
    let mut g = generate::rectangle(1.0, 1.0, nx, ny, kind);
    for p in g.mesh.nodes.iter_mut() {
        let xi = 2.0 * p[0] - 1.0;
        let eta = 1.0 - p[1];
        let sx = if beta > 0.0 {
            (beta * xi).sinh() / beta.sinh()
        } else {
            xi
        };
        let sy = if beta > 0.0 {
            (beta * eta).sinh() / beta.sinh()
        } else {
            eta
        };
        *p = [0.5 * w * sx, h * (1.0 - sy)];
    }
    g
}
