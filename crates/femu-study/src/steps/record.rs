//! The record of a run (`steps.json`): every step's status and time, written after each step so
//! that a run that stops keeps an account of what it finished.

use crate::error::Result;
use crate::output::write_json;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// One step of a run, as recorded in `steps.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StepRecord {
    pub name: String,
    /// `done`, `failed` or `skipped`.
    pub status: String,
    pub folder: Option<String>,
    pub seconds: f64,
    pub error: Option<String>,
}

/// The record of a run (`steps.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunRecord {
    pub femu_version: String,
    pub command: String,
    pub study: String,
    pub started_unix_s: u64,
    pub threads: usize,
    pub os: String,
    pub steps: Vec<StepRecord>,
    pub total_seconds: f64,
}

impl RunRecord {
    /// Writes `out/steps.json`.
    pub fn save(&self, out: &Path) -> Result<()> {
        write_json(&out.join("steps.json"), self)
    }
}

/// Starts a step: records it as running.
pub(crate) fn begin(
    record: &mut RunRecord,
    out: &Path,
    name: &str,
    folder: Option<&str>,
) -> Result<Instant> {
    record.steps.push(StepRecord {
        name: name.into(),
        status: "running".into(),
        folder: folder.map(Into::into),
        seconds: 0.0,
        error: None,
    });
    record.save(out)?;
    Ok(Instant::now())
}

pub(crate) fn finish(record: &mut RunRecord, out: &Path, t: Instant) -> Result<()> {
    let last = record.steps.last_mut().expect("a step was begun");
    last.status = "done".into();
    last.seconds = t.elapsed().as_secs_f64();
    record.save(out)
}

pub(crate) fn skip(record: &mut RunRecord, out: &Path, name: &str, why: &str) -> Result<()> {
    record.steps.push(StepRecord {
        name: name.into(),
        status: "skipped".into(),
        folder: None,
        seconds: 0.0,
        error: Some(why.into()),
    });
    record.save(out)
}
