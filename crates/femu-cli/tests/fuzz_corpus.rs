//! The fuzzing corpus replayed on stable (issue 28, item 2): every input in
//! `fuzz/corpus/TARGET/` — the seeds and what libFuzzer kept (minimized with `cargo fuzz cmin`),
//! and the inputs that once crashed a reader (`fuzz/regressions/TARGET/`) — goes through the
//! same harness as the fuzz target (`fuzz/harness.rs`) and must return without panicking. A
//! reader that panics again on an input the fuzzer found fails this test in CI, without a
//! nightly compiler.

#[path = "../../../fuzz/harness.rs"]
mod harness;

use std::path::{Path, PathBuf};

/// What a fuzz target runs on one input.
type Harness = fn(&[u8]);

/// The fuzz targets and the harness function each runs.
const TARGETS: [(&str, Harness); 8] = [
    ("deck", harness::deck),
    ("gmsh", harness::gmsh),
    ("measured_csv", harness::measured_csv),
    ("study", harness::study),
    ("image", harness::image),
    ("dicom", harness::dicom),
    ("label_image", harness::label_image),
    ("nifti", harness::nifti),
];

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

/// The files of `dir` (none when it does not exist), sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.path())
                .filter(|p| p.is_file())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Runs every input of `target`; returns how many ran and the ones that panicked.
fn replay(target: &str, run: Harness) -> (usize, Vec<String>) {
    let mut inputs = files(&fuzz_dir().join("corpus").join(target));
    inputs.extend(files(&fuzz_dir().join("regressions").join(target)));
    let mut panics = Vec::new();
    for p in &inputs {
        let data = std::fs::read(p).unwrap();
        if let Err(e) = std::panic::catch_unwind(|| run(&data)) {
            let why = e
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            panics.push(format!("{target}: {}: {why}", p.display()));
        }
    }
    (inputs.len(), panics)
}

#[test]
fn no_input_of_the_fuzzing_corpus_panics_a_reader() {
    let mut panics = Vec::new();
    let mut total = 0;
    for (target, run) in TARGETS {
        let (n, p) = replay(target, run);
        // Every target has its seeds committed: an empty folder means a lost corpus.
        assert!(n > 0, "fuzz/corpus/{target} is empty");
        eprintln!("{target}: {n} inputs");
        total += n;
        panics.extend(p);
    }
    eprintln!("{total} inputs replayed, {} panicked", panics.len());
    assert!(panics.is_empty(), "\n{}", panics.join("\n"));
}

/// The seeds (`fuzz/corpus/TARGET/seed_*`, written by `fuzz/seeds.py`) are valid inputs, so that
/// the fuzzer mutates files that reach deep into each reader, not only its first check.
#[test]
fn the_seeds_are_inputs_the_readers_accept() {
    let seeds = |target: &str| -> Vec<PathBuf> {
        let v: Vec<PathBuf> = files(&fuzz_dir().join("corpus").join(target))
            .into_iter()
            .filter(|p| {
                p.file_name()
                    .unwrap()
                    .to_string_lossy()
                    .starts_with("seed_")
            })
            .collect();
        assert!(!v.is_empty(), "no seed in fuzz/corpus/{target}");
        v
    };
    let text = |p: &Path| std::fs::read_to_string(p).unwrap();
    for p in seeds("deck") {
        let deck = femu_mesh::inp::parse_inp(&text(&p), "seed.inp")
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        femu_mech::Model::from_deck(deck).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
    for p in seeds("gmsh") {
        femu_mesh::msh::parse_msh(&text(&p), "seed.msh")
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
    for p in seeds("measured_csv") {
        femu_identify::measured::MeasuredField::parse(&text(&p), "seed.csv")
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
    for p in seeds("image").into_iter().chain(seeds("dicom")) {
        femu_dic::GreyImage::open(&p, 0).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
    for p in seeds("label_image").into_iter().chain(seeds("nifti")) {
        // The readers look at the extension: the seeds are named seed_NAME.EXT.
        femu_geometry::labels::read_label_image(
            &p,
            p.to_string_lossy().ends_with("volume_u8.nii").then_some(1),
        )
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
    for p in seeds("study") {
        let base = p.parent().unwrap();
        femu_study::parse(&text(&p), base).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
    }
}

/// The DICOM inputs that once made dicom-rs reserve gigabytes (`fuzz/regressions/dicom/oom_*`)
/// are refused by femu's own walk over the element headers (a length the file cannot hold, or
/// one that would put dicom-rs's reader off), before dicom-rs reads a value: the
/// replay above would pass on a machine with the memory to spare, this does not.
#[test]
fn dicom_inputs_that_once_asked_for_gigabytes_are_refused_before_a_value_is_read() {
    let oom: Vec<PathBuf> = files(&fuzz_dir().join("regressions").join("dicom"))
        .into_iter()
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("oom_"))
        .collect();
    assert!(oom.len() >= 3, "the oom_* regressions are missing");
    for p in oom {
        let e = femu_dic::GreyImage::open(&p, 0).unwrap_err().to_string();
        assert!(
            e.contains("damaged") && e.contains("at byte"),
            "{}: {e}",
            p.display()
        );
    }
}
