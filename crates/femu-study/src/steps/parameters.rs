//! The free parameters of a study: its materials' parameters on its model, the groups tied,
//! the fixed ones left out, bounds from `[identification] bounds_factor`. Shared by the
//! identification, the joint fit, the measurement and the design steps.

use crate::error::Result;
use crate::schema::Study;
use femu_identify::campaign;
use femu_identify::fit::FreeParameter;
use femu_mech::Model;

/// The free parameters of `study` on `model` (its groups tied when `grouped`).
pub fn free_parameters(
    study: &Study,
    model: &Model,
    grouped: bool,
) -> Result<(Vec<FreeParameter>, Vec<f64>)> {
    let groups = if grouped {
        study.groups.clone()
    } else {
        Vec::new()
    };
    campaign::free_parameters(
        model,
        &groups,
        &study.identification.fixed,
        study.identification.bounds_factor,
    )
    .map_err(|e| match e {
        campaign::CampaignError::UnknownParameter { .. }
        | campaign::CampaignError::PartlyFixed(_)
        | campaign::CampaignError::NothingFree => {
            crate::input!("[identification] fixed: {e}")
        }
        e => e.into(),
    })
}
