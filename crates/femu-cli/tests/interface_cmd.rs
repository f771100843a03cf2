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

/// The identification on a thigh whose quadriceps slides on the hamstrings: the virtual data
/// made on a mesh with the element size halved (`data_refinement = 2`, the split thigh of that
/// mesh), C10 and D of fat and quadriceps identified with the sliding model; the model folder
/// shows the mesh as solved (split: `mesh.vtu` has the duplicated nodes) and the picture of
/// its regions draws the interface.
#[test]
fn a_study_with_a_sliding_interface_identifies_and_shows_the_split() {
    let study = r#"
[model]
elements = 700
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[[interface]]
between = ["QUADRICEPS", "ISCHIO"]
kind = "frictionless"
[identification]
grouped = true
starts = 1
discretization = "off"
data_refinement = 2
fixed = ["C10_ISCHIO", "C10_SARTORIUS", "C10_GRACILIS", "D_ISCHIO", "D_SARTORIUS", "D_GRACILIS"]
[run]
sensitivity = false
"#;
    let (o, out, _s) = run(study, "iface-identify");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = json(&out.join("identify/grouped/summary.json"));
    let params = s["parameters"].as_array().unwrap();
    let names: Vec<&str> = params.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        ["C10_FAT", "D_FAT", "C10_QUADRICEPS", "D_QUADRICEPS"],
        "{s}"
    );
    // The data's finer mesh biases the 700-element fit (the discretization check is off):
    // measured 5.5 %, 29 %, 0.7 % and 2.1 % (release, seed 1); the bounds leave room for the
    // solver's last digits and would catch a fit of the wrong model (the tied thigh on these
    // data: 35 %, 192 %, 7.9 % and 45 %).
    for (p, bound) in params.iter().zip([0.15, 0.8, 0.03, 0.15]) {
        let e = p["relative_error"].as_f64().unwrap();
        assert!(e.abs() < bound, "{}: error {e}", p["name"]);
    }

    // The model folder: the meshed thigh's nodes, and mesh.vtu with the interface's copies.
    let meshed = json(&out.join("model/summary.json"))["nodes"]
        .as_u64()
        .unwrap();
    let vtu = std::fs::read_to_string(out.join("model/mesh.vtu")).unwrap();
    let points: u64 = vtu
        .split("NumberOfPoints=\"")
        .nth(1)
        .and_then(|t| t.split('"').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert!(points > meshed, "mesh.vtu {points} points, meshed {meshed}");
    // The summary gives both counts: the meshed thigh's and the model's as solved.
    let solved = json(&out.join("model/summary.json"))["nodes_as_solved"]
        .as_u64()
        .unwrap();
    assert_eq!(solved, points, "nodes_as_solved against mesh.vtu");
    // The same study tied: its picture is the meshed thigh's; the sliding one's draws the
    // interface (and says the split in its title), so the two differ.
    let tied_study = study.replace("kind = \"frictionless\"", "kind = \"tied\"");
    let (o, tied, _t) = run(&tied_study, "iface-identify-tied");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let tied_vtu = std::fs::read_to_string(tied.join("model/mesh.vtu")).unwrap();
    assert!(tied_vtu.contains(&format!("NumberOfPoints=\"{meshed}\"")));
    assert_eq!(
        json(&tied.join("model/summary.json"))["nodes_as_solved"].as_u64(),
        Some(meshed),
        "tied: nothing split"
    );
    let png = |d: &PathBuf| std::fs::read(d.join("model/regions.png")).unwrap();
    assert_ne!(png(&out), png(&tied));
}

/// A Gmsh mesh is taken as meshed: a sliding interface on it is refused, naming the table.
#[test]
fn a_gmsh_mesh_refuses_a_sliding_interface() {
    let dir = scratch("iface-gmsh");
    let mesh = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../femu-mesh/tests/data/gmsh_two_surfaces.msh");
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        "element = \"CPE4H\"\n[materials.Fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n\
         [materials.surface_7]\nc10_kpa = 1.75\nd_per_mpa = 18.0\n[[fixed]]\ncurve = \"Bottom\"\n\
         [[pressure]]\ncurve = \"Bottom\"\nmmhg = 20\n\
         [[interface]]\nbetween = [\"Fat\", \"surface_7\"]\nkind = \"frictionless\"\n",
    )
    .unwrap();
    let out = dir.join("out");
    let o = femu(&[
        "solve",
        mesh.to_str().unwrap(),
        "--study",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("[[interface]]") && e.contains("Gmsh mesh is not split"),
        "{e}"
    );
}
