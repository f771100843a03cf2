//! `[[fixed]]`, `[[pressure]]`, `[step]`: the boundary conditions of a Gmsh mesh
//! (`femu solve MESH.msh --study S.toml`), by physical curve.
//!
//! ```toml
//! [model]
//! element = "cpe4h"            # quads: cpe4 or cpe4h (triangles are CPE3)
//! [materials.fat]              # a physical surface of the mesh
//! c10_kpa = 0.8                # or c10_mpa
//! d_per_mpa = 30.8
//! [[fixed]]                    # a physical curve; dofs default to [1, 2]
//! curve = "femur"
//! [[pressure]]                 # follower pressure on a physical curve
//! curve = "skin"
//! mmhg = 20.0                  # or mpa
//! [step]                       # optional, as *STATIC
//! initial_increment = 1.0
//! [[test]]                     # optional: one rigid body pressed on a physical curve
//! kind = "compression"         # or "indentation" (with radius_mm)
//! curve = "skin"
//! side = "anterior"
//! force_n_per_mm = 0.1
//! ```

use super::lines::KeyLines;
use super::raw::{FixedEntry, PressureEntry, StepEntry};
use super::StudyError;
use femu_mech::build::{CurveDisplacement, CurvePressure};
use femu_mesh::{StepDef, MMHG_IN_MPA};

/// The boundary conditions of a Gmsh mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshBoundary {
    pub fixed: Vec<CurveDisplacement>,
    pub pressures: Vec<CurvePressure>,
    pub step: StepDef,
}

/// No boundary table: no condition, the declared `[step]`.
impl Default for MeshBoundary {
    fn default() -> Self {
        let real = |key: &str| super::keys::default::<f64>("step", key);
        MeshBoundary {
            fixed: Vec::new(),
            pressures: Vec::new(),
            step: StepDef {
                initial_increment: real("initial_increment"),
                min_increment: real("min_increment"),
                max_increment: real("max_increment"),
                max_increments: super::keys::default("step", "max_increments"),
                ..StepDef::default()
            },
        }
    }
}

impl MeshBoundary {
    /// Whether the study gives any boundary table (`[[fixed]]`, `[[pressure]]`, `[step]`).
    pub fn is_given(&self) -> bool {
        *self != MeshBoundary::default()
    }
}

/// Checks `[[fixed]]`, `[[pressure]]` and `[step]`.
pub(crate) fn parse(
    fixed: &[FixedEntry],
    pressure: &[PressureEntry],
    step: Option<&StepEntry>,
    lines: &KeyLines,
) -> Result<MeshBoundary, StudyError> {
    let mut out = MeshBoundary::default();
    for (k, fx) in fixed.iter().enumerate() {
        let dofs: Vec<usize> = super::keys::or_default(fx.dofs.clone(), "fixed", "dofs");
        let value_mm: f64 = super::keys::or_default(fx.value_mm, "fixed", "value_mm");
        if dofs.is_empty() || dofs.iter().any(|&d| d != 1 && d != 2) {
            return Err(lines.err(
                "fixed",
                k,
                "dofs",
                format!("plane strain has dofs 1 and 2, got {dofs:?}"),
            ));
        }
        if !value_mm.is_finite() {
            return Err(lines.err("fixed", k, "value_mm", "must be finite".into()));
        }
        out.fixed.push(CurveDisplacement {
            curve: fx.curve.clone(),
            dofs: dofs.iter().map(|d| d - 1).collect(),
            value: value_mm,
        });
    }
    for (k, p) in pressure.iter().enumerate() {
        let mpa = match (p.mmhg, p.mpa) {
            (Some(h), None) => h * MMHG_IN_MPA,
            (None, Some(v)) => v,
            _ => return Err(lines.err("pressure", k, "", "give exactly one of mmhg, mpa".into())),
        };
        if !mpa.is_finite() {
            return Err(lines.err("pressure", k, "", "not a finite number".into()));
        }
        out.pressures.push(CurvePressure {
            curve: p.curve.clone(),
            pressure: mpa,
        });
    }
    if let Some(s) = step {
        let st = &mut out.step;
        if let Some(v) = s.initial_increment {
            st.initial_increment = v;
        }
        if let Some(v) = s.min_increment {
            st.min_increment = v;
        }
        if let Some(v) = s.max_increment {
            st.max_increment = v;
        }
        if let Some(v) = s.max_increments {
            st.max_increments = v;
        }
        if !(st.initial_increment > 0.0 && st.initial_increment <= 1.0) {
            return Err(lines.err(
                "step",
                0,
                "initial_increment",
                format!("must be in (0, 1], got {}", st.initial_increment),
            ));
        }
        if !(st.min_increment > 0.0 && st.min_increment <= st.initial_increment) {
            return Err(lines.err(
                "step",
                0,
                "min_increment",
                format!(
                    "must be in (0, initial_increment = {}], got {}",
                    st.initial_increment, st.min_increment
                ),
            ));
        }
        if !(st.max_increment >= st.initial_increment && st.max_increment <= 1.0) {
            return Err(lines.err(
                "step",
                0,
                "max_increment",
                format!(
                    "must be in [initial_increment = {}, 1], got {}",
                    st.initial_increment, st.max_increment
                ),
            ));
        }
        if st.max_increments == 0 {
            return Err(lines.err("step", 0, "max_increments", "must be at least 1".into()));
        }
    }
    Ok(out)
}
