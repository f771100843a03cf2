//! Image manifests of `us-settings` and `us-noise`: a CSV with a header naming the columns
//! `file, frequency_mhz, gain_db, dynamic_db` and optionally `subject` (any order; `#` lines
//! and blank lines skipped). Paths are relative to the manifest's folder. For `us-noise` the
//! rows of one setting and subject, in file order, are successive acquisitions.
//!
//! ```text
//! file,frequency_mhz,gain_db,dynamic_db,subject
//! s1/g34_d42_01.png,9,34,42,s1
//! s1/g34_d42_02.png,9,34,42,s1
//! ```

use crate::error::UsError;
use femu_dic::GreyImage;
use std::path::{Path, PathBuf};

/// One row of a manifest.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Entry {
    /// Line number in the manifest (1-based).
    pub line: usize,
    /// The file as written and resolved against the manifest's folder.
    pub file: String,
    pub path: PathBuf,
    pub frequency_mhz: f64,
    pub gain_db: f64,
    pub dynamic_db: f64,
    /// Subject (empty when the column is absent).
    pub subject: String,
}

impl Entry {
    /// The setting as a short label, e.g. `9MHz G34 D42`.
    pub fn setting_label(&self) -> String {
        format!(
            "{}MHz G{} D{}",
            fmt_num(self.frequency_mhz),
            fmt_num(self.gain_db),
            fmt_num(self.dynamic_db)
        )
    }
}

/// A number without a trailing `.0`.
pub fn fmt_num(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e9 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}

/// A read manifest.
#[derive(Debug, Clone)]
pub struct Manifest {
    pub path: PathBuf,
    pub entries: Vec<Entry>,
}

impl Manifest {
    /// The files a command reads through this manifest: the manifest and its images (an
    /// output folder must not hold them: `femu_mesh::folder`).
    pub fn input_files(&self) -> Vec<&Path> {
        std::iter::once(self.path.as_path())
            .chain(self.entries.iter().map(|e| e.path.as_path()))
            .collect()
    }

