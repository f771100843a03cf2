//! The state of every case of a batch (`femu batch status DIR`), from what the cases recorded
//! (`case.json`, written by each case's own process when it starts and when it ends) and, for
//! cases submitted to Slurm, from the queue (`squeue`; `sacct` too where the cluster keeps
//! accounting). A case's own record is the authority on how it ended; Slurm tells what the
//! record cannot: that a task waits, or that it ended without recording anything (killed at
//! its time or memory limit, its node lost).

use crate::error::Result;
use crate::folder::{host_name, BatchDir, CaseRecord, PlannedCase, RecordStatus};
use crate::slurm::{self, Submissions, TaskState};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// Where a case stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CaseState {
    /// Not started.
    Pending,
    /// Waiting in Slurm's queue.
    Queued,
    Running,
    Done,
    Failed,
    Interrupted,
    /// Started (or submitted) and gone without an outcome: its process or task ended without
    /// writing one (killed, out of memory or time, its node lost).
    Lost,
}

impl CaseState {
    pub fn name(self) -> &'static str {
        match self {
            CaseState::Pending => "pending",
            CaseState::Queued => "queued",
            CaseState::Running => "running",
            CaseState::Done => "done",
            CaseState::Failed => "failed",
            CaseState::Interrupted => "interrupted",
            CaseState::Lost => "lost",
        }
    }
}

/// One case's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseStatus {
    pub name: String,
    pub origin: String,
    pub vars: BTreeMap<String, String>,
    pub state: CaseState,
    /// Done, but of another version of its study (its values changed since): `--resume` runs
    /// it again.
    pub changed: bool,
    /// `JOB_TASK STATE (reason)` for a case submitted to Slurm.
    pub slurm: Option<String>,
    pub host: Option<String>,
    pub seconds: Option<f64>,
    pub error: Option<String>,
}

impl CaseStatus {
    /// Whether `femu batch run --resume` runs this case again.
    pub fn needs_run(&self) -> bool {
        matches!(
            self.state,
            CaseState::Pending | CaseState::Failed | CaseState::Interrupted | CaseState::Lost
        ) || (self.state == CaseState::Done && self.changed)
    }
}

/// Every case's state, and what the status could not learn (no Slurm here, no accounting).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchStatus {
    pub cases: Vec<CaseStatus>,
    pub notes: Vec<String>,
}

impl BatchStatus {
    /// How many cases are in each state.
    pub fn counts(&self) -> BTreeMap<CaseState, usize> {
        let mut m = BTreeMap::new();
        for c in &self.cases {
            *m.entry(c.state).or_insert(0) += 1;
        }
        m
    }
}

