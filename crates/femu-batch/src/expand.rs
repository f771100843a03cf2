//! The study of each case: its template (or its own study file) with the case's values put in,
//! file names made absolute (the case runs in its own folder), `${name}` filled from the case's
//! variables — and checked by femu-study's schema, with the files it names, before anything
//! runs. Every bad case is reported at once, each with its row and key.

pub use crate::error::CaseErrors;
use crate::folder::fingerprint;
use crate::spec::{BatchFile, CaseInput, Cell, KeySetting};
use femu_study::schema::files::{absolute_file_names, is_file_key, resolve_from};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A case ready to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    pub name: String,
    /// `cases.csv line 4`.
    pub origin: String,
    pub vars: Vec<(String, String)>,
    /// The case's study file (TOML), checked.
    pub text: String,
    pub fingerprint: String,
}

/// The cases of `batch`, each checked; every problem reported together.
pub fn expand(batch: &BatchFile) -> Result<Vec<Case>, CaseErrors> {
    let mut templates: BTreeMap<PathBuf, Result<toml::Table, String>> = BTreeMap::new();
    let mut problems = Vec::new();
    let mut cases = Vec::new();
    let mut names: BTreeMap<String, String> = BTreeMap::new();
    for (k, input) in batch.cases.iter().enumerate() {
        let name = input
            .name
            .clone()
            .unwrap_or_else(|| format!("case-{:03}", k + 1));
        let at = format!("case {name} ({})", input.origin);
        if let Err(e) = check_name(&name) {
            problems.push(format!("{at}: {e}"));
            continue;
        }
        if let Some(first) = names.insert(name.clone(), input.origin.to_string()) {
            problems.push(format!("{at}: the name is taken by {first}"));
            continue;
        }
        let Some(study) = input.study.as_ref().or(batch.template.as_ref()) else {
            problems.push(format!("{at}: no study file"));
            continue;
        };
        let template = templates
            .entry(study.clone())
            .or_insert_with(|| read_template(study))
            .clone();
        match template.and_then(|t| case_study(&t, study, input, &name)) {
            Ok(text) => match check(&text, input) {
                Ok(()) => cases.push(Case {
                    fingerprint: fingerprint(&text),
                    name,
                    origin: input.origin.to_string(),
                    vars: input.vars.clone(),
                    text,
                }),
                Err(e) => problems.push(format!("{at}: {e}")),
            },
            Err(e) => problems.push(format!("{at}: {e}")),
        }
    }
    if problems.is_empty() {
        Ok(cases)
    } else {
        Err(CaseErrors {
            problems,
            total: batch.cases.len(),
        })
    }
}

/// A case's name is its folder: letters, digits, `.`, `_`, `-`; not starting with a dot.
fn check_name(name: &str) -> Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= 100
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "the case name `{name}` is a folder name: use letters, digits, '.', '_' and '-' (up to 100, not starting with '.')"
        ))
    }
}

fn read_template(path: &Path) -> Result<toml::Table, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read study file {}: {e}", path.display()))?;
    let mut doc: toml::Table = text
        .parse()
        .map_err(|e| format!("study file {}: {e}", path.display()))?;
    absolute_file_names(&mut doc, path.parent().unwrap_or(Path::new("/")));
    Ok(doc)
}

/// The study text of case `name`: `template` (read from `study`, file names already absolute)
/// with the case's keys set and its variables filled in.
fn case_study(
    template: &toml::Table,
    study: &Path,
    input: &CaseInput,
    name: &str,
) -> Result<String, String> {
    let mut doc = template.clone();
    for setting in &input.keys {
        set_key(&mut doc, setting, &input.base)?;
    }
    let mut vars: BTreeMap<&str, &str> = input
        .vars
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    vars.insert("case", name);
    fill_table(&mut doc, &vars, &mut Vec::new())?;
    let body = toml::to_string(&doc).map_err(|e| format!("cannot write the case's study: {e}"))?;
    let mut header = format!(
        "# femu batch: case {name} ({}), from {}\n",
        input.origin,
        study.display()
    );
    for (k, v) in &input.vars {
        header.push_str(&format!("# {k} = {v}\n"));
    }
    Ok(format!("{header}\n{body}"))
}

