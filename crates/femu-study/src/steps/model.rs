//! The model step (`femu mesh`, and the first step of `femu run`): a meshed thigh's folder
//!
//! - `mesh.inp` — the contention deck (the materials, femur fixed, 20 mmHg on the skin,
//!   element sets per region, node sets `FEMUR` and `SKIN`, surfaces `SKIN` and `FEMUR`),
//!   runnable by CalculiX and `femu solve` as is;
//! - `mesh.vtu` — the mesh for ParaView (cell fields `region`, `scaled_jacobian`); for a study
//!   with a sliding `[[interface]]`, the mesh split along it (its nodes duplicated), as solved;
//! - `regions.png` — a picture of the regions with a legend and axes in mm (and the sliding
//!   interfaces, where the mesh is split);
//! - `quality.csv`, `quality.json` — scaled Jacobian, aspect ratio and angles per region;
//! - `summary.json` — inputs, counts, areas (meshed vs source), warnings, timings;
//!
//! or, for a deck, its mesh with the materials (VTU), the element quality and a summary.

use crate::bail;
use crate::error::{Context, Result};
use crate::model::StudyModel;
use crate::output::{create_dir, write_json, write_text};
use crate::progress::Progress;
use crate::schema::{Geometry, QuadElement};
use femu_geometry::{
    contention_deck, mesh_label_image, parametric_thigh, quality_report, read_label_image,
    table1_materials, write_inp_with_surfaces, write_regions_png, write_regions_vtu, LabelSpec,
    MeshOptions, QualityReport, ThighModel, ThighParams, CONTENTION_MPA,
};
use femu_mesh::FieldWriter;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A region of a meshed thigh.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RegionSummary {
    pub elements: usize,
    pub area_mm2: f64,
    pub source_area_mm2: f64,
    pub area_error_percent: f64,
}

/// `summary.json` of a meshed thigh.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeshSummary {
    pub femu_version: String,
    pub command: String,
    /// The inputs as given (parametric dimensions, or the label image and its map).
    pub input: serde_json::Value,
    pub element: String,
    pub element_size_mm: f64,
    /// Nodes of the meshed thigh (`mesh.inp`).
    pub nodes: usize,
    /// Nodes of the model as solved (`mesh.vtu`): the meshed thigh's, plus the copies a
    /// sliding interface makes of its nodes; equal to `nodes` without one.
    #[serde(default)]
    pub nodes_as_solved: usize,
    pub elements: usize,
    pub regions: BTreeMap<String, RegionSummary>,
    pub femur_hole_area_mm2: f64,
    pub femur_source_area_mm2: f64,
    pub femur_area_error_percent: f64,
    pub skin_length_mm: f64,
    pub femur_nodes: usize,
    pub skin_faces: usize,
    pub contention_pressure_mpa: f64,
    pub quality: QualityReport,
    pub warnings: Vec<String>,
    pub files: Vec<String>,
    pub timings: BTreeMap<String, f64>,
}

/// `summary.json` of a deck's model folder.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DeckModelSummary {
    pub femu_version: String,
    pub command: String,
    pub input: String,
    pub nodes: usize,
    pub elements: usize,
    pub skin_faces: usize,
    pub quality: QualityReport,
}

/// What `femu mesh thigh` meshes.
#[derive(Debug, Clone)]
pub struct ThighMeshRequest {
    pub params: ThighParams,
    /// The TOML file the dimensions came from, if any (recorded in the summary).
    pub params_file: Option<PathBuf>,
    pub element: QuadElement,
}

/// What `femu mesh labels` meshes.
#[derive(Debug, Clone)]
pub struct LabelMeshRequest {
    pub image: PathBuf,
    pub pixel_size_mm: Option<f64>,
    pub map: String,
    pub bone: Vec<u32>,
    pub background: Vec<u32>,
    pub slice: Option<usize>,
    pub size_mm: f64,
    pub min_island_mm2: f64,
    pub element: QuadElement,
    /// `[materials.REGION]` tables (`--materials FILE`): a region outside Table 1 needs one.
    pub materials: Vec<crate::schema::MaterialSpec>,
}

/// `femu mesh thigh`: the built-in thigh meshed into `out`.
pub fn mesh_thigh(req: &ThighMeshRequest, out: &Path, progress: &dyn Progress) -> Result<()> {
    let t0 = Instant::now();
    req.params.validate().context("invalid thigh dimensions")?;
    let kind = req.element.kind();
    let model = parametric_thigh(&req.params, kind).context("meshing the parametric thigh")?;
    let input = serde_json::json!({ "model": "parametric thigh", "params": req.params, "params_file": req.params_file });
    let mesh_s = t0.elapsed().as_secs_f64();
    write_model_folder(
        &model,
        &table1_materials(),
        &ModelFolder {
            input,
            kind,
            command: "mesh thigh",
            out,
            mesh_s,
            split: None,
        },
        progress,
    )
}

