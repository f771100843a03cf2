//! `femu mesh thigh` and `femu mesh labels` as a user runs them: the output folder, its
//! summary, and clear errors on bad input.

use std::path::Path;

mod common;
use common::{femu, scratch};

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// A 60 x 60 px label disk: bone (7) within 8 px of the centre, `inner` (a label value) to
/// 18 px, fat (1) to 28 px, background (0) outside.
fn disk(dir: &Path, inner: f64) -> std::path::PathBuf {
    let path = dir.join("disk.png");
    let data = (0..60 * 60)
        .map(|k| {
            let (x, y) = ((k % 60) as f64 - 29.5, (k / 60) as f64 - 29.5);
            match x.hypot(y) {
                r if r < 8.0 => 7.0,
                r if r < 18.0 => inner,
                r if r < 28.0 => 1.0,
                _ => 0.0,
            }
        })
        .collect();
    femu_dic::GreyImage::new(60, 60, data)
        .unwrap()
        .save_png(&path)
        .unwrap();
    path
}

fn assert_outputs(dir: &Path) {
    for f in [
        "mesh.inp",
        "mesh.vtu",
        "regions.png",
        "quality.csv",
        "quality.json",
        "summary.json",
    ] {
        assert!(dir.join(f).exists(), "{f} missing in {}", dir.display());
    }
}

