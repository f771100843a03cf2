//! The study's deck (`[model] deck`) read as a model spec with the study's `[materials]`
//! applied: the study check reads its materials' laws, the model is built from it.

use super::MaterialSpec;
use crate::bail;
use crate::error::{Context, Result};
use femu_mech::model::ModelSpec as MechSpec;
use std::path::Path;

/// A study's deck as a model spec, the study's `[materials]` applied, its `*DLOAD` faces made
/// the surface `SKIN` (the loads removed), and those faces.
pub(crate) fn read_deck(
    specs: &[MaterialSpec],
    path: &Path,
) -> Result<(MechSpec, Vec<(usize, usize)>)> {
    read_deck_split(specs, path, 0)
}

/// [`read_deck`] with every element split `times` times in four (`femu_convergence::split`:
/// the element size halved each time, the outline and interfaces on smooth curves).
pub(crate) fn read_deck_split(
    specs: &[MaterialSpec],
    path: &Path,
    times: usize,
) -> Result<(MechSpec, Vec<(usize, usize)>)> {
    let mut deck = femu_mesh::read_inp(path)?;
    if times > 0 {
        deck = femu_convergence::split_deck_times(&deck, times)
            .map_err(|e| crate::input!("{}: {e}", path.display()))?;
    }
    let mut spec = MechSpec::from_deck(deck)?;
    if spec.pressures.is_empty() {
        bail!(
            "{}: the deck has no *DLOAD: its pressure faces define the skin the tests load (write a contention deck, e.g. with femu mesh)",
            path.display()
        );
    }
    let skin: Vec<(usize, usize)> = spec.pressures.iter().map(|p| (p.element, p.face)).collect();
    spec.pressures.clear();
    spec.surfaces.insert("SKIN".into(), skin.clone());
    for m_spec in specs {
        let name = &m_spec.region;
        let by_material = spec
            .materials
            .iter()
            .position(|m| m.name.eq_ignore_ascii_case(name));
        let by_region = spec
            .region_names
            .iter()
            .position(|r| r.eq_ignore_ascii_case(name))
            .and_then(|r| {
                spec.element_region
                    .iter()
                    .position(|&e| e == r)
                    .map(|e| spec.element_material[e])
            });
        let m = by_material.or(by_region).with_context(|| {
            format!(
                "[materials.{name}]: the deck {} has no such material or region",
                path.display()
            )
        })?;
        spec.materials[m].law = m_spec
            .apply(&*spec.materials[m].law)
            .with_context(|| format!("[materials.{name}]"))?;
    }
    Ok((spec, skin))
}
