//! The study file's keys are declared once (`femu_study::schema::keys`): `femu init`'s file
//! (`example_study.toml`, [`schema::EXAMPLE_STUDY`]) and the reference page
//! (`docs/guide/src/reference/study-file.md`) are generated from the declarations, and a key declared
//! there appears in both without touching either by hand.
//!
//! When a declaration changed, regenerate the two files with
//! `FEMU_BLESS=1 cargo test -p femu-study --test study_keys`.

use femu_study::schema::keys::{self, Allowed, Def, Init, Item, KeySpec, TableSpec, Ty, TABLES};
use femu_study::schema::{self, EXAMPLE_STUDY};
use std::path::{Path, PathBuf};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Compares `path` (from the workspace root) with `generated`; writes it under `FEMU_BLESS=1`.
fn check_generated(path: &str, generated: &str) {
    let file = workspace().join(path);
    if std::env::var_os("FEMU_BLESS").is_some() {
        if let Some(dir) = file.parent() {
            std::fs::create_dir_all(dir).unwrap();
        }
        std::fs::write(&file, generated).unwrap();
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
            "{path} differs from what the declarations of crates/femu-study/src/schema/keys.rs \
             generate (first at line {}:\n  committed: {:?}\n  generated: {:?}).\nRegenerate it \
             with: FEMU_BLESS=1 cargo test -p femu-study --test study_keys",
            first + 1,
            committed.lines().nth(first).unwrap_or("(end of file)"),
            generated.lines().nth(first).unwrap_or("(end of file)"),
        );
    }
}

#[test]
fn femu_init_file_is_generated_from_the_declarations() {
    let generated = keys::generated_init_file();
    check_generated(
        "crates/femu-study/src/schema/example_study.toml",
        &generated,
    );
    // What `femu init` writes is that file (compiled in).
    if std::env::var_os("FEMU_BLESS").is_none() {
        assert_eq!(EXAMPLE_STUDY, generated);
    }
}

#[test]
fn reference_page_is_generated_from_the_declarations() {
    check_generated(
        "docs/guide/src/reference/study-file.md",
        &keys::generated_reference_page(),
    );
}

/// The lines of `femu init`'s file that set or show `key` (`key = ...` or `# key = ...`).
fn shows(text: &str, key: &str) -> bool {
    text.lines().any(|l| {
        let l = l.trim_start_matches('#').trim_start();
        l.strip_prefix(key)
            .is_some_and(|rest| rest.trim_start().starts_with('='))
    })
}

/// Every declared key is in its table's part of `femu init`'s file and in its table of the
/// reference page.
#[test]
fn every_declared_key_is_in_init_and_in_the_reference() {
    let page = keys::generated_reference_page();
    for t in TABLES {
        let part = keys::init_table(t);
        let section = page
            .split(&format!("\n## `{}`\n", t.title()))
            .nth(1)
            .unwrap_or_else(|| panic!("no section {} in the reference", t.title()));
        let section = section.split("\n## ").next().unwrap();
        for k in t.keys() {
            assert!(
                shows(&part, k.name),
                "{} {} not in femu init's file",
                t.title(),
                k.name
            );
            assert!(
                section.contains(&format!("| `{}` |", k.name)),
                "{} {} not in the reference",
                t.title(),
                k.name
            );
        }
    }
}

/// A key added to the schema's declarations appears in the reference and in `femu init`'s file
/// without touching either: here a key declared at test time in `[identification]` and in a
/// table of its own.
#[test]
fn a_new_key_appears_in_init_and_the_reference() {
    let new_key = KeySpec {
        name: "trust_radius",
        ty: Ty::Real,
        unit: "",
        allowed: Allowed::Real {
            min: 0.0,
            min_open: true,
            max: 10.0,
            max_open: false,
        },
        default: Def::Value("0.5"),
        doc: "the step bound of the optimizer",
        init: Init::Default,
        comment: "largest step, relative",
    };
    let mut tables: Vec<TableSpec> = TABLES.to_vec();
    let at = tables
        .iter()
        .position(|t| t.name == "identification")
        .unwrap();
    let mut items = tables[at].items.to_vec();
    items.push(Item::Key(new_key));
    tables[at].items = Box::leak(items.into_boxed_slice());
    let new_table = TableSpec {
        name: "solver",
        array: false,
        doc: "The nonlinear solver.",
        banner: "The solver.",
        header: keys::Header::Commented,
        header_comment: "",
        tight: false,
        items: Box::leak(Box::new([Item::Key(KeySpec {
            name: "line_search",
            ty: Ty::Bool,
            default: Def::Value("true"),
            allowed: Allowed::Any,
            doc: "backtracking on the residual",
            comment: "",
            ..new_key
        })])),
    };
    tables.push(new_table);

    let before_init = keys::init_file(TABLES);
    let before_page = keys::reference_page(TABLES);
    let init = keys::init_file(&tables);
    let page = keys::reference_page(&tables);
    // Not there before; there after, in its table, with its default, comment and range.
    assert!(!before_init.contains("trust_radius") && !before_page.contains("trust_radius"));
    let ident = keys::init_table(&tables[at]);
    assert!(
        ident.contains("trust_radius = 0.5               # largest step, relative\n"),
        "{ident}"
    );
    assert!(page.contains(
        "| `trust_radius` | number |  | (0, 10] | `0.5` | the step bound of the optimizer |"
    ));
    assert!(
        init.contains("# [solver]\n# line_search = true\n"),
        "{init}"
    );
    assert!(page.contains("\n## `[solver]`\n\nThe nonlinear solver.\n"));
    assert!(page.contains("| `line_search` | boolean |"));
    assert!(page.contains("[`[solver]`](#solver)"));
    // Nothing else changed.
    let line = "trust_radius = 0.5               # largest step, relative\n";
    let solver = keys::init_table(&tables[tables.len() - 1]);
    assert_eq!(init.replace(line, "").replace(&solver, ""), before_init);
}

/// The generated file is a valid study: `femu init`'s output parses (the same study as the empty
/// one is `schema::unit_tests::the_example_study_is_the_default`).
#[test]
fn the_generated_init_file_parses() {
    schema::parse(&keys::generated_init_file(), Path::new(".")).unwrap();
}
