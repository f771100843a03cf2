//! `femu mesh thigh3d` and `femu solve` on a 3D deck, through the binary.
//!
//! 1. A slab of the swept thigh whose ends are held along the axis, loaded over its whole
//!    length, is in plane strain: every level of nodes moves alike and nothing moves along the
//!    axis. The deck goes through the writer, the reader and the 3D solve of the command line;
//!    the check is the physics, not a second run of the same code.
//! 2. The 3D output folder: `displacements.csv` with three components per node, the summary's
//!    counts and reactions (the femur's reactions balance the pressure's resultant).
//! 3. Bad inputs: a section too coarse for the thigh, a probe longer than the thigh, a deck
//!    mixing plane-strain and 3D elements.

mod common;
use common::{femu, scratch};
use std::collections::BTreeMap;

/// `node,x,y,z,ux,uy,uz` rows of a 3D `displacements.csv`.
fn rows(text: &str) -> Vec<[f64; 6]> {
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("node,x,y,z,ux,uy,uz"));
    lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').skip(1).map(|s| s.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4], v[5]]
        })
        .collect()
}

#[test]
fn a_plane_strain_slab_solved_from_the_command_line_moves_alike_at_every_level() {
    let dir = scratch("slab");
    let mesh = dir.join("mesh");
    let out = femu(&[
        "mesh",
        "thigh3d",
        "--length",
        "6",
        "--layer",
        "3",
        "--growth",
        "1",
        "--probe-length",
        "6",
        "--probe-width",
        "20",
        "--pressure",
        "2.67",
        "--plane-strain-ends",
        "--out",
        mesh.to_str().unwrap(),
        "-q",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let deck = mesh.join("thigh3d.inp");
    assert!(deck.exists() && mesh.join("mesh.vtu").exists());
    let solved = dir.join("solve");
    let out = femu(&[
        "solve",
        deck.to_str().unwrap(),
        "--out",
        solved.to_str().unwrap(),
        "-q",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(solved.join("displacements.csv")).unwrap();
    let rows = rows(&text);
    let max_u = rows
        .iter()
        .map(|r| (r[3] * r[3] + r[4] * r[4] + r[5] * r[5]).sqrt())
        .fold(0.0, f64::max);
    assert!(max_u > 0.05, "the probe moves the skin: max |u| = {max_u}");
    // Group the nodes by their section position (x, y); each group has one node per level.
    let mut by_xy: BTreeMap<(i64, i64), Vec<[f64; 3]>> = BTreeMap::new();
    for r in &rows {
        let key = ((r[0] * 1e6).round() as i64, (r[1] * 1e6).round() as i64);
        by_xy.entry(key).or_default().push([r[3], r[4], r[5]]);
    }
    let levels = by_xy.values().map(Vec::len).max().unwrap();
    assert_eq!(levels, 3, "two layers of 3 mm: three levels of nodes");
    let mut worst: f64 = 0.0;
    for us in by_xy.values() {
        for u in us {
            worst = worst.max(u[2].abs());
            worst = worst
                .max((u[0] - us[0][0]).abs())
                .max((u[1] - us[0][1]).abs());
        }
    }
    // Plane strain holds exactly in the continuum and in the discretization (each level's
    // nodes see the same element rows); what is left is the Newton tolerance (1e-10 on forces);
    // the CSV holds every digit.
    assert!(
        worst < 1e-7 * max_u,
        "levels differ by {worst:.3e} mm (max |u| {max_u:.3e} mm)"
    );

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(solved.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["dimension"], 3);
    assert_eq!(summary["status"], "converged");
    assert_eq!(summary["nodes"].as_u64().unwrap() as usize, rows.len());
    assert!(summary["element_types"]["C3D8H"].as_u64().unwrap() > 1000);
    assert!(summary["min_volume_ratio"].as_f64().unwrap() > 0.5);
    assert!(solved.join("result.vtu").exists());
    // The reactions (femur and the end faces along z) balance the pressure's resultant: the
    // pressure is a follower load, so its resultant is over the deformed faces; its size is
    // the pressure times the footprint's projected width times 6 mm. The footprint is made of
    // whole skin faces (≤ 4.5 mm) whose midpoints lie within 10 mm of the probe's centre: its
    // width lies between 20 - 4.5 and 20 + 2 x 4.5 mm, so the force between 0.25 and 0.47 N.
    let r = &summary["reaction_force_total_n"];
    let ry = r[1].as_f64().unwrap();
    assert!(ry > 0.25 && ry < 0.47, "vertical reaction {ry} N");
}

#[test]
fn bad_3d_inputs_are_refused_by_name() {
    let dir = scratch("bad");
    // A section coarser than the thigh allows (the small muscles would be lost).
    let out = femu(&[
        "mesh",
        "thigh3d",
        "--size",
        "6",
        "--out",
        dir.join("m").to_str().unwrap(),
        "-q",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("element_size_mm = 6"), "{err}");
    // A probe longer than the thigh.
    let out = femu(&[
        "mesh",
        "thigh3d",
        "--length",
        "20",
        "--out",
        dir.join("m").to_str().unwrap(),
        "-q",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--probe-length"));
    // A deck mixing 3D and plane-strain elements.
    let deck = dir.join("mixed.inp");
    std::fs::write(
        &deck,
        "*NODE\n1,0,0,0\n2,1,0,0\n3,1,1,0\n4,0,1,0\n5,0,0,1\n6,1,0,1\n7,1,1,1\n8,0,1,1\n\
         *ELEMENT, TYPE=C3D8, ELSET=A\n1,1,2,3,4,5,6,7,8\n\
         *ELEMENT, TYPE=CPE4, ELSET=B\n2,1,2,3,4\n",
    )
    .unwrap();
    let out = femu(&[
        "solve",
        deck.to_str().unwrap(),
        "--out",
        dir.join("s").to_str().unwrap(),
        "-q",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("mixed.inp:") && err.contains("CPE4"), "{err}");
}
