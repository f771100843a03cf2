//! The loads of `[model] deck`: the deck's `*DLOAD` faces are the skin the tests act on, and
//! its `*DLOAD` magnitude is the contention pressure — kept, not replaced without a word by the
//! test's default (20 mmHg). A study that sets another pressure is stopped with both values.

use super::lines::KeyLines;
use super::loading_tests::TestSpec;
use super::raw::TestEntry;
use super::StudyError;
use femu_mech::loading::{contention, Contention, Loading};
use femu_mesh::MMHG_IN_MPA;
use std::path::Path;

/// Relative difference below which two pressures are the same (the deck's number as written).
const SAME: f64 = 1e-9;

/// Sets the pressure of the contention tests of a deck study to the deck's `*DLOAD` magnitude
/// (`entries`: the `[[test]]` tables as written, `None` for the seed's tests). A deck whose
/// magnitudes are all zero only marks the skin: the tests keep their pressure.
pub(crate) fn apply(
    deck: &Path,
    tests: &mut [TestSpec],
    entries: Option<&[TestEntry]>,
    lines: &KeyLines,
) -> Result<(), StudyError> {
    if !tests.iter().any(|t| t.loading.is(&contention::KIND)) {
        return Ok(());
    }
    lines.existing_file("model", "deck", deck)?;
    let read = femu_mesh::read_inp(deck)
        .map_err(|e| lines.err("model", 0, "deck", format!("cannot read the deck: {e}")))?;
    let magnitudes: Vec<f64> = read.pressures.iter().map(|p| p.magnitude).collect();
    let (lo, hi) = magnitudes
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &m| {
            (a.min(m), b.max(m))
        });
    if magnitudes.is_empty() || (lo == 0.0 && hi == 0.0) {
        return Ok(());
    }
    let name = deck.display();
    if (hi - lo).abs() > SAME * hi.abs().max(lo.abs()) {
        return Err(lines.err(
            "model",
            0,
            "deck",
            format!(
                "{name}: the *DLOAD magnitudes vary from {lo} to {hi} MPa, and the contention test applies one pressure on the whole skin: give the deck one magnitude"
            ),
        ));
    }
    let pressure = hi;
    for (k, t) in tests.iter_mut().enumerate() {
        if !t.loading.is(&contention::KIND) {
            continue;
        }
        let given = entries.and_then(|e| e.get(k)).and_then(|e| {
            ["pressure_mmhg", "pressure_mpa"]
                .into_iter()
                .find(|key| e.keys.contains_key(*key))
        });
        let study = t.loading.skin_pressure().unwrap_or(f64::NAN);
        if let Some(key) = given {
            if (study - pressure).abs() > SAME * pressure.abs() {
                return Err(lines.err(
                    "test",
                    k,
                    key,
                    format!(
                        "the contention pressure is {study} MPa ({:.4} mmHg), but the deck {name} loads its skin with *DLOAD {pressure} MPa ({:.4} mmHg): remove {key} to use the deck's, or change one of them",
                        study / MMHG_IN_MPA,
                        pressure / MMHG_IN_MPA
                    ),
                ));
            }
        }
        t.loading = Loading::new(Contention { pressure });
    }
    Ok(())
}