/// `femu mesh labels`: a segmented image meshed into `out`.
pub fn mesh_labels(req: &LabelMeshRequest, out: &Path, progress: &dyn Progress) -> Result<()> {
    let t0 = Instant::now();
    femu_mesh::folder::refuse_inputs_in(out, &[&req.image])?;
    let spec = LabelSpec::new(&req.map, &req.bone, &req.background)
        .context("--map/--bone/--background")?;
    // Every region's material before anything is read or meshed: Table 1, or the
    // `--materials` file's table for a region outside it (issue 32.13).
    let materials: Vec<_> = crate::model::materials(&req.materials, &spec.region_names())
        .context("--map and --materials")?
        .iter()
        .map(|m| m.to_def())
        .collect();
    if let Some(s) = req.pixel_size_mm {
        if !(s > 0.0) || !s.is_finite() {
            bail!("--pixel-size must be a positive number of mm, got {s}");
        }
    }
    let img = read_label_image(&req.image, req.slice)?;
    let kind = req.element.kind();
    let options = MeshOptions {
        element_size_mm: req.size_mm,
        kind,
        min_island_mm2: req.min_island_mm2,
        ..MeshOptions::default()
    };
    let model = mesh_label_image(&img, &spec, req.pixel_size_mm, &options)
        .with_context(|| format!("meshing {}", req.image.display()))?;
    let input = serde_json::json!({
        "model": "label image",
        "image": req.image.display().to_string(),
        "width": img.width,
        "height": img.height,
        "pixel_size_mm": req.pixel_size_mm.map(|s| [s, s]).or(img.pixel_size_mm),
        "slice": req.slice,
        "map": spec.regions,
        "bone": spec.bone,
        "background": spec.background,
        "min_island_mm2": req.min_island_mm2,
    });
    let mesh_s = t0.elapsed().as_secs_f64();
    write_model_folder(
        &model,
        &materials,
        &ModelFolder {
            input,
            kind,
            command: "mesh labels",
            out,
            mesh_s,
            split: None,
        },
        progress,
    )
}

/// How a meshed thigh's folder is described.
pub struct ModelFolder<'a> {
    /// The inputs, recorded in the summary.
    pub input: serde_json::Value,
    pub kind: femu_mesh::ElementKind,
    /// `mesh thigh` or `mesh labels`.
    pub command: &'a str,
    pub out: &'a Path,
    /// Seconds spent meshing.
    pub mesh_s: f64,
    /// The thigh split along the study's sliding interfaces (the model as solved): drawn and
    /// written to `mesh.vtu` instead of the meshed one; `mesh.inp` stays the meshed thigh's
    /// deck (a deck without the contact would leave the split sides free).
    pub split: Option<&'a ThighModel>,
}

/// Writes the folder of a meshed thigh (see the module documentation).
pub fn write_model_folder(
    model: &ThighModel,
    materials: &[femu_mesh::MaterialDef],
    f: &ModelFolder,
    progress: &dyn Progress,
) -> Result<()> {
    let t0 = Instant::now();
    for w in &model.warnings {
        progress.warn(w);
    }
    let t1 = Instant::now();
    let out = f.out;
    create_dir(out)?;
    let quality = quality_report(&model.mesh.mesh, &model.regions)?;
    let deck = contention_deck(model, materials, CONTENTION_MPA)?;
    write_inp_with_surfaces(&deck, &model.mesh.surfaces, &out.join("mesh.inp"))?;
    let view = f.split.unwrap_or(model);
    write_regions_vtu(view, &out.join("mesh.vtu"))?;
    let mut title = format!(
        "{}: {} {} quads, h = {:.2} mm",
        if f.command == "mesh thigh" {
            "parametric thigh"
        } else {
            "label image"
        },
        model.mesh.mesh.elements.len(),
        f.kind.deck_name(),
        model.element_size_mm
    );
    if let Some(split) = f.split {
        let extra = split.mesh.mesh.nodes.len() - model.mesh.mesh.nodes.len();
        title.push_str(&format!(", split: {extra} nodes duplicated"));
    }
    write_regions_png(view, &out.join("regions.png"), 1000, &title)?;
    write_text(&out.join("quality.csv"), &quality.to_csv())?;
    write_json(&out.join("quality.json"), &quality)?;
    let write_s = t1.elapsed().as_secs_f64();
    let summary = mesh_summary(model, f, quality, write_s, t0);
    write_json(&out.join("summary.json"), &summary)?;
    let q = &summary.quality.total;
    progress.note(&format!(
        "{}: {} quads, {} nodes, {} regions; scaled Jacobian {:.3}..{:.3}, angles {:.1}..{:.1} deg; mesh {:.3} s; written to {}",
        f.command,
        summary.elements,
        summary.nodes,
        summary.regions.len(),
        q.min_scaled_jacobian,
        q.max_scaled_jacobian,
        q.min_angle_deg,
        q.max_angle_deg,
        f.mesh_s,
        out.display()
    ));
    Ok(())
}

