//! An independent second opinion on femu-dic's fields from real frames (issue 31): every
//! consecutive pair of the shared GE Logiq E9 frames correlated by femu-dic with its defaults
//! and by a public implementation of another method, scikit-image's iterative Lucas–Kanade
//! optical flow (`optical_flow_ilk`, Gaussian window of radius 16 px, coarse-to-fine;
//! `bench/lk_real.py`), compared at femu-dic's trusted nodes.
//!
//! What the comparison may show and why (the numbers measured are in the assertions' comments):
//!
//! - femu-dic's nodal sd (`quality::covariance`) is the random error of *its* field, which the
//!   128 px regularization makes small (0.05 px); Lucas–Kanade has no regularization, and its
//!   random error is that of an unregularized correlation with a window of about 33 px, bounded
//!   above by femu-dic's predicted sd of an unregularized Q4 field with its 16 px elements
//!   (`quality::covariance_unregularized`, 0.4–0.8 px along x). Differences are compared with
//!   the combined sd `sqrt(sd_femu² + sd_unreg²)`.
//! - Half of the raw difference is scale: seen at the same scale (the Lucas–Kanade field
//!   smoothed by a Gaussian of σ = ℓ/4 inside the ROI, ℓ femu-dic's regularization length),
//!   pair 048 → 050 agrees to RMS (0.38, 0.08) px instead of (0.67, 0.12).
//! - What is left beyond that is bias of one method or the other where the images do not
//!   follow the tissue: the middle and deep bands in the fast phase of the jump (050 → 058,
//!   x RMS 0.9–4.5 px at the same scale), below the deep aponeurosis where the soleus slides
//!   under the gastrocnemius (a displacement jump a continuous Q4 field smooths over) and
//!   where femu-dic's own composition check fails too (`tests/ultrasound.rs`, deep band RMS
//!   1.96 px along x). femu-dic's trust mask does not catch these places (their ZNCC is as high
//!   as elsewhere: medians 0.64–0.86 against 0.73–0.86), so its nodal sd is not an error bar
//!   there: it is the random error of the regularized field only.
//!
//! Skipped with a message when the frames or a Python with scikit-image, SciPy and Pillow are
//! absent (`.ci/run` installs them; `FEMU_PYTHON` chooses the interpreter).

use femu_dic::auto::Setting;
use femu_dic::command::{CorrelationSpec, RoiSpec};
use femu_dic::quality::{self, TrustCriteria};
use femu_dic::{DicOptions, GreyImage, Rect};
use std::path::PathBuf;
use std::process::Command;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

fn frames_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ultrasound/logiq-e9-gastrocnemius")
}

