//! `femu batch run BATCH --out DIR`: every case checked, the folder planned (each case's
//! study written), then the cases run on this machine or submitted as one Slurm job array.
//! With `--resume` the batch file is read again (a case fixed since is planned anew) and only
//! the cases not done — failed, interrupted, lost, never run, or changed since they ran — run
//! again; cases Slurm still has queued or running are left to it.

use crate::bail;
use crate::error::{Error, IoContext, Result};
use crate::expand::{expand, Case};
use crate::folder::{unix_now, BatchDir, Plan, PlannedCase};
use crate::local::{run_local, LocalOptions, LocalOutcome};
use crate::slurm::{self, SlurmResources, Submission};
use crate::status::{status, CaseState};
use femu_study::Progress;
use std::path::{Path, PathBuf};

/// What `femu batch run` is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Continue the batch in `out`: only the cases not done run.
    pub resume: bool,
    /// Cases at once on this machine (the batch file's `jobs`, else 1).
    pub jobs: Option<usize>,
    /// Submit to Slurm instead of running here.
    pub slurm: Option<SlurmRequest>,
    /// The femu binary the cases run with (this one).
    pub femu: PathBuf,
}

/// `--slurm`: the resources given as flags (over the batch file's `[slurm]`), `--dry-run`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SlurmRequest {
    pub dry_run: bool,
    pub resources: SlurmResources,
}

/// What `femu batch run` did.
#[derive(Debug, Clone, PartialEq)]
pub enum RunOutcome {
    /// The cases ran here (`skipped`: done before, left as they were).
    Local {
        outcome: LocalOutcome,
        skipped: Vec<String>,
    },
    /// The cases were submitted as one job array.
    Submitted {
        submission: Submission,
        skipped: Vec<String>,
    },
    /// `--dry-run`: the script that would be submitted, and its cases.
    DryRun { script: String, cases: Vec<String> },
    /// Every case is done (or with Slurm already).
    NothingToDo { skipped: Vec<String> },
}

/// Runs (or submits) the batch of `batch_file` into `opts.out`.
pub fn run(batch_file: &Path, opts: &RunOptions, progress: &dyn Progress) -> Result<RunOutcome> {
    let batch = crate::spec::read(batch_file)?;
    let cases = expand(&batch)?;
    let root =
        std::path::absolute(&opts.out).at(&opts.out, || format!("--out {}", opts.out.display()))?;
    let dir = BatchDir::new(&root);
    progress.note(&format!(
        "femu batch: {} cases of {} checked -> {}",
        cases.len(),
        batch.path.display(),
        root.display()
    ));
    let batch_fingerprint = batch_text_fingerprint(&batch.path)?;
    if opts.resume {
        same_batch(&dir, &batch.path, &batch_fingerprint)?;
    }
    let (to_run, skipped) = select(&dir, &cases, opts.resume, progress)?;
    let names: Vec<String> = to_run.iter().map(|c| c.name.clone()).collect();
    if let Some(req) = opts.slurm.as_ref().filter(|r| r.dry_run) {
        let res = batch.slurm.with(&req.resources);
        res.check()
            .map_err(|e| Error::input(format!("--slurm: {e}")))?;
        let femu = femu_on_nodes(&res, &opts.femu);
        let script = slurm::script(&dir, &names, &res, &femu)?;
        return Ok(RunOutcome::DryRun {
            script,
            cases: names,
        });
    }
    write_plan(
        &dir,
        &batch.path,
        &batch_fingerprint,
        &cases,
        &to_run,
        &skipped,
    )?;
    if to_run.is_empty() {
        return Ok(RunOutcome::NothingToDo { skipped });
    }
    match &opts.slurm {
        Some(req) => {
            let res = batch.slurm.with(&req.resources);
            res.check()
                .map_err(|e| Error::input(format!("--slurm: {e}")))?;
            let femu = femu_on_nodes(&res, &opts.femu);
            let submission = slurm::submit(&dir, &names, &res, &femu)?;
            Ok(RunOutcome::Submitted {
                submission,
                skipped,
            })
        }
        None => {
            let jobs = opts.jobs.or(batch.jobs).unwrap_or(1);
            let local = LocalOptions::new(jobs, names.len(), opts.femu.clone());
            progress.note(&format!(
                "running {} cases here, {} at once ({} threads each); logs in cases/NAME/femu.log",
                names.len(),
                local.jobs,
                local.threads_per_case
            ));
            let outcome = run_local(&dir, &names, &local, progress)?;
            Ok(RunOutcome::Local { outcome, skipped })
        }
    }
}

/// The fingerprint of the batch file's text (what `batch.json` records of it).
fn batch_text_fingerprint(path: &Path) -> Result<String> {
    let text = std::fs::read_to_string(path).at(path, || {
        format!("cannot read batch file {}", path.display())
    })?;
    Ok(crate::folder::fingerprint(&text))
}

