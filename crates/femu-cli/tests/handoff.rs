//! The hand-off from `femu dic` to `femu identify`, end to end on B-mode frames: femu's own
//! simulated cine loop of the compression test (`femu us-sim`, five frames, the skin moving
//! tens of pixels), correlated by `femu dic` as a sequence with its defaults, and its
//! `field.csv` identified through `[measurement] file` and through `--measured` alike.

mod common;
use common::{femu, json, scratch, write};
use std::path::Path;

fn ok(o: &std::process::Output) {
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The identified values and relative sds of a run.
fn estimates(dir: &Path) -> Vec<(String, f64, f64)> {
    json(&dir.join("summary.json"))["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["name"].as_str().unwrap().to_string(),
                p["identified"].as_f64().unwrap(),
                p["relative_sd"].as_f64().unwrap(),
            )
        })
        .collect()
}

/// A sequence's field read by the identification: `# units: mm` declared; the untrusted
/// points (w = 0) left out, so that the same file with those rows removed gives the same
/// estimates and intervals, through `[measurement] file` and `--measured` (which honours the
/// study's frame keys); the full covariance with the same points left out; a field in pixels
/// read as mm, and frame keys on a virtual measurement, refused naming the key; a pair with no
/// trusted element an error.
#[test]
fn dic_sequence_field_reaches_identify() {
    let dir = scratch("handoff");
    let sim = dir.join("sim");
    ok(&femu(&["us-sim", "--elements", "700", "--out", s(&sim)]));
    let frames: Vec<String> = (0..5)
        .map(|k| s(&sim.join(format!("frame_{k:02}.png"))).to_string())
        .collect();
    let d = dir.join("dic");
    let mut args: Vec<&str> = vec!["dic"];
    args.extend(frames.iter().map(String::as_str));
    args.extend(["--pixel-size", "0.1", "--out", s(&d)]);
    ok(&femu(&args));
    let text = std::fs::read_to_string(d.join("field.csv")).unwrap();
    assert!(text.starts_with("# units: mm\n"), "{}", &text[..80]);
    assert!(text.contains("\nx,y,ux,uy,sx,sy,w\n"));
    let rows: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    let untrusted = rows[1..].iter().filter(|r| r.ends_with(",0")).count();
    assert!(
        untrusted > 0 && untrusted < rows.len() / 2,
        "{untrusted} untrusted of {}",
        rows.len() - 1
    );
    assert!(d.join("frame_1/field.csv").exists() && d.join("field_covariance.mtx").exists());
    // Composed over a large motion: the largest displacement is tens of pixels (mm / 0.1).
    let umax = rows[1..]
        .iter()
        .map(|r| {
            let c: Vec<f64> = r.split(',').map(|v| v.parse().unwrap()).collect();
            c[2].hypot(c[3]) / 0.1
        })
        .fold(0.0, f64::max);
    assert!(umax > 40.0, "largest composed displacement {umax} px");

    // The image (mm, rows going down) in the model: the probe of us-sim's summary.
    let probe = &json(&sim.join("summary.json"))["probe"];
    let v = |k: &str, i: usize| probe[k][i].as_f64().unwrap();
    let (c, n) = (
        [v("centre_mm", 0), v("centre_mm", 1)],
        [v("direction", 0), v("direction", 1)],
    );
    let t = [-n[1], n[0]];
    let (px, hw) = (0.1, 20.0);
    let origin = [0, 1].map(|i| c[i] + t[i] * (0.5 * px - hw) + 0.5 * px * n[i]);
    let study = |extra: &str| {
        format!(
            "[model]\nelements = 700\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
             [measurement]\nfile = \"{}\"\norigin_mm = [{:?}, {:?}]\nx_axis = [{:?}, {:?}]\n\
             y_axis = [{:?}, {:?}]\n{extra}[identification]\nstarts = 1\ngrouped = true\n\
             discretization = \"off\"\n",
            s(&d.join("field.csv")),
            origin[0],
            origin[1],
            t[0],
            t[1],
            n[0],
            n[1]
        )
    };
    let plain = write(&dir, "plain.toml", &study(""));
    let (i1, i2, i3) = (dir.join("i1"), dir.join("i2"), dir.join("i3"));
    ok(&femu(&["identify", s(&plain), "--out", s(&i1)]));
    let sum = json(&i1.join("summary.json"));
    assert_eq!(
        sum["points_in_tissue"].as_u64().unwrap() as usize,
        rows.len() - 1 - untrusted,
        "the untrusted points are left out"
    );
    ok(&femu(&[
        "identify",
        s(&plain),
        "--measured",
        s(&d.join("field.csv")),
        "--out",
        s(&i2),
    ]));
    let trimmed: String = text
        .lines()
        .filter(|l| !l.ends_with(",0"))
        .map(|l| format!("{l}\n"))
        .collect();
    let trimmed = write(&dir, "trimmed.csv", &trimmed);
    ok(&femu(&[
        "identify",
        s(&plain),
        "--measured",
        s(&trimmed),
        "--out",
        s(&i3),
    ]));
    let (e1, e2, e3) = (estimates(&i1), estimates(&i2), estimates(&i3));
    assert_eq!(e1, e2, "[measurement] file and --measured");
    assert_eq!(e1, e3, "w = 0 rows kept and removed");
    // The quadriceps under the probe: a sane estimate (the truth is 1.75 kPa).
    let q = e1.iter().find(|e| e.0 == "C10_QUADRICEPS").unwrap();
    assert!((q.1 / 1.75e-3 - 1.0).abs() < 0.1, "{q:?}");

    // Weighted by the full covariance, its untrusted rows left out with their points.
    let weighted = write(
        &dir,
        "weighted.toml",
        &study(&format!(
            "covariance = \"{}\"\n",
            s(&d.join("field_covariance.mtx"))
        )),
    );
    let iw = dir.join("iw");
    ok(&femu(&["identify", s(&weighted), "--out", s(&iw)]));

    // The speckle's lateral shift under shear in the measurement model, its scale fitted:
    // read through `[measurement] file` and `--measured` alike, the scale reported. femu's
    // renderer has a Gaussian point-spread function without the lens phase that makes the
    // speckle move, so the scale the field supports is small and the estimates stay sane.
    let speckle = write(
        &dir,
        "speckle.toml",
        &study(
            "speckle_frequency_mhz = 9.0
speckle_resolution_mm = 0.9
",
        ),
    );
    let (is1, is2) = (dir.join("is1"), dir.join("is2"));
    ok(&femu(&["identify", s(&speckle), "--out", s(&is1)]));
    ok(&femu(&[
        "identify",
        s(&speckle),
        "--measured",
        s(&d.join("field.csv")),
        "--out",
        s(&is2),
    ]));
    assert_eq!(
        estimates(&is1),
        estimates(&is2),
        "speckle keys through --measured"
    );
    let shift = &json(&is1.join("summary.json"))["speckle_shift"];
    let kappa = shift["scale"].as_f64().unwrap();
    assert!(
        shift["fitted"].as_bool().unwrap() && kappa.abs() < 0.5,
        "{shift}"
    );
    let sd = shift["scale_sd"].as_f64().unwrap();
    assert!(sd > 0.0 && sd.is_finite(), "{shift}");
    let q = estimates(&is1);
    let q = q.iter().find(|e| e.0 == "C10_QUADRICEPS").unwrap();
    assert!((q.1 / 1.75e-3 - 1.0).abs() < 0.1, "{q:?}");

    // A field in pixels (no pixel size given) read in mm: refused, naming the declaration.
    let dpx = dir.join("dic_px");
    ok(&femu(&[
        "dic",
        &frames[0],
        &frames[1],
        &frames[2],
        "--out",
        s(&dpx),
    ]));
    let o = femu(&[
        "identify",
        s(&plain),
        "--measured",
        s(&dpx.join("field.csv")),
        "--out",
        s(&dir.join("ipx")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("units: px"), "{err}");

    // Frame keys on a virtual measurement would be silently unused: refused.
    let virt = write(
        &dir,
        "virtual.toml",
        "[model]\nelements = 700\n[measurement]\norigin_mm = [1, 2]\n",
    );
    let o = femu(&["identify", s(&virt), "--out", s(&dir.join("iv"))]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("origin_mm"), "{err}");

    // A pair whose field has no trusted element (the last frame against the first, with one
    // long regularization) exits non-zero; the folder is written and says why.
    let d = dir.join("untrusted");
    let o = femu(&[
        "dic",
        &frames[0],
        &frames[4],
        "--element",
        "64",
        "--regularization",
        "512",
        "--out",
        s(&d),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no element of the"),
        "{err}"
    );
    assert!(d.join("elements.csv").exists());
}