#[test]
fn mesh_thigh_writes_the_output_folder_and_its_deck_solves() {
    let out = scratch("thigh");
    let o = femu(&[
        "mesh",
        "thigh",
        "--size",
        "4",
        "--element",
        "cpe4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_outputs(&out);
    let s = summary(&out);
    assert_eq!(s["command"], "mesh thigh");
    assert_eq!(s["element"], "CPE4");
    let n = s["elements"].as_u64().unwrap();
    assert!(n > 300 && n < 2000, "{n}");
    assert_eq!(s["regions"].as_object().unwrap().len(), 5);
    assert!(
        s["quality"]["total"]["min_scaled_jacobian"]
            .as_f64()
            .unwrap()
            > 0.3
    );
    let csv = std::fs::read_to_string(out.join("quality.csv")).unwrap();
    assert!(csv.starts_with("region,elements,area_mm2,min_scaled_jacobian"));
    assert_eq!(csv.lines().count(), 7);
    // The deck runs through `femu solve` as is.
    let solved = out.join("solve");
    let o = femu(&[
        "solve",
        out.join("mesh.inp").to_str().unwrap(),
        "--out",
        solved.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(solved.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(s["status"], "converged");
    // Dimensions from a study-style file; bad ones are refused with the key named.
    let params = out.join("thigh.toml");
    std::fs::write(
        &params,
        "[thigh]\nfat_thickness_mm = 12.0\nelement_size_mm = 4.0\n",
    )
    .unwrap();
    let o = femu(&[
        "mesh",
        "thigh",
        "--params",
        params.to_str().unwrap(),
        "--out",
        out.join("p").to_str().unwrap(),
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        summary(&out.join("p"))["input"]["params"]["fat_thickness_mm"],
        12.0
    );
    std::fs::write(&params, "[thigh]\nfemur_diameter_mm = 80.0\n").unwrap();
    let o = femu(&[
        "mesh",
        "thigh",
        "--params",
        params.to_str().unwrap(),
        "--out",
        out.join("q").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("femur_diameter_mm"));
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn mesh_labels_on_the_mri_slice_and_bad_inputs() {
    let out = scratch("labels");
    let image = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/mri/thigh_001_slice06_labels.png");
    let map = "1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=ischio";
    if image.exists() {
        let o = femu(&[
            "mesh",
            "labels",
            image.to_str().unwrap(),
            "--pixel-size",
            "0.7422",
            "--map",
            map,
            "--bone",
            "7",
            "--size",
            "2",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_outputs(&out);
        let s = summary(&out);
        for (r, v) in s["regions"].as_object().unwrap() {
            let e = v["area_error_percent"].as_f64().unwrap();
            assert!(e.abs() < 2.0, "{r}: {e} %");
        }
        assert!(s["femur_area_error_percent"].as_f64().unwrap().abs() < 3.0);
        assert!(!s["warnings"].as_array().unwrap().is_empty());
        // A label without a mapping (6 left out) is named.
        let o = femu(&[
            "mesh",
            "labels",
            image.to_str().unwrap(),
            "--pixel-size",
            "0.7422",
            "--map",
            "1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius",
            "--bone",
            "7",
            "--out",
            out.join("x").to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        assert!(String::from_utf8_lossy(&o.stderr).contains("label 6"));
        // A region without a Table 1 material.
        let o = femu(&[
            "mesh",
            "labels",
            image.to_str().unwrap(),
            "--pixel-size",
            "0.7422",
            "--map",
            "1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=adductor",
            "--bone",
            "7",
            "--out",
            out.join("y").to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        assert!(String::from_utf8_lossy(&o.stderr).contains("ADDUCTOR"));
    } else {
        eprintln!("SKIPPED the MRI part: {} is absent", image.display());
    }
    // Unreadable image; missing pixel size; bad map.
    std::fs::create_dir_all(&out).unwrap();
    let junk = out.join("junk.png");
    std::fs::write(&junk, "not a picture").unwrap();
    let o = femu(&[
        "mesh",
        "labels",
        junk.to_str().unwrap(),
        "--pixel-size",
        "1",
        "--map",
        "1=fat",
        "--bone",
        "7",
        "--out",
        out.join("z").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("junk.png"));
    let o = femu(&[
        "mesh",
        "labels",
        junk.to_str().unwrap(),
        "--map",
        "1=fat",
        "--bone",
        "7",
        "--pixel-size",
        "0",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--pixel-size"));
    let o = femu(&[
        "mesh",
        "labels",
        junk.to_str().unwrap(),
        "--pixel-size",
        "1",
        "--map",
        "1-fat",
        "--bone",
        "7",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("LABEL=REGION"));
    std::fs::remove_dir_all(&out).ok();
}

/// Issues 32.7 and 32.8: a thigh too coarse to keep its regions, and a label-image mesh whose
/// estimated size is absurd, are refused at once with the limit (before: `--elements 100`
/// gave 639 quads without a femur; `--size 0.01` ran 40 s to 3.6 GB and aborted).
#[test]
fn too_coarse_or_absurd_meshes_are_refused_with_the_limit() {
    let out = scratch("limits");
    let o = femu(&[
        "mesh",
        "thigh",
        "--elements",
        "100",
        "--out",
        out.join("thigh").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("at least 622"), "{err}");
    assert!(!out.join("thigh/mesh.inp").exists());
    // A 60 x 60 px disk of tissue (label 1) around a bone (label 7), 0.5 mm pixels.
    std::fs::create_dir_all(&out).unwrap();
    let labels = disk(&out, 1.0);
    let t = std::time::Instant::now();
    let o = femu(&[
        "mesh",
        "labels",
        labels.to_str().unwrap(),
        "--pixel-size",
        "0.5",
        "--map",
        "1=fat",
        "--bone",
        "7",
        "--size",
        "0.01",
        "--out",
        out.join("labels").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("quads") && err.contains("above the limit of 500000"),
        "{err}"
    );
    assert!(t.elapsed().as_secs_f64() < 10.0, "{:?}", t.elapsed());
    std::fs::remove_dir_all(&out).ok();
}

/// Issue 32.13: a region outside Table 1 (`6=adductor`) takes the material a
/// `[materials.ADDUCTOR]` table gives it — in `femu mesh labels --materials` and in a study —
/// and has its own parameters (C10_ADDUCTOR, D_ADDUCTOR); without a table the error names the
/// one to add. Before, both were refused and the adductor had to be merged into ischio.
#[test]
fn an_extra_region_gets_its_own_material() {
    let dir = scratch("adductor");
    let labels = disk(&dir, 6.0);
    let mesh = |extra: &[&str], out: &str| {
        let mut a = vec![
            "mesh",
            "labels",
            labels.to_str().unwrap(),
            "--pixel-size",
            "0.5",
            "--map",
            "1=fat,6=adductor",
            "--bone",
            "7",
            "--size",
            "1.5",
        ];
        a.extend(extra);
        let out = dir.join(out);
        a.extend(["--out", out.to_str().unwrap(), "--quiet"]);
        (femu(&a), out)
    };
    let (o, _) = mesh(&[], "none");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("add a [materials.ADDUCTOR] table"), "{err}");
    let mats = dir.join("adductor.toml");
    std::fs::write(
        &mats,
        "[materials.ADDUCTOR]\nc10_kpa = 2.5\nd_per_mpa = 20\n",
    )
    .unwrap();
    let (o, out) = mesh(&["--materials", mats.to_str().unwrap()], "mesh");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let deck = std::fs::read_to_string(out.join("mesh.inp")).unwrap();
    assert!(deck.contains("*MATERIAL, NAME=ADDUCTOR"), "{deck}");
    assert!(deck.contains("0.0025"), "C10 = 2.5 kPa in MPa");
    // An incomplete table for a new region names what is missing.
    std::fs::write(&mats, "[materials.ADDUCTOR]\nc10_kpa = 2.5\n").unwrap();
    let (o, _) = mesh(&["--materials", mats.to_str().unwrap()], "half");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("d_per_mpa"), "{err}");
    // The same region in a study: its parameters are the model's.
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        "[labels]\nimage = \"disk.png\"\nmap = \"1=fat,6=adductor\"\nbone = [7]\npixel_size_mm = 0.5\n\
         [model]\nsize_mm = 1.5\n[materials.ADDUCTOR]\nc10_kpa = 2.5\nd_per_mpa = 20\n\
         [[test]]\nkind = \"contention\"\n[grid]\ncounts = [16, 16]\n\
         [identification]\nfixed = [\"D_ADDUCTOR\"]\ngrouped = false\n[run]\nsensitivity = false\n",
    )
    .unwrap();
    let run = dir.join("run");
    let o = femu(&[
        "run",
        study.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("identify/ungrouped/summary.json")).unwrap(),
    )
    .unwrap();
    let names: Vec<&str> = s["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["C10_FAT", "D_FAT", "C10_ADDUCTOR"], "{s}");
    std::fs::remove_dir_all(&dir).ok();
}
