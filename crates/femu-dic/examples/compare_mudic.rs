//! femu-dic against muDIC on the shared GE Logiq E9 frames: every consecutive pair correlated
//! by femu-dic with its defaults (automatic element size and regularization) and by muDIC
//! (global Q4 without regularization, `bench/mudic_real.py`) on the same ROI with 32 px
//! elements (`--mudic-element`; 16 px diverge without regularization), started from
//! femu-dic's FFT integer shift (muDIC has no initializer of its own). The nodal fields are
//! compared over femu-dic's trusted nodes (muDIC's field interpolated there), against femu-dic's nodal standard deviation and
//! against the combined one `sqrt(sd_femu² + sd_unreg²)`, where `sd_unreg` is the predicted
//! scatter of an unregularized Q4 DIC on the same images with femu-dic's elements
//! (`quality::covariance_unregularized`; for muDIC's larger elements an upper bound).
//!
//! `cargo run --release -p femu-dic --example compare_mudic -- --python VENV/bin/python [--roi x,y,w,h] [--out DIR]`
//! (`pip install muDIC==0.2.1 pillow` in the venv). Skips with a message when the frames are absent.
//!
//! `bash bench/dic_real/mudic.sh PYTHON` runs it and keeps `compare.json` with its provenance in
//! `bench/dic_real/results_mudic/`, from which the guide's DIC page is made: without
//! regularization muDIC's nodes run away in the low-texture elements beyond the slow first pair,
//! so the second opinion kept as a test is Lucas–Kanade optical flow (`tests/second_opinion.rs`),
//! which holds on every pair.

