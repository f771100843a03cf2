//! `femu run` on a study with a sliding `[[interface]]`: the thigh's mesh is split along the
//! QUADRICEPS–ISCHIO boundary and the compression test is solved with the contact; a sliding
//! interface changes the solution, and errors name the table.

use std::path::PathBuf;
use std::process::Output;

mod common;
use common::{femu, json, scratch, Scratch};

const BASE: &str = r#"
[model]
elements = 700
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[run]
sensitivity = false
identification = false
"#;

fn run(study: &str, name: &str) -> (Output, PathBuf, Scratch) {
    let dir = scratch(name);
    let path = dir.join("study.toml");
    std::fs::write(&path, study).unwrap();
    let out = dir.join("out");
    let o = femu(&[
        "run",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    (o, out, dir)
}

#[test]
fn a_study_with_a_frictionless_interface_runs() {
    let sliding = format!(
        "{BASE}[[interface]]\nbetween = [\"QUADRICEPS\", \"ISCHIO\"]\nkind = \"frictionless\"\n"
    );
    let (o, out, _s) = run(&sliding, "iface-sliding");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = json(&out.join("summary.json"));
    let comp = &s["forward"]["compression-anterior"];
    assert_eq!(comp["status"], "converged", "{comp}");
    let f = comp["rigid_bodies"][0]["force_n_per_mm"].as_f64().unwrap();
    // Force control: the plate's force is the prescribed one to the solver's tolerance.
    assert!((f - 0.1).abs() < 1e-8, "plate force {f}");
    assert!(out.join("report.html").exists());

    // The tied model: the same study without the interface; the plate travels less when the
    // quadriceps cannot slide over the ischio-jambiers (a stiffer assembly).
    let (o, tied, _t) = run(BASE, "iface-tied");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t = json(&tied.join("summary.json"));
    let travel = |c: &serde_json::Value| c["rigid_bodies"][0]["travel_mm"].as_f64().unwrap();
    let (a, b) = (travel(comp), travel(&t["forward"]["compression-anterior"]));
    assert!(
        a.abs() > b.abs() * (1.0 + 1e-6),
        "sliding {a} mm, tied {b} mm"
    );
}

#[test]
fn a_bad_interface_is_an_error_naming_the_table() {
    let bad = format!(
        "{BASE}[[interface]]\nbetween = [\"QUADRICEPS\", \"GLUTEUS\"]\nkind = \"frictionless\"\n"
    );
    let (o, _, _s) = run(&bad, "iface-bad-region");
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("[[interface]]") && e.contains("GLUTEUS"), "{e}");
    let bad =
        format!("{BASE}[[interface]]\nbetween = [\"QUADRICEPS\", \"ISCHIO\"]\nkind = \"glued\"\n");
    let (o, _, _s) = run(&bad, "iface-bad-kind");
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("[[interface]] number 1") && e.contains("kind"),
        "{e}"
    );
}
