//! Every key of the study file, declared once: its table, name, type, unit, allowed values,
//! default and documentation ([`TABLES`]). From these declarations come `femu init`'s commented
//! study file ([`init_file`], committed as `example_study.toml`), the reference page
//! `docs/guide/src/reference/study-file.md` ([`reference_page`]), the parser's range and
//! choice checks ([`check_int`], [`check_real`], [`word`]) and the values the parser takes for
//! an absent key ([`default`], [`or_default`], [`word_or_default`]), so that a declared range
//! or default and the parser's cannot differ. The keys of a `[[test]]` kind and of a
//! `[materials.REGION]` law are declared with the kind (`femu_mech::loading::TEST_KINDS`) and
//! the law (`femu_mech::material::LAWS`); the reference page lists them from there.
//!
//! To add a key: its field in the serde struct of its table (`raw.rs` or the table's own file),
//! its [`KeySpec`] here, and its check in the table's parser (its default read with
//! [`or_default`]); then regenerate the two files with
//! `FEMU_BLESS=1 cargo test -p femu-study --test study_keys`.

use std::fmt::Write;

// The limits the parsers of several tables check, declared here with the keys they bound.

/// The accepted target element counts of the built-in thigh.
pub const ELEMENTS_RANGE: std::ops::RangeInclusive<usize> = 100..=femu_geometry::MAX_ELEMENTS;

/// Largest `[identification] bounds_factor`.
pub const MAX_BOUNDS_FACTOR: f64 = 100.0;

/// Smallest nonzero `image_normalization_px` (px): below, the Gaussian window is narrower than a
/// pixel, the local mean is the pixel itself and nothing is left to compare.
pub const MIN_IMAGE_NORMALIZATION_PX: f64 = 0.5;

/// Largest `image_normalization_px` (px): beyond, the window spans the fat's thickness and the
/// normalization no longer separates an interface's position from its brightness.
pub const MAX_IMAGE_NORMALIZATION_PX: f64 = 32.0;

/// Largest `render_refine`: 4 makes 16 times the elements of `[model]`.
pub const MAX_RENDER_REFINE: usize = 4;

/// The TOML type of a key's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    Int,
    Real,
    Bool,
    Text,
    /// Two numbers, `[x, y]`.
    RealPair,
    /// Two integers, `[n, m]`.
    IntPair,
    Texts,
    Reals,
    Ints,
    /// A list of `[x, y]` pairs.
    RealPairs,
    /// A list of lists of names.
    TextLists,
    /// `true`, `false` or a word.
    BoolOrText,
}

impl Ty {
    /// How the reference page names it.
    pub fn name(self) -> &'static str {
        match self {
            Ty::Int => "integer",
            Ty::Real => "number",
            Ty::Bool => "boolean",
            Ty::Text => "string",
            Ty::RealPair => "[number, number]",
            Ty::IntPair => "[integer, integer]",
            Ty::Texts => "list of strings",
            Ty::Reals => "list of numbers",
            Ty::Ints => "list of integers",
            Ty::RealPairs => "list of [number, number]",
            Ty::TextLists => "list of lists of strings",
            Ty::BoolOrText => "boolean or string",
        }
    }
}

/// The values a key accepts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Allowed {
    /// Any value of its type.
    Any,
    /// An integer in `[min, max]`.
    Int { min: u64, max: u64 },
    /// A number between `min` and `max`, each bound included unless `open`; an infinite bound
    /// is none (the number must still be finite).
    Real {
        min: f64,
        min_open: bool,
        max: f64,
        max_open: bool,
    },
    /// 0, or a number in `[min, max]`.
    ZeroOrReal { min: f64, max: f64 },
    /// One of these words (case-insensitive); `what` names the kind of word in messages.
    Words {
        what: &'static str,
        words: &'static [&'static str],
    },
    /// Checked by the table's parser, as this says (a rule over several keys or the elements
    /// of a list).
    Rule(&'static str),
}

/// A number in `[min, max]`.
const fn closed(min: f64, max: f64) -> Allowed {
    Allowed::Real {
        min,
        min_open: false,
        max,
        max_open: false,
    }
}

/// A positive finite number.
const POSITIVE: Allowed = Allowed::Real {
    min: 0.0,
    min_open: true,
    max: f64::INFINITY,
    max_open: true,
};

/// A number in `(0, max]`.
const fn up_to(max: f64) -> Allowed {
    Allowed::Real {
        min: 0.0,
        min_open: true,
        max,
        max_open: false,
    }
}

fn number(v: f64) -> String {
    format!("{v}")
}

impl Allowed {
    /// As the reference page and the messages write it.
    pub fn describe(&self) -> String {
        match *self {
            Allowed::Any => String::new(),
            Allowed::Int { min, max } => format!("[{min}, {max}]"),
            Allowed::Real {
                min,
                min_open,
                max,
                max_open,
            } => {
                if max.is_infinite() {
                    format!("{} {}", if min_open { ">" } else { "≥" }, number(min))
                } else {
                    format!(
                        "{}{}, {}{}",
                        if min_open { "(" } else { "[" },
                        number(min),
                        number(max),
                        if max_open { ")" } else { "]" }
                    )
                }
            }
            Allowed::ZeroOrReal { min, max } => {
                format!("0 or [{}, {}]", number(min), number(max))
            }
            Allowed::Words { words, .. } => words
                .iter()
                .map(|w| format!("`{w}`"))
                .collect::<Vec<_>>()
                .join(", "),
            Allowed::Rule(text) => text.to_string(),
        }
    }

    /// Whether `v` is allowed (a number's range).
    pub fn admits(&self, v: f64) -> bool {
        match *self {
            Allowed::Int { min, max } => v.fract() == 0.0 && v >= min as f64 && v <= max as f64,
            Allowed::Real {
                min,
                min_open,
                max,
                max_open,
            } => {
                v.is_finite()
                    && if min_open { v > min } else { v >= min }
                    && if max_open { v < max } else { v <= max }
            }
            Allowed::ZeroOrReal { min, max } => v == 0.0 || (min..=max).contains(&v),
            Allowed::Any | Allowed::Words { .. } | Allowed::Rule(_) => true,
        }
    }
}

/// A key's default.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Def {
    /// The value (TOML) the key takes when absent.
    Value(&'static str),
    /// What the key is when absent, in words (required, derived from other keys, none).
    Text(&'static str),
}

/// How `femu init`'s file shows a key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Init {
    /// `key = <default>`.
    Default,
    /// `key = <value>` (an explicit value for a key whose default is in words).
    Set(&'static str),
    /// `# key = <value>`: commented out.
    Example(&'static str),
    /// Shown by the table's note (a free-text block of the file).
    InNote,
}

/// One key of the study file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeySpec {
    pub name: &'static str,
    pub ty: Ty,
    /// Its unit (also the name's suffix), or empty.
    pub unit: &'static str,
    pub allowed: Allowed,
    pub default: Def,
    /// One line on what it is (the reference page).
    pub doc: &'static str,
    pub init: Init,
    /// The comment beside it in `femu init`'s file (lines separated by `\n`), or empty.
    pub comment: &'static str,
}

/// A key shown in `femu init`'s file with its default and no comment.
const fn key(
    name: &'static str,
    ty: Ty,
    unit: &'static str,
    allowed: Allowed,
    default: Def,
    doc: &'static str,
) -> KeySpec {
    KeySpec {
        name,
        ty,
        unit,
        allowed,
        default,
        doc,
        init: Init::Default,
        comment: "",
    }
}

impl KeySpec {
    /// Shown with its default and this comment.
    const fn shown(self, comment: &'static str) -> KeySpec {
        KeySpec {
            init: Init::Default,
            comment,
            ..self
        }
    }

    /// Shown set to `value`, with this comment.
    const fn set(self, value: &'static str, comment: &'static str) -> KeySpec {
        KeySpec {
            init: Init::Set(value),
            comment,
            ..self
        }
    }

    /// Commented out, set to `value`, with this comment.
    const fn example(self, value: &'static str, comment: &'static str) -> KeySpec {
        KeySpec {
            init: Init::Example(value),
            comment,
            ..self
        }
    }

    /// Shown by the table's note.
    const fn in_note(self) -> KeySpec {
        KeySpec {
            init: Init::InNote,
            ..self
        }
    }
}

/// A part of a table in `femu init`'s file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Item {
    Key(KeySpec),
    /// Verbatim lines of the file (comments, or the tables of a `[[test]]` or `[materials]`
    /// example).
    Note(&'static str),
}

/// How `femu init`'s file writes a table's header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Header {
    /// `[name]`: the table is set.
    Plain,
    /// `# [name]`: commented out, with its keys.
    Commented,
    /// Written by the table's notes.
    InNote,
}

