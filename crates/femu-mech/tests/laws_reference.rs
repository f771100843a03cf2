//! The guide's material-law reference (`docs/guide/src/reference/laws.md`) is generated from the
//! registry's declarations (`femu_mech::material::LAWS`: each law's [`LawSpec`] and its
//! [`ParameterSpec`]s), never written by hand: this test fails when the committed page differs
//! from what the registry generates, and a law added to the registry appears in the page without
//! touching it.
//!
//! When a law or a parameter changed, regenerate the page with
//! `FEMU_BLESS=1 cargo test -p femu-mech --test laws_reference`.

use femu_mech::material::law::{C10 as C10_SPEC, D as D_SPEC};
use femu_mech::material::{AbaqusField, Bound, EnergyPart, LawSpec, ParameterSpec, Unit, LAWS};
use std::fmt::Write;
use std::path::Path;

const PAGE: &str = "docs/guide/src/reference/laws.md";

/// A number as a reader wants it: at most nine significant digits, no trailing zeros.
fn num(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    let digits = 9 - 1 - v.abs().log10().floor() as i32;
    let scale = 10f64.powi(digits.clamp(-300, 300));
    let rounded = (v * scale).round() / scale;
    format!("{rounded}")
}

fn bound(b: Bound, unit: Unit, lower: bool) -> Option<String> {
    let (symbol, factor) = unit.report();
    let (open, closed) = if lower { (">", "≥") } else { ("<", "≤") };
    match b {
        Bound::Open(v) => Some(format!("{open} {} {symbol}", num(v * factor))),
        Bound::Closed(v) => Some(format!("{closed} {} {symbol}", num(v * factor))),
        Bound::Unbounded => None,
    }
}

fn range(p: &ParameterSpec) -> String {
    match (bound(p.lower, p.unit, true), bound(p.upper, p.unit, false)) {
        (Some(l), Some(u)) => format!("{l} and {u}"),
        (Some(b), None) | (None, Some(b)) => b,
        (None, None) => "any finite value".to_string(),
    }
}

fn part(p: &ParameterSpec) -> &'static str {
    match p.part {
        EnergyPart::Isochoric => "isochoric",
        EnergyPart::Volumetric => "volumetric",
    }
}

