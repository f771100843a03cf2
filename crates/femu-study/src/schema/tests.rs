//! `[[test]]`: the loading tests of the study (seed §2.1.2.3, Fig. 3), the seed's three by
//! default.

use super::lines::KeyLines;
use super::raw::TestEntry;
use super::StudyError;
use femu_mech::loading::{Loading, Side};
use femu_mesh::MMHG_IN_MPA;

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
        Loading::SEED_CONTENTION,
        Loading::SEED_COMPRESSION,
        Loading::Indentation {
            site: Side::Anterior,
            radius: 10.0,
            force: 0.1,
        },
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
    let at = |key: &str| format!("{} ({})", lines.at("test", k, key), t.kind);
    let err = |key: &str, message: String| StudyError::key(at(key), message);
    let positive = |key: &str, v: f64| -> Result<f64, StudyError> {
        if !(v > 0.0 && v.is_finite()) {
            return Err(err(key, format!("must be positive and finite, got {v}")));
        }
        Ok(v)
    };
    let side = || -> Result<Side, StudyError> {
        Side::parse(t.side.as_deref().unwrap_or("anterior")).map_err(|e| err("side", e))
    };
    let force = || -> Result<f64, StudyError> {
        let f = t
            .force_n_per_mm
            .ok_or_else(|| err("", "force_n_per_mm is missing".into()))?;
        positive("force_n_per_mm", f)
    };
    let kind = t.kind.to_ascii_lowercase();
    let loading = match kind.as_str() {
        "contention" => {
            let p = match (t.pressure_mmhg, t.pressure_mpa) {
                (Some(_), Some(_)) => {
                    return Err(err(
                        "pressure_mpa",
                        "give pressure_mmhg or pressure_mpa".into(),
                    ))
                }
                (Some(mmhg), None) => positive("pressure_mmhg", mmhg)? * MMHG_IN_MPA,
                (None, Some(mpa)) => positive("pressure_mpa", mpa)?,
                (None, None) => 20.0 * MMHG_IN_MPA,
            };
            Loading::Contention { pressure: p }
        }
        "compression" => Loading::Compression {
            side: side()?,
            force: force()?,
        },
        "indentation" => Loading::Indentation {
            site: side()?,
            radius: positive("radius_mm", t.radius_mm.unwrap_or(10.0))?,
            force: force()?,
        },
        other => {
            return Err(lines.err(
                "test",
                k,
                "kind",
                format!("unknown kind '{other}' (contention, compression, indentation)"),
            ))
        }
    };
    let extra = match kind.as_str() {
        "contention" => t.side.is_some() || t.force_n_per_mm.is_some() || t.radius_mm.is_some(),
        "compression" => {
            t.pressure_mmhg.is_some() || t.pressure_mpa.is_some() || t.radius_mm.is_some()
        }
        _ => t.pressure_mmhg.is_some() || t.pressure_mpa.is_some(),
    };
    if extra {
        return Err(err("", "a key of another kind of test is given".into()));
    }
    Ok(TestSpec {
        loading,
        curve: t.curve.clone(),
    })
}
