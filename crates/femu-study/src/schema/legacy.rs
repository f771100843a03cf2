//! Older layouts of the study file, read as views of the one schema.
//!
//! Before the schema was one, `femu solve MESH.msh --study S.toml` and `femu convergence S.toml`
//! read files of their own. Those files keep working: their tables are moved to where the
//! schema has them before the file is checked, and every moved key remembers its line.
//!
//! | older file | key | in the schema |
//! |---|---|---|
//! | Gmsh study | `element = "CPE4"` | `[model] element` |
//! | Gmsh and convergence studies | `[compression]`, `[indentation]` | a `[[test]]` of that kind |
//! | convergence study | `[contention] mmhg` | `[[test]] kind = "contention"`, `pressure_mmhg` |
//! | convergence study | `elements = [...]` | `[convergence] element_types` |
//! | convergence study | `target_elements`, `element_size_mm`, `tolerance_mm`, `locking`, `d_scale`, `locking_meshes`, `raster_mm` | `[convergence]` |

use toml::{Table, Value};

/// A key moved by [`translate`]: where the schema has it, and where the file had it.
#[derive(Debug, Clone)]
pub(crate) struct Moved {
    pub table: String,
    pub index: usize,
    pub key: String,
    pub old_table: String,
    pub old_key: String,
}

const CONVERGENCE_KEYS: [&str; 7] = [
    "target_elements",
    "element_size_mm",
    "tolerance_mm",
    "locking",
    "d_scale",
    "locking_meshes",
    "raster_mm",
];

/// Moves the older layouts' keys into the schema's tables (see the module documentation);
/// returns what moved.
pub(crate) fn translate(doc: &mut Table) -> Vec<Moved> {
    let mut moved = Vec::new();
    let mut note = |table: &str, index: usize, key: &str, old_table: &str, old_key: &str| {
        moved.push(Moved {
            table: table.into(),
            index,
            key: key.into(),
            old_table: old_table.into(),
            old_key: old_key.into(),
        })
    };
    // Top-level `element` (a string) of the Gmsh study.
    if let Some(v @ Value::String(_)) = doc.get("element").cloned() {
        doc.remove("element");
        table_of(doc, "model").insert("element".into(), v);
        note("model", 0, "element", "", "element");
    }
    // Top-level keys of the convergence study.
    if let Some(v @ Value::Array(_)) = doc.get("elements").cloned() {
        doc.remove("elements");
        table_of(doc, "convergence").insert("element_types".into(), v);
        note("convergence", 0, "element_types", "", "elements");
    }
    for key in CONVERGENCE_KEYS {
        if let Some(v) = doc.remove(key) {
            table_of(doc, "convergence").insert(key.into(), v);
            note("convergence", 0, key, "", key);
        }
    }
    // Single-test tables.
    let mut tests = Vec::new();
    for kind in ["contention", "compression", "indentation"] {
        let Some(Value::Table(mut t)) = doc.remove(kind) else {
            continue;
        };
        let index = doc
            .get("test")
            .and_then(Value::as_array)
            .map_or(0, Vec::len)
            + tests.len();
        for key in t.keys() {
            let new_key = if kind == "contention" && key == "mmhg" {
                "pressure_mmhg"
            } else {
                key.as_str()
            };
            note("test", index, new_key, kind, key);
        }
        note("test", index, "", kind, "");
        if let Some(v) = t.remove("mmhg") {
            t.insert("pressure_mmhg".into(), v);
        }
        t.insert("kind".into(), Value::String(kind.into()));
        tests.push(Value::Table(t));
    }
    if !tests.is_empty() {
        let entry = doc
            .entry("test")
            .or_insert_with(|| Value::Array(Vec::new()));
        if let Value::Array(a) = entry {
            a.extend(tests);
        }
    }
    moved
}

/// The sub-table `name` of `doc`, created if absent (a non-table value is replaced: the
/// typed check then reports the conflict).
fn table_of<'a>(doc: &'a mut Table, name: &str) -> &'a mut Table {
    let entry = doc
        .entry(name.to_string())
        .or_insert_with(|| Value::Table(Table::new()));
    if !entry.is_table() {
        *entry = Value::Table(Table::new());
    }
    entry.as_table_mut().expect("a table")
}
