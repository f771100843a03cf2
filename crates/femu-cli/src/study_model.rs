//! The model of a study: the geometry of `[thigh]`, `[labels]` or `[model] deck` meshed, its
//! materials (Table 1 or the deck's, with the study's overrides), the femur fixed, no load yet;
//! and the skin faces the loading tests act on.

use crate::plan::{Geometry, Plan};
use anyhow::{bail, Context, Result};
use femu_geometry::{table1_materials, MeshOptions, ThighModel};
use femu_mech::material::{material_def, material_from_def, set_from_keys};
use femu_mech::Model;
use femu_mesh::MaterialDef;

/// A study's model before any loading.
pub struct StudyModel {
    pub model: Model,
    /// Skin faces `(element, face)`.
    pub skin: Vec<(usize, usize)>,
    /// The meshed thigh (built-in or label image); `None` for a deck.
    pub thigh: Option<ThighModel>,
    /// "parametric thigh", "label image IMAGE" or "deck FILE".
    pub source: String,
}

/// Target element count of the built-in thigh when the study gives none.
pub const DEFAULT_ELEMENTS: usize = 6000;

/// Table 1 with the study's `[materials]` overrides (regions checked against `regions`).
fn materials(plan: &Plan, regions: &[String]) -> Result<Vec<MaterialDef>> {
    let mut materials = table1_materials();
    for (region, c10, d) in &plan.materials {
        if !regions.iter().any(|r| r.eq_ignore_ascii_case(region)) {
            bail!(
                "[materials.{region}]: no such region in the model ({})",
                regions.join(", ")
            );
        }
        let m = materials
            .iter_mut()
            .find(|m| m.name.eq_ignore_ascii_case(region))
            .with_context(|| format!("[materials.{region}]: not a Table 1 region"))?;
        override_parameters(m, *c10, *d).with_context(|| format!("[materials.{region}]"))?;
    }
    for r in regions {
        if !materials.iter().any(|m| m.name.eq_ignore_ascii_case(r)) {
            bail!(
                "region {r} has no material: map its label to a Table 1 region (fat, quadriceps, ischio, gracilis, sartorius)"
            );
        }
    }
    Ok(materials)
}

/// Sets C10 and D (MPa, MPa⁻¹) of a deck material through the material registry.
fn override_parameters(m: &mut MaterialDef, c10: Option<f64>, d: Option<f64>) -> Result<()> {
    let keys = (c10.map(|c| ("c10_mpa", c)).into_iter()).chain(d.map(|d| ("d_per_mpa", d)));
    let mut law = material_from_def(m)?;
    set_from_keys(&mut *law, keys)?;
    *m = material_def(&m.name, &*law);
    Ok(())
}

/// Builds the study's model.
pub fn study_model(plan: &Plan) -> Result<StudyModel> {
    let kind = plan.element.kind();
    let (thigh, source) = match &plan.geometry {
        Geometry::Thigh(dims) => {
            let params = femu_geometry::ThighParams {
                target_elements: if plan.size_mm.is_some() {
                    None
                } else {
                    Some(plan.elements.unwrap_or(DEFAULT_ELEMENTS))
                },
                element_size_mm: plan.size_mm,
                ..(**dims).clone()
            };
            (
                femu_geometry::parametric_thigh(&params, kind)
                    .context("meshing the parametric thigh")?,
                "parametric thigh".to_string(),
            )
        }
        Geometry::Labels(l) => {
            let spec = femu_geometry::LabelSpec::new(&l.map, &l.bone, &l.background)
                .context("[labels] map/bone/background")?;
            let img = femu_geometry::read_label_image(&l.image, l.slice)
                .with_context(|| format!("[labels] image {}", l.image.display()))?;
            let options = MeshOptions {
                element_size_mm: plan.size_mm.unwrap_or(1.0),
                kind,
                min_island_mm2: l.min_island_mm2,
                ..MeshOptions::default()
            };
            (
                femu_geometry::mesh_label_image(&img, &spec, l.pixel_size_mm, &options)
                    .with_context(|| format!("meshing {}", l.image.display()))?,
                format!("label image {}", l.image.display()),
            )
        }
        Geometry::Deck(path) => return deck_model(plan, path),
    };
    let materials = materials(plan, &thigh.regions)?;
    let skin = thigh.mesh.surfaces.get("SKIN").cloned().unwrap_or_default();
    if skin.is_empty() {
        bail!("the model has no skin surface");
    }
    let mut deck = femu_geometry::contention_deck(&thigh, &materials, 0.0)?;
    deck.pressures.clear();
    Ok(StudyModel {
        model: Model::from_deck(deck)?,
        skin,
        thigh: Some(thigh),
        source,
    })
}

/// A deck: its materials (overridden by `[materials.NAME]`, NAME a material or a region), its
/// boundary conditions; the skin is the set of faces its `*DLOAD` loads, then removed.
fn deck_model(plan: &Plan, path: &std::path::Path) -> Result<StudyModel> {
    let mut deck = femu_mesh::read_inp(path)?;
    if deck.pressures.is_empty() {
        bail!(
            "{}: the deck has no *DLOAD: its pressure faces define the skin the tests load (write a contention deck, e.g. with femu mesh)",
            path.display()
        );
    }
    let skin: Vec<(usize, usize)> = deck.pressures.iter().map(|p| (p.element, p.face)).collect();
    deck.pressures.clear();
    for (name, c10, d) in &plan.materials {
        let by_material = deck
            .materials
            .iter()
            .position(|m| m.name.eq_ignore_ascii_case(name));
        let by_region = deck
            .region_names
            .iter()
            .position(|r| r.eq_ignore_ascii_case(name))
            .and_then(|r| {
                deck.element_region
                    .iter()
                    .position(|&e| e == r)
                    .map(|e| deck.element_material[e])
            });
        let m = by_material.or(by_region).with_context(|| {
            format!(
                "[materials.{name}]: the deck {} has no such material or region",
                path.display()
            )
        })?;
        override_parameters(&mut deck.materials[m], *c10, *d)
            .with_context(|| format!("[materials.{name}]"))?;
    }
    Ok(StudyModel {
        model: Model::from_deck(deck)?,
        skin,
        thigh: None,
        source: format!("deck {}", path.display()),
    })
}
