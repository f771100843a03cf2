//! One case of a batch (`femu batch case DIR NAME`): what each runner starts, as a process of
//! its own — a child of the local runner, an array task under Slurm. It runs the case's study
//! (femu-study's `femu run`) into the case's folder and records the outcome in `case.json`
//! when it starts and when it ends, so that the batch knows a case's state without the process
//! that ran it.

use crate::bail;
use crate::error::{IoContext, Result};
use crate::folder::{fingerprint, host_name, unix_now, BatchDir, CaseRecord, RecordStatus};
use femu_study::Progress;
use std::time::Instant;

/// The Slurm array task this process is, from the environment Slurm gives it (`JOB_TASK`).
fn slurm_task() -> Option<String> {
    let job = std::env::var("SLURM_ARRAY_JOB_ID").ok()?;
    let task = std::env::var("SLURM_ARRAY_TASK_ID").ok()?;
    Some(format!("{job}_{task}"))
}

/// Runs case `name` of the batch folder `dir`; its record says how it ended. An error when the
/// case failed or was interrupted (after recording it), as `femu run` would return it.
pub fn run_case(dir: &BatchDir, name: &str, progress: &dyn Progress) -> Result<CaseRecord> {
    let plan = dir.read_plan()?;
    let Some(planned) = plan.cases.iter().find(|c| c.name == name) else {
        bail!("{}: the batch has no case {name}", dir.root().display());
    };
    let study = dir.case_study(name);
    let text = std::fs::read_to_string(&study).at(&study, || {
        format!("case {name}: cannot read {}", study.display())
    })?;
    if fingerprint(&text) != planned.fingerprint {
        bail!(
            "case {name}: {} is not the study planned in batch.json (changed since): run `femu batch run BATCH --out {} --resume` to plan it again",
            study.display(),
            dir.root().display()
        );
    }
    let mut record = CaseRecord {
        case: name.to_string(),
        status: RecordStatus::Running,
        fingerprint: planned.fingerprint.clone(),
        host: host_name(),
        pid: std::process::id(),
        slurm_task: slurm_task(),
        started_unix_s: unix_now(),
        seconds: 0.0,
        error: None,
        femu_version: env!("CARGO_PKG_VERSION").into(),
    };
    dir.write_record(&record)?;
    progress.note(&format!(
        "femu batch: case {name} ({}) on {}, pid {}",
        planned.origin, record.host, record.pid
    ));
    let t0 = Instant::now();
    let result = femu_study::steps::run::run(&study, &dir.case_dir(name), progress);
    record.seconds = t0.elapsed().as_secs_f64();
    match &result {
        Ok(_) => record.status = RecordStatus::Done,
        Err(e) => {
            record.status = if femu_study::progress::is_interrupted(e) {
                RecordStatus::Interrupted
            } else {
                RecordStatus::Failed
            };
            record.error = Some(e.chain());
        }
    }
    dir.write_record(&record)?;
    result?;
    Ok(record)
}
