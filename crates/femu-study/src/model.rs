//! The model of a study: the geometry of `[thigh]`, `[labels]` or `[model] deck` meshed, its
//! materials (Table 1 or the deck's, with the study's `[materials]`), the femur fixed, no load
//! yet; and the skin faces the loading tests act on.

use crate::bail;
use crate::error::{Context, Result};
use crate::interfaces::model_with_interfaces;
use crate::schema::{read_deck, read_deck_split};
use crate::schema::{
    Geometry, LabelsSpec, MaterialSpec, ModelSpec, Resolution, Study, StudyError, DEFAULT_ELEMENTS,
    DEFAULT_LABEL_SIZE_MM,
};
use femu_geometry::{MeshOptions, ThighModel};
use femu_mech::loading::apply_loading;
use femu_mech::model::NamedMaterial;
use femu_mech::Model;
use femu_mesh::{Deck, ElementKind, FacePressure};
use std::path::Path;

/// A study's model before any loading.
pub struct StudyModel {
    pub model: Model,
    /// Skin faces `(element, face)`.
    pub skin: Vec<(usize, usize)>,
    /// The meshed thigh (built-in or label image); `None` for a deck.
    pub thigh: Option<ThighModel>,
    /// "parametric thigh", "label image IMAGE" or "deck FILE".
    pub source: String,
    /// The discretization check's meshes and solutions, for the next identification on this
    /// model.
    pub check_meshes: std::sync::Mutex<CheckMeshes>,
    /// Solutions of loaded copies of the model at the study's own material parameters, by
    /// loading ([`StudyModel::keep_reference_state`]): the forward step's, from which the
    /// virtual measurement and the identifications start Newton.
    pub reference_states: std::sync::Mutex<Vec<(String, Vec<f64>)>>,
}

/// The meshes of a discretization check and their last solutions, kept with the study's model
/// ([`StudyModel::check_meshes`], filled by `crate::steps::discretization::check`) for the
/// next check on it (the demo's grouped identification after the ungrouped one): the refined
/// meshes are built once, and Newton on each mesh starts from the solution at the earlier
/// check's parameters instead of the load increments.
#[derive(Default)]
pub struct CheckMeshes {
    pub(crate) levels: Vec<CachedLevel>,
}

/// One mesh of [`CheckMeshes`].
pub(crate) struct CachedLevel {
    pub(crate) ratio: f64,
    /// The measured tests' loadings (as printed) the models carry.
    pub(crate) tests: Vec<String>,
    pub(crate) elements: usize,
    /// The models of the measured tests on this mesh (none kept for the model's own mesh).
    pub(crate) models: Vec<Model>,
    /// Their last solved states.
    pub(crate) states: Vec<Option<Vec<f64>>>,
}

impl StudyModel {
    /// Keeps `state`, the solution of the model loaded with `loading` at its own material
    /// parameters, for later steps ([`StudyModel::reference_state`]).
    pub fn keep_reference_state(&self, loading: &femu_mech::loading::Loading, state: Vec<f64>) {
        let key = format!("{loading:?}");
        let mut kept = self
            .reference_states
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        kept.retain(|(k, _)| *k != key);
        kept.push((key, state));
    }

    /// The solution kept for `loading` ([`StudyModel::keep_reference_state`]), if any.
    pub fn reference_state(&self, loading: &femu_mech::loading::Loading) -> Option<Vec<f64>> {
        let key = format!("{loading:?}");
        self.reference_states
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, s)| s.clone())
    }

    /// A copy of the model with `test` applied on the skin.
    pub fn loaded(&self, test: &femu_mech::loading::Loading) -> Result<Model> {
        let mut model = self.model.clone();
        apply_loading(&mut model, &self.skin, test)
            .with_context(|| format!("test {}", test.name()))?;
        Ok(model)
    }
}

