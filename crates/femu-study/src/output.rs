//! Writing an output folder: files with the path in every error, each written whole or not at
//! all (a temporary name renamed when complete: [`femu_mesh::atomic`]).

use anyhow::{Context, Result};
use femu_mesh::atomic::AtomicFile;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Creates `dir` (and its parents).
pub fn create_dir(dir: &Path) -> Result<()> {
    femu_mesh::atomic::create_dir_all(dir)
        .with_context(|| format!("cannot create output folder {}", dir.display()))
}

/// Writes `text` to `path`.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    femu_mesh::atomic::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Starts writing `path` under a temporary name; [`commit`] gives it its name.
pub fn create_file(path: &Path) -> Result<AtomicFile> {
    AtomicFile::create(path).with_context(|| format!("cannot write {}", path.display()))
}

/// Completes a file begun with [`create_file`].
pub fn commit(file: AtomicFile) -> Result<()> {
    let path = file.path().to_path_buf();
    file.commit()
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `value` as pretty JSON to `path`.
pub fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    write_text(path, &serde_json::to_string_pretty(value)?)
}

/// Reads the JSON file `path` as a `T` (a non-finite number, written as `null`, reads back as
/// NaN: see [`crate::json`]).
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    crate::json::from_str(&text).with_context(|| format!("{} is not a femu result", path.display()))
}

/// `summary.json` of a command the user stopped before its results were complete (`femu
/// identify` before a repeat finished, `femu dic`, `femu convergence`): what it was doing and
/// which files it kept.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StoppedSummary {
    pub command: String,
    pub version: String,
    /// Always `interrupted`.
    pub status: String,
    /// What was stopped and what was kept, in words.
    pub interrupted: String,
    /// The files of the folder that hold finished work.
    pub kept: Vec<String>,
    pub wall_time_s: f64,
}

/// Writes `out/summary.json` for a command stopped by the user (see [`StoppedSummary`]).
pub fn write_stopped(
    out: &Path,
    command: &str,
    interrupted: &str,
    kept: &[&str],
    wall_time_s: f64,
) -> Result<()> {
    create_dir(out)?;
    write_json(
        &out.join("summary.json"),
        &StoppedSummary {
            command: command.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            status: "interrupted".into(),
            interrupted: interrupted.into(),
            kept: kept.iter().map(|k| k.to_string()).collect(),
            wall_time_s,
        },
    )
}