/// A Python that has what `bench/lk_real.py` imports, or `None` with the reason printed.
fn python() -> Option<String> {
    let py = std::env::var("FEMU_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args([
            "-c",
            "import skimage.registration, scipy.ndimage, PIL, numpy",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!(
            "SKIPPED: {py} cannot import scikit-image, SciPy, Pillow and NumPy (pip install scikit-image pillow)"
        );
        return None;
    }
    Some(py)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn median_abs(v: &[f64]) -> f64 {
    let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
    a.sort_by(|p, q| p.total_cmp(q));
    a.get(a.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The comparison of one pair over the trusted nodes, per depth band (superficial, middle,
/// deep) and in all.
#[derive(Debug, Default)]
struct PairComparison {
    /// Differences femu − LK (x, y) per band (px).
    dx: [Vec<f64>; 3],
    dy: [Vec<f64>; 3],
    /// Components within 2 combined sd, and within 2 femu sd, of all components.
    within_combined: usize,
    within_femu: usize,
    components: usize,
    sd_femu: Vec<[f64; 2]>,
    sd_unreg: Vec<[f64; 2]>,
    /// Differences femu − LK smoothed to femu-dic's scale (x, y) per band (px).
    sx: [Vec<f64>; 3],
    sy: [Vec<f64>; 3],
}

impl PairComparison {
    fn all(v: &[Vec<f64>; 3]) -> Vec<f64> {
        v.iter().flatten().copied().collect()
    }
}

fn compare(py: &str, k: usize, names: &[PathBuf], out: &std::path::Path) -> PairComparison {
    let spec = CorrelationSpec {
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
    };
    let f = GreyImage::open(&names[k], 0).unwrap();
    let g = GreyImage::open(&names[k + 1], 0).unwrap();
    let (m, choice) = spec.measure(&f, &g).unwrap();
    let unreg = quality::covariance_unregularized(&m.res).unwrap();
    let w = femu_dic::output::node_weights(&m.res, &m.trust);
    let trusted: Vec<usize> = (0..m.res.mesh.nodes.len()).filter(|&q| w[q] > 0).collect();
    let nodes = out.join(format!("nodes_{k}.json"));
    let xs: Vec<f64> = trusted.iter().map(|&q| m.res.mesh.nodes[q][0]).collect();
    let ys: Vec<f64> = trusted.iter().map(|&q| m.res.mesh.nodes[q][1]).collect();
    std::fs::write(&nodes, serde_json::json!({"x": xs, "y": ys}).to_string()).unwrap();
    let flow = out.join(format!("lk_{k}.json"));
    let mesh = &m.res.mesh;
    let mesh_rect = [
        mesh.x0,
        mesh.y0,
        mesh.x0 + mesh.nx * mesh.h,
        mesh.y0 + mesh.ny * mesh.h,
    ];
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bench/lk_real.py");
    let o = Command::new(py)
        .arg(&script)
        .args([&names[k], &names[k + 1]])
        // Window radius 16 px (about femu-dic's 16 px elements' support); the smoothed copy at
        // σ = ℓ/4 of femu-dic's regularization length ℓ (128 px here), which passes the long
        // waves femu-dic keeps and damps the short ones it regularizes away.
        .arg("16")
        .arg(format!(
            "{}",
            0.25 * choice
                .regularization_px
                .unwrap_or(2.0 * choice.element_size_px as f64)
        ))
        .arg(format!(
            "{},{},{},{}",
            mesh_rect[0], mesh_rect[1], mesh_rect[2], mesh_rect[3]
        ))
        .args([&nodes, &flow])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "lk_real.py: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let lk: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&flow).unwrap()).unwrap();
    let col = |name: &str| -> Vec<f64> {
        lk[name]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (lx, ly) = (col("ux"), col("uy"));
    let (sx, sy) = (col("ux_smooth"), col("uy_smooth"));
    let (y0, y1) = (mesh.y0 as f64, (mesh.y0 + mesh.ny * mesh.h) as f64);
    let mut c = PairComparison::default();
    for (i, &q) in trusted.iter().enumerate() {
        let d = [
            m.res.displacement[q][0] - lx[i],
            m.res.displacement[q][1] - ly[i],
        ];
        let s = m.cov.node[q];
        let su = unreg.node[q];
        let band = (((mesh.nodes[q][1] - y0) / (y1 - y0) * 3.0).floor() as usize).min(2);
        c.dx[band].push(d[0]);
        c.dy[band].push(d[1]);
        let sf = [s.sd_ux_px, s.sd_uy_px];
        let sc = [s.sd_ux_px.hypot(su.sd_ux_px), s.sd_uy_px.hypot(su.sd_uy_px)];
        for a in 0..2 {
            c.components += 1;
            c.within_femu += (d[a].abs() <= 2.0 * sf[a]) as usize;
            c.within_combined += (d[a].abs() <= 2.0 * sc[a]) as usize;
        }
        c.sx[band].push(m.res.displacement[q][0] - sx[i]);
        c.sy[band].push(m.res.displacement[q][1] - sy[i]);
        c.sd_femu.push(sf);
        c.sd_unreg.push([su.sd_ux_px, su.sd_uy_px]);
    }
    c
}

#[test]
fn femu_dic_agrees_with_lucas_kanade_on_the_logiq_e9_frames() {
    let dir = frames_dir();
    let names: Vec<PathBuf> = [48, 50, 52, 54, 56, 58]
        .iter()
        .map(|n| dir.join(format!("gastroc_jumping_{n:03}.png")))
        .collect();
    if !names[0].is_file() {
        eprintln!("SKIPPED: shared data not found at {}", dir.display());
        return;
    }
    let Some(py) = python() else { return };
    let out = std::env::temp_dir().join(format!("femu-second-opinion-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    for k in 0..names.len() - 1 {
        let c = compare(&py, k, &names, &out);
        let (ax, ay) = (PairComparison::all(&c.dx), PairComparison::all(&c.dy));
        let (bx, by) = (PairComparison::all(&c.sx), PairComparison::all(&c.sy));
        let srms = |v: &[[f64; 2]], a: usize| rms(&v.iter().map(|s| s[a]).collect::<Vec<_>>());
        let within = c.within_combined as f64 / c.components as f64;
        eprintln!(
            "pair {k}: {} trusted nodes; raw: RMS diff (x, y) ({:.3}, {:.3}) px, median |d| ({:.3}, {:.3}), x RMS per band ({:.3}, {:.3}, {:.3}); femu sd ({:.3}, {:.3}), unregularized sd ({:.3}, {:.3}); within 2 femu sd {:.0} %, within 2 combined sd {:.0} %; same scale: RMS diff ({:.3}, {:.3}) px, median |d| ({:.3}, {:.3}), x RMS per band ({:.3}, {:.3}, {:.3})",
            ax.len(),
            rms(&ax), rms(&ay), median_abs(&ax), median_abs(&ay),
            rms(&c.dx[0]), rms(&c.dx[1]), rms(&c.dx[2]),
            srms(&c.sd_femu, 0), srms(&c.sd_femu, 1), srms(&c.sd_unreg, 0), srms(&c.sd_unreg, 1),
            100.0 * c.within_femu as f64 / c.components as f64,
            100.0 * within,
            rms(&bx), rms(&by), median_abs(&bx), median_abs(&by),
            rms(&c.sx[0]), rms(&c.sx[1]), rms(&c.sx[2]),
        );
        // Measured (2026-11-25): within 2 combined sd 90, 79, 78, 74, 87 % of the components
        // of pairs 0-4; the rest is the bias discussed in the module documentation.
        let pair = format!("{:03} → {:03}", 48 + 2 * k, 50 + 2 * k);
        measure::record(
            &format!(
                "pair {pair} ({} trusted nodes): components within 2 combined sd of Lucas–Kanade",
                ax.len()
            ),
            within,
            "≥ 0.7",
            "",
        );
        measure::record(
            &format!("pair {pair}, same scale, superficial band: lateral RMS difference"),
            rms(&c.sx[0]),
            "< 1.2",
            "px",
        );
        measure::record(
            &format!("pair {pair}, same scale, superficial band: axial RMS difference"),
            rms(&c.sy[0]),
            "< 0.5",
            "px",
        );
        if k == 0 {
            measure::record(
                &format!("pair {pair}, same scale, whole ROI: lateral RMS difference"),
                rms(&bx),
                "< 0.6",
                "px",
            );
            measure::record(
                &format!("pair {pair}, same scale, whole ROI: axial RMS difference"),
                rms(&by),
                "< 0.15",
                "px",
            );
        }
        assert!(within >= 0.7, "pair {k}: {:.0} %", 100.0 * within);
        // Seen at the same scale, the superficial band (gastrocnemius under the superficial
        // aponeurosis, best texture) agrees in every pair: measured x RMS 0.30, 0.52, 0.45,
        // 0.92, 0.34 px (raw 0.59, 0.95, 0.94, 1.34, 0.85 px); y over the whole ROI at most
        // 0.33 px.
        assert!(rms(&c.sx[0]) < 1.2, "pair {k}: {:.3}", rms(&c.sx[0]));
        assert!(rms(&c.sy[0]) < 0.5, "pair {k}: {:.3}", rms(&c.sy[0]));
        if k == 0 {
            // The slow phase (048 -> 050, 3 px mean motion) agrees over the whole ROI: measured
            // RMS (0.38, 0.08) px at the same scale, medians (0.17, 0.04) px.
            assert!(
                rms(&bx) < 0.6 && rms(&by) < 0.15,
                "{:.3} {:.3}",
                rms(&bx),
                rms(&by)
            );
        }
    }
    let _ = std::fs::remove_dir_all(&out);
}
