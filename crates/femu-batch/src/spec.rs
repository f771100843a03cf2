//! The batch file: which studies to run. Either a TOML batch file — a template study and a table
//! of per-case values (a CSV file or `[[case]]` entries), the Slurm resources — or a CSV
//! manifest whose rows name their own study files.
//!
//! ```toml
//! template = "study.toml"      # the study every case starts from (relative to this file)
//! cases = "cases.csv"          # one row per case; or [[case]] entries below
//! jobs = 2                     # cases at once on this machine (femu batch run --jobs)
//!
//! [slurm]                      # resources of each array task (femu batch run --slurm)
//! cpus_per_task = 2
//! mem = "4G"
//! time = "01:00:00"
//! partition = "compute"
//!
//! [[case]]                     # instead of `cases = ...`
//! case = "s01-left"
//! subject = "s01"              # a plain key: a variable (${subject} in the template's strings)
//! labels.slice = 12            # a dotted key: the study's [labels] slice for this case
//! ```
//!
//! A table's columns are read the same way: `case` (the case's name and folder; `case-001`, ...
//! by default), `study` (this row's own study file instead of the template), plain names
//! (variables: `subject`, `side`, `session`; they appear in the collected table and fill `${name}`
//! in the template's strings), and dotted study keys (`materials.fat.c10_kpa`, `labels.image`,
//! `identification.seed`, `test.2.force_n_per_mm` for the second `[[test]]`). An empty cell
//! keeps the template's value. Relative file names in a row start from the table's folder.

