//! The nodal covariance of `femu_dic::quality` (eq. 4, `C = A⁻¹ M_σ A⁻¹`) against the scatter of
//! the measured displacement over many seeded noise realizations in the virtual lab.
//!
//! Speckle 160 x 160 px (σ = 1.5 px spots), rigid translation (0.3, −0.2) px, white Gaussian
//! noise of 4 grey levels added to both images (new seeds per realization), ROI 96 x 96 px,
//! 16 px elements (49 nodes, 98 unknowns). For each realization the covariance is predicted from
//! that realization alone (its own residual variance and correlation), as `femu dic` does; the
//! empirical standard deviation of each nodal component over the realizations is compared with
//! the mean predicted one. With R realizations the empirical variance has a relative standard
//! error sqrt(2/(R−1)) = 0.13 for R = 120, i.e. ±7 % on the standard deviation per component;
//! averaged over 98 components the ratio is known to ~1 %, so the band 0.85..1.15 tests the
//! formula, not the sampling. Coverage: the fraction of (node, component, realization) errors
//! within ±2 predicted σ, 95.4 % for Gaussian errors.

use femu_dic::lab::{self, Speckle};
use femu_dic::{correlate, quality, DicOptions, Rect, Roi};

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

fn run(reg: Option<f64>) -> (f64, f64, f64) {
    let s = Speckle::new(160, 160, 1.5, 41);
    let u = lab::translation(0.3, -0.2);
    let (f0, g0) = (s.reference(), s.deformed(&u));
    let roi = Roi::Rect(Rect {
        x: 32,
        y: 32,
        w: 96,
        h: 96,
    });
    let opts = DicOptions {
        element_size: 16,
        regularization_length: reg,
        ..Default::default()
    };
    let r_count = 120;
    let mut disp: Vec<Vec<f64>> = Vec::new();
    let mut pred_var: Vec<f64> = Vec::new();
    let mut within = 0usize;
    let mut total = 0usize;
    for k in 0..r_count {
        let f = lab::add_noise(&f0, 4.0, 1000 + 2 * k);
        let g = lab::add_noise(&g0, 4.0, 1001 + 2 * k);
        let res = correlate(&f, &g, &roi, &opts).expect("correlation");
        assert!(res.converged);
        let cov = quality::covariance(&res).unwrap();
        let d: Vec<f64> = res.displacement.iter().flat_map(|v| [v[0], v[1]]).collect();
        let sd: Vec<f64> = cov
            .node
            .iter()
            .flat_map(|n| [n.sd_ux_px, n.sd_uy_px])
            .collect();
        if pred_var.is_empty() {
            pred_var = vec![0.0; d.len()];
        }
        for (i, s) in sd.iter().enumerate() {
            pred_var[i] += s * s / r_count as f64;
            let t = if i % 2 == 0 { 0.3 } else { -0.2 };
            total += 1;
            if (d[i] - t).abs() <= 2.0 * s {
                within += 1;
            }
        }
        disp.push(d);
    }
    let n = pred_var.len();
    let mut ratio = 0.0;
    for i in 0..n {
        let m = disp.iter().map(|d| d[i]).sum::<f64>() / r_count as f64;
        let v = disp.iter().map(|d| (d[i] - m).powi(2)).sum::<f64>() / (r_count - 1) as f64;
        ratio += (v / pred_var[i]).sqrt() / n as f64;
    }
    let mean_pred = (pred_var.iter().sum::<f64>() / n as f64).sqrt();
    (ratio, within as f64 / total as f64, mean_pred)
}

#[test]
fn predicted_nodal_sd_matches_the_scatter_over_noise_realizations() {
    for reg in [None, Some(64.0)] {
        let (ratio, coverage, sd) = run(reg);
        eprintln!(
            "regularization {reg:?}: empirical / predicted nodal sd = {ratio:.3} (mean over 98 components), \
             coverage of ±2σ = {:.1} %, predicted sd {sd:.4} px",
            100.0 * coverage
        );
        let label = match reg {
            None => "no regularization".to_string(),
            Some(l) => format!("regularization length {l} px"),
        };
        measure::record(
            &format!("{label}: empirical / predicted nodal sd, mean over 98 components, 120 realizations"),
            ratio,
            "in [0.85, 1.15)",
            "",
        );
        measure::record(
            &format!("{label}: errors within ±2 predicted σ (Gaussian: 0.954)"),
            coverage,
            "in [0.92, 0.98)",
            "",
        );
        assert!((0.85..1.15).contains(&ratio), "ratio {ratio}");
        assert!((0.92..0.98).contains(&coverage), "coverage {coverage}");
    }
}
