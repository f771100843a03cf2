//! `[convergence]`: the mesh and element validation of `femu convergence` (seed §2.1.2.1) on
//! the built-in thigh, with the study's `[thigh]`, `[materials]`, a `[[test]]` and `[grid]`.
//!
//! ```toml
//! [convergence]
//! element_types = ["CPE4H", "CPE4", "CPE3"]  # element types compared (CPE3: each quad split in two)
//! target_elements = [1500, 3000, 6000, 12000, 25000, 50000]   # the mesh sequence, or
//! # element_size_mm = [4.0, 2.0, 1.0]       # ... element sizes (one of the two)
//! tolerance_mm = 1e-4                       # the seed's criterion (§2.1.2.1)
//! locking = true                            # the nearly incompressible study (D x d_scale)
//! d_scale = 1e-3                            # ... on the locking_meshes coarsest meshes
//! locking_meshes = 2
//! # raster_mm = 0.13                        # shape raster, one for all meshes (default h_min/4)
//! # test = "contention"                     # the [[test]] run on every mesh (default: the first)
//! ```
//!
//! The comparison points are `[grid]` with its `origin_mm` and `spacing_mm` (default: the
//! seed's 64 x 64 window under the anterior probe, [`DicGrid::seed_default`]).

use super::geometry::{Geometry, Resolution};
use super::lines::KeyLines;
use super::loading_tests::TestSpec;
use super::materials::MaterialSpec;
use super::measurement::GridSpec;
use super::raw::ConvergenceEntry;
use super::StudyError;
use femu_convergence::{ConvergenceStudy, DicGrid, MeshSequence};
use femu_mech::model::NamedMaterial;
use femu_mesh::ElementKind;

/// The `[convergence]` table, checked.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ConvergenceSpec {
    pub element_types: Option<Vec<ElementKind>>,
    pub meshes: Option<MeshSequence>,
    pub tolerance_mm: Option<f64>,
    pub locking: Option<bool>,
    pub d_scale: Option<f64>,
    pub locking_meshes: Option<usize>,
    pub raster_mm: Option<f64>,
    /// Index of the study's test run on every mesh.
    pub test: usize,
    /// Whether the study has the table at all.
    pub given: bool,
}

/// Checks `[convergence]` (the ranges are checked with the whole view, see [`view`]).
pub(crate) fn parse(
    entry: Option<ConvergenceEntry>,
    tests: &[TestSpec],
    lines: &KeyLines,
) -> Result<ConvergenceSpec, StudyError> {
    let Some(c) = entry else {
        return Ok(ConvergenceSpec::default());
    };
    let err = |key: &str, message: String| lines.err("convergence", 0, key, message);
    let element_types = match c.element_types {
        None => None,
        Some(names) => {
            let mut kinds = Vec::new();
            for n in &names {
                let k = ElementKind::from_deck_name(n).ok_or_else(|| {
                    err(
                        "element_types",
                        format!("'{n}' is not an element type (CPE4, CPE4H, CPE3)"),
                    )
                })?;
                if kinds.contains(&k) {
                    return Err(err("element_types", format!("'{n}' is listed twice")));
                }
                kinds.push(k);
            }
            Some(kinds)
        }
    };
    let meshes = match (c.target_elements, c.element_size_mm) {
        (Some(_), Some(_)) => {
            return Err(err(
                "element_size_mm",
                "give either target_elements or element_size_mm, not both".into(),
            ))
        }
        (Some(v), None) => Some(MeshSequence::TargetElements(v)),
        (None, Some(v)) => Some(MeshSequence::ElementSizes(v)),
        (None, None) => None,
    };
    let test = match &c.test {
        None => 0,
        Some(name) => tests
            .iter()
            .position(|t| {
                let n = t.loading.name();
                n.eq_ignore_ascii_case(name)
                    || n.split('-')
                        .next()
                        .is_some_and(|k| k.eq_ignore_ascii_case(name))
            })
            .ok_or_else(|| err("test", format!("no test '{name}' in [[test]]")))?,
    };
    Ok(ConvergenceSpec {
        element_types,
        meshes,
        tolerance_mm: c.tolerance_mm,
        locking: c.locking,
        d_scale: c.d_scale,
        locking_meshes: c.locking_meshes,
        raster_mm: c.raster_mm,
        test,
        given: true,
    })
}

