//! Every law's parameters reach a run's summaries and report: a small study whose fat and
//! quadriceps follow the Yeoh law (C10, C20, C30, D each; the other tissues Neo-Hookean) and
//! one whose tissues all follow the Mooney–Rivlin law (C10, C01, D), run through the library (`femu run`: model, forward test, sensitivity,
//! virtual measurement, identification) on a coarse built-in thigh. Each parameter must be
//! listed per tissue with its unit in `summary.json` (the run's, the forward test's, the
//! sensitivity's), in the test ranking (worst relative sd per family of parameters, beside the
//! C10 and D keys kept for scripts) and in the HTML report.

use serde_json::Value;
use std::path::{Path, PathBuf};

const TISSUES: [&str; 5] = ["FAT", "QUADRICEPS", "ISCHIO", "GRACILIS", "SARTORIUS"];

/// A tissue's law and its parameters by study-file key.
type Material<'a> = (&'a str, &'a str, &'a [(&'a str, f64)]);

/// A scratch folder of its own for `name`, emptied.
fn scratch(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("femu-law-parameters-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The study: the compression test on a 700-element thigh, a 24 x 24 grid, one start of the
/// grouped identification, no discretization check (the pieces that write the summaries, at
/// the smallest size that runs them all), every tissue with its law and keyed values.
fn study(materials: &[Material]) -> String {
    let mut text = String::from(
        "[model]\nelements = 700\n\
         [[test]]\nkind = \"compression\"\nside = \"anterior\"\nforce_n_per_mm = 0.1\n\
         [grid]\ncounts = [24, 24]\n[noise]\nsigma_mm = 2e-3\n\
         [identification]\ngrouped = true\nstarts = 1\nseed = 3\ndiscretization = \"off\"\n",
    );
    for (tissue, law, keys) in materials {
        text.push_str(&format!("[materials.{tissue}]\nlaw = \"{law}\"\n"));
        for (k, v) in *keys {
            text.push_str(&format!("{k} = {v}\n"));
        }
    }
    text
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// The unit a report shows parameter `kind` in, and its internal unit.
fn units(kind: &str) -> (&'static str, &'static str) {
    if kind == "D" {
        ("MPa⁻¹", "MPa⁻¹")
    } else {
        ("kPa", "MPa")
    }
}

/// The law parameter a study-file key names: `c20_kpa` → `C20`.
fn kind_of(key: &str) -> String {
    key.split('_').next().unwrap().to_ascii_uppercase()
}

/// Runs the study of `materials` (every tissue) and checks every summary and the report;
/// `families` are the law parameters of the model in the order its materials declare them.
fn check_laws(name: &str, materials: &[Material], families: &[&str]) {
    assert_eq!(materials.len(), TISSUES.len());
    let dir = scratch(name);
    let file = dir.join("study.toml");
    std::fs::write(&file, study(materials)).unwrap();
    let total: usize = materials.iter().map(|m| m.2.len()).sum();
    let out = dir.join("out");
    femu_study::steps::run::run(&file, &out, &femu_study::Quiet).unwrap();

    // Keyed values as given, written back in the key's unit: equal up to the rounding of the
    // unit changes (kPa → MPa → kPa, two products by powers of ten).
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1.0);
    let key_of = |kind: &str| {
        format!(
            "{}_{}",
            kind.to_ascii_lowercase(),
            if kind == "D" { "per_mpa" } else { "kpa" }
        )
    };

    // The forward test's summary: each material's law and every parameter by its key, the
    // Neo-Hookean keys kept beside them.
    let forward = read_json(&out.join("forward/compression-anterior/summary.json"));
    let run = read_json(&out.join("summary.json"));
    for materials_list in [&forward["materials"], &run["materials"]] {
        let listed = materials_list.as_array().expect("materials listed");
        assert_eq!(listed.len(), TISSUES.len(), "{materials_list}");
        for (tissue, law, keys) in materials {
            let m = listed
                .iter()
                .find(|m| m["name"] == *tissue)
                .unwrap_or_else(|| panic!("{tissue} not in {materials_list}"));
            assert_eq!(m["law"], *law, "{m}");
            let params = m["parameters"].as_object().expect("parameters by key");
            assert_eq!(params.len(), keys.len(), "{m}");
            for (k, v) in *keys {
                let got = params[*k].as_f64().unwrap_or(f64::NAN);
                assert!(close(got, *v), "{tissue} {k}: {got} against {v}");
            }
            assert!(close(
                m["c10_kpa"].as_f64().unwrap(),
                params["c10_kpa"].as_f64().unwrap()
            ));
            assert!(close(
                m["d_per_mpa"].as_f64().unwrap(),
                params["d_per_mpa"].as_f64().unwrap()
            ));
        }
    }

    // The sensitivity's summary (and the run's copy): every parameter of every tissue with its
    // law, units, key and scale as the law declares them.
    let sens = read_json(&out.join("sensitivity/summary.json"));
    for list in [&sens["law_parameters"], &run["sensitivity"]["parameters"]] {
        let list = list.as_array().expect("parameters listed");
        assert_eq!(list.len(), total);
        for (tissue, law, keys) in materials {
            for (key, value) in *keys {
                let kind = kind_of(key);
                let name = format!("{kind}_{tissue}");
                let e = list
                    .iter()
                    .find(|e| e["name"] == name.as_str())
                    .unwrap_or_else(|| panic!("{name} not listed"));
                let (shown, internal) = units(&kind);
                assert_eq!(e["kind"], kind.as_str(), "{e}");
                assert_eq!(e["material"], *tissue, "{e}");
                assert_eq!(e["law"], *law, "{e}");
                assert_eq!(e["unit"], internal, "{e}");
                assert_eq!(e["shown_unit"], shown, "{e}");
                assert_eq!(e["key"], key_of(&kind).as_str(), "{e}");
                let factor = if kind == "D" { 1.0 } else { 1e3 };
                assert!(close(e["shown"].as_f64().unwrap(), *value), "{e}");
                assert!(
                    close(
                        e["shown"].as_f64().unwrap(),
                        factor * e["value"].as_f64().unwrap()
                    ),
                    "{e}"
                );
            }
        }
    }

    // The test ranking: the worst predicted relative sd of every family, each the largest of
    // the family's parameters, the C10 and D keys equal to their families'.
    let ranking = sens["ranking"].as_array().unwrap();
    assert!(!ranking.is_empty());
    for r in ranking {
        let worst = r["worst_relative_sd"].as_array().expect("worst per family");
        let listed: Vec<&str> = worst.iter().map(|w| w[0].as_str().unwrap()).collect();
        assert_eq!(listed, families, "{r}");
        let id = &r["identifiability"];
        let names = id["names"].as_array().unwrap();
        let sd = id["relative_sd"].as_array().unwrap();
        for w in worst {
            let family = w[0].as_str().unwrap();
            // A tied group is named by its members joined by '+', each of the family.
            let expected = names
                .iter()
                .zip(sd)
                .filter(|(n, _)| n.as_str().unwrap().starts_with(&format!("{family}_")))
                .map(|(_, s)| s.as_f64().unwrap_or(f64::INFINITY))
                .fold(0.0f64, f64::max);
            let got = w[1].as_f64().unwrap_or(f64::INFINITY);
            assert_eq!(got, expected, "{family}: {r}");
        }
        assert_eq!(r["worst_c10_relative_sd"], worst[0][1], "{r}");
        let d = families.iter().position(|f| *f == "D").unwrap();
        assert_eq!(r["worst_d_relative_sd"], worst[d][1], "{r}");
    }
    // Not a comparison of infinities only: some measurement predicts a finite sd for every
    // family.
    assert!(
        ranking.iter().any(|r| r["worst_relative_sd"]
            .as_array()
            .unwrap()
            .iter()
            .all(|w| w[1].is_f64())),
        "{ranking:?}"
    );
    for r in run["sensitivity"]["ranking"].as_array().unwrap() {
        let listed: Vec<&str> = r["worst_relative_sd"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w[0].as_str().unwrap())
            .collect();
        assert_eq!(listed, families, "{r}");
    }
    let csv = std::fs::read_to_string(out.join("sensitivity/identifiability.csv")).unwrap();
    let mut lines = csv.lines();
    assert!(
        lines.next().unwrap().ends_with(",worst_relative_sd"),
        "{csv}"
    );
    for line in lines {
        for kind in families {
            assert!(
                line.contains(&format!(" {kind}=")) || line.contains(&format!(",{kind}=")),
                "{kind}: {line}"
            );
        }
    }
    // The finding names every family.
    for f in sens["finding"].as_array().unwrap() {
        for kind in families {
            assert!(
                f.as_str().unwrap().contains(&format!(" {kind} ")),
                "{kind}: {f}"
            );
        }
    }

    // The identification: every free parameter with the unit the report shows it in, in the
    // identification's summary and in the run's.
    let ident = read_json(&out.join("identify/grouped/summary.json"));
    for free in [
        &ident["free_parameters"],
        &run["identification"]["grouped"]["free_parameters"],
    ] {
        let free = free.as_array().expect("free parameters listed");
        for (tissue, _, keys) in materials {
            for (key, _) in *keys {
                let kind = kind_of(key);
                let name = format!("{kind}_{tissue}");
                let f = free
                    .iter()
                    .find(|f| f["name"].as_str().unwrap().split('+').any(|n| n == name))
                    .unwrap_or_else(|| panic!("{name} not free"));
                assert_eq!(f["unit"], units(&kind).0, "{f}");
                assert_eq!(f["members"][0]["kind"], kind.as_str(), "{f}");
            }
        }
    }

    // The report: the materials table lists each tissue's law and every parameter with its
    // unit; the parameters table every parameter with its unit; the ranking a column per
    // family.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let row = |first_cell: &str| -> &str {
        let start = html
            .find(&format!("<tr><td>{first_cell}</td>"))
            .unwrap_or_else(|| panic!("no row {first_cell} in the report"));
        let end = start + html[start..].find("</tr>").unwrap();
        &html[start..end]
    };
    for (tissue, law, keys) in materials {
        // (The model's table of regions has rows of the tissues too: the one with the law.)
        let r = row(&format!("{tissue}</td><td>{law}"));
        let mut at = 0;
        for (key, _) in *keys {
            let kind = kind_of(key);
            // Each parameter with its unit, in the law's order (as the keys are listed here).
            let label = format!("{kind} ({})", units(&kind).0);
            let found = r.find(&label).unwrap_or_else(|| panic!("{label}: {r}"));
            assert!(found >= at, "{label} out of the law's order: {r}");
            at = found;
            let r = row(&format!("{kind}_{tissue}"));
            assert!(r.contains(&format!("<td>{}</td>", units(&kind).0)), "{r}");
        }
    }
    for kind in families {
        assert!(
            html.contains(&format!("<th>worst {kind} sd</th>")),
            "worst {kind} sd"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_yeoh_study_lists_c10_c20_c30_and_d_of_every_tissue() {
    // Yeoh fat and quadriceps, the three others Neo-Hookean: 14 parameters that the
    // compression's field on the grid identifies (all five tissues Yeoh, 20 parameters, make
    // its Fisher information singular and every predicted sd infinite).
    let materials: [Material; 5] = [
        (
            "FAT",
            "yeoh",
            &[
                ("c10_kpa", 0.8),
                ("c20_kpa", 0.3),
                ("c30_kpa", 0.1),
                ("d_per_mpa", 30.8),
            ],
        ),
        (
            "QUADRICEPS",
            "yeoh",
            &[
                ("c10_kpa", 1.75),
                ("c20_kpa", 0.5),
                ("c30_kpa", 0.2),
                ("d_per_mpa", 18.0),
            ],
        ),
        (
            "ISCHIO",
            "neo-hookean",
            &[("c10_kpa", 3.0), ("d_per_mpa", 18.0)],
        ),
        (
            "GRACILIS",
            "neo-hookean",
            &[("c10_kpa", 2.2), ("d_per_mpa", 18.0)],
        ),
        (
            "SARTORIUS",
            "neo-hookean",
            &[("c10_kpa", 3.75), ("d_per_mpa", 18.0)],
        ),
    ];
    check_laws("yeoh", &materials, &["C10", "C20", "C30", "D"]);
}

#[test]
fn a_mooney_rivlin_study_lists_c10_c01_and_d_of_every_tissue() {
    let materials: [Material; 5] = [
        (
            "FAT",
            "mooney-rivlin",
            &[("c10_kpa", 0.5), ("c01_kpa", 0.3), ("d_per_mpa", 30.8)],
        ),
        (
            "QUADRICEPS",
            "mooney-rivlin",
            &[("c10_kpa", 1.2), ("c01_kpa", 0.5), ("d_per_mpa", 18.0)],
        ),
        (
            "ISCHIO",
            "mooney-rivlin",
            &[("c10_kpa", 2.0), ("c01_kpa", 1.0), ("d_per_mpa", 18.0)],
        ),
        (
            "GRACILIS",
            "mooney-rivlin",
            &[("c10_kpa", 1.5), ("c01_kpa", 0.7), ("d_per_mpa", 18.0)],
        ),
        (
            "SARTORIUS",
            "mooney-rivlin",
            &[("c10_kpa", 2.5), ("c01_kpa", 1.2), ("d_per_mpa", 18.0)],
        ),
    ];
    check_laws("mooney-rivlin", &materials, &["C10", "C01", "D"]);
}
