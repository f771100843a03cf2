//! Commands that run a pipeline step and then write its report: a layer above `steps` and
//! `report`, so that the report, which reads the steps' summaries, is never called from a step.

use crate::error::Result;
use crate::progress::Progress;
use crate::schema::Study;
use crate::steps::design::{self, DesignSummary};
use std::path::Path;

/// `femu design`: the study's model built, its designs ranked into `out`, and `report.html`
/// with the design section.
pub fn design(study: &Study, out: &Path, progress: &dyn Progress) -> Result<DesignSummary> {
    let built = crate::model::build(&study.model)?;
    let inputs = design::DesignInputs::of(study, &built)?;
    let summary = design::run_on(&inputs, &built, out, progress)?;
    let report = crate::report::write_design(out)?;
    progress.note(&format!("wrote {}", report.display()));
    Ok(summary)
}