/// Sets one study key of the case in `doc`.
fn set_key(doc: &mut toml::Table, setting: &KeySetting, base: &Path) -> Result<(), String> {
    let column = &setting.column;
    let path: Vec<&str> = setting.path.iter().map(String::as_str).collect();
    let existing = get_path(doc, &path);
    let mut value = match &setting.value {
        Cell::Value(v) => v.clone(),
        Cell::Text(t) => {
            typed_cell(t, existing).map_err(|e| format!("column {column} = \"{t}\": {e}"))?
        }
    };
    if is_file_key(&path) {
        if let toml::Value::String(s) = &mut value {
            *s = resolve_from(base, s).to_string_lossy().into_owned();
        }
    }
    set_path(doc, &path, value, "").map_err(|e| format!("column {column}: {e}"))
}

/// A table cell as the TOML value the template has at its key: text for text, a number for a
/// number, ...; a key the template lacks takes the cell as a TOML value if it is one (`12`,
/// `0.9`, `true`, `[1, 2]`), else as text.
fn typed_cell(text: &str, existing: Option<&toml::Value>) -> Result<toml::Value, String> {
    use toml::Value as V;
    match existing {
        Some(V::String(_)) => Ok(V::String(text.to_string())),
        Some(V::Integer(_)) => text
            .parse::<i64>()
            .map(V::Integer)
            .map_err(|_| "the template has a whole number here".to_string()),
        Some(V::Float(_)) => text
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .map(V::Float)
            .ok_or_else(|| "the template has a number here".to_string()),
        Some(V::Boolean(_)) => text
            .parse::<bool>()
            .map(V::Boolean)
            .map_err(|_| "the template has true or false here".to_string()),
        _ => Ok(toml_value(text).unwrap_or_else(|| V::String(text.to_string()))),
    }
}

/// `text` parsed as one TOML value, if it is one.
fn toml_value(text: &str) -> Option<toml::Value> {
    let mut t: toml::Table = format!("v = {text}").parse().ok()?;
    t.remove("v")
}

/// The key of `doc` (the table at dotted path `at`) that `key` names: itself, or under
/// `[materials]`, whose tables the study names by region whatever their case (`fat`, `FAT`),
/// the template's table of that region in the template's case, so that a column
/// `materials.fat.c20_kpa` sets the template's `[materials.FAT]` instead of adding a second
/// table of the region beside it.
fn key_in(doc: &toml::Table, key: &str, at: &str) -> String {
    if at != "materials" || doc.contains_key(key) {
        return key.to_string();
    }
    doc.keys()
        .find(|k| k.eq_ignore_ascii_case(key))
        .cloned()
        .unwrap_or_else(|| key.to_string())
}

/// The value at a dotted path (`test.2.side`: entry 2, from 1, of the `[[test]]` array).
fn get_path<'a>(doc: &'a toml::Table, path: &[&str]) -> Option<&'a toml::Value> {
    let (first, rest) = path.split_first()?;
    let mut v = doc.get(*first)?;
    let mut at = first.to_string();
    for seg in rest {
        v = match v {
            toml::Value::Table(t) => {
                let key = key_in(t, seg, &at);
                at = format!("{at}.{seg}");
                t.get(&key)?
            }
            toml::Value::Array(a) => a.get(seg.parse::<usize>().ok()?.checked_sub(1)?)?,
            _ => return None,
        };
    }
    Some(v)
}

/// Sets the value at a dotted path, creating the tables on the way; an entry of an array of
/// tables is named by its number from 1, as femu's messages name them (`[[test]] 2`). `at` is
/// the path above `doc` (for messages).
fn set_path(
    doc: &mut toml::Table,
    path: &[&str],
    value: toml::Value,
    at: &str,
) -> Result<(), String> {
    let (first, rest) = path.split_first().ok_or("an empty key")?;
    let key = key_in(doc, first, at);
    let key: &str = &key;
    let first = &key;
    if rest.is_empty() {
        doc.insert(first.to_string(), value);
        return Ok(());
    }
    let here = if at.is_empty() {
        first.to_string()
    } else {
        format!("{at}.{first}")
    };
    let index = rest[0].parse::<usize>().ok();
    if index.is_some() && !doc.contains_key(*first) {
        return Err(format!("the template has no [[{here}]] entries"));
    }
    let entry = doc
        .entry(first.to_string())
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    match (entry, index) {
        (toml::Value::Array(a), Some(index)) => {
            let n = a.len();
            let e = index
                .checked_sub(1)
                .and_then(|i| a.get_mut(i))
                .ok_or_else(|| {
                    format!(
                        "the template has {n} [[{here}]] entries (numbered from 1), not {index}"
                    )
                })?;
            match (e, &rest[1..]) {
                (e, []) => {
                    *e = value;
                    Ok(())
                }
                (toml::Value::Table(t), deeper) => {
                    set_path(t, deeper, value, &format!("{here}.{index}"))
                }
                (other, _) => Err(format!(
                    "[[{here}]] {index} is {}, not a table",
                    kind(other)
                )),
            }
        }
        (toml::Value::Table(t), None) => set_path(t, rest, value, &here),
        (toml::Value::Table(_), Some(_)) => Err(format!(
            "`{here}` is a table in the template, not a list of [[{here}]] entries"
        )),
        (other, _) => Err(format!(
            "`{here}` is {} in the template, not a table",
            kind(other)
        )),
    }
}

