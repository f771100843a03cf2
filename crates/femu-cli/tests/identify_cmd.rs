//! `femu synth` and `femu identify` as a user runs them: a nearly noise-free virtual
//! experiment written to CSV and identified back from it, and the errors of bad input.

mod common;
use common::{femu, scratch, write};

/// Compression on a 700-quad thigh, noise 1e-9 mm, D of ischio, sartorius and gracilis tied:
/// identified back from the CSV to 0.1 % (the noise is far below the model's sensitivity).
#[test]
fn synth_then_identify_recovers_table1() {
    let dir = scratch("roundtrip");
    let study = write(
        &dir,
        "study.toml",
        "[model]\nelements = 700\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
         [noise]\nsigma_mm = 1e-9\n[identification]\nstarts = 2\n",
    );
    let synth = dir.join("synth");
    let o = femu(&[
        "synth",
        study.to_str().unwrap(),
        "--out",
        synth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let measured = synth.join("measured.csv");
    let text = std::fs::read_to_string(&measured).unwrap();
    assert!(text.contains("x,y,ux,uy,sx,sy"));
    let out = dir.join("identify");
    let o = femu(&[
        "identify",
        study.to_str().unwrap(),
        "--measured",
        measured.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let table1 = [
        ("C10_FAT", 0.8e-3),
        ("D_FAT", 30.8),
        ("C10_QUADRICEPS", 1.75e-3),
        ("D_QUADRICEPS", 18.0),
        ("C10_ISCHIO", 3e-3),
        ("D_ISCHIO+D_GRACILIS+D_SARTORIUS", 18.0),
        ("C10_GRACILIS", 2.2e-3),
        ("C10_SARTORIUS", 3.75e-3),
    ];
    let params = s["parameters"].as_array().unwrap();
    assert_eq!(params.len(), table1.len());
    for (p, (name, v)) in params.iter().zip(table1) {
        assert_eq!(p["name"], name);
        let t = p["identified"].as_f64().unwrap();
        assert!(((t - v) / v).abs() < 1e-3, "{name}: {t} vs {v}");
    }
    for n in s["forward_solves_per_start"].as_array().unwrap() {
        assert!(n.as_u64().unwrap() <= 40, "{n} forward solves");
    }
    for f in [
        "parameters.csv",
        "starts.csv",
        "cost_history.png",
        "fields.png",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }

    // The same field as an image-frame CSV (pixels of 0.05 mm, origin at the image's top-left
    // corner at (-80, 70) mm, rows going down) identifies the same parameters through the study
    // file's [measurement] frame.
    let (s_px, origin) = (0.05, [-80.0, 70.0]);
    let mut image = String::from("x,y,ux,uy,sx,sy\n");
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let v: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
        image.push_str(&format!(
            "{:.12e},{:.12e},{:.12e},{:.12e},{:.6e},{:.6e}\n",
            (v[0] - origin[0]) / s_px,
            -(v[1] - origin[1]) / s_px,
            v[2] / s_px,
            -v[3] / s_px,
            v[4] / s_px,
            v[5] / s_px
        ));
    }
    write(&dir, "image.csv", &image);
    let framed = write(
        &dir,
        "framed.toml",
        &format!(
            "{}[measurement]\nfile = \"image.csv\"\nunits = \"px\"\npixel_size_mm = {s_px}\n\
             origin_mm = [{}, {}]\nx_axis = [1.0, 0.0]\ny_axis = [0.0, -1.0]\n",
            std::fs::read_to_string(&study).unwrap(),
            origin[0],
            origin[1]
        ),
    );
    let out2 = dir.join("identify-framed");
    let o = femu(&[
        "identify",
        framed.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out2.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s2["points_in_tissue"], s["points_in_tissue"]);
    for (p, q) in params.iter().zip(s2["parameters"].as_array().unwrap()) {
        let (a, b) = (
            p["identified"].as_f64().unwrap(),
            q["identified"].as_f64().unwrap(),
        );
        assert!(((a - b) / a).abs() < 1e-6, "{}: {a} vs {b}", p["name"]);
    }
}

/// Multilevel: three starts on a coarse (~800-quad) thigh, the best refined on 1 800 quads, noise-free data
/// of the 1 800-quad model: the refined optimum is the fine model's (Table 1 to 1e-4), in a
/// handful of fine forward solves.
#[test]
fn multilevel_identification_refines_on_the_fine_mesh() {
    let dir = scratch("multilevel");
    let study = write(
        &dir,
        "study.toml",
        "[model]\nelements = 1800\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
         [noise]\nsigma_mm = 1e-9\n[identification]\nstarts = 3\ncoarse_elements = 700\n",
    );
    let out = dir.join("identify");
    let o = femu(&[
        "identify",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let coarse = s["coarse_elements"].as_u64().unwrap();
    let fine = s["elements"].as_u64().unwrap();
    assert!(2 * coarse < fine, "{coarse} coarse, {fine} fine elements");
    let refine = s["refinement_forward_solves"][0].as_u64().unwrap();
    assert!(refine <= 15, "{refine} fine forward solves");
    for p in s["parameters"].as_array().unwrap() {
        let e = p["relative_error"].as_f64().unwrap();
        assert!(e < 1e-4, "{}: error {e}", p["name"]);
    }
}

/// The actuator term (`[measurement] travel_sigma_mm`): the plate's travel measured to 1 µm
/// adds information, so no predicted standard deviation grows and the overall stiffness
/// (C10 of the quadriceps, the largest region under the plate) is pinned down better.
#[test]
fn the_travel_term_adds_information() {
    let dir = scratch("travel");
    let base = "[model]\nelements = 700\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
                [grid]\ncounts = [16, 16]\n[identification]\nstarts = 1\n";
    let run = |name: &str, extra: &str| -> serde_json::Value {
        let study = write(&dir, &format!("{name}.toml"), &format!("{base}{extra}"));
        let out = dir.join(name);
        let o = femu(&[
            "identify",
            study.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
    };
    let without = run("without", "");
    let with = run("with", "[measurement]\ntravel_sigma_mm = 0.001\n");
    assert!(without["travel_term"].is_null());
    let t = with["travel_term"][0].as_f64().unwrap();
    assert!(t > 1.0 && t < 20.0, "reference travel {t} mm");
    let sd = |s: &serde_json::Value| -> Vec<f64> {
        s["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["relative_sd"].as_f64().unwrap())
            .collect()
    };
    let (a, b) = (sd(&without), sd(&with));
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(
            *y <= x * 1.01,
            "parameter {k}: sd {x} without, {y} with the travel"
        );
    }
    assert!(
        b.iter().zip(&a).any(|(y, x)| *y < 0.9 * x),
        "the travel pins nothing down: {a:?} vs {b:?}"
    );
    // A measured field without its measured travel is refused, naming the key.
    let bad = write(
        &dir,
        "bad.toml",
        &format!("{base}[measurement]\nfile = \"m.csv\"\ntravel_sigma_mm = 0.01\n"),
    );
    let o = femu(&[
        "identify",
        bad.to_str().unwrap(),
        "--out",
        dir.join("bad").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("travel_mm"));
}

#[test]
fn bad_inputs_are_named() {
    let dir = scratch("bad");
    let study = write(
        &dir,
        "s.toml",
        "[model]\nelements = 700\n[identification]\nstarts = 1\n",
    );
    let nan = write(&dir, "m.csv", "x,y,ux,uy\n0,40,0.1,0.1\n0,41,NaN,0.1\n");
    let o = femu(&[
        "identify",
        study.to_str().unwrap(),
        "--measured",
        nan.to_str().unwrap(),
        "--out",
        dir.join("o1").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("m.csv:3"));
    let fixed = write(
        &dir,
        "f.toml",
        "[model]\nelements = 700\n[identification]\nfixed = [\"C10_BONE\"]\n",
    );
    let o = femu(&[
        "identify",
        fixed.to_str().unwrap(),
        "--out",
        dir.join("o2").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("C10_BONE"));
    let test = write(&dir, "t.toml", "[identification]\ntest = \"stretch\"\n");
    let o = femu(&[
        "identify",
        test.to_str().unwrap(),
        "--out",
        dir.join("o3").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("stretch"));
}

/// Issue 32.6 (and the unit of 32.12): a field that cannot identify the model (all zero) ends
/// with warnings in the console, the summary and the report — parameters at their bounds — and
/// a point repeated in the CSV is refused naming both lines (it weighed 2 500 times and shrank
/// the sd); the console table shows C10 in kPa, D in MPa⁻¹. Before: exit 0, `inf %` and no word.
#[test]
fn unusable_fits_are_warned_and_duplicates_refused() {
    let dir = scratch("unusable");
    let study = write(
        &dir,
        "study.toml",
        "[model]\nelements = 700\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0.1\n\
         [grid]\ncounts = [16, 16]\n[identification]\nstarts = 1\ngrouped = true\n",
    );
    let synth = dir.join("synth");
    let o = femu(&[
        "synth",
        study.to_str().unwrap(),
        "--out",
        synth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(synth.join("measured.csv")).unwrap();
    let rows: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    // Every displacement zero.
    let mut zero = format!("{}\n", rows[0]);
    for r in &rows[1..] {
        let mut c: Vec<&str> = r.split(',').collect();
        c[2] = "0";
        c[3] = "0";
        zero.push_str(&format!("{}\n", c.join(",")));
    }
    write(&dir, "zero.csv", &zero);
    let out = dir.join("zero");
    let o = femu(&[
        "identify",
        study.to_str().unwrap(),
        "--measured",
        dir.join("zero.csv").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: identification:") && err.contains("bound"),
        "{err}"
    );
    assert!(
        err.contains("C10_FAT") && err.contains("kPa") && err.contains("MPa⁻¹"),
        "{err}"
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let warnings = s["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("bound")),
        "{warnings:?}"
    );
    // The same field through femu run: the report says so.
    let run_study = write(
        &dir,
        "run.toml",
        &format!(
            "{}[run]\nsensitivity = false\n[measurement]\nsource = \"file\"\nfile = \"zero.csv\"\n",
            std::fs::read_to_string(&study).unwrap()
        ),
    );
    let run_out = dir.join("run");
    let o = femu(&[
        "run",
        run_study.to_str().unwrap(),
        "--out",
        run_out.to_str().unwrap(),
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(run_out.join("report.html")).unwrap();
    assert!(html.contains("<b>Warning</b>") && html.contains("bound"));
    assert!(html.contains("kPa"));

    // One point repeated: refused with both lines.
    let dup = format!("{}\n{}\n{}\n{}\n", rows[0], rows[1], rows[2], rows[1]);
    write(&dir, "dup.csv", &dup);
    let o = femu(&[
        "identify",
        study.to_str().unwrap(),
        "--measured",
        dir.join("dup.csv").to_str().unwrap(),
        "--out",
        dir.join("dup").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("dup.csv:4") && err.contains("also on line 2"),
        "{err}"
    );
}
