//! The loading tests (seed §2.1.2.3, Fig. 3), one type each behind [`LoadingTest`], registered
//! in [`TEST_KINDS`] with the study-file keys they read:
//!
//! - [`contention::Contention`]: a follower pressure on the whole skin (20 mmHg = 2.666e-3 MPa);
//! - [`compression::Compression`]: a rigid flat plate pressed on one side of the thigh with a
//!   force (0.1 N per mm of thickness), frictionless, femur fixed;
//! - [`indentation::Indentation`]: a rigid cylindrical indenter pressed at one site.
//!
//! Sides are named in the cross-section frame used by every femu model: +y anterior,
//! -y posterior, +x lateral, -x medial (or any angle in degrees from +x, counter-clockwise).
//!
//! Adding a test: one file with a type implementing [`LoadingTest`] and its [`TestKind`] (name,
//! keys, builder), and one line in [`TEST_KINDS`] (see `docs/adding-a-material.md`).

pub mod compression;
pub mod contention;
pub mod indentation;

use crate::contact::{ContactError, RigidContact, RigidSurface, TravelControl};
use crate::model::Model;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

pub use compression::Compression;
pub use contention::Contention;
pub use indentation::Indentation;

/// Every loading test femu knows, by study-file `kind`.
pub static TEST_KINDS: [&TestKind; 3] = [&contention::KIND, &compression::KIND, &indentation::KIND];

/// A loading test: how a load acts on the skin of a model whose femur is fixed.
pub trait LoadingTest: Send + Sync + std::fmt::Debug {
    /// The registered kind.
    fn kind(&self) -> &'static TestKind;
    /// `contention`, `compression-anterior`, `indentation-medial`, ...: names its folders.
    fn name(&self) -> String;
    /// Adds the load to `model` on the skin faces `skin` (`(element, face)`).
    fn apply(&self, model: &mut Model, skin: &[(usize, usize)]) -> Result<(), LoadingError>;
    /// The same test with its load scaled by `s` (the load steps of an image sequence).
    fn scaled(&self, s: f64) -> Loading;
    /// The study-file keys and values that give this test (besides `kind`).
    fn keys(&self) -> Vec<(&'static str, KeyValue)>;
    /// Whether a force-controlled rigid body pushes (compression, indentation): the test has
    /// a travel (the actuator term) and moves the tissue by contact.
    fn has_rigid_body(&self) -> bool;
    /// The uniform follower pressure on the skin (MPa) when that is the whole test, so that it
    /// can be written as an Abaqus/CalculiX deck (`*DLOAD`); `None` otherwise.
    fn skin_pressure(&self) -> Option<f64> {
        None
    }
}

/// A loading test, shared.
#[derive(Debug, Clone)]
pub struct Loading(Arc<dyn LoadingTest>);

impl Loading {
    /// Wraps a test.
    pub fn new(test: impl LoadingTest + 'static) -> Loading {
        Loading(Arc::new(test))
    }

    /// The seed's contention: 20 mmHg.
    pub fn seed_contention() -> Loading {
        Loading::new(Contention {
            pressure: 20.0 * femu_mesh::MMHG_IN_MPA,
        })
    }

    /// The seed's compression: 0.1 N/mm, plate on the anterior side.
    pub fn seed_compression() -> Loading {
        Loading::new(Compression {
            side: Side::Anterior,
            force: 0.1,
        })
    }

    /// An indenter of radius 10 mm at the anterior site pushed with `force` N/mm (the seed:
    /// 3 N/mm; femu's default study: 0.1 N/mm, the compression's force).
    pub fn anterior_indentation(force: f64) -> Loading {
        Loading::new(Indentation {
            site: Side::Anterior,
            radius: 10.0,
            force,
        })
    }

    /// Whether the test is of kind `kind`.
    pub fn is(&self, kind: &TestKind) -> bool {
        std::ptr::eq(self.0.kind(), kind)
    }
}

impl std::ops::Deref for Loading {
    type Target = dyn LoadingTest;
    fn deref(&self) -> &Self::Target {
        &*self.0
    }
}

/// Two tests are the same when their kind and keys are.
impl PartialEq for Loading {
    fn eq(&self, other: &Loading) -> bool {
        std::ptr::eq(self.kind(), other.kind()) && self.keys() == other.keys()
    }
}

/// The value of a study-file key of a test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum KeyValue {
    Number(f64),
    Text(String),
}

