//! Where a key stands in the study file: the line numbers of every table and key, so that a
//! value the TOML parser accepted but the study rejects is reported with its line.

use super::legacy::Moved;
use super::StudyError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Line numbers of the keys of a TOML text by table (`noise`, `materials.FAT`, `test`), entry of
/// an array of tables (0 for a plain table) and key.
#[derive(Debug)]
pub(crate) struct KeyLines {
    keys: Vec<(String, usize, String, usize)>,
    /// Tables written as arrays (`[[measurement]]`) in this text.
    arrays: Vec<String>,
    /// Keys of an older layout moved into the schema's tables (see [`super::legacy`]).
    moved: Vec<Moved>,
}

impl KeyLines {
    pub(crate) fn new(text: &str) -> KeyLines {
        let mut keys = Vec::new();
        let mut table = String::new();
        let mut index = 0;
        let mut counts: BTreeMap<String, usize> = BTreeMap::new();
        let mut arrays = Vec::new();
        for (k, raw) in text.lines().enumerate() {
            let t = raw.trim();
            if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
                table = name.trim().to_string();
                if !arrays.contains(&table) {
                    arrays.push(table.clone());
                }
                let c = counts.entry(table.clone()).or_insert(0);
                index = *c;
                *c += 1;
                keys.push((table.clone(), index, String::new(), k + 1));
            } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
                table = name.trim().trim_matches('"').to_string();
                index = 0;
                keys.push((table.clone(), 0, String::new(), k + 1));
            } else if let Some((key, _)) = t.split_once('=') {
                if !t.starts_with('#') {
                    keys.push((table.clone(), index, key.trim().to_string(), k + 1));
                }
            }
        }
        KeyLines {
            keys,
            arrays,
            moved: Vec::new(),
        }
    }

    /// The same lines, knowing which keys an older layout had elsewhere.
    pub(crate) fn with_moved(mut self, moved: Vec<Moved>) -> KeyLines {
        self.moved = moved;
        self
    }

    /// `"[table] key (line N)"`; the table header's line when the key is absent. Arrays of
    /// tables are named by their entry: `"[[test]] 2 side (line 9)"`.
    pub(crate) fn at(&self, table: &str, index: usize, key: &str) -> String {
        let line_of = |table: &str, index: usize, key: &str| {
            self.keys
                .iter()
                .find(|(t, i, k, _)| t.eq_ignore_ascii_case(table) && *i == index && k == key)
                .map(|e| e.3)
        };
        let find = |key: &str| {
            line_of(table, index, key).or_else(|| {
                self.moved
                    .iter()
                    .find(|m| {
                        m.table.eq_ignore_ascii_case(table) && m.index == index && m.key == key
                    })
                    .and_then(|m| line_of(&m.old_table, 0, &m.old_key))
            })
        };
        let name = if ARRAY_TABLES.contains(&table) || self.is_array(table) {
            format!("[[{table}]] {}", index + 1)
        } else if table.is_empty() {
            "(top level)".to_string()
        } else {
            format!("[{table}]")
        };
        let key_part = if key.is_empty() {
            String::new()
        } else {
            format!(" {key}")
        };
        match find(key).or_else(|| find("")) {
            Some(line) => format!("{name}{key_part} (line {line})"),
            None => format!("{name}{key_part}"),
        }
    }

    /// Whether `table` is written as an array of tables (`[[table]]`) in the text.
    pub(crate) fn is_array(&self, table: &str) -> bool {
        self.arrays.iter().any(|a| a.eq_ignore_ascii_case(table))
    }

    /// The line of `key` wherever it stands (the first occurrence), for the parser's messages
    /// about a key of a moved table.
    pub(crate) fn first_line_of(&self, key: &str) -> Option<usize> {
        self.keys.iter().find(|e| e.2 == key).map(|e| e.3)
    }

    /// A [`StudyError::Key`] at the key.
    pub(crate) fn err(&self, table: &str, index: usize, key: &str, message: String) -> StudyError {
        StudyError::key(self.at(table, index, key), message)
    }

    /// An error at the key unless `path` (a file the key names) is a file.
    pub(crate) fn existing_file(
        &self,
        table: &str,
        key: &str,
        path: &std::path::Path,
    ) -> Result<(), StudyError> {
        if path.is_file() {
            return Ok(());
        }
        Err(self.err(
            table,
            0,
            key,
            format!(
                "{} does not exist (relative names start from the study file's folder)",
                path.display()
            ),
        ))
    }

    /// `v` if it is positive and finite, else an error at the key.
    pub(crate) fn positive(
        &self,
        table: &str,
        index: usize,
        key: &str,
        v: f64,
    ) -> Result<f64, StudyError> {
        if !(v > 0.0 && v.is_finite()) {
            return Err(self.err(
                table,
                index,
                key,
                format!("must be positive and finite, got {v}"),
            ));
        }
        Ok(v)
    }
}

impl KeyLines {
    /// `v` if it is positive and at most `max` (beyond, a unit or typing mistake), else an
    /// error at the key.
    pub(crate) fn at_most(
        &self,
        table: &str,
        index: usize,
        key: &str,
        v: f64,
        max: f64,
    ) -> Result<f64, StudyError> {
        if !(v > 0.0 && v <= max) {
            return Err(self.err(
                table,
                index,
                key,
                format!("must be positive and at most {max}, got {v}"),
            ));
        }
        Ok(v)
    }
}

/// The tables written `[[name]]` (one entry per item).
const ARRAY_TABLES: [&str; 3] = ["test", "fixed", "pressure"];

/// A file named in the study, relative to the study file's folder `base`.
pub(crate) fn resolve(base: &Path, file: &str) -> PathBuf {
    let p = PathBuf::from(file);
    if p.is_absolute() {
        p
    } else {
        base.join(p)
    }
}
