//! `femu mesh thigh` and `femu mesh labels`: build a thigh model (the built-in parametric thigh
//! or a segmented label image), check its quality and write the output folder:
//!
//! - `mesh.inp` — the contention deck (Table 1 materials, femur fixed, 20 mmHg on the skin,
//!   element sets per region, node sets `FEMUR` and `SKIN`, surfaces `SKIN` and `FEMUR`),
//!   runnable by CalculiX and `femu solve` as is;
//! - `mesh.vtu` — the mesh for ParaView (cell fields `region`, `scaled_jacobian`);
//! - `regions.png` — a picture of the regions with a legend and axes in mm;
//! - `quality.csv`, `quality.json` — scaled Jacobian, aspect ratio and angles per region;
//! - `summary.json` — inputs, counts, areas (meshed vs source), warnings, timings.
//!
//! Thin glue: parsing and validation here, everything else in `femu-geometry`.

use crate::QuadElement;
use anyhow::{bail, Context, Result};
use clap::Subcommand;
use femu_geometry::{
    contention_deck, mesh_label_image, parametric_thigh, quality_report, read_label_image,
    table1_materials, write_inp_with_surfaces, write_regions_png, write_regions_vtu, LabelSpec,
    MeshOptions, QualityReport, ThighModel, ThighParams, CONTENTION_MPA, TABLE1,
};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `femu mesh` builds.
#[derive(Subcommand, Debug)]
pub enum MeshCommand {
    /// The built-in parametric thigh (skin, fat, quadriceps, ischio, gracilis, sartorius around
    /// a fixed femur; about 25 000 quads by default).
    Thigh {
        /// Element size (mm); exclusive with --elements.
        #[arg(long)]
        size: Option<f64>,
        /// Target number of quads (default 25 000, the seed's scale).
        #[arg(long, conflicts_with = "size")]
        elements: Option<usize>,
        /// TOML file with a [thigh] table of dimensions (keys of femu_geometry::ThighParams,
        /// e.g. fat_thickness_mm = 10).
        #[arg(long)]
        params: Option<PathBuf>,
        /// Element formulation.
        #[arg(long, value_enum, default_value = "cpe4h")]
        element: QuadElement,
        /// Output folder (created if absent).
        #[arg(long, default_value = "out/mesh")]
        out: PathBuf,
    },
    /// A segmented image: PNG/TIFF (8/16-bit grey) or NIfTI (.nii, .nii.gz) label map.
    Labels {
        /// The label image.
        image: PathBuf,
        /// Pixel size (mm); required unless the file gives it (NIfTI header).
        #[arg(long)]
        pixel_size: Option<f64>,
        /// Label to region table, e.g. 1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=ischio
        /// (several labels may share a region; regions need a Table 1 material).
        #[arg(long)]
        map: String,
        /// Bone label(s), comma-separated: a hole whose edge is fixed.
        #[arg(long, value_delimiter = ',', required = true)]
        bone: Vec<u32>,
        /// Background label(s), comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "0")]
        background: Vec<u32>,
        /// Axial slice of a NIfTI volume (index along the third axis).
        #[arg(long)]
        slice: Option<usize>,
        /// Element size (mm), independent of the pixel size.
        #[arg(long, default_value_t = 1.0)]
        size: f64,
        /// Pieces of a label smaller than this (mm²) are merged into their neighbour.
        #[arg(long, default_value_t = 5.0)]
        min_island: f64,
        /// Element formulation.
        #[arg(long, value_enum, default_value = "cpe4h")]
        element: QuadElement,
        /// Output folder (created if absent).
        #[arg(long, default_value = "out/mesh")]
        out: PathBuf,
    },
}

#[derive(Serialize)]
struct RegionSummary {
    elements: usize,
    area_mm2: f64,
    source_area_mm2: f64,
    area_error_percent: f64,
}

#[derive(Serialize)]
struct Summary {
    femu_version: &'static str,
    command: String,
    input: serde_json::Value,
    element: &'static str,
    element_size_mm: f64,
    nodes: usize,
    elements: usize,
    regions: BTreeMap<String, RegionSummary>,
    femur_hole_area_mm2: f64,
    femur_source_area_mm2: f64,
    femur_area_error_percent: f64,
    skin_length_mm: f64,
    femur_nodes: usize,
    skin_faces: usize,
    contention_pressure_mpa: f64,
    quality: QualityReport,
    warnings: Vec<String>,
    files: Vec<&'static str>,
    timings: BTreeMap<&'static str, f64>,
}