/// A key a test kind reads from the study file.
#[derive(Debug, Clone, Copy)]
pub struct TestKey {
    pub name: &'static str,
    /// What it is, with its unit and default (for messages and `femu init`).
    pub doc: &'static str,
}

/// The study file's keys of one `[[test]]`, as given.
pub type TestKeys = std::collections::BTreeMap<String, KeyValue>;

/// A key of a test with a bad value.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyError {
    /// The key (empty: the test as a whole).
    pub key: String,
    pub message: String,
}

/// A kind of loading test, registered in [`TEST_KINDS`].
pub struct TestKind {
    /// The study file's `kind`.
    pub name: &'static str,
    /// One line on what it does.
    pub doc: &'static str,
    /// The keys it reads.
    pub keys: &'static [TestKey],
    /// Builds the test from its keys (checked against `keys` before).
    pub build: fn(&TestKeys) -> Result<Loading, KeyError>,
}

impl std::fmt::Debug for TestKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

impl TestKind {
    /// The registered kind named `name` (case-insensitive).
    pub fn find(name: &str) -> Option<&'static TestKind> {
        TEST_KINDS
            .iter()
            .copied()
            .find(|k| k.name.eq_ignore_ascii_case(name))
    }

    /// Checks that every key of `keys` is one of this kind's, then builds the test.
    pub fn parse(&self, keys: &TestKeys) -> Result<Loading, KeyError> {
        for k in keys.keys() {
            if !self.keys.iter().any(|known| known.name == k) {
                return Err(KeyError {
                    key: k.clone(),
                    message: format!(
                        "not a key of a {} test (its keys: {})",
                        self.name,
                        self.keys
                            .iter()
                            .map(|k| k.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                });
            }
        }
        (self.build)(keys)
    }
}

/// The largest force of a plate or an indenter (N per mm of thickness): 100, a thousand times
/// the seed's 0.1 (some 10 kN on a 10 cm slice).
pub const MAX_FORCE_N_PER_MM: f64 = 100.0;

/// The largest size of a rigid body pressed on the thigh (mm): 1 m.
pub const MAX_BODY_SIZE_MM: f64 = 1000.0;

/// `keys[name]` as a positive number up to `max` (the largest the key can mean: beyond it the
/// value is a unit or typing mistake), `default` when absent (`None`: required).
pub fn positive_key(
    keys: &TestKeys,
    name: &str,
    default: Option<f64>,
    max: f64,
) -> Result<f64, KeyError> {
    let bad = |message: String| KeyError {
        key: name.to_string(),
        message,
    };
    let v = match keys.get(name) {
        None => default.ok_or_else(|| KeyError {
            key: String::new(),
            message: format!("{name} is missing"),
        })?,
        Some(KeyValue::Number(v)) => *v,
        Some(KeyValue::Text(t)) => return Err(bad(format!("must be a number, got \"{t}\""))),
    };
    if !(v > 0.0 && v.is_finite()) {
        return Err(bad(format!("must be positive and finite, got {v}")));
    }
    if v > max {
        return Err(bad(format!("must be positive and at most {max}, got {v}")));
    }
    Ok(v)
}

/// `keys[name]` as a side of the section, anterior when absent.
pub fn side_key(keys: &TestKeys, name: &str) -> Result<Side, KeyError> {
    let text = match keys.get(name) {
        None => "anterior".to_string(),
        Some(KeyValue::Text(t)) => t.clone(),
        Some(KeyValue::Number(v)) => v.to_string(),
    };
    Side::parse(&text).map_err(|message| KeyError {
        key: name.to_string(),
        message,
    })
}

/// A side of the thigh cross-section.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// +y.
    Anterior,
    /// -y.
    Posterior,
    /// +x.
    Lateral,
    /// -x.
    Medial,
    /// Any direction, degrees counter-clockwise from +x.
    Angle(f64),
}

