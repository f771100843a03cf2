//! `[model]`, `[thigh]`, `[labels]`: where the model's mesh comes from, and its size.

use super::keys::ELEMENTS_RANGE;
use super::lines::{resolve, KeyLines};
use super::raw::{LabelsEntry, ModelEntry};
use super::StudyError;
use femu_geometry::ThighParams;
use femu_mesh::ElementKind;
use std::path::{Path, PathBuf};

/// Where the model comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// The built-in parametric thigh with these dimensions (`[thigh]`).
    Thigh(Box<ThighParams>),
    /// A segmented image (`[labels]`).
    Labels(LabelsSpec),
    /// An Abaqus/CalculiX deck (`[model] deck`): its materials and boundary conditions; the
    /// skin is the set of faces its `*DLOAD` loads (a contention deck, as `femu mesh` writes).
    Deck(PathBuf),
}

/// A label image to mesh (`[labels]`).
#[derive(Debug, Clone, PartialEq)]
pub struct LabelsSpec {
    pub image: PathBuf,
    /// `1=fat,2=quadriceps,...`
    pub map: String,
    pub bone: Vec<u32>,
    pub background: Vec<u32>,
    pub slice: Option<usize>,
    pub pixel_size_mm: Option<f64>,
    pub min_island_mm2: f64,
}

/// The element formulation of the generated quads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QuadElement {
    /// Fully integrated 4-node quad (2x2 Gauss).
    Cpe4,
    /// 4-node quad, hybrid with constant pressure (mean dilatation; the seed's CPE4H).
    Cpe4h,
}

impl QuadElement {
    /// The mesh's element kind.
    pub fn kind(self) -> ElementKind {
        match self {
            QuadElement::Cpe4 => ElementKind::Cpe4,
            QuadElement::Cpe4h => ElementKind::Cpe4h,
        }
    }
}

/// The mesh size of a generated model: a target element count or an element size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resolution {
    /// About this many quads (the built-in thigh).
    Elements(usize),
    /// Elements of about this size (mm).
    SizeMm(f64),
    /// The study gives none: the geometry's default (6 000 quads for the thigh, 1 mm for a
    /// label image; a deck brings its own mesh).
    Default,
}

/// Target element count of the built-in thigh when the study gives none.
pub const DEFAULT_ELEMENTS: usize = 6000;
/// Element size of a meshed label image when the study gives none (mm).
pub const DEFAULT_LABEL_SIZE_MM: f64 = 1.0;

/// Checks `[model]` and the geometry tables.
pub(crate) fn parse(
    model: ModelEntry,
    thigh: Option<ThighParams>,
    labels: Option<LabelsEntry>,
    lines: &KeyLines,
    base: &Path,
) -> Result<(Geometry, Resolution, QuadElement), StudyError> {
    if model.elements.is_some() && model.size_mm.is_some() {
        return Err(lines.err(
            "model",
            0,
            "size_mm",
            "give elements or size_mm, not both".into(),
        ));
    }
    if let Some(h) = model.size_mm {
        lines.at_most("model", 0, "size_mm", h, MAX_LENGTH_MM)?;
    }
    if let Some(n) = model.elements {
        super::keys::check_int("model", "elements", n)
            .map_err(|m| lines.err("model", 0, "elements", m))?;
    }
    let element = super::keys::word_or_default("model", "element", model.element.as_deref())
        .map_err(|m| lines.err("model", 0, "element", m))?;
    let element = match element {
        "cpe4h" => QuadElement::Cpe4h,
        "cpe4" => QuadElement::Cpe4,
        other => {
            return Err(lines.err(
                "model",
                0,
                "element",
                super::keys::unhandled("model", "element", other),
            ))
        }
    };
    let resolution = match (model.elements, model.size_mm) {
        (Some(n), _) => Resolution::Elements(n),
        (None, Some(h)) => Resolution::SizeMm(h),
        (None, None) => Resolution::Default,
    };
    let geometry = match (model.deck, thigh, labels) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) | (None, Some(_), Some(_)) => {
            return Err(StudyError::Study(
                "give one geometry: [thigh] (the built-in thigh), [labels] (a label image) or [model] deck"
                    .into(),
            ))
        }
        (Some(deck), None, None) => {
            if resolution != Resolution::Default {
                return Err(lines.err(
                    "model",
                    0,
                    "deck",
                    "a deck brings its own mesh; elements and size_mm do not apply".into(),
                ));
            }
            Geometry::Deck(resolve(base, &deck))
        }
        (None, thigh, None) => Geometry::Thigh(Box::new(check_thigh(thigh, resolution, lines)?)),
        (None, None, Some(l)) => {
            if model.elements.is_some() {
                return Err(lines.err(
                    "model",
                    0,
                    "elements",
                    "a label image is meshed by element size; give [model] size_mm".into(),
                ));
            }
            Geometry::Labels(check_labels(l, lines, base)?)
        }
    };
    Ok((geometry, resolution, element))
}