fn kind(v: &toml::Value) -> &'static str {
    match v {
        toml::Value::String(_) => "text",
        toml::Value::Integer(_) | toml::Value::Float(_) => "a number",
        toml::Value::Boolean(_) => "true/false",
        toml::Value::Datetime(_) => "a date",
        toml::Value::Array(_) => "a list",
        toml::Value::Table(_) => "a table",
    }
}

/// Fills `${name}` in every string of `table` from `vars`.
fn fill_table(
    table: &mut toml::Table,
    vars: &BTreeMap<&str, &str>,
    at: &mut Vec<String>,
) -> Result<(), String> {
    for (k, v) in table.iter_mut() {
        at.push(k.clone());
        fill_value(v, vars, at)?;
        at.pop();
    }
    Ok(())
}

fn fill_value(
    v: &mut toml::Value,
    vars: &BTreeMap<&str, &str>,
    at: &mut Vec<String>,
) -> Result<(), String> {
    match v {
        toml::Value::String(s) if s.contains("${") => {
            *s = fill(s, vars).map_err(|e| format!("{} = \"{s}\": {e}", at.join(".")))?;
        }
        toml::Value::Array(a) => {
            for (i, x) in a.iter_mut().enumerate() {
                at.push((i + 1).to_string());
                fill_value(x, vars, at)?;
                at.pop();
            }
        }
        toml::Value::Table(t) => fill_table(t, vars, at)?,
        _ => {}
    }
    Ok(())
}