/// One material per region of `regions` (in that order, named as the region): Table 1 with
/// the study's `[materials]` (regions checked against `regions`). A Table 1 region's table
/// overrides its parameters (or gives it another law); a region outside Table 1 (`6=adductor`
/// in a label map) gets the whole material its table gives (Neo-Hookean unless `law` names
/// another; issue 32.13); a region with neither is an error naming the table to add. `femu
/// mesh labels --materials` and the study share it.
pub fn materials(specs: &[MaterialSpec], regions: &[String]) -> Result<Vec<NamedMaterial>> {
    let mut materials = crate::schema::table1();
    for spec in specs {
        let region = &spec.region;
        if !regions.iter().any(|r| r.eq_ignore_ascii_case(region)) {
            bail!(
                "[materials.{region}]: no such region in the model ({})",
                regions.join(", ")
            );
        }
        match materials
            .iter_mut()
            .find(|m| m.name.eq_ignore_ascii_case(region))
        {
            Some(m) => {
                m.law = spec
                    .apply(&*m.law)
                    .with_context(|| format!("[materials.{region}]"))?
            }
            None => materials.push(NamedMaterial {
                name: region.to_ascii_uppercase(),
                law: spec.build().with_context(|| {
                    format!("[materials.{region}]: {region} is not in Table 1, so its table gives its whole material")
                })?,
            }),
        }
    }
    regions
        .iter()
        .map(|r| {
            let m = materials.iter().find(|m| m.name.eq_ignore_ascii_case(r)).with_context(|| {
                format!(
                    "region {r} has no material (it is not in the seed's Table 1): add a [materials.{r}] table with c10_kpa and d_per_mpa (or law = \"...\" and its keys), or map its label to a Table 1 region"
                )
            })?;
            Ok(NamedMaterial {
                name: r.clone(),
                law: m.law.clone(),
            })
        })
        .collect()
}

/// The contention deck of a model (written for Abaqus/CalculiX): its own content with a
/// follower pressure `pressure_mpa` on every skin face.
pub fn contention_deck(model: &Model, skin: &[(usize, usize)], pressure_mpa: f64) -> Deck {
    let mut deck = model.to_deck();
    deck.pressures = skin
        .iter()
        .map(|&(element, face)| FacePressure {
            element,
            face,
            magnitude: pressure_mpa,
        })
        .collect();
    deck
}

/// The built-in thigh of `spec`'s dimensions meshed at `resolution`.
fn mesh_thigh(
    dims: &femu_geometry::ThighParams,
    resolution: Resolution,
    kind: ElementKind,
) -> Result<ThighModel> {
    let (target_elements, element_size_mm) = match resolution {
        Resolution::Elements(n) => (Some(n), None),
        Resolution::SizeMm(h) => (None, Some(h)),
        Resolution::Default => (Some(DEFAULT_ELEMENTS), None),
    };
    let params = femu_geometry::ThighParams {
        target_elements,
        element_size_mm,
        ..dims.clone()
    };
    femu_geometry::parametric_thigh(&params, kind).context("meshing the parametric thigh")
}

/// Builds the model a study describes.
pub fn build(spec: &ModelSpec) -> Result<StudyModel> {
    let kind = spec.element.kind();
    let (thigh, source) = match &spec.geometry {
        Geometry::Thigh(dims) => (
            mesh_thigh(dims, spec.resolution, kind)?,
            "parametric thigh".to_string(),
        ),
        Geometry::Labels(l) => (
            mesh_labels(l, label_size(spec.resolution), kind)?,
            format!("label image {}", l.image.display()),
        ),
        Geometry::Deck(path) => return deck_model(&spec.materials, path),
    };
    from_thigh(spec, thigh, source)
}

/// The element size of a meshed label image (mm).
fn label_size(resolution: Resolution) -> f64 {
    match resolution {
        Resolution::SizeMm(h) => h,
        _ => DEFAULT_LABEL_SIZE_MM,
    }
}

/// The label image of `l` meshed with elements of `size_mm`.
fn mesh_labels(l: &LabelsSpec, size_mm: f64, kind: ElementKind) -> Result<ThighModel> {
    let img = femu_geometry::read_label_image(&l.image, l.slice)
        .with_context(|| format!("[labels] image {}", l.image.display()))?;
    mesh_label_array(l, &img, size_mm, kind)
}

/// Builds the model of `spec`, a `[labels]` geometry, from its label image already in memory
/// (read from a file, or handed over by a script); `[labels] image` only names it in messages.
pub fn build_from_label_image(
    spec: &ModelSpec,
    img: &femu_geometry::LabelImage,
) -> Result<StudyModel> {
    let Geometry::Labels(l) = &spec.geometry else {
        bail!("internal: a label image for a model that is not a [labels] geometry");
    };
    let thigh = mesh_label_array(l, img, label_size(spec.resolution), spec.element.kind())?;
    from_thigh(spec, thigh, format!("label image {}", l.image.display()))
}

/// The label image `img` (of `l`, which only names it) meshed with elements of `size_mm`.
fn mesh_label_array(
    l: &LabelsSpec,
    img: &femu_geometry::LabelImage,
    size_mm: f64,
    kind: ElementKind,
) -> Result<ThighModel> {
    let labels = femu_geometry::LabelSpec::new(&l.map, &l.bone, &l.background)
        .context("[labels] map/bone/background")?;
    let options = MeshOptions {
        element_size_mm: size_mm,
        kind,
        min_island_mm2: l.min_island_mm2,
        ..MeshOptions::default()
    };
    femu_geometry::mesh_label_image(img, &labels, l.pixel_size_mm, &options)
        .with_context(|| format!("meshing {}", l.image.display()))
}

