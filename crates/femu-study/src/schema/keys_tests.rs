//! The declarations of [`super::keys`] against the parser: every key the serde structs accept is
//! declared and every declared key is accepted; each key set to its declared default gives the
//! study it has without it, and with the declaration changed the parser takes the new default;
//! each declared range and word list is the one the parser checks.

use super::keys::{Allowed, Def, TableSpec, TABLES};
use super::{parse, raw, ProbeSection, Study, UltrasoundSection};
use femu_geometry::ThighParams;
use serde::de::{self, Deserialize, Deserializer, Visitor};
use std::cell::Cell;
use std::collections::BTreeSet;
use std::path::Path;

/// A deserializer that records the field names a struct asks for and fails.
struct Recorder<'a>(&'a Cell<&'static [&'static str]>);

impl<'de> Deserializer<'de> for Recorder<'_> {
    type Error = de::value::Error;

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Self::Error> {
        Err(de::Error::custom("not a struct"))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        fields: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Self::Error> {
        self.0.set(fields);
        Err(de::Error::custom("recorded"))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
        ignored_any
    }
}

/// The keys serde accepts in a table read into `T`.
fn fields<T: for<'de> Deserialize<'de>>() -> BTreeSet<&'static str> {
    let cell = Cell::new(&[][..]);
    let _ = T::deserialize(Recorder(&cell));
    cell.get().iter().copied().collect()
}

/// Keys serde accepts and the parser refuses, with the reason (not declared: not study keys).
const REFUSED: &[(&str, &str, &str)] = &[
    (
        "thigh",
        "element_size_mm",
        "the mesh size of femu_geometry::ThighParams: [model] gives it in a study",
    ),
    (
        "thigh",
        "target_elements",
        "the mesh size of femu_geometry::ThighParams: [model] gives it in a study",
    ),
];

fn declared(table: &str) -> BTreeSet<&'static str> {
    TABLES
        .iter()
        .filter(|t| t.name == table)
        .flat_map(|t| t.keys())
        .map(|k| k.name)
        .collect()
}

/// Every table and key of the serde structs is declared, and every declared one is theirs.
#[test]
fn every_accepted_key_is_declared_and_back() {
    let top = fields::<raw::StudyFile>();
    let tables: BTreeSet<&str> = TABLES
        .iter()
        .map(|t| t.name.split('.').next().unwrap())
        .collect();
    assert_eq!(
        top, tables,
        "the study file's tables against the declared ones"
    );
    let structs = [
        ("model", fields::<raw::ModelEntry>()),
        ("thigh", fields::<ThighParams>()),
        ("labels", fields::<raw::LabelsEntry>()),
        ("grid", fields::<raw::GridEntry>()),
        ("noise", fields::<raw::NoiseEntry>()),
        ("measurement", fields::<raw::MeasurementEntry>()),
        ("parameters", fields::<raw::ParametersEntry>()),
        ("identification", fields::<raw::IdentificationEntry>()),
        ("run", fields::<raw::RunEntry>()),
        ("probe", fields::<ProbeSection>()),
        ("ultrasound", fields::<UltrasoundSection>()),
        ("fixed", fields::<raw::FixedEntry>()),
        ("pressure", fields::<raw::PressureEntry>()),
        ("step", fields::<raw::StepEntry>()),
        ("convergence", fields::<raw::ConvergenceEntry>()),
        ("design", fields::<raw::DesignEntry>()),
    ];
    // Every table but [materials.REGION] and [[test]], whose keys are a law's and a kind's
    // (declared in their registries), and [[interface]], read by `crate::interfaces` (its keys'
    // ranges and words are checked against its parser below), is read into one of these structs.
    let covered: BTreeSet<&str> = structs.iter().map(|s| s.0).collect();
    let dynamic: BTreeSet<&str> = tables.difference(&covered).copied().collect();
    assert_eq!(dynamic, BTreeSet::from(["interface", "materials", "test"]));
    for (table, accepted) in &structs {
        assert!(!accepted.is_empty(), "no fields recorded for [{table}]");
        let refused: BTreeSet<&str> = REFUSED
            .iter()
            .filter(|r| r.0 == *table)
            .map(|r| r.1)
            .collect();
        assert!(refused.is_subset(accepted), "[{table}] {refused:?}");
        let keys: BTreeSet<&str> = accepted.difference(&refused).copied().collect();
        assert_eq!(
            keys,
            declared(table),
            "[{table}]: serde's keys against the declared ones"
        );
    }
    for (table, key, why) in REFUSED {
        let e = parse(&format!("[{table}]\n{key} = 1000\n"), Path::new(".")).unwrap_err();
        assert!(e.to_string().contains(table), "{key} ({why}): {e}");
    }
}

