//! DIC Challenge 1.0 images with known answers (`../shared/data/dic-challenge/`, see its README;
//! skipped with a message when absent).
//!
//! - Sample 5: a rigid shift of +0.10 px in x and y between noisy images whose brightness and
//!   contrast also change (mean 97 → 66 grey levels): bias and standard deviation of the nodal
//!   displacements for 8, 16 and 32 px elements; issue 7's target at 16 px is |bias| ≤ 0.01 px
//!   and std ≤ 0.02 px.
//! - Sample 14: a sinusoidal x-displacement of 0.1 px amplitude whose period shrinks along x
//!   (L1, L3, L5 with more noise from L1 to L5), against `command.csv`: the displacement error
//!   along x and the period below which the sinusoid is lost, per element size.

use femu_dic::{correlate, DicOptions, GreyImage, Rect, Roi};
use std::path::PathBuf;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

fn data(sub: &str) -> Option<PathBuf> {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/dic-challenge")
        .join(sub);
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("SKIPPED: shared data not found at {}", d.display());
        None
    }
}

fn open(p: PathBuf) -> GreyImage {
    GreyImage::open(&p, 0).unwrap()
}

#[test]
fn sample5_rigid_shift() {
    let Some(dir) = data("sample5") else { return };
    let f = open(dir.join("reference.tif"));
    let roi = Roi::Rect(Rect {
        x: 32,
        y: 32,
        w: 448,
        h: 448,
    });
    eprintln!("Sample 5 (ROI 448 x 448 px) | image | element | bias x, y | std x, y (px)");
    for (name, shift) in [
        ("shift_x0.00_y0.00.tif", 0.0),
        ("shift_x0.10_y0.10.tif", 0.10),
    ] {
        let g = open(dir.join(name));
        for h in [8usize, 16, 32] {
            let opts = DicOptions {
                element_size: h,
                ..Default::default()
            };
            let res = correlate(&f, &g, &roi, &opts).unwrap();
            assert!(res.converged);
            let (m, s) = femu_dic::output::mean_std(&res.displacement);
            let b = [m[0] - shift, m[1] - shift];
            eprintln!(
                "{name} | {h:2} | {:+.4} {:+.4} | {:.4} {:.4}",
                b[0], b[1], s[0], s[1]
            );
            if shift > 0.0 {
                let bound = |b: &str| {
                    if h == 16 {
                        b.to_string()
                    } else {
                        "not asserted".into()
                    }
                };
                measure::record(
                    &format!("Sample 5, 0.10 px shift, {h} px elements: largest |bias| of x and y"),
                    b[0].abs().max(b[1].abs()),
                    &bound("≤ 0.01"),
                    "px",
                );
                measure::record(
                    &format!("Sample 5, 0.10 px shift, {h} px elements: largest std of x and y"),
                    s[0].max(s[1]),
                    &bound("≤ 0.02"),
                    "px",
                );
            }
            if h == 16 {
                assert!(b[0].abs() <= 0.01 && b[1].abs() <= 0.01, "bias {b:?}");
                assert!(s[0] <= 0.02 && s[1] <= 0.02, "std {s:?}");
            }
        }
    }
}

/// `command.csv`: one row per pixel column, `x, u_L1, strain_L1, u_L3, strain_L3, u_L5, strain_L5`.
fn command(dir: &std::path::Path) -> Vec<[f64; 7]> {
    std::fs::read_to_string(dir.join("command.csv"))
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|t| t.trim().parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4], v[5], v[6]]
        })
        .collect()
}

