//! Abaqus/CalculiX input decks (`.inp`): a reader for the subset femu solves, a writer whose
//! output both femu and CalculiX 2.20 (`ccx`) accept, and a reader for the displacements that
//! `ccx` prints into its `.dat` file.
//!
//! # Subset read by [`parse_inp`]
//!
//! Keywords and parameter names are case-insensitive (blanks inside a keyword are ignored, so
//! `*SOLID SECTION` and `*SOLIDSECTION` are the same), `**` lines and blank lines are comments,
//! and a data line that ends with `,` continues on the next data line. Set, surface and
//! material names are case-insensitive as in Abaqus; the spelling of their first definition is
//! kept (region names, the keys of [`Mesh::node_sets`] and [`Mesh::element_sets`]).
//!
//! | keyword | use |
//! |---|---|
//! | `*HEADING` | text ignored |
//! | `*NODE[, NSET=]` | `label, x, y[, z]` (z ignored) |
//! | `*ELEMENT, TYPE=CPE4\|CPE4H\|CPE3[, ELSET=]` | `label, n1, n2, n3[, n4]` |
//! | `*NSET, NSET=[, GENERATE]`, `*ELSET, ELSET=[, GENERATE]` | labels or names of sets defined earlier; `first, last[, step]` with `GENERATE` |
//! | `*SURFACE, NAME=[, TYPE=ELEMENT]` | `element or element set, S1..S4` |
//! | `*MATERIAL, NAME=` then `*HYPERELASTIC, <law>` | the law's constants, stored as given in [`MaterialDef`]; which laws exist and what their constants may be is the material registry's (`femu_mech::material`), checked when a model is built, with errors naming the data line |
//! | `*SOLID SECTION, ELSET=, MATERIAL=` | optional thickness line; must be 1 (per-mm plane strain) |
//! | `*BOUNDARY` (model or step data) | `node or node set, first dof[, last dof][, value]`; dofs 1 (x) and 2 (y); a range from 1 or 2 may run to 6 (3–6 are absent in plane strain), a line constraining neither 1 nor 2, or naming a dof above 6, is an error |
//! | `*STEP[, NLGEOM[=YES\|NO]][, INC=n]` … `*END STEP` | exactly one step |
//! | `*STATIC` | `initial, period, min, max` (Abaqus defaults for missing values) |
//! | `*DLOAD` | `element or element set, P1..P4, pressure` or `surface, P, pressure` |
//! | `*CLOAD` | `node or node set, dof (1 or 2), force` |
//! | `*NODE PRINT`, `*NODE FILE`, `*EL PRINT`, `*EL FILE`, `*OUTPUT`, `*NODE OUTPUT`, `*ELEMENT OUTPUT`, `*CONTACT OUTPUT` | accepted, data skipped |
//!
//! Any other keyword or parameter is an error naming it and its line: femu never silently skips
//! something that could change the physics.
//!
//! `NLGEOM` absent from `*STEP` reads as `true`: CalculiX switches geometric nonlinearity on for
//! hyperelastic materials unless the deck says `NLGEOM=NO` (checked with ccx 2.20), and every
//! material femu reads is hyperelastic.
//!
//! Repeated loads or boundary conditions on the same node dof or element face replace the
//! earlier value (Abaqus `OP=MOD`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs;
use std::io::{self, Write};
use std::path::Path;

use crate::deck::{BoundaryCondition, Deck, FacePressure, MaterialDef, PointLoad, StepDef};
use crate::mesh::{Element, ElementKind, Mesh, MeshError};
use crate::mesh3d::{Element3, ElementKind3, Mesh3};

/// An error reading a deck (or a ccx `.dat` file): names the file and, where there is one, the
/// 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum InpError {
    /// The file could not be read.
    #[error("{file}: {source}")]
    Io {
        file: String,
        #[source]
        source: io::Error,
    },
    /// Something wrong on one line.
    #[error("{file}:{line}: {message}")]
    Line {
        file: String,
        line: usize,
        message: String,
    },
    /// Something wrong with the deck as a whole (e.g. no `*STEP`).
    #[error("{file}: {message}")]
    Deck { file: String, message: String },
}

type Result<T> = std::result::Result<T, InpError>;

/// Reads and resolves an input deck. See the [module documentation](self) for the subset.
pub fn read_inp(path: &Path) -> Result<Deck> {
    let file = path.display().to_string();
    let bytes = fs::read(path).map_err(|source| InpError::Io {
        file: file.clone(),
        source,
    })?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..at].iter().filter(|b| **b == b'\n').count();
        InpError::Line {
            file: file.clone(),
            line,
            message: format!(
                "not a text deck: byte {} is not UTF-8 text (an Abaqus/CalculiX deck is a text file)",
                at + 1
            ),
        }
    })?;
    parse_inp(&text, &file)
}

/// Parses and resolves the text of an input deck; `file_name` is only used in error messages.
pub fn parse_inp(text: &str, file_name: &str) -> Result<Deck> {
    let mut p = Parser::new(file_name);
    lex(text, file_name, |b| p.block(b))?;
    p.finish()
}

/// Reads and resolves a 3D input deck: the subset of [`parse_inp`] with `*NODE` lines
/// `label, x, y, z`, `*ELEMENT, TYPE=C3D8|C3D8H|C3D4|C3D10`, faces `S1..S6` / `P1..P6` (as
/// [`crate::mesh3d`] numbers them), dofs 1–3 in `*BOUNDARY` and `*CLOAD`; the named surfaces
/// are kept in the mesh ([`Mesh3::surfaces`]).
pub fn read_inp3(path: &Path) -> Result<Deck3> {
    let file = path.display().to_string();
    let text = fs::read_to_string(path).map_err(|source| InpError::Io {
        file: file.clone(),
        source,
    })?;
    parse_inp3(&text, &file)
}

/// The text version of [`read_inp3`]; `file_name` is used in error messages.
pub fn parse_inp3(text: &str, file_name: &str) -> Result<Deck3> {
    let mut p = Parser::with_dim(file_name, 3);
    lex(text, file_name, |b| p.block(b))?;
    p.finish3()
}

/// The dimension of a deck's elements: 3 when its first `*ELEMENT` keyword has a `TYPE=C3D…`,
/// 2 otherwise (plane-strain `CPE…` types, or no element at all: the plane-strain reader then
/// names what is missing). Only the keyword lines are looked at; [`parse_inp`] or
/// [`parse_inp3`] reads the deck itself, and refuses a deck mixing the two.
pub fn deck_dimension(text: &str) -> usize {
    for line in text.lines() {
        let line = line.trim_start();
        if !line.starts_with('*') || line.starts_with("**") {
            continue;
        }
        let upper: String = line
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect::<String>()
            .to_ascii_uppercase();
        if upper.starts_with("*ELEMENT,") || upper == "*ELEMENT" {
            let is_3d = upper.split(',').any(|p| {
                p.strip_prefix("TYPE=")
                    .is_some_and(|t| t.starts_with("C3D"))
            });
            return if is_3d { 3 } else { 2 };
        }
    }
    2
}

// ---------------------------------------------------------------------------------------------
// Lexing: keyword blocks with their parameters and (continuation-joined) data records.

struct Field<'a> {
    text: &'a str,
    line: usize,
}

/// Fields of one data record: a node line has 3, a quad line 5; longer records (sets,
/// continuation lines) spill to the heap.
type Fields<'a> = smallvec::SmallVec<[Field<'a>; 6]>;

struct Record<'a> {
    line: usize,
    fields: Fields<'a>,
}

struct Param {
    /// Upper case, blanks removed.
    key: String,
    /// Upper case with single blanks, as shown in messages and kept where a parameter names
    /// something (`NEO HOOKE` of `*HYPERELASTIC`).
    display: String,
    value: Option<String>,
}

struct Block<'a> {
    line: usize,
    /// Keyword without `*`, upper case, blanks removed (`SOLIDSECTION`).
    key: String,
    /// Keyword as shown in messages (`*SOLID SECTION`).
    display: String,
    params: Vec<Param>,
    data: Vec<Record<'a>>,
}

fn squash(s: &str) -> String {
    s.chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .to_ascii_uppercase()
}

