//! What each fuzz target does with its input: the reader a user's file goes through, as the
//! command line calls it, and then the next step that trusts what the reader returned. Every
//! function takes any bytes and must return without panicking (errors are the expected outcome
//! of most inputs). Included by the fuzz targets (`fuzz_targets/*.rs`, nightly, libFuzzer) and by
//! the corpus replay test on stable (`crates/femu-cli/tests/fuzz_corpus.rs`).

#![allow(dead_code)] // each fuzz target uses one function

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Runs `f` on a file holding `data` named `name` (readers that take a path and look at the
/// extension). The file lives in a folder of its own per process and call, so that parallel
/// replays do not share it.
fn with_file(name: &str, data: &[u8], f: impl FnOnce(&Path)) {
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let dir: PathBuf = std::env::temp_dir().join(format!(
        "femu-fuzz-{}-{}",
        std::process::id(),
        CALLS.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let path = dir.join(name);
    std::fs::write(&path, data).expect("a temporary file");
    f(&path);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Models small enough to be solved on every input (a fuzzed deck is a few hundred bytes).
const MAX_SOLVED_NODES: usize = 64;

/// An Abaqus/CalculiX deck (`femu solve DECK.inp`): read, resolved into a model, and, when it
/// is small, solved.
pub fn deck(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return; // read_inp reads UTF-8 text: anything else is an I/O error there
    };
    let Ok(deck) = femu_mesh::inp::parse_inp(text, "fuzz.inp") else {
        return;
    };
    let Ok(model) = femu_mech::Model::from_deck(deck) else {
        return;
    };
    if model.node_count() <= MAX_SOLVED_NODES {
        let options = femu_mech::SolverOptions::default();
        if let Ok(mut solver) = femu_mech::StaticSolver::new(&model, options) {
            let _ = solver.solve(&model);
        }
    }
}

/// The study file of `femu solve MESH.msh --study`: two regions, a fixed curve, a pressure.
const GMSH_STUDY: &str = r#"element = "CPE4H"
[materials.Fat]
c10_kpa = 0.8
d_per_mpa = 30.8
[materials.surface_7]
c10_kpa = 1.75
d_per_mpa = 18.0
[[fixed]]
curve = "Bottom"
[[pressure]]
curve = "Bottom"
mmhg = 20
"#;

/// A Gmsh 4.1 mesh (`femu solve MESH.msh --study S`): read, then set up with a study naming
/// its regions and curves, and, when it is small, solved.
pub fn gmsh(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    if femu_mesh::msh::parse_msh(&text, "fuzz.msh").is_err() {
        return;
    }
    let study = femu_study::parse(GMSH_STUDY, Path::new(".")).expect("the harness's study");
    with_file("fuzz.msh", data, |path| {
        if let Ok(model) = femu_study::model::gmsh_model(&study, path) {
            if model.node_count() <= MAX_SOLVED_NODES {
                let options = femu_mech::SolverOptions::default();
                if let Ok(mut solver) = femu_mech::StaticSolver::new(&model, options) {
                    let _ = solver.solve(&model);
                }
            }
        }
    });
}

/// A measured-field CSV (`femu identify --measured`, `[measurement] file`): read and mapped to
/// the model frame of an image (pixels, rows going down).
pub fn measured_csv(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    if let Ok(field) = femu_identify::measured::MeasuredField::parse(&text, "fuzz.csv") {
        let _ = field.to_model_frame(0.1, [-20.0, 30.0], [1.0, 0.0], [0.0, -1.0]);
    }
}

/// A study file (`femu run`, `identify`, `sensitivity`, `synth`, `convergence`): parsed and
/// checked in full, and its convergence view built.
pub fn study(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    with_file("study.toml", data, |path| {
        let base = path.parent().expect("a folder");
        if let Ok(study) = femu_study::parse(text, base) {
            let _ = study.convergence_study();
        }
    });
}

/// An image of `femu dic` (PNG or TIFF by content, DICOM by its magic): decoded to grey levels.
pub fn image(data: &[u8]) {
    with_file("fuzz.img", data, |path| {
        let _ = femu_dic::GreyImage::open(path, 0);
    });
}

/// A DICOM file (`femu dic A.dcm B.dcm --frame-ref K`): its header, its first and second frames.
pub fn dicom(data: &[u8]) {
    with_file("fuzz.dcm", data, |path| {
        let _ = femu_dic::dicom::dicom_info(path);
        let _ = femu_dic::GreyImage::open(path, 0);
        let _ = femu_dic::GreyImage::open(path, 1);
    });
}

/// A label image of `femu mesh labels` / `[labels] image` (PNG or TIFF): read, its histogram.
pub fn label_image(data: &[u8]) {
    with_file("labels.png", data, |path| {
        if let Ok(img) = femu_geometry::labels::read_label_image(path, None) {
            let _ = img.histogram();
        }
    });
}

/// A NIfTI-1 label volume (`femu mesh labels VOLUME.nii --slice K`): its first slices.
pub fn nifti(data: &[u8]) {
    with_file("labels.nii", data, |path| {
        for slice in [None, Some(0), Some(1)] {
            if let Ok(img) = femu_geometry::labels::read_label_image(path, slice) {
                let _ = img.histogram();
            }
        }
    });
}