    /// Reads and checks a manifest (columns, numbers, files present).
    pub fn read(path: &Path) -> Result<Manifest, UsError> {
        let text = std::fs::read_to_string(path).map_err(|e| UsError::Manifest {
            path: path.to_path_buf(),
            line: 0,
            message: format!("cannot read: {e}"),
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::parse(&text, path, base)
    }

    /// Parses manifest `text` (for messages: `path`; files resolved against `base`).
    pub fn parse(text: &str, path: &Path, base: &Path) -> Result<Manifest, UsError> {
        let err = |line: usize, message: String| UsError::Manifest {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut rows = text
            .lines()
            .enumerate()
            .map(|(k, l)| (k + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (hline, header) = rows
            .next()
            .ok_or_else(|| err(1, "empty manifest: no header line".into()))?;
        let cols: Vec<String> = header
            .split(',')
            .map(|c| c.trim().to_ascii_lowercase())
            .collect();
        let find = |name: &str| cols.iter().position(|c| c == name);
        let mut idx = [0usize; 4];
        for (k, name) in ["file", "frequency_mhz", "gain_db", "dynamic_db"]
            .iter()
            .enumerate()
        {
            idx[k] = find(name).ok_or_else(|| {
                err(
                    hline,
                    format!(
                        "the header has no '{name}' column (columns: file, frequency_mhz, gain_db, dynamic_db[, subject])"
                    ),
                )
            })?;
        }
        let subject = find("subject");
        if let Some(c) = cols.iter().find(|c| {
            !["file", "frequency_mhz", "gain_db", "dynamic_db", "subject"].contains(&c.as_str())
        }) {
            return Err(err(hline, format!("unknown column '{c}'")));
        }
        let mut entries = Vec::new();
        for (line, l) in rows {
            let f: Vec<&str> = l.split(',').map(str::trim).collect();
            if f.len() != cols.len() {
                return Err(err(
                    line,
                    format!("{} fields, the header has {}", f.len(), cols.len()),
                ));
            }
            let num = |k: usize, name: &str| -> Result<f64, UsError> {
                let v: f64 = f[k]
                    .parse()
                    .map_err(|_| err(line, format!("{name} '{}' is not a number", f[k])))?;
                if !v.is_finite() {
                    return Err(err(line, format!("{name} '{}' is not finite", f[k])));
                }
                Ok(v)
            };
            let frequency_mhz = num(idx[1], "frequency_mhz")?;
            if !(frequency_mhz > 0.0) {
                return Err(err(
                    line,
                    format!("frequency_mhz {frequency_mhz} must be positive"),
                ));
            }
            let gain_db = num(idx[2], "gain_db")?;
            let dynamic_db = num(idx[3], "dynamic_db")?;
            if !(dynamic_db > 0.0) {
                return Err(err(
                    line,
                    format!("dynamic_db {dynamic_db} must be positive"),
                ));
            }
            let file = f[idx[0]].to_string();
            if file.is_empty() {
                return Err(err(line, "empty file name".into()));
            }
            let p = base.join(&file);
            if !p.is_file() {
                return Err(err(line, format!("image {} does not exist", p.display())));
            }
            entries.push(Entry {
                line,
                file,
                path: p,
                frequency_mhz,
                gain_db,
                dynamic_db,
                subject: subject.map(|k| f[k].to_string()).unwrap_or_default(),
            });
        }
        if entries.is_empty() {
            return Err(err(hline, "no image listed".into()));
        }
        Ok(Manifest {
            path: path.to_path_buf(),
            entries,
        })
    }

    /// Opens the image of entry `k` (grey levels; colour → luminance) and checks its size
    /// against `expected` (the first image's), naming the line on a mismatch.
    pub fn open(&self, k: usize, expected: Option<(usize, usize)>) -> Result<GreyImage, UsError> {
        let e = &self.entries[k];
        let img_err = |message: String| UsError::Image {
            path: self.path.clone(),
            line: e.line,
            image: e.path.clone(),
            message,
        };
        let img = GreyImage::open(&e.path, 0).map_err(|x| img_err(x.to_string()))?;
        if let Some((w, h)) = expected {
            if (img.width, img.height) != (w, h) {
                return Err(img_err(format!(
                    "{} x {} px, but the first image ({}) is {w} x {h} px: all images must have one size",
                    img.width, img.height, self.entries[0].file
                )));
            }
        }
        Ok(img)
    }

    /// Opens every image, checking that they share one size.
    pub fn open_all(&self) -> Result<Vec<GreyImage>, UsError> {
        let first = self.open(0, None)?;
        let size = (first.width, first.height);
        let mut out = vec![first];
        for k in 1..self.entries.len() {
            out.push(self.open(k, Some(size))?);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_manifests_name_the_line() {
        let dir = std::env::temp_dir().join(format!("femu-us-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a.png"), b"x").unwrap();
        let p = dir.join("m.csv");
        let e = Manifest::parse("file,gain_db\n", &p, &dir)
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.csv:1") && e.contains("frequency_mhz"), "{e}");
        let e = Manifest::parse(
            "# c\nfile,frequency_mhz,gain_db,dynamic_db\na.png,9,34,42\nb.png,9,34,42\n",
            &p,
            &dir,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("m.csv:4") && e.contains("b.png") && e.contains("does not exist"),
            "{e}"
        );
        let e = Manifest::parse(
            "file,frequency_mhz,gain_db,dynamic_db\na.png,9,x,42\n",
            &p,
            &dir,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains(":2") && e.contains("gain_db 'x'"), "{e}");
        let m = Manifest::parse(
            "subject,file,frequency_mhz,gain_db,dynamic_db\ns1,a.png,9,34,42\n",
            &p,
            &dir,
        )
        .unwrap();
        assert_eq!(m.entries[0].subject, "s1");
        assert_eq!(m.entries[0].setting_label(), "9MHz G34 D42");
        std::fs::remove_dir_all(&dir).ok();
    }
}