#[test]
fn sample14_sinusoid_against_command() {
    let Some(dir) = data("sample14") else { return };
    let cmd = command(&dir);
    let f = open(dir.join("reference.tif"));
    let at = |col: usize, x: f64| {
        let i = (x.floor().max(0.0) as usize).min(cmd.len() - 2);
        let t = x - i as f64;
        (1.0 - t) * cmd[i][col] + t * cmd[i + 1][col]
    };
    // Local period of the command from its zero crossings (L1's; all levels share the
    // frequency law): half a period between consecutive crossings.
    let crossings: Vec<f64> = (1..cmd.len())
        .filter(|&i| cmd[i - 1][1] * cmd[i][1] < 0.0)
        .map(|i| i as f64)
        .collect();
    let period_at = |x: f64| {
        let k = crossings
            .iter()
            .position(|&c| c > x)
            .unwrap_or(crossings.len() - 1)
            .max(1);
        2.0 * (crossings[k] - crossings[k - 1])
    };
    let shortest = crossings
        .windows(2)
        .map(|w| 2.0 * (w[1] - w[0]))
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "Sample 14: {} zero crossings in command.csv, shortest period {shortest:.0} px",
        crossings.len()
    );
    let roi = Roi::Rect(Rect {
        x: 16,
        y: 40,
        w: 2016,
        h: 509,
    });
    eprintln!("Sample 14 | level | element | rms error (px) over x < 1024 | over all x | period where the amplitude falls below 50 % (px)");
    let mut rms16 = Vec::new();
    for (level, col) in [("L1", 1usize), ("L3", 3), ("L5", 5)] {
        let g = open(dir.join(format!("{level}.tif")));
        for h in [8usize, 16, 32] {
            // Without regularization, 8 px elements do not converge on this speckle: about 200
            // of the 16 000 nodes, where the texture is weak, cycle by ±2 px. A Tikhonov
            // length of 4 elements (32 px) fixes it; 16 and 32 px elements need none.
            let reg = (h == 8).then_some(32.0);
            let opts = DicOptions {
                element_size: h,
                regularization_length: reg,
                ..Default::default()
            };
            let res = correlate(&f, &g, &roi, &opts).unwrap();
            assert!(res.converged, "{level} {h}: not converged");
            // ux averaged over each column of nodes.
            let m = &res.mesh;
            let mut sum = vec![0.0; m.nx + 1];
            let mut cnt = vec![0usize; m.nx + 1];
            for (n, &(i, _)) in m.node_grid.iter().enumerate() {
                sum[i] += res.displacement[n][0];
                cnt[i] += 1;
            }
            let cols: Vec<(f64, f64, f64)> = (0..=m.nx)
                .map(|i| {
                    let x = m.x0 as f64 - 0.5 + (i * h) as f64;
                    (x, sum[i] / cnt[i] as f64, at(col, x))
                })
                .collect();
            let rms = |sel: &dyn Fn(f64) -> bool| {
                let e: Vec<f64> = cols
                    .iter()
                    .filter(|c| sel(c.0))
                    .map(|c| c.1 - c.2)
                    .collect();
                (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
            };
            let (r_half, r_all) = (rms(&|x| x < 1024.0), rms(&|_| true));
            // Amplitude ratio over windows of 128 px: <u_meas u_cmd> / <u_cmd²>.
            let mut lost = None;
            let mut x0 = m.x0 as f64;
            while x0 + 128.0 <= (m.x0 + m.nx * h) as f64 {
                let w: Vec<&(f64, f64, f64)> = cols
                    .iter()
                    .filter(|c| c.0 >= x0 && c.0 < x0 + 128.0)
                    .collect();
                let num: f64 = w.iter().map(|c| c.1 * c.2).sum();
                let den: f64 = w.iter().map(|c| c.2 * c.2).sum();
                // Only windows where the command has amplitude (rms > 0.05 px) can tell.
                let strong = den / w.len().max(1) as f64 > 0.05f64.powi(2);
                if strong && num / den < 0.5 && lost.is_none() {
                    lost = Some(period_at(x0 + 64.0));
                }
                x0 += 64.0;
            }
            eprintln!(
                "{level} | {h:2}{} | {r_half:.4} | {r_all:.4} | {}",
                if reg.is_some() { " (reg. 32 px)" } else { "" },
                lost.map_or("not lost".to_string(), |p| format!("{p:.0}"))
            );
            measure::record(
                &format!("Sample 14 {level}, {h} px elements: RMS error of u_x over x < 1024 px"),
                r_half,
                if h == 16 { "< 0.03" } else { "not asserted" },
                "px",
            );
            if h == 16 {
                rms16.push(r_half);
            }
        }
    }
    // The periods of this sample are long (620 px and more, 3 zero crossings), so 16 px
    // elements follow the 0.1 px sinusoid everywhere: rms error below 0.03 px (30 % of the
    // amplitude; measured 0.005-0.007) for every noise level.
    assert!(rms16.iter().all(|&r| r < 0.03), "{rms16:?}");
}
