//! Benchmark: a 1024 x 1024 speckle pair (virtual lab, 8-bit) with 16 px elements over a
//! 960 x 960 px ROI (60 x 60 elements), measured by femu-dic and, side by side in the same run,
//! by muDIC (Python, global Q4) on the same images and the same mesh.
//!
//! `cargo run --release -p femu-dic --example bench_dic -- [--python PYTHON] [--repeat N] [--out DIR]`
//!
//! Without `--python` only femu-dic runs. The muDIC script is `crates/femu-dic/bench/mudic_bench.py`
//! (`pip install mudic pillow` in a venv). Reports the wall times, their ratio, the nodal error
//! of each against the known field, and femu-dic's peak memory (VmHWM of this process).

use femu_dic::lab::{self, Speckle};
use femu_dic::{correlate, DicOptions, Rect, Roi};
use std::path::PathBuf;
use std::time::Instant;

fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let l = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = l.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let python = opt("--python");
    let repeat: usize = opt("--repeat").map(|v| v.parse()).transpose()?.unwrap_or(5);
    let out = PathBuf::from(opt("--out").unwrap_or_else(|| "target/bench-dic".into()));
    std::fs::create_dir_all(&out)?;

    // The known field: translation + small affine part about the image centre.
    let (ux, uy) = (0.35, -0.45);
    let g = [[0.002, 0.001], [-0.0015, 0.0025]];
    let c = [512.0, 512.0];
    let field = lab::affine([ux, uy], g, c);
    let t = Instant::now();
    let s = Speckle::new(1024, 1024, 1.5, 2024);
    let f = lab::quantize_8bit(&s.reference());
    let d = lab::quantize_8bit(&s.deformed(&field));
    let (pf, pd) = (out.join("ref.png"), out.join("def.png"));
    f.save_png(&pf)?;
    d.save_png(&pd)?;
    // Re-read the PNGs so that both tools see exactly the same 8-bit data.
    let f = femu_dic::GreyImage::open(&pf, 0)?;
    let d = femu_dic::GreyImage::open(&pd, 0)?;
    println!(
        "images 1024 x 1024 written in {:.2} s ({})",
        t.elapsed().as_secs_f64(),
        out.display()
    );

    let roi_rect = Rect {
        x: 32,
        y: 32,
        w: 960,
        h: 960,
    };
    let roi = Roi::Rect(roi_rect);
    let opts = DicOptions {
        element_size: 16,
        ..Default::default()
    };
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        let r = correlate(&f, &d, &roi, &opts)?;
        times.push(t.elapsed().as_secs_f64());
        last = Some(r);
    }
    let r = last.expect("at least one run");
    times.sort_by(|a, b| a.total_cmp(b));
    let errs: Vec<[f64; 2]> = r
        .mesh
        .nodes
        .iter()
        .zip(&r.displacement)
        .map(|(p, u)| {
            let t = lab::DisplacementField::at(&field, p[0], p[1]);
            [u[0] - t[0], u[1] - t[1]]
        })
        .collect();
    let (b, sd) = femu_dic::output::mean_std(&errs);
    let rms = (errs.iter().map(|e| e[0] * e[0] + e[1] * e[1]).sum::<f64>()
        / (2.0 * errs.len() as f64))
        .sqrt();
    println!(
        "femu-dic: {} elements, {} nodes, {} iterations; wall best {:.3} s, median {:.3} s (of {}); \
         setup {:.3} s, iterations {:.3} s; nodal error rms {:.5} px, bias ({:+.5}, {:+.5}), std ({:.5}, {:.5}); peak RSS {:.0} MB",
        r.mesh.n_elements(),
        r.mesh.n_nodes(),
        r.iterations,
        times[0],
        times[times.len() / 2],
        times.len(),
        r.timings.setup_s,
        r.timings.iterations_s,
        rms,
        b[0],
        b[1],
        sd[0],
        sd[1],
        peak_rss_mb().unwrap_or(f64::NAN)
    );
    let mut report = serde_json::json!({
        "femu_dic": {"wall_best_s": times[0], "wall_median_s": times[times.len() / 2], "runs": times.len(),
            "iterations": r.iterations, "nodes": r.mesh.n_nodes(), "rms_error_px": rms,
            "bias_px": b, "std_px": sd, "peak_rss_mb": peak_rss_mb()},
    });
    if let Some(py) = python {
        let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bench/mudic_bench.py");
        let o = std::process::Command::new(&py)
            .arg(&script)
            .args([pf.to_str().unwrap(), pd.to_str().unwrap()])
            .args([roi_rect.x, roi_rect.y, roi_rect.w, roi_rect.h, 16].map(|v| v.to_string()))
            .args([ux, uy, g[0][0], g[0][1], g[1][0], g[1][1], c[0], c[1]].map(|v| v.to_string()))
            .output()?;
        let stdout = String::from_utf8_lossy(&o.stdout);
        let line = stdout.lines().rev().find(|l| l.starts_with('{'));
        match (o.status.success(), line) {
            (true, Some(l)) => {
                let m: serde_json::Value = serde_json::from_str(l)?;
                let tm = m["wall_s"].as_f64().unwrap_or(f64::NAN);
                println!("muDIC: {l}");
                println!(
                    "ratio muDIC / femu-dic wall time: {:.1}x (best femu-dic run); accuracy rms {:.5} px (femu-dic) vs {:.5} px (muDIC)",
                    tm / times[0],
                    rms,
                    m["rms_error_px"].as_f64().unwrap_or(f64::NAN)
                );
                report["mudic"] = m;
                report["ratio"] = serde_json::json!(tm / times[0]);
            }
            _ => {
                eprintln!(
                    "muDIC failed: {}\n{}",
                    o.status,
                    String::from_utf8_lossy(&o.stderr)
                );
                report["mudic_error"] = serde_json::json!(String::from_utf8_lossy(&o.stderr));
            }
        }
    }
    std::fs::write(
        out.join("bench.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    Ok(())
}