/// One table of the study file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableSpec {
    /// `model`, `materials.REGION`, `test`.
    pub name: &'static str,
    /// An array of tables (`[[test]]`).
    pub array: bool,
    /// What it is (the reference page).
    pub doc: &'static str,
    /// Comment lines before it in `femu init`'s file, after a rule (a new part of the file).
    pub banner: &'static str,
    pub header: Header,
    /// The comment on its header line.
    pub header_comment: &'static str,
    /// No blank line before it.
    pub tight: bool,
    pub items: &'static [Item],
}

impl TableSpec {
    /// Its keys.
    pub fn keys(&self) -> impl Iterator<Item = &KeySpec> + '_ {
        self.items.iter().filter_map(|i| match i {
            Item::Key(k) => Some(k),
            Item::Note(_) => None,
        })
    }

    /// How it is written: `[model]`, `[[test]]`.
    pub fn title(&self) -> String {
        if self.array {
            format!("[[{}]]", self.name)
        } else {
            format!("[{}]", self.name)
        }
    }
}

/// The declaration of `key` in `table`.
///
/// # Panics
/// When it is not declared: a parser checking an undeclared key (the tests run every check).
pub fn spec(table: &str, key: &str) -> &'static KeySpec {
    TABLES
        .iter()
        .filter(|t| t.name == table)
        .flat_map(|t| t.keys())
        .find(|k| k.name == key)
        .unwrap_or_else(|| panic!("[{table}] {key} is not declared in schema::keys"))
}

/// The declared default of `key` in `table` as a `T` (a number, a flag, a word, a list): what
/// the parser takes when the key is absent, so that the declaration and the parser cannot
/// differ.
///
/// # Panics
/// When the key declares no value, or a value that is not a `T` (the tests parse the study
/// without keys, so every default the parser takes is read).
pub fn default<T: serde::de::DeserializeOwned>(table: &str, key: &str) -> T {
    let text = default_text(table, key);
    let parsed: Result<toml::Table, _> = toml::from_str(&format!("v = {text}"));
    parsed
        .ok()
        .and_then(|mut t| t.remove("v"))
        .and_then(|v| v.try_into().ok())
        .unwrap_or_else(|| {
            panic!(
                "[{table}] {key}: the declared default {text} is not a {}",
                std::any::type_name::<T>()
            )
        })
}

/// The declared default word of `key` in `table` (one of its declared words).
pub fn default_word(table: &str, key: &str) -> &'static str {
    let text: String = default(table, key);
    word(table, key, &text).unwrap_or_else(|m| panic!("[{table}] {key}: the declared default: {m}"))
}

/// `v`, or the declared default of `key` in `table` when it is absent.
pub fn or_default<T: serde::de::DeserializeOwned>(v: Option<T>, table: &str, key: &str) -> T {
    v.unwrap_or_else(|| default(table, key))
}

/// The declared word `v` is, or the declared default word when it is absent.
pub fn word_or_default(table: &str, key: &str, v: Option<&str>) -> Result<&'static str, String> {
    match v {
        Some(v) => word(table, key, v),
        None => Ok(default_word(table, key)),
    }
}

/// The TOML text of the declared default of `key` in `table`.
fn default_text(table: &str, key: &str) -> String {
    #[cfg(test)]
    if let Some(v) = overrides::overridden(table, key) {
        return v;
    }
    match spec(table, key).default {
        Def::Value(v) => v.to_string(),
        Def::Text(t) => panic!("[{table}] {key} declares no default value ({t})"),
    }
}

/// Test-only: declared defaults replaced for the current thread, to show that the parser
/// takes what is declared.
#[cfg(test)]
pub(crate) mod overrides {
    use std::cell::RefCell;

    thread_local! {
        static OVERRIDES: RefCell<Vec<(String, String, String)>> = const { RefCell::new(Vec::new()) };
    }

    /// The replaced default of `key` in `table`, if any.
    pub(super) fn overridden(table: &str, key: &str) -> Option<String> {
        OVERRIDES.with(|o| {
            o.borrow()
                .iter()
                .rev()
                .find(|(t, k, _)| t == table && k == key)
                .map(|(_, _, v)| v.clone())
        })
    }

    /// `f` run with the declared defaults replaced by `values` (`(table, key, TOML value)`).
    pub(crate) fn with_defaults<R>(values: &[(&str, &str, &str)], f: impl FnOnce() -> R) -> R {
        OVERRIDES.with(|o| {
            o.borrow_mut().extend(
                values
                    .iter()
                    .map(|(t, k, v)| (t.to_string(), k.to_string(), v.to_string())),
            )
        });
        let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
        OVERRIDES.with(|o| o.borrow_mut().clear());
        out.unwrap_or_else(|p| std::panic::resume_unwind(p))
    }
}

/// The check of an integer against its declared range: the message names the range.
pub fn check_int(table: &str, key: &str, v: usize) -> Result<usize, String> {
    let s = spec(table, key);
    if s.allowed.admits(v as f64) {
        Ok(v)
    } else {
        Err(out_of_range(s, &v.to_string()))
    }
}

/// The check of a number against its declared range.
pub fn check_real(table: &str, key: &str, v: f64) -> Result<f64, String> {
    let s = spec(table, key);
    if s.allowed.admits(v) {
        Ok(v)
    } else {
        Err(out_of_range(s, &number(v)))
    }
}

fn out_of_range(s: &KeySpec, v: &str) -> String {
    let unit = if s.unit.is_empty() {
        String::new()
    } else {
        format!(" {}", s.unit)
    };
    match s.allowed {
        Allowed::ZeroOrReal { min, max } => {
            format!(
                "must be 0 or in [{}, {}]{unit}, got {v}",
                number(min),
                number(max)
            )
        }
        Allowed::Real {
            min,
            min_open: true,
            max,
            max_open,
        } if max.is_infinite() || !max_open => {
            let (min, max) = (number(min), number(max));
            if max.contains("inf") {
                format!("must be above {min}{unit}, got {v}")
            } else {
                format!("must be above {min} and at most {max}{unit}, got {v}")
            }
        }
        _ => format!("must be in {}{unit}, got {v}", s.allowed.describe()),
    }
}

/// The error of a declared word the parser does not handle (a declaration ahead of its
/// parser; the tests try every declared word).
pub fn unhandled(table: &str, key: &str, v: &str) -> String {
    format!("[{table}] {key} = '{v}' is declared but not handled by the parser")
}

/// The declared word `v` is (case-insensitive), or the message naming the words.
pub fn word(table: &str, key: &str, v: &str) -> Result<&'static str, String> {
    let s = spec(table, key);
    let Allowed::Words { what, words } = s.allowed else {
        panic!("[{table}] {key} is not declared with words")
    };
    words
        .iter()
        .find(|w| w.eq_ignore_ascii_case(v.trim()))
        .copied()
        .ok_or_else(|| {
            let v = v.trim().to_ascii_lowercase();
            format!("unknown {what} '{v}' ({})", words.join(", "))
        })
}

/// The column of the comments in `femu init`'s file.
const COMMENT_COLUMN: usize = 33;

/// A rule between the parts of `femu init`'s file.
const RULE: &str =
    "# ---------------------------------------------------------------------------------------------";

/// The first lines of `femu init`'s file.
const PREAMBLE: &str = "\
# femu study file — the seed's numerical example: FEMU of the thigh's Neo-Hookean parameters.
# Run it with:   femu run study.toml --out out/study
# Every key is optional: the values below are the defaults. Units are part of the key names
# (mm, kpa, mpa, mmhg, n_per_mm). An unknown or misspelt key is an error naming its line.
";

/// `text` then `comment` at the comment column, its further lines below it.
fn with_comment(out: &mut String, text: &str, comment: &str) {
    if comment.is_empty() {
        out.push_str(text);
        out.push('\n');
        return;
    }
    for (k, line) in comment.lines().enumerate() {
        let lead = if k == 0 { text } else { "" };
        let pad = if lead.chars().count() < COMMENT_COLUMN {
            COMMENT_COLUMN - lead.chars().count()
        } else {
            2
        };
        let _ = writeln!(out, "{lead}{}# {line}", " ".repeat(pad));
    }
}

