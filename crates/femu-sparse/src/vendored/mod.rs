//! Code derived from other projects, each file with its origin, its licence (the licence text
//! beside it) and what was changed, and checked against one release of its origin:
//!
//! - [`faer_supernodal`]: faer's supernodal numeric LDLᵀ stopped at a separator (MIT,
//!   `LICENSE-faer`), and the one call into faer's update kernel (`private-gemm-x86`).
//!
//! The copy relies on how faer lays out its supernodal factor and on the arguments of the
//! kernel, which faer may change in any release: a test fails when Cargo.lock holds another
//! faer or `private-gemm-x86` than the ones named here, saying what to do.

pub mod faer_supernodal;

/// The faer release [`faer_supernodal`] was derived from and checked against.
pub const FAER_VERSION: &str = "0.24.4";

/// The `private-gemm-x86` release [`faer_supernodal`] calls (the one faer 0.24.4 locks; pinned
/// with `=` in femu-sparse's Cargo.toml).
pub const PRIVATE_GEMM_X86_VERSION: &str = "0.1.22";

/// Every version of the package `name` in the text of a Cargo.lock.
#[cfg(test)]
fn locked_versions<'a>(lock: &'a str, name: &str) -> Vec<&'a str> {
    let name_line = format!("name = \"{name}\"");
    let mut versions = Vec::new();
    let mut lines = lock.lines().map(str::trim);
    while let Some(line) = lines.next() {
        if line == name_line {
            if let Some(v) = lines
                .next()
                .and_then(|l| l.strip_prefix("version = \""))
                .and_then(|l| l.strip_suffix('"'))
            {
                versions.push(v);
            }
        }
    }
    versions
}

/// `Err` with what to do when the lock file `lock` holds another faer or `private-gemm-x86`
/// than the vendored code was checked against.
#[cfg(test)]
fn check_lock(lock: &str) -> Result<(), String> {
    let mut problems = Vec::new();
    for (name, checked) in [
        ("faer", FAER_VERSION),
        ("private-gemm-x86", PRIVATE_GEMM_X86_VERSION),
    ] {
        let locked = locked_versions(lock, name);
        if locked != [checked] {
            problems.push(format!(
                "Cargo.lock has {name} {locked:?}, the vendored code was checked against {checked}"
            ));
        }
    }
    if problems.is_empty() {
        return Ok(());
    }
    Err(format!(
        "{}.\nThe supernodal LDLT in crates/femu-sparse/src/vendored/faer_supernodal.rs is \
         derived from faer {FAER_VERSION}. Before moving on: compare faer's \
         factorize_supernodal_numeric_ldlt (faer/src/sparse/linalg/cholesky.rs) and the \
         private_gemm_x86::gemm call of its spicy_matmul (faer/src/linalg/matmul/internal/mod.rs) \
         between the two releases, carry the changes into faer_supernodal.rs, pin \
         private-gemm-x86 in crates/femu-sparse/Cargo.toml to the release the new faer locks, \
         run `cargo test -p femu-sparse -p femu-mech` (the partial_ldlt_* and split_ldlt_* tests \
         compare the copy with faer's own factorization), then set FAER_VERSION and \
         PRIVATE_GEMM_X86_VERSION in crates/femu-sparse/src/vendored/mod.rs. Or keep the \
         previous releases: cargo update -p faer --precise {FAER_VERSION}.",
        problems.join("; ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The workspace's Cargo.lock holds the faer and `private-gemm-x86` the vendored code was
    /// checked against.
    #[test]
    fn vendored_faer_code_matches_the_locked_faer() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../Cargo.lock");
        let lock = std::fs::read_to_string(path)
            .unwrap_or_else(|e| panic!("the workspace's lock file {path}: {e}"));
        if let Err(message) = check_lock(&lock) {
            panic!("{message}");
        }
    }

    /// A lock file with another faer (or two of them) is refused with the instructions.
    #[test]
    fn another_faer_in_the_lock_is_refused() {
        let lock = |faer: &[&str]| {
            let mut text = String::from("version = 4\n\n");
            for v in faer {
                text += &format!("[[package]]\nname = \"faer\"\nversion = \"{v}\"\n\n");
            }
            text += &format!(
                "[[package]]\nname = \"private-gemm-x86\"\nversion = \"{PRIVATE_GEMM_X86_VERSION}\"\n"
            );
            text
        };
        assert_eq!(check_lock(&lock(&[FAER_VERSION])), Ok(()));
        for faer in [&["0.24.5"][..], &[FAER_VERSION, "0.25.0"], &[]] {
            let err = check_lock(&lock(faer)).unwrap_err();
            assert!(
                err.contains("faer_supernodal.rs") && err.contains("FAER_VERSION"),
                "{err}"
            );
        }
    }
}
