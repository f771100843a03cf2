//! The local runner: the cases on this machine, at most `jobs` at once, each a child process
//! (`femu batch case DIR NAME`) of its own — a case that fails, panics or is killed takes
//! nothing of the others with it — writing its output to `cases/NAME/femu.log`.
//!
//! Stopping: each child runs in a process group of its own, so a Ctrl-C at the terminal reaches
//! the runner alone; the runner then starts no new case and sends each running case one
//! SIGTERM, which `femu run` takes as a request to stop after its current unit of work (keeping
//! its finished steps, recording `interrupted`), and waits for them. The groups of the running
//! cases are recorded process-wide, so that a second Ctrl-C, which ends the runner at once, ends
//! them too ([`end_case_groups`]: SIGTERM, then SIGKILL) instead of leaving them running.

use crate::error::{IoContext, Result};
use crate::folder::{BatchDir, CaseRecord, RecordStatus};
use femu_study::Progress;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The process groups (each led by its case's process) of the cases running now.
static CASE_GROUPS: Mutex<Vec<u32>> = Mutex::new(Vec::new());

fn case_groups() -> std::sync::MutexGuard<'static, Vec<u32>> {
    CASE_GROUPS.lock().unwrap_or_else(|p| p.into_inner())
}

/// Ends the process group of every case this process is running: SIGTERM (a case's second stop
/// request, which ends it at once), up to `grace` for the groups to go, then SIGKILL to those
/// left. For the command line's second Ctrl-C, just before it exits; returns the groups ended.
pub fn end_case_groups(grace: Duration) -> usize {
    let groups: Vec<u32> = case_groups().clone();
    for &g in &groups {
        signal_group(g, Signal::Term);
    }
    let t0 = Instant::now();
    while t0.elapsed() < grace && groups.iter().any(|&g| group_alive(g)) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let left: Vec<u32> = groups.iter().copied().filter(|&g| group_alive(g)).collect();
    for &g in &left {
        signal_group(g, Signal::Kill);
    }
    // SIGKILL is not refused, but the kernel takes a moment to end a process.
    let t1 = Instant::now();
    while t1.elapsed() < Duration::from_millis(500) && left.iter().any(|&g| group_alive(g)) {
        std::thread::sleep(Duration::from_millis(10));
    }
    groups.len()
}

/// How the local runner runs.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalOptions {
    /// Cases at once.
    pub jobs: usize,
    /// Threads of each case (RAYON_NUM_THREADS of its process).
    pub threads_per_case: usize,
    /// The femu binary the cases run with.
    pub femu: PathBuf,
}

impl LocalOptions {
    /// `jobs` cases at once (no more than `cases`) with `femu`, this machine's cores shared
    /// among them.
    pub fn new(jobs: usize, cases: usize, femu: PathBuf) -> LocalOptions {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let jobs = jobs.min(cases).max(1);
        LocalOptions {
            jobs,
            threads_per_case: (cores / jobs).max(1),
            femu,
        }
    }
}

/// What a local run came to: the cases by outcome (with the error of each failed one).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LocalOutcome {
    pub done: Vec<String>,
    pub failed: Vec<(String, String)>,
    pub interrupted: Vec<String>,
    /// Cases not started because the run was stopped.
    pub not_started: Vec<String>,
    pub seconds: f64,
}

struct Running {
    name: String,
    child: Child,
    signalled: bool,
}

