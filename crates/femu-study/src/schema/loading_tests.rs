//! `[[test]]`: the loading tests of the study (seed §2.1.2.3, Fig. 3), the seed's three by
//! default. Each `kind` is a registered loading test (`femu_mech::loading::TEST_KINDS`) that
//! declares and checks its own keys.

use super::lines::KeyLines;
use super::raw::TestEntry;
use super::StudyError;
use femu_mech::loading::{KeyValue, Loading, TestKeys, TestKind, TEST_KINDS};

/// A loading test of the study and, for a Gmsh mesh, the physical curve it acts on (the skin
/// otherwise).
#[derive(Debug, Clone, PartialEq)]
pub struct TestSpec {
    pub loading: Loading,
    pub curve: Option<String>,
}

/// The seed's three tests (contention 20 mmHg, compression 0.1 N/mm anterior, indentation
/// R = 10 mm, 0.1 N/mm anterior): the tests of a study that names none.
pub fn seed_tests() -> Vec<TestSpec> {
    [
        Loading::seed_contention(),
        Loading::seed_compression(),
        Loading::anterior_indentation(0.1),
    ]
    .into_iter()
    .map(|loading| TestSpec {
        loading,
        curve: None,
    })
    .collect()
}

/// Checks the `[[test]]` entries (`None`: the table is absent, the seed's tests).
pub(crate) fn parse(
    entries: Option<&[TestEntry]>,
    lines: &KeyLines,
) -> Result<Vec<TestSpec>, StudyError> {
    let Some(entries) = entries else {
        return Ok(seed_tests());
    };
    if entries.is_empty() {
        return Err(StudyError::Study(
            "test = []: give at least one [[test]] (or leave the key out for the seed's three)"
                .into(),
        ));
    }
    let mut tests: Vec<TestSpec> = Vec::new();
    for (k, t) in entries.iter().enumerate() {
        let spec = parse_one(k, t, lines)?;
        if tests
            .iter()
            .any(|o| o.loading.name() == spec.loading.name())
        {
            return Err(StudyError::key(
                format!("{} ({})", lines.at("test", k, ""), t.kind),
                format!(
                    "a second test named {} (one per kind and side)",
                    spec.loading.name()
                ),
            ));
        }
        tests.push(spec);
    }
    Ok(tests)
}

fn parse_one(k: usize, t: &TestEntry, lines: &KeyLines) -> Result<TestSpec, StudyError> {
    let kind = TestKind::find(&t.kind).ok_or_else(|| {
        lines.err(
            "test",
            k,
            "kind",
            format!(
                "unknown kind '{}' ({})",
                t.kind.to_ascii_lowercase(),
                TEST_KINDS
                    .iter()
                    .map(|k| k.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    let at = |key: &str| format!("{} ({})", lines.at("test", k, key), t.kind);
    let mut keys = TestKeys::new();
    for (name, v) in &t.keys {
        let value = match v {
            toml::Value::Float(f) => KeyValue::Number(*f),
            toml::Value::Integer(i) => KeyValue::Number(*i as f64),
            toml::Value::String(s) => KeyValue::Text(s.clone()),
            other => {
                return Err(StudyError::key(
                    at(name),
                    format!("must be a number or a text, got {other}"),
                ))
            }
        };
        keys.insert(name.clone(), value);
    }
    let loading = kind
        .parse(&keys)
        .map_err(|e| StudyError::key(at(&e.key), e.message))?;
    Ok(TestSpec {
        loading,
        curve: t.curve.clone(),
    })
}
