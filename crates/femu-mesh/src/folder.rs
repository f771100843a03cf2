//! Output folders and the inputs they must not overwrite (conventions.md, "Output folders": a
//! run never overwrites a user's input file).
//!
//! Every command writes its results into one folder with fixed names (`field.csv`, `ux.png`,
//! `summary.json`, ...). An input file lying in that folder could be one of those names (issue
//! 32.2: `femu dic ux.png uy.png --out .` replaced both images with its maps and exited 0), so a
//! command refuses an output folder that holds one of its input files, before it writes
//! anything. Study and parameter files (`.toml`) are exempt: no command writes a TOML file but
//! `femu run`, which keeps the study file it copies (see its own folder rules).

use std::path::{Path, PathBuf};

/// Why an output folder is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--out {}: it holds the input {}; femu writes its results there and could overwrite it: choose another folder (e.g. {})", out.display(), input.display(), suggestion.display())]
pub struct InputInOutput {
    pub out: PathBuf,
    pub input: PathBuf,
    /// A sub-folder that would do.
    pub suggestion: PathBuf,
}

/// Refuses `out` when one of `inputs` lies directly in it (the same folder, however either
/// is spelled: `.`, a relative or an absolute path, a symbolic link). A folder that does not
/// exist yet holds nothing; an input that does not exist is left to its reader's error.
pub fn refuse_inputs_in(out: &Path, inputs: &[&Path]) -> Result<(), InputInOutput> {
    let Ok(folder) = out.canonicalize() else {
        return Ok(());
    };
    for input in inputs {
        if input
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        {
            continue;
        }
        let Ok(file) = input.canonicalize() else {
            continue;
        };
        if file.parent() == Some(folder.as_path()) {
            return Err(InputInOutput {
                out: out.to_path_buf(),
                input: input.to_path_buf(),
                suggestion: out.join("results"),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_in_the_output_folder_is_refused_however_spelled() {
        let dir = std::env::temp_dir().join(format!("femu-folder-{}", std::process::id()));
        let sub = dir.join("sub");
        std::fs::create_dir_all(&sub).unwrap();
        let image = dir.join("ux.png");
        std::fs::write(&image, b"x").unwrap();
        let study = dir.join("study.toml");
        std::fs::write(&study, b"").unwrap();
        // The folder itself, spelled with a `..` detour.
        let e = refuse_inputs_in(&sub.join(".."), &[&image]).unwrap_err();
        assert_eq!(e.input, image);
        assert!(e.to_string().contains("holds the input"), "{e}");
        // A sub-folder, a missing folder, a TOML input: fine.
        assert!(refuse_inputs_in(&sub, &[&image]).is_ok());
        assert!(refuse_inputs_in(&dir.join("new"), &[&image]).is_ok());
        assert!(refuse_inputs_in(&dir, &[&study]).is_ok());
        std::fs::remove_dir_all(&dir).ok();
    }
}