/// `--resume` continues the batch that made the folder: the batch file recorded in its
/// `batch.json` (the same path, whose text may have been edited since: changed and added rows
/// are planned anew), or a copy of that file with the same text elsewhere. Another batch's
/// file is refused: its plan would replace the folder's and drop the other batch's cases.
fn same_batch(dir: &BatchDir, batch_file: &Path, batch_fingerprint: &str) -> Result<()> {
    if !dir.plan_file().is_file() {
        return Ok(()); // `select` says the folder holds no batch
    }
    let plan = dir.read_plan()?;
    let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    if canonical(&plan.batch_file) == canonical(batch_file)
        || plan.batch_fingerprint.as_deref() == Some(batch_fingerprint)
    {
        return Ok(());
    }
    bail!(
        "--resume: {} holds the batch of {} ({} cases), not of {}: resuming would replace its plan and drop its cases. Resume that batch with femu batch run {} --out {} --resume, or give {} another --out",
        dir.root().display(),
        plan.batch_file.display(),
        plan.cases.len(),
        batch_file.display(),
        plan.batch_file.display(),
        dir.root().display(),
        batch_file.display()
    )
}

/// The femu binary named in `[slurm] femu`, else this one.
fn femu_on_nodes(res: &SlurmResources, this: &Path) -> PathBuf {
    res.femu
        .as_ref()
        .map_or_else(|| this.to_path_buf(), PathBuf::from)
}

/// The cases to run now and those left as they are: all of them in a new folder; with
/// `resume`, those not done (or changed since) and not with Slurm.
fn select<'a>(
    dir: &BatchDir,
    cases: &'a [Case],
    resume: bool,
    progress: &dyn Progress,
) -> Result<(Vec<&'a Case>, Vec<String>)> {
    let root = dir.root();
    let planned = dir.plan_file().is_file();
    if !resume {
        if planned {
            bail!(
                "{} holds a batch already: pass --resume to run what is not done, or choose another --out",
                root.display()
            );
        }
        let occupied = std::fs::read_dir(root).is_ok_and(|mut d| d.next().is_some());
        if occupied {
            bail!(
                "{} is not empty and holds no batch: choose an empty or new folder for --out",
                root.display()
            );
        }
        return Ok((cases.iter().collect(), Vec::new()));
    }
    if !planned {
        bail!(
            "--resume: {} holds no batch (no batch.json); run without --resume first",
            root.display()
        );
    }
    let now = status(dir)?;
    let mut run = Vec::new();
    let mut skipped = Vec::new();
    for case in cases {
        let before = now.cases.iter().find(|c| c.name == case.name);
        let rerun = match before {
            None => true,
            Some(b) if matches!(b.state, CaseState::Queued | CaseState::Running) => {
                progress.note(&format!(
                    "case {}: {} ({}), left as it is",
                    case.name,
                    b.state.name(),
                    b.slurm.as_deref().unwrap_or("this machine")
                ));
                false
            }
            Some(b) if b.state == CaseState::Done => {
                // Done: again only if its values changed since it ran.
                let record = dir.read_record(&case.name)?;
                record.is_none_or(|r| r.fingerprint != case.fingerprint)
            }
            Some(b) => b.needs_run(),
        };
        if rerun {
            run.push(case);
        } else {
            skipped.push(case.name.clone());
        }
    }
    progress.note(&format!(
        "--resume: {} cases to run, {} left as they are",
        run.len(),
        skipped.len()
    ));
    Ok((run, skipped))
}

/// Writes `batch.json` and the study of each case about to run; these lose the record of their
/// last attempt (their folder's outputs are cleared by the run itself). A case `skipped` keeps
/// its earlier plan (a case Slurm holds runs the study it was submitted with).
fn write_plan(
    dir: &BatchDir,
    batch_file: &Path,
    batch_fingerprint: &str,
    cases: &[Case],
    to_run: &[&Case],
    skipped: &[String],
) -> Result<()> {
    let earlier = if dir.plan_file().is_file() {
        dir.read_plan()?.cases
    } else {
        Vec::new()
    };
    let mut variables: Vec<String> = Vec::new();
    for c in cases {
        for (k, _) in &c.vars {
            if !variables.contains(k) {
                variables.push(k.clone());
            }
        }
    }
    for c in to_run {
        let case_dir = dir.case_dir(&c.name);
        std::fs::create_dir_all(&case_dir).at(&case_dir, || {
            format!("cannot create {}", case_dir.display())
        })?;
        crate::folder::write_atomic(&dir.case_study(&c.name), &c.text)?;
        let record = dir.case_record(&c.name);
        if record.exists() {
            std::fs::remove_file(&record)
                .at(&record, || format!("cannot remove {}", record.display()))?;
        }
    }
    let plan = Plan {
        femu_version: env!("CARGO_PKG_VERSION").into(),
        batch_file: batch_file.to_path_buf(),
        batch_fingerprint: Some(batch_fingerprint.to_string()),
        written_unix_s: unix_now(),
        variables,
        cases: cases
            .iter()
            .map(|c| {
                let kept = earlier.iter().find(|e| e.name == c.name);
                match kept.filter(|_| skipped.contains(&c.name)) {
                    Some(e) => e.clone(),
                    None => PlannedCase {
                        name: c.name.clone(),
                        origin: c.origin.clone(),
                        vars: c.vars.iter().cloned().collect(),
                        fingerprint: c.fingerprint.clone(),
                    },
                }
            })
            .collect(),
    };
    dir.write_plan(&plan)
}
