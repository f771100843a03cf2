//! Building decks and models in code (tests, benchmarks, generated meshes), without a file.
//!
//! Unknown set names panic: the builder is for programs, whose set names are fixed in code;
//! user input goes through the deck reader and its errors.

use femu_mesh::generate::GeneratedMesh;
use femu_mesh::{BoundaryCondition, Deck, FacePressure, MaterialDef, StepDef};

/// Assembles a [`Deck`] from a generated mesh: one material per element set (in the order
/// given), node sets fixed in both directions, follower pressure on named surfaces.
#[derive(Debug, Clone)]
pub struct DeckBuilder {
    deck: Deck,
    surfaces: std::collections::BTreeMap<String, Vec<(usize, usize)>>,
}

impl DeckBuilder {
    /// Starts from a generated mesh (no materials, no loads).
    pub fn new(g: GeneratedMesh) -> Self {
        let n = g.mesh.elements.len();
        DeckBuilder {
            deck: Deck {
                mesh: g.mesh,
                element_material: vec![usize::MAX; n],
                element_region: vec![usize::MAX; n],
                step: StepDef::default(),
                ..Default::default()
            },
            surfaces: g.surfaces,
        }
    }

    /// Assigns a Neo-Hookean material (C10 in MPa, D in MPa^-1) to element set `elset`;
    /// the set becomes a region of the same name.
    pub fn material(mut self, elset: &str, c10: f64, d: f64) -> Self {
        let m = self.deck.materials.len();
        self.deck.materials.push(MaterialDef {
            name: elset.to_string(),
            c10,
            d1: d,
        });
        self.deck.region_names.push(elset.to_string());
        let set = self
            .deck
            .mesh
            .element_set(elset)
            .unwrap_or_else(|| panic!("DeckBuilder: unknown element set '{elset}'"))
            .to_vec();
        for e in set {
            self.deck.element_material[e] = m;
            self.deck.element_region[e] = m;
        }
        self
    }

    /// The same material on every element (region `ALL`).
    pub fn material_everywhere(mut self, c10: f64, d: f64) -> Self {
        let n = self.deck.mesh.elements.len();
        self.deck
            .mesh
            .element_sets
            .insert("ALL".into(), (0..n).collect());
        self.material("ALL", c10, d)
    }

    /// The nodes of a set; an unknown name is a programming error of the caller.
    fn node_set(&self, nset: &str) -> Vec<usize> {
        self.deck
            .mesh
            .node_set(nset)
            .unwrap_or_else(|| panic!("DeckBuilder: unknown node set '{nset}'"))
            .to_vec()
    }

    /// Prescribes displacement `value` on dof `dof` (0 = x, 1 = y) of every node of `nset`.
    pub fn displacement(mut self, nset: &str, dof: usize, value: f64) -> Self {
        for node in self.node_set(nset) {
            self.deck
                .boundaries
                .push(BoundaryCondition { node, dof, value });
        }
        self
    }

    /// Prescribes a displacement computed from the reference position on every node of `nset`.
    pub fn displacement_field(mut self, nset: &str, f: impl Fn([f64; 2]) -> [f64; 2]) -> Self {
        for node in self.node_set(nset) {
            let u = f(self.deck.mesh.nodes[node]);
            for (dof, value) in u.into_iter().enumerate() {
                self.deck
                    .boundaries
                    .push(BoundaryCondition { node, dof, value });
            }
        }
        self
    }

    /// Fixes both dofs of every node of `nset`.
    pub fn fix(self, nset: &str) -> Self {
        self.displacement(nset, 0, 0.0).displacement(nset, 1, 0.0)
    }

    /// Follower pressure `p` (MPa) on every face of surface `surface`.
    pub fn pressure(mut self, surface: &str, p: f64) -> Self {
        let faces = self
            .surfaces
            .get(surface)
            .unwrap_or_else(|| panic!("DeckBuilder: unknown surface '{surface}'"))
            .clone();
        for (element, face) in faces {
            self.deck.pressures.push(FacePressure {
                element,
                face,
                magnitude: p,
            });
        }
        self
    }

    /// Step settings.
    pub fn step(mut self, step: StepDef) -> Self {
        self.deck.step = step;
        self
    }

    /// The deck.
    pub fn build(self) -> Deck {
        self.deck
    }
}
