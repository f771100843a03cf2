//! The convergence study: the meshes, element types, tolerance, locking check and comparison
//! points of the seed's mesh validation (§2.1.2.1). The study file's `[convergence]` table
//! (femu-study) describes it; [`ConvergenceStudy::validate`] checks its ranges.

use femu_geometry::{ThighParams, TABLE1};
use femu_mech::loading::Loading;
use femu_mech::model::NamedMaterial;
use femu_mesh::ElementKind;
use serde::Deserialize;

/// The mesh sequence: target element counts or element sizes, coarse to fine.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshSequence {
    /// About this many quads per mesh.
    TargetElements(Vec<usize>),
    /// Element sizes (mm).
    ElementSizes(Vec<f64>),
}

impl MeshSequence {
    /// The raster (mm) shared by every mesh of the sequence: a quarter of the finest element
    /// size (estimated from the tissue area for counts), clamped to [0.1, 0.25] mm like the
    /// default of [`femu_geometry::parametric_thigh`].
    pub fn raster_mm(&self, tissue_area_mm2: f64) -> f64 {
        let h_min = match self {
            MeshSequence::TargetElements(v) => {
                (tissue_area_mm2 / *v.iter().max().unwrap_or(&1) as f64).sqrt()
            }
            MeshSequence::ElementSizes(v) => v.iter().copied().fold(f64::INFINITY, f64::min),
        };
        (h_min / 4.0).clamp(0.1, 0.25)
    }

    /// Number of meshes.
    pub fn len(&self) -> usize {
        match self {
            MeshSequence::TargetElements(v) => v.len(),
            MeshSequence::ElementSizes(v) => v.len(),
        }
    }

    /// True if there is no mesh.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The common comparison points: a regular grid, as the DIC measures (seed §2.4.1: 64 x 64
/// points, 16 px apart).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DicGrid {
    /// Lower-left point of the grid (model frame, mm).
    pub origin_mm: [f64; 2],
    /// Distance between neighbouring points (mm).
    pub spacing_mm: f64,
    /// Number of points `[along x, along y]`.
    pub counts: [usize; 2],
}

impl DicGrid {
    /// The seed's grid: 64 x 64 points 16 px apart. The seed does not give one consistent pixel
    /// size (its noise of 1.5 px = 1.76e-2 mm would mean 0.012 mm/px, its abstract's 0.2 mm
    /// noise about 0.13 mm/px); at 0.1 mm/px, typical of a linear-probe B-mode image, the points
    /// are 1.6 mm apart and the window is 100.8 mm wide. It is centred medio-laterally on the
    /// default thigh with its top row on the anterior skin (y = 60 mm), under the probe, so it
    /// covers the quadriceps, the sartorius, the femur (masked) and the front of the ischio.
    pub fn seed_default() -> DicGrid {
        let spacing = 16.0 * 0.1;
        let span = 63.0 * spacing;
        DicGrid {
            origin_mm: [-0.5 * span, 60.0 - span],
            spacing_mm: spacing,
            counts: [64, 64],
        }
    }

    /// The points, row by row from the lower left (x fastest).
    pub fn points(&self) -> Vec<[f64; 2]> {
        let mut p = Vec::with_capacity(self.counts[0] * self.counts[1]);
        for j in 0..self.counts[1] {
            for i in 0..self.counts[0] {
                p.push([
                    self.origin_mm[0] + i as f64 * self.spacing_mm,
                    self.origin_mm[1] + j as f64 * self.spacing_mm,
                ]);
            }
        }
        p
    }
}

/// A validated convergence study.
#[derive(Debug, Clone)]
pub struct ConvergenceStudy {
    /// The built-in thigh's dimensions (its mesh-size keys unset: the sequence sets them).
    pub thigh: ThighParams,
    /// Materials per region (Table 1 unless overridden).
    pub materials: Vec<NamedMaterial>,
    /// The loading test.
    pub loading: Loading,
    /// Element types compared, in the order given.
    pub elements: Vec<ElementKind>,
    /// The meshes, coarse to fine; the finest is the reference.
    pub meshes: MeshSequence,
    /// A mesh is accepted when its largest displacement difference from the finest at the
    /// common points is below this (mm).
    pub tolerance_mm: f64,
    /// Whether to run the nearly incompressible (locking) study.
    pub locking: bool,
    /// Factor on every D of the locking study (0 < d_scale < 1).
    pub d_scale: f64,
    /// The locking study runs on this many of the coarsest meshes.
    pub locking_meshes: usize,
    /// Raster of the parametric shapes (mm), the same for every mesh so that all discretize
    /// one geometry; by default a quarter of the finest element size, in [0.1, 0.25].
    pub raster_mm: Option<f64>,
    /// The common comparison points.
    pub grid: DicGrid,
}

