//! `femu convergence STUDY --out DIR` as a user runs it: the output folder of a small study on
//! the built-in thigh, and the error a bad study file gets.

mod common;
use common::{femu, scratch};

/// Three small meshes (700 to 2 400 quads), contention, CPE4H and CPE4, no locking study; the
/// tolerance is the DIC noise (2e-2 mm) since the meshes are far coarser than the seed's.
#[test]
fn convergence_writes_table_figure_and_recommendation() {
    let dir = scratch("study");
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        "elements = [\"CPE4H\", \"CPE4\"]\ntarget_elements = [700, 1200, 2400]\ntolerance_mm = 2e-2\nlocking = false\n[contention]\nmmhg = 20.0\n",
    )
    .unwrap();
    let out = dir.join("out");
    let o = femu(&[
        "convergence",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("Recommended mesh"), "{stdout}");
    for f in [
        "convergence.csv",
        "convergence.json",
        "convergence.png",
        "reference_grid.csv",
        "summary.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("convergence.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 2 * 3, "{csv}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let rec = &summary["recommended"];
    assert!(rec["elements"].as_u64().unwrap() > 0, "{summary}");
    assert!(rec["max_diff_mm"].as_f64().unwrap() < 2e-2);
    assert!(summary["common_points"].as_u64().unwrap() > 1000);
    // The reference field is in the measured-field format (conventions.md).
    let grid = std::fs::read_to_string(out.join("reference_grid.csv")).unwrap();
    assert!(grid.lines().any(|l| l == "x,y,ux,uy"));
}

/// An unknown key: non-zero exit, the message names the file and the key, nothing is solved.
#[test]
fn bad_study_file_names_the_key() {
    let dir = scratch("bad");
    let study = dir.join("bad.toml");
    std::fs::write(
        &study,
        "target_elements = [700, 1200, 2400]\ntolerence_mm = 1e-3\n",
    )
    .unwrap();
    let o = femu(&[
        "convergence",
        study.to_str().unwrap(),
        "--out",
        dir.join("out").to_str().unwrap(),
        "--quiet",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("bad.toml") && err.contains("tolerence_mm"),
        "{err}"
    );
    assert!(!dir.join("out").join("summary.json").exists());
}