/// The study the key is tried in: a label image for `[labels]`, a measured file for a file's
/// frame, a Gmsh boundary for `[[fixed]]`, the convergence view for `[convergence]`.
fn context(table: &str, key: &str) -> &'static str {
    match (table, key) {
        ("labels", _) => {
            "[model]\nsize_mm = 1.0\n[labels]\nimage = \"labels.png\"\n\
             map = \"1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius\"\nbone = [7]\n"
        }
        ("measurement", "units" | "x_axis" | "y_axis" | "origin_mm" | "weighting") => {
            "[measurement]\nsource = \"file\"\nfile = \"field.csv\"\n"
        }
        ("measurement", "speckle_frequency_mhz") => {
            "[measurement]\nsource = \"file\"\nfile = \"field.csv\"\nspeckle_resolution_mm = 0.9\n"
        }
        ("measurement", "speckle_resolution_mm") => {
            "[measurement]\nsource = \"file\"\nfile = \"field.csv\"\nspeckle_frequency_mhz = 9.0\n"
        }
        ("measurement", "speckle_scale") => {
            "[measurement]\nsource = \"file\"\nfile = \"field.csv\"\n\
             speckle_frequency_mhz = 9.0\nspeckle_resolution_mm = 0.9\nspeckle_shift = \"fixed\"\n"
        }
        ("measurement", "speckle_sound_speed_m_s" | "speckle_shift") => {
            "[measurement]\nsource = \"file\"\nfile = \"field.csv\"\n\
             speckle_frequency_mhz = 9.0\nspeckle_resolution_mm = 0.9\n"
        }
        ("measurement", "force_log_offset_s") => {
            "[measurement]\nsource = \"frames\"\nframes = [\"f0.png\", \"f1.png\"]\n\
             force_log = \"force.csv\"\nframe_times_s = [0.0, 1.0]\npixel_size_mm = 0.1\n"
        }
        ("measurement", "pose") => {
            "[measurement]\nsource = \"frames\"\nframes = [\"f0.png\", \"f1.png\"]\n\
             loads_n_per_mm = [0.1]\npixel_size_mm = 0.1\n"
        }
        ("measurement", "pixel_size_mm") => {
            "[measurement]\nsource = \"file\"\nfile = \"field.csv\"\nunits = \"px\"\n"
        }
        ("fixed", _) => "[[fixed]]\ncurve = \"femur\"\n",
        ("interface", "mu") => {
            "[[interface]]\nbetween = [\"QUADRICEPS\", \"ISCHIO\"]\nkind = \"friction\"\n"
        }
        ("interface", _) => "[[interface]]\nbetween = [\"QUADRICEPS\", \"ISCHIO\"]\n",
        ("convergence", _) => "[convergence]\n",
        _ => "",
    }
}

/// `context` with `key = value` in `table`.
fn with_key(t: &TableSpec, key: &str, value: &str) -> String {
    let name = t.name.replace("REGION", "FAT");
    let context = context(&name, key);
    let header = if t.array {
        format!("[[{name}]]\n")
    } else {
        format!("[{name}]\n")
    };
    if context.contains(&header) {
        format!("{context}{key} = {value}\n")
    } else {
        format!("{context}{header}{key} = {value}\n")
    }
}

