//! `femu dic` and `femu dic-noise` as a user runs them: the output folder on a synthetic
//! speckle pair (virtual lab, 8-bit PNG), and clear errors for bad input.

use femu_dic::lab::{self, Speckle};
use std::path::{Path, PathBuf};

mod common;
use common::{femu, scratch};

/// A reference and a translated speckle image (0.4, -0.25) px, 8-bit PNG.
fn pair(dir: &Path) -> (PathBuf, PathBuf) {
    let s = Speckle::new(192, 160, 1.5, 3);
    let (f, g) = (s.reference(), s.deformed(&lab::translation(0.4, -0.25)));
    let (pf, pg) = (dir.join("ref.png"), dir.join("def.png"));
    lab::quantize_8bit(&f).save_png(&pf).unwrap();
    lab::quantize_8bit(&g).save_png(&pg).unwrap();
    (pf, pg)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn dic_writes_the_output_folder() {
    let dir = scratch("ok");
    let (f, g) = pair(&dir);
    let out = dir.join("out");
    let o = femu(&[
        "dic",
        s(&f),
        s(&g),
        "--roi",
        "16,16,160x128",
        "--element",
        "16",
        "--pixel-size",
        "0.1",
        "--y-up",
        "--out",
        s(&out),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for name in [
        "field.csv",
        "nodes.csv",
        "elements.csv",
        "covariance.mtx",
        "hessian.mtx",
        "hessian_noise.mtx",
        "result.vtu",
        "summary.json",
        "ux.png",
        "uy.png",
        "exx.png",
        "eyy.png",
        "exy.png",
        "residual.png",
        "sd.png",
        "zncc.png",
        "trust.png",
    ] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    let csv = std::fs::read_to_string(out.join("field.csv")).unwrap();
    let mut rows = csv.lines().filter(|l| !l.starts_with('#'));
    assert_eq!(rows.next(), Some("x,y,ux,uy,sx,sy,w"));
    // ux = 0.4 px x 0.1 mm, uy = -0.25 px x 0.1 mm x (-1: y up) = +0.025 mm; noise-free
    // 8-bit images: standard deviations of a few thousandths of a pixel (1e-4 mm), positive.
    let mut n = 0;
    for r in rows {
        let v: Vec<f64> = r.split(',').map(|t| t.parse().unwrap()).collect();
        assert!(
            (v[2] - 0.04).abs() < 0.002 && (v[3] - 0.025).abs() < 0.002,
            "{r}"
        );
        assert!(
            v[4] > 0.0 && v[4] < 2e-3 && v[5] > 0.0 && v[5] < 2e-3,
            "{r}"
        );
        assert!(v[6] == 0.0 || v[6] == 1.0, "{r}");
        n += 1;
    }
    assert_eq!(n, 80, "grid points: 10 x 8 elements at the default step");
    let sum: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(sum["result"]["converged"], true);
    assert_eq!(sum["pixel_size"]["source"], "option --pixel-size");
    assert_eq!(sum["choice"]["element_size_px"], 16);
    assert!(
        sum["choice"]["regularization_px"].is_null(),
        "speckle: unregularized"
    );
    // The covariance file: a symmetric Matrix Market matrix over 2 x 99 equations, whose
    // diagonal matches the nodal sd of nodes.csv.
    let mtx = std::fs::read_to_string(out.join("covariance.mtx")).unwrap();
    let mut lines = mtx.lines().filter(|l| !l.starts_with('%'));
    let dims: Vec<usize> = lines
        .next()
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    assert_eq!((dims[0], dims[1]), (198, 198));
    let diag: std::collections::HashMap<usize, f64> = lines
        .filter_map(|l| {
            let v: Vec<&str> = l.split_whitespace().collect();
            (v[0] == v[1]).then(|| (v[0].parse().unwrap(), v[2].parse().unwrap()))
        })
        .collect();
    let nodes = std::fs::read_to_string(out.join("nodes.csv")).unwrap();
    let mut it = nodes.lines();
    let head: Vec<&str> = it.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    for l in it {
        let v: Vec<&str> = l.split(',').collect();
        let node: usize = v[0].parse().unwrap();
        let sd: f64 = v[col("sd_ux_px")].parse().unwrap();
        let var = diag[&(2 * (node - 1) + 1)];
        assert!(
            (sd * sd - var).abs() <= 1e-5 * var,
            "node {node}: {sd}² vs {var}"
        );
    }
}

#[test]
fn dic_check_writes_pairs_checks_and_maps() {
    let dir = scratch("check");
    let s3 = Speckle::new(160, 144, 1.5, 12);
    let mut paths = Vec::new();
    for (k, t) in [(0.0, 0.0), (0.4, -0.2), (0.9, 0.1)].iter().enumerate() {
        let p = dir.join(format!("f{k}.png"));
        lab::quantize_8bit(&s3.deformed(&lab::translation(t.0, t.1)))
            .save_png(&p)
            .unwrap();
        paths.push(p);
    }
    let out = dir.join("out");
    let mut args = vec!["dic-check"];
    args.extend(paths.iter().map(|p| s(p)));
    args.extend(["--roi", "16,16,128x112", "--out", s(&out), "--quiet"]);
    let o = femu(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let pairs = std::fs::read_to_string(out.join("pairs.csv")).unwrap();
    assert_eq!(
        pairs.lines().count(),
        1 + 2 + 2 + 1,
        "2 forward, 2 backward, 1 direct"
    );
    let sum: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(sum["all_converged"], true);
    for c in sum["pooled"].as_array().unwrap() {
        let rms = &c["regions"][0]["rms_px"];
        for k in 0..2 {
            assert!(rms[k].as_f64().unwrap() < 0.02, "{c}");
        }
    }
    assert!(out.join("composition_f0_f1_f2.png").is_file());
    assert!(out.join("forward-backward_f0_f1_f0.png").is_file());
    // points.csv holds the points each check's statistics are made of: the RMS of its rows is
    // the check's RMS over all points in checks.csv (both printed to 5 decimals).
    let points = std::fs::read_to_string(out.join("points.csv")).unwrap();
    let checks = std::fs::read_to_string(out.join("checks.csv")).unwrap();
    for c in sum["checks"].as_array().unwrap() {
        let (name, frames) = (
            c["check"].as_str().unwrap(),
            c["frames"]
                .as_array()
                .unwrap()
                .iter()
                .map(|f| f.as_str().unwrap())
                .collect::<Vec<_>>()
                .join(">"),
        );
        let rows: Vec<Vec<f64>> = points
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect::<Vec<_>>())
            .filter(|v| v[0] == name && v[1] == frames)
            .map(|v| v[2..].iter().map(|x| x.parse().unwrap()).collect())
            .collect();
        let listed: Vec<f64> = checks
            .lines()
            .map(|l| l.split(',').collect::<Vec<_>>())
            .find(|v| v[0] == name && v[1] == frames && v[2] == "all" && v[3] == "all")
            .map(|v| v[4..9].iter().map(|x| x.parse().unwrap()).collect())
            .unwrap();
        assert_eq!(rows.len() as f64, listed[0], "{name} {frames}");
        let rms =
            |k: usize| (rows.iter().map(|r| r[k] * r[k]).sum::<f64>() / rows.len() as f64).sqrt();
        assert!(
            (rms(2) - listed[3]).abs() < 1e-4,
            "{name} {frames}: {} against {}",
            rms(2),
            listed[3]
        );
        assert!(
            (rms(3) - listed[4]).abs() < 1e-4,
            "{name} {frames}: {} against {}",
            rms(3),
            listed[4]
        );
    }
}

#[test]
fn dic_noise_writes_csv_and_box_plot() {
    let dir = scratch("noise");
    let s3 = Speckle::new(128, 128, 1.5, 9);
    let base = s3.reference();
    let mut paths = Vec::new();
    for k in 0..3 {
        let p = dir.join(format!("f{k}.png"));
        lab::quantize_8bit(&lab::add_noise(&base, 2.0, k))
            .save_png(&p)
            .unwrap();
        paths.push(p);
    }
    let out = dir.join("out");
    let mut args = vec!["dic-noise"];
    args.extend(paths.iter().map(|p| s(p)));
    args.extend(["--roi", "16,16,96x96", "--out", s(&out), "--quiet"]);
    let o = femu(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("noise.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "header + 2 pairs");
    assert!(out.join("noise_box.png").is_file() && out.join("summary.json").is_file());
}

#[test]
fn bad_input_gets_a_clear_error() {
    let dir = scratch("bad");
    let (f, g) = pair(&dir);
    let small = dir.join("small.png");
    femu_dic::GreyImage::new(64, 64, vec![10.0; 64 * 64])
        .unwrap()
        .save_png(&small)
        .unwrap();
    let flat = dir.join("flat.png");
    femu_dic::GreyImage::new(192, 160, vec![90.0; 192 * 160])
        .unwrap()
        .save_png(&flat)
        .unwrap();
    let out = dir.join("out");
    let missing = dir.join("missing.png");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec![s(&f), s(&small)], "differ in size"),
        (vec![s(&f), s(&g), "--roi", "150,10,100x50"], "outside"),
        (
            vec![s(&f), s(&g), "--roi", "0,0,40x40", "--element", "64"],
            "larger than the region of interest",
        ),
        (vec![s(&flat), s(&g)], "no texture"),
        (vec![s(&f), s(&g), "--roi", "1,2,3"], "x,y,WxH"),
        // Issue 32.12: four plain numbers are refused with both readings.
        (
            vec![s(&f), s(&g), "--roi", "10,10,150,120"],
            "10,10,150x120 if 150,120 are the width and height, or 10,10,140x110",
        ),
        (vec![s(&f), s(&missing)], "missing.png"),
    ];
    for (args, expect) in cases {
        let mut a = vec!["dic"];
        a.extend(args);
        a.extend(["--out", s(&out), "--quiet"]);
        let o = femu(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{a:?} succeeded");
        assert!(err.contains(expect), "{a:?}: '{err}' lacks '{expect}'");
        assert!(!err.contains("panicked"), "{err}");
    }
}

/// Issue 32.2: `femu dic ux.png uy.png --out .` replaced both images with its maps and exited
/// 0; an output folder holding an input is now refused before anything is written (`.`, or the
/// folder by its path), and the inputs are untouched.
#[test]
fn an_output_folder_holding_an_input_is_refused() {
    let dir = scratch("inputs-in-out");
    let (f, g) = pair(&dir);
    let (ux, uy) = (dir.join("ux.png"), dir.join("uy.png"));
    std::fs::rename(&f, &ux).unwrap();
    std::fs::rename(&g, &uy).unwrap();
    let before = (std::fs::read(&ux).unwrap(), std::fs::read(&uy).unwrap());
    let in_dir = std::process::Command::new(env!("CARGO_BIN_EXE_femu"))
        .current_dir(&dir)
        .args(["dic", "ux.png", "uy.png", "--out", ".", "--quiet"])
        .output()
        .unwrap();
    let by_path = femu(&["dic", s(&ux), s(&uy), "--out", s(&dir), "--quiet"]);
    let noise = femu(&["dic-noise", s(&ux), s(&uy), "--out", s(&dir), "--quiet"]);
    for o in [in_dir, by_path, noise] {
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{err}");
        assert!(
            err.contains("holds the input") && err.contains("ux.png"),
            "{err}"
        );
    }
    assert_eq!(std::fs::read(&ux).unwrap(), before.0);
    assert_eq!(std::fs::read(&uy).unwrap(), before.1);
    assert!(!dir.join("field.csv").exists() && !dir.join("summary.json").exists());
    // A sub-folder is fine.
    let o = femu(&[
        "dic",
        s(&ux),
        s(&uy),
        "--out",
        s(&dir.join("dic")),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