fn mesh_summary(
    model: &ThighModel,
    f: &ModelFolder,
    quality: QualityReport,
    write_s: f64,
    t0: Instant,
) -> MeshSummary {
    let m = &model.mesh.mesh;
    let areas = model.region_areas();
    let regions = model
        .regions
        .iter()
        .map(|r| {
            let a = areas[r];
            let s = model.source_areas_mm2.get(r).copied().unwrap_or(0.0);
            (
                r.clone(),
                RegionSummary {
                    elements: m.element_set(r).map_or(0, <[usize]>::len),
                    area_mm2: a,
                    source_area_mm2: s,
                    area_error_percent: percent(a, s),
                },
            )
        })
        .collect();
    let hole = model.hole_area();
    MeshSummary {
        femu_version: env!("CARGO_PKG_VERSION").into(),
        command: f.command.to_string(),
        input: f.input.clone(),
        element: f.kind.deck_name().into(),
        element_size_mm: model.element_size_mm,
        nodes: m.nodes.len(),
        nodes_as_solved: f.split.map_or(m.nodes.len(), |s| s.mesh.mesh.nodes.len()),
        elements: m.elements.len(),
        regions,
        femur_hole_area_mm2: hole,
        femur_source_area_mm2: model.source_bone_area_mm2,
        femur_area_error_percent: percent(hole, model.source_bone_area_mm2),
        skin_length_mm: model.surface_length("SKIN"),
        femur_nodes: m.node_set("FEMUR").map_or(0, <[usize]>::len),
        skin_faces: model.mesh.surfaces.get("SKIN").map_or(0, Vec::len),
        contention_pressure_mpa: CONTENTION_MPA,
        quality,
        warnings: model.warnings.clone(),
        files: [
            "mesh.inp",
            "mesh.vtu",
            "regions.png",
            "quality.csv",
            "quality.json",
            "summary.json",
        ]
        .map(String::from)
        .to_vec(),
        timings: BTreeMap::from([
            ("mesh_s".to_string(), f.mesh_s),
            ("write_s".to_string(), write_s),
            ("total_s".to_string(), f.mesh_s + t0.elapsed().as_secs_f64()),
        ]),
    }
}

fn percent(a: f64, reference: f64) -> f64 {
    if reference > 0.0 {
        100.0 * (a / reference - 1.0)
    } else {
        0.0
    }
}

/// The model folder of `femu run`: for a meshed thigh the `femu mesh` folder; for a deck its
/// mesh with the materials (VTU) and the element quality.
pub fn write_study_model(
    built: &StudyModel,
    geometry: &Geometry,
    kind: femu_mesh::ElementKind,
    dir: &Path,
    mesh_s: f64,
    progress: &dyn Progress,
) -> Result<()> {
    let Some(thigh) = &built.thigh else {
        return write_deck_model(built, dir);
    };
    let materials: Vec<femu_mesh::MaterialDef> =
        built.model.materials.iter().map(|m| m.to_def()).collect();
    // A sliding interface split the model's mesh: the folder shows it as solved.
    let split = (!built.model.interfaces.is_empty()).then(|| {
        let mut t = thigh.clone();
        t.mesh.mesh = built.model.mesh.clone();
        t.mesh.surfaces = built.model.surfaces.clone();
        t
    });
    let (input, command) = match geometry {
        Geometry::Labels(l) => (
            serde_json::json!({"model": "label image", "image": l.image, "map": l.map}),
            "mesh labels",
        ),
        _ => (
            serde_json::json!({"model": "parametric thigh"}),
            "mesh thigh",
        ),
    };
    write_model_folder(
        thigh,
        &materials,
        &ModelFolder {
            input,
            kind,
            command,
            out: dir,
            mesh_s,
            split: split.as_ref(),
        },
        progress,
    )
}

fn write_deck_model(built: &StudyModel, dir: &Path) -> Result<()> {
    create_dir(dir)?;
    let mesh = &built.model.mesh;
    let names: Vec<String> = built
        .model
        .materials
        .iter()
        .map(|m| m.name.clone())
        .collect();
    let quality = quality_report(mesh, &names).or_else(|_| quality_report(mesh, &[]))?;
    write_text(&dir.join("quality.csv"), &quality.to_csv())?;
    let region: Vec<f64> = built
        .model
        .element_material
        .iter()
        .map(|&m| m as f64)
        .collect();
    let cell_fields = [femu_mesh::VtuField {
        name: "material",
        components: 1,
        data: &region,
    }];
    femu_mesh::VtuWriter.write(
        &dir.join("mesh.vtu"),
        &femu_mesh::FieldSet {
            cell_fields: &cell_fields,
            ..femu_mesh::FieldSet::mesh(mesh)
        },
    )?;
    write_json(
        &dir.join("summary.json"),
        &DeckModelSummary {
            femu_version: env!("CARGO_PKG_VERSION").into(),
            command: "run (deck)".into(),
            input: built.source.clone(),
            nodes: mesh.nodes.len(),
            elements: mesh.elements.len(),
            skin_faces: built.skin.len(),
            quality,
        },
    )
}
