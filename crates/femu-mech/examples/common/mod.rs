//! Shared by the cost examples (`assembly_cost`, `factorization_cost`, `sensitivity_cost`):
//! their arguments and the built-in thigh at paper scale.

use femu_mech::Model;
use femu_mesh::{Deck, ElementKind};

/// The arguments `[elements] [repeat] [cpe4|cpe4h]`.
pub struct CostArgs {
    pub elements: usize,
    pub repeat: usize,
    pub kind: ElementKind,
}

/// Reads [`CostArgs`] from the command line: 25 000 elements by default, `repeat` and `kind`
/// as given here when absent.
pub fn cost_args(repeat: usize, kind: ElementKind) -> CostArgs {
    let mut args = std::env::args().skip(1);
    CostArgs {
        elements: args.next().and_then(|a| a.parse().ok()).unwrap_or(25_000),
        repeat: args.next().and_then(|a| a.parse().ok()).unwrap_or(repeat),
        kind: match args.next().as_deref() {
            Some("cpe4") => ElementKind::Cpe4,
            Some("cpe4h") => ElementKind::Cpe4h,
            _ => kind,
        },
    }
}

/// The built-in thigh with about `elements` quads of `kind` as a contention deck (Table 1
/// materials, femur fixed, 20 mmHg on the skin), and its skin faces.
pub fn thigh_deck(elements: usize, kind: ElementKind) -> (Deck, Vec<(usize, usize)>) {
    let params = femu_geometry::ThighParams {
        target_elements: Some(elements),
        ..Default::default()
    };
    let thigh = femu_geometry::parametric_thigh(&params, kind).expect("thigh");
    let skin = thigh.mesh.surfaces.get("SKIN").cloned().unwrap_or_default();
    let deck = femu_geometry::contention_deck(
        &thigh,
        &femu_geometry::table1_materials(),
        femu_geometry::CONTENTION_MPA,
    )
    .expect("deck");
    (deck, skin)
}

/// Prints the model's size and the thread count.
pub fn print_model(model: &Model, kind: ElementKind) {
    println!(
        "built-in thigh: {} {kind:?} elements, {} nodes, {} threads",
        model.mesh.elements.len(),
        model.node_count(),
        rayon::current_num_threads()
    );
}
