//! The Slurm runner: one job array per submission (`sbatch --array`), each array task one case
//! (`femu batch case DIR NAME`, which runs the case's `femu run` and records its outcome), the
//! resources of each task from the batch file's `[slurm]` table or the command's flags; the
//! array's state from `squeue` (and `sacct` where the cluster keeps accounting). Slurm does the
//! distribution: nothing here schedules.
//!
//! ```text
//! DIR/slurm/array-K.sbatch     the K-th submission's script (what --dry-run prints)
//! DIR/slurm/jobs.json          every submission: its job id and the case of each array task
//! DIR/slurm/logs/JOB_TASK.out  Slurm's output of each task (the case's own is cases/NAME/femu.log)
//! ```

use crate::bail;
use crate::error::{IoContext, Result};
use crate::folder::{write_atomic, BatchDir};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The resources of each array task (`[slurm]` in the batch file; the flags of `femu batch
/// run --slurm` over it). `None`: the cluster's default.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlurmResources {
    /// `--cpus-per-task`; also the threads of the task's `femu run` (RAYON_NUM_THREADS).
    pub cpus_per_task: Option<u32>,
    /// `--mem` per task: `4G`, `4000M`, `4000` (MB).
    pub mem: Option<String>,
    /// `--time` per task: `MM`, `HH:MM:SS`, `D-HH:MM:SS`, ...
    pub time: Option<String>,
    pub partition: Option<String>,
    pub account: Option<String>,
    /// Array tasks running at once (`--array=0-N%MAX`).
    pub max_parallel: Option<u32>,
    /// More `#SBATCH` options, as written (`"--qos=normal"`, `"--constraint=avx2"`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extra: Vec<String>,
    /// Shell lines run before femu in each task (`"module load gcc"`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub setup: Vec<String>,
    /// The femu binary on the compute nodes (default: the one submitting).
    pub femu: Option<String>,
}

impl SlurmResources {
    /// `self` with every value `flags` gives put over it.
    pub fn with(&self, flags: &SlurmResources) -> SlurmResources {
        let pick = |a: &Option<String>, b: &Option<String>| b.clone().or_else(|| a.clone());
        SlurmResources {
            cpus_per_task: flags.cpus_per_task.or(self.cpus_per_task),
            mem: pick(&self.mem, &flags.mem),
            time: pick(&self.time, &flags.time),
            partition: pick(&self.partition, &flags.partition),
            account: pick(&self.account, &flags.account),
            max_parallel: flags.max_parallel.or(self.max_parallel),
            extra: [self.extra.clone(), flags.extra.clone()].concat(),
            setup: [self.setup.clone(), flags.setup.clone()].concat(),
            femu: pick(&self.femu, &flags.femu),
        }
    }

    /// Checks the values Slurm would reject late (at submission, or worse, as a pending reason).
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.cpus_per_task == Some(0) {
            return Err("cpus_per_task must be at least 1".into());
        }
        if self.max_parallel == Some(0) {
            return Err("max_parallel must be at least 1".into());
        }
        if let Some(m) = &self.mem {
            let digits = m.trim_end_matches(['K', 'M', 'G', 'T', 'k', 'm', 'g', 't']);
            if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
                return Err(format!(
                    "mem = \"{m}\": give a size such as \"4G\", \"4000M\" or \"4000\" (MB)"
                ));
            }
        }
        if let Some(t) = &self.time {
            if !is_slurm_time(t) {
                return Err(format!(
                    "time = \"{t}\": give MM, MM:SS, HH:MM:SS, D-HH, D-HH:MM or D-HH:MM:SS"
                ));
            }
        }
        for (key, v) in [
            ("partition", &self.partition),
            ("account", &self.account),
            ("femu", &self.femu),
        ] {
            if v.as_deref()
                .is_some_and(|v| v.is_empty() || v.contains('\n'))
            {
                return Err(format!("{key} must be one non-empty line"));
            }
        }
        if let Some(e) = self
            .extra
            .iter()
            .find(|e| !e.starts_with('-') || e.contains('\n'))
        {
            return Err(format!(
                "extra = \"{e}\": each entry is one sbatch option (\"--qos=normal\")"
            ));
        }
        if let Some(s) = self.setup.iter().find(|s| s.contains('\n')) {
            return Err(format!("setup = \"{s}\": one shell line per entry"));
        }
        Ok(())
    }
}

/// Slurm's time formats: `M`, `M:S`, `H:M:S`, `D-H`, `D-H:M`, `D-H:M:S`.
fn is_slurm_time(t: &str) -> bool {
    let numbers = |s: &str, max: usize| {
        let parts: Vec<&str> = s.split(':').collect();
        parts.len() <= max
            && parts
                .iter()
                .all(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()))
    };
    match t.split_once('-') {
        Some((days, rest)) => numbers(days, 1) && numbers(rest, 3),
        None => numbers(t, 3),
    }
}

