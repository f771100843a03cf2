//! The resolved content of an Abaqus/CalculiX input deck, independent of the file syntax.
//!
//! Sets named in the deck are resolved to indices by the reader; what is left here is what a
//! solver needs: the mesh, one material per element, boundary conditions and loads of one step.

use crate::mesh::Mesh;

/// A `*MATERIAL` with its `*HYPERELASTIC` law as the deck gives it: the law keyword and the
/// constants of its data line. This crate knows no mechanics: which keywords exist, what the
/// constants mean and which values are valid is decided by the material registry of `femu-mech`
/// (`femu_mech::material`), whose errors name [`MaterialDef::line`].
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialDef {
    pub name: String,
    /// The `*HYPERELASTIC` parameter naming the law, upper case with single blanks as written
    /// (`NEO HOOKE`, `MOONEY-RIVLIN`, `YEOH`).
    pub keyword: String,
    /// The numbers of the law's data line in deck order (MPa, MPa^-1); trailing values the deck
    /// leaves out are absent (Abaqus reads them as 0).
    pub constants: Vec<f64>,
    /// The 1-based deck line of the data line, for error messages (`None` for a deck built in
    /// code).
    pub line: Option<usize>,
}

/// A prescribed displacement of one degree of freedom (0 = x, 1 = y) of one node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryCondition {
    pub node: usize,
    pub dof: usize,
    /// Prescribed displacement at the end of the step (mm).
    pub value: f64,
}

/// A follower pressure (MPa) on face `face` (0-based: `P1` is 0) of element `element`;
/// positive pushes into the element, as in Abaqus `*DLOAD ... Pn`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacePressure {
    pub element: usize,
    pub face: usize,
    pub magnitude: f64,
}

/// A concentrated force (N per mm of thickness) on one dof (0 = x, 1 = y) of one node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLoad {
    pub node: usize,
    pub dof: usize,
    pub magnitude: f64,
}

/// `*STEP` / `*STATIC` settings (load-factor increments over the step period).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepDef {
    pub nlgeom: bool,
    /// Maximum number of increments (`INC=`, default 100 as in Abaqus).
    pub max_increments: usize,
    pub initial_increment: f64,
    pub period: f64,
    pub min_increment: f64,
    pub max_increment: f64,
}

impl Default for StepDef {
    fn default() -> Self {
        StepDef {
            nlgeom: true,
            max_increments: 100,
            initial_increment: 1.0,
            period: 1.0,
            min_increment: 1e-5,
            max_increment: 1.0,
        }
    }
}

/// A deck resolved to indices: mesh, materials, one material per element, one static step.
#[derive(Debug, Clone, Default)]
pub struct Deck {
    pub mesh: Mesh,
    pub materials: Vec<MaterialDef>,
    /// Index into `materials` for each element.
    pub element_material: Vec<usize>,
    /// Name of the region (the `*SOLID SECTION` ELSET) of each element, as an index into
    /// `region_names`.
    pub element_region: Vec<usize>,
    pub region_names: Vec<String>,
    pub step: StepDef,
    pub boundaries: Vec<BoundaryCondition>,
    pub pressures: Vec<FacePressure>,
    pub point_loads: Vec<PointLoad>,
}

impl Deck {
    /// Replaces the (follower) pressures by dead nodal forces equal to them on the reference
    /// geometry (`*CLOAD`): what a solver whose static follower pressure is unreliable (ccx 2.20)
    /// solves exactly. The deck's point loads are replaced.
    pub fn pressures_to_dead_loads(&mut self) {
        let mut f = vec![0.0; 2 * self.mesh.nodes.len()];
        for p in std::mem::take(&mut self.pressures) {
            let [a, b] = self.mesh.elements[p.element].face_nodes(p.face);
            let (xa, xb) = (self.mesh.nodes[a], self.mesh.nodes[b]);
            let h = 0.5 * p.magnitude;
            for n in [a, b] {
                f[2 * n] -= h * (xb[1] - xa[1]);
                f[2 * n + 1] += h * (xb[0] - xa[0]);
            }
        }
        self.point_loads = f
            .iter()
            .enumerate()
            .filter(|(_, v)| **v != 0.0)
            .map(|(i, &magnitude)| PointLoad {
                node: i / 2,
                dof: i % 2,
                magnitude,
            })
            .collect();
    }
}
