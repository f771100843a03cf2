//! The keys of a study file that name other files (`[model] deck`, `[labels] image`,
//! `[measurement] file`): relative names start from the study file's folder ([`super::read`]).
//! A study copied elsewhere (the cases of `femu batch`, each written into its own folder) keeps
//! pointing at the same files once these names are made absolute ([`absolute_file_names`]);
//! [`Study::input_files`] lists the files a checked study will read, so that a caller can check
//! they exist before anything runs.
//!
//! A new key that names a file is added to [`FILE_KEYS`] (and read through
//! [`super::lines::resolve`], as the three here are).

use super::{Geometry, MeasurementSource, Study};
use std::path::{Path, PathBuf};

/// `(table, key)` of every study-file key that names a file.
pub const FILE_KEYS: [(&str, &str); 3] = [
    ("model", "deck"),
    ("labels", "image"),
    ("measurement", "file"),
];

/// Whether the key at `path` (`["labels", "image"]`) names a file.
pub fn is_file_key(path: &[&str]) -> bool {
    matches!(path, [table, key] if FILE_KEYS.contains(&(*table, *key)))
}

/// `name` as a path from `base` (unchanged when absolute).
pub fn resolve_from(base: &Path, name: &str) -> PathBuf {
    super::lines::resolve(base, name)
}

/// Makes the file names of a study's TOML tables absolute, relative ones taken from `base`
/// (the study file's folder). Values that are not strings are left for the schema to reject.
pub fn absolute_file_names(doc: &mut toml::Table, base: &Path) {
    for (table, key) in FILE_KEYS {
        let Some(toml::Value::Table(t)) = doc.get_mut(table) else {
            continue;
        };
        if let Some(toml::Value::String(name)) = t.get_mut(key) {
            *name = resolve_from(base, name).to_string_lossy().into_owned();
        }
    }
}

impl Study {
    /// The files the study reads, each with the key that names it (`"[labels] image"`).
    pub fn input_files(&self) -> Vec<(&'static str, &Path)> {
        let mut files = Vec::new();
        match &self.model.geometry {
            Geometry::Deck(p) => files.push(("[model] deck", p.as_path())),
            Geometry::Labels(l) => files.push(("[labels] image", l.image.as_path())),
            Geometry::Thigh(_) => {}
        }
        if let MeasurementSource::File { path, .. } = &self.measurement.source {
            files.push(("[measurement] file", path.as_path()));
        }
        files
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A study's file names made absolute from its folder and read from another folder name
    /// the same files as the study read from its own folder.
    #[test]
    fn absolute_names_survive_a_move() {
        let labels = "[labels]\nimage = \"mri/s01.png\"\nmap = \"1=fat\"\nbone = [7]\n\
                      [model]\nsize_mm = 2.0\n\
                      [measurement]\nsource = \"file\"\nfile = \"../fields/s01.csv\"\n";
        let deck = "[model]\ndeck = \"decks/thigh.inp\"\n";
        for text in [labels, deck] {
            let home = Path::new("/data/study");
            let at_home = super::super::parse(text, home).unwrap();
            let mut doc: toml::Table = text.parse().unwrap();
            absolute_file_names(&mut doc, home);
            let moved = toml::to_string(&doc).unwrap();
            let elsewhere = super::super::parse(&moved, Path::new("/tmp/case")).unwrap();
            assert_eq!(at_home.input_files(), elsewhere.input_files());
            assert!(!at_home.input_files().is_empty());
            for (key, path) in at_home.input_files() {
                assert!(path.starts_with(home), "{key}: {}", path.display());
                let (table, name) = key
                    .trim_start_matches('[')
                    .split_once("] ")
                    .expect("[table] key");
                assert!(is_file_key(&[table, name]), "{key} is not in FILE_KEYS");
            }
        }
        assert!(!is_file_key(&["labels", "map"]));
    }
}