/// One submission: its job id and the case of each array task (task k runs `cases[k]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Submission {
    pub job_id: String,
    /// The script, relative to the batch folder.
    pub script: String,
    pub cases: Vec<String>,
    pub submitted_unix_s: u64,
}

/// `slurm/jobs.json`: every submission, oldest first.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Submissions {
    pub submissions: Vec<Submission>,
}

impl Submissions {
    /// The submissions of a batch folder (none when it never used Slurm).
    pub fn read(dir: &BatchDir) -> Result<Submissions> {
        let path = dir.jobs_file();
        if !path.exists() {
            return Ok(Submissions::default());
        }
        Ok(femu_study::output::read_json(&path)?)
    }

    fn save(&self, dir: &BatchDir) -> Result<()> {
        write_atomic(&dir.jobs_file(), &serde_json::to_string_pretty(self)?)
    }

    /// The latest array task of `case`: `(job id, task index)`.
    pub fn task_of(&self, case: &str) -> Option<(&str, usize)> {
        self.submissions.iter().rev().find_map(|s| {
            let k = s.cases.iter().position(|c| c == case)?;
            Some((s.job_id.as_str(), k))
        })
    }
}

/// `s` quoted for a POSIX shell.
fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// The array script running `cases` of the batch folder `dir` (absolute) with `femu`.
pub fn script(
    dir: &BatchDir,
    cases: &[String],
    res: &SlurmResources,
    femu: &Path,
) -> Result<String> {
    let root = dir.root();
    let shown = root.display().to_string();
    if shown.chars().any(|c| c.is_whitespace() || c == '%') {
        bail!(
            "the batch folder {shown} has a blank or a % in its path, which #SBATCH lines cannot carry: choose another --out"
        );
    }
    if cases.is_empty() {
        bail!("no case to submit");
    }
    let n = cases.len();
    let mut s = String::from("#!/bin/bash\n");
    let mut opt = |o: String| {
        let _ = writeln!(s, "#SBATCH {o}");
    };
    let job = root
        .file_name()
        .map(|n| {
            n.to_string_lossy().replace(
                |c: char| !c.is_ascii_alphanumeric() && c != '-' && c != '_' && c != '.',
                "_",
            )
        })
        .unwrap_or_default();
    opt(format!("--job-name=femu-batch-{job}"));
    opt(match res.max_parallel {
        Some(m) => format!("--array=0-{}%{m}", n - 1),
        None => format!("--array=0-{}", n - 1),
    });
    opt(format!("--output={shown}/slurm/logs/%A_%a.out"));
    opt(format!(
        "--cpus-per-task={}",
        res.cpus_per_task.unwrap_or(1)
    ));
    for (flag, v) in [
        ("mem", &res.mem),
        ("time", &res.time),
        ("partition", &res.partition),
        ("account", &res.account),
    ] {
        if let Some(v) = v {
            opt(format!("--{flag}={v}"));
        }
    }
    for e in &res.extra {
        opt(e.clone());
    }
    let _ = write!(
        s,
        "# femu batch {shown}: {n} cases, one `femu run` per array task (written by femu {}).\n\
         # Task k runs `femu batch case DIR NAME` for the k-th name below: the case's study.toml\n\
         # run into cases/NAME/, its outcome recorded in cases/NAME/case.json, its output in\n\
         # cases/NAME/femu.log. `femu batch status DIR` reads them; `femu batch collect DIR` gathers.\n\
         set -u\n",
        env!("CARGO_PKG_VERSION")
    );
    for line in &res.setup {
        let _ = writeln!(s, "{line}");
    }
    let _ = writeln!(s, "cases=({})", cases.join(" "));
    let dir_q = sh_quote(&shown);
    let femu_q = sh_quote(&femu.display().to_string());
    let _ = write!(
        s,
        "name=\"${{cases[$SLURM_ARRAY_TASK_ID]}}\"\n\
         export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"\n\
         echo \"femu batch: array task $SLURM_ARRAY_TASK_ID runs case $name on $(hostname)\"\n\
         exec {femu_q} batch case {dir_q} \"$name\" > {dir_q}/cases/\"$name\"/femu.log 2>&1\n"
    );
    Ok(s)
}