pub use crate::error::SpecError;
use crate::slurm::SlurmResources;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Where a case comes from, for messages: `cases.csv line 4`, `batch.toml [[case]] 2 (line 9)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Origin {
    pub file: PathBuf,
    pub line: usize,
    /// The entry of a TOML batch file's `[[case]]` array (1-based), `None` for a table row.
    pub entry: Option<usize>,
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let name = self.file.file_name().map_or_else(
            || self.file.display().to_string(),
            |n| n.to_string_lossy().into(),
        );
        match self.entry {
            Some(k) => write!(f, "{name} [[case]] {k} (line {})", self.line),
            None => write!(f, "{name} line {}", self.line),
        }
    }
}

/// A per-case value: a table cell (typed by the template's value at its key) or a TOML value.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    Text(String),
    Value(toml::Value),
}

/// A study key set by a case: its dotted path and value, and the column (or key) that set it.
#[derive(Debug, Clone, PartialEq)]
pub struct KeySetting {
    pub path: Vec<String>,
    pub value: Cell,
    pub column: String,
}

/// One case as the batch file gives it, before its study is written.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseInput {
    pub name: Option<String>,
    /// This case's own study file (instead of the template).
    pub study: Option<PathBuf>,
    /// Variables in column order (`subject`, `side`, ...).
    pub vars: Vec<(String, String)>,
    pub keys: Vec<KeySetting>,
    /// The folder relative file names of this case start from.
    pub base: PathBuf,
    pub origin: Origin,
}

/// A read batch file.
#[derive(Debug, Clone)]
pub struct BatchFile {
    /// The batch file (absolute).
    pub path: PathBuf,
    pub template: Option<PathBuf>,
    pub cases: Vec<CaseInput>,
    pub slurm: SlurmResources,
    pub jobs: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBatch {
    template: Option<String>,
    cases: Option<String>,
    #[serde(default)]
    case: Vec<toml::Table>,
    slurm: Option<SlurmResources>,
    jobs: Option<usize>,
}

/// Reads a batch file: TOML (`.toml`) or a CSV manifest (any other name).
pub fn read(path: &Path) -> Result<BatchFile, SpecError> {
    let path = std::path::absolute(path)
        .map_err(|e| SpecError(format!("batch file {}: {e}", path.display())))?;
    let text = std::fs::read_to_string(&path)
        .map_err(|e| SpecError(format!("cannot read batch file {}: {e}", path.display())))?;
    let base = path.parent().unwrap_or(Path::new("/")).to_path_buf();
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    {
        return parse_toml(&text, &path, &base);
    }
    let cases = read_table(&text, &path)?;
    if let Some(c) = cases.iter().find(|c| c.study.is_none()) {
        return Err(SpecError(format!(
            "{}: no study for this case: a CSV manifest names each row's study file in a `study` column (or use a TOML batch file with a template)",
            c.origin
        )));
    }
    Ok(BatchFile {
        path,
        template: None,
        cases,
        slurm: SlurmResources::default(),
        jobs: None,
    })
}

fn parse_toml(text: &str, path: &Path, base: &Path) -> Result<BatchFile, SpecError> {
    let raw: RawBatch = toml::from_str(text)
        .map_err(|e| SpecError(format!("batch file {}: {e}", path.display())))?;
    let at = |what: &str| format!("batch file {}: {what}", path.display());
    let cases = match (&raw.cases, raw.case.is_empty()) {
        (Some(_), false) => {
            return Err(SpecError(at(
                "give the cases once: `cases = \"TABLE.csv\"` or [[case]] entries, not both",
            )))
        }
        (None, true) => {
            return Err(SpecError(at(
                "no case: give `cases = \"TABLE.csv\"` or [[case]] entries",
            )))
        }
        (Some(table), true) => {
            let table = femu_study::schema::files::resolve_from(base, table);
            let text = std::fs::read_to_string(&table).map_err(|e| {
                SpecError(at(&format!("cases: cannot read {}: {e}", table.display())))
            })?;
            read_table(&text, &table)?
        }
        (None, false) => {
            let lines = case_lines(text);
            raw.case
                .iter()
                .enumerate()
                .map(|(k, entry)| {
                    let origin = Origin {
                        file: path.to_path_buf(),
                        line: lines.get(k).copied().unwrap_or(0),
                        entry: Some(k + 1),
                    };
                    case_from_toml(entry, base, origin)
                })
                .collect::<Result<_, _>>()?
        }
    };
    if raw.jobs == Some(0) {
        return Err(SpecError(at("jobs must be at least 1")));
    }
    let slurm = raw.slurm.unwrap_or_default();
    slurm
        .check()
        .map_err(|e| SpecError(at(&format!("[slurm] {e}"))))?;
    let template = raw
        .template
        .map(|t| femu_study::schema::files::resolve_from(base, &t));
    if template.is_none() {
        if let Some(c) = cases.iter().find(|c| c.study.is_none()) {
            return Err(SpecError(format!(
                "{}: no study for this case: give `template = \"study.toml\"` in the batch file or a `study` for the case",
                c.origin
            )));
        }
    }
    Ok(BatchFile {
        path: path.to_path_buf(),
        template,
        cases,
        slurm,
        jobs: raw.jobs,
    })
}

/// The line of each `[[case]]` header of a TOML text, in order.
fn case_lines(text: &str) -> Vec<usize> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| {
            l.trim()
                .strip_prefix("[[")
                .and_then(|r| r.split("]]").next())
                .is_some_and(|n| n.trim() == "case")
        })
        .map(|(k, _)| k + 1)
        .collect()
}

/// A `[[case]]` entry: `case`, `study`, plain values (variables) and tables (study keys).
fn case_from_toml(
    entry: &toml::Table,
    base: &Path,
    origin: Origin,
) -> Result<CaseInput, SpecError> {
    let mut case = CaseInput {
        name: None,
        study: None,
        vars: Vec::new(),
        keys: Vec::new(),
        base: base.to_path_buf(),
        origin,
    };
    for (key, value) in entry {
        match (key.as_str(), value) {
            ("case", toml::Value::String(s)) => case.name = Some(s.clone()),
            ("study", toml::Value::String(s)) => {
                case.study = Some(femu_study::schema::files::resolve_from(base, s))
            }
            ("case" | "study", v) => {
                return Err(SpecError(format!(
                    "{}: {key} must be a string, got {v}",
                    case.origin
                )))
            }
            (_, toml::Value::Table(t)) => flatten(t, &mut vec![key.clone()], &mut case.keys),
            (_, toml::Value::Array(_)) => {
                return Err(SpecError(format!(
                    "{}: {key}: a plain value is a variable (text or number); study keys are dotted (`materials.fat.c10_kpa = 0.9`)",
                    case.origin
                )))
            }
            (_, v) => {
                check_variable_name(key, &case.origin)?;
                let text = match v {
                    toml::Value::String(s) => s.clone(),
                    v => v.to_string(),
                };
                case.vars.push((key.clone(), text));
            }
        }
    }
    Ok(case)
}

