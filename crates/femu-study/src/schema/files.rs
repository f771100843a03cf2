//! The keys of a study file that name other files (`[model] deck`, `[labels] image`,
//! `[measurement] file` and `covariance`, the same keys of each `[[measurement]]`): relative names start from the study
//! file's folder ([`super::read`]).
//! A study copied elsewhere (the cases of `femu batch`, each written into its own folder) keeps
//! pointing at the same files once these names are made absolute ([`absolute_file_names`]);
//! [`super::Study::input_files`] lists the files a checked study will read, so that a caller can check
//! they exist before anything runs.
//!
//! A new key that names a file is added to [`FILE_KEYS`] (and read through
//! [`super::lines::resolve`], as the four here are).

use std::path::{Path, PathBuf};

/// `(table, key)` of every study-file key that names a file.
pub const FILE_KEYS: [(&str, &str); 7] = [
    ("model", "deck"),
    ("labels", "image"),
    ("measurement", "file"),
    ("measurement", "covariance"),
    ("measurement", "frames"),
    ("measurement", "cine"),
    ("measurement", "force_log"),
];

/// Whether the key at `path` (`["labels", "image"]`, `["measurement", "2", "file"]` for the
/// second `[[measurement]]`) names a file.
pub fn is_file_key(path: &[&str]) -> bool {
    match path {
        [table, key] => FILE_KEYS.contains(&(*table, *key)),
        [table, index, key] => {
            index.parse::<usize>().is_ok() && FILE_KEYS.contains(&(*table, *key))
        }
        _ => false,
    }
}

/// `name` as a path from `base` (unchanged when absolute).
pub fn resolve_from(base: &Path, name: &str) -> PathBuf {
    super::lines::resolve(base, name)
}

/// Makes the file names of a study's TOML tables absolute, relative ones taken from `base`
/// (the study file's folder). Values that are not strings are left for the schema to reject.
pub fn absolute_file_names(doc: &mut toml::Table, base: &Path) {
    let absolute = |t: &mut toml::Table, key: &str| {
        match t.get_mut(key) {
            Some(toml::Value::String(name)) => {
                *name = resolve_from(base, name).to_string_lossy().into_owned();
            }
            // A list of files (`frames`).
            Some(toml::Value::Array(names)) => {
                for v in names {
                    if let toml::Value::String(name) = v {
                        *name = resolve_from(base, name).to_string_lossy().into_owned();
                    }
                }
            }
            _ => {}
        }
    };
    for (table, key) in FILE_KEYS {
        match doc.get_mut(table) {
            Some(toml::Value::Table(t)) => absolute(t, key),
            // A list of tables (`[[measurement]]`): the key of each entry.
            Some(toml::Value::Array(entries)) => {
                for e in entries {
                    if let toml::Value::Table(t) = e {
                        absolute(t, key);
                    }
                }
            }
            _ => {}
        }
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
        let list = "[[measurement]]\nsource = \"file\"\nfile = \"a.csv\"\n\
                    [[measurement]]\nsource = \"file\"\nfile = \"b.csv\"\n";
        // (A deck is read while the study is parsed, so it is checked on the TOML alone below.)
        for text in [labels, list] {
            let home = Path::new("/data/study");
            let at_home = super::super::parse(text, home).unwrap();
            let mut doc: toml::Table = text.parse().unwrap();
            absolute_file_names(&mut doc, home);
            let moved = toml::to_string(&doc).unwrap();
            let elsewhere = super::super::parse(&moved, Path::new("/tmp/case")).unwrap();
            assert_eq!(at_home.input_files(), elsewhere.input_files());
            assert!(!at_home.input_files().is_empty());
            for path in at_home.input_files() {
                assert!(path.starts_with(home), "{}", path.display());
            }
        }
        let mut deck: toml::Table = "[model]\ndeck = \"decks/thigh.inp\"\n".parse().unwrap();
        absolute_file_names(&mut deck, Path::new("/data/study"));
        assert_eq!(
            deck["model"]["deck"].as_str(),
            Some("/data/study/decks/thigh.inp")
        );
        assert!(is_file_key(&["model", "deck"]));
        assert!(is_file_key(&["measurement", "file"]));
        assert!(!is_file_key(&["labels", "map"]));
        assert!(is_file_key(&["measurement", "2", "file"]));
    }
}