/// The model of a meshed thigh with the study's materials, femur fixed, no load.
fn from_thigh(spec: &ModelSpec, thigh: ThighModel, source: String) -> Result<StudyModel> {
    let regions = materials(&spec.materials, &thigh.regions)?;
    let (model, skin) = model_with_interfaces(&thigh, regions, &spec.interfaces)?;
    Ok(StudyModel {
        model,
        skin,
        thigh: Some(thigh),
        source,
        check_meshes: Default::default(),
        reference_states: Default::default(),
    })
}

/// The study's model `built` of `spec` on a finer mesh of the same geometry: the element size
/// divided by `ratio` (the built-in thigh on the raster of `built`'s mesh, as the convergence
/// study; a label image at the finer size; a deck's elements split in four, `log2 ratio`
/// times, the outline and interfaces on smooth curves through its nodes:
/// [`femu_convergence::split`]). `None` for a deck and a ratio that is not a power of two.
pub fn build_refined(
    spec: &ModelSpec,
    built: &StudyModel,
    ratio: f64,
) -> Result<Option<StudyModel>> {
    let kind = spec.element.kind();
    if let Geometry::Deck(path) = &spec.geometry {
        let times = ratio.log2().round();
        if !(times >= 1.0 && (times.exp2() - ratio).abs() < 1e-9) {
            return Ok(None);
        }
        let (deck_spec, skin) = read_deck_split(&spec.materials, path, times as usize)?;
        return Ok(Some(StudyModel {
            model: Model::new(deck_spec)?,
            skin,
            thigh: None,
            source: format!("{} split {times}x", built.source),
            check_meshes: Default::default(),
            reference_states: Default::default(),
        }));
    }
    let Some(h) = built.thigh.as_ref().map(|t| t.element_size_mm) else {
        return Ok(None);
    };
    let thigh = match &spec.geometry {
        Geometry::Thigh(dims) => femu_convergence::refined_thigh(dims, kind, h, ratio)
            .context("meshing the refined parametric thigh")?,
        Geometry::Labels(l) => mesh_labels(l, h / ratio, kind)?,
        Geometry::Deck(_) => return Ok(None),
    };
    let source = format!("{} refined {ratio:.3}x", built.source);
    from_thigh(spec, thigh, source).map(Some)
}

/// A deck: its materials (overridden by `[materials.NAME]`, NAME a material or a region), its
/// boundary conditions; the skin is the set of faces its `*DLOAD` loads, then removed.
fn deck_model(specs: &[MaterialSpec], path: &Path) -> Result<StudyModel> {
    let (spec, skin) = read_deck(specs, path)?;
    Ok(StudyModel {
        model: Model::new(spec)?,
        skin,
        thigh: None,
        source: format!("deck {}", path.display()),
        check_meshes: Default::default(),
        reference_states: Default::default(),
    })
}

