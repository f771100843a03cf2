//! Real muscle ultrasound (GE Logiq E9, ML6-15 probe, lateral gastrocnemius during a jump;
//! `../shared/data/ultrasound/logiq-e9-gastrocnemius/`, skipped with a message when absent).
//!
//! With the defaults of `femu dic` (element size and regularization chosen from the images,
//! `femu_dic::auto`), every consecutive pair of the six frames converges inside the tissue area
//! (ROI x 144..656, y 80..496), most elements are trusted, and the field from frame 048 to 052
//! agrees with the composition of 048 → 050 and 050 → 052,
//! `u_48→52(X) ≈ u_48→50(X) + u_50→52(X + u_48→50(X))`, to the bounds below (measured numbers
//! in the comments; the heavy comparisons are `femu dic-check` and the `compare_mudic` example).

use femu_dic::auto::{Measured, Setting};
use femu_dic::command::{CorrelationSpec, RoiSpec};
use femu_dic::consistency::{composition, forward_backward, region_stats, CheckedField};
use femu_dic::quality::{Trust, TrustCriteria};
use femu_dic::{DicOptions, GreyImage, Rect};
use std::path::PathBuf;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

fn frame(n: u32) -> Option<GreyImage> {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ultrasound/logiq-e9-gastrocnemius");
    let p = d.join(format!("gastroc_jumping_{n:03}.png"));
    if !p.is_file() {
        eprintln!("SKIPPED: shared data not found at {}", p.display());
        return None;
    }
    Some(GreyImage::open(&p, 0).unwrap())
}

fn spec() -> CorrelationSpec {
    CorrelationSpec {
        roi: RoiSpec::Rect(Rect {
            x: 144,
            y: 80,
            w: 512,
            h: 416,
        }),
        options: DicOptions {
            acceleration_depth: femu_dic::anderson::DEFAULT_DEPTH,
            ..Default::default()
        },
        element: Setting::Auto,
        regularization: Setting::Auto,
        trust: TrustCriteria::default(),
    }
}

fn checked(m: &Measured) -> CheckedField<'_> {
    CheckedField {
        res: &m.res,
        cov: &m.cov,
        trust: &m.trust,
    }
}

/// Issue 31: with the defaults, 0 of the 5 consecutive pairs converged; now all do (measured:
/// 16 px elements, the regularization the ladder chose, 76-96 % of the elements trusted).
#[test]
fn every_consecutive_pair_converges_with_the_defaults() {
    let frames: Vec<GreyImage> = match [48, 50, 52, 54, 56, 58].iter().map(|&n| frame(n)).collect()
    {
        Some(f) => f,
        None => return,
    };
    for k in 0..5 {
        let (m, c) = spec().measure(&frames[k], &frames[k + 1]).unwrap();
        let trusted =
            m.trust.iter().filter(|&&t| t == Trust::Trusted).count() as f64 / m.trust.len() as f64;
        eprintln!(
            "pair {k}: element {} px, regularization {:?} px, {} iterations, {:.0} % trusted, {} attempt(s)",
            c.element_size_px,
            c.regularization_px,
            m.res.iterations,
            100.0 * trusted,
            c.attempts.len()
        );
        let pair = format!("{:03} → {:03}", 48 + 2 * k, 50 + 2 * k);
        measure::record(
            &format!(
                "pair {pair} ({} px elements, {} iterations, converged): elements trusted",
                c.element_size_px, m.res.iterations
            ),
            trusted,
            "≥ 0.5, converged",
            "",
        );
        assert!(m.res.converged, "pair {k}");
        assert!(trusted >= 0.5, "pair {k}: {trusted}");
    }
}

#[test]
fn frames_048_052_agree_with_the_composition_through_050() {
    let (Some(f48), Some(f50), Some(f52)) = (frame(48), frame(50), frame(52)) else {
        return;
    };
    let s = spec();
    let a = s.measure(&f48, &f50).unwrap().0;
    let b = s.measure(&f50, &f52).unwrap().0;
    let c = s.measure(&f48, &f52).unwrap().0;
    let back = s.measure(&f50, &f48).unwrap().0;
    let yr = [79.5, 495.5];
    let comp = region_stats(&composition(&checked(&a), &checked(&b), &checked(&c)), yr);
    let fb = region_stats(&forward_backward(&checked(&a), &checked(&back)), yr);
    for (name, st) in [("composition", &comp), ("forward-backward", &fb)] {
        for r in st {
            eprintln!(
                "{name} {} {}: {} points, mean ({:+.3}, {:+.3}) px, rms ({:.3}, {:.3}) px, predicted sd ({:.3}, {:.3}) px",
                r.region,
                if r.trusted_only { "trusted" } else { "all" },
                r.points,
                r.mean_px[0],
                r.mean_px[1],
                r.rms_px[0],
                r.rms_px[1],
                r.predicted_sd_px[0],
                r.predicted_sd_px[1]
            );
        }
    }
    // Measured (all points): composition RMS (1.57, 0.20) px for a mean motion of 8.2 px, most
    // of it below the deep aponeurosis where the soleus slides (deep band 2.43 px lateral);
    // forward-backward RMS (0.13, 0.04) px. The line-like texture's first rung is 64 px: a
    // 128 px regularization is more self-consistent here ((1.28, 0.13) px) but less accurate on
    // simulated sequences whose true field is known (its lateral error twice as large,
    // bench/independent_us), and this check measures consistency, not accuracy. Bounds with
    // margin over the 64 px numbers.
    measure::record(
        "composition check, points compared",
        comp[0].points as f64,
        "> 600",
        "",
    );
    for (name, st, bound) in [
        (
            "048 → 052 against 048 → 050 → 052",
            &comp,
            ["< 1.7", "< 0.25"],
        ),
        (
            "forward-backward 048 → 050 → 048",
            &fb,
            ["< 0.15", "< 0.05"],
        ),
    ] {
        for (a, axis) in ["lateral", "axial"].iter().enumerate() {
            measure::record(
                &format!("{name}: {axis} RMS difference, all points"),
                st[0].rms_px[a],
                bound[a],
                "px",
            );
        }
    }
    assert!(comp[0].points > 600);
    assert!(
        comp[0].rms_px[0] < 1.7 && comp[0].rms_px[1] < 0.25,
        "{:?}",
        comp[0]
    );
    assert!(
        fb[0].rms_px[0] < 0.15 && fb[0].rms_px[1] < 0.05,
        "{:?}",
        fb[0]
    );
}
