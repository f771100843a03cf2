//! The measurement and identification steps take only the parts of a study they read
//! (`MeasureInputs`, `IdentificationInputs`), not the study: the steps run on the parts of one
//! study with another study's `[identification]` (through `IdentificationInputs::with`) and
//! `[grid]` must give what `femu identify` gives on the study that has them — to the bit, the
//! same computation — and must differ from what the first study's own sections give (so the
//! parts given, not the study they came from, are what the steps read).

use femu_study::progress::Quiet;
use femu_study::steps::identify::{self, IdentificationSummary};
use femu_study::steps::measure::{self, MeasureInputs, PreparedData};
use femu_study::steps::parameters::IdentificationInputs;
use std::path::PathBuf;

/// This test's scratch folder (removed when it passes).
fn base() -> PathBuf {
    std::env::temp_dir().join(format!("femu-steps-parts-{}", std::process::id()))
}

/// A scratch folder of its own for `name`, emptied.
fn scratch(name: &str) -> PathBuf {
    let dir = base().join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The compression test on a 700-element thigh measured on a `grid x grid` grid, the grouped
/// identification from `starts` starts with noise seed `seed`, no discretization check (the
/// smallest study that runs both steps).
fn study(grid: usize, starts: usize, seed: u64) -> femu_study::Study {
    let text = format!(
        "[model]\nelements = 700\n\
         [[test]]\nkind = \"compression\"\nside = \"anterior\"\nforce_n_per_mm = 0.1\n\
         [grid]\ncounts = [{grid}, {grid}]\n[noise]\nsigma_mm = 2e-3\n\
         [identification]\ngrouped = true\nstarts = {starts}\nseed = {seed}\ndiscretization = \"off\"\n"
    );
    femu_study::parse(&text, std::path::Path::new(".")).unwrap()
}

/// The identified values and the forward solves of each start.
fn outcome(s: &IdentificationSummary) -> (Vec<f64>, Vec<usize>) {
    (
        s.parameters.iter().map(|p| p.identified).collect(),
        s.forward_solves_per_start.clone(),
    )
}

#[test]
fn the_steps_read_the_sections_they_are_given() {
    // `a` is run on the parts of `own`, with the grid and [identification] of `other`.
    let own = study(12, 2, 1);
    let other = study(16, 1, 5);
    let whole = identify::identify(&other, None, &scratch("whole"), &Quiet).unwrap();
    assert_eq!(whole.starts_per_repeat, 1);

    let built = femu_study::model::build(&own.model).unwrap();
    let measure_inputs = MeasureInputs {
        grid: &other.measurement.grid,
        ..MeasureInputs::of(&own)
    };
    let prepared = measure::prepare(&measure_inputs, &built, &scratch("parts"), &Quiet).unwrap();
    let [p] = prepared.as_slice() else {
        panic!("one measurement expected, got {}", prepared.len())
    };
    let PreparedData::Virtual { total, .. } = &p.data else {
        panic!("a virtual measurement expected")
    };
    assert_eq!(*total, 16 * 16, "the grid given, not the study's 12 x 12");
    let inputs = IdentificationInputs::of(&own).with(&other.identification);
    let parts = identify::identify_on(
        &inputs,
        other.identification.grouped(),
        &built,
        &prepared,
        &scratch("parts-identify"),
        &Quiet,
    )
    .unwrap();
    assert_eq!(parts.starts_per_repeat, 1);
    assert_eq!(parts.points_in_tissue, whole.points_in_tissue);
    assert_eq!(outcome(&parts), outcome(&whole));

    // The first study's own sections: another grid, seed and number of starts, so another fit.
    let own_prepared =
        measure::prepare(&MeasureInputs::of(&own), &built, &scratch("own"), &Quiet).unwrap();
    let own_fit = identify::identify_on(
        &IdentificationInputs::of(&own),
        true,
        &built,
        &own_prepared,
        &scratch("own-identify"),
        &Quiet,
    )
    .unwrap();
    assert_eq!(own_fit.starts_per_repeat, 2);
    assert_ne!(own_fit.points_in_tissue, whole.points_in_tissue);
    assert_ne!(outcome(&own_fit).0, outcome(&whole).0);
    std::fs::remove_dir_all(base()).ok();
}
