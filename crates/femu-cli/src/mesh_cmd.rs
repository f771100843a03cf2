//! `femu mesh thigh`, `femu mesh labels` and `femu mesh thigh3d`: build a thigh model (the
//! built-in parametric thigh, a segmented label image, or the thigh swept into a 3D deck), check its quality and write the output folder (see
//! `femu_study::steps::model`). Thin glue: arguments here, everything else in femu-study and
//! femu-geometry.

use crate::progress::Terminal;
use crate::QuadElement;
use anyhow::{Context, Result};
use clap::Subcommand;
use femu_geometry::ThighParams;
use femu_study::progress::Progress;
use femu_study::steps::model::{self, LabelMeshRequest, ThighMeshRequest};
use std::path::{Path, PathBuf};

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
        /// Label to region table, e.g. 1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=adductor
        /// (several labels may share a region; a region outside Table 1 needs its material in
        /// --materials).
        #[arg(long)]
        map: String,
        /// A TOML file of [materials.REGION] tables, the study file's form (a study file will
        /// do): c10_kpa, d_per_mpa, or law = "..." and its keys. Table 1 regions may be
        /// overridden; a region outside Table 1 takes its table whole.
        #[arg(long)]
        materials: Option<PathBuf>,
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
    /// The built-in thigh swept along the femur axis into a 3D deck of hexahedra (C3D8H or
    /// C3D8), with a taper, the femur fixed and a pressure on the probe's footprint:
    /// `thigh3d.inp` (for `femu solve` and CalculiX), `mesh.vtu`, `summary.json`.
    Thigh3d {
        /// Element size of the cross-section (mm).
        #[arg(long, default_value_t = 4.5)]
        size: f64,
        /// Length along the femur axis (mm).
        #[arg(long, default_value_t = 120.0)]
        length: f64,
        /// Layer thickness under the probe (mm); layers grow by --growth towards the ends.
        #[arg(long, default_value_t = 5.0)]
        layer: f64,
        /// Growth of the layers' thickness per layer away from the probe.
        #[arg(long, default_value_t = 1.6)]
        growth: f64,
        /// Scale of the section at the far end relative to the near end (1: no taper).
        #[arg(long, default_value_t = 1.0)]
        end_scale: f64,
        /// Element formulation.
        #[arg(long, value_enum, default_value = "c3d8h")]
        element: HexElement,
        /// Direction of the probe from the section's centre (degrees; 90 = anterior).
        #[arg(long, default_value_t = 90.0)]
        probe_angle: f64,
        /// Probe footprint width across the thigh (mm).
        #[arg(long, default_value_t = 10.0)]
        probe_width: f64,
        /// Probe footprint length along the thigh (mm).
        #[arg(long, default_value_t = 40.0)]
        probe_length: f64,
        /// Pressure on the footprint (kPa; 2.67 kPa = 20 mmHg).
        #[arg(long, default_value_t = 2.67)]
        pressure: f64,
        /// Hold both ends along the axis (a slab in plane strain) instead of leaving them free.
        #[arg(long)]
        plane_strain_ends: bool,
        /// Output folder (created if absent).
        #[arg(long, default_value = "out/mesh3d")]
        out: PathBuf,
    },
}

/// Hexahedron formulations of `femu mesh thigh3d`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum HexElement {
    /// Trilinear hexahedron with a constant pressure (mean dilatation), for near-incompressible tissue.
    C3d8h,
    /// Plain trilinear hexahedron.
    C3d8,
}

/// Runs `femu mesh ...`.
pub fn run(cmd: MeshCommand, quiet: bool) -> Result<()> {
    let progress = Terminal { quiet };
    match cmd {
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
            let req = ThighMeshRequest {
                params: p,
                params_file: params,
                element: element.into(),
            };
            Ok(model::mesh_thigh(&req, &out, &progress)?)
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
            materials,
        } => {
            let materials = match &materials {
                Some(f) => femu_study::read(f)?.model.materials,
                None => Vec::new(),
            };
            let req = LabelMeshRequest {
                materials,
                image,
                pixel_size_mm: pixel_size,
                map,
                bone,
                background,
                slice,
                size_mm: size,
                min_island_mm2: min_island,
                element: element.into(),
            };
            Ok(model::mesh_labels(&req, &out, &progress)?)
        }
        MeshCommand::Thigh3d {
            size,
            length,
            layer,
            growth,
            end_scale,
            element,
            probe_angle,
            probe_width,
            probe_length,
            pressure,
            plane_strain_ends,
            out,
        } => {
            let req = femu_study::steps::solve3::Thigh3Request {
                size_mm: size,
                length_mm: length,
                layer_mm: layer,
                growth,
                end_scale,
                kind: match element {
                    HexElement::C3d8h => femu_mesh::ElementKind3::C3d8h,
                    HexElement::C3d8 => femu_mesh::ElementKind3::C3d8,
                },
                probe_angle_deg: probe_angle,
                probe_width_mm: probe_width,
                probe_length_mm: probe_length,
                pressure_kpa: pressure,
                plane_strain_ends,
            };
            let s = femu_study::steps::solve3::mesh_thigh3d(&req, &out)?;
            progress.note(&format!(
                "{}: {} nodes, {} {} elements ({} layers of {} quads), {} loaded faces",
                s.deck,
                s.nodes,
                s.elements,
                s.element_type,
                s.layers,
                s.section_quads,
                s.probe_faces
            ));
            Ok(())
        }
    }
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