/// Splits `text` into keyword blocks and hands each to `on_block` as soon as it is complete,
/// in deck order. The blocks are not kept: the record vector of one is reused for the next, so
/// the deck is never held as records whole (on a paper-scale deck that saves touching about
/// 10 MB of fresh memory, half the cost of a cold parse).
fn lex<'a>(
    text: &'a str,
    file: &str,
    mut on_block: impl FnMut(&Block<'a>) -> Result<()>,
) -> Result<()> {
    let mut current: Option<Block<'a>> = None;
    let mut spare_records: Vec<Record<'a>> = Vec::new();
    // Whether the last data record ended with a comma and continues on the next data line.
    let mut continued = false;
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let t = raw.trim_start_matches('\u{feff}').trim();
        if t.is_empty() || t.starts_with("**") {
            continue;
        }
        if let Some(kw) = t.strip_prefix('*') {
            continued = false;
            let mut parts = kw.split(',');
            let name = parts.next().unwrap_or("").trim();
            let display = format!(
                "*{}",
                name.split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" ")
                    .to_ascii_uppercase()
            );
            let mut params = Vec::new();
            for part in parts {
                let part = part.trim();
                if part.is_empty() {
                    continue;
                }
                let (key, value) = match part.split_once('=') {
                    Some((k, v)) => (k, Some(v.trim().to_string())),
                    None => (part, None),
                };
                let display = key
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" ")
                    .to_ascii_uppercase();
                params.push(Param {
                    key: squash(key),
                    display,
                    value,
                });
            }
            if let Some(done) = current.take() {
                on_block(&done)?;
                spare_records = done.data;
                spare_records.clear();
            }
            current = Some(Block {
                line,
                key: squash(name),
                display,
                params,
                data: std::mem::take(&mut spare_records),
            });
            continue;
        }
        let Some(block) = current.as_mut() else {
            return Err(InpError::Line {
                file: file.to_string(),
                line,
                message: "data line before the first keyword".to_string(),
            });
        };
        let mut fields = Fields::new();
        let mut start = 0;
        for (i, &c) in t.as_bytes().iter().enumerate() {
            if c == b',' {
                fields.push(Field {
                    text: t[start..i].trim(),
                    line,
                });
                start = i + 1;
            }
        }
        // A trailing comma continues the record on the next data line.
        let ends_with_comma = start == t.len();
        if !ends_with_comma {
            fields.push(Field {
                text: t[start..].trim(),
                line,
            });
        }
        match (continued, block.data.last_mut()) {
            (true, Some(rec)) => rec.fields.extend(fields),
            _ => block.data.push(Record { line, fields }),
        }
        continued = ends_with_comma;
    }
    match current {
        Some(last) => on_block(&last),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// Parsing and resolution.

/// A node or element given by label, or a set (or surface) given by name.
enum Target {
    Label(i64),
    Name(String),
}

struct SetDef {
    /// Spelling of the first definition.
    name: String,
    /// Member labels with the line that named them.
    members: Vec<(i64, usize)>,
}

/// A plane-strain or a 3D element type (the reader's `dim` decides which it reads).
#[derive(Clone, Copy)]
enum RawKind {
    Two(ElementKind),
    Three(ElementKind3),
}

impl RawKind {
    fn node_count(self) -> usize {
        match self {
            RawKind::Two(k) => k.node_count(),
            RawKind::Three(k) => k.node_count(),
        }
    }

    fn face_count(self) -> usize {
        match self {
            RawKind::Two(k) => k.node_count(),
            RawKind::Three(k) => k.face_count(),
        }
    }

    fn deck_name(self) -> &'static str {
        match self {
            RawKind::Two(k) => k.deck_name(),
            RawKind::Three(k) => k.deck_name(),
        }
    }
}

struct RawElement {
    kind: RawKind,
    nodes: [i64; 10],
    line: usize,
}

struct RawMaterial {
    name: String,
    line: usize,
    /// The `*HYPERELASTIC` law keyword, its constants and the line of its data.
    law: Option<(String, Vec<f64>, usize)>,
}

struct RawSection {
    elset: String,
    material: String,
    line: usize,
}

struct RawSurface {
    name: String,
    faces: Vec<(Target, usize, usize)>, // target, 0-based face, line
}

struct RawBoundary {
    target: Target,
    first: usize,
    last: usize,
    value: f64,
    line: usize,
}

struct RawDload {
    target: Target,
    /// 0-based face, or `None` for `P` on a surface.
    face: Option<usize>,
    magnitude: f64,
    line: usize,
}

struct RawCload {
    target: Target,
    dof: usize,
    magnitude: f64,
    line: usize,
}

#[derive(PartialEq)]
enum State {
    Model,
    InStep,
    AfterStep,
}

struct Parser<'f> {
    file: &'f str,
    /// 2 (plane strain: `CPE*` elements, dofs 1–2, faces 1–4) or 3 (`C3D*`, dofs 1–3, faces
    /// up to 6).
    dim: usize,
    /// Coordinates (z is 0 when a plane-strain deck leaves it out, and unused there).
    nodes: Vec<[f64; 3]>,
    node_labels: Vec<i64>,
    node_map: LabelMap,
    elements: Vec<RawElement>,
    element_labels: Vec<i64>,
    element_map: LabelMap,
    nsets: Vec<SetDef>,
    nset_map: HashMap<String, usize>,
    elsets: Vec<SetDef>,
    elset_map: HashMap<String, usize>,
    surfaces: Vec<RawSurface>,
    surface_map: HashMap<String, usize>,
    materials: Vec<RawMaterial>,
    material_map: HashMap<String, usize>,
    current_material: Option<usize>,
    sections: Vec<RawSection>,
    boundaries: Vec<RawBoundary>,
    dloads: Vec<RawDload>,
    cloads: Vec<RawCload>,
    state: State,
    step_line: usize,
    step: StepDef,
    static_seen: bool,
}

const OUTPUT_REQUESTS: &[&str] = &[
    "NODEPRINT",
    "NODEFILE",
    "ELPRINT",
    "ELFILE",
    "OUTPUT",
    "NODEOUTPUT",
    "ELEMENTOUTPUT",
    "CONTACTOUTPUT",
];

/// Keywords that would change the physics if they were skipped.
const PHYSICS_KEYWORDS: &[&str] = &[
    "PLASTIC",
    "ELASTIC",
    "FRICTION",
    "CONTACTPAIR",
    "CONTACT",
    "SURFACEINTERACTION",
    "SURFACEBEHAVIOR",
    "DYNAMIC",
    "AMPLITUDE",
    "ORIENTATION",
    "DENSITY",
    "EXPANSION",
    "VISCOELASTIC",
    "HYPERFOAM",
    "USERMATERIAL",
    "DEPVAR",
    "CREEP",
    "EQUATION",
    "MPC",
    "TIE",
    "COUPLING",
    "KINEMATICCOUPLING",
    "DISTRIBUTINGCOUPLING",
    "RIGIDBODY",
    "TRANSFORM",
    "INITIALCONDITIONS",
    "TEMPERATURE",
    "DAMPING",
    "FREQUENCY",
    "BUCKLE",
    "VISCO",
    "HEATTRANSFER",
    "COUPLEDTEMPERATURE-DISPLACEMENT",
    "SHELLSECTION",
    "BEAMSECTION",
    "MEMBRANESECTION",
    "SPRING",
    "DASHPOT",
    "GAP",
    "DSLOAD",
    "DFLUX",
    "CFLUX",
    "FILM",
    "RADIATE",
    "MASS",
    "PRE-TENSIONSECTION",
    "CONTROLS",
    "CHANGEFRICTION",
    "MODELCHANGE",
];

const SUPPORTED: &str = "*HEADING, *NODE, *ELEMENT, *NSET, *ELSET, *SURFACE, *MATERIAL, \
*HYPERELASTIC, *SOLID SECTION, *BOUNDARY, *STEP, *STATIC, *DLOAD, *CLOAD, *END STEP and \
output requests";

impl<'f> Parser<'f> {
    fn new(file: &'f str) -> Self {
        Self::with_dim(file, 2)
    }

    fn with_dim(file: &'f str, dim: usize) -> Self {
        Parser {
            file,
            dim,
            nodes: Vec::new(),
            node_labels: Vec::new(),
            node_map: LabelMap::default(),
            elements: Vec::new(),
            element_labels: Vec::new(),
            element_map: LabelMap::default(),
            nsets: Vec::new(),
            nset_map: HashMap::new(),
            elsets: Vec::new(),
            elset_map: HashMap::new(),
            surfaces: Vec::new(),
            surface_map: HashMap::new(),
            materials: Vec::new(),
            material_map: HashMap::new(),
            current_material: None,
            sections: Vec::new(),
            boundaries: Vec::new(),
            dloads: Vec::new(),
            cloads: Vec::new(),
            state: State::Model,
            step_line: 0,
            step: StepDef::default(),
            static_seen: false,
        }
    }

    fn err(&self, line: usize, message: impl Into<String>) -> InpError {
        InpError::Line {
            file: self.file.to_string(),
            line,
            message: message.into(),
        }
    }

    // --- field helpers -------------------------------------------------------------------------