/// A Gmsh mesh set up by the study's Gmsh view (`[materials]` per physical surface, `[[fixed]]`,
/// `[[pressure]]`, `[step]`, at most one rigid `[[test]]` on its `curve`).
pub fn gmsh_model(study: &Study, mesh: &Path) -> Result<Model> {
    use femu_mech::build::{curve_faces, deck_from_msh, MshSetup, RegionMaterial};
    let name = mesh.display().to_string();
    // A Gmsh mesh is taken as meshed: its physical surfaces share their nodes (tied).
    if let Some(i) = study
        .model
        .interfaces
        .iter()
        .find(|i| i.law != crate::schema::InterfaceLaw::Tied)
    {
        let [a, b] = &i.between;
        return Err(study
            .key_error(
                "interface",
                "kind",
                format!(
                    "between = [{a}, {b}]: a Gmsh mesh is not split along sliding interfaces (its physical surfaces stay tied); remove the table or give kind = \"tied\", or run the study on the built-in thigh or a label image"
                ),
            )
            .into());
    }
    let mut regions = Vec::new();
    for m in &study.model.materials {
        let law = m.build().map_err(|e| {
            study.key_error(
                &format!("materials.{}", m.region),
                "",
                format!("a Gmsh region needs its whole material: {e}"),
            )
        })?;
        regions.push(RegionMaterial {
            region: m.region.clone(),
            law,
        });
    }
    // The seed's default tests (no [[test]] given) do not apply to a Gmsh mesh.
    let rigid: Vec<_> = if study.tests_given() {
        study.tests.iter().collect()
    } else {
        Vec::new()
    };
    if rigid.len() > 1 || rigid.iter().any(|t| t.curve.is_none()) {
        return Err(StudyError::Study(
            "a Gmsh study takes at most one rigid [[test]] (compression or indentation) with the curve it presses on (curve = \"...\")"
                .into(),
        )
        .into());
    }
    let setup = MshSetup {
        quad_kind: study.model.element.kind(),
        materials: regions,
        displacements: study.boundary.fixed.clone(),
        pressures: study.boundary.pressures.clone(),
        step: study.boundary.step,
    };
    // The caller names the mesh and the study file in its context; these errors name the
    // region or curve.
    let msh = femu_mesh::read_msh(mesh)?;
    let faces = match rigid.first() {
        Some(t) => Some(curve_faces(&msh, t.curve.as_deref().expect("a curve"))?),
        None => None,
    };
    let deck = deck_from_msh(msh, &setup)?;
    let mut model = Model::from_deck(deck).with_context(|| format!("invalid model in {name}"))?;
    if let (Some(t), Some(faces)) = (rigid.first(), faces) {
        if !t.loading.has_rigid_body() {
            bail!("a contention on a Gmsh mesh is a [[pressure]] on the skin curve");
        }
        apply_loading(&mut model, &faces, &t.loading)?;
    }
    Ok(model)
}

/// The built-in parametric thigh (femu-geometry) with about `elements` quads of `kind` as a
/// model: Table 1 materials, the femur fixed, no load; and its skin faces.
pub fn thigh_model(elements: usize, kind: ElementKind) -> Result<(Model, Vec<(usize, usize)>)> {
    let params = femu_geometry::ThighParams {
        target_elements: Some(elements),
        ..Default::default()
    };
    if let Err(m) = crate::schema::thigh_elements(&params, elements) {
        bail!("the number of elements: {m}");
    }
    let thigh = femu_geometry::parametric_thigh(&params, kind)?;
    let regions = materials(&[], &thigh.regions)?;
    model_with_interfaces(&thigh, regions, &[])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deck is refined by splitting its elements: 4 and 16 times its elements at ratios 2 and
    /// 4, the same regions' areas within the smooth curves' change of the outline (the split's
    /// curved edges add a sliver along each chord), the skin's faces doubled per split, the
    /// femur still fixed; a ratio a split cannot make is `None`.
    #[test]
    fn a_deck_is_refined_by_splitting() {
        let (model, skin) = thigh_model(700, ElementKind::Cpe4h).unwrap();
        let deck = contention_deck(&model, &skin, 0.002);
        let dir = std::env::temp_dir().join(format!("femu-deck-split-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("thigh.inp");
        femu_mesh::write_inp(&deck, &mut std::fs::File::create(&path).unwrap()).unwrap();
        let spec = ModelSpec {
            geometry: Geometry::Deck(path),
            resolution: Resolution::Default,
            element: crate::schema::QuadElement::Cpe4h,
            materials: Vec::new(),
            interfaces: Vec::new(),
        };
        let built = build(&spec).unwrap();
        let area = |m: &Model| -> f64 {
            m.mesh
                .elements
                .iter()
                .map(|el| {
                    let n = el.nodes();
                    (0..n.len())
                        .map(|k| {
                            let (p, q) = (m.mesh.nodes[n[k]], m.mesh.nodes[n[(k + 1) % n.len()]]);
                            0.5 * (p[0] * q[1] - q[0] * p[1])
                        })
                        .sum::<f64>()
                })
                .sum()
        };
        let supports = built.model.constraints.len();
        for (ratio, factor) in [(2.0, 4), (4.0, 16)] {
            let fine = build_refined(&spec, &built, ratio).unwrap().unwrap();
            let e = built.model.mesh.elements.len();
            assert_eq!(fine.model.mesh.elements.len(), factor * e);
            assert_eq!(
                fine.skin.len(),
                (factor as f64).sqrt() as usize * built.skin.len()
            );
            // The curved chords move the outline by a fraction of a percent of the area (a
            // 600-element thigh: chords of some 4 mm on radii of 20 mm and more).
            let change = area(&fine.model) / area(&built.model) - 1.0;
            assert!(change.abs() < 5e-3 && change != 0.0, "area change {change}");
            assert!(fine.model.constraints.len() > supports);
        }
        assert!(build_refined(&spec, &built, std::f64::consts::SQRT_2)
            .unwrap()
            .is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