/// The lines of `femu init`'s file for one table.
pub fn init_table(t: &TableSpec) -> String {
    let mut out = String::new();
    if !t.tight {
        out.push('\n');
    }
    if !t.banner.is_empty() {
        out.push_str(RULE);
        out.push('\n');
        for line in t.banner.lines() {
            let _ = writeln!(out, "# {line}");
        }
    }
    let commented = t.header != Header::Plain;
    match t.header {
        Header::Plain | Header::Commented => {
            let prefix = if commented { "# " } else { "" };
            with_comment(
                &mut out,
                &format!("{prefix}{}", t.title()),
                t.header_comment,
            );
        }
        Header::InNote => {}
    }
    for item in t.items {
        match item {
            Item::Note(text) => out.push_str(text),
            Item::Key(k) => {
                let (value, hidden) = match (k.init, k.default) {
                    (Init::Default, Def::Value(v)) => (v, commented),
                    (Init::Default, Def::Text(_)) => {
                        panic!("[{}] {} has no default value to show", t.name, k.name)
                    }
                    (Init::Set(v), _) => (v, commented),
                    (Init::Example(v), _) => (v, true),
                    (Init::InNote, _) => continue,
                };
                let prefix = if hidden { "# " } else { "" };
                with_comment(
                    &mut out,
                    &format!("{prefix}{} = {value}", k.name),
                    k.comment,
                );
            }
        }
    }
    out
}

/// `femu init`'s commented study file from the declarations `tables`.
pub fn init_file(tables: &[TableSpec]) -> String {
    let mut out = PREAMBLE.to_string();
    for t in tables {
        out.push_str(&init_table(t));
    }
    out
}

/// A table cell: `|` escaped, line breaks as spaces.
fn cell(text: &str) -> String {
    text.replace('|', "\\|").replace('\n', " ")
}

/// The reference page of the study file (Markdown) from the declarations `tables`, with the
/// keys of the loading tests and of the material laws from their registries.
pub fn reference_page(tables: &[TableSpec]) -> String {
    let mut out = String::from(
        "# The study file: every key\n\n\
         <!-- Generated from crates/femu-study/src/schema/keys.rs: do not edit. Regenerate with\n     \
         FEMU_BLESS=1 cargo test -p femu-study --test study_keys -->\n\n\
         A study is a TOML file (`femu init` writes one with every key, its default and a\n\
         comment). Every key is optional unless its default says *required*; units are part of\n\
         the key names (mm, kpa, mpa, mmhg, n_per_mm). An unknown or misspelt key, a value out of\n\
         its range or a word not among its choices is an error naming the key and its line.\n\
         Relative file names are relative to the study file's folder.\n\n\
         Tables: ",
    );
    let links: Vec<String> = tables
        .iter()
        .map(|t| format!("[`{}`](#{})", t.title(), anchor(t)))
        .collect();
    out.push_str(&links.join(", "));
    out.push_str(".\n");
    for t in tables {
        let _ = write!(out, "\n## `{}`\n\n{}\n", t.title(), t.doc);
        if t.keys().next().is_some() {
            out.push_str("\n| key | type | unit | allowed | default | description |\n");
            out.push_str("|---|---|---|---|---|---|\n");
            for k in t.keys() {
                let default = match k.default {
                    Def::Value(v) => format!("`{v}`"),
                    Def::Text(t) => t.to_string(),
                };
                let _ = writeln!(
                    out,
                    "| `{}` | {} | {} | {} | {} | {} |",
                    k.name,
                    k.ty.name(),
                    cell(k.unit),
                    cell(&k.allowed.describe()),
                    cell(&default),
                    cell(k.doc)
                );
            }
        }
        match t.name {
            "test" => out.push_str(&test_kinds()),
            "materials.REGION" => out.push_str(&laws()),
            _ => {}
        }
    }
    out
}

/// The anchor GitHub gives a heading `` ## `[name]` ``.
fn anchor(t: &TableSpec) -> String {
    t.title()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == '_')
        .collect::<String>()
        .to_ascii_lowercase()
}

/// The keys of each loading-test kind (`femu_mech::loading::TEST_KINDS`).
fn test_kinds() -> String {
    let mut out = String::new();
    for kind in femu_mech::loading::TEST_KINDS {
        let _ = write!(
            out,
            "\n### `kind = \"{}\"`\n\n{}.\n\n| key | description |\n|---|---|\n",
            kind.name,
            capitalized(kind.doc)
        );
        for k in kind.keys {
            let _ = writeln!(out, "| `{}` | {} |", k.name, cell(k.doc));
        }
    }
    out
}

/// `text` with its first letter upper case.
fn capitalized(text: &str) -> String {
    let mut chars = text.chars();
    match chars.next() {
        Some(first) => first.to_uppercase().chain(chars).collect(),
        None => String::new(),
    }
}

/// The parameter keys of each material law (`femu_mech::material::LAWS`).
fn laws() -> String {
    let mut out = String::new();
    for law in femu_mech::material::LAWS {
        let spec = law.spec;
        let _ = write!(
            out,
            "\n### `law = \"{}\"`\n\n{}\n\n| keys | unit of the range | allowed | description |\n|---|---|---|---|\n",
            spec.name, spec.doc
        );
        for p in spec.parameters {
            let keys: Vec<String> = p.keys().map(|k| format!("`{k}`")).collect();
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} |",
                keys.join(", "),
                p.unit.symbol(),
                cell(&p.range()),
                cell(p.doc)
            );
        }
    }
    out
}

/// The committed `femu init` file: [`init_file`] of [`TABLES`].
pub fn generated_init_file() -> String {
    init_file(TABLES)
}

/// The committed reference page: [`reference_page`] of [`TABLES`].
pub fn generated_reference_page() -> String {
    reference_page(TABLES)
}

/// A pair of mm numbers.
const MM2: Ty = Ty::RealPair;

const ELEMENTS_MIN: u64 = *ELEMENTS_RANGE.start() as u64;
const ELEMENTS_MAX: u64 = *ELEMENTS_RANGE.end() as u64;