impl Default for ConvergenceStudy {
    /// The seed's setup: the built-in thigh with Table 1, the contention test (20 mmHg), CPE4H,
    /// CPE4 and CPE3, six meshes from 1 500 to 50 000 quads (the seed tested 6 000 to 26 000
    /// nodes and kept 25 392 elements), tolerance 1e-4 mm, locking with D / 1000, the seed's
    /// 64 x 64 grid.
    fn default() -> Self {
        ConvergenceStudy {
            thigh: ThighParams::default(),
            materials: TABLE1
                .iter()
                .map(|&(region, c10_kpa, d)| NamedMaterial::neo_hookean(region, c10_kpa * 1e-3, d))
                .collect(),
            loading: Loading::seed_contention(),
            elements: vec![ElementKind::Cpe4h, ElementKind::Cpe4, ElementKind::Cpe3],
            meshes: MeshSequence::TargetElements(vec![1500, 3000, 6000, 12_000, 25_000, 50_000]),
            tolerance_mm: 1e-4,
            locking: true,
            d_scale: 1e-3,
            locking_meshes: 2,
            raster_mm: None,
            grid: DicGrid::seed_default(),
        }
    }
}

impl ConvergenceStudy {
    /// Checks the ranges; on failure returns the key and the reason.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let key = |k: &str, m: String| Err((k.to_string(), m));
        if self.elements.is_empty() {
            return key("elements", "give at least one element type".into());
        }
        match &self.meshes {
            MeshSequence::TargetElements(v) => {
                if v.len() < 3 {
                    return key(
                        "target_elements",
                        format!("give at least 3 meshes (a rate needs two differences from the finest), got {}", v.len()),
                    );
                }
                if let Some(n) = v.iter().find(|n| !(100..=500_000).contains(*n)) {
                    return key("target_elements", format!("{n} is outside [100, 500000]"));
                }
                let min = self.thigh.min_target_elements();
                if let Some(n) = v.iter().find(|n| **n < min) {
                    return key(
                        "target_elements",
                        format!("{n} is too few for the thigh: at least {min} keep every region"),
                    );
                }
                if v.windows(2).any(|w| w[1] <= w[0]) {
                    return key("target_elements", "must increase (coarse to fine)".into());
                }
            }
            MeshSequence::ElementSizes(v) => {
                if v.len() < 3 {
                    return key(
                        "element_size_mm",
                        format!("give at least 3 meshes, got {}", v.len()),
                    );
                }
                if let Some(h) = v.iter().find(|h| !(**h >= 0.2 && **h <= 20.0)) {
                    return key("element_size_mm", format!("{h} is outside [0.2, 20] mm"));
                }
                let h_max = self.thigh.max_element_size_mm();
                if let Some(h) = v.iter().find(|h| **h > h_max) {
                    return key(
                        "element_size_mm",
                        format!("{h} mm is too coarse for the thigh: at most {h_max:.2} mm keeps every region"),
                    );
                }
                if v.windows(2).any(|w| w[1] >= w[0]) {
                    return key("element_size_mm", "must decrease (coarse to fine)".into());
                }
            }
        }
        // Beyond 10 mm (the tests' largest displacements) every mesh would pass.
        if !(self.tolerance_mm > 0.0 && self.tolerance_mm <= 10.0) {
            return key(
                "tolerance_mm",
                format!("must be in (0, 10] mm, got {}", self.tolerance_mm),
            );
        }
        if !(self.d_scale > 0.0 && self.d_scale < 1.0) {
            return key(
                "d_scale",
                format!(
                    "must be in (0, 1) (D smaller: nearly incompressible), got {}",
                    self.d_scale
                ),
            );
        }
        if self.locking && !(1..=self.meshes.len()).contains(&self.locking_meshes) {
            return key(
                "locking_meshes",
                format!(
                    "must be in [1, {}] (the number of meshes)",
                    self.meshes.len()
                ),
            );
        }
        if let Some(px) = self.raster_mm {
            if !(0.05..=0.5).contains(&px) {
                return key("raster_mm", format!("must be in [0.05, 0.5] mm, got {px}"));
            }
        }
        let g = &self.grid;
        if !(g.spacing_mm > 0.0 && g.spacing_mm.is_finite()) {
            return key(
                "grid.spacing_mm",
                format!("must be positive, got {}", g.spacing_mm),
            );
        }
        if !(g.origin_mm[0].is_finite() && g.origin_mm[1].is_finite()) {
            return key("grid.origin_mm", "must be finite".into());
        }
        if g.counts[0] == 0
            || g.counts[1] == 0
            || g.counts[0].saturating_mul(g.counts[1]) > 1_000_000
        {
            return key(
                "grid.counts",
                format!("{:?}: between 1 and 1e6 points", g.counts),
            );
        }
        let mut t = self.thigh.clone();
        t.target_elements = Some(t.min_target_elements().max(1000));
        t.validate()
            .map_err(|e| ("thigh".to_string(), e.to_string()))?;
        Ok(())
    }
}
