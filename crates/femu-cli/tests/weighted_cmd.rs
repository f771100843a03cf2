//! Weighted FEMU through the command line: `femu identify --measured FILE` with the field's
//! full covariance named by `[measurement] covariance`, and with the error estimated from the
//! residuals (`[measurement] weighting = "estimated"`).

mod common;
use common::{femu, json, scratch, write};

/// Correlated noise along the point order, AR(1) per component: `e_k = ρ e_(k−1) + σ √(1−ρ²) z_k`
/// (stationary variance σ², covariance σ² ρ^|i−j|), from a seeded Box–Muller on a 64-bit LCG.
fn ar1_noise(n: usize, sigma: f64, rho: f64, seed: u64) -> Vec<f64> {
    let mut state = seed;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut e = Vec::with_capacity(n);
    let mut prev = 0.0;
    for k in 0..n {
        let z = (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
        prev = if k == 0 {
            sigma * z
        } else {
            rho * prev + sigma * (1.0 - rho * rho).sqrt() * z
        };
        e.push(prev);
    }
    e
}

/// A 700-quad compression field on an 12 x 12 grid with AR(1) noise (σ = 5 µm, ρ = 0.9 between
/// consecutive points, per component) and that covariance as a Matrix Market file: the weighted
/// fit runs through `--measured`, whitens by it (its misfit χ² is near its degrees of freedom,
/// where the file's one-σ weights of 1e-9 mm would give ~1e7 times more), recovers
/// C10_QUADRICEPS and covers it; a covariance of another point count is refused naming both
/// files before anything is solved.
#[test]
fn identify_measured_with_a_covariance_file() {
    let dir = scratch("weighted");
    let base = "[model]\nelements = 700\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
                [grid]\ncounts = [12, 12]\n[noise]\nsigma_mm = 1e-9\n\
                [identification]\nstarts = 2\ngrouped = true\n";
    let study = write(&dir, "study.toml", base);
    let synth = dir.join("synth");
    let o = femu(&[
        "synth",
        study.to_str().unwrap(),
        "--out",
        synth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(synth.join("measured.csv")).unwrap();
    let header = text
        .lines()
        .find(|l| !l.starts_with('#'))
        .unwrap()
        .to_string();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    let n = rows.len();
    assert!(n > 20, "{n} points in the tissue");
    let (sigma, rho) = (0.005, 0.9);
    let ex = ar1_noise(n, sigma, rho, 11);
    let ey = ar1_noise(n, sigma, rho, 12);
    let mut noisy = format!("{header}\n");
    for (k, r) in rows.iter().enumerate() {
        let mut r = r.clone();
        r[2] += ex[k];
        r[3] += ey[k];
        let cells: Vec<String> = r.iter().map(|v| format!("{v:.12e}")).collect();
        noisy.push_str(&format!("{}\n", cells.join(",")));
    }
    write(&dir, "noisy.csv", &noisy);
    // Dense symmetric Matrix Market, [ux, uy] per point, lower triangle column by column.
    let mtx = |points: usize| {
        let m = 2 * points;
        let mut s = format!("%%MatrixMarket matrix array real symmetric\n{m} {m}\n");
        for j in 0..m {
            for i in j..m {
                let v = if i % 2 == j % 2 {
                    sigma * sigma * rho.powi(((i / 2) as i32 - (j / 2) as i32).abs())
                } else {
                    0.0
                };
                s.push_str(&format!("{v:.12e}\n"));
            }
        }
        s
    };
    write(&dir, "cov.mtx", &mtx(n));
    write(&dir, "cov_short.mtx", &mtx(n - 1));
    let weighted =
        |cov: &str| format!("{base}[measurement]\nfile = \"noisy.csv\"\ncovariance = \"{cov}\"\n");
    let w_study = write(&dir, "weighted.toml", &weighted("cov.mtx"));
    let out = dir.join("w");
    let o = femu(&[
        "identify",
        w_study.to_str().unwrap(),
        "--measured",
        dir.join("noisy.csv").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("interval widths on the measured field"),
        "{err}"
    );
    let s = json(&out.join("summary.json"));
    // Whitened: 2·cost ~ χ²(ν), ν = 2n − 8; its sd is √(2ν) ~ 20 for ~100 points: a factor 3
    // either way is far outside it and far from the one-σ misfit (σ = 1e-9 mm: ~1e13).
    let nu = (2 * n - 8) as f64;
    let chi2 = 2.0 * s["best_cost"].as_f64().unwrap();
    assert!(chi2 > nu / 3.0 && chi2 < 3.0 * nu, "χ² {chi2}, ν {nu}");
    let params = s["parameters"].as_array().unwrap();
    let q = params
        .iter()
        .find(|p| p["name"] == "C10_QUADRICEPS")
        .unwrap();
    let t = q["identified"].as_f64().unwrap();
    // 5 µm noise on displacements of ~1 mm: the quadriceps' C10 to a few per cent (its Fisher
    // sd here is ~1 %); 5 % leaves room for a 3-sd draw.
    assert!((t / 1.75e-3 - 1.0).abs() < 0.05, "C10_QUADRICEPS {t}");
    let ci = q["ci95"].as_array().unwrap();
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    assert!(lo <= 1.75e-3 && 1.75e-3 <= hi, "[{lo}, {hi}]");
    assert!(q["birge_ratio"].as_f64().is_some() && q["width_from"].as_str().is_some());

    let bad = write(&dir, "bad.toml", &weighted("cov_short.mtx"));
    let o = femu(&[
        "identify",
        bad.to_str().unwrap(),
        "--measured",
        dir.join("noisy.csv").to_str().unwrap(),
        "--out",
        dir.join("bad").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("cov_short.mtx") && err.contains("noisy.csv") && err.contains("points"),
        "{err}"
    );

    // Without the covariance file, `weighting = "estimated"` finds the noise from the residuals
    // of a first fit: its sd within a factor 2 of the 5 µm drawn (~100 points of AR(1) noise whose
    // correlation follows the point order, not the distance: the model's exponential is an
    // approximation), the quadriceps' C10 inside its interval.
    let e_study = write(
        &dir,
        "estimated.toml",
        &format!("{base}[measurement]\nfile = \"noisy.csv\"\nweighting = \"estimated\"\n"),
    );
    let out = dir.join("e");
    let o = femu(&[
        "identify",
        e_study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("stage 2 of 2"), "{err}");
    let s = json(&out.join("summary.json"));
    assert_eq!(s["weighting"], "covariance and estimated error");
    for c in s["error_model"]["components"].as_array().unwrap() {
        for sd in c["sd_mm"].as_array().unwrap() {
            let sd = sd.as_f64().unwrap();
            assert!(sd > 0.0025 && sd < 0.01, "band sd {sd} mm for 0.005 drawn");
        }
    }
    let q = s["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "C10_QUADRICEPS")
        .unwrap()
        .clone();
    let ci = q["ci95"].as_array().unwrap();
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    assert!(lo <= 1.75e-3 && 1.75e-3 <= hi, "[{lo}, {hi}]");
}
