//! The free parameters of a study: its materials' parameters on its model, the groups tied,
//! the fixed ones left out, bounds from `[identification] bounds_factor`. Shared by the
//! identification, the joint fit, the measurement and the design steps, with what the
//! identification steps read of a study ([`IdentificationInputs`]).

use crate::error::Result;
use crate::schema::{IdentificationSpec, ModelSpec, Study, TestSpec};
use femu_identify::campaign;
use femu_identify::fit::FreeParameter;
use femu_mech::Model;

/// The free parameters of `study` on `model` (its groups tied when `grouped`).
pub fn free_parameters(
    study: &Study,
    model: &Model,
    grouped: bool,
) -> Result<(Vec<FreeParameter>, Vec<f64>)> {
    IdentificationInputs::of(study).free_parameters(model, grouped)
}

/// What the identification steps read of a study (`identify_on`, the joint fit, the
/// discretization check, the identification from images and from recorded frames): built once
/// by the caller, a variant of it (another loss, no Latin-hypercube starts) by
/// [`IdentificationInputs::with`].
#[derive(Debug, Clone, Copy)]
pub struct IdentificationInputs<'a> {
    /// The model's description: the multilevel's coarse mesh, the virtual data's finer mesh and
    /// the discretization check's meshes are built from it.
    pub model: &'a ModelSpec,
    /// The study's tests (a measurement names its test by index).
    pub tests: &'a [TestSpec],
    /// `[parameters] groups` (tied in a grouped identification).
    pub groups: &'a [Vec<String>],
    /// `[identification]`.
    pub identification: &'a IdentificationSpec,
    /// The study's noise of the measured displacement (mm): the summary's when no measurement
    /// is virtual.
    pub sigma_mm: f64,
    /// Whether the measurements were written as a `[[measurement]]` list (outputs per
    /// measurement).
    pub measurement_list: bool,
    /// `[ultrasound] render_refine`: 1 when simulated images are rendered from the model's own
    /// mesh (their intervals then need no widening for the mesh).
    pub render_refine: usize,
}

impl<'a> IdentificationInputs<'a> {
    /// The study's model, tests, groups, `[identification]`, noise, list flag and
    /// `render_refine`.
    pub fn of(study: &'a Study) -> IdentificationInputs<'a> {
        IdentificationInputs {
            model: &study.model,
            tests: &study.tests,
            groups: &study.groups,
            identification: &study.identification,
            sigma_mm: study.measurement.sigma_mm,
            measurement_list: study.measurement_list(),
            render_refine: study.ultrasound.render_refine,
        }
    }

    /// The same inputs with `identification` in place of the study's `[identification]`.
    pub fn with<'b>(&self, identification: &'b IdentificationSpec) -> IdentificationInputs<'b>
    where
        'a: 'b,
    {
        IdentificationInputs {
            identification,
            ..*self
        }
    }

    /// The test whose field is identified (`[identification] test`).
    pub fn identification_test(&self) -> &'a TestSpec {
        &self.tests[self.identification.test]
    }

    /// The free parameters on `model` (the groups tied when `grouped`).
    pub fn free_parameters(
        &self,
        model: &Model,
        grouped: bool,
    ) -> Result<(Vec<FreeParameter>, Vec<f64>)> {
        let groups = if grouped {
            self.groups.to_vec()
        } else {
            Vec::new()
        };
        let spec = self.identification;
        campaign::free_parameters(model, &groups, &spec.fixed, spec.bounds_factor).map_err(|e| {
            match e {
                campaign::CampaignError::UnknownParameter { .. }
                | campaign::CampaignError::PartlyFixed(_)
                | campaign::CampaignError::NothingFree => {
                    crate::input!("[identification] fixed: {e}")
                }
                e => e.into(),
            }
        })
    }
}