/// What a study is, every part that the file sets (its key lines left out). The built-in
/// thigh's default resolution is written as its element count (`DEFAULT_ELEMENTS`).
fn outcome(s: &Study) -> String {
    // The convergence view of the study as parsed (it refuses a [model] resolution).
    let convergence = if s.convergence.given {
        format!("{:?}", s.convergence_study().map(|c| format!("{c:?}")))
    } else {
        String::new()
    };
    let mut s = s.clone();
    if s.model.resolution == super::Resolution::Default
        && matches!(s.model.geometry, super::Geometry::Thigh(_))
    {
        s.model.resolution = super::Resolution::Elements(super::DEFAULT_ELEMENTS);
    }
    let s = &s;
    format!(
        "{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{convergence}",
        s.model,
        s.tests,
        s.measurement,
        s.measurements,
        s.groups,
        s.identification,
        s.steps,
        s.probe,
        s.ultrasound,
        s.boundary,
        s.design
    )
}

/// Each key with a declared default, set to it, gives the study without it.
#[test]
fn every_declared_default_is_the_parsers() {
    let mut tried = 0;
    for t in TABLES {
        for k in t.keys() {
            let Def::Value(v) = k.default else { continue };
            let base_text = context(&t.name.replace("REGION", "FAT"), k.name);
            let text = with_key(t, k.name, v);
            let base = parse(base_text, Path::new("."))
                .unwrap_or_else(|e| panic!("context of {} {}: {e}", t.title(), k.name));
            let set = parse(&text, Path::new("."))
                .unwrap_or_else(|e| panic!("{} {} = {v}: {e}\n{text}", t.title(), k.name));
            assert_eq!(
                outcome(&set),
                outcome(&base),
                "{} {} = {v} is not its default",
                t.title(),
                k.name
            );
            tried += 1;
        }
    }
    assert!(tried > 60, "{tried}");
}

/// Keys whose declared range the study's context narrows (their range test would refuse a
/// declared bound), and why.
const NARROWED: &[(&str, &str, &str)] = &[(
    "model",
    "elements",
    "the default thigh keeps its regions from 622 elements on (geometry::thigh_elements)",
)];

/// The declared bounds of every ranged number are the parser's: the bounds are accepted,
/// beyond them refused with an error naming the key.
#[test]
fn every_declared_range_is_the_parsers() {
    let mut tried = 0;
    for t in TABLES {
        for k in t.keys() {
            let (inside, outside): (Vec<f64>, Vec<f64>) = match k.allowed {
                Allowed::Int { min, max } => (
                    vec![min as f64, max as f64],
                    [min.checked_sub(1).map(|m| m as f64), Some(max as f64 + 1.0)]
                        .into_iter()
                        .flatten()
                        .collect(),
                ),
                Allowed::Real {
                    min,
                    min_open,
                    max,
                    max_open,
                } => {
                    let step = |b: f64| b.abs().max(1.0) * 1e-6;
                    let mut inside = Vec::new();
                    let mut outside = vec![min - step(min)];
                    if min_open {
                        outside.push(min);
                    } else {
                        inside.push(min);
                    }
                    if max.is_finite() {
                        outside.push(max + step(max));
                        if max_open {
                            outside.push(max);
                        } else {
                            inside.push(max);
                        }
                    }
                    (inside, outside)
                }
                Allowed::ZeroOrReal { min, max } => {
                    (vec![0.0, min, max], vec![min / 2.0, -min, max * 1.01])
                }
                _ => continue,
            };
            let narrowed = NARROWED.iter().any(|n| n.0 == t.name && n.1 == k.name);
            let text = |v: f64| {
                let value = if matches!(k.allowed, Allowed::Int { .. }) {
                    format!("{v}")
                } else {
                    format!("{v:?}")
                };
                with_key(t, k.name, &value)
            };
            for v in inside {
                if narrowed {
                    continue;
                }
                let text = text(v);
                if let Err(e) = parse(&text, Path::new(".")) {
                    panic!(
                        "{} {} = {v} is within its declared range: {e}\n{text}",
                        t.title(),
                        k.name
                    );
                }
            }
            for v in outside {
                let text = text(v);
                match parse(&text, Path::new(".")) {
                    Ok(_) => panic!(
                        "{} {} = {v} is outside its declared range\n{text}",
                        t.title(),
                        k.name
                    ),
                    Err(e) => assert!(
                        e.to_string().contains(k.name),
                        "{} {} = {v}: {e}",
                        t.title(),
                        k.name
                    ),
                }
            }
            tried += 1;
        }
    }
    assert!(tried >= 20, "{tried}");
}