    fn num(&self, f: &Field) -> Result<f64> {
        if f.text.is_empty() {
            return Err(self.err(f.line, "a number is missing (empty field)"));
        }
        // Fortran exponents (1.5D3): rewritten only when present (no allocation otherwise).
        let parsed = if f.text.contains(['d', 'D']) {
            f.text.replace(['d', 'D'], "e").parse::<f64>()
        } else {
            f.text.parse::<f64>()
        };
        match parsed {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(
                f.line,
                format!(
                    "cannot read '{}' as a number (a finite decimal such as 0.5, -2 or 1.5e-3)",
                    f.text
                ),
            )),
        }
    }

    fn opt_num(&self, fields: &[Field], i: usize) -> Result<Option<f64>> {
        match fields.get(i) {
            Some(f) if !f.text.is_empty() => self.num(f).map(Some),
            _ => Ok(None),
        }
    }

    fn int(&self, f: &Field, what: &str) -> Result<i64> {
        if f.text.is_empty() {
            return Err(self.err(f.line, format!("{what} is missing (empty field)")));
        }
        f.text.parse::<i64>().map_err(|_| {
            self.err(
                f.line,
                format!("cannot read '{}' as {what} (an integer)", f.text),
            )
        })
    }

    fn dof(&self, f: &Field) -> Result<usize> {
        let d = self.int(f, "a degree of freedom")?;
        if d < 1 {
            return Err(self.err(
                f.line,
                format!("degree of freedom {d} does not exist (dofs start at 1)"),
            ));
        }
        Ok(d as usize)
    }

    fn target(&self, f: &Field, what: &str) -> Result<Target> {
        if f.text.is_empty() {
            return Err(self.err(f.line, format!("{what} is missing (empty field)")));
        }
        Ok(match f.text.parse::<i64>() {
            Ok(l) => Target::Label(l),
            Err(_) => Target::Name(f.text.to_string()),
        })
    }

    fn max_fields(&self, b: &Block, r: &Record, n: usize, form: &str) -> Result<()> {
        if let Some(extra) = r
            .fields
            .get(n..)
            .and_then(|x| x.iter().find(|f| !f.text.is_empty()))
        {
            return Err(self.err(
                extra.line,
                format!(
                    "{}: too many values on the data line (expected '{form}')",
                    b.display
                ),
            ));
        }
        Ok(())
    }

    // --- parameter helpers ---------------------------------------------------------------------

    fn check_params(&self, b: &Block, allowed: &[&str]) -> Result<()> {
        for p in &b.params {
            if !allowed.contains(&p.key.as_str()) {
                return Err(self.err(
                    b.line,
                    format!(
                        "{}: parameter '{}' is not supported{}",
                        b.display,
                        p.key,
                        if allowed.is_empty() {
                            String::new()
                        } else {
                            format!(" (supported: {})", allowed.join(", "))
                        }
                    ),
                ));
            }
        }
        Ok(())
    }

    fn param<'b>(b: &'b Block, key: &str) -> Option<&'b Param> {
        b.params.iter().find(|p| p.key == key)
    }

    fn value<'b>(&self, b: &'b Block, key: &str) -> Result<Option<&'b str>> {
        match Self::param(b, key) {
            None => Ok(None),
            Some(Param { value: Some(v), .. }) if !v.is_empty() => Ok(Some(v.as_str())),
            Some(_) => Err(self.err(
                b.line,
                format!("{}: parameter {key} needs a value ({key}=...)", b.display),
            )),
        }
    }

    fn required(&self, b: &'_ Block, key: &str) -> Result<String> {
        self.value(b, key)?.map(str::to_string).ok_or_else(|| {
            self.err(
                b.line,
                format!("{}: parameter {key}= is required", b.display),
            )
        })
    }

    /// `OP=MOD` (the default) is accepted; `OP=NEW` would remove earlier definitions.
    fn check_op(&self, b: &Block) -> Result<()> {
        if let Some(op) = self.value(b, "OP")? {
            if !op.eq_ignore_ascii_case("MOD") {
                return Err(self.err(
                    b.line,
                    format!("{}: OP={op} is not supported (only OP=MOD)", b.display),
                ));
            }
        }
        Ok(())
    }

    fn no_data(&self, b: &Block) -> Result<()> {
        match b.data.first() {
            Some(r) => Err(self.err(r.line, format!("{} takes no data lines", b.display))),
            None => Ok(()),
        }
    }

    // --- blocks --------------------------------------------------------------------------------

    fn block(&mut self, b: &Block) -> Result<()> {
        if b.key != "HYPERELASTIC" {
            self.current_material = None;
        }
        let model_data = matches!(
            b.key.as_str(),
            "NODE"
                | "ELEMENT"
                | "NSET"
                | "ELSET"
                | "SURFACE"
                | "MATERIAL"
                | "HYPERELASTIC"
                | "SOLIDSECTION"
                | "HEADING"
        );
        let step_data = matches!(b.key.as_str(), "STATIC" | "DLOAD" | "CLOAD" | "ENDSTEP")
            || OUTPUT_REQUESTS.contains(&b.key.as_str());
        if model_data && self.state != State::Model {
            return Err(self.err(
                b.line,
                format!(
                    "{} is model data and must come before *STEP (line {})",
                    b.display, self.step_line
                ),
            ));
        }
        if step_data && self.state != State::InStep && !OUTPUT_REQUESTS.contains(&b.key.as_str()) {
            return Err(self.err(
                b.line,
                format!("{} must be inside *STEP ... *END STEP", b.display),
            ));
        }
        match b.key.as_str() {
            "HEADING" => Ok(()),
            "NODE" => self.node(b),
            "ELEMENT" => self.element(b),
            "NSET" => self.set(b, false),
            "ELSET" => self.set(b, true),
            "SURFACE" => self.surface(b),
            "MATERIAL" => self.material(b),
            "HYPERELASTIC" => self.hyperelastic(b),
            "SOLIDSECTION" => self.solid_section(b),
            "BOUNDARY" => self.boundary(b),
            "STEP" => self.step(b),
            "STATIC" => self.static_(b),
            "DLOAD" => self.dload(b),
            "CLOAD" => self.cload(b),
            "ENDSTEP" => {
                self.check_params(b, &[])?;
                self.no_data(b)?;
                if !self.static_seen {
                    return Err(self.err(
                        b.line,
                        format!(
                            "the *STEP on line {} has no *STATIC procedure",
                            self.step_line
                        ),
                    ));
                }
                self.state = State::AfterStep;
                Ok(())
            }
            k if OUTPUT_REQUESTS.contains(&k) => Ok(()),
            k if PHYSICS_KEYWORDS.contains(&k) => Err(self.err(
                b.line,
                format!(
                    "{} is not supported (it would change the physics)",
                    b.display
                ),
            )),
            _ => Err(self.err(
                b.line,
                format!("{} is not supported (femu reads {SUPPORTED})", b.display),
            )),
        }
    }

    fn set_entry(&mut self, elset: bool, name: &str) -> usize {
        let (sets, map) = if elset {
            (&mut self.elsets, &mut self.elset_map)
        } else {
            (&mut self.nsets, &mut self.nset_map)
        };
        *map.entry(name.to_ascii_uppercase()).or_insert_with(|| {
            sets.push(SetDef {
                name: name.to_string(),
                members: Vec::new(),
            });
            sets.len() - 1
        })
    }

    fn node(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["NSET"])?;
        let nset = self.value(b, "NSET")?.map(|s| self.set_entry(false, s));
        for r in &b.data {
            if r.fields.len() < 3 {
                return Err(self.err(
                    r.line,
                    format!(
                        "*NODE: expected 'label, x, y', got {} value(s)",
                        r.fields.len()
                    ),
                ));
            }
            self.max_fields(b, r, 4, "label, x, y[, z]")?;
            let label = self.int(&r.fields[0], "a node label")?;
            if label < 1 {
                return Err(self.err(
                    r.line,
                    format!("*NODE: node label {label}: labels must be positive integers"),
                ));
            }
            let x = self.num(&r.fields[1])?;
            let y = self.num(&r.fields[2])?;
            let z = self.opt_num(&r.fields, 3)?;
            let checked = match (self.dim, z) {
                (2, _) => [x, y, 0.0],
                (_, Some(z)) => [x, y, z],
                (_, None) => {
                    return Err(self.err(
                        r.line,
                        format!("*NODE: node {label}: expected 'label, x, y, z' in a 3D deck"),
                    ))
                }
            };
            for v in &checked[..self.dim] {
                let v = *v;
                crate::mesh::check_coordinate(v)
                    .map_err(|m| self.err(r.line, format!("node {label}: {m}")))?;
            }
            if !self.node_map.insert(label, self.nodes.len()) {
                return Err(self.err(r.line, format!("node {label} is defined twice")));
            }
            self.nodes.push([x, y, z.unwrap_or(0.0)]);
            self.node_labels.push(label);
            if let Some(s) = nset {
                self.nsets[s].members.push((label, r.line));
            }
        }
        Ok(())
    }

    fn element(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["TYPE", "ELSET"])?;
        let ty = self.required(b, "TYPE")?;
        let kind = match self.dim {
            2 => ElementKind::from_deck_name(&ty).map(RawKind::Two),
            _ => ElementKind3::from_deck_name(&ty).map(RawKind::Three),
        }
        .ok_or_else(|| {
            self.err(
                b.line,
                format!(
                    "unknown element type '{ty}' in *ELEMENT (supported: {})",
                    if self.dim == 2 {
                        "CPE4, CPE4H, CPE3"
                    } else {
                        "C3D8, C3D8H, C3D4, C3D10 in a 3D deck"
                    }
                ),
            )
        })?;
        let elset = self.value(b, "ELSET")?.map(|s| self.set_entry(true, s));
        let n = kind.node_count();
        for r in &b.data {
            let label = self.int(&r.fields[0], "an element label")?;
            let given = r
                .fields
                .iter()
                .skip(1)
                .filter(|f| !f.text.is_empty())
                .count();
            if r.fields.len() != n + 1 || given != n {
                return Err(self.err(
                    r.line,
                    format!(
                        "*ELEMENT, TYPE={}: element {label} needs {n} node labels, got {given}",
                        kind.deck_name()
                    ),
                ));
            }
            let mut nodes = [0i64; 10];
            for (k, f) in r.fields[1..].iter().enumerate() {
                nodes[k] = self.int(f, "a node label")?;
            }
            if !self.element_map.insert(label, self.elements.len()) {
                return Err(self.err(r.line, format!("element {label} is defined twice")));
            }
            self.elements.push(RawElement {
                kind,
                nodes,
                line: r.line,
            });
            self.element_labels.push(label);
            if let Some(s) = elset {
                self.elsets[s].members.push((label, r.line));
            }
        }
        Ok(())
    }

    fn set(&mut self, b: &Block, elset: bool) -> Result<()> {
        let key = if elset { "ELSET" } else { "NSET" };
        self.check_params(b, &[key, "GENERATE", "UNSORTED", "INTERNAL"])?;
        let name = self.required(b, key)?;
        let generate = Self::param(b, "GENERATE").is_some();
        let mut members: Vec<(i64, usize)> = Vec::new();
        for r in &b.data {
            if generate {
                if r.fields.len() < 2 {
                    return Err(self.err(
                        r.line,
                        format!("{}, GENERATE: expected 'first, last[, step]'", b.display),
                    ));
                }
                self.max_fields(b, r, 3, "first, last[, step]")?;
                let first = self.int(&r.fields[0], "a label")?;
                let last = self.int(&r.fields[1], "a label")?;
                let step = match r.fields.get(2) {
                    Some(f) if !f.text.is_empty() => self.int(f, "a step")?,
                    _ => 1,
                };
                if step < 1 || last < first {
                    return Err(self.err(
                        r.line,
                        format!(
                            "{}, GENERATE: need first <= last and step >= 1, got {first}, {last}, {step}",
                            b.display
                        ),
                    ));
                }
                let count = (last as i128 - first as i128) / step as i128 + 1;
                if count > MAX_GENERATED as i128 {
                    return Err(self.err(
                        r.line,
                        format!(
                            "{}, GENERATE: {first}, {last}, {step} makes {count} members, above the limit of {MAX_GENERATED} (some {} MB)",
                            b.display,
                            count.saturating_mul(16) / 1_000_000
                        ),
                    ));
                }
                members.extend((first..=last).step_by(step as usize).map(|l| (l, r.line)));
            } else {
                for f in &r.fields {
                    if f.text.is_empty() {
                        continue;
                    }
                    match self.target(f, "a label")? {
                        Target::Label(l) => members.push((l, f.line)),
                        Target::Name(other) => {
                            let map = if elset {
                                &self.elset_map
                            } else {
                                &self.nset_map
                            };
                            let Some(&i) = map.get(&other.to_ascii_uppercase()) else {
                                return Err(self.err(
                                    f.line,
                                    format!(
                                        "{}: {} set '{other}' is not defined (sets must be defined before they are used)",
                                        b.display,
                                        if elset { "element" } else { "node" }
                                    ),
                                ));
                            };
                            let sets = if elset { &self.elsets } else { &self.nsets };
                            members.extend(sets[i].members.iter().copied());
                        }
                    }
                }
            }
        }
        let s = self.set_entry(elset, &name);
        let sets = if elset {
            &mut self.elsets
        } else {
            &mut self.nsets
        };
        sets[s].members.extend(members);
        Ok(())
    }

    fn surface(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["NAME", "TYPE"])?;
        let name = self.required(b, "NAME")?;
        if let Some(t) = self.value(b, "TYPE")? {
            if !t.eq_ignore_ascii_case("ELEMENT") {
                return Err(self.err(
                    b.line,
                    format!("*SURFACE, TYPE={t} is not supported (only TYPE=ELEMENT)"),
                ));
            }
        }
        let mut faces = Vec::new();
        for r in &b.data {
            self.max_fields(b, r, 2, "element or element set, Sn")?;
            let target = self.target(&r.fields[0], "an element or element set")?;
            let face_field = r
                .fields
                .get(1)
                .filter(|f| !f.text.is_empty())
                .ok_or_else(|| self.err(r.line, "*SURFACE: the face (S1..S4) is missing"))?;
            let max = self.max_face();
            let face = face_number(face_field.text, 'S', max).ok_or_else(|| {
                self.err(
                    face_field.line,
                    format!("*SURFACE: face '{}' is not S1..S{max}", face_field.text),
                )
            })?;
            faces.push((target, face, r.line));
        }
        let key = name.to_ascii_uppercase();
        match self.surface_map.get(&key) {
            Some(&i) => self.surfaces[i].faces.extend(faces),
            None => {
                self.surface_map.insert(key, self.surfaces.len());
                self.surfaces.push(RawSurface { name, faces });
            }
        }
        Ok(())
    }

    fn material(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["NAME"])?;
        self.no_data(b)?;
        let name = self.required(b, "NAME")?;
        let key = name.to_ascii_uppercase();
        if let Some(&i) = self.material_map.get(&key) {
            return Err(self.err(
                b.line,
                format!(
                    "material '{name}' is defined twice (first on line {})",
                    self.materials[i].line
                ),
            ));
        }
        self.material_map.insert(key, self.materials.len());
        self.current_material = Some(self.materials.len());
        self.materials.push(RawMaterial {
            name,
            line: b.line,
            law: None,
        });
        Ok(())
    }

    /// `*HYPERELASTIC, <law>` and its data line, stored as given: the law and the meaning of its
    /// constants are the material registry's (`femu_mech::material`), which reports bad values
    /// with the line kept here.
    fn hyperelastic(&mut self, b: &Block) -> Result<()> {
        let Some(m) = self.current_material else {
            return Err(self.err(b.line, "*HYPERELASTIC must follow a *MATERIAL definition"));
        };
        let keyword = match b.params.as_slice() {
            [p] if p.value.is_none() => p.display.clone(),
            given => {
                let given: Vec<&str> = given.iter().map(|p| p.display.as_str()).collect();
                return Err(self.err(
                    b.line,
                    format!(
                        "*HYPERELASTIC needs exactly one parameter, the law (e.g. *HYPERELASTIC, NEO HOOKE); given: {}",
                        if given.is_empty() {
                            "none, which means POLYNOMIAL".to_string()
                        } else {
                            given.join(", ")
                        }
                    ),
                ));
            }
        };
        if self.materials[m].law.is_some() {
            return Err(self.err(
                b.line,
                format!(
                    "material '{}' has two *HYPERELASTIC definitions",
                    self.materials[m].name
                ),
            ));
        }
        let r = match b.data.as_slice() {
            [r] => r,
            [] => {
                return Err(self.err(
                    b.line,
                    format!("*HYPERELASTIC, {keyword} needs a data line with its constants"),
                ))
            }
            [_, r2, ..] => {
                return Err(self.err(
                    r2.line,
                    "*HYPERELASTIC: one data line expected (temperature-dependent data is not supported)",
                ))
            }
        };
        // Blank trailing fields are absent values; a blank field before a number reads as 0,
        // as in Abaqus.
        let last = r.fields.iter().rposition(|f| !f.text.is_empty());
        let constants = r.fields[..last.map_or(0, |l| l + 1)]
            .iter()
            .map(|f| match f.text.is_empty() {
                true => Ok(0.0),
                false => self.num(f),
            })
            .collect::<Result<Vec<f64>>>()?;
        self.materials[m].law = Some((keyword, constants, r.line));
        Ok(())
    }

    fn solid_section(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["ELSET", "MATERIAL"])?;
        let elset = self.required(b, "ELSET")?;
        let material = self.required(b, "MATERIAL")?;
        match b.data.as_slice() {
            [] => {}
            [r] => {
                self.max_fields(b, r, 1, "thickness")?;
                if let Some(t) = self.opt_num(&r.fields, 0)? {
                    if t != 1.0 {
                        return Err(self.err(
                            r.line,
                            format!(
                                "*SOLID SECTION: thickness {t} is not supported: femu works per mm \
                                 of plane-strain thickness (give 1 or nothing)"
                            ),
                        ));
                    }
                }
            }
            [_, r2, ..] => {
                return Err(self.err(
                    r2.line,
                    "*SOLID SECTION: at most one data line (the thickness) is expected",
                ))
            }
        }
        self.sections.push(RawSection {
            elset,
            material,
            line: b.line,
        });
        Ok(())
    }

    fn boundary(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["OP", "TYPE"])?;
        self.check_op(b)?;
        if let Some(t) = self.value(b, "TYPE")? {
            if !t.eq_ignore_ascii_case("DISPLACEMENT") {
                return Err(self.err(
                    b.line,
                    format!("*BOUNDARY, TYPE={t} is not supported (only TYPE=DISPLACEMENT)"),
                ));
            }
        }
        for r in &b.data {
            self.max_fields(b, r, 4, "node or node set, first dof, last dof, value")?;
            let target = self.target(&r.fields[0], "a node or node set")?;
            let Some(ff) = r.fields.get(1).filter(|f| !f.text.is_empty()) else {
                return Err(self.err(r.line, "*BOUNDARY: the first degree of freedom is missing"));
            };
            if ff.text.parse::<i64>().is_err() && ff.text.chars().all(|c| c.is_ascii_alphabetic()) {
                return Err(self.err(
                    ff.line,
                    format!(
                        "*BOUNDARY: boundary type '{}' is not supported: give 'node or set, first dof, last dof, value'",
                        ff.text
                    ),
                ));
            }
            let first = self.dof(ff)?;
            let last = match r.fields.get(2) {
                Some(f) if !f.text.is_empty() => self.dof(f)?,
                _ => first,
            };
            if last < first {
                return Err(self.err(
                    r.line,
                    format!("*BOUNDARY: last dof {last} is smaller than first dof {first}"),
                ));
            }
            match self.dim {
                2 => check_plane_strain_dofs(first, last),
                _ => check_solid_dofs(first, last),
            }
            .map_err(|m| self.err(r.line, m))?;
            let value = self.opt_num(&r.fields, 3)?.unwrap_or(0.0);
            self.boundaries.push(RawBoundary {
                target,
                first,
                last,
                value,
                line: r.line,
            });
        }
        Ok(())
    }

    fn step(&mut self, b: &Block) -> Result<()> {
        match self.state {
            State::Model => {}
            State::InStep => {
                return Err(self.err(
                    b.line,
                    format!(
                        "*STEP inside the step of line {} (missing *END STEP?)",
                        self.step_line
                    ),
                ))
            }
            State::AfterStep => {
                return Err(self.err(
                    b.line,
                    format!(
                        "a second *STEP is not supported: femu solves exactly one step (the first is on line {})",
                        self.step_line
                    ),
                ))
            }
        }
        self.check_params(b, &["NLGEOM", "INC", "NAME", "AMPLITUDE"])?;
        self.no_data(b)?;
        self.state = State::InStep;
        self.step_line = b.line;
        self.step.nlgeom = match Self::param(b, "NLGEOM").and_then(|p| p.value.as_deref()) {
            None => true,
            Some(v) if v.eq_ignore_ascii_case("YES") => true,
            Some(v) if v.eq_ignore_ascii_case("NO") => false,
            Some(v) => return Err(self.err(b.line, format!("*STEP: NLGEOM={v} is not YES or NO"))),
        };
        if let Some(inc) = self.value(b, "INC")? {
            self.step.max_increments = match inc.parse::<usize>() {
                Ok(n) if n >= 1 => n,
                _ => {
                    return Err(self.err(
                        b.line,
                        format!("*STEP: INC={inc} is not a positive integer"),
                    ))
                }
            };
        }
        if let Some(a) = self.value(b, "AMPLITUDE")? {
            if !a.eq_ignore_ascii_case("RAMP") {
                return Err(self.err(
                    b.line,
                    format!("*STEP: AMPLITUDE={a} is not supported (loads are ramped: only RAMP)"),
                ));
            }
        }
        Ok(())
    }

    fn static_(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &[])?;
        if self.static_seen {
            return Err(self.err(b.line, "a second *STATIC in the step"));
        }
        self.static_seen = true;
        let r = match b.data.as_slice() {
            [] => None,
            [r] => Some(r),
            [_, r2, ..] => return Err(self.err(r2.line, "*STATIC: one data line expected")),
        };
        let fields: &[Field] = r.map(|r| r.fields.as_slice()).unwrap_or(&[]);
        if let Some(r) = r {
            self.max_fields(b, r, 4, "initial, period, min, max")?;
        }
        let initial = self.opt_num(fields, 0)?;
        let period = self.opt_num(fields, 1)?.unwrap_or(1.0);
        let initial = initial.unwrap_or(period);
        let min = self
            .opt_num(fields, 2)?
            .unwrap_or((1e-5 * period).min(initial));
        let max = self.opt_num(fields, 3)?.unwrap_or(period);
        let line = r.map(|r| r.line).unwrap_or(b.line);
        for (name, v) in [
            ("initial increment", initial),
            ("period", period),
            ("minimum increment", min),
            ("maximum increment", max),
        ] {
            if v <= 0.0 {
                return Err(self.err(line, format!("*STATIC: {name} must be > 0, got {v}")));
            }
        }
        if min > max {
            return Err(self.err(
                line,
                format!("*STATIC: minimum increment {min} is larger than maximum {max}"),
            ));
        }
        self.step.initial_increment = initial;
        self.step.period = period;
        self.step.min_increment = min;
        self.step.max_increment = max;
        Ok(())
    }

    fn dload(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["OP"])?;
        self.check_op(b)?;
        for r in &b.data {
            self.max_fields(b, r, 3, "element or element set, Pn, magnitude")?;
            if r.fields.len() < 3 {
                return Err(self.err(
                    r.line,
                    "*DLOAD: expected 'element or element set, Pn, magnitude'",
                ));
            }
            let target = self.target(&r.fields[0], "an element or element set")?;
            let t = &r.fields[1];
            let face = if t.text.eq_ignore_ascii_case("P") {
                None
            } else {
                let max = self.max_face();
                Some(face_number(t.text, 'P', max).ok_or_else(|| {
                    self.err(
                        t.line,
                        format!(
                            "*DLOAD: load type '{}' is not supported (only pressure P1..P{max} on an \
                             element face, or P on a *SURFACE)",
                            t.text
                        ),
                    )
                })?)
            };
            let magnitude = self.num(&r.fields[2])?;
            self.dloads.push(RawDload {
                target,
                face,
                magnitude,
                line: r.line,
            });
        }
        Ok(())
    }

    fn cload(&mut self, b: &Block) -> Result<()> {
        self.check_params(b, &["OP"])?;
        self.check_op(b)?;
        for r in &b.data {
            self.max_fields(b, r, 3, "node or node set, dof, magnitude")?;
            if r.fields.len() < 3 {
                return Err(self.err(
                    r.line,
                    "*CLOAD: expected 'node or node set, dof, magnitude'",
                ));
            }
            let target = self.target(&r.fields[0], "a node or node set")?;
            let dof = self.dof(&r.fields[1])?;
            if dof > self.dim {
                return Err(self.err(
                    r.fields[1].line,
                    match self.dim {
                        2 => format!(
                            "*CLOAD: dof {dof} does not exist in plane strain (only 1 and 2)"
                        ),
                        _ => format!("*CLOAD: dof {dof} is not a displacement dof (1, 2 or 3)"),
                    },
                ));
            }
            let magnitude = self.num(&r.fields[2])?;
            self.cloads.push(RawCload {
                target,
                dof,
                magnitude,
                line: r.line,
            });
        }
        Ok(())
    }

    /// The largest face number of the deck's elements: 4 in plane strain, 6 in 3D.
    fn max_face(&self) -> usize {
        if self.dim == 2 {
            4
        } else {
            6
        }
    }

    // --- resolution ----------------------------------------------------------------------------

    fn resolve_set(&self, set: &SetDef, map: &LabelMap, what: &str) -> Result<Vec<usize>> {
        let mut out = Vec::with_capacity(set.members.len());
        for &(label, line) in &set.members {
            match map.get(label) {
                Some(i) => out.push(i),
                None => {
                    return Err(self.err(
                        line,
                        format!("set '{}': {what} {label} is not defined", set.name),
                    ))
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        Ok(out)
    }

    fn finish(self) -> Result<Deck> {
        let r = self.resolve()?;
        let AnyMesh::Two(mesh) = r.mesh else {
            unreachable!("a plane-strain parser makes a 2D mesh")
        };
        Ok(Deck {
            mesh,
            materials: r.materials,
            element_material: r.element_material,
            element_region: r.element_region,
            region_names: r.region_names,
            step: r.step,
            boundaries: r.boundaries,
            pressures: r.pressures,
            point_loads: r.point_loads,
        })
    }

    fn finish3(self) -> Result<Deck3> {
        let r = self.resolve()?;
        let AnyMesh::Three(mesh) = r.mesh else {
            unreachable!("a 3D parser makes a 3D mesh")
        };
        Ok(Deck3 {
            mesh,
            materials: r.materials,
            element_material: r.element_material,
            element_region: r.element_region,
            region_names: r.region_names,
            step: r.step,
            boundaries: r.boundaries,
            pressures: r.pressures,
            point_loads: r.point_loads,
        })
    }

    /// Resolves the deck: its mesh (2D or 3D as `dim`), sets, materials, sections, supports
    /// and loads.
    fn resolve(self) -> Result<Resolved> {
        match self.state {
            State::Model => {
                return Err(InpError::Deck {
                    file: self.file.to_string(),
                    message: "the deck has no *STEP (femu solves exactly one static step)"
                        .to_string(),
                })
            }
            State::InStep => return Err(self.err(self.step_line, "this *STEP has no *END STEP")),
            State::AfterStep => {}
        }
        if self.elements.is_empty() {
            return Err(InpError::Deck {
                file: self.file.to_string(),
                message: "the deck defines no elements (*ELEMENT)".to_string(),
            });
        }

        // Mesh.
        let mut conns: Vec<[usize; 10]> = Vec::with_capacity(self.elements.len());
        for (e, raw) in self.elements.iter().enumerate() {
            let mut conn = [usize::MAX; 10];
            let n = raw.kind.node_count();
            for (slot, label) in conn.iter_mut().zip(&raw.nodes[..n]) {
                *slot = self.node_map.get(*label).ok_or_else(|| {
                    self.err(
                        raw.line,
                        format!(
                            "element {} refers to node {label}, which is not defined",
                            self.element_labels[e]
                        ),
                    )
                })?;
            }
            conns.push(conn);
        }
        let mut mesh = if self.dim == 2 {
            AnyMesh::Two(Mesh {
                nodes: self.nodes.iter().map(|p| [p[0], p[1]]).collect(),
                node_labels: self.node_labels.clone(),
                element_labels: self.element_labels.clone(),
                elements: self
                    .elements
                    .iter()
                    .zip(&conns)
                    .map(|(raw, c)| match raw.kind {
                        RawKind::Two(kind) => Element {
                            kind,
                            conn: [c[0], c[1], c[2], c[3]],
                        },
                        RawKind::Three(_) => unreachable!("2D deck"),
                    })
                    .collect(),
                ..Mesh::default()
            })
        } else {
            AnyMesh::Three(Mesh3 {
                nodes: self.nodes.clone(),
                node_labels: self.node_labels.clone(),
                element_labels: self.element_labels.clone(),
                elements: self
                    .elements
                    .iter()
                    .zip(&conns)
                    .map(|(raw, c)| match raw.kind {
                        RawKind::Three(kind) => Element3 { kind, conn: *c },
                        RawKind::Two(_) => unreachable!("3D deck"),
                    })
                    .collect(),
                ..Mesh3::default()
            })
        };
        let mut nsets: HashMap<String, Vec<usize>> = HashMap::new();
        for s in &self.nsets {
            let idx = self.resolve_set(s, &self.node_map, "node")?;
            nsets.insert(s.name.to_ascii_uppercase(), idx.clone());
            mesh.sets_mut().0.insert(s.name.clone(), idx);
        }
        let mut elsets: HashMap<String, Vec<usize>> = HashMap::new();
        for s in &self.elsets {
            let idx = self.resolve_set(s, &self.element_map, "element")?;
            elsets.insert(s.name.to_ascii_uppercase(), idx.clone());
            mesh.sets_mut().1.insert(s.name.clone(), idx);
        }
        let checked = match &mesh {
            AnyMesh::Two(m) => m.check_orientation(),
            AnyMesh::Three(m) => m.check_orientation(),
        };
        checked.map_err(|e| {
            let label = match &e {
                MeshError::Inverted { label, .. }
                | MeshError::InvertedSolid { label, .. }
                | MeshError::MissingNode { label, .. } => Some(*label),
                _ => None,
            };
            match label.and_then(|l| self.element_map.get(l)) {
                Some(i) => self.err(self.elements[i].line, e.to_string()),
                None => InpError::Deck {
                    file: self.file.to_string(),
                    message: e.to_string(),
                },
            }
        })?;

        // Materials and sections.
        let mut materials = Vec::with_capacity(self.materials.len());
        for m in &self.materials {
            let Some((keyword, constants, line)) = &m.law else {
                return Err(self.err(
                    m.line,
                    format!(
                        "material '{}' has no *HYPERELASTIC definition (e.g. *HYPERELASTIC, NEO HOOKE)",
                        m.name
                    ),
                ));
            };
            materials.push(MaterialDef {
                name: m.name.clone(),
                keyword: keyword.clone(),
                constants: constants.clone(),
                line: Some(*line),
            });
        }
        let n_el = self.elements.len();
        let mut element_material = vec![usize::MAX; n_el];
        let mut element_region = vec![usize::MAX; n_el];
        let mut region_names = Vec::with_capacity(self.sections.len());
        for (r, s) in self.sections.iter().enumerate() {
            let Some(&mat) = self.material_map.get(&s.material.to_ascii_uppercase()) else {
                return Err(self.err(
                    s.line,
                    format!("*SOLID SECTION: material '{}' is not defined", s.material),
                ));
            };
            let Some(members) = elsets.get(&s.elset.to_ascii_uppercase()) else {
                return Err(self.err(
                    s.line,
                    format!("*SOLID SECTION: element set '{}' is not defined", s.elset),
                ));
            };
            for &e in members {
                if element_region[e] != usize::MAX {
                    return Err(self.err(
                        s.line,
                        format!(
                            "element {} is in two *SOLID SECTIONs (lines {} and {})",
                            self.element_labels[e], self.sections[element_region[e]].line, s.line
                        ),
                    ));
                }
                element_region[e] = r;
                element_material[e] = mat;
            }
            region_names.push(s.elset.clone());
        }
        if let Some(e) = element_region.iter().position(|&r| r == usize::MAX) {
            return Err(self.err(
                self.elements[e].line,
                format!("element {} has no *SOLID SECTION", self.element_labels[e]),
            ));
        }

        // Boundary conditions and loads (later definitions replace earlier ones).
        let nodes_of = |t: &Target, line: usize, kw: &str| -> Result<Vec<usize>> {
            match t {
                Target::Label(l) => self
                    .node_map
                    .get(*l)
                    .map(|i| vec![i])
                    .ok_or_else(|| self.err(line, format!("{kw}: node {l} is not defined"))),
                Target::Name(n) => nsets
                    .get(&n.to_ascii_uppercase())
                    .cloned()
                    .ok_or_else(|| self.err(line, format!("{kw}: node set '{n}' is not defined"))),
            }
        };
        let mut boundaries: Vec<BoundaryCondition> = Vec::new();
        let mut bc_index: HashMap<(usize, usize), usize> = HashMap::new();
        for bc in &self.boundaries {
            for node in nodes_of(&bc.target, bc.line, "*BOUNDARY")? {
                for dof in bc.first..=bc.last.min(self.dim) {
                    let c = BoundaryCondition {
                        node,
                        dof: dof - 1,
                        value: bc.value,
                    };
                    match bc_index.get(&(node, dof - 1)) {
                        Some(&i) => boundaries[i] = c,
                        None => {
                            bc_index.insert((node, dof - 1), boundaries.len());
                            boundaries.push(c);
                        }
                    }
                }
            }
        }
        let mut point_loads: Vec<PointLoad> = Vec::new();
        let mut cl_index: HashMap<(usize, usize), usize> = HashMap::new();
        for cl in &self.cloads {
            for node in nodes_of(&cl.target, cl.line, "*CLOAD")? {
                let c = PointLoad {
                    node,
                    dof: cl.dof - 1,
                    magnitude: cl.magnitude,
                };
                match cl_index.get(&(node, cl.dof - 1)) {
                    Some(&i) => point_loads[i] = c,
                    None => {
                        cl_index.insert((node, cl.dof - 1), point_loads.len());
                        point_loads.push(c);
                    }
                }
            }
        }
        let elements_of = |t: &Target, line: usize, kw: &str| -> Result<Vec<usize>> {
            match t {
                Target::Label(l) => self
                    .element_map
                    .get(*l)
                    .map(|i| vec![i])
                    .ok_or_else(|| self.err(line, format!("{kw}: element {l} is not defined"))),
                Target::Name(n) => elsets.get(&n.to_ascii_uppercase()).cloned().ok_or_else(|| {
                    self.err(line, format!("{kw}: element set '{n}' is not defined"))
                }),
            }
        };
        let check_face = |e: usize, face: usize, line: usize, kw: &str, p: char| -> Result<()> {
            let kind = self.elements[e].kind;
            if face >= kind.face_count() {
                return Err(self.err(
                    line,
                    format!(
                        "{kw}: element {} is a {} with faces {p}1..{p}{}, not {p}{}",
                        self.element_labels[e],
                        kind.deck_name(),
                        kind.face_count(),
                        face + 1
                    ),
                ));
            }
            Ok(())
        };
        let mut pressures: Vec<FacePressure> = Vec::new();
        let mut p_index: HashMap<(usize, usize), usize> = HashMap::new();
        for dl in &self.dloads {
            let mut faces: Vec<(usize, usize)> = Vec::new();
            match dl.face {
                Some(face) => {
                    for e in elements_of(&dl.target, dl.line, "*DLOAD")? {
                        check_face(e, face, dl.line, "*DLOAD", 'P')?;
                        faces.push((e, face));
                    }
                }
                None => {
                    let Target::Name(name) = &dl.target else {
                        return Err(self.err(
                            dl.line,
                            "*DLOAD: load type P needs a surface name (use P1..P4 on an element)",
                        ));
                    };
                    let Some(&si) = self.surface_map.get(&name.to_ascii_uppercase()) else {
                        return Err(
                            self.err(dl.line, format!("*DLOAD: surface '{name}' is not defined"))
                        );
                    };
                    for (t, face, line) in &self.surfaces[si].faces {
                        let kw = format!("*SURFACE '{}'", self.surfaces[si].name);
                        for e in elements_of(t, *line, &kw)? {
                            check_face(e, *face, *line, &kw, 'S')?;
                            faces.push((e, *face));
                        }
                    }
                }
            }
            for (element, face) in faces {
                let p = FacePressure {
                    element,
                    face,
                    magnitude: dl.magnitude,
                };
                match p_index.get(&(element, face)) {
                    Some(&i) => pressures[i] = p,
                    None => {
                        p_index.insert((element, face), pressures.len());
                        pressures.push(p);
                    }
                }
            }
        }

        // The named surfaces of a 3D deck are kept in its mesh.
        if let AnyMesh::Three(m) = &mut mesh {
            for surface in &self.surfaces {
                let kw = format!("*SURFACE '{}'", surface.name);
                let mut faces = Vec::new();
                for (t, face, line) in &surface.faces {
                    for e in elements_of(t, *line, &kw)? {
                        check_face(e, *face, *line, &kw, 'S')?;
                        faces.push((e, *face));
                    }
                }
                m.surfaces.insert(surface.name.clone(), faces);
            }
        }

        Ok(Resolved {
            mesh,
            materials,
            element_material,
            element_region,
            region_names,
            step: self.step,
            boundaries,
            pressures,
            point_loads,
        })
    }
}

/// A 2D or a 3D mesh being read.
enum AnyMesh {
    Two(Mesh),
    Three(Mesh3),
}

impl AnyMesh {
    /// The node sets and element sets.
    #[allow(clippy::type_complexity)]
    fn sets_mut(
        &mut self,
    ) -> (
        &mut BTreeMap<String, Vec<usize>>,
        &mut BTreeMap<String, Vec<usize>>,
    ) {
        match self {
            AnyMesh::Two(m) => (&mut m.node_sets, &mut m.element_sets),
            AnyMesh::Three(m) => (&mut m.node_sets, &mut m.element_sets),
        }
    }
}

/// A resolved deck of either dimension.
struct Resolved {
    mesh: AnyMesh,
    materials: Vec<MaterialDef>,
    element_material: Vec<usize>,
    element_region: Vec<usize>,
    region_names: Vec<String>,
    step: StepDef,
    boundaries: Vec<BoundaryCondition>,
    pressures: Vec<FacePressure>,
    point_loads: Vec<PointLoad>,
}

/// `P3` → face 2 (0-based), for prefix `P` or `S`.
/// The dofs of a `*BOUNDARY` line in plane strain: 1 (x) and 2 (y) exist; a range starting
/// at 1 or 2 may run up to 6 (e.g. `1, 6`, Abaqus's "all displacements and rotations"), its
/// out-of-plane dofs 3–6 being absent from the plane-strain nodes; a line that constrains
/// neither in-plane dof, or names a dof above 6 (7 warping, 8 pore pressure, 11 temperature),
/// would leave the node free without a word and is refused.
fn check_plane_strain_dofs(first: usize, last: usize) -> std::result::Result<(), String> {
    let range = if first == last {
        format!("dof {first}")
    } else {
        format!("dofs {first} to {last}")
    };
    if first > 2 {
        return Err(format!(
            "*BOUNDARY: {range}: not a dof of plane strain (only 1 = x and 2 = y): the node would stay free"
        ));
    }
    if last > 6 {
        return Err(format!(
            "*BOUNDARY: dof {last} is not a displacement dof (plane strain has dofs 1 = x and 2 = y; ranges up to 6 are accepted)"
        ));
    }
    Ok(())
}

/// The most members a `GENERATE` line may make (16 bytes each): ten million, far above any
/// deck femu can solve (500 000 quads), so that `1, 1000000000` is refused before it is
/// allocated (issue 28.4).
const MAX_GENERATED: usize = 10_000_000;

fn face_number(text: &str, prefix: char, max: usize) -> Option<usize> {
    let rest = text
        .strip_prefix(prefix)
        .or_else(|| text.strip_prefix(prefix.to_ascii_lowercase()))?;
    match rest.parse::<usize>() {
        Ok(n) if (1..=max).contains(&n) => Some(n - 1),
        _ => None,
    }
}

/// The dofs of a `*BOUNDARY` line of a 3D deck: 1–3 (x, y, z) exist; a range from 1–3 may run
/// up to 6 (the rotations 4–6 being absent from solid nodes); a line constraining none of
/// 1–3, or naming a dof above 6, is refused (the node would stay free).
fn check_solid_dofs(first: usize, last: usize) -> std::result::Result<(), String> {
    if first > 3 {
        return Err(format!(
            "*BOUNDARY: dof {first}: not a displacement dof (1 = x, 2 = y, 3 = z): the node would stay free"
        ));
    }
    if last > 6 {
        return Err(format!(
            "*BOUNDARY: dof {last} is not a displacement dof (solids have dofs 1, 2, 3; ranges up to 6 are accepted)"
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Writer.

/// Full-precision, shortest round-trip text of a float (`0.1`, `1e-5`).
/// A number in at most 20 characters: CalculiX 2.20 reads only the first 20 characters of a
/// data field (a longer `1.000000000000000e-15` is silently read as 0.1). Shortest round-trip
/// form when it fits, otherwise the most significant digits that fit (at least 13 significant digits).
fn fmt_f64(v: f64) -> String {
    let s = format!("{v:?}");
    if s.len() <= 20 {
        return s;
    }
    (0..=15)
        .rev()
        .map(|digits| format!("{v:.digits$e}"))
        .find(|s| s.len() <= 20)
        .unwrap_or_else(|| format!("{v:.6e}"))
}

#[cfg(test)]
mod number_format_tests {
    use super::fmt_f64;

    #[test]
    fn numbers_fit_in_twenty_characters_and_round_trip() {
        for v in [
            1.0e-15,
            1.1225928992184071e-15,
            -1.1225928992184071e-15,
            -1.2345678901234567e-100,
            123456.78901234567,
            0.1 + 0.2,
            -0.0,
            2.666e-3,
            1.0e300,
        ] {
            let s = fmt_f64(v);
            assert!(s.len() <= 20, "{s}");
            let back: f64 = s.parse().unwrap();
            // At least 13 significant digits survive: relative error below 5e-13.
            assert!((back - v).abs() <= 5e-13 * v.abs(), "{v} -> {s}");
        }
    }
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// A name that both our reader and ccx read back unchanged: starts with a letter, then
/// letters, digits, `_`, `-`, `.`; at most 80 characters.
fn check_name(kind: &str, name: &str) -> io::Result<()> {
    let ok = name.len() <= 80
        && name.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
    if ok {
        Ok(())
    } else {
        Err(invalid(format!(
            "cannot write {kind} name '{name}' to a deck: use a letter, then letters, digits, _ - . (at most 80 characters)"
        )))
    }
}

fn write_labels(w: &mut impl Write, labels: impl Iterator<Item = i64>) -> io::Result<()> {
    let labels: Vec<i64> = labels.collect();
    for chunk in labels.chunks(8) {
        let line: Vec<String> = chunk.iter().map(|l| l.to_string()).collect();
        writeln!(w, "{}", line.join(", "))?;
    }
    Ok(())
}

/// Name of the node set of all nodes that [`write_inp`] defines and prints.
pub const ALL_NODES_SET: &str = "NALL";

/// Writes `deck` as an input deck that [`read_inp`] and CalculiX 2.20 both accept.
///
/// Layout: `*NODE, NSET=NALL` (all nodes, full precision), one `*ELEMENT` block per (element
/// type, region) with `ELSET=` the region, `*NSET` / `*ELSET` for the other sets of the mesh
/// (a mesh node set named `NALL` is replaced by all nodes), `*MATERIAL` +
/// `*HYPERELASTIC, <law>` with the law's constants, one `*SOLID SECTION` per region, zero `*BOUNDARY` conditions as
/// model data, then `*STEP, NLGEOM[=NO], INC=`, `*STATIC`, the nonzero `*BOUNDARY` values,
/// `*DLOAD` (`label, Pn, value`), `*CLOAD`, `*NODE PRINT, NSET=NALL` / `U`,
/// `*NODE FILE` / `U` and `*END STEP`.
///
/// Errors (`InvalidInput`) if the deck is inconsistent (lengths, indices, a region with two
/// materials), holds a non-finite number, or a name cannot be written.
pub fn write_inp(deck: &Deck, w: &mut impl Write) -> io::Result<()> {
    let mesh = &deck.mesh;
    let elements: Vec<WriteElement> = mesh
        .elements
        .iter()
        .map(|el| WriteElement {
            order: el.kind as usize,
            name: el.kind.deck_name(),
            nodes: el.nodes(),
            faces: el.face_count(),
        })
        .collect();
    write_deck(
        &DeckParts {
            dim: 2,
            coordinates: mesh.nodes.as_flattened(),
            node_labels: &mesh.node_labels,
            elements: &elements,
            element_labels: &mesh.element_labels,
            element_sets: &mesh.element_sets,
            node_sets: &mesh.node_sets,
            surfaces: None,
            materials: &deck.materials,
            element_material: &deck.element_material,
            element_region: &deck.element_region,
            region_names: &deck.region_names,
            step: &deck.step,
            boundaries: &deck.boundaries,
            pressures: &deck.pressures,
            point_loads: &deck.point_loads,
        },
        w,
    )
}

/// One element as the writer sees it: the order of its type (the `*ELEMENT` blocks are sorted
/// by region, then by it), its deck type name, its nodes and its number of faces.
pub(crate) struct WriteElement<'a> {
    pub(crate) order: usize,
    pub(crate) name: &'static str,
    pub(crate) nodes: &'a [usize],
    pub(crate) faces: usize,
}

/// The parts of a 2D or 3D deck that [`write_deck`] writes.
pub(crate) struct DeckParts<'a> {
    /// 2 (plane strain: coordinates x, y; dofs 1, 2; a thickness line of 1) or 3.
    pub(crate) dim: usize,
    /// `dim` coordinates per node.
    pub(crate) coordinates: &'a [f64],
    pub(crate) node_labels: &'a [i64],
    pub(crate) elements: &'a [WriteElement<'a>],
    pub(crate) element_labels: &'a [i64],
    pub(crate) element_sets: &'a BTreeMap<String, Vec<usize>>,
    pub(crate) node_sets: &'a BTreeMap<String, Vec<usize>>,
    /// Element-face surfaces written as `*SURFACE, NAME=, TYPE=ELEMENT` (`label, Sn`).
    pub(crate) surfaces: Option<&'a BTreeMap<String, Vec<(usize, usize)>>>,
    pub(crate) materials: &'a [MaterialDef],
    pub(crate) element_material: &'a [usize],
    pub(crate) element_region: &'a [usize],
    pub(crate) region_names: &'a [String],
    pub(crate) step: &'a StepDef,
    pub(crate) boundaries: &'a [BoundaryCondition],
    pub(crate) pressures: &'a [FacePressure],
    pub(crate) point_loads: &'a [PointLoad],
}

/// The writer of [`write_inp`] and of the 3D decks (`write_inp3`).
pub(crate) fn write_deck(deck: &DeckParts, w: &mut impl Write) -> io::Result<()> {
    let dim = deck.dim;
    let n_el = deck.elements.len();
    let n_nodes = deck.node_labels.len();
    if deck.coordinates.len() != dim * n_nodes
        || deck.element_labels.len() != n_el
        || deck.element_region.len() != n_el
        || deck.element_material.len() != n_el
    {
        return Err(invalid(
            "deck is inconsistent: node_labels, element_labels, element_region and element_material must match the mesh".to_string(),
        ));
    }
    for (e, el) in deck.elements.iter().enumerate() {
        if el.nodes.iter().any(|&n| n >= n_nodes) {
            return Err(invalid(format!(
                "element {} refers to a node index that does not exist",
                deck.element_labels[e]
            )));
        }
    }
    // Region → material, checking that every region has one material.
    let mut region_material: Vec<Option<usize>> = vec![None; deck.region_names.len()];
    for e in 0..n_el {
        let (r, m) = (deck.element_region[e], deck.element_material[e]);
        if r >= deck.region_names.len() || m >= deck.materials.len() {
            return Err(invalid(format!(
                "element {}: region or material index out of range",
                deck.element_labels[e]
            )));
        }
        match region_material[r] {
            None => region_material[r] = Some(m),
            Some(m0) if m0 != m => {
                return Err(invalid(format!(
                    "region '{}' has elements of two materials ('{}' and '{}'): a deck needs one material per *SOLID SECTION",
                    deck.region_names[r], deck.materials[m0].name, deck.materials[m].name
                )))
            }
            Some(_) => {}
        }
    }
    // Names: valid and unique (case-insensitively) per namespace.
    let unique = |kind: &str, names: &mut dyn Iterator<Item = &String>| -> io::Result<()> {
        let mut seen = HashSet::new();
        for n in names {
            check_name(kind, n)?;
            if !seen.insert(n.to_ascii_uppercase()) {
                return Err(invalid(format!(
                    "two {kind}s named '{n}' (names are case-insensitive in a deck)"
                )));
            }
        }
        Ok(())
    };
    unique("region", &mut deck.region_names.iter())?;
    unique("material", &mut deck.materials.iter().map(|m| &m.name))?;
    let is_region = |name: &str| {
        deck.region_names
            .iter()
            .any(|r| r.eq_ignore_ascii_case(name))
    };
    let extra_elsets: Vec<(&String, &Vec<usize>)> = deck
        .element_sets
        .iter()
        .filter(|(n, _)| !is_region(n))
        .collect();
    let nsets: Vec<(&String, &Vec<usize>)> = deck
        .node_sets
        .iter()
        .filter(|(n, _)| !n.eq_ignore_ascii_case(ALL_NODES_SET))
        .collect();
    unique(
        "element set",
        &mut deck
            .region_names
            .iter()
            .chain(extra_elsets.iter().map(|(n, _)| *n)),
    )?;
    unique("node set", &mut nsets.iter().map(|(n, _)| *n))?;
    for (n, s) in &extra_elsets {
        if s.iter().any(|&e| e >= n_el) {
            return Err(invalid(format!(
                "element set '{n}' has an index out of range"
            )));
        }
    }
    for (n, s) in &nsets {
        if s.iter().any(|&i| i >= n_nodes) {
            return Err(invalid(format!("node set '{n}' has an index out of range")));
        }
    }
    let finite = |what: &str, v: f64| -> io::Result<()> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(invalid(format!("{what} is not finite ({v})")))
        }
    };

    writeln!(w, "*HEADING")?;
    if dim == 2 {
        writeln!(w, "femu deck (plane strain, mm, N, MPa)")?;
    } else {
        writeln!(w, "femu deck (3D, mm, N, MPa)")?;
    }
    writeln!(w, "*NODE, NSET={ALL_NODES_SET}")?;
    for (i, p) in deck.coordinates.chunks_exact(dim).enumerate() {
        let mut line = deck.node_labels[i].to_string();
        for &v in p {
            finite("node coordinate", v)?;
            line.push_str(", ");
            line.push_str(&fmt_f64(v));
        }
        writeln!(w, "{line}")?;
    }
    // One *ELEMENT block per (region, type).
    let mut groups: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
    for (e, el) in deck.elements.iter().enumerate() {
        groups
            .entry((deck.element_region[e], el.order))
            .or_default()
            .push(e);
    }
    for ((r, _), elems) in &groups {
        writeln!(
            w,
            "*ELEMENT, TYPE={}, ELSET={}",
            deck.elements[elems[0]].name, deck.region_names[*r]
        )?;
        for &e in elems {
            let nodes: Vec<String> = deck.elements[e]
                .nodes
                .iter()
                .map(|&n| deck.node_labels[n].to_string())
                .collect();
            writeln!(w, "{}, {}", deck.element_labels[e], nodes.join(", "))?;
        }
    }
    for (name, set) in &extra_elsets {
        writeln!(w, "*ELSET, ELSET={name}")?;
        write_labels(w, set.iter().map(|&e| deck.element_labels[e]))?;
    }
    for (name, set) in &nsets {
        writeln!(w, "*NSET, NSET={name}")?;
        write_labels(w, set.iter().map(|&n| deck.node_labels[n]))?;
    }
    for m in deck.materials {
        let keyword_ok = !m.keyword.is_empty()
            && m.keyword
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == ' ' || c == '-' || c == '_');
        if !keyword_ok || m.constants.is_empty() {
            return Err(invalid(format!(
                "material '{}': the *HYPERELASTIC law '{}' with {} constants cannot be written",
                m.name,
                m.keyword,
                m.constants.len()
            )));
        }
        let mut data = Vec::with_capacity(m.constants.len());
        for &c in &m.constants {
            finite(&format!("a constant of material '{}'", m.name), c)?;
            data.push(fmt_f64(c));
        }
        writeln!(w, "*MATERIAL, NAME={}", m.name)?;
        writeln!(w, "*HYPERELASTIC, {}", m.keyword)?;
        writeln!(w, "{}", data.join(", "))?;
    }
    for (r, name) in deck.region_names.iter().enumerate() {
        if let Some(m) = region_material[r] {
            writeln!(
                w,
                "*SOLID SECTION, ELSET={name}, MATERIAL={}",
                deck.materials[m].name
            )?;
            if dim == 2 {
                writeln!(w, "1.0")?;
            }
        }
    }
    for bc in deck.boundaries {
        if bc.node >= n_nodes || bc.dof >= dim {
            return Err(invalid(format!(
                "boundary condition on node index {} dof {} does not exist",
                bc.node, bc.dof
            )));
        }
        finite("boundary value", bc.value)?;
    }
    if let Some(surfaces) = deck.surfaces {
        for (name, faces) in surfaces {
            check_name("surface", name)?;
            writeln!(w, "*SURFACE, NAME={name}, TYPE=ELEMENT")?;
            for &(e, f) in faces {
                if e >= n_el || f >= deck.elements[e].faces {
                    return Err(invalid(format!(
                        "surface '{name}': element index {e} face {f} does not exist"
                    )));
                }
                writeln!(w, "{}, S{}", deck.element_labels[e], f + 1)?;
            }
        }
    }
    let zero_bcs: Vec<&BoundaryCondition> =
        deck.boundaries.iter().filter(|b| b.value == 0.0).collect();
    if !zero_bcs.is_empty() {
        writeln!(w, "*BOUNDARY")?;
        for b in zero_bcs {
            writeln!(
                w,
                "{}, {}, {}",
                deck.node_labels[b.node],
                b.dof + 1,
                b.dof + 1
            )?;
        }
    }
    let s = &deck.step;
    for (what, v) in [
        ("initial increment", s.initial_increment),
        ("period", s.period),
        ("minimum increment", s.min_increment),
        ("maximum increment", s.max_increment),
    ] {
        finite(what, v)?;
    }
    writeln!(
        w,
        "*STEP, NLGEOM{}, INC={}",
        if s.nlgeom { "" } else { "=NO" },
        s.max_increments.max(1)
    )?;
    writeln!(w, "*STATIC")?;
    writeln!(
        w,
        "{}, {}, {}, {}",
        fmt_f64(s.initial_increment),
        fmt_f64(s.period),
        fmt_f64(s.min_increment),
        fmt_f64(s.max_increment)
    )?;
    let moved: Vec<&BoundaryCondition> =
        deck.boundaries.iter().filter(|b| b.value != 0.0).collect();
    if !moved.is_empty() {
        writeln!(w, "*BOUNDARY")?;
        for b in moved {
            writeln!(
                w,
                "{}, {}, {}, {}",
                deck.node_labels[b.node],
                b.dof + 1,
                b.dof + 1,
                fmt_f64(b.value)
            )?;
        }
    }
    if !deck.pressures.is_empty() {
        writeln!(w, "*DLOAD")?;
        for p in deck.pressures {
            if p.element >= n_el || p.face >= deck.elements[p.element].faces {
                return Err(invalid(format!(
                    "pressure on element index {} face {} does not exist",
                    p.element, p.face
                )));
            }
            finite("pressure", p.magnitude)?;
            writeln!(
                w,
                "{}, P{}, {}",
                deck.element_labels[p.element],
                p.face + 1,
                fmt_f64(p.magnitude)
            )?;
        }
    }
    if !deck.point_loads.is_empty() {
        writeln!(w, "*CLOAD")?;
        for l in deck.point_loads {
            if l.node >= n_nodes || l.dof >= dim {
                return Err(invalid(format!(
                    "point load on node index {} dof {} does not exist",
                    l.node, l.dof
                )));
            }
            finite("point load", l.magnitude)?;
            writeln!(
                w,
                "{}, {}, {}",
                deck.node_labels[l.node],
                l.dof + 1,
                fmt_f64(l.magnitude)
            )?;
        }
    }
    writeln!(w, "*NODE PRINT, NSET={ALL_NODES_SET}")?;
    writeln!(w, "U")?;
    writeln!(w, "*NODE FILE")?;
    writeln!(w, "U")?;
    writeln!(w, "*END STEP")?;
    Ok(())
}

/// Writes `deck` to the file `path` with [`write_inp`].
pub fn write_inp_file(deck: &Deck, path: &Path) -> io::Result<()> {
    crate::atomic::write_with(path, |w| write_inp(deck, w))
}

// ---------------------------------------------------------------------------------------------
// CalculiX .dat output.

/// Reads the displacements of the last `displacements (vx,vy,vz) for set NALL and time ...`
/// block of a CalculiX `.dat` file (written by `*NODE PRINT, NSET=NALL` / `U`): `(node label,
/// [ux, uy])` in file order. ccx prints 7 significant digits.
pub fn read_ccx_dat_displacements(path: &Path) -> Result<Vec<(i64, [f64; 2])>> {
    let file = path.display().to_string();
    let text = fs::read_to_string(path).map_err(|source| InpError::Io {
        file: file.clone(),
        source,
    })?;
    parse_ccx_dat_displacements(&text, &file)
}

/// The text version of [`read_ccx_dat_displacements`]; `file_name` is used in messages.
pub fn parse_ccx_dat_displacements(text: &str, file_name: &str) -> Result<Vec<(i64, [f64; 2])>> {
    let header = format!("displacements (vx,vy,vz) for set {ALL_NODES_SET} and time");
    let lines: Vec<&str> = text.lines().collect();
    let Some(start) = lines
        .iter()
        .rposition(|l| l.trim_start().starts_with(&header))
    else {
        return Err(InpError::Deck {
            file: file_name.to_string(),
            message: format!(
                "no '{header} ...' block (did the deck have *NODE PRINT, NSET={ALL_NODES_SET} / U, and did ccx finish an increment?)"
            ),
        });
    };
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate().skip(start + 1) {
        let t = l.trim();
        if t.is_empty() {
            if out.is_empty() {
                continue;
            }
            break;
        }
        let cols: Vec<&str> = t.split_whitespace().collect();
        let parsed = (|| {
            let label = cols.first()?.parse::<i64>().ok()?;
            let ux = fortran_float(cols.get(1)?)?;
            let uy = fortran_float(cols.get(2)?)?;
            Some((label, [ux, uy]))
        })();
        match parsed {
            Some(row) => out.push(row),
            None if out.is_empty() => {
                return Err(InpError::Line {
                    file: file_name.to_string(),
                    line: i + 1,
                    message: format!("cannot read '{t}' as 'node ux uy uz'"),
                })
            }
            // The next block (e.g. stresses) starts without a blank line.
            None => break,
        }
    }
    Ok(out)
}

/// Parses a Fortran `E` float, including the `1.234567-100` form (three-digit exponent without
/// `E`). Non-finite values (`NaN`) are returned as such.
fn fortran_float(s: &str) -> Option<f64> {
    if let Ok(v) = s.parse::<f64>() {
        return Some(v);
    }
    let pos = s.rfind(['+', '-']).filter(|&p| p > 0)?;
    format!("{}E{}", &s[..pos], &s[pos..]).parse().ok()
}

mod labels;
use labels::LabelMap;
mod solid;
pub use solid::{parse_ccx_dat_displacements3, write_inp3, write_inp3_file, Deck3};

#[cfg(test)]
mod tests;