/// The leaves of `table` as dotted settings (arrays are values: a `[[test]]` list replaces the
/// template's).
fn flatten(table: &toml::Table, prefix: &mut Vec<String>, out: &mut Vec<KeySetting>) {
    for (k, v) in table {
        prefix.push(k.clone());
        match v {
            toml::Value::Table(t) => flatten(t, prefix, out),
            v => out.push(KeySetting {
                path: prefix.clone(),
                value: Cell::Value(v.clone()),
                column: prefix.join("."),
            }),
        }
        prefix.pop();
    }
}

fn check_variable_name(name: &str, origin: &Origin) -> Result<(), SpecError> {
    let ok = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(SpecError(format!(
            "{origin}: `{name}` is neither a variable name (letters, digits, _ and -) nor a dotted study key"
        )))
    }
}

/// The cases of a CSV table (header line first; `#` comment lines; cells trimmed).
pub fn read_table(text: &str, path: &Path) -> Result<Vec<CaseInput>, SpecError> {
    let base = path.parent().unwrap_or(Path::new("/")).to_path_buf();
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let name = path.display();
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| SpecError(format!("{name}: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    let header_origin = Origin {
        file: path.to_path_buf(),
        line: 1,
        entry: None,
    };
    let mut seen = std::collections::BTreeSet::new();
    for col in &header {
        if !seen.insert(col.as_str()) {
            return Err(SpecError(format!("{header_origin}: column `{col}` twice")));
        }
        if col.contains('.') {
            if col.split('.').any(str::is_empty) {
                return Err(SpecError(format!(
                    "{header_origin}: column `{col}`: an empty part in a dotted study key"
                )));
            }
        } else if col != "case" && col != "study" {
            check_variable_name(col, &header_origin)?;
        }
    }
    let mut cases = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| SpecError(format!("{name}: {e}")))?;
        let origin = Origin {
            file: path.to_path_buf(),
            line: record.position().map_or(0, |p| p.line() as usize),
            entry: None,
        };
        let mut case = CaseInput {
            name: None,
            study: None,
            vars: Vec::new(),
            keys: Vec::new(),
            base: base.clone(),
            origin,
        };
        for (col, cell) in header.iter().zip(record.iter()) {
            match col.as_str() {
                "case" => case.name = (!cell.is_empty()).then(|| cell.to_string()),
                "study" if !cell.is_empty() => {
                    case.study = Some(femu_study::schema::files::resolve_from(&base, cell))
                }
                "study" => {}
                c if c.contains('.') => {
                    if !cell.is_empty() {
                        case.keys.push(KeySetting {
                            path: c.split('.').map(str::to_string).collect(),
                            value: Cell::Text(cell.to_string()),
                            column: c.to_string(),
                        });
                    }
                }
                c => case.vars.push((c.to_string(), cell.to_string())),
            }
        }
        cases.push(case);
    }
    if cases.is_empty() {
        return Err(SpecError(format!(
            "{name}: no case (a header line and no row)"
        )));
    }
    Ok(cases)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> Result<Vec<CaseInput>, SpecError> {
        read_table(text, Path::new("/data/cases.csv"))
    }

    #[test]
    fn a_table_gives_names_variables_and_keys() {
        let cases = table(
            "# subjects of the pilot\ncase,subject,materials.fat.c10_kpa,labels.image,study\n\
             s01,s01,0.9,mri/s01.png,\n\"s02\", s02 ,,mri/s02.png,other.toml\n",
        )
        .unwrap();
        assert_eq!(cases.len(), 2);
        assert_eq!(cases[0].name.as_deref(), Some("s01"));
        assert_eq!(cases[0].origin.to_string(), "cases.csv line 3");
        assert_eq!(cases[1].origin.line, 4);
        assert_eq!(cases[0].vars, vec![("subject".into(), "s01".into())]);
        assert_eq!(cases[1].vars, vec![("subject".into(), "s02".into())]);
        assert_eq!(cases[0].keys.len(), 2);
        assert_eq!(cases[0].keys[0].path, ["materials", "fat", "c10_kpa"]);
        // The empty cell keeps the template's value.
        assert_eq!(cases[1].keys.len(), 1);
        assert_eq!(cases[1].study, Some(PathBuf::from("/data/other.toml")));
        assert_eq!(cases[0].study, None);
    }

    #[test]
    fn bad_tables_are_named() {
        let e = table("case,case\na,b\n").unwrap_err().to_string();
        assert!(e.contains("line 1") && e.contains("`case` twice"), "{e}");
        let e = table("case,materials..c10_kpa\na,1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("empty part"), "{e}");
        let e = table("case,sub ject\na,1\n").unwrap_err().to_string();
        assert!(e.contains("sub ject"), "{e}");
        let e = table("case,x\na,1,2\n").unwrap_err().to_string();
        assert!(e.contains("cases.csv"), "{e}");
        let e = table("case,x\n").unwrap_err().to_string();
        assert!(e.contains("no case"), "{e}");
    }

    #[test]
    fn toml_cases_flatten_their_tables() {
        let text = "template = \"study.toml\"\n[slurm]\ncpus_per_task = 2\n\n[[case]]\ncase = \"a\"\nsubject = \"s01\"\nseed = 3\nmaterials.fat.c10_kpa = 0.9\n[[case]]\ncase = \"b\"\n[case.identification]\nseed = 4\n";
        let b = parse_toml(text, Path::new("/d/batch.toml"), Path::new("/d")).unwrap();
        assert_eq!(b.template, Some(PathBuf::from("/d/study.toml")));
        assert_eq!(b.slurm.cpus_per_task, Some(2));
        assert_eq!(b.cases.len(), 2);
        let a = &b.cases[0];
        assert_eq!(a.origin.to_string(), "batch.toml [[case]] 1 (line 5)");
        assert_eq!(
            a.vars,
            vec![
                ("seed".into(), "3".into()),
                ("subject".into(), "s01".into())
            ]
        );
        assert_eq!(a.keys[0].column, "materials.fat.c10_kpa");
        assert_eq!(
            a.keys[0].value,
            Cell::Value(toml::Value::Float(0.9)),
            "a TOML value keeps its type"
        );
        assert_eq!(b.cases[1].origin.line, 10);
        assert_eq!(b.cases[1].keys[0].path, ["identification", "seed"]);
        for (bad, says) in [
            ("[[case]]\ncase = \"a\"\n", "no study"),
            ("template = \"s.toml\"\n", "no case"),
            (
                "template = \"s.toml\"\ncases = \"c.csv\"\n[[case]]\n",
                "not both",
            ),
            (
                "template = \"s.toml\"\nfoo = 1\n[[case]]\n",
                "unknown field",
            ),
            (
                "template = \"s.toml\"\n[slurm]\nmem = \"lots\"\n[[case]]\n",
                "[slurm] mem",
            ),
            (
                "template = \"s.toml\"\n[[case]]\nlist = [1, 2]\n",
                "[[case]] 1 (line 2): list",
            ),
        ] {
            let e = parse_toml(bad, Path::new("/d/batch.toml"), Path::new("/d"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(says), "{bad:?}: {e}");
        }
    }
}
