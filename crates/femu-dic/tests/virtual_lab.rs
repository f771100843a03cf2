//! Virtual-lab verification: synthetic speckle warped by known fields (module `lab`), measured
//! by the global Q4 DIC and scored node by node against the exact displacement.

use femu_dic::lab::{self, DisplacementField, Speckle};
use femu_dic::{correlate, DicOptions, GreyImage, Rect, Roi};

/// Bias (mean error) and standard deviation of the nodal error, per component.
fn score(res: &femu_dic::DicResult, u: &dyn DisplacementField) -> ([f64; 2], [f64; 2]) {
    let n = res.displacement.len() as f64;
    let mut mean = [0.0; 2];
    let errs: Vec<[f64; 2]> = res
        .mesh
        .nodes
        .iter()
        .zip(&res.displacement)
        .map(|(p, d)| {
            let t = u.at(p[0], p[1]);
            [d[0] - t[0], d[1] - t[1]]
        })
        .collect();
    for e in &errs {
        mean[0] += e[0] / n;
        mean[1] += e[1] / n;
    }
    let mut var = [0.0; 2];
    for e in &errs {
        var[0] += (e[0] - mean[0]).powi(2) / n;
        var[1] += (e[1] - mean[1]).powi(2) / n;
    }
    (mean, [var[0].sqrt(), var[1].sqrt()])
}

fn run(f: &GreyImage, g: &GreyImage, roi: Rect, h: usize) -> femu_dic::DicResult {
    let opts = DicOptions {
        element_size: h,
        ..Default::default()
    };
    correlate(f, g, &Roi::Rect(roi), &opts).expect("correlation")
}

#[test]
fn translation_sub_pixel() {
    let s = Speckle::new(256, 256, 1.5, 11);
    let f = s.reference();
    let u = lab::translation(0.35, -0.62);
    let g = s.deformed(&u);
    let t = std::time::Instant::now();
    let res = run(
        &f,
        &g,
        Rect {
            x: 32,
            y: 32,
            w: 192,
            h: 192,
        },
        16,
    );
    let (b, sd) = score(&res, &u);
    eprintln!(
        "translation: bias {b:?} std {sd:?} its {} {:?} {:?}",
        res.iterations,
        t.elapsed(),
        res.levels
    );
    assert!(res.converged);
    assert!(b[0].abs() < 0.005 && b[1].abs() < 0.005, "bias {b:?}");
    assert!(sd[0] < 0.01 && sd[1] < 0.01, "std {sd:?}");
}
