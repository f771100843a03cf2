//! Helpers of the identification tests: the built-in thigh under the seed's compression, the
//! free parameters of a model, and CalculiX (a
//! deck solved by `ccx` through femu's `.inp` writer, dead loads, its nodal displacements read
//! back; skipped with a message when ccx is absent).
#![allow(dead_code)] // each test binary uses its own subset

use femu_identify::fit::FreeParameter;
use femu_mech::sensitivity::{all_parameters, Parameter};
use femu_mech::Model;

use femu_mesh::inp::read_ccx_dat_displacements;
use femu_mesh::{write_inp, Deck};
use std::collections::HashMap;
use std::process::Command;

pub fn ccx_installed() -> bool {
    let found = Command::new("ccx").arg("-v").output().is_ok();
    if !found {
        eprintln!("SKIPPED: ccx not installed (apt-get install calculix-ccx)");
    }
    found
}

/// Rounds the deck's numbers to 14 significant digits (ccx reads 20 characters per field); both
/// codes solve the rounded deck.
pub fn ccx_ready(deck: &mut Deck) {
    let r = |v: &mut f64| *v = format!("{v:.13e}").parse().unwrap();
    deck.mesh.nodes.iter_mut().flatten().for_each(r);
    for m in &mut deck.materials {
        m.constants.iter_mut().for_each(r);
    }
    deck.boundaries.iter_mut().for_each(|b| r(&mut b.value));
    deck.point_loads
        .iter_mut()
        .for_each(|p| r(&mut p.magnitude));
}

/// The nodal displacements (2 per node, the deck's node order) of `deck` solved by ccx in a
/// scratch folder named after `name`.
pub fn ccx_displacements(deck: &Deck, name: &str) -> Vec<f64> {
    let dir = std::env::temp_dir().join(format!("femu-identify-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut text = Vec::new();
    write_inp(deck, &mut text).unwrap();
    std::fs::write(dir.join("job.inp"), &text).unwrap();
    let out = Command::new("ccx")
        .args(["-i", "job"])
        .current_dir(&dir)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .expect("ccx runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && !stdout.contains("*ERROR"),
        "ccx failed; deck kept in {}",
        dir.display()
    );
    let ccx: HashMap<i64, [f64; 2]> = read_ccx_dat_displacements(&dir.join("job.dat"))
        .unwrap()
        .into_iter()
        .collect();
    if std::env::var_os("FEMU_KEEP_CCX").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    deck.mesh.node_labels.iter().flat_map(|l| ccx[l]).collect()
}

/// Every material parameter of `model` free, bounds a factor 4 either side of its value, and
/// those values (the references).
pub fn free_parameters(model: &Model) -> (Vec<FreeParameter>, Vec<f64>) {
    let free: Vec<FreeParameter> = all_parameters(model)
        .into_iter()
        .map(|p| {
            let v = p.value(model);
            FreeParameter {
                name: p.name(model),
                members: vec![p],
                lower: v / 4.0,
                upper: v * 4.0,
            }
        })
        .collect();
    let reference = free.iter().map(|f| f.members[0].value(model)).collect();
    (free, reference)
}

/// The parameters `names` of `model` free, bounds a factor 4 either side of their values, and
/// those values (the references).
pub fn named_free(model: &Model, names: &[&str]) -> (Vec<FreeParameter>, Vec<f64>) {
    let free: Vec<FreeParameter> = names
        .iter()
        .map(|n| {
            let p = Parameter::named(model, n).unwrap();
            let v = p.value(model);
            FreeParameter {
                name: n.to_string(),
                members: vec![p],
                lower: v / 4.0,
                upper: v * 4.0,
            }
        })
        .collect();
    let reference = free.iter().map(|f| f.members[0].value(model)).collect();
    (free, reference)
}

/// The built-in thigh (about `elements` CPE4H) with Table 1's materials under the seed's
/// compression (the plate on the anterior skin, dead loads off).
pub fn compression_thigh(elements: usize) -> Model {
    let t = femu_geometry::parametric_thigh(
        &femu_geometry::ThighParams {
            target_elements: Some(elements),
            ..Default::default()
        },
        femu_mesh::ElementKind::Cpe4h,
    )
    .unwrap();
    let skin = t.mesh.surfaces["SKIN"].clone();
    let mut deck =
        femu_geometry::contention_deck(&t, &femu_geometry::table1_materials(), 0.0).unwrap();
    deck.pressures.clear();
    let mut model = Model::from_deck(deck).unwrap();
    femu_mech::loading::apply_loading(
        &mut model,
        &skin,
        &femu_mech::loading::Loading::seed_compression(),
    )
    .unwrap();
    model
}
