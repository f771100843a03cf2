//! The small study file that turns a Gmsh mesh into a solvable model (`femu solve X.msh
//! --study S.toml`). Units are in the key names, as conventions.md asks:
//!
//! ```toml
//! element = "CPE4H"            # quads: CPE4 or CPE4H (triangles are CPE3)
//!
//! [materials.fat]              # a physical surface of the mesh
//! c10_kpa = 0.8                # or c10_mpa
//! d_per_mpa = 30.8
//!
//! [[fixed]]                    # a physical curve; dofs default to [1, 2]
//! curve = "femur"
//!
//! [[pressure]]                 # follower pressure on a physical curve
//! curve = "skin"
//! mmhg = 20.0                  # or mpa
//!
//! [step]                       # optional, as *STATIC
//! initial_increment = 1.0
//!
//! [compression]                # optional: a rigid plate pressed on a physical curve
//! curve = "skin"
//! side = "anterior"            # anterior (+y), posterior, lateral (+x), medial, or degrees
//! force_n_per_mm = 0.1
//!
//! [indentation]                # optional: a rigid cylinder (one of the two per run)
//! curve = "skin"
//! side = "anterior"
//! radius_mm = 10.0
//! force_n_per_mm = 0.1
//! ```

use anyhow::{bail, Context, Result};
use femu_mech::build::{CurveDisplacement, CurvePressure, MshSetup, RegionMaterial};
use femu_mech::loading::{Loading, Side};
use femu_mesh::MMHG_IN_MPA;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StudyFile {
    element: Option<String>,
    materials: BTreeMap<String, MaterialEntry>,
    #[serde(default)]
    fixed: Vec<FixedEntry>,
    #[serde(default)]
    pressure: Vec<PressureEntry>,
    step: Option<StepEntry>,
    compression: Option<RigidEntry>,
    indentation: Option<RigidEntry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RigidEntry {
    curve: String,
    side: String,
    force_n_per_mm: f64,
    radius_mm: Option<f64>,
}

/// A study: the Gmsh setup and, optionally, a rigid-body loading on a curve.
#[derive(Debug)]
pub struct Study {
    pub setup: MshSetup,
    /// `(curve, loading)` for a compression or indentation test.
    pub rigid: Option<(String, Loading)>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialEntry {
    c10_kpa: Option<f64>,
    c10_mpa: Option<f64>,
    d_per_mpa: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FixedEntry {
    curve: String,
    dofs: Option<Vec<usize>>,
    #[serde(default)]
    value_mm: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PressureEntry {
    curve: String,
    mmhg: Option<f64>,
    mpa: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StepEntry {
    initial_increment: Option<f64>,
    min_increment: Option<f64>,
    max_increment: Option<f64>,
    max_increments: Option<usize>,
}

/// Reads and validates a study file.
pub fn read(path: &Path) -> Result<Study> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    parse(&text).with_context(|| format!("in study file {}", path.display()))
}

fn parse(text: &str) -> Result<Study> {
    let f: StudyFile = toml::from_str(text)?;
    let quad_kind = match f.element.as_deref().map(str::to_ascii_uppercase).as_deref() {
        None | Some("CPE4H") => femu_mesh::ElementKind::Cpe4h,
        Some("CPE4") => femu_mesh::ElementKind::Cpe4,
        Some(other) => bail!("key 'element': '{other}' is not a quad element type (CPE4 or CPE4H)"),
    };
    let mut materials = Vec::new();
    for (name, m) in &f.materials {
        let c10 = match (m.c10_kpa, m.c10_mpa) {
            (Some(k), None) => k * 1e-3,
            (None, Some(v)) => v,
            _ => bail!("materials.{name}: give exactly one of c10_kpa, c10_mpa"),
        };
        if !(c10 > 0.0 && c10.is_finite()) {
            bail!("materials.{name}: C10 must be positive, got {c10} MPa");
        }
        if !(m.d_per_mpa > 0.0 && m.d_per_mpa.is_finite()) {
            bail!(
                "materials.{name}.d_per_mpa: D must be positive (compressible), got {}",
                m.d_per_mpa
            );
        }
        materials.push(RegionMaterial {
            region: name.clone(),
            law: Box::new(femu_mech::NeoHookean {
                c10,
                d: m.d_per_mpa,
            }),
        });
    }
    let mut displacements = Vec::new();
    for (k, fx) in f.fixed.iter().enumerate() {
        let dofs = fx.dofs.clone().unwrap_or_else(|| vec![1, 2]);
        if dofs.iter().any(|&d| d != 1 && d != 2) {
            bail!("fixed[{k}].dofs: plane strain has dofs 1 and 2, got {dofs:?}");
        }
        displacements.push(CurveDisplacement {
            curve: fx.curve.clone(),
            dofs: dofs.iter().map(|d| d - 1).collect(),
            value: fx.value_mm,
        });
    }
    let mut pressures = Vec::new();
    for (k, p) in f.pressure.iter().enumerate() {
        let mpa = match (p.mmhg, p.mpa) {
            (Some(h), None) => h * MMHG_IN_MPA,
            (None, Some(v)) => v,
            _ => bail!("pressure[{k}]: give exactly one of mmhg, mpa"),
        };
        if !mpa.is_finite() {
            bail!("pressure[{k}]: not a finite number");
        }
        pressures.push(CurvePressure {
            curve: p.curve.clone(),
            pressure: mpa,
        });
    }
    let mut step = femu_mesh::StepDef::default();
    if let Some(s) = &f.step {
        if let Some(v) = s.initial_increment {
            step.initial_increment = v;
        }
        if let Some(v) = s.min_increment {
            step.min_increment = v;
        }
        if let Some(v) = s.max_increment {
            step.max_increment = v;
        }
        if let Some(v) = s.max_increments {
            step.max_increments = v;
        }
        if !(step.initial_increment > 0.0 && step.initial_increment <= 1.0) {
            bail!(
                "step.initial_increment must be in (0, 1], got {}",
                step.initial_increment
            );
        }
    }
    let rigid = match (&f.compression, &f.indentation) {
        (Some(_), Some(_)) => {
            bail!("give either [compression] or [indentation], one rigid body per run")
        }
        (Some(c), None) => {
            if c.radius_mm.is_some() {
                bail!("compression.radius_mm: a plate has no radius (did you mean [indentation]?)");
            }
            let side =
                Side::parse(&c.side).map_err(|e| anyhow::anyhow!("compression.side: {e}"))?;
            Some((
                c.curve.clone(),
                Loading::Compression {
                    side,
                    force: c.force_n_per_mm,
                },
            ))
        }
        (None, Some(c)) => {
            let site =
                Side::parse(&c.side).map_err(|e| anyhow::anyhow!("indentation.side: {e}"))?;
            let Some(radius) = c.radius_mm else {
                bail!("indentation.radius_mm is missing")
            };
            Some((
                c.curve.clone(),
                Loading::Indentation {
                    site,
                    radius,
                    force: c.force_n_per_mm,
                },
            ))
        }
        (None, None) => None,
    };
    Ok(Study {
        setup: MshSetup {
            quad_kind,
            materials,
            displacements,
            pressures,
            step,
        },
        rigid,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_study_and_names_bad_keys() {
        let s = parse(
            "element = \"CPE4\"\n[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n[[fixed]]\ncurve = \"femur\"\n[[pressure]]\ncurve = \"skin\"\nmmhg = 20\n",
        )
        .unwrap();
        assert_eq!(s.setup.materials[0].law.parameter(0), 0.8e-3);
        assert!((s.setup.pressures[0].pressure - 2.666e-3).abs() < 1e-6);
        assert_eq!(s.setup.displacements[0].dofs, vec![0, 1]);
        assert!(s.rigid.is_none());
        let s = parse("[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n[compression]\ncurve = \"skin\"\nside = \"medial\"\nforce_n_per_mm = 0.1\n").unwrap();
        assert!(matches!(
            s.rigid,
            Some((
                _,
                Loading::Compression {
                    side: Side::Medial,
                    ..
                }
            ))
        ));
        let e = parse("[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n[indentation]\ncurve = \"skin\"\nside = \"up\"\nforce_n_per_mm = 0.1\nradius_mm = 5\n").unwrap_err();
        assert!(format!("{e:#}").contains("indentation.side"), "{e:#}");
        let e = parse("[materials.fat]\nc10_kpa = 0.8\nd = 30.8\n").unwrap_err();
        assert!(format!("{e:#}").contains("unknown field `d`"), "{e:#}");
        let e = parse("[materials.fat]\nc10_kpa = -0.8\nd_per_mpa = 30.8\n").unwrap_err();
        assert!(format!("{e:#}").contains("materials.fat"), "{e:#}");
    }
}
