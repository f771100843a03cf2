//! `femu batch`: a population study — several subjects, MRI slices, legs, sessions, Monte
//! Carlo seeds — as many `femu run`s of one template study with a table of per-case values,
//! run on this machine or as one Slurm job array, their results gathered into one table and
//! one report.
//!
//! - [`spec`]: the batch file (a TOML file with a template and a table, or a CSV manifest of
//!   studies) read into cases;
//! - [`expand`]: each case's study — the template with its values — checked by femu-study's
//!   schema before anything runs (every bad case named with its row and key);
//! - [`folder`]: the batch folder, its plan (`batch.json`) and each case's record (`case.json`);
//! - [`task`]: one case, run as a process of its own (`femu batch case DIR NAME`);
//! - [`local`]: the local runner (child processes, at most `jobs` at once);
//! - [`slurm`]: the array script, its submission, the queue's state;
//! - [`status`](mod@status): the state of every case from its record and the queue;
//! - [`run`](mod@run): `femu batch run`, with `--resume` and `--slurm`;
//! - [`collect`](mod@collect): the population table (CSV, JSON) and report;
//! - [`error`]: the crate's one typed [`Error`].
//!
//! The crate sits on femu-study (the schema, `femu run`, the typed summaries) and femu-plot;
//! the command line calls one function of it per subcommand.

pub mod collect;
pub mod error;
pub mod expand;
pub mod folder;
pub mod local;
pub mod run;
pub mod slurm;
pub mod spec;
pub mod status;
pub mod task;

pub use collect::{collect, Collected, Population};
pub use error::{Error, Result};
pub use folder::BatchDir;
pub use run::{run, RunOptions, RunOutcome, SlurmRequest};
pub use status::{status, BatchStatus, CaseState};
pub use task::run_case;
