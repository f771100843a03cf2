//! The settings and random-error analyses: t-test against SciPy, the real GE Logiq E9
//! frames, and bad manifests.

use femu_ultrasound::manifest::Manifest;
use femu_ultrasound::settings::{self, Region, SettingsOptions};
use femu_ultrasound::stats::paired_t_test;
use std::path::{Path, PathBuf};

#[test]
fn paired_t_test_matches_scipy() {
    // Reference values: scipy.stats.ttest_rel(a, b) with SciPy 1.17.1 (statistic, pvalue, df).
    let a = [
        1.21, 0.98, 1.35, 1.10, 1.48, 0.96, 1.22, 1.05, 1.31, 1.15, 1.02, 1.27,
    ];
    let b = [
        1.05, 0.99, 1.12, 1.08, 1.30, 0.97, 1.01, 1.10, 1.15, 1.12, 0.95, 1.18,
    ];
    let r = paired_t_test(&a, &b).unwrap();
    assert!((r.t - 3.2633422116655555).abs() < 1e-12, "{r:?}");
    assert!((r.p_value - 0.00755399394052248).abs() < 1e-10, "{r:?}");
    assert_eq!(r.degrees_of_freedom, 11.0);
    let c = [0.73, 0.81, 0.95, 1.19, 0.88];
    let d = [0.90, 0.85, 1.02, 1.25, 0.80];
    let r = paired_t_test(&c, &d).unwrap();
    assert!((r.t + 1.3024443769626237).abs() < 1e-12, "{r:?}");
    assert!((r.p_value - 0.2626930321804511).abs() < 1e-10, "{r:?}");
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("femu-us-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn real_logiq_frames_give_sane_histograms_inside_the_roi() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ultrasound/logiq-e9-gastrocnemius");
    if !dir.is_dir() {
        eprintln!("SKIPPED: {} is absent", dir.display());
        return;
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    files.sort();
    let out = tmp("logiq");
    // One acquisition setting (the files do not say theirs): frequency and gains as labels.
    let mut text = String::from("file,frequency_mhz,gain_db,dynamic_db\n");
    for (k, f) in files.iter().enumerate() {
        text += &format!("{},10,{},60\n", f.display(), 40 + k);
    }
    let mp = out.join("manifest.csv");
    std::fs::write(&mp, text).unwrap();
    let m = Manifest::read(&mp).unwrap();
    // The tissue area (README: x 110..690, y 60..520), inside the burned-in text and scales.
    let roi = SettingsOptions {
        region: Region::parse_rect("115,65,570x450").unwrap(),
        ..Default::default()
    };
    let all = SettingsOptions::default();
    let with = settings::analyse(&m, &roi).unwrap();
    let without = settings::analyse(&m, &all).unwrap();
    for (r, a) in with.images.iter().zip(&without.images) {
        let s = &r.stats;
        eprintln!(
            "{}: ROI mean {:.1} std {:.1} black {:.4} white {:.4} p1-p99 {}-{} entropy {:.2} bits | whole frame black {:.3}",
            r.entry.file, s.mean, s.std, s.fraction_black, s.fraction_white, s.p01, s.p99, s.entropy_bits, a.stats.fraction_black
        );
        assert_eq!(s.pixels, 570 * 450);
        assert!(s.saturation() < 0.01);
        assert!(s.mean > 20.0 && s.mean < 200.0 && s.std > 10.0 && s.entropy_bits > 5.0);
        // The frame around the image (annotations, black background) would dominate.
        assert!(a.stats.fraction_black > 10.0 * s.fraction_black.max(1e-3));
    }
    let files = settings::write_outputs(&with, &roi, &out).unwrap();
    assert!(files.iter().any(|f| f == "optimal_gain.png"));
    std::fs::remove_dir_all(&out).ok();
}

fn grey_png(path: &Path, w: u32, h: u32, seed: u32) {
    let img = image::GrayImage::from_fn(w, h, |x, y| {
        image::Luma([((x * 37 + y * 91 + seed * 13) % 251) as u8])
    });
    img.save(path).unwrap();
}

#[test]
fn bad_inputs_name_the_file_and_line() {
    let dir = tmp("bad");
    grey_png(&dir.join("a.png"), 64, 64, 1);
    grey_png(&dir.join("b.png"), 64, 64, 2);
    grey_png(&dir.join("c.png"), 48, 64, 3);
    let write = |name: &str, body: &str| {
        let p = dir.join(name);
        std::fs::write(&p, body).unwrap();
        p
    };
    // A missing file.
    let p = write(
        "missing.csv",
        "file,frequency_mhz,gain_db,dynamic_db\na.png,9,34,42\nnope.png,9,34,42\n",
    );
    let e = Manifest::read(&p).unwrap_err().to_string();
    assert!(e.contains("missing.csv:3") && e.contains("nope.png"), "{e}");
    // Mixed image sizes.
    let p = write(
        "mixed.csv",
        "file,frequency_mhz,gain_db,dynamic_db\na.png,9,34,42\nc.png,9,38,42\n",
    );
    let e = settings::analyse(&Manifest::read(&p).unwrap(), &SettingsOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("mixed.csv:3") && e.contains("c.png") && e.contains("48 x 64"),
        "{e}"
    );
    // A setting with a single image for the random error.
    let p = write("single.csv", "file,frequency_mhz,gain_db,dynamic_db,subject\na.png,9,34,42,s1\nb.png,9,34,42,s1\na.png,9,38,42,s1\n");
    let e = femu_ultrasound::noise::analyse(
        &Manifest::read(&p).unwrap(),
        &Region::All,
        &Default::default(),
        0.05,
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("single.csv:4") && e.contains("single image") && e.contains("G38"),
        "{e}"
    );
    // A ROI outside the images.
    let p = write(
        "ok.csv",
        "file,frequency_mhz,gain_db,dynamic_db\na.png,9,34,42\n",
    );
    let opts = SettingsOptions {
        region: Region::parse_rect("0,0,100x10").unwrap(),
        ..Default::default()
    };
    let e = settings::analyse(&Manifest::read(&p).unwrap(), &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--roi") && e.contains("64 x 64"), "{e}");
    assert!(Region::parse_rect("5,5,2,9").is_err());
    assert!(Region::parse_rect("5,5,0x9").is_err());
    std::fs::remove_dir_all(&dir).ok();
}