/// Every declared word is one the parser knows (in a study where it may stand or not, the
/// error is never that the word is unknown or unhandled), and another word is refused naming
/// the declared ones.
#[test]
fn every_declared_word_is_the_parsers() {
    let mut tried = 0;
    for t in TABLES {
        for k in t.keys() {
            let Allowed::Words { words, .. } = k.allowed else {
                continue;
            };
            for w in words {
                for spelt in [w.to_string(), w.to_ascii_uppercase()] {
                    let text = with_key(t, k.name, &format!("{spelt:?}"));
                    if let Err(e) = parse(&text, Path::new(".")) {
                        let e = e.to_string();
                        assert!(
                            !e.contains("unknown") && !e.contains("not handled"),
                            "{} {} = {spelt:?}: {e}",
                            t.title(),
                            k.name
                        );
                    }
                }
            }
            let text = with_key(t, k.name, "\"no-such-word\"");
            let e = parse(&text, Path::new(".")).unwrap_err().to_string();
            assert!(
                e.contains(k.name) && e.contains(&words.join(", ")),
                "{} {}: {e}",
                t.title(),
                k.name
            );
            tried += 1;
        }
    }
    assert!(tried >= 8, "{tried}");
}

/// Values other than the declared default for the keys whose type [`other_values`] cannot
/// vary by itself (pairs, lists, free words), each valid in the key's [`context`].
const OTHER_VALUES: &[(&str, &str, &str)] = &[
    ("grid", "counts", "[32, 16]"),
    ("labels", "background", "[0, 9]"),
    ("measurement", "x_axis", "[-1.0, 0.0]"),
    ("measurement", "y_axis", "[0.0, -1.0]"),
    ("parameters", "groups", "[[\"D_ISCHIO\", \"D_SARTORIUS\"]]"),
    ("identification", "fixed", "[\"C10_FAT\"]"),
    ("identification", "grouped", "false"),
    ("probe", "side", "\"lateral\""),
    ("design", "sides", "[\"lateral\", \"medial\"]"),
    ("design", "windows_mm", "[[30.0, 30.0]]"),
    ("convergence", "element_types", "[\"CPE4\", \"CPE3\"]"),
    ("convergence", "target_elements", "[3000, 6000, 12000]"),
    ("fixed", "dofs", "[1]"),
];

/// Keys whose every other value needs another key set too (the parser takes their default
/// from the declaration all the same), and why.
const NO_OTHER_VALUE_ALONE: &[(&str, &str, &str)] = &[
    (
        "measurement",
        "units",
        "its other word, px, needs pixel_size_mm, which mm refuses",
    ),
    (
        "step",
        "max_increment",
        "at most 1 and at least initial_increment, whose default is 1",
    ),
];

/// Keys with a declared default the parser does not take from the declaration, and why (the
/// test above still checks that the two agree).
const NOT_FROM_THE_DECLARATION: &[(&str, &str, &str)] = &[
    (
        "model",
        "elements",
        "the thigh's default resolution is geometry::DEFAULT_ELEMENTS, a constant the mesher and the commands read",
    ),
    (
        "thigh",
        "*",
        "[thigh] is femu_geometry::ThighParams, its defaults the geometry crate's",
    ),
];