/// Runs `cases` of the batch in `dir` (their study.toml written) on this machine.
pub fn run_local(
    dir: &BatchDir,
    cases: &[String],
    opts: &LocalOptions,
    progress: &dyn Progress,
) -> Result<LocalOutcome> {
    let t0 = Instant::now();
    let mut out = LocalOutcome::default();
    let mut queue = cases.iter();
    let mut running: Vec<Running> = Vec::new();
    let bar = progress.task(&format!("cases ({} at once)", opts.jobs), Some(cases.len()));
    loop {
        let stop = progress.cancelled();
        if stop {
            for r in running.iter_mut().filter(|r| !r.signalled) {
                terminate(r.child.id());
                r.signalled = true;
            }
        }
        while !stop && running.len() < opts.jobs {
            let Some(name) = queue.next() else { break };
            let child = spawn(dir, name, opts)?;
            case_groups().push(child.id());
            running.push(Running {
                name: name.clone(),
                child,
                signalled: false,
            });
        }
        if running.is_empty() {
            break;
        }
        let names: Vec<&str> = running.iter().map(|r| r.name.as_str()).collect();
        bar.message(&names.join(", "));
        let mut k = 0;
        while k < running.len() {
            let ended = running[k].child.try_wait().at(&opts.femu, || {
                format!("cannot wait for the process of case {}", running[k].name)
            })?;
            match ended {
                Some(status) => {
                    let r = running.swap_remove(k);
                    case_groups().retain(|&g| g != r.child.id());
                    let record = settle(dir, &r.name, status)?;
                    match record.status {
                        RecordStatus::Done => out.done.push(r.name),
                        RecordStatus::Interrupted => out.interrupted.push(r.name),
                        _ => {
                            let why = record.error.unwrap_or_default();
                            let first = why.lines().next().unwrap_or("").to_string();
                            progress.warn(&format!("case {} failed: {first}", r.name));
                            out.failed.push((r.name, why));
                        }
                    }
                    bar.inc(1);
                }
                None => k += 1,
            }
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    out.not_started = queue.cloned().collect();
    out.seconds = t0.elapsed().as_secs_f64();
    Ok(out)
}

/// Starts case `name` as a child process.
fn spawn(dir: &BatchDir, name: &str, opts: &LocalOptions) -> Result<Child> {
    let log_path = dir.case_log(name);
    let log = std::fs::File::create(&log_path)
        .at(&log_path, || format!("cannot write {}", log_path.display()))?;
    let out = log
        .try_clone()
        .at(&log_path, || format!("cannot write {}", log_path.display()))?;
    let mut cmd = Command::new(&opts.femu);
    cmd.arg("batch")
        .arg("case")
        .arg(dir.root())
        .arg(name)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(log)
        .env("RAYON_NUM_THREADS", opts.threads_per_case.to_string());
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        cmd.process_group(0);
    }
    cmd.spawn().at(&opts.femu, || {
        format!("cannot start {} for case {name}", opts.femu.display())
    })
}

/// The record of a case whose process ended with `status`: its own, or — when the process ended
/// without recording its end (killed, crashed) — a failure written for it.
fn settle(dir: &BatchDir, name: &str, status: ExitStatus) -> Result<CaseRecord> {
    let record = dir.read_record(name).ok().flatten();
    match record {
        Some(r) if r.status != RecordStatus::Running => Ok(r),
        earlier => {
            let log = std::fs::read_to_string(dir.case_log(name)).unwrap_or_default();
            let last = log
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("");
            let planned = dir.read_plan()?;
            let fingerprint = planned
                .cases
                .iter()
                .find(|c| c.name == name)
                .map(|c| c.fingerprint.clone())
                .unwrap_or_default();
            let r = CaseRecord {
                case: name.to_string(),
                status: RecordStatus::Failed,
                error: Some(format!(
                    "the case's process ended without recording an outcome ({status}); last line of {}: {last}",
                    dir.case_log(name).display()
                )),
                ..earlier.unwrap_or(CaseRecord {
                    case: name.to_string(),
                    status: RecordStatus::Failed,
                    fingerprint,
                    host: crate::folder::host_name(),
                    pid: 0,
                    slurm_task: None,
                    started_unix_s: crate::folder::unix_now(),
                    seconds: 0.0,
                    error: None,
                    femu_version: env!("CARGO_PKG_VERSION").into(),
                })
            };
            dir.write_record(&r)?;
            Ok(r)
        }
    }
}

#[derive(Clone, Copy)]
enum Signal {
    Term,
    Kill,
}

/// Sends `signal` to the process group `pgid` (a case's, which its process leads).
fn signal_group(pgid: u32, signal: Signal) {
    #[cfg(unix)]
    if let Ok(pgid) = i32::try_from(pgid) {
        let sig = match signal {
            Signal::Term => libc::SIGTERM,
            Signal::Kill => libc::SIGKILL,
        };
        // SAFETY: kill(2) takes plain integers and touches no memory of this process; `pgid`
        // is positive (a group this runner created), so `-pgid` names that group alone, never
        // 0 (this process's group) or -1 (every process).
        if pgid > 1 {
            unsafe {
                libc::kill(-pgid, sig);
            }
        }
    }
    #[cfg(not(unix))]
    let _ = (pgid, signal);
}

/// Whether a process of group `pgid` is alive (a zombie, ended but not yet reaped by the
/// runner, does not count).
fn group_alive(pgid: u32) -> bool {
    #[cfg(target_os = "linux")]
    {
        // The group's leader is the case's process; any process of the group counts.
        let Ok(entries) = std::fs::read_dir("/proc") else {
            return false;
        };
        entries.flatten().any(|e| {
            let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
                return false;
            };
            // pid (comm) state ppid pgrp ...: the fields after the last ')'.
            let fields: Vec<&str> = stat
                .rsplit_once(')')
                .map_or(vec![], |(_, rest)| rest.split_whitespace().collect());
            fields.len() > 2 && fields[0] != "Z" && fields[2] == pgid.to_string()
        })
    }
    #[cfg(not(target_os = "linux"))]
    {
        process_alive(pgid)
    }
}

/// Asks process `pid` to stop (SIGTERM).
fn terminate(pid: u32) {
    #[cfg(unix)]
    if let Ok(pid) = i32::try_from(pid) {
        // SAFETY: kill(2) takes plain integers and touches no memory of this process; `pid` is
        // a positive process id (a child this runner started), never 0 or negative (which
        // would name process groups).
        if pid > 0 {
            unsafe {
                libc::kill(pid, libc::SIGTERM);
            }
        }
    }
    #[cfg(not(unix))]
    let _ = pid;
}

/// Whether process `pid` of this host is alive (signal 0: the existence check of kill(2)).
pub fn process_alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = i32::try_from(pid) else {
            return false;
        };
        if pid <= 0 {
            return false;
        }
        // SAFETY: as in `terminate`; signal 0 sends nothing, it only checks that the process
        // exists (EPERM: it exists, owned by another user).
        let r = unsafe { libc::kill(pid, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}
