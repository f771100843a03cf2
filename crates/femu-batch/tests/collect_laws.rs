//! `femu batch collect` over cases whose tissues follow the Yeoh law: the population table
//! (`population.csv`, `population.json`) lists C10, C20, C30 and D of every tissue of every case
//! with its law parameter and unit, and the population report shows a distribution per law
//! parameter — also when, as here, the compression's field cannot see every one of the 18 free
//! parameters (their intervals [0, ∞) on the report's plots). The cases run in this process (`femu batch case`'s library call, one after the
//! other) from a plan written as `femu batch run` writes it.

use femu_batch::folder::{fingerprint, write_atomic, BatchDir, Plan, PlannedCase};
use std::path::PathBuf;

const TISSUES: [&str; 5] = ["FAT", "QUADRICEPS", "ISCHIO", "GRACILIS", "SARTORIUS"];
const KINDS: [&str; 4] = ["C10", "C20", "C30", "D"];

/// The template: the compression test on a 700-element thigh, a 24 x 24 grid, one start of
/// the grouped identification (no forward or sensitivity step, no discretization check), every
/// tissue a Yeoh solid.
const TEMPLATE: &str = "\
[model]
elements = 700
[[test]]
kind = \"compression\"
side = \"anterior\"
force_n_per_mm = 0.1
[grid]
counts = [24, 24]
[noise]
sigma_mm = 2e-3
[identification]
grouped = true
starts = 1
seed = 3
discretization = \"off\"
[run]
forward = false
sensitivity = false
[materials.FAT]
law = \"yeoh\"
c10_kpa = 0.8
c20_kpa = 0.3
c30_kpa = 0.1
d_per_mpa = 30.8
[materials.QUADRICEPS]
law = \"yeoh\"
c10_kpa = 1.75
c20_kpa = 0.5
c30_kpa = 0.2
d_per_mpa = 18.0
[materials.ISCHIO]
law = \"yeoh\"
c10_kpa = 3.0
c20_kpa = 0.9
c30_kpa = 0.3
d_per_mpa = 18.0
[materials.GRACILIS]
law = \"yeoh\"
c10_kpa = 2.2
c20_kpa = 0.6
c30_kpa = 0.2
d_per_mpa = 18.0
[materials.SARTORIUS]
law = \"yeoh\"
c10_kpa = 3.75
c20_kpa = 1.0
c30_kpa = 0.4
d_per_mpa = 18.0
";

/// Two subjects, each with its own C20 of the fat (the value its case's reference must hold).
const CASES: &str = "\
case,subject,materials.fat.c20_kpa,identification.seed
s01,s01,0.3,1
s02,s02,0.35,2
";

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "femu-batch-collect-laws-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_yeoh_population_lists_c10_c20_c30_and_d_of_every_tissue() {
    let dir = scratch("yeoh");
    std::fs::write(dir.join("study.toml"), TEMPLATE).unwrap();
    std::fs::write(dir.join("cases.csv"), CASES).unwrap();
    let batch_file = dir.join("batch.toml");
    std::fs::write(
        &batch_file,
        "template = \"study.toml\"\ncases = \"cases.csv\"\n",
    )
    .unwrap();

    // The plan, as `femu batch run` writes it: each case's study, then batch.json.
    let batch = femu_batch::spec::read(&batch_file).unwrap();
    let cases = femu_batch::expand::expand(&batch).unwrap();
    let out = BatchDir::new(&dir.join("out"));
    for c in &cases {
        std::fs::create_dir_all(out.case_dir(&c.name)).unwrap();
        write_atomic(&out.case_study(&c.name), &c.text).unwrap();
    }
    out.write_plan(&Plan {
        femu_version: env!("CARGO_PKG_VERSION").into(),
        batch_file: batch_file.clone(),
        batch_fingerprint: Some(fingerprint(&std::fs::read_to_string(&batch_file).unwrap())),
        written_unix_s: 0,
        variables: vec!["subject".into()],
        cases: cases
            .iter()
            .map(|c| PlannedCase {
                name: c.name.clone(),
                origin: c.origin.clone(),
                vars: c.vars.iter().cloned().collect(),
                fingerprint: c.fingerprint.clone(),
            })
            .collect(),
    })
    .unwrap();
    for c in &cases {
        femu_batch::run_case(&out, &c.name, &femu_study::Quiet).unwrap();
    }

    let collected = femu_batch::collect(&out).unwrap();

    // The typed population: every parameter of every tissue, its law parameter, its unit.
    for case in &collected.population.cases {
        assert_eq!(case.fits.len(), 1, "{}", case.case);
        let fit = &case.fits[0];
        for tissue in TISSUES {
            for kind in KINDS {
                let name = format!("{kind}_{tissue}");
                let p = fit
                    .parameters
                    .iter()
                    .find(|p| p.name.split('+').any(|n| n == name))
                    .unwrap_or_else(|| panic!("{}: {name} not collected", case.case));
                assert_eq!(p.kind, kind, "{}: {name}", case.case);
                assert!(p.tissue.split('+').any(|t| t == tissue), "{p:?}");
                assert_eq!(p.unit, if kind == "D" { "MPa⁻¹" } else { "MPa" }, "{p:?}");
                assert!(p.identified.is_finite() && p.reference.is_some(), "{p:?}");
            }
        }
        // The case's own C20 of the fat reached its reference (the table's kPa in MPa, up to
        // the rounding of the unit change).
        let c20 = if case.case == "s01" { 0.3e-3 } else { 0.35e-3 };
        let p = fit.parameters.iter().find(|p| p.name == "C20_FAT").unwrap();
        assert!((p.reference.unwrap() / c20 - 1.0).abs() < 1e-12, "{p:?}");
    }

    // population.csv: one row per case and parameter, with its kind and unit columns.
    let csv = std::fs::read_to_string(out.collect_dir().join("population.csv")).unwrap();
    let mut rows = csv::Reader::from_reader(csv.as_bytes());
    let header = rows.headers().unwrap().clone();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (case_col, parameter, kind_col, unit_col) =
        (col("case"), col("parameter"), col("kind"), col("unit"));
    let records: Vec<csv::StringRecord> = rows.records().map(|r| r.unwrap()).collect();
    for case in ["s01", "s02"] {
        for tissue in TISSUES {
            for kind in KINDS {
                let name = format!("{kind}_{tissue}");
                let r = records
                    .iter()
                    .find(|r| r[case_col] == *case && r[parameter].split('+').any(|n| n == name))
                    .unwrap_or_else(|| panic!("{case}: no row of {name} in\n{csv}"));
                assert_eq!(&r[kind_col], kind, "{r:?}");
                assert_eq!(
                    &r[unit_col],
                    if kind == "D" { "MPa⁻¹" } else { "MPa" },
                    "{r:?}"
                );
            }
        }
    }

    // The population report: a distribution per law parameter, in the unit reports show.
    let html = std::fs::read_to_string(out.collect_dir().join("report.html")).unwrap();
    for (kind, unit) in [
        ("C10", "kPa"),
        ("C20", "kPa"),
        ("C30", "kPa"),
        ("D", "MPa⁻¹"),
    ] {
        let caption = format!("{kind} ({unit}) of each tissue across the cases");
        assert!(html.contains(&caption), "{caption}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