/// Runs `femu mesh ...`.
pub fn run(cmd: MeshCommand, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    let (model, out, input, kind, command) = match cmd {
        MeshCommand::Thigh {
            size,
            elements,
            params,
            element,
            out,
        } => {
            let mut p = match &params {
                Some(file) => read_thigh_params(file)?,
                None => ThighParams::default(),
            };
            if size.is_some() || elements.is_some() {
                p.element_size_mm = size;
                p.target_elements = elements;
            }
            p.validate().context("invalid thigh dimensions")?;
            let model =
                parametric_thigh(&p, element.kind()).context("meshing the parametric thigh")?;
            let input = serde_json::json!({ "model": "parametric thigh", "params": p, "params_file": params });
            (model, out, input, element.kind(), "mesh thigh")
        }
        MeshCommand::Labels {
            image,
            pixel_size,
            map,
            bone,
            background,
            slice,
            size,
            min_island,
            element,
            out,
        } => {
            let spec =
                LabelSpec::new(&map, &bone, &background).context("--map/--bone/--background")?;
            for name in spec.region_names() {
                if !TABLE1.iter().any(|(r, _, _)| r.eq_ignore_ascii_case(&name)) {
                    bail!(
                        "region '{name}' of --map has no material: the deck uses the seed's Table 1 (fat, quadriceps, ischio, gracilis, sartorius); map its label to one of them"
                    );
                }
            }
            if let Some(s) = pixel_size {
                if !(s > 0.0) || !s.is_finite() {
                    bail!("--pixel-size must be a positive number of mm, got {s}");
                }
            }
            let img = read_label_image(&image, slice)?;
            let options = MeshOptions {
                element_size_mm: size,
                kind: element.kind(),
                min_island_mm2: min_island,
                ..MeshOptions::default()
            };
            let model = mesh_label_image(&img, &spec, pixel_size, &options)
                .with_context(|| format!("meshing {}", image.display()))?;
            let input = serde_json::json!({
                "model": "label image",
                "image": image.display().to_string(),
                "width": img.width,
                "height": img.height,
                "pixel_size_mm": pixel_size.map(|s| [s, s]).or(img.pixel_size_mm),
                "slice": slice,
                "map": spec.regions,
                "bone": spec.bone,
                "background": spec.background,
                "min_island_mm2": min_island,
            });
            (model, out, input, element.kind(), "mesh labels")
        }
    };
    let mesh_s = t0.elapsed().as_secs_f64();
    write_model_folder(
        &model,
        &table1_materials(),
        input,
        kind,
        command,
        &out,
        mesh_s,
        quiet,
    )
}

/// Writes the folder of a meshed thigh: `mesh.inp` (the contention deck with `materials`),
/// `mesh.vtu`, `regions.png`, `quality.csv/json`, `summary.json`.
#[allow(clippy::too_many_arguments)]
pub fn write_model_folder(
    model: &ThighModel,
    materials: &[femu_mesh::MaterialDef],
    input: serde_json::Value,
    kind: femu_mesh::ElementKind,
    command: &str,
    out: &Path,
    mesh_s: f64,
    quiet: bool,
) -> Result<()> {
    let t0 = Instant::now();
    if !quiet {
        for w in &model.warnings {
            eprintln!("warning: {w}");
        }
    }
    let t1 = Instant::now();
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    let quality = quality_report(&model.mesh.mesh, &model.regions)?;
    let deck = contention_deck(model, materials, CONTENTION_MPA)?;
    write_inp_with_surfaces(&deck, &model.mesh.surfaces, &out.join("mesh.inp"))?;
    write_regions_vtu(model, &out.join("mesh.vtu"))?;
    let title = format!(
        "{}: {} {} quads, h = {:.2} mm",
        if command == "mesh thigh" {
            "parametric thigh"
        } else {
            "label image"
        },
        model.mesh.mesh.elements.len(),
        kind.deck_name(),
        model.element_size_mm
    );
    write_regions_png(model, &out.join("regions.png"), 1000, &title)?;
    write_file(&out.join("quality.csv"), quality.to_csv())?;
    write_file(
        &out.join("quality.json"),
        serde_json::to_string_pretty(&quality)?,
    )?;
    let write_s = t1.elapsed().as_secs_f64();
    let summary = summary(model, input, kind, command, quality, mesh_s, write_s, t0);
    write_file(
        &out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    if !quiet {
        let q = &summary.quality.total;
        eprintln!(
            "{command}: {} quads, {} nodes, {} regions; scaled Jacobian {:.3}..{:.3}, angles {:.1}..{:.1} deg; mesh {:.3} s; written to {}",
            summary.elements,
            summary.nodes,
            summary.regions.len(),
            q.min_scaled_jacobian,
            q.max_scaled_jacobian,
            q.min_angle_deg,
            q.max_angle_deg,
            mesh_s,
            out.display()
        );
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn summary(
    model: &ThighModel,
    input: serde_json::Value,
    kind: femu_mesh::ElementKind,
    command: &str,
    quality: QualityReport,
    mesh_s: f64,
    write_s: f64,
    t0: Instant,
) -> Summary {
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
    Summary {
        femu_version: env!("CARGO_PKG_VERSION"),
        command: command.to_string(),
        input,
        element: kind.deck_name(),
        element_size_mm: model.element_size_mm,
        nodes: m.nodes.len(),
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
        files: vec![
            "mesh.inp",
            "mesh.vtu",
            "regions.png",
            "quality.csv",
            "quality.json",
            "summary.json",
        ],
        timings: BTreeMap::from([
            ("mesh_s", mesh_s),
            ("write_s", write_s),
            ("total_s", mesh_s + t0.elapsed().as_secs_f64()),
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

fn write_file(path: &Path, text: String) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Reads the `[thigh]` table of a TOML file.
fn read_thigh_params(path: &Path) -> Result<ThighParams> {
    #[derive(serde::Deserialize)]
    struct File {
        thigh: ThighParams,
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let f: File = toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
    Ok(f.thigh)
}
