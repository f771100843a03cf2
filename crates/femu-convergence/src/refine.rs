//! Refined meshes of the same geometry: what an identification's discretization check solves
//! on (`femu_identify::discretization`). As in a convergence study, the built-in thigh's shapes
//! are sampled on one raster, so that every mesh discretizes one geometry and the differences
//! between them are the discretization's alone.

use femu_geometry::{parametric_thigh_on_raster, GeometryError, ThighModel, ThighParams};
use femu_mesh::ElementKind;

/// The raster [`femu_geometry::parametric_thigh`] samples the shapes on for elements of
/// `element_size_mm` (a quarter of it, within [0.1, 0.25] mm).
pub fn default_raster_mm(element_size_mm: f64) -> f64 {
    (element_size_mm / 4.0).clamp(0.1, 0.25)
}

/// The built-in thigh `params` meshed with elements of `element_size_mm / ratio` on the raster
/// a mesh of `element_size_mm` has by default: the geometry of `parametric_thigh(params)` at
/// that size, finer.
pub fn refined_thigh(
    params: &ThighParams,
    kind: ElementKind,
    element_size_mm: f64,
    ratio: f64,
) -> Result<ThighModel, GeometryError> {
    if !(ratio >= 1.0 && ratio.is_finite()) {
        return Err(GeometryError::InvalidParameter {
            name: "refinement ratio".into(),
            value: ratio.to_string(),
            reason: "must be at least 1".into(),
        });
    }
    let fine = ThighParams {
        element_size_mm: Some(element_size_mm / ratio),
        target_elements: None,
        ..params.clone()
    };
    parametric_thigh_on_raster(&fine, kind, Some(default_raster_mm(element_size_mm)))
}