impl Side {
    /// Unit vector from the section's centre towards this side.
    pub fn direction(self) -> [f64; 2] {
        let deg: f64 = match self {
            Side::Lateral => 0.0,
            Side::Anterior => 90.0,
            Side::Medial => 180.0,
            Side::Posterior => 270.0,
            Side::Angle(a) => a,
        };
        let (s, c) = deg.to_radians().sin_cos();
        [c, s]
    }

    /// Parses `anterior`, `posterior`, `lateral`, `medial` or an angle in degrees (in
    /// [-360, 360]).
    pub fn parse(text: &str) -> Result<Side, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "anterior" => Ok(Side::Anterior),
            "posterior" => Ok(Side::Posterior),
            "lateral" => Ok(Side::Lateral),
            "medial" => Ok(Side::Medial),
            other => other
                .trim_end_matches("deg")
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|a| a.is_finite() && a.abs() <= 360.0)
                .map(Side::Angle)
                .ok_or_else(|| format!("'{text}' is not a side (anterior, posterior, lateral, medial or an angle in degrees within ±360)")),
        }
    }

    /// A short name for files and reports.
    pub fn name(self) -> String {
        match self {
            Side::Anterior => "anterior".into(),
            Side::Posterior => "posterior".into(),
            Side::Lateral => "lateral".into(),
            Side::Medial => "medial".into(),
            Side::Angle(a) => format!("{a}deg"),
        }
    }

    /// The side as a study-file value.
    pub fn key_value(self) -> KeyValue {
        match self {
            Side::Angle(a) => KeyValue::Number(a),
            s => KeyValue::Text(s.name()),
        }
    }
}

/// A loading that cannot be applied to the model.
#[derive(Debug, thiserror::Error)]
pub enum LoadingError {
    #[error("the skin surface is empty")]
    NoSkin,
    #[error("contention pressure must be finite, got {0} MPa")]
    BadPressure(f64),
    #[error(transparent)]
    Contact(#[from] ContactError),
}

/// Applies `loading` to `model` on the skin faces `skin` (see [`LoadingTest::apply`]).
pub fn apply_loading(
    model: &mut Model,
    skin: &[(usize, usize)],
    loading: &Loading,
) -> Result<(), LoadingError> {
    if skin.is_empty() {
        return Err(LoadingError::NoSkin);
    }
    loading.apply(model, skin)
}

/// Skin centre (mean of the face midpoints) and the largest extent of the skin along `e`.
fn skin_extent(model: &Model, skin: &[(usize, usize)], e: [f64; 2]) -> ([f64; 2], f64) {
    let mut c = [0.0, 0.0];
    let mut pts = Vec::with_capacity(2 * skin.len());
    for &(el, f) in skin {
        for n in model.mesh.elements[el].face_nodes(f) {
            pts.push(model.mesh.nodes[n]);
        }
    }
    for p in &pts {
        c[0] += p[0] / pts.len() as f64;
        c[1] += p[1] / pts.len() as f64;
    }
    let reach = pts
        .iter()
        .map(|p| (p[0] - c[0]) * e[0] + (p[1] - c[1]) * e[1])
        .fold(f64::NEG_INFINITY, f64::max);
    (c, reach)
}

/// Adds a force-controlled rigid body `body` named `name` against the skin; contact spreads
/// from a single node at first contact, so the first increment is kept at 2 % of the load
/// (increments then grow automatically) instead of trying the whole load at once.
fn push_rigid_body(
    model: &mut Model,
    skin: &[(usize, usize)],
    name: &str,
    body: Arc<dyn RigidSurface>,
    force: f64,
) -> Result<(), LoadingError> {
    let contact = RigidContact::new(name, &model.mesh, skin, body, TravelControl::Force(force))?;
    model.contacts.push(contact);
    let period = if model.step.period > 0.0 {
        model.step.period
    } else {
        1.0
    };
    model.step.initial_increment = model.step.initial_increment.min(0.02 * period);
    model.step.max_increments = model.step.max_increments.max(200);
    Ok(())
}