/// Candidate values of key `k` other than its declared default `v` (the first the study
/// accepts is used): the other flag, a neighbouring integer or number in the declared range,
/// the other declared words, or the value of [`OTHER_VALUES`].
fn other_values(table: &str, k: &super::keys::KeySpec, v: &str) -> Vec<String> {
    use super::keys::Ty;
    if let Some((_, _, o)) = OTHER_VALUES
        .iter()
        .find(|(t, key, _)| *t == table && *key == k.name)
    {
        return vec![o.to_string()];
    }
    match (k.ty, k.allowed) {
        (Ty::Bool, _) => vec![if v == "true" { "false" } else { "true" }.to_string()],
        (Ty::Int, allowed) => {
            let n: f64 = v.parse().expect("an integer default");
            [n + 1.0, n - 1.0]
                .into_iter()
                .filter(|x| allowed.admits(*x) && *x >= 0.0)
                .map(|x| format!("{x}"))
                .collect()
        }
        (Ty::Real, allowed) => {
            let x: f64 = v.parse().expect("a number default");
            [x * 1.25, x * 0.8, 0.5]
                .into_iter()
                .filter(|y| *y != x && allowed.admits(*y))
                .map(|y| format!("{y:?}"))
                .collect()
        }
        (_, Allowed::Words { words, .. }) => words
            .iter()
            .filter(|w| format!("{w:?}") != v)
            .map(|w| format!("{w:?}"))
            .collect(),
        _ => Vec::new(),
    }
}

/// The parser takes every declared default from its declaration: with the declaration
/// replaced by another value, the study without the key is the study with the key set to that
/// value (a default written by hand in the parser would keep the old one).
#[test]
fn a_changed_declaration_changes_the_parsed_default() {
    let mut tried = Vec::new();
    let mut untried = Vec::new();
    for t in TABLES {
        let table = t.name.replace("REGION", "FAT");
        for k in t.keys() {
            let Def::Value(v) = k.default else { continue };
            if NOT_FROM_THE_DECLARATION
                .iter()
                .any(|(tt, kk, _)| *tt == table && (*kk == k.name || *kk == "*"))
            {
                continue;
            }
            let base_text = context(&table, k.name);
            let candidates = other_values(&table, k, v);
            let Some((other, set)) = candidates.iter().find_map(|o| {
                parse(&with_key(t, k.name, o), Path::new("."))
                    .ok()
                    .map(|s| (o, s))
            }) else {
                let why = NO_OTHER_VALUE_ALONE
                    .iter()
                    .find(|(tt, kk, _)| *tt == table && *kk == k.name)
                    .map_or(format!("tried {candidates:?}"), |w| w.2.to_string());
                untried.push(format!("{} {}: {why}", t.title(), k.name));
                continue;
            };
            // The views read later (the convergence study) are made under the declaration too.
            let by_declaration =
                super::keys::overrides::with_defaults(&[(&table, k.name, other)], || {
                    parse(base_text, Path::new(".")).map(|s| outcome(&s))
                })
                .unwrap_or_else(|e| panic!("{} {} declared {other}: {e}", t.title(), k.name));
            assert_ne!(
                outcome(&set),
                outcome(&parse(base_text, Path::new(".")).unwrap()),
                "{} {} = {other} changes nothing: choose another value",
                t.title(),
                k.name
            );
            assert_eq!(
                by_declaration,
                outcome(&set),
                "{} {}: declared {other}, the parser still takes {v}",
                t.title(),
                k.name
            );
            tried.push(format!("{} {}", t.title(), k.name));
        }
    }
    assert_eq!(
        untried,
        NO_OTHER_VALUE_ALONE
            .iter()
            .map(|(t, k, why)| format!("[{t}] {k}: {why}"))
            .collect::<Vec<_>>(),
        "no other value to try"
    );
    // 58 keys when this was written: a key cannot silently leave the test.
    assert!(tried.len() >= 58, "{}: {tried:?}", tried.len());
}
