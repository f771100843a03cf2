//! Verification of the B-mode simulator (seed §2.2 trends, speckle statistics) and of the
//! virtual experiment (a known displacement recovered by the DIC).

use femu_mesh::generate::rectangle;
use femu_mesh::ElementKind;
use femu_ultrasound::experiment::{self, ExperimentOptions};
use femu_ultrasound::stats::{correlation_length, grey_stats, texture_by_depth};
use femu_ultrasound::{render, Acoustics, Phantom, Probe, Scanner, Tissue, Transducer};

/// A homogeneous block of muscle-like tissue, 40 mm wide and `depth` deep, the probe on
/// its top edge (y = depth) firing down.
fn block(depth: f64, attenuation: f64, ppm: f64, seed: u64) -> (Phantom, Probe) {
    let g = rectangle(60.0, depth + 10.0, 12, 12, ElementKind::Cpe4);
    let probe = Probe::new([30.0, depth + 10.0], [0.0, -1.0], 30.0, depth, ppm).unwrap();
    let tissue = Tissue {
        name: "MUSCLE".into(),
        density_per_mm2: 400.0,
        echo_db: 0.0,
        attenuation_db_per_cm_mhz: attenuation,
    };
    let ph = Phantom::generate(
        &g.mesh,
        &[],
        &Acoustics::homogeneous(tissue),
        &probe,
        2.0,
        seed,
    )
    .unwrap();
    (ph, probe)
}

fn tx(f: f64) -> Transducer {
    Transducer {
        frequency_mhz: f,
        ..Default::default()
    }
}

#[test]
fn gain_shifts_the_histogram_up_and_dynamic_range_narrows_it() {
    let (ph, probe) = block(20.0, 0.0, 10.0, 1);
    let st = ph.reference();
    let stats = |g: f64, d: f64| {
        let s = Scanner {
            gain_db: g,
            dynamic_db: d,
            ..Default::default()
        };
        let fr = render(&ph, &st, &probe, &tx(9.0), &s, 1).unwrap();
        grey_stats(&fr.image.data, None).unwrap()
    };
    let (lo, hi) = (stats(26.0, 42.0), stats(38.0, 42.0));
    eprintln!("gain 26 -> 38 dB: mean {:.1} -> {:.1}", lo.mean, hi.mean);
    assert!(hi.mean > lo.mean + 40.0);
    let (narrow, wide) = (stats(34.0, 42.0), stats(34.0, 84.0));
    eprintln!(
        "dynamic 42 -> 84 dB: std {:.1} -> {:.1}",
        narrow.std, wide.std
    );
    assert!(wide.std < 0.6 * narrow.std);
}

#[test]
fn envelope_of_fully_developed_speckle_is_rayleigh() {
    // Rayleigh: mean/std = sqrt(pi/2)/sqrt(2 - pi/2) = 1.913. The ~16 000 speckle cells of
    // the image give the ratio a statistical spread of about 1 %; 400 scatterers/mm² are
    // 15 per resolution cell at 9 MHz (finite density lowers the ratio by ~1/(2N)); 3 %.
    let (ph, probe) = block(30.0, 0.0, 10.0, 7);
    let fr = render(
        &ph,
        &ph.reference(),
        &probe,
        &tx(9.0),
        &Scanner {
            noise_db: None,
            ..Default::default()
        },
        1,
    )
    .unwrap();
    let (w, h) = (fr.width, fr.height);
    let env: Vec<f64> = (0..w * h)
        .filter(|k| (k % w) > 10 && (k % w) < w - 10 && k / w > 10 && k / w < h - 10)
        .map(|k| fr.envelope[k])
        .collect();
    let (m, s) = femu_ultrasound::stats::mean_sd(&env);
    let rayleigh = (std::f64::consts::PI / 2.0).sqrt() / (2.0 - std::f64::consts::PI / 2.0).sqrt();
    eprintln!(
        "envelope mean/std = {:.4} (Rayleigh {:.4}), {} px, {:.2} s",
        m / s,
        rayleigh,
        env.len(),
        fr.seconds
    );
    assert!((m / s - rayleigh).abs() < 0.03 * rayleigh);
}

#[test]
fn higher_frequency_gives_finer_speckle_and_weaker_texture_at_depth() {
    let (ph, probe) = block(45.0, 0.7, 10.0, 3);
    let st = ph.reference();
    let mut lengths = Vec::new();
    let mut deep = Vec::new();
    for f in [7.0, 13.0] {
        let fr = render(&ph, &st, &probe, &tx(f), &Scanner::default(), 1).unwrap();
        let (w, h) = (fr.width, fr.height);
        let rect = [20, 20, w - 20, 160];
        let ax = correlation_length(&fr.envelope, w, rect, 1).unwrap();
        let lat = correlation_length(&fr.envelope, w, rect, 0).unwrap();
        let tex = texture_by_depth(&fr.image.data, w, h, None, 50).unwrap();
        eprintln!("{f} MHz: speckle half-widths axial {ax:.2} px, lateral {lat:.2} px; texture per 5 mm band {tex:.1?}");
        lengths.push((ax, lat));
        deep.push(tex[tex.len() - 2] / tex[1]);
    }
    assert!(lengths[1].0 < 0.8 * lengths[0].0, "axial {lengths:?}");
    assert!(lengths[1].1 < 0.8 * lengths[0].1, "lateral {lengths:?}");
    assert!(deep[1] < 0.5 * deep[0], "deep / shallow texture {deep:?}");
}

#[test]
fn dic_recovers_a_known_affine_field_from_moved_scatterers() {
    // 3 % axial compression about the probe face plus 0.6 mm lateral shift and a little
    // shear: applied to the scatterers (not to the picture), re-rendered, correlated.
    let (ph, probe) = block(30.0, 0.5, 10.0, 11);
    let top = 40.0;
    let field = move |x: [f64; 2]| [0.6 + 0.01 * (top - x[1]), -0.03 * (top - x[1])];
    let opts = ExperimentOptions::default();
    let t = std::time::Instant::now();
    let exp = experiment::run_analytic(&ph, &field, &probe, &opts).unwrap();
    let e = exp.error;
    eprintln!(
        "affine field, {} points: bias ({:.3}, {:.3}) px, RMS ({:.3}, {:.3}) px = ({:.4}, {:.4}) mm, max ({:.3}, {:.3}) px, largest displacement {:.1} px, {:.1} s",
        e.points, e.bias_px[0], e.bias_px[1], e.rms_px[0], e.rms_px[1], e.rms_mm[0], e.rms_mm[1],
        e.max_abs_px[0], e.max_abs_px[1], e.max_true_px, t.elapsed().as_secs_f64()
    );
    assert!(e.points > 100);
    assert!(e.rms_px[0] < 0.1 && e.rms_px[1] < 0.1);
}
