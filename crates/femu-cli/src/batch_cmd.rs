//! `femu batch run|status|collect|case`: arguments, one call of femu-batch each, the outcome
//! told to the user.

use clap::{Args, Subcommand};
use femu_batch::{BatchDir, RunOptions, RunOutcome, SlurmRequest};
use femu_study::Progress;
use std::path::PathBuf;

#[derive(Subcommand, Debug)]
pub enum BatchCommand {
    /// Check every case of a batch file (a template study and a table of per-case values, or a
    /// CSV manifest of studies), then run them here (--jobs at once, each in its own folder) or
    /// submit them as one Slurm job array (--slurm).
    Run(RunArgs),
    /// The state of every case of a batch folder, from each case's record and Slurm's queue.
    Status {
        /// The batch folder (--out of femu batch run).
        dir: PathBuf,
        /// Print the status as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Gather every case's identified parameters, intervals and fit quality into
    /// collect/population.csv (and .json, cases.csv) and the population report
    /// collect/report.html.
    Collect {
        /// The batch folder.
        dir: PathBuf,
    },
    /// Run one case of a batch folder and record its outcome (what the runners start: a child
    /// process of `femu batch run`, or a Slurm array task).
    Case {
        /// The batch folder.
        dir: PathBuf,
        /// The case's name.
        name: String,
    },
}

#[derive(Args, Debug)]
pub struct RunArgs {
    /// The batch file: TOML (template, cases table, [slurm]) or a CSV manifest of studies.
    batch: PathBuf,
    /// The batch folder (a case per sub-folder of cases/).
    #[arg(long, default_value = "out/batch")]
    out: PathBuf,
    /// Cases at once on this machine (default: the batch file's `jobs`, else 1).
    #[arg(long)]
    jobs: Option<usize>,
    /// Continue the batch in --out: run only the cases not done (failed, interrupted, never
    /// run, or changed in the batch file since); with --slurm, resubmit only those.
    #[arg(long)]
    resume: bool,
    /// Submit the cases as one Slurm job array (sbatch --array) instead of running them here.
    #[arg(long)]
    slurm: bool,
    /// With --slurm: print the array script instead of submitting it.
    #[arg(long, requires = "slurm")]
    dry_run: bool,
    /// With --slurm: CPUs per task (also the case's threads).
    #[arg(long, requires = "slurm")]
    cpus_per_task: Option<u32>,
    /// With --slurm: memory per task (4G, 4000M).
    #[arg(long, requires = "slurm")]
    mem: Option<String>,
    /// With --slurm: time limit per task (HH:MM:SS, D-HH:MM:SS, minutes).
    #[arg(long, requires = "slurm")]
    time: Option<String>,
    /// With --slurm: the partition.
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
    /// With --slurm: the account.
    #[arg(long, requires = "slurm")]
    account: Option<String>,
}

pub fn run(cmd: BatchCommand, progress: &dyn Progress, quiet: bool) -> anyhow::Result<()> {
    match cmd {
        BatchCommand::Run(a) => run_batch(a, progress),
        BatchCommand::Status { dir, json } => {
            let st = femu_batch::status(&BatchDir::new(&dir))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&st)?);
            } else {
                print!("{st}");
            }
            Ok(())
        }
        BatchCommand::Collect { dir } => {
            let c = femu_batch::collect(&BatchDir::new(&dir))?;
            for n in &c.notes {
                progress.note(&format!("note: {n}"));
            }
            if !quiet {
                for f in &c.files {
                    eprintln!("wrote {}", f.display());
                }
            }
            Ok(())
        }
        BatchCommand::Case { dir, name } => {
            femu_batch::run_case(&BatchDir::new(&dir), &name, progress)
                .map(|_| ())
                .map_err(case_error)
        }
    }
}

/// A case's error as the command line reports it: femu-study's own when the case's `femu run`
/// failed (as `femu run` reports it: a stop found in it ends with status 130), else
/// femu-batch's.
fn case_error(e: femu_batch::Error) -> anyhow::Error {
    match e {
        femu_batch::Error::Study(e) => e.into(),
        e => e.into(),
    }
}

fn run_batch(a: RunArgs, progress: &dyn Progress) -> anyhow::Result<()> {
    let opts = RunOptions {
        out: a.out.clone(),
        resume: a.resume,
        jobs: a.jobs,
        slurm: a.slurm.then(|| SlurmRequest {
            dry_run: a.dry_run,
            resources: femu_batch::slurm::SlurmResources {
                cpus_per_task: a.cpus_per_task,
                mem: a.mem,
                time: a.time,
                partition: a.partition,
                account: a.account,
                ..Default::default()
            },
        }),
        femu: std::env::current_exe()?,
    };
    if a.jobs == Some(0) {
        anyhow::bail!("--jobs must be at least 1");
    }
    let dir = a.out.display();
    let skipped_note = |skipped: &[String]| {
        if !skipped.is_empty() {
            progress.note(&format!(
                "{} cases left as they were (done, or with Slurm)",
                skipped.len()
            ));
        }
    };
    match femu_batch::run(&a.batch, &opts, progress)? {
        RunOutcome::DryRun { script, cases } => {
            progress.note(&format!(
                "--dry-run: the array script of {} cases (not submitted):",
                cases.len()
            ));
            print!("{script}");
            Ok(())
        }
        RunOutcome::NothingToDo { skipped } => {
            skipped_note(&skipped);
            progress.note(&format!(
                "nothing to run: femu batch status {dir}; femu batch collect {dir}"
            ));
            Ok(())
        }
        RunOutcome::Submitted {
            submission,
            skipped,
        } => {
            skipped_note(&skipped);
            progress.note(&format!(
                "submitted job {} ({} array tasks, {}); follow it with: femu batch status {dir}",
                submission.job_id,
                submission.cases.len(),
                submission.script
            ));
            Ok(())
        }
        RunOutcome::Local { outcome, skipped } => {
            skipped_note(&skipped);
            progress.note(&format!(
                "{} cases done, {} failed, {} interrupted, {} not started, in {:.1} s",
                outcome.done.len(),
                outcome.failed.len(),
                outcome.interrupted.len(),
                outcome.not_started.len(),
                outcome.seconds
            ));
            if !outcome.interrupted.is_empty() || !outcome.not_started.is_empty() {
                return Err(
                    anyhow::Error::new(femu_study::progress::Interrupted).context(format!(
                        "batch stopped: finish it with femu batch run {} --out {dir} --resume",
                        a.batch.display()
                    )),
                );
            }
            if !outcome.failed.is_empty() {
                let names: Vec<&str> = outcome.failed.iter().map(|(n, _)| n.as_str()).collect();
                anyhow::bail!(
                    "{} of {} cases failed ({}); the others are done. See femu batch status {dir} and cases/NAME/femu.log; fix, then femu batch run {} --out {dir} --resume",
                    names.len(),
                    outcome.done.len() + names.len(),
                    names.join(", "),
                    a.batch.display()
                );
            }
            progress.note(&format!(
                "gather the results with: femu batch collect {dir}"
            ));
            Ok(())
        }
    }
}