/// The parts of a study the convergence view reads.
pub(crate) struct ViewInputs<'a> {
    pub spec: &'a ConvergenceSpec,
    pub geometry: &'a Geometry,
    pub resolution: Resolution,
    pub materials: &'a [MaterialSpec],
    pub tests: &'a [TestSpec],
    pub grid: Option<&'a GridSpec>,
}

/// The convergence study of a study file, checked in full (ranges included); errors name the
/// key and its line.
pub(crate) fn view(v: ViewInputs, lines: &KeyLines) -> Result<ConvergenceStudy, StudyError> {
    let Geometry::Thigh(thigh) = v.geometry else {
        return Err(StudyError::Study(
            "the convergence study runs on the built-in thigh ([thigh]); a label image or a deck cannot be remeshed by it"
                .into(),
        ));
    };
    if v.resolution != Resolution::Default {
        return Err(lines.err(
            "model",
            0,
            "",
            "the meshes of a convergence study come from [convergence] target_elements or element_size_mm, not [model]"
                .into(),
        ));
    }
    let mut study = ConvergenceStudy {
        thigh: (**thigh).clone(),
        ..ConvergenceStudy::default()
    };
    let s = v.spec;
    study.elements = match &s.element_types {
        Some(k) => k.clone(),
        None => super::keys::default::<Vec<String>>("convergence", "element_types")
            .iter()
            .map(|n| {
                ElementKind::from_deck_name(n)
                    .unwrap_or_else(|| panic!("[convergence] element_types: the declared '{n}'"))
            })
            .collect(),
    };
    study.meshes = match &s.meshes {
        Some(m) => m.clone(),
        None => {
            MeshSequence::TargetElements(super::keys::default("convergence", "target_elements"))
        }
    };
    let declared = |key: &str| super::keys::default::<f64>("convergence", key);
    study.tolerance_mm = s.tolerance_mm.unwrap_or_else(|| declared("tolerance_mm"));
    study.locking = super::keys::or_default(s.locking, "convergence", "locking");
    study.d_scale = s.d_scale.unwrap_or_else(|| declared("d_scale"));
    study.locking_meshes =
        super::keys::or_default(s.locking_meshes, "convergence", "locking_meshes");
    study.raster_mm = s.raster_mm;
    study.materials = table1_with(v.materials, lines)?;
    study.loading = v.tests[s.test].loading.clone();
    if let Some(g) = v.grid {
        let (Some(origin_mm), Some(spacing_mm)) = (g.origin, g.spacing) else {
            return Err(lines.err(
                "grid",
                0,
                "",
                "the convergence study compares the meshes at fixed points: give origin_mm and spacing_mm"
                    .into(),
            ));
        };
        study.grid = DicGrid {
            origin_mm,
            spacing_mm,
            counts: g.counts,
        };
    }
    study.validate().map_err(|(key, message)| {
        let at = match key.split_once('.') {
            Some((table, k)) => lines.at(table, 0, k),
            None if key == "thigh" => lines.at("thigh", 0, ""),
            None => lines.at("convergence", 0, &key),
        };
        StudyError::key(at, message)
    })?;
    Ok(study)
}

/// Table 1 with the study's `[materials]` (regions of the built-in thigh only).
fn table1_with(
    materials: &[MaterialSpec],
    lines: &KeyLines,
) -> Result<Vec<NamedMaterial>, StudyError> {
    let mut out = super::table1();
    for m in materials {
        let table = format!("materials.{}", m.region);
        let entry = out
            .iter_mut()
            .find(|x| x.name.eq_ignore_ascii_case(&m.region))
            .ok_or_else(|| {
                lines.err(
                    &table,
                    0,
                    "",
                    "not a region of the built-in thigh (fat, quadriceps, ischio, gracilis, sartorius)".into(),
                )
            })?;
        entry.law = m
            .apply(&*entry.law)
            .map_err(|e| lines.err(&table, 0, "", e.to_string()))?;
    }
    Ok(out)
}
