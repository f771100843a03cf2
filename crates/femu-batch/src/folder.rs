//! The batch folder and the records in it:
//!
//! ```text
//! DIR/batch.json            the plan: every case, where it comes from, its variables, the
//!                           fingerprint of its study (written before any case runs)
//! DIR/cases/NAME/study.toml the case's study (the template with the case's values)
//! DIR/cases/NAME/case.json  the case's outcome: running / done / failed / interrupted, the
//!                           error, the time, the host and process (or Slurm task)
//! DIR/cases/NAME/femu.log   what the case's femu run printed
//! DIR/cases/NAME/...        the femu run folder (steps.json, model/, identify/, report.html)
//! DIR/slurm/                the Slurm runner's scripts, jobs and logs
//! DIR/collect/              femu batch collect: the population table and report
//! ```
//!
//! Records are written whole (a temporary file renamed over the old one), so that a reader —
//! `femu batch status` while the cases run — never sees half a file.

use crate::error::{IoContext, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A batch folder.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchDir(PathBuf);

impl BatchDir {
    pub fn new(root: &Path) -> BatchDir {
        BatchDir(root.to_path_buf())
    }
    pub fn root(&self) -> &Path {
        &self.0
    }
    pub fn plan_file(&self) -> PathBuf {
        self.0.join("batch.json")
    }
    pub fn case_dir(&self, case: &str) -> PathBuf {
        self.0.join("cases").join(case)
    }
    pub fn case_study(&self, case: &str) -> PathBuf {
        self.case_dir(case).join("study.toml")
    }
    pub fn case_record(&self, case: &str) -> PathBuf {
        self.case_dir(case).join("case.json")
    }
    pub fn case_log(&self, case: &str) -> PathBuf {
        self.case_dir(case).join("femu.log")
    }
    pub fn slurm_dir(&self) -> PathBuf {
        self.0.join("slurm")
    }
    pub fn jobs_file(&self) -> PathBuf {
        self.slurm_dir().join("jobs.json")
    }
    pub fn collect_dir(&self) -> PathBuf {
        self.0.join("collect")
    }

    /// The plan of the batch in this folder.
    pub fn read_plan(&self) -> Result<Plan> {
        let path = self.plan_file();
        if !path.is_file() {
            crate::bail!(
                "{} is not a femu batch folder (no batch.json)",
                self.0.display()
            );
        }
        Ok(femu_study::output::read_json(&path)?)
    }

    pub fn write_plan(&self, plan: &Plan) -> Result<()> {
        write_atomic(&self.plan_file(), &serde_json::to_string_pretty(plan)?)
    }

    /// The outcome a case recorded, if it ever started.
    pub fn read_record(&self, case: &str) -> Result<Option<CaseRecord>> {
        let path = self.case_record(case);
        if !path.exists() {
            return Ok(None);
        }
        Ok(Some(femu_study::output::read_json(&path)?))
    }

    pub fn write_record(&self, record: &CaseRecord) -> Result<()> {
        write_atomic(
            &self.case_record(&record.case),
            &serde_json::to_string_pretty(record)?,
        )
    }
}

/// `batch.json`: what the batch is made of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub femu_version: String,
    /// The batch file the plan was made from.
    pub batch_file: PathBuf,
    /// [`fingerprint`] of the batch file's text when the plan was written (`None` in a folder
    /// written before it was recorded): tells a `--resume` with a moved copy of the same file
    /// from one with another batch's file.
    #[serde(default)]
    pub batch_fingerprint: Option<String>,
    pub written_unix_s: u64,
    /// The variables (`subject`, `side`, ...) in the table's column order.
    pub variables: Vec<String>,
    pub cases: Vec<PlannedCase>,
}

/// One case of the plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedCase {
    pub name: String,
    /// `cases.csv line 4`.
    pub origin: String,
    pub vars: BTreeMap<String, String>,
    /// [`fingerprint`] of the case's study.toml.
    pub fingerprint: String,
}

/// What a case's run came to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RecordStatus {
    Running,
    Done,
    Failed,
    Interrupted,
}

/// `cases/NAME/case.json`: a case's outcome, written when it starts and when it ends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseRecord {
    pub case: String,
    pub status: RecordStatus,
    /// The fingerprint of the study this outcome is of.
    pub fingerprint: String,
    pub host: String,
    pub pid: u32,
    /// `JOB_TASK` when a Slurm array task ran it.
    pub slurm_task: Option<String>,
    pub started_unix_s: u64,
    pub seconds: f64,
    pub error: Option<String>,
    pub femu_version: String,
}

/// Writes `text` to `path` whole: a temporary file in the same folder renamed over `path`.
pub fn write_atomic(path: &Path, text: &str) -> Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    std::fs::write(&tmp, text).at(&tmp, || format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).at(path, || format!("cannot write {}", path.display()))
}

/// Seconds since 1970.
pub fn unix_now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// This machine's name (`/proc/sys/kernel/hostname`, else `$HOSTNAME`, else `localhost`).
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into())
}

/// A fingerprint of a study's text (64-bit FNV-1a, hexadecimal): tells an unchanged case from
/// one whose values changed since it ran (not a cryptographic hash).
pub fn fingerprint(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprints_tell_texts_apart() {
        // FNV-1a's published test vectors.
        assert_eq!(fingerprint(""), "cbf29ce484222325");
        assert_eq!(fingerprint("a"), "af63dc4c8601ec8c");
        assert_ne!(fingerprint("c10_kpa = 0.8"), fingerprint("c10_kpa = 0.9"));
    }

    #[test]
    fn records_round_trip_whole() {
        let dir = std::env::temp_dir().join(format!("femu-batch-folder-{}", std::process::id()));
        let b = BatchDir::new(&dir);
        std::fs::create_dir_all(b.case_dir("a")).unwrap();
        let r = CaseRecord {
            case: "a".into(),
            status: RecordStatus::Failed,
            fingerprint: fingerprint("x"),
            host: host_name(),
            pid: 7,
            slurm_task: Some("12_3".into()),
            started_unix_s: unix_now(),
            seconds: 1.5,
            error: Some("measurement: line 7 is not finite".into()),
            femu_version: "0".into(),
        };
        b.write_record(&r).unwrap();
        assert_eq!(b.read_record("a").unwrap(), Some(r));
        assert_eq!(b.read_record("b").unwrap(), None);
        // No temporary file is left behind.
        let left: Vec<_> = std::fs::read_dir(b.case_dir("a")).unwrap().collect();
        assert_eq!(left.len(), 1);
        assert!(b.read_plan().is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