/// Every table of the study file, in the order of `femu init`'s file.
pub static TABLES: &[TableSpec] = &[
    TableSpec {
        name: "model",
        array: false,
        doc: "The mesh of the model: its size and element, or an Abaqus/CalculiX deck instead of \
              the built-in thigh or a label image.",
        banner: "Geometry: one of [thigh] (the built-in parametric thigh, default), [labels] (a segmented\n\
                 image) or [model] deck (an Abaqus/CalculiX deck whose *DLOAD faces are the skin).",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "elements",
                    Ty::Int,
                    "",
                    Allowed::Int { min: ELEMENTS_MIN, max: ELEMENTS_MAX },
                    Def::Value("6000"),
                    "target number of quads of the generated mesh (the default thigh needs at least 622)",
                )
                .shown("target quads of the built-in thigh (the seed: 25 392), or"),
            ),
            Item::Key(
                key(
                    "size_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("from `elements`; 1 for [labels]"),
                    "element size instead of `elements` (at most 4.5 mm for the default thigh)",
                )
                .example("1.0", "the element size (required for [labels])"),
            ),
            Item::Key(
                key(
                    "element",
                    Ty::Text,
                    "",
                    Allowed::Words { what: "element type", words: &["cpe4h", "cpe4"] },
                    Def::Value("\"cpe4h\""),
                    "element formulation: hybrid (the seed's CPE4H) or displacement-only CPE4",
                )
                .shown("cpe4h (hybrid, the seed's CPE4H) or cpe4"),
            ),
            Item::Key(
                key(
                    "deck",
                    Ty::Text,
                    "",
                    Allowed::Rule("an .inp file"),
                    Def::Text("none"),
                    "an Abaqus/CalculiX deck whose *DLOAD faces are the skin, instead of [thigh] / [labels]",
                )
                .example("\"mesh.inp\"", "instead of [thigh] / [labels]"),
            ),
        ],
    },
    TableSpec {
        name: "thigh",
        array: false,
        doc: "The dimensions of the built-in parametric thigh (the default geometry). Its mesh \
              size is `[model]`'s.",
        banner: "",
        header: Header::Plain,
        header_comment: "dimensions of the built-in thigh (mm, degrees)",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "skin_semi_axes_mm",
                    MM2,
                    "mm",
                    Allowed::Rule("each in [30, 150]"),
                    Def::Value("[70.0, 60.0]"),
                    "skin ellipse semi-axes: medio-lateral, antero-posterior",
                )
                .shown("medio-lateral, antero-posterior"),
            ),
            Item::Key(key(
                "fat_thickness_mm",
                Ty::Real,
                "mm",
                Allowed::Rule("[1, 30] and below 40 % of the smaller semi-axis"),
                Def::Value("8.0"),
                "subcutaneous fat thickness",
            )),
            Item::Key(
                key(
                    "femur_center_mm",
                    MM2,
                    "mm",
                    Allowed::Rule("the femur 5 mm inside the fat"),
                    Def::Value("[8.0, 8.0]"),
                    "femur centre: lateral, anterior offset from the skin centre",
                )
                .shown("lateral, anterior offset from the skin centre"),
            ),
            Item::Key(key(
                "femur_diameter_mm",
                Ty::Real,
                "mm",
                Allowed::Rule("[10, 50], the femur 5 mm inside the fat"),
                Def::Value("28.0"),
                "femur diameter",
            )),
            Item::Key(key(
                "lateral_septum_deg",
                MM2,
                "deg",
                Allowed::Rule("each in [-120, 60]"),
                Def::Value("[-75.0, -35.0]"),
                "lateral septum angles about the femur centre, at the femur and at the fat (0 = lateral, 90 = anterior)",
            )),
            Item::Key(key(
                "medial_septum_deg",
                MM2,
                "deg",
                Allowed::Rule("each in [120, 300]"),
                Def::Value("[240.0, 170.0]"),
                "medial septum angles, at the femur and at the fat",
            )),
            Item::Key(key(
                "sartorius_angle_deg",
                Ty::Real,
                "deg",
                Allowed::Any,
                Def::Value("128.0"),
                "direction of the sartorius from the skin centre (90 = anterior, 180 = medial)",
            )),
            Item::Key(key(
                "sartorius_semi_axes_mm",
                MM2,
                "mm",
                Allowed::Rule("each in [2, 40]"),
                Def::Value("[16.0, 10.0]"),
                "sartorius ellipse semi-axes, along the skin and across",
            )),
            Item::Key(key(
                "gracilis_angle_deg",
                Ty::Real,
                "deg",
                Allowed::Any,
                Def::Value("205.0"),
                "direction of the gracilis from the skin centre",
            )),
            Item::Key(key(
                "gracilis_semi_axes_mm",
                MM2,
                "mm",
                Allowed::Rule("each in [2, 40]"),
                Def::Value("[13.0, 9.0]"),
                "gracilis ellipse semi-axes, along the skin and across",
            )),
        ],
    },
    TableSpec {
        name: "labels",
        array: false,
        doc: "A segmented image (MRI slice) as the geometry instead of `[thigh]`; its mesh size \
              is `[model] size_mm`.",
        banner: "",
        header: Header::Commented,
        header_comment: "a segmented MRI slice instead of [thigh]",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "image",
                    Ty::Text,
                    "",
                    Allowed::Rule("PNG/TIFF grey labels or NIfTI (.nii, .nii.gz)"),
                    Def::Text("required"),
                    "the label image",
                )
                .set("\"thigh_labels.png\"", "PNG/TIFF grey labels or NIfTI (.nii, .nii.gz)"),
            ),
            Item::Key(
                key(
                    "map",
                    Ty::Text,
                    "",
                    Allowed::Rule("`label=region` pairs, comma-separated"),
                    Def::Text("required"),
                    "the region of each label; any region name, given its [materials.REGION] when outside Table 1",
                )
                .set("\"1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=ischio\"", ""),
            ),
            Item::Key(
                key(
                    "bone",
                    Ty::Ints,
                    "",
                    Allowed::Any,
                    Def::Text("required"),
                    "the femur's label(s): a hole whose edge is fixed",
                )
                .set("[7]", "femur label(s): a hole whose edge is fixed"),
            ),
            Item::Key(key(
                "background",
                Ty::Ints,
                "",
                Allowed::Any,
                Def::Value("[0]"),
                "labels outside the thigh",
            )),
            Item::Key(
                key(
                    "pixel_size_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("the file's (NIfTI); required otherwise"),
                    "pixel size",
                )
                .set("0.7422", "unless the file gives it (NIfTI)"),
            ),
            Item::Key(
                key(
                    "slice",
                    Ty::Int,
                    "",
                    Allowed::Any,
                    Def::Text("required for a NIfTI volume of more than one slice"),
                    "axial slice of a NIfTI volume (from 0)",
                )
                .example("0", "axial slice of a NIfTI volume"),
            ),
            Item::Key(
                key(
                    "min_island_mm2",
                    Ty::Real,
                    "mm²",
                    closed(0.0, 1e4),
                    Def::Value("5.0"),
                    "smaller pieces of a label merge into their neighbour",
                )
                .shown("smaller pieces of a label merge into their neighbour"),
            ),
        ],
    },
    TableSpec {
        name: "materials.REGION",
        array: false,
        doc: "The material of a region (`[materials.FAT]`, `[materials.QUADRICEPS]`, ... or a \
              label map's own region): Table 1's compressible Neo-Hookean by default, or `law` \
              and that law's parameters, each with a unit suffix. A region outside Table 1 \
              gives every parameter of its law.",
        banner: "Materials: compressible Neo-Hookean W = C10 (I1bar - 3) + (1/D) (J - 1)^2 per region.\n\
                 Table 1 of the seed by default; override any region:",
        header: Header::InNote,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "law",
                    Ty::Text,
                    "",
                    Allowed::Rule("a registered law (below)"),
                    Def::Text("Table 1's neo-hookean for a Table 1 region"),
                    "the hyperelastic law; a law named gives all its parameters in the table",
                )
                .in_note(),
            ),
            Item::Note(
                "[materials.FAT]
c10_kpa = 0.8                    # or c10_mpa
d_per_mpa = 30.8
[materials.QUADRICEPS]
c10_kpa = 1.75
d_per_mpa = 18.0
[materials.ISCHIO]
c10_kpa = 3.0
d_per_mpa = 18.0
[materials.GRACILIS]
c10_kpa = 2.2
d_per_mpa = 18.0
[materials.SARTORIUS]
c10_kpa = 3.75
d_per_mpa = 18.0
# law = \"mooney-rivlin\"          # another law, with its own keys (the reference page)
",
            ),
        ],
    },
    TableSpec {
        name: "test",
        array: true,
        doc: "A loading test (the femur fixed): its `kind` and that kind's keys; the seed's \
              three (contention, compression, indentation) when the study gives none.",
        banner: "Loading tests (femur fixed); the seed's three by default.",
        header: Header::InNote,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "kind",
                    Ty::Text,
                    "",
                    Allowed::Rule("a registered kind (below)"),
                    Def::Text("required"),
                    "the loading test",
                )
                .in_note(),
            ),
            Item::Note(
                "[[test]]
kind = \"contention\"              # follower pressure on the whole skin
pressure_mmhg = 20.0             # or pressure_mpa
[[test]]
kind = \"compression\"             # rigid frictionless plate, force-controlled
side = \"anterior\"                # anterior, posterior, lateral, medial, or an angle in degrees
force_n_per_mm = 0.1             # per mm of thickness (plane strain)
[[test]]
kind = \"indentation\"             # rigid frictionless cylinder, force-controlled
side = \"anterior\"
radius_mm = 10.0
force_n_per_mm = 0.1
",
            ),
            Item::Key(
                key(
                    "curve",
                    Ty::Text,
                    "",
                    Allowed::Rule("a physical curve of the mesh"),
                    Def::Text("the skin; required for a Gmsh mesh's rigid test"),
                    "the physical curve of a Gmsh mesh the test acts on (`femu solve MESH.msh --study`)",
                )
                .example("\"skin\"", "a Gmsh mesh's physical curve it acts on"),
            ),
        ],
    },
    TableSpec {
        name: "interface",
        array: true,
        doc: "A sliding interface between two regions of a meshed thigh (built-in or label \
              image; not a deck): `tied` keeps the shared nodes, `frictionless` and `friction` \
              split the nodes of the regions' common boundary (its ends stay tied) and add a \
              node-to-segment contact, the first region slave, the second master.",
        banner: "Sliding interfaces between regions (none by default: the regions share their nodes).",
        header: Header::Commented,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "between",
                    Ty::Texts,
                    "",
                    Allowed::Rule("two regions of the model that touch"),
                    Def::Text("required"),
                    "the two regions, slave first",
                )
                .set("[\"QUADRICEPS\", \"ISCHIO\"]", "two regions of the thigh"),
            ),
            Item::Key(
                key(
                    "kind",
                    Ty::Text,
                    "",
                    Allowed::Words {
                        what: "interface kind",
                        words: &["tied", "frictionless", "friction"],
                    },
                    Def::Text("required"),
                    "shared nodes, normal contact only, or Coulomb friction",
                )
                .set("\"frictionless\"", "tied, frictionless or friction"),
            ),
            Item::Key(
                key(
                    "mu",
                    Ty::Real,
                    "",
                    Allowed::Real {
                        min: 0.0,
                        min_open: false,
                        max: f64::INFINITY,
                        max_open: false,
                    },
                    Def::Text("required for kind = \"friction\", else absent"),
                    "the Coulomb friction coefficient",
                )
                .example("0.2", "kind = \"friction\" only"),
            ),
        ],
    },
    TableSpec {
        name: "grid",
        array: false,
        doc: "The DIC grid of the virtual measurement (seed §2.4.1).",
        banner: "Measurement: the DIC grid and its noise (seed §2.4.1: 64 x 64 points 16 px apart, 1.5 px).",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(key(
                "counts",
                Ty::IntPair,
                "",
                Allowed::Rule("at least 2 x 2, at most 4e6 points"),
                Def::Value("[64, 64]"),
                "points along x and y",
            )),
            Item::Key(
                key(
                    "origin_mm",
                    MM2,
                    "mm",
                    Allowed::Rule("within ±1000 mm"),
                    Def::Text("the grid centred on the skin"),
                    "the lower-left point",
                )
                .example("[-70.0, -60.0]", "lower-left point; default: the grid centred on the skin"),
            ),
            Item::Key(
                key(
                    "spacing_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("the skin's larger extent / (count - 1)"),
                    "the distance between points",
                )
                .example("2.2", "default: the skin's larger extent / (count - 1)"),
            ),
        ],
    },
    TableSpec {
        name: "noise",
        array: false,
        doc: "The noise of the virtual measurement.",
        banner: "",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[Item::Key(
            key(
                "sigma_mm",
                Ty::Real,
                "mm",
                POSITIVE,
                Def::Value("0.0176"),
                "standard deviation of the displacement noise (1.5 px of 11.7 µm, seed §3.1.3)",
            )
            .shown("1.5 px of 11.7 um (seed §3.1.3)"),
        )],
    },
    TableSpec {
        name: "measurement",
        array: false,
        doc: "What is measured: the virtual field (FE field of the reference parameters plus \
              noise), a measured-field file, simulated B-mode images, or recorded frames. \
              `[[measurement]]`, a list of such tables, is fitted together (joint \
              identification).",
        banner: "",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "source",
                    Ty::Text,
                    "",
                    Allowed::Words {
                        what: "source",
                        words: &["virtual", "file", "ultrasound", "frames"],
                    },
                    Def::Value("\"virtual\""),
                    "virtual: FE field + noise; file: a measured-field CSV; ultrasound: simulated B-mode images under [probe], [ultrasound]; frames: recorded B-mode frames",
                )
                .shown(
                    "virtual: FE field of the reference parameters + noise;\n\
                     file: a measured-field CSV (x,y,ux,uy[,sx,sy][,w]);\n\
                     ultrasound: simulated B-mode images under [probe] and\n\
                     [ultrasound], identified by integrated DIC (beside DIC -> FEMU);\n\
                     frames: your recorded B-mode frames, identified by integrated DIC",
                ),
            ),
            Item::Key(
                key(
                    "file",
                    Ty::Text,
                    "",
                    Allowed::Rule("a CSV x,y,ux,uy[,sx,sy][,w]"),
                    Def::Text("required for source = \"file\""),
                    "the measured field",
                )
                .example("\"field.csv\"", "relative to this study file"),
            ),
            Item::Key(
                key(
                    "covariance",
                    Ty::Text,
                    "",
                    Allowed::Rule("a Matrix Market file"),
                    Def::Text("none"),
                    "the field's full covariance (`femu dic` writes it): weighted FEMU",
                )
                .example("\"field_covariance.mtx\"", "its full covariance (femu dic writes it): weighted FEMU"),
            ),
            Item::Key(
                key(
                    "weighting",
                    Ty::Text,
                    "",
                    Allowed::Words {
                        what: "weighting",
                        words: &["per-point", "covariance", "estimated"],
                    },
                    Def::Text("per-point; estimated with a covariance"),
                    "how a measured field's misfit is weighted: per point (sx, sy or w), by the covariance alone, or estimated (plus the error the residuals of a first fit show beyond it)",
                )
                .example(
                    "\"estimated\"",
                    "per-point (sx, sy or w; the default without covariance),\n\
                     covariance (the covariance alone), or estimated (the\n\
                     covariance, or the per-point variances, plus the error the\n\
                     residuals of a first fit show beyond it; the default with one)",
                ),
            ),
            Item::Key(
                key(
                    "units",
                    Ty::Text,
                    "",
                    Allowed::Words { what: "units", words: &["mm", "px"] },
                    Def::Value("\"mm\""),
                    "the units of the file (px with pixel_size_mm)",
                )
                .example("\"mm\"", "mm, or px with pixel_size_mm"),
            ),
            Item::Key(
                key(
                    "pixel_size_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("none (a DICOM's own for frames)"),
                    "mm per pixel of a file in px, or of recorded frames",
                )
                .example("0.0117", ""),
            ),
            Item::Key(
                key(
                    "origin_mm",
                    MM2,
                    "mm",
                    Allowed::Rule("finite"),
                    Def::Text("[0, 0]; [probe]'s placement for frames"),
                    "model coordinates of the file's (0, 0)",
                )
                .example("[-20.0, 60.0]", "model coordinates of the file's (0, 0)"),
            ),
            Item::Key(
                key(
                    "x_axis",
                    Ty::RealPair,
                    "",
                    Allowed::Rule("a unit vector"),
                    Def::Value("[1.0, 0.0]"),
                    "model direction of the file's +x",
                )
                .example("[1.0, 0.0]", "model direction of the file's +x"),
            ),
            Item::Key(
                key(
                    "y_axis",
                    Ty::RealPair,
                    "",
                    Allowed::Rule("a unit vector, perpendicular to x_axis"),
                    Def::Value("[0.0, 1.0]"),
                    "model direction of the file's +y ([0, -1] for image rows going down)",
                )
                .example("[0.0, -1.0]", "model direction of the file's +y (image rows go down)"),
            ),
            Item::Key(
                key(
                    "travel_sigma_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("none: no actuator term"),
                    "actuator term: the noise of the plate's (indenter's) measured travel",
                )
                .example("0.01", "actuator term: the plate's (indenter's) travel, measured"),
            ),
            Item::Key(
                key(
                    "travel_mm",
                    Ty::Real,
                    "mm",
                    Allowed::Rule("finite; a file measurement's only"),
                    Def::Text("none"),
                    "the measured travel of the force-controlled plate or indenter",
                )
                .example("6.99", "(a file measurement; the virtual one synthesizes it)"),
            ),
            Item::Key(
                key(
                    "speckle_frequency_mhz",
                    Ty::Real,
                    "MHz",
                    POSITIVE,
                    Def::Text("none: the speckle moves with the tissue"),
                    "B-mode frames of a measured file: the echo's centre frequency, for the speckle's lateral shift under shear (with speckle_resolution_mm)",
                )
                .example("9.0", "the frames' centre frequency: the speckle's shift under shear"),
            ),
            Item::Key(
                key(
                    "speckle_resolution_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("none; required with speckle_frequency_mhz"),
                    "the frames' lateral resolution: FWHM of the point-spread function across the beam",
                )
                .example("0.9", "lateral resolution (FWHM of the point-spread function)"),
            ),
            Item::Key(
                key(
                    "speckle_sound_speed_m_s",
                    Ty::Real,
                    "m/s",
                    POSITIVE,
                    Def::Value("1540.0"),
                    "the speed of sound the frames were beamformed with",
                )
                .example("1540.0", "the beamforming's speed of sound"),
            ),
            Item::Key(
                key(
                    "speckle_shift",
                    Ty::Text,
                    "",
                    Allowed::Words {
                        what: "speckle shift",
                        words: &["fitted", "fixed"],
                    },
                    Def::Value("\"fitted\""),
                    "the shift's scale estimated with the parameters (its uncertainty in their intervals), or held at the closed form's",
                )
                .example("\"fitted\"", "fitted with the parameters, or fixed (the closed form)"),
            ),
            Item::Key(
                key(
                    "speckle_scale",
                    Ty::Real,
                    "",
                    Allowed::Rule(">= 0; with speckle_shift = \"fixed\" only"),
                    Def::Value("1.0"),
                    "the scale held with speckle_shift = \"fixed\" (1: the closed form; a scanner's calibrated value)",
                )
                .example("1.0", "held scale with speckle_shift = \"fixed\""),
            ),
            Item::Key(
                key(
                    "test",
                    Ty::Text,
                    "",
                    Allowed::Rule("a [[test]] name or kind"),
                    Def::Text("[identification] test"),
                    "the measured test",
                )
                .example("\"compression\"", "the measured [[test]] ([identification] test by default)"),
            ),
            Item::Key(
                key(
                    "window",
                    Ty::Text,
                    "",
                    Allowed::Rule("anterior, posterior, lateral, medial, or degrees"),
                    Def::Text("none: the grid"),
                    "seen through a probe window on this side instead of the grid",
                )
                .example("\"anterior\"", "seen through a probe window on this side instead of the grid"),
            ),
            Item::Key(
                key(
                    "window_mm",
                    MM2,
                    "mm",
                    Allowed::Rule("each in (0, 200]"),
                    Def::Text("[probe] width_mm, depth_mm"),
                    "the window's width and depth",
                )
                .example("[40.0, 40.0]", "its width x depth ([probe] by default)"),
            ),
            Item::Key(
                key(
                    "spacing_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("16 px of [probe]"),
                    "the window's grid spacing",
                )
                .example("1.6", "its grid spacing (16 px of [probe] by default)"),
            ),
            Item::Key(
                key(
                    "sigma_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("[noise] sigma_mm"),
                    "this measurement's noise",
                )
                .example("0.0176", "this measurement's noise ([noise] by default)"),
            ),
            Item::Note("# Recorded frames (source = \"frames\"), the unloaded frame first:\n"),
            Item::Key(
                key(
                    "frames",
                    Ty::Texts,
                    "",
                    Allowed::Rule("PNG/TIFF (8/16 bit) or DICOM files, the unloaded first"),
                    Def::Text("none"),
                    "recorded frames, one file per frame",
                )
                .example("[\"f0.png\", \"f1.png\"]", "PNG/TIFF (8/16 bit) or DICOM, one per frame, or"),
            ),
            Item::Key(
                key(
                    "cine",
                    Ty::Text,
                    "",
                    Allowed::Rule("a multi-frame DICOM"),
                    Def::Text("none"),
                    "recorded frames in one multi-frame DICOM (cropped to its ultrasound region)",
                )
                .example("\"loop.dcm\"", "one multi-frame DICOM (cropped to its ultrasound region) with"),
            ),
            Item::Key(
                key(
                    "frame_indices",
                    Ty::Ints,
                    "",
                    Allowed::Rule("frames of the cine, from 0"),
                    Def::Text("none"),
                    "the cine's frames by index",
                )
                .example("[0, 30]", "its frames by index (from 0), or"),
            ),
            Item::Key(
                key(
                    "frame_times_s",
                    Ty::Reals,
                    "s",
                    Allowed::Rule("finite, increasing"),
                    Def::Text("none"),
                    "the cine's frames by time, or the times of a list of files (for a force log)",
                )
                .example("[0.0, 1.2]", "by time (a list of files: their times, for a force log)"),
            ),
            Item::Note(
                "# pixel_size_mm = 0.1            # mm/px (a DICOM gives its own); units = \"px\" if given\n\
                 # origin_mm, x_axis, y_axis      # the frames' placement as above; [probe] when absent\n",
            ),
            Item::Key(
                key(
                    "loads_n_per_mm",
                    Ty::Reals,
                    "N/mm",
                    Allowed::Rule("one per loaded frame"),
                    Def::Text("none"),
                    "the force on each loaded frame",
                )
                .example("[0.1]", "the force on each loaded frame, or"),
            ),
            Item::Key(
                key(
                    "force_log",
                    Ty::Text,
                    "",
                    Allowed::Rule("a CSV of time,force rows"),
                    Def::Text("none"),
                    "a force log read at the frames' times ('# units: s, N/mm' or ms, mN/mm)",
                )
                .example("\"force.csv\"", "time,force rows with '# units: s, N/mm' (or ms, mN/mm), read at"),
            ),
            Item::Key(
                key(
                    "force_log_units",
                    Ty::Texts,
                    "",
                    Allowed::Rule("[s or ms, N/mm or mN/mm]"),
                    Def::Text("the log's units line"),
                    "the force log's units when it has no units line",
                )
                .example("[\"s\", \"N/mm\"]", "the frames' times (units here if the log has no line)"),
            ),
            Item::Key(
                key(
                    "force_log_offset_s",
                    Ty::Real,
                    "s",
                    Allowed::Rule("finite"),
                    Def::Value("0.0"),
                    "the log's clock minus the frames'",
                )
                .example("0.0", "the log's clock minus the frames'"),
            ),
            Item::Key(
                key(
                    "pose",
                    Ty::Text,
                    "",
                    Allowed::Words { what: "pose", words: &["given", "refined"] },
                    Def::Value("\"given\""),
                    "the frames' placement as given (keys or [probe]), or refined from the unloaded frame: the model's skin, fascia and bone matched to its bright lines",
                )
                .example("\"refined\"", "as given, or refined from the unloaded frame's bright lines"),
            ),
            Item::Note(
                "
# A joint identification fits several measurements at once: replace the [measurement] table
# above by a list, one [[measurement]] per test and window (or grid, or file), with the keys
# above; e.g. the seed's two tests seen through two probe windows each:
# [[measurement]]
# test = \"contention\"
# window = \"anterior\"
# [[measurement]]
# test = \"contention\"
# window = \"lateral\"
# [[measurement]]
# test = \"compression\"
# window = \"anterior\"
# [[measurement]]
# test = \"compression\"
# window = \"lateral\"
",
            ),
        ],
    },
    TableSpec {
        name: "parameters",
        array: false,
        doc: "The parameters identified together. Parameter names are `C10_<REGION>` and \
              `D_<REGION>` (a law's own parameters likewise).",
        banner: "Identification (FEMU, seed §2.1.3): parameter names are C10_<REGION> and D_<REGION>.",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[Item::Key(
            key(
                "groups",
                Ty::TextLists,
                "",
                Allowed::Rule("parameters of the model"),
                Def::Value("[[\"D_ISCHIO\", \"D_SARTORIUS\", \"D_GRACILIS\"]]"),
                "tied parameters (seed §2.4.2)",
            )
            .shown("tied parameters (seed §2.4.2)"),
        )],
    },
    TableSpec {
        name: "identification",
        array: false,
        doc: "How the parameters are identified (FEMU).",
        banner: "",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "test",
                    Ty::Text,
                    "",
                    Allowed::Rule("a [[test]] name or kind"),
                    Def::Text("the first compression test, else the first"),
                    "the test whose field is measured",
                )
                .set("\"compression\"", "the test whose field is measured"),
            ),
            Item::Key(
                key(
                    "grouped",
                    Ty::BoolOrText,
                    "",
                    Allowed::Rule("true, false or \"both\""),
                    Def::Value("\"both\""),
                    "identify with [parameters] groups tied, untied, or both one after the other (seed Fig. 9)",
                )
                .shown("true, false, or \"both\" (ungrouped and grouped, seed Fig. 9)"),
            ),
            Item::Key(
                key(
                    "optimizer",
                    Ty::Text,
                    "",
                    Allowed::Words { what: "optimizer", words: &["lm", "bfgs", "bfgs-fd"] },
                    Def::Value("\"lm\""),
                    "Levenberg-Marquardt (exact Jacobian), BFGS (exact gradient) or BFGS on finite differences (the seed's)",
                )
                .shown("lm (exact Jacobian), bfgs (exact gradient), bfgs-fd (the seed's)"),
            ),
            Item::Key(
                key(
                    "fixed",
                    Ty::Texts,
                    "",
                    Allowed::Rule("parameters of the model"),
                    Def::Value("[]"),
                    "parameters held at their reference value",
                )
                .shown("parameters held at their reference value"),
            ),
            Item::Key(
                key(
                    "bounds_factor",
                    Ty::Real,
                    "",
                    Allowed::Real {
                        min: 1.0,
                        min_open: true,
                        max: MAX_BOUNDS_FACTOR,
                        max_open: false,
                    },
                    Def::Value("4.0"),
                    "bounds: reference / factor .. reference x factor",
                )
                .shown("bounds: reference / 4 .. reference x 4"),
            ),
            Item::Key(
                key(
                    "starts",
                    Ty::Int,
                    "",
                    Allowed::Int { min: 1, max: 64 },
                    Def::Value("5"),
                    "Latin-hypercube starts",
                )
                .shown("Latin-hypercube starts"),
            ),
            Item::Key(
                key("seed", Ty::Int, "", Allowed::Any, Def::Value("1"), "seed of the noise and the starts")
                    .shown("noise and starts"),
            ),
            Item::Key(
                key(
                    "repeat",
                    Ty::Int,
                    "",
                    Allowed::Int { min: 1, max: 1000 },
                    Def::Value("1"),
                    "noise realizations (Monte Carlo error bars)",
                )
                .shown("noise realizations (Monte Carlo error bars)"),
            ),
            Item::Key(
                key(
                    "coarse_elements",
                    Ty::Int,
                    "",
                    Allowed::Rule("fewer than [model]'s elements; the built-in thigh's range"),
                    Def::Text("none: one level"),
                    "multilevel: the starts on a coarse built-in thigh of this many quads, the best refined on [model]",
                )
                .example(
                    "2000",
                    "multilevel: starts on a coarse built-in thigh, the best\n\
                     refined on [model] (paper-scale meshes in a minute)",
                ),
            ),
            Item::Key(
                key(
                    "loss",
                    Ty::Text,
                    "",
                    Allowed::Words { what: "loss", words: &["squared", "huber"] },
                    Def::Value("\"squared\""),
                    "the loss on the whitened residuals; huber is robust to a measured field's outliers",
                )
                .shown("squared, or huber (robust to outliers of a measured field)"),
            ),
            Item::Key(
                key(
                    "discretization",
                    Ty::Text,
                    "",
                    Allowed::Words { what: "choice", words: &["check", "refine", "off"] },
                    Def::Value("\"check\""),
                    "check: the bias the mesh implies, from refined meshes (intervals widened when not negligible); refine: also identify again on the finest; off",
                )
                .shown(
                    "check: the bias the mesh implies, from meshes refined by\n\
                     sqrt(2) and 2 (intervals widened when it is not negligible);\n\
                     refine: also identify again on the finest; off",
                ),
            ),
            Item::Key(
                key(
                    "data_refinement",
                    Ty::Real,
                    "",
                    closed(1.0, 4.0),
                    Def::Value("1.0"),
                    "virtual data made on a mesh with the element size divided by this (1: the model's own mesh)",
                )
                .shown(
                    "virtual data made on a mesh with the element size divided by\n\
                     this (1: the model's own mesh, the seed's numerical example)",
                ),
            ),
            Item::Key(
                key(
                    "image_normalization_px",
                    Ty::Real,
                    "px",
                    Allowed::ZeroOrReal {
                        min: MIN_IMAGE_NORMALIZATION_PX,
                        max: MAX_IMAGE_NORMALIZATION_PX,
                    },
                    Def::Value(DEFAULT_NORMALIZATION_TEXT),
                    "identification from images: each frame's grey levels normalized over this window (0: as recorded)",
                )
                .shown(
                    "identification from images: each frame's grey levels\n\
                     normalized over this window (px; 0: as recorded; else >= 0.5)",
                ),
            ),
            Item::Key(
                key(
                    "image_pairing",
                    Ty::Text,
                    "",
                    Allowed::Words {
                        what: "pairing",
                        words: &["all", "both", "consecutive", "reference"],
                    },
                    Def::Value("\"all\""),
                    "identification from images: each frame against every earlier one (all), against the one before and the unloaded one (both), or only one of these",
                )
                .shown(
                    "identification from images: each frame against every\n\
                     earlier one (all), against the one before and the unloaded\n\
                     one (both), or only \"consecutive\", or only \"reference\"",
                ),
            ),
        ],
    },
    TableSpec {
        name: "probe",
        array: false,
        doc: "The linear probe of the simulated B-mode acquisition (`[measurement] source = \
              \"ultrasound\"`, `femu us-sim`), and the default probe window of a measurement.",
        banner: "The simulated B-mode acquisition ([measurement] source = \"ultrasound\", femu us-sim).",
        header: Header::Commented,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "side",
                    Ty::Text,
                    "",
                    Allowed::Rule("anterior, posterior, lateral, medial, or degrees"),
                    Def::Value("\"anterior\""),
                    "where the probe stands on the skin",
                )
                .shown("the linear probe on the skin, its field of view"),
            ),
            Item::Key(key(
                "width_mm",
                Ty::Real,
                "mm",
                Allowed::Rule("the simulator's probe range"),
                Def::Value("40.0"),
                "field of view: width",
            )),
            Item::Key(key(
                "depth_mm",
                Ty::Real,
                "mm",
                Allowed::Rule("the simulator's probe range"),
                Def::Value("40.0"),
                "field of view: depth",
            )),
            Item::Key(key(
                "px_per_mm",
                Ty::Real,
                "1/mm",
                Allowed::Rule("the simulator's probe range"),
                Def::Value("10.0"),
                "image pixels per mm",
            )),
        ],
    },
    TableSpec {
        name: "ultrasound",
        array: false,
        doc: "The transducer and the scanner of the simulated B-mode acquisition.",
        banner: "",
        header: Header::Commented,
        header_comment: "",
        tight: true,
        items: &[
            Item::Key(key(
                "frequency_mhz",
                Ty::Real,
                "MHz",
                closed(1.0, 30.0),
                Def::Value("9.0"),
                "centre frequency of the transducer",
            )),
            Item::Key(key(
                "cycles",
                Ty::Real,
                "",
                closed(1.0, 10.0),
                Def::Value("2.0"),
                "cycles of the transmitted pulse",
            )),
            Item::Key(key(
                "f_number",
                Ty::Real,
                "",
                closed(0.5, 10.0),
                Def::Value("3.0"),
                "f-number of the lateral focus",
            )),
            Item::Key(key(
                "gain_db",
                Ty::Real,
                "dB",
                closed(-20.0, 100.0),
                Def::Value("34.0"),
                "scanner gain",
            )),
            Item::Key(key(
                "dynamic_db",
                Ty::Real,
                "dB",
                closed(10.0, 120.0),
                Def::Value("42.0"),
                "dynamic range shown",
            )),
            Item::Key(key(
                "black_level_db",
                Ty::Real,
                "dB",
                closed(-100.0, 100.0),
                Def::Value("15.0"),
                "level shown black",
            )),
            Item::Key(key(
                "tgc_db_per_cm_mhz",
                Ty::Real,
                "dB/(cm MHz)",
                closed(0.0, 10.0),
                Def::Value("0.6"),
                "time-gain compensation slope",
            )),
            Item::Key(key(
                "tgc_max_db",
                Ty::Real,
                "dB",
                closed(0.0, 120.0),
                Def::Value("45.0"),
                "largest time-gain compensation",
            )),
            Item::Key(
                key(
                    "noise_db",
                    Ty::Real,
                    "dB",
                    closed(-200.0, 40.0),
                    Def::Value("-65.0"),
                    "electronic noise level",
                ),
            ),
            Item::Key(
                key("seed", Ty::Int, "", Allowed::Any, Def::Value("1"), "seed of the scatterers and the electronic noise")
                    .shown("scatterers and electronic noise"),
            ),
            Item::Key(
                key(
                    "render_refine",
                    Ty::Int,
                    "",
                    Allowed::Int { min: 1, max: MAX_RENDER_REFINE as u64 },
                    Def::Value("2"),
                    "images rendered on a mesh of [model]'s element size divided by this (1: the identified mesh, an inverse crime)",
                )
                .shown(
                    "images rendered on a mesh of element size / 2 (not the one\n\
                     identified: no inverse crime)",
                ),
            ),
            Item::Key(
                key(
                    "decorrelation",
                    Ty::Real,
                    "",
                    closed(0.0, 0.9),
                    Def::Value("0.05"),
                    "fraction of the scatterers renewed per load step (out-of-plane motion)",
                )
                .shown("fraction of the scatterers renewed per load step"),
            ),
        ],
    },
    TableSpec {
        name: "design",
        array: false,
        doc: "The candidate measurements of `femu design` (or `[run] design = true`): the tests \
              seen through probe windows, alone and combined, ranked by the predicted parameter \
              standard deviation.",
        banner: "Design of the experiment (`femu design`, or [run] design = true): the tests seen through probe\n\
                 windows, alone and combined, ranked by the predicted parameter sd.",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "tests",
                    Ty::Texts,
                    "",
                    Allowed::Rule("[[test]] names or kinds"),
                    Def::Text("every [[test]]"),
                    "the tests of the candidates",
                )
                .set("[\"contention\", \"compression\", \"indentation\"]", ""),
            ),
            Item::Key(key(
                "sides",
                Ty::Texts,
                "",
                Allowed::Rule("anterior, posterior, lateral, medial, or degrees"),
                Def::Value("[\"anterior\", \"lateral\", \"medial\", \"posterior\"]"),
                "the probe window's sides",
            )),
            Item::Key(
                key(
                    "windows_mm",
                    Ty::RealPairs,
                    "mm",
                    Allowed::Rule("each in (0, 200]"),
                    Def::Value("[[40.0, 40.0], [60.0, 40.0]]"),
                    "the probe window sizes, width x depth",
                )
                .shown("probe width x depth"),
            ),
            Item::Key(
                key(
                    "spacing_mm",
                    Ty::Real,
                    "mm",
                    POSITIVE,
                    Def::Text("16 px of [probe]"),
                    "grid spacing in a window",
                )
                .example("1.6", "grid spacing in a window (16 px of [probe])"),
            ),
            Item::Key(
                key(
                    "max_measurements",
                    Ty::Int,
                    "",
                    Allowed::Int { min: 1, max: 4 },
                    Def::Value("2"),
                    "measurements per design",
                )
                .shown("measurements per design"),
            ),
            Item::Key(
                key(
                    "identifiable_sd",
                    Ty::Real,
                    "",
                    up_to(1.0),
                    Def::Value("0.1"),
                    "a parameter is identified below this relative standard deviation",
                )
                .shown("a parameter is identified below this relative sd"),
            ),
            Item::Key(
                key("grouped", Ty::Bool, "", Allowed::Any, Def::Value("false"), "tie [parameters] groups")
                    .shown("tie [parameters] groups"),
            ),
        ],
    },
    TableSpec {
        name: "run",
        array: false,
        doc: "The steps of `femu run` (the model step always runs).",
        banner: "Steps of `femu run` (the model step always runs).",
        header: Header::Plain,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key("forward", Ty::Bool, "", Allowed::Any, Def::Value("true"), "each test solved: deformed shape with LE11 (seed Fig. 3)")
                    .shown("each test solved: deformed shape with LE11 (seed Fig. 3)"),
            ),
            Item::Key(
                key("sensitivity", Ty::Bool, "", Allowed::Any, Def::Value("true"), "sensitivity maps and the test ranking (seed Fig. 8)")
                    .shown("sensitivity maps and the test ranking (seed Fig. 8)"),
            ),
            Item::Key(
                key("identification", Ty::Bool, "", Allowed::Any, Def::Value("true"), "measurement and identification (seed Fig. 9)")
                    .shown("measurement and identification (seed Fig. 9)"),
            ),
            Item::Key(
                key("design", Ty::Bool, "", Allowed::Any, Def::Value("false"), "the design of the experiment ([design])")
                    .shown("the design of the experiment ([design])"),
            ),
        ],
    },
    TableSpec {
        name: "convergence",
        array: false,
        doc: "The mesh convergence study of `femu convergence` on the study's geometry, \
              materials and test: the field on a sequence of meshes of each element type.",
        banner: "Mesh convergence study (`femu convergence`): the study's thigh, materials and test on a\n\
                 sequence of meshes of each element type.",
        header: Header::Commented,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "element_types",
                    Ty::Texts,
                    "",
                    Allowed::Rule("CPE4, CPE4H, CPE3, each once"),
                    Def::Value("[\"CPE4H\", \"CPE4\", \"CPE3\"]"),
                    "the element types compared",
                ),
            ),
            Item::Key(
                key(
                    "target_elements",
                    Ty::Ints,
                    "",
                    Allowed::Rule("the built-in thigh's range; not with element_size_mm"),
                    Def::Value("[1500, 3000, 6000, 12000, 25000, 50000]"),
                    "the meshes by element count",
                )
                .shown("the meshes, or"),
            ),
            Item::Key(
                key(
                    "element_size_mm",
                    Ty::Reals,
                    "mm",
                    Allowed::Rule("positive; not with target_elements"),
                    Def::Text("none"),
                    "the meshes by element size",
                )
                .example("[4.0, 2.0, 1.0]", "by element size"),
            ),
            Item::Key(
                key(
                    "tolerance_mm",
                    Ty::Real,
                    "mm",
                    up_to(10.0),
                    Def::Value("1e-4"),
                    "the displacement difference below which a mesh is converged",
                ),
            ),
            Item::Key(
                key("locking", Ty::Bool, "", Allowed::Any, Def::Value("true"), "also the locking study (every D scaled by d_scale)")
                    .shown("also the locking study (every D scaled by d_scale)"),
            ),
            Item::Key(key(
                "d_scale",
                Ty::Real,
                "",
                Allowed::Real { min: 0.0, min_open: true, max: 1.0, max_open: true },
                Def::Value("1e-3"),
                "factor on every D of the locking study",
            )),
            Item::Key(
                key(
                    "locking_meshes",
                    Ty::Int,
                    "",
                    Allowed::Rule("[1, the number of meshes]"),
                    Def::Value("2"),
                    "meshes of the locking study",
                ),
            ),
            Item::Key(
                key(
                    "raster_mm",
                    Ty::Real,
                    "mm",
                    closed(0.05, 0.5),
                    Def::Text("from the tissue's area"),
                    "raster of the field comparison between meshes",
                )
                .example("0.2", ""),
            ),
            Item::Key(
                key(
                    "test",
                    Ty::Text,
                    "",
                    Allowed::Rule("a [[test]] name or kind"),
                    Def::Text("the first [[test]]"),
                    "the test run on every mesh",
                )
                .example("\"contention\"", "the [[test]] run on every mesh (the first by default)"),
            ),
        ],
    },
    TableSpec {
        name: "fixed",
        array: true,
        doc: "A fixed physical curve of a Gmsh mesh (`femu solve MESH.msh --study`).",
        banner: "Boundary conditions of a Gmsh mesh (`femu solve MESH.msh --study`), by physical curve;\n\
                 [materials.NAME] then name its physical surfaces.",
        header: Header::Commented,
        header_comment: "",
        tight: false,
        items: &[
            Item::Key(
                key(
                    "curve",
                    Ty::Text,
                    "",
                    Allowed::Rule("a physical curve of the mesh"),
                    Def::Text("required"),
                    "the curve",
                )
                .set("\"femur\"", "a physical curve"),
            ),
            Item::Key(
                key(
                    "dofs",
                    Ty::Ints,
                    "",
                    Allowed::Rule("1 and/or 2 (plane strain)"),
                    Def::Value("[1, 2]"),
                    "the fixed displacement components",
                ),
            ),
            Item::Key(key(
                "value_mm",
                Ty::Real,
                "mm",
                Allowed::Rule("finite"),
                Def::Value("0.0"),
                "the imposed displacement",
            )),
        ],
    },
    TableSpec {
        name: "pressure",
        array: true,
        doc: "A follower pressure on a physical curve of a Gmsh mesh; exactly one of `mmhg` and \
              `mpa`.",
        banner: "",
        header: Header::Commented,
        header_comment: "",
        tight: true,
        items: &[
            Item::Key(
                key(
                    "curve",
                    Ty::Text,
                    "",
                    Allowed::Rule("a physical curve of the mesh"),
                    Def::Text("required"),
                    "the curve",
                )
                .set("\"skin\"", "follower pressure on it"),
            ),
            Item::Key(
                key(
                    "mmhg",
                    Ty::Real,
                    "mmHg",
                    Allowed::Rule("finite; exactly one of mmhg, mpa"),
                    Def::Text("required (or mpa)"),
                    "the pressure",
                )
                .set("20.0", "or mpa"),
            ),
            Item::Key(
                key(
                    "mpa",
                    Ty::Real,
                    "MPa",
                    Allowed::Rule("finite; exactly one of mmhg, mpa"),
                    Def::Text("required (or mmhg)"),
                    "the pressure",
                )
                .example("0.00267", ""),
            ),
        ],
    },
    TableSpec {
        name: "step",
        array: false,
        doc: "The increments of a Gmsh mesh's static step (as Abaqus's *STATIC).",
        banner: "",
        header: Header::Commented,
        header_comment: "as *STATIC",
        tight: true,
        items: &[
            Item::Key(key(
                "initial_increment",
                Ty::Real,
                "",
                up_to(1.0),
                Def::Value("1.0"),
                "first increment (fraction of the step)",
            )),
            Item::Key(key(
                "min_increment",
                Ty::Real,
                "",
                Allowed::Rule("(0, initial_increment]"),
                Def::Value("1e-5"),
                "smallest increment",
            )),
            Item::Key(key(
                "max_increment",
                Ty::Real,
                "",
                Allowed::Rule("[initial_increment, 1]"),
                Def::Value("1.0"),
                "largest increment",
            )),
            Item::Key(key(
                "max_increments",
                Ty::Int,
                "",
                Allowed::Rule("≥ 1"),
                Def::Value("100"),
                "most increments",
            )),
        ],
    },
];

/// [`DEFAULT_IMAGE_NORMALIZATION_PX`](super::identification::DEFAULT_IMAGE_NORMALIZATION_PX) as written in the study file (checked by a unit test).
const DEFAULT_NORMALIZATION_TEXT: &str = "0.75";

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema::DEFAULT_IMAGE_NORMALIZATION_PX;

    #[test]
    fn the_normalization_default_is_the_parsers() {
        let v: f64 = DEFAULT_NORMALIZATION_TEXT.parse().unwrap();
        assert_eq!(v, DEFAULT_IMAGE_NORMALIZATION_PX);
    }
}
