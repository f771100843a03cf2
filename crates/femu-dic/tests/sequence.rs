//! DIC on a sequence (`femu_dic::sequence`): frames of a synthetic speckle under a growing
//! field whose last frame has moved the material by up to 60 px — beyond one correlation's
//! reach — correlated frame to frame, warm-started, and composed to the first frame; scored
//! against the exact field at the composed points.

use femu_dic::auto::Setting;
use femu_dic::command::{CorrelationSpec, RoiSpec};
use femu_dic::lab::{self, Speckle};
use femu_dic::output::ModelFrame;
use femu_dic::quality::TrustCriteria;
use femu_dic::sequence::correlate_sequence;
use femu_dic::{DicOptions, GreyImage};

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

/// The field at load fraction `t`: a downward motion of 60 px at the top shrinking with depth
/// (a compression of 10 %) and a lateral spread of 4 % (px).
fn field(t: f64) -> impl Fn(f64, f64) -> [f64; 2] + Sync {
    move |x, y| [t * 0.04 * (x - 160.0), t * (60.0 - 0.1 * y)]
}

fn frames(n: usize, noise: f64) -> Vec<GreyImage> {
    let speckle = Speckle::new(320, 320, 1.5, 7);
    (0..=n)
        .map(|k| {
            let g = speckle.deformed(&field(k as f64 / n as f64));
            let g = if noise > 0.0 {
                lab::add_noise(&g, noise, 100 + k as u64)
            } else {
                g
            };
            lab::quantize_8bit(&g)
        })
        .collect()
}

fn spec() -> CorrelationSpec {
    CorrelationSpec {
        roi: RoiSpec::Whole,
        options: DicOptions::default(),
        element: Setting::Auto,
        regularization: Setting::Auto,
        trust: TrustCriteria::default(),
    }
}

/// Composed 0 → 4 over 60 px of motion: RMS error at the trusted points below 0.05 px without
/// noise and 0.2 px with 2 grey levels of noise per frame (four increments' errors add up; an
/// increment's noise-free error on 8-bit speckle is ~0.01 px); the later increments start warm.
#[test]
fn a_sequence_composes_large_motion() {
    for (noise, tol) in [(0.0, 0.05), (2.0, 0.2)] {
        let fr = frames(4, noise);
        let seq = correlate_sequence(&fr, &spec(), None, &|_, _| {}).expect("sequence");
        assert_eq!(seq.frames(), 5);
        assert!(seq.increments[1..].iter().all(|i| i.warm_start));
        let truth = field(1.0);
        let pts = seq.field(4, &ModelFrame::default());
        let trusted: Vec<_> = pts.iter().filter(|p| p.w > 0.0).collect();
        measure::record(
            &format!(
                "noise {noise} grey levels: composed points trusted, of {}",
                pts.len()
            ),
            trusted.len() as f64,
            &format!("> {} (half), of more than 100", pts.len() / 2),
            "",
        );
        assert!(
            trusted.len() > pts.len() / 2 && pts.len() > 100,
            "{} of {} points trusted",
            trusted.len(),
            pts.len()
        );
        let mut sq = [0.0; 2];
        for p in &trusted {
            let t = truth(p.x_px[0], p.x_px[1]);
            sq[0] += (p.u_px[0] - t[0]).powi(2);
            sq[1] += (p.u_px[1] - t[1]).powi(2);
        }
        let rms = sq.map(|s| (s / trusted.len() as f64).sqrt());
        for (k, axis) in ["lateral", "axial"].iter().enumerate() {
            measure::record(
                &format!("noise {noise} grey levels: {axis} RMS error of the composed 0 → 4 field (60 px of motion)"),
                rms[k],
                &format!("< {tol}"),
                "px",
            );
        }
        assert!(
            rms[0] < tol && rms[1] < tol,
            "noise {noise}: RMS {rms:?} px"
        );
        // The composed standard deviations grow with the number of increments.
        let sd1: f64 = seq.field(1, &ModelFrame::default())[0].s_mm[1];
        let sd4: f64 = pts[0].s_mm[1];
        measure::record(
            &format!("noise {noise} grey levels: composed axial sd to frame 4 / to frame 1"),
            sd4 / sd1,
            "> 1",
            "",
        );
        assert!(sd4 > sd1, "sd to frame 1 {sd1}, to frame 4 {sd4}");
    }
}

/// Frames of another size are refused before any correlation, naming the frame.
#[test]
fn frames_of_another_size_are_refused() {
    let mut fr = frames(2, 0.0);
    fr[2] = GreyImage::new(100, 100, vec![0.0; 100 * 100]).unwrap();
    let e = correlate_sequence(&fr, &spec(), None, &|_, _| {})
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("frame 2"), "{e}");
}