use femu_dic::auto::Setting;
use femu_dic::command::{CorrelationSpec, RoiSpec};
use femu_dic::quality::{self, TrustCriteria};
use femu_dic::{DicOptions, GreyImage, Rect};
use std::path::PathBuf;

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let python = opt("--python").ok_or("--python PYTHON (with muDIC) is required")?;
    let roi = Rect::parse(&opt("--roi").unwrap_or_else(|| "144,80,512x416".into()))?;
    let out = PathBuf::from(opt("--out").unwrap_or_else(|| "target/compare-mudic".into()));
    // muDIC's element size: without regularization 16 px elements diverge on these frames
    // (measured: 183 of 891 nodes beyond 20 px on 048 -> 050), so 32 px by default.
    let mu_h: usize = opt("--mudic-element").map_or(Ok(32), |v| v.parse())?;
    std::fs::create_dir_all(&out)?;
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ultrasound/logiq-e9-gastrocnemius");
    let names: Vec<PathBuf> = [48, 50, 52, 54, 56, 58]
        .iter()
        .map(|n| dir.join(format!("gastroc_jumping_{n:03}.png")))
        .collect();
    if !names[0].is_file() {
        eprintln!("SKIPPED: shared data not found at {}", dir.display());
        return Ok(());
    }
    let spec = CorrelationSpec {
        roi: RoiSpec::Rect(roi),
        options: DicOptions {
            acceleration_depth: femu_dic::anderson::DEFAULT_DEPTH,
            ..Default::default()
        },
        element: Setting::Auto,
        regularization: Setting::Auto,
        trust: TrustCriteria::default(),
    };
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bench/mudic_real.py");
    println!("pair | femu-dic (h, l) | muDIC s | trusted nodes | mean diff (x, y) px | RMS diff (x, y) px | femu sd (x, y) | unreg sd (x, y) | within 2 sd_femu | within 2 combined sd | RMS diff per band x (sup, mid, deep)");
    let mut report = Vec::new();
    for k in 0..names.len() - 1 {
        let f = GreyImage::open(&names[k], 0)?;
        let g = GreyImage::open(&names[k + 1], 0)?;
        let (m, choice) = spec.measure(&f, &g)?;
        let unreg = quality::covariance_unregularized(&m.res)?;
        let w = femu_dic::output::node_weights(&m.res, &m.trust);
        let js = out.join(format!("mudic_{k}.json"));
        let o = std::process::Command::new(&python)
            .arg(&script)
            .args([names[k].to_str().unwrap(), names[k + 1].to_str().unwrap()])
            .args([roi.x, roi.y, roi.w, roi.h, mu_h].map(|v| v.to_string()))
            .arg(&js)
            .args([m.res.initial_shift.0, m.res.initial_shift.1].map(|v| v.to_string()))
            .output()?;
        if !o.status.success() {
            return Err(format!("muDIC failed: {}", String::from_utf8_lossy(&o.stderr)).into());
        }
        let mu: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&js)?)?;
        let col = |name: &str| -> Vec<f64> {
            mu[name]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect()
        };
        let (mx, my, mux, muy) = (col("x"), col("y"), col("ux"), col("uy"));
        // muDIC's mesh is femu-dic's structured mesh of the same ROI and element size: its
        // nodes are matched by position (in either axis convention of muDIC's arrays) and its
        // field interpolated at femu-dic's nodes.
        let mu_mesh = femu_dic::DicMesh::new(&femu_dic::Roi::Rect(roi), f.width, f.height, mu_h)?;
        let find = |p: [f64; 2], swap: bool| {
            (0..mx.len()).find(|&i| {
                let (a, b) = if swap { (my[i], mx[i]) } else { (mx[i], my[i]) };
                (a - p[0]).abs() < 0.05 && (b - p[1]).abs() < 0.05
            })
        };
        let swap = find(mu_mesh.nodes[0], false).is_none();
        let mu_u: Vec<[f64; 2]> = mu_mesh
            .nodes
            .iter()
            .map(|p| {
                find(*p, swap).map_or([f64::NAN; 2], |i| {
                    if swap {
                        [muy[i], mux[i]]
                    } else {
                        [mux[i], muy[i]]
                    }
                })
            })
            .collect();
        let yr = [
            m.res.mesh.y0 as f64,
            (m.res.mesh.y0 + m.res.mesh.ny * m.res.mesh.h) as f64,
        ];
        let (mut dx, mut dy, mut n2, mut n2c, mut tot) = (vec![], vec![], 0, 0, 0);
        let mut band: [Vec<f64>; 3] = [vec![], vec![], vec![]];
        let (mut sdf, mut sdu) = (vec![[0.0; 2]; 0], vec![[0.0; 2]; 0]);
        for (q, p) in m.res.mesh.nodes.iter().enumerate() {
            if w[q] == 0 {
                continue;
            }
            let Some([ux, uy]) = mu_mesh.interpolate(&mu_u, p[0], p[1]) else {
                continue;
            };
            if !(ux.is_finite() && uy.is_finite()) {
                continue;
            }
            let d = [m.res.displacement[q][0] - ux, m.res.displacement[q][1] - uy];
            let s = m.cov.node[q];
            let su = unreg.node[q];
            dx.push(d[0]);
            dy.push(d[1]);
            sdf.push([s.sd_ux_px, s.sd_uy_px]);
            sdu.push([su.sd_ux_px, su.sd_uy_px]);
            tot += 2;
            n2 += (d[0].abs() <= 2.0 * s.sd_ux_px) as usize
                + (d[1].abs() <= 2.0 * s.sd_uy_px) as usize;
            n2c += (d[0].abs() <= 2.0 * s.sd_ux_px.hypot(su.sd_ux_px)) as usize
                + (d[1].abs() <= 2.0 * s.sd_uy_px.hypot(su.sd_uy_px)) as usize;
            let b = (((p[1] - yr[0]) / (yr[1] - yr[0]) * 3.0).floor() as usize).min(2);
            band[b].push(d[0]);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let med = |v: &[f64]| {
            let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
            a.sort_by(|p, q| p.total_cmp(q));
            a.get(a.len() / 2).copied().unwrap_or(f64::NAN)
        };
        let srms = |v: &[[f64; 2]], c: usize| rms(&v.iter().map(|a| a[c]).collect::<Vec<_>>());
        println!(
            "{} -> {} | {} px, {:?} px | {:.1} | {} | ({:+.3}, {:+.3}) | ({:.3}, {:.3}) median |d| ({:.3}, {:.3}) | ({:.3}, {:.3}) | ({:.3}, {:.3}) | {:.0} % | {:.0} % | ({:.3}, {:.3}, {:.3})",
            names[k].file_stem().unwrap().to_string_lossy(), names[k + 1].file_stem().unwrap().to_string_lossy(),
            choice.element_size_px, choice.regularization_px, mu["wall_s"].as_f64().unwrap_or(f64::NAN), dx.len(),
            mean(&dx), mean(&dy), rms(&dx), rms(&dy), med(&dx), med(&dy), srms(&sdf, 0), srms(&sdf, 1), srms(&sdu, 0), srms(&sdu, 1),
            100.0 * n2 as f64 / tot.max(1) as f64, 100.0 * n2c as f64 / tot.max(1) as f64,
            rms(&band[0]), rms(&band[1]), rms(&band[2])
        );
        report.push(serde_json::json!({"pair": k, "nodes": dx.len(), "rms_diff_px": [rms(&dx), rms(&dy)],
            "mean_diff_px": [mean(&dx), mean(&dy)], "median_abs_diff_px": [med(&dx), med(&dy)], "mudic_element_px": mu_h, "femu_sd_px": [srms(&sdf, 0), srms(&sdf, 1)],
            "unregularized_sd_px": [srms(&sdu, 0), srms(&sdu, 1)], "within_2sd_femu": n2 as f64 / tot.max(1) as f64,
            "within_2sd_combined": n2c as f64 / tot.max(1) as f64, "mudic_wall_s": mu["wall_s"],
            "rms_diff_x_bands_px": [rms(&band[0]), rms(&band[1]), rms(&band[2])]}));
    }
    std::fs::write(
        out.join("compare.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    Ok(())
}
