//! Output files written whole or not at all.
//!
//! Every result file of femu (CSV, VTU, PNG, JSON, decks, matrices) is written through this
//! module: the bytes go to a temporary file in the same folder (`.NAME.PID.femu-tmp`), which
//! is renamed over `NAME` once it is complete. A rename within one folder is atomic on POSIX
//! file systems, so a run that is interrupted, killed or fails midway never leaves a truncated
//! file under the name a user or a script reads: the final name holds either the complete new
//! file or what was there before. A temporary file is removed when its writer is dropped
//! without [`AtomicFile::commit`] (an error, an unwinding panic); only a process killed while
//! writing leaves it behind, under its temporary name.

use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// A file being written under a temporary name; [`AtomicFile::commit`] gives it its name.
#[derive(Debug)]
pub struct AtomicFile {
    path: PathBuf,
    tmp: PathBuf,
    file: Option<BufWriter<File>>,
}

/// The temporary name of `path`: hidden, in the same folder, unique to this process.
fn temporary_name(path: &Path) -> io::Result<PathBuf> {
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} is not a file name", path.display()),
        )
    })?;
    let mut tmp = std::ffi::OsString::from(".");
    tmp.push(name);
    tmp.push(format!(".{}.femu-tmp", std::process::id()));
    Ok(path.with_file_name(tmp))
}

impl AtomicFile {
    /// Starts writing `path` (under its temporary name; the folder must exist).
    pub fn create(path: &Path) -> io::Result<AtomicFile> {
        let tmp = temporary_name(path)?;
        let file = File::create(&tmp)?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            tmp,
            file: Some(BufWriter::new(file)),
        })
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes the file and renames it to its final name (replacing a file of that name).
    pub fn commit(mut self) -> io::Result<()> {
        let file = self.file.take().expect("an AtomicFile is committed once");
        let result = file.into_inner().map_err(|e| e.into_error()).and_then(|f| {
            drop(f);
            std::fs::rename(&self.tmp, &self.path)
        });
        if result.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
        }
        result
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file.as_mut().expect("not committed").write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.file.as_mut().expect("not committed").write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.as_mut().expect("not committed").flush()
    }
}

/// Encoders that go back to patch a header (PNG, TIFF) need to seek.
impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.as_mut().expect("not committed").seek(pos)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            // Not committed: the partial file never takes the final name.
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `path` with `fill`, atomically: the final name appears only if `fill` succeeds.
pub fn write_with<E: From<io::Error>>(
    path: &Path,
    fill: impl FnOnce(&mut AtomicFile) -> Result<(), E>,
) -> Result<(), E> {
    let mut f = AtomicFile::create(path)?;
    fill(&mut f)?;
    f.commit()?;
    Ok(())
}

/// Writes `bytes` to `path`, atomically (as `std::fs::write`, but never a partial file).
pub fn write(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    write_with(path.as_ref(), |f| f.write_all(bytes.as_ref()))
}

/// Creates the folder `dir` and its parents (as `std::fs::create_dir_all`), with errors that
/// say what is wrong in a user's terms: a file of that name, a file on the way, no permission.
pub fn create_dir_all(dir: &Path) -> io::Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            "it is a file, not a folder (an output folder is created if absent: give a new or existing folder)",
        ));
    }
    std::fs::create_dir_all(dir).map_err(|e| {
        let hint = match e.kind() {
            io::ErrorKind::NotADirectory => {
                "a part of the path is a file, not a folder".to_string()
            }
            io::ErrorKind::PermissionDenied => {
                "no permission to write there: choose a folder you can write to".to_string()
            }
            _ => e.to_string(),
        };
        io::Error::new(e.kind(), hint)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("femu-atomic-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn the_final_name_appears_only_when_complete() {
        let dir = scratch("commit");
        let path = dir.join("a.csv");
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"x,y\n").unwrap();
        f.flush().unwrap();
        // While writing: only the hidden temporary name exists.
        assert!(!path.exists());
        assert_eq!(names(&dir).len(), 1);
        assert!(names(&dir)[0].starts_with(".a.csv.") && names(&dir)[0].ends_with(".femu-tmp"));
        f.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "x,y\n");
        assert_eq!(names(&dir), vec!["a.csv".to_string()]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_leaves_nothing_else() {
        let dir = scratch("fail");
        let path = dir.join("b.csv");
        write(&path, "old\n").unwrap();
        let r: Result<(), io::Error> = write_with(&path, |f| {
            f.write_all(b"new, half")?;
            Err(io::Error::other("the writer failed midway"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old\n");
        assert_eq!(names(&dir), vec!["b.csv".to_string()]);
        // A panic while writing: the temporary file is removed as the writer unwinds.
        let p2 = path.clone();
        let caught = std::panic::catch_unwind(move || {
            let mut f = AtomicFile::create(&p2).unwrap();
            f.write_all(b"partial").unwrap();
            panic!("deliberate");
        });
        assert!(caught.is_err());
        assert_eq!(names(&dir), vec!["b.csv".to_string()]);
        write(&path, "new\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new\n");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn folder_errors_say_what_is_wrong() {
        let dir = scratch("folders");
        let file = dir.join("a.txt");
        write(&file, "x").unwrap();
        let e = create_dir_all(&file).unwrap_err().to_string();
        assert!(e.contains("is a file, not a folder"), "{e}");
        let e = create_dir_all(&file.join("sub")).unwrap_err().to_string();
        assert!(e.contains("a part of the path is a file"), "{e}");
        create_dir_all(&dir.join("new/deeper")).unwrap();
        assert!(dir.join("new/deeper").is_dir());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_missing_folder_is_an_error_naming_nothing_written() {
        let dir = scratch("missing");
        let r = write(dir.join("no/such/c.csv"), "x");
        assert!(r.is_err());
        assert!(names(&dir).is_empty());
        std::fs::remove_dir_all(&dir).ok();
    }
}