/// The state of every case of the batch in `dir`.
pub fn status(dir: &BatchDir) -> Result<BatchStatus> {
    let plan = dir.read_plan()?;
    let jobs = Submissions::read(dir)?;
    let mut notes = Vec::new();
    let ids: Vec<&str> = jobs.submissions.iter().map(|s| s.job_id.as_str()).collect();
    let mut tasks = BTreeMap::new();
    if !ids.is_empty() {
        match slurm::queue(&ids) {
            Ok(q) => tasks = q,
            Err(e) => notes.push(format!(
                "the Slurm queue cannot be read ({e:#}): states from the cases' own records only"
            )),
        }
        match slurm::accounting(&ids) {
            // Accounting knows tasks the queue has forgotten (and their exit codes); the
            // queue's state of a task it still holds is the fresher.
            Ok(acct) => {
                for (k, v) in acct {
                    tasks.entry(k).or_insert(v);
                }
            }
            Err(e) => notes.push(format!(
                "no Slurm accounting ({}): finished tasks are known from the queue while it holds them (MinJobAge) and from each case's case.json",
                first_line(&format!("{e:#}"))
            )),
        }
    }
    let here = host_name();
    let cases = plan
        .cases
        .iter()
        .map(|c| {
            let record = dir.read_record(&c.name)?;
            let task = jobs.task_of(&c.name).map(|(job, k)| {
                let state = tasks.get(&(job.to_string(), k)).cloned();
                (format!("{job}_{k}"), state)
            });
            Ok(case_status(c, record, task, &here, dir))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(BatchStatus { cases, notes })
}

fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or("")
}

/// One case's state from its record, its Slurm task (`JOB_TASK` and what Slurm says of it,
/// if anything) and this host's name.
fn case_status(
    c: &PlannedCase,
    record: Option<CaseRecord>,
    task: Option<(String, Option<TaskState>)>,
    here: &str,
    dir: &BatchDir,
) -> CaseStatus {
    let slurm = task.as_ref().map(|(id, s)| match s {
        Some(s) if s.detail.is_empty() => format!("{id} {}", s.state),
        Some(s) => format!("{id} {} ({})", s.state, s.detail),
        None => format!("{id} (no longer in the queue)"),
    });
    let mut st = CaseStatus {
        name: c.name.clone(),
        origin: c.origin.clone(),
        vars: c.vars.clone(),
        state: CaseState::Pending,
        changed: false,
        slurm,
        host: record.as_ref().map(|r| r.host.clone()),
        seconds: record.as_ref().map(|r| r.seconds),
        error: record.as_ref().and_then(|r| r.error.clone()),
    };
    let queued = task.as_ref().and_then(|(_, s)| s.as_ref());
    // A task Slurm still has to run (or runs) is the case's present, whatever an earlier
    // attempt recorded.
    if let Some(q) = queued.filter(|q| q.is_active()) {
        st.state = match q.state.as_str() {
            "RUNNING" | "COMPLETING" => CaseState::Running,
            _ => CaseState::Queued,
        };
        return st;
    }
    let slurm_log = || {
        task.as_ref().and_then(|(id, _)| {
            let (job, k) = id.split_once('_')?;
            let path = slurm::task_log(dir, job, k.parse().ok()?);
            Some(path.display().to_string())
        })
    };
    match record {
        Some(r) => {
            st.changed = r.fingerprint != c.fingerprint;
            st.state = match r.status {
                RecordStatus::Done => CaseState::Done,
                RecordStatus::Failed => CaseState::Failed,
                RecordStatus::Interrupted => CaseState::Interrupted,
                RecordStatus::Running => running_or_lost(&r, queued, here),
            };
            if st.state == CaseState::Lost {
                let why = match queued {
                    Some(q) => format!("Slurm ended its task: {}", q.state),
                    None => "its process is gone".to_string(),
                };
                st.error = Some(format!(
                    "started on {} (pid {}) and ended without an outcome ({why}); see {}",
                    r.host,
                    r.pid,
                    slurm_log().unwrap_or_else(|| dir.case_log(&c.name).display().to_string())
                ));
            }
        }
        None if task.is_some() => {
            st.state = CaseState::Lost;
            st.error = Some(format!(
                "submitted to Slurm and never started ({}); see {}",
                queued.map_or("not in the queue any more".to_string(), |q| q.state.clone()),
                slurm_log().unwrap_or_default()
            ));
        }
        None => {}
    }
    st
}

/// A case whose record says it runs: still running, unless its process is known to be gone (a
/// Slurm task that ended, or a process of this host that is not alive).
fn running_or_lost(r: &CaseRecord, queued: Option<&TaskState>, here: &str) -> CaseState {
    if queued.is_some_and(|q| !q.is_active()) {
        return CaseState::Lost;
    }
    if r.host == here && !crate::local::process_alive(r.pid) {
        return CaseState::Lost;
    }
    CaseState::Running
}

impl fmt::Display for BatchStatus {
    /// A table: one line per case, the counts, the notes.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let w = self
            .cases
            .iter()
            .map(|c| c.name.len())
            .max()
            .unwrap_or(4)
            .max(4);
        let slurm = self.cases.iter().any(|c| c.slurm.is_some());
        write!(f, "{:<w$}  {:<11}  {:>8}", "case", "state", "time (s)")?;
        if slurm {
            write!(f, "  {:<28}", "slurm task")?;
        }
        writeln!(f, "  note")?;
        for c in &self.cases {
            let state = if c.changed { "done*" } else { c.state.name() };
            let time = c.seconds.map_or(String::new(), |s| format!("{s:.1}"));
            write!(f, "{:<w$}  {:<11}  {:>8}", c.name, state, time)?;
            if slurm {
                write!(f, "  {:<28}", c.slurm.as_deref().unwrap_or(""))?;
            }
            let note = c.error.as_deref().map(first_line).unwrap_or("");
            writeln!(f, "  {note}")?;
        }
        let counts: Vec<String> = self
            .counts()
            .iter()
            .map(|(s, n)| format!("{n} {}", s.name()))
            .collect();
        writeln!(f, "{} cases: {}", self.cases.len(), counts.join(", "))?;
        if self.cases.iter().any(|c| c.changed) {
            writeln!(
                f,
                "done*: done, but its values changed since; --resume runs it again"
            )?;
        }
        for n in &self.notes {
            writeln!(f, "note: {n}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::folder::unix_now;

    fn planned() -> PlannedCase {
        PlannedCase {
            name: "s01".into(),
            origin: "cases.csv line 2".into(),
            vars: BTreeMap::new(),
            fingerprint: "f1".into(),
        }
    }

    fn record(status: RecordStatus, host: &str, pid: u32) -> CaseRecord {
        CaseRecord {
            case: "s01".into(),
            status,
            fingerprint: "f1".into(),
            host: host.into(),
            pid,
            slurm_task: None,
            started_unix_s: unix_now(),
            seconds: 2.0,
            error: None,
            femu_version: "0".into(),
        }
    }

    fn state(s: &str) -> Option<TaskState> {
        Some(TaskState {
            state: s.into(),
            detail: String::new(),
        })
    }

    #[test]
    fn records_and_queue_make_the_state() {
        let dir = BatchDir::new(std::path::Path::new("/b"));
        let here = "this-host";
        let me = std::process::id();
        let st = |r: Option<CaseRecord>, t: Option<(String, Option<TaskState>)>| {
            case_status(&planned(), r, t, here, &dir).state
        };
        let task = |s: &str| Some(("7_0".to_string(), state(s)));
        assert_eq!(st(None, None), CaseState::Pending);
        assert_eq!(st(None, task("PENDING")), CaseState::Queued);
        assert_eq!(st(None, Some(("7_0".into(), None))), CaseState::Lost);
        assert_eq!(
            st(Some(record(RecordStatus::Done, here, me)), None),
            CaseState::Done
        );
        // A resubmitted case waits in the queue whatever its last attempt recorded.
        assert_eq!(
            st(
                Some(record(RecordStatus::Failed, here, me)),
                task("PENDING")
            ),
            CaseState::Queued
        );
        assert_eq!(
            st(
                Some(record(RecordStatus::Running, here, me)),
                task("RUNNING")
            ),
            CaseState::Running
        );
        // Running on this host: alive (this process) or gone.
        assert_eq!(
            st(Some(record(RecordStatus::Running, here, me)), None),
            CaseState::Running
        );
        assert_eq!(
            st(
                Some(record(RecordStatus::Running, here, u32::MAX - 1)),
                None
            ),
            CaseState::Lost
        );
        // Another host's process cannot be checked without Slurm: taken as running.
        assert_eq!(
            st(Some(record(RecordStatus::Running, "node7", 1)), None),
            CaseState::Running
        );
        // Slurm ended the task before it could record its end (time limit).
        let lost = case_status(
            &planned(),
            Some(record(RecordStatus::Running, "node7", 1)),
            task("TIMEOUT"),
            here,
            &dir,
        );
        assert_eq!(lost.state, CaseState::Lost);
        assert!(lost.error.unwrap().contains("TIMEOUT"));
        // Done, then its values changed: run again on --resume.
        let mut old = record(RecordStatus::Done, here, me);
        old.fingerprint = "f0".into();
        let c = case_status(&planned(), Some(old), None, here, &dir);
        assert!(c.changed && c.needs_run());
    }
}