/// Writes the script of `cases` as the next submission, submits it with `sbatch`, records the
/// job in `slurm/jobs.json`.
pub fn submit(
    dir: &BatchDir,
    cases: &[String],
    res: &SlurmResources,
    femu: &Path,
) -> Result<Submission> {
    let text = script(dir, cases, res, femu)?;
    let mut jobs = Submissions::read(dir)?;
    let logs = dir.slurm_dir().join("logs");
    std::fs::create_dir_all(&logs).at(&logs, || {
        format!("cannot create {}", dir.slurm_dir().display())
    })?;
    let name = format!("array-{}.sbatch", jobs.submissions.len() + 1);
    let path = dir.slurm_dir().join(&name);
    write_atomic(&path, &text)?;
    let out = Command::new("sbatch")
        .arg("--parsable")
        .arg(&path)
        .output()
        .at(Path::new("sbatch"), || {
            "cannot run sbatch (is Slurm installed on this machine?)"
        })?;
    if !out.status.success() {
        bail!(
            "sbatch {} failed: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    // `--parsable`: "JOBID" or "JOBID;CLUSTER".
    let stdout = String::from_utf8_lossy(&out.stdout);
    let job_id = stdout.trim().split(';').next().unwrap_or("").to_string();
    if job_id.is_empty() || !job_id.bytes().all(|b| b.is_ascii_digit()) {
        bail!("sbatch printed no job id: {stdout:?}");
    }
    let submission = Submission {
        job_id,
        script: format!("slurm/{name}"),
        cases: cases.to_vec(),
        submitted_unix_s: crate::folder::unix_now(),
    };
    jobs.submissions.push(submission.clone());
    jobs.save(dir)?;
    Ok(submission)
}

/// A task's state as Slurm reports it (`PENDING`, `RUNNING`, `COMPLETED`, `FAILED`, `TIMEOUT`,
/// ...) and, from squeue, the reason it waits.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskState {
    pub state: String,
    pub detail: String,
}

impl TaskState {
    /// Whether Slurm has the task still to run or running.
    pub fn is_active(&self) -> bool {
        matches!(
            self.state.as_str(),
            "PENDING"
                | "CONFIGURING"
                | "RUNNING"
                | "COMPLETING"
                | "REQUEUED"
                | "RESIZING"
                | "SUSPENDED"
        ) || self.state.starts_with("REQUEUE")
    }
}

/// The states of the array tasks of `job_ids` still known to the controller: `squeue` (which
/// also lists tasks finished within the cluster's MinJobAge).
pub fn queue(job_ids: &[&str]) -> Result<BTreeMap<(String, usize), TaskState>> {
    if job_ids.is_empty() {
        return Ok(BTreeMap::new());
    }
    let out = Command::new("squeue")
        .args(["-h", "-r", "-t", "all", "-o", "%F|%K|%T|%r"])
        .output()
        .at(Path::new("squeue"), || "cannot run squeue")?;
    if !out.status.success() {
        bail!("squeue: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(parse_rows(&String::from_utf8_lossy(&out.stdout), job_ids))
}

/// The states and exit codes of the array tasks of `job_ids` from Slurm's accounting (`sacct`);
/// an error where the cluster keeps none.
pub fn accounting(job_ids: &[&str]) -> Result<BTreeMap<(String, usize), TaskState>> {
    if job_ids.is_empty() {
        return Ok(BTreeMap::new());
    }
    let out = Command::new("sacct")
        .args(["-n", "-P", "-X", "-o", "JobID,State,ExitCode", "-j"])
        .arg(job_ids.join(","))
        .output()
        .at(Path::new("sacct"), || "cannot run sacct")?;
    if !out.status.success() {
        bail!("sacct: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(parse_accounting(
        &String::from_utf8_lossy(&out.stdout),
        job_ids,
    ))
}

/// `JobID|State|ExitCode` rows (`sacct -n -P -X`) of the array tasks of `job_ids`: JobID is
/// `JOB_TASK` for a task that started, `JOB_[3-9]` for tasks still pending together (left out,
/// as are other jobs); State may carry a detail (`CANCELLED by 0`).
fn parse_accounting(text: &str, job_ids: &[&str]) -> BTreeMap<(String, usize), TaskState> {
    let mut map = BTreeMap::new();
    for line in text.lines() {
        let f: Vec<&str> = line.trim().split('|').collect();
        let [id, state, exit] = f[..] else { continue };
        let Some((job, task)) = id.split_once('_') else {
            continue;
        };
        let (Ok(task), true) = (task.parse::<usize>(), job_ids.contains(&job)) else {
            continue;
        };
        let state = state.split_whitespace().next().unwrap_or("").to_string();
        map.insert(
            (job.to_string(), task),
            TaskState {
                state,
                detail: format!("exit code {exit}"),
            },
        );
    }
    map
}

/// `JOB|TASK|STATE|REASON` rows of `job_ids` (rows of other jobs, and job-level rows of arrays
/// not yet split into tasks, left out).
fn parse_rows(text: &str, job_ids: &[&str]) -> BTreeMap<(String, usize), TaskState> {
    let mut map = BTreeMap::new();
    for line in text.lines() {
        let f: Vec<&str> = line.trim().split('|').collect();
        let [job, task, state, reason] = f[..] else {
            continue;
        };
        let (Ok(task), true) = (task.parse::<usize>(), job_ids.contains(&job)) else {
            continue;
        };
        map.insert(
            (job.to_string(), task),
            TaskState {
                state: state.to_string(),
                detail: if reason == "None" {
                    String::new()
                } else {
                    reason.to_string()
                },
            },
        );
    }
    map
}

/// The log Slurm writes for task `task` of `job`.
pub fn task_log(dir: &BatchDir, job: &str, task: usize) -> PathBuf {
    dir.slurm_dir()
        .join("logs")
        .join(format!("{job}_{task}.out"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_and_sizes() {
        for t in ["30", "30:00", "01:00:00", "2-00", "2-12:00", "1-00:00:00"] {
            assert!(is_slurm_time(t), "{t}");
        }
        for t in ["", "1h", "1:2:3:4", "-1", "1-", "a-1"] {
            assert!(!is_slurm_time(t), "{t}");
        }
        let ok = SlurmResources {
            mem: Some("4G".into()),
            time: Some("01:00:00".into()),
            ..Default::default()
        };
        assert!(ok.check().is_ok());
        for bad in [
            SlurmResources {
                mem: Some("4 GB".into()),
                ..Default::default()
            },
            SlurmResources {
                cpus_per_task: Some(0),
                ..Default::default()
            },
            SlurmResources {
                extra: vec!["qos=x".into()],
                ..Default::default()
            },
        ] {
            assert!(bad.check().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn flags_win_over_the_file() {
        let file = SlurmResources {
            cpus_per_task: Some(4),
            mem: Some("8G".into()),
            extra: vec!["--qos=long".into()],
            ..Default::default()
        };
        let flags = SlurmResources {
            mem: Some("2G".into()),
            time: Some("10".into()),
            ..Default::default()
        };
        let r = file.with(&flags);
        assert_eq!(r.cpus_per_task, Some(4));
        assert_eq!(r.mem.as_deref(), Some("2G"));
        assert_eq!(r.time.as_deref(), Some("10"));
        assert_eq!(r.extra, vec!["--qos=long".to_string()]);
    }

    #[test]
    fn the_script_maps_tasks_to_cases() {
        let dir = BatchDir::new(Path::new("/scratch/pop"));
        let res = SlurmResources {
            cpus_per_task: Some(2),
            mem: Some("4G".into()),
            max_parallel: Some(10),
            setup: vec!["module load gcc".into()],
            ..Default::default()
        };
        let s = script(
            &dir,
            &["s01".into(), "s02".into()],
            &res,
            Path::new("/opt/femu it's"),
        )
        .unwrap();
        assert!(s.starts_with("#!/bin/bash\n#SBATCH --job-name=femu-batch-pop\n"));
        assert!(s.contains("#SBATCH --array=0-1%10\n"));
        assert!(s.contains("#SBATCH --output=/scratch/pop/slurm/logs/%A_%a.out\n"));
        assert!(s.contains("#SBATCH --cpus-per-task=2\n#SBATCH --mem=4G\n"));
        assert!(s.contains("module load gcc\ncases=(s01 s02)\n"));
        assert!(s.contains("exec '/opt/femu it'\\''s' batch case '/scratch/pop' \"$name\""));
        assert!(script(
            &BatchDir::new(Path::new("/a b")),
            &["x".into()],
            &res,
            Path::new("f")
        )
        .is_err());
    }

    /// sacct's `-P` format as its manual gives it (not checked against a real accounting
    /// database: the CI Slurm keeps none).
    #[test]
    fn accounting_rows() {
        let rows = "12_0|COMPLETED|0:0\n12_3|FAILED|1:0\n12_1|CANCELLED by 0|0:15\n12_[4-9]|PENDING|0:0\n13_0|TIMEOUT|0:0\n12|COMPLETED|0:0\n";
        let m = parse_accounting(rows, &["12"]);
        assert_eq!(m.len(), 3);
        assert_eq!(m[&("12".to_string(), 3)].state, "FAILED");
        assert_eq!(m[&("12".to_string(), 3)].detail, "exit code 1:0");
        assert_eq!(m[&("12".to_string(), 1)].state, "CANCELLED");
        assert!(!m[&("12".to_string(), 1)].is_active());
    }

    #[test]
    fn queue_rows() {
        let rows = "12|0|COMPLETED|None\n12|1|RUNNING|None\n12|2|PENDING|Resources\n13|0|RUNNING|None\n12|N/A|PENDING|None\n";
        let m = parse_rows(rows, &["12"]);
        assert_eq!(m.len(), 3);
        assert_eq!(m[&("12".to_string(), 2)].detail, "Resources");
        assert!(m[&("12".to_string(), 1)].is_active());
        assert!(!m[&("12".to_string(), 0)].is_active());
    }
}