/// `[thigh]`: the dimensions of the built-in thigh, without its mesh-size keys, and `[model]`'s
/// mesh size for them (fine enough to keep every region: see
/// `femu_geometry::ThighParams::max_element_size_mm`).
pub(crate) fn check_thigh(
    thigh: Option<ThighParams>,
    resolution: Resolution,
    lines: &KeyLines,
) -> Result<ThighParams, StudyError> {
    let t = thigh.unwrap_or_default();
    if t.element_size_mm.is_some() || t.target_elements.is_some() {
        return Err(lines.err(
            "thigh",
            0,
            "",
            "give the mesh size in [model] (elements or size_mm)".into(),
        ));
    }
    let mut check = t.clone();
    check.target_elements = Some(t.min_target_elements().max(1000));
    check
        .validate()
        .map_err(|e| lines.err("thigh", 0, "", e.to_string()))?;
    match resolution {
        Resolution::Elements(n) => {
            thigh_elements(&t, n).map_err(|m| lines.err("model", 0, "elements", m))?
        }
        Resolution::SizeMm(h) => {
            let h_max = t.max_element_size_mm();
            if h > h_max {
                return Err(lines.err(
                    "model",
                    0,
                    "size_mm",
                    format!("{h} mm is too coarse for the thigh: at most {h_max:.2} mm keeps every region (the smallest muscles and the femur hole)"),
                ));
            }
        }
        Resolution::Default => {}
    }
    Ok(t)
}

/// Whether the built-in thigh `t` can be meshed with about `n` quads: within
/// [`ELEMENTS_RANGE`] and not below the count that keeps every region.
pub(crate) fn thigh_elements(t: &ThighParams, n: usize) -> Result<(), String> {
    if !ELEMENTS_RANGE.contains(&n) {
        return Err(format!("must be in [100, 500000], got {n}"));
    }
    let min = t.min_target_elements();
    if n < min {
        return Err(format!(
            "{n} is too few for the thigh: at least {min} keep every region (elements of at most {:.2} mm; fewer lose the small muscles and the femur hole)",
            t.max_element_size_mm()
        ));
    }
    Ok(())
}

/// The largest element or pixel size (mm): 100 mm, two thirds of the thigh's width.
pub(crate) const MAX_LENGTH_MM: f64 = 100.0;

fn check_labels(l: LabelsEntry, lines: &KeyLines, base: &Path) -> Result<LabelsSpec, StudyError> {
    if let Some(s) = l.pixel_size_mm {
        lines.at_most("labels", 0, "pixel_size_mm", s, MAX_LENGTH_MM)?;
    }
    // The thigh's cross-section is some 13 000 mm²: a threshold beyond 10 000 mm² (the
    // declared maximum) would merge whole muscles.
    let min_island = super::keys::check_real(
        "labels",
        "min_island_mm2",
        super::keys::or_default(l.min_island_mm2, "labels", "min_island_mm2"),
    )
    .map_err(|m| lines.err("labels", 0, "min_island_mm2", m))?;
    let background: Vec<u32> =
        super::keys::or_default(l.background.clone(), "labels", "background");
    femu_geometry::LabelSpec::new(&l.map, &l.bone, &background)
        .map_err(|e| lines.err("labels", 0, "map", e.to_string()))?;
    Ok(LabelsSpec {
        image: resolve(base, &l.image),
        map: l.map,
        bone: l.bone,
        background,
        slice: l.slice,
        pixel_size_mm: l.pixel_size_mm,
        min_island_mm2: min_island,
    })
}