/// `text` with each `${name}` replaced by its variable.
fn fill(text: &str, vars: &BTreeMap<&str, &str>) -> Result<String, String> {
    let mut out = String::new();
    let mut rest = text;
    while let Some(i) = rest.find("${") {
        out.push_str(&rest[..i]);
        let after = &rest[i + 2..];
        let j = after.find('}').ok_or("a `${` without its `}`")?;
        let name = &after[..j];
        let value = vars.get(name).ok_or_else(|| {
            let known: Vec<&str> = vars.keys().copied().collect();
            format!("no variable `{name}` (the case has: {})", known.join(", "))
        })?;
        out.push_str(value);
        rest = &after[j + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Checks a case's study with the schema, and what needs its files (they exist; the regions
/// of the model have materials; the fixed and grouped parameters are the model's).
fn check(text: &str, input: &CaseInput) -> Result<(), String> {
    let named = |e: femu_study::StudyError| {
        let msg = e.to_string();
        match column_named_in(&msg, &input.keys) {
            Some(col) => format!("{msg} (the value of column {col})"),
            None => msg,
        }
    };
    // File names are absolute by now: the base folder plays no part.
    let study = femu_study::parse(text, Path::new("/")).map_err(named)?;
    study.check_model_inputs().map_err(named)
}

/// The column whose key the schema's message names (`[materials.fat] c10_kpa`, `[[test]] 2
/// force_n_per_mm`), if a column of the case set it.
fn column_named_in<'a>(msg: &str, keys: &'a [KeySetting]) -> Option<&'a str> {
    keys.iter().find_map(|s| {
        let (key, table) = s.path.split_last()?;
        let named = match table {
            [array, index] if index.parse::<usize>().is_ok() => {
                format!("[[{array}]] {index} {key}")
            }
            _ => format!("[{}] {key}", table.join(".")),
        };
        msg.contains(&named).then_some(s.column.as_str())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::{read_table, Origin};

    const TEMPLATE: &str = "[model]\nelements = 700\n[[test]]\nkind = \"contention\"\n[[test]]\nkind = \"compression\"\nside = \"anterior\"\nforce_n_per_mm = 0.1\n[materials.fat]\nc10_kpa = 0.8\n[identification]\ntest = \"compression\"\nseed = 1\n[measurement]\nsource = \"file\"\nfile = \"fields/${subject}.csv\"\n";

    /// A batch in a scratch folder: the template, a table, the measured fields it names.
    fn batch(table: &str, fields: &[&str]) -> (BatchFile, PathBuf) {
        let dir = std::env::temp_dir().join(format!(
            "femu-batch-expand-{}-{}",
            std::process::id(),
            fingerprint(table)
        ));
        std::fs::create_dir_all(dir.join("fields")).unwrap();
        std::fs::write(dir.join("study.toml"), TEMPLATE).unwrap();
        for f in fields {
            std::fs::write(dir.join("fields").join(f), "x,y,ux,uy\n0,0,0,0\n").unwrap();
        }
        let path = dir.join("cases.csv");
        let cases = read_table(table, &path).unwrap();
        let b = BatchFile {
            path: dir.join("batch.toml"),
            template: Some(dir.join("study.toml")),
            cases,
            slurm: Default::default(),
            jobs: None,
        };
        (b, dir)
    }

    /// A column names a region's table in any case, as the study does: its value goes into
    /// the template's table of the region (with the law the template gives it), not into a
    /// second table beside it; other keys keep their case.
    #[test]
    fn a_column_sets_the_templates_table_of_its_region_whatever_its_case() {
        let mut doc: toml::Table =
            "[materials.FAT]\nlaw = \"yeoh\"\nc20_kpa = 0.3\n[model]\nelements = 700\n"
                .parse()
                .unwrap();
        let path = ["materials", "fat", "c20_kpa"];
        assert_eq!(get_path(&doc, &path).and_then(|v| v.as_float()), Some(0.3));
        set_path(&mut doc, &path, toml::Value::Float(0.35), "").unwrap();
        let materials = doc["materials"].as_table().unwrap();
        assert_eq!(materials.len(), 1, "{materials:?}");
        assert_eq!(materials["FAT"]["c20_kpa"].as_float(), Some(0.35));
        assert_eq!(materials["FAT"]["law"].as_str(), Some("yeoh"));
        set_path(
            &mut doc,
            &["Model", "elements"],
            toml::Value::Integer(800),
            "",
        )
        .unwrap();
        assert_eq!(doc["model"]["elements"].as_integer(), Some(700));
    }

    #[test]
    fn values_go_where_their_columns_say() {
        let (b, dir) = batch(
            "case,subject,materials.fat.c10_kpa,identification.seed,test.2.force_n_per_mm,materials.ischio.c10_kpa\n\
             s01,s01,0.9,7,0.2,3\ns02,s02,,8,,\n",
            &["s01.csv", "s02.csv"],
        );
        let cases = expand(&b).unwrap();
        assert_eq!(cases.len(), 2);
        let s = femu_study::parse(&cases[0].text, Path::new("/")).unwrap();
        assert_eq!(s.identification.seed, 7);
        let fat = s
            .model
            .materials
            .iter()
            .find(|m| m.region == "fat")
            .unwrap();
        assert_eq!(fat.keys, vec![("c10_kpa".to_string(), 0.9)]);
        // A whole number for a key the template lacks is still a number for the schema.
        let ischio = s
            .model
            .materials
            .iter()
            .find(|m| m.region == "ischio")
            .unwrap();
        assert_eq!(ischio.keys, vec![("c10_kpa".to_string(), 3.0)]);
        assert!(cases[0].text.contains("force_n_per_mm = 0.2"));
        // ${subject} filled, the file name made absolute from the template's folder.
        assert_eq!(s.input_files(), vec![dir.join("fields/s01.csv").as_path()]);
        // The empty cells keep the template's values.
        let s2 = femu_study::parse(&cases[1].text, Path::new("/")).unwrap();
        let fat2 = s2
            .model
            .materials
            .iter()
            .find(|m| m.region == "fat")
            .unwrap();
        assert_eq!(fat2.keys, vec![("c10_kpa".to_string(), 0.8)]);
        assert!(cases[1].text.contains("force_n_per_mm = 0.1"));
        assert_ne!(cases[0].fingerprint, cases[1].fingerprint);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn every_bad_case_is_named_with_its_row_and_key() {
        let (b, dir) = batch(
            "case,subject,materials.fat.c10_kpa,identification.seed,test.3.side,model.elements.x\n\
             ok,s01,0.9,1,,\nneg,s01,-1,1,,\nword,s01,soft,1,,\nnofile,s09,0.9,1,,\nbad/name,s01,,,,\n\
             ok,s01,,,,\nnotest,s01,,,lateral,\nscalar,s01,,,,3\nseed,s01,,1.5,,\n",
            &["s01.csv"],
        );
        let e = expand(&b).unwrap_err();
        let all = e.to_string();
        assert_eq!(e.total, 9);
        assert_eq!(e.problems.len(), 8, "{all}");
        let says = |case: &str, what: &[&str]| {
            let line = e
                .problems
                .iter()
                .find(|p| p.starts_with(&format!("case {case} ")))
                .unwrap_or_else(|| panic!("no problem for {case}: {all}"));
            for w in what {
                assert!(line.contains(w), "{case}: `{w}` not in: {line}");
            }
        };
        says(
            "neg",
            &[
                "cases.csv line 3",
                "[materials.fat] c10_kpa",
                "column materials.fat.c10_kpa",
            ],
        );
        says(
            "word",
            &[
                "line 4",
                "column materials.fat.c10_kpa = \"soft\"",
                "a number",
            ],
        );
        says(
            "nofile",
            &["line 5", "[measurement] file", "does not exist", "s09.csv"],
        );
        says("bad/name", &["line 6", "folder name"]);
        says("ok", &["line 7", "taken by cases.csv line 2"]);
        says(
            "notest",
            &["line 8", "column test.3.side", "2 [[test]] entries"],
        );
        says(
            "scalar",
            &[
                "line 9",
                "column model.elements.x",
                "`model.elements` is a number",
            ],
        );
        says(
            "seed",
            &["line 10", "column identification.seed", "whole number"],
        );
        std::fs::remove_dir_all(dir).ok();
    }

    /// A `[[measurement]]` list: `measurement.2.file` sets the second entry's file, made
    /// absolute from the table's folder.
    #[test]
    fn a_measurement_list_entry_takes_its_file() {
        let dir = std::env::temp_dir().join(format!("femu-batch-list-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("fields")).unwrap();
        std::fs::write(dir.join("fields/b.csv"), "x,y,ux,uy\n0,0,0,0\n").unwrap();
        let template: toml::Table = "[[measurement]]\ntest = \"contention\"\n[[measurement]]\ntest = \"compression\"\nsource = \"file\"\nfile = \"a.csv\"\n".parse().unwrap();
        let cases = read_table(
            "case,measurement.2.file,measurement.3.file\nx,fields/b.csv,\ny,,fields/b.csv\n",
            &dir.join("cases.csv"),
        )
        .unwrap();
        let text = case_study(&template, &dir.join("study.toml"), &cases[0], "x").unwrap();
        let doc: toml::Table = text.parse().unwrap();
        let file = get_path(&doc, &["measurement", "2", "file"]).unwrap();
        assert_eq!(
            file.as_str().unwrap(),
            dir.join("fields/b.csv").to_str().unwrap()
        );
        let e = case_study(&template, &dir.join("study.toml"), &cases[1], "y").unwrap_err();
        assert!(e.contains("2 [[measurement]] entries"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn placeholders() {
        let vars: BTreeMap<&str, &str> = [("subject", "s01"), ("case", "a")].into();
        assert_eq!(
            fill("mri/${subject}_${case}.png", &vars).unwrap(),
            "mri/s01_a.png"
        );
        assert!(fill("mri/${side}.png", &vars)
            .unwrap_err()
            .contains("no variable `side`"));
        assert!(fill("mri/${side.png", &vars).is_err());
        let input = CaseInput {
            name: None,
            study: None,
            vars: vec![],
            keys: vec![],
            base: PathBuf::from("/"),
            origin: Origin {
                file: PathBuf::from("/b.toml"),
                line: 3,
                entry: Some(1),
            },
        };
        let t: toml::Table = "[labels]\nimage = \"${nobody}.png\"\n".parse().unwrap();
        let e = case_study(&t, Path::new("/s.toml"), &input, "c").unwrap_err();
        assert!(e.contains("labels.image = \"${nobody}.png\""), "{e}");
    }
}