/// The reference page of `laws`, in registration order.
fn page(laws: &[&LawSpec]) -> String {
    let mut s = String::new();
    s.push_str(
        "# Material laws\n\n\
         <!-- Generated from the registry of crates/femu-mech/src/material.rs (LAWS): do not \
         edit. Regenerate with\n     FEMU_BLESS=1 cargo test -p femu-mech --test laws_reference \
         -->\n\n\
         A region's material is one of these laws: `law = \"NAME\"` in its \
         `[materials.REGION]` table of the study file (Neo-Hookean when absent), or the \
         `*HYPERELASTIC` keyword of a deck. Each parameter is set in the study file by one of its \
         keys (the unit is part of the key: `c10_kpa = 1.75` is 1.75 kPa) and named in results \
         as the parameter and the region (`C10_FAT`). Values are stored in the deck's units (MPa, \
         MPa⁻¹); ranges and typical values are shown in the units of the reports (kPa for \
         stresses). A parameter on a log scale is identified as its logarithm.\n\n",
    );
    s.push_str("Laws: ");
    let links: Vec<String> = laws
        .iter()
        .map(|l| format!("[`{}`](#{})", l.name, l.name))
        .collect();
    s.push_str(&links.join(", "));
    s.push_str(".\n");
    for l in laws {
        let _ = write!(
            s,
            "\n## `{}`\n\n{}\n\n- study file: `law = \"{}\"`\n- deck: `*HYPERELASTIC, {}`, \
             data line `{}`\n",
            l.name,
            l.doc,
            l.name,
            l.abaqus_keyword,
            l.abaqus_data_line(),
        );
        let unused: Vec<&str> = l
            .abaqus_fields
            .iter()
            .filter(|f: &&AbaqusField| f.parameter.is_none())
            .map(|f| f.name)
            .collect();
        if !unused.is_empty() {
            let _ = writeln!(
                s,
                "- deck constants femu does not implement (must be 0): {}",
                unused
                    .iter()
                    .map(|n| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        s.push_str(
            "\n| parameter | study-file keys | unit | allowed | typical | scale | energy part | \
             description |\n|---|---|---|---|---|---|---|---|\n",
        );
        for p in l.parameters {
            let (symbol, factor) = p.unit.report();
            let keys: Vec<String> = p.keys().map(|k| format!("`{k}`")).collect();
            let _ = writeln!(
                s,
                "| `{}` | {} | {} | {} | {} | {} | {} | {} |",
                p.name,
                keys.join(", "),
                symbol,
                range(p),
                num(p.typical * factor),
                if p.log_scale { "log" } else { "linear" },
                part(p),
                p.doc.replace('|', "\\|"),
            );
        }
    }
    s
}

fn registered() -> Vec<&'static LawSpec> {
    LAWS.iter().map(|l| l.spec).collect()
}

#[test]
fn laws_page_is_generated_from_the_registry() {
    let generated = page(&registered());
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(PAGE);
    if std::env::var_os("FEMU_BLESS").is_some() {
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        std::fs::write(&file, &generated).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(&file).unwrap_or_default();
    if committed != generated {
        let first = committed
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(committed.lines().count().min(generated.lines().count()));
        panic!(
            "{PAGE} differs from what the registry generates (first at line {}:\n  committed: \
             {:?}\n  generated: {:?}).\nRegenerate it with: FEMU_BLESS=1 cargo test -p femu-mech \
             --test laws_reference",
            first + 1,
            committed.lines().nth(first).unwrap_or("(end of file)"),
            generated.lines().nth(first).unwrap_or("(end of file)"),
        );
    }
}

/// Every registered law and every one of its parameters and keys is on the page.
#[test]
fn every_law_and_parameter_is_on_the_page() {
    let text = page(&registered());
    for l in registered() {
        assert!(text.contains(&format!("\n## `{}`\n", l.name)), "{}", l.name);
        assert!(text.contains(&format!("`*HYPERELASTIC, {}`", l.abaqus_keyword)));
        for p in l.parameters {
            assert!(text.contains(&format!("| `{}` |", p.name)), "{}", p.name);
            for k in p.keys() {
                assert!(text.contains(&format!("`{k}`")), "{k}");
            }
        }
    }
    // The Neo-Hookean C10 as the seed's Table 1 states it: kPa, positive.
    assert!(text.contains("| `C10` | `c10_kpa`, `c10_mpa` | kPa | > 0 kPa and ≤ 10000000 kPa |"));
}

/// A law added to the registry appears on the page with its parameters, without touching the
/// page's code: here a law declared at test time.
#[test]
fn a_new_law_appears_on_the_page() {
    static NEW: LawSpec = LawSpec {
        name: "gent-like",
        abaqus_keyword: "GENTLIKE",
        abaqus_fields: &[
            AbaqusField {
                name: "MU",
                parameter: Some(0),
            },
            AbaqusField {
                name: "JM",
                parameter: None,
            },
            AbaqusField {
                name: "D1",
                parameter: Some(1),
            },
        ],
        parameters: &[
            ParameterSpec {
                name: "MU",
                typical: 2.5e-3,
                doc: "shear modulus",
                ..C10_SPEC
            },
            D_SPEC,
        ],
        doc: "W = a test law",
    };
    let before = page(&registered());
    let mut laws = registered();
    laws.push(&NEW);
    let after = page(&laws);
    assert!(!before.contains("gent-like"));
    assert!(after.contains("[`gent-like`](#gent-like)"));
    assert!(after.contains("\n## `gent-like`\n\nW = a test law\n"));
    assert!(after.contains("- deck: `*HYPERELASTIC, GENTLIKE`, data line `MU, JM, D1`\n"));
    assert!(after.contains("- deck constants femu does not implement (must be 0): `JM`\n"));
    assert!(after.contains(
        "| `MU` | `mu_kpa`, `mu_mpa` | kPa | > 0 kPa and ≤ 10000000 kPa | 2.5 | log | isochoric \
         | shear modulus |"
    ));
    // Nothing else changed: the new law's section is appended, its link added.
    let section = &after[after.find("\n## `gent-like`").unwrap()..];
    assert_eq!(
        after
            .replace(section, "")
            .replace(", [`gent-like`](#gent-like)", ""),
        before
    );
}
