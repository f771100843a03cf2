//! `femu sensitivity`: the seed's qualitative finding on a coarse built-in thigh, the direct
//! differentiation against finite differences through the command, the outputs, and bad input.

use std::path::{Path, PathBuf};

mod common;
use common::{femu, scratch};
#[path = "../../../scripts/guide/measure.rs"]
mod measure;

fn write_study(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("study.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// Contention and compression on an 800-quad thigh: contention is most sensitive to D and
/// compression to C10 (the seed's Fig. 8 finding), the finite-difference check agrees to 1e-5,
/// and the files are written.
#[test]
fn seed_finding_and_fd_check() {
    let dir = scratch("finding");
    let study = write_study(
        &dir,
        "[model]\nelements = 800\n[[test]]\nkind = \"contention\"\n\
         [[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n",
    );
    let out = dir.join("out");
    let o = femu(&[
        "sensitivity",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--fd-check",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let finding: Vec<String> = s["finding"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    assert!(
        finding[0].starts_with("contention: the D family"),
        "{finding:?}"
    );
    assert!(
        finding[1].starts_with("compression-anterior: the C10 family"),
        "{finding:?}"
    );
    for t in s["tests"].as_array().unwrap() {
        for pair in t["finite_difference_max_relative_difference"]
            .as_array()
            .unwrap()
        {
            let d = pair[1].as_f64().unwrap();
            measure::record(
                &format!(
                    "{}, {}: direct sensitivity against `--fd-check`, largest relative difference",
                    t["test"].as_str().unwrap_or("?"),
                    pair[0].as_str().unwrap_or("?")
                ),
                d,
                "< 1e-5",
                "",
            );
            assert!(d < 1e-5, "{}: {pair}", t["test"]);
        }
    }
    // The grouped compression predicts a finite sd for every parameter.
    let ranking = s["ranking"].as_array().unwrap();
    assert!(ranking.iter().any(|r| r["grouping"] == "grouped"
        && r["measurement"] == "compression-anterior"
        && r["worst_d_relative_sd"].as_f64().unwrap().is_finite()));
    for f in [
        "identifiability.csv",
        "sensitivity_maps.png",
        "sensitivity_quadriceps.png",
        "sensitivity_index.png",
        "contention/sensitivity.csv",
        "contention/sensitivity.vtu",
        "compression-anterior/sensitivity.csv",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let header = std::fs::read_to_string(out.join("contention/sensitivity.csv")).unwrap();
    assert!(header.starts_with("node,x,y,ux,uy,S_C10_FAT,S_D_FAT"));
}

/// Registered laws other than the seed's reach the sensitivity maps through the registry (issue
/// 26): a Yeoh fat and a Mooney–Rivlin quadriceps give one map per law parameter (C20 and C30
/// of the fat, C01 of the quadriceps), with the exact derivatives agreeing with finite
/// differences through the command.
#[test]
fn other_laws_have_their_maps() {
    let dir = scratch("laws");
    let study = write_study(
        &dir,
        "[model]\nelements = 700\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
         [materials.FAT]\nlaw = \"yeoh\"\nc10_kpa = 0.8\nc20_kpa = 0.3\nc30_kpa = 0.1\nd_per_mpa = 30.8\n\
         [materials.QUADRICEPS]\nlaw = \"mooney-rivlin\"\nc10_kpa = 1.2\nc01_kpa = 0.5\nd_per_mpa = 18\n",
    );
    let out = dir.join("out");
    let o = femu(&[
        "sensitivity",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--fd-check",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let header = std::fs::read_to_string(out.join("compression-anterior/sensitivity.csv")).unwrap();
    let header = header.lines().next().unwrap();
    assert!(
        header.starts_with(
            "node,x,y,ux,uy,S_C10_FAT,S_C20_FAT,S_C30_FAT,S_D_FAT,S_C10_QUADRICEPS,S_C01_QUADRICEPS,S_D_QUADRICEPS"
        ),
        "{header}"
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let fd = s["tests"][0]["finite_difference_max_relative_difference"]
        .as_array()
        .unwrap();
    assert_eq!(fd.len(), 13, "{fd:?}");
    for pair in fd {
        // The FD check's own tolerance above (re-solves converged to 1e-12, step 5e-4).
        assert!(pair[1].as_f64().unwrap() < 1e-5, "{pair}");
    }
}

#[test]
fn bad_studies_are_named() {
    let dir = scratch("bad");
    let cases = [
        ("[model]\nelemnts = 800\n", "elemnts"),
        ("[materials.bone]\nc10_kpa = 1.0\n", "[materials.bone]"),
        ("[parameters]\ngroups = [[\"D_FEMUR\"]]\n", "D_FEMUR"),
        ("[grid]\norigin_mm = [1000.0, 1000.0]\nspacing_mm = 1.0\ncounts = [4, 4]\n[model]\nelements = 700\n[[test]]\nkind = \"contention\"\n", "no grid point"),
    ];
    for (k, (text, needle)) in cases.iter().enumerate() {
        let study = write_study(&dir, text);
        let o = femu(&[
            "sensitivity",
            study.to_str().unwrap(),
            "--out",
            dir.join(format!("o{k}")).to_str().unwrap(),
            "--no-figures",
            "--elements",
            "700",
        ]);
        assert!(!o.status.success(), "case {k} should fail");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "case {k}: {err}");
    }
}
