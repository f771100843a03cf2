//! The bad-input catalogue (issue 28, item 1): every input kind a user gives femu — decks, Gmsh
//! meshes, study files, measured-field CSVs, images, DICOM files, label images, ultrasound
//! manifests, command-line values and output folders — broken in the ways users break them, each
//! run through the `femu` binary as a user would. Every case asserts:
//!
//! - a non-zero exit that is not a panic's (101), and no "panicked" on stderr;
//! - a message holding the case's fragments: the file, line, key or value at fault, and what
//!   would be valid;
//! - nothing created, changed or removed outside `--out` (the case's folder, where its inputs
//!   are and where the command runs, is compared before and after).
//!
//! The cases are a table; their inputs are generated here, in a folder per case, and they run
//! in parallel. Issue 32's defects and issue 28's bounded resources are catalogued by their own
//! tests where they were fixed, not repeated here: a node no element uses, an output folder
//! holding an input (`--out .` beside the images), `*BOUNDARY` dof 7, duplicated or all-zero
//! measured fields, a thigh below 622 elements, `--roi` as four plain numbers (ambiguous),
//! unbounded meshing, grids and image headers, silently accepted study names.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

mod common;
use common::scratch;

/// One bad input: its files (name, bytes) in the case's folder, the command line (run in that
/// folder), the fragments its message must hold.
struct Case {
    name: &'static str,
    files: Vec<(&'static str, Vec<u8>)>,
    args: Vec<String>,
    expect: Vec<&'static str>,
}

fn case(
    name: &'static str,
    files: Vec<(&'static str, Vec<u8>)>,
    args: &[&str],
    expect: &[&'static str],
) -> Case {
    Case {
        name,
        files,
        args: args.iter().map(|s| s.to_string()).collect(),
        expect: expect.to_vec(),
    }
}

fn text(name: &'static str, body: &str) -> (&'static str, Vec<u8>) {
    (name, body.as_bytes().to_vec())
}

// ---------------------------------------------------------------------------------------------
// Inputs.

/// Two CPE4H quads, the left edge fixed, a pressure on the right face: solves.
const DECK: &str = "*HEADING
two quads
*NODE, NSET=ALL
1, 0.0, 0.0
2, 1.0, 0.0
3, 2.0, 0.0
4, 0.0, 1.0
5, 1.0, 1.0
6, 2.0, 1.0
*ELEMENT, TYPE=CPE4H, ELSET=FAT
1, 1, 2, 5, 4
2, 2, 3, 6, 5
*MATERIAL, NAME=FATMAT
*HYPERELASTIC, NEO HOOKE
0.0008, 30.8
*SOLID SECTION, ELSET=FAT, MATERIAL=FATMAT
*NSET, NSET=LEFT
1, 4
*BOUNDARY
LEFT, 1, 2
*STEP, NLGEOM
*STATIC
0.1, 1.0
*DLOAD
2, P2, 0.0005
*END STEP
";

/// `DECK` with `from` replaced by `to` (which must occur).
fn deck_with(from: &str, to: &str) -> String {
    assert!(DECK.contains(from), "{from}");
    DECK.replacen(from, to, 1)
}

fn solve_deck(name: &'static str, deck: &str, expect: &[&'static str]) -> Case {
    case(
        name,
        vec![text("deck.inp", deck)],
        &["solve", "deck.inp", "--out", "out", "-q"],
        expect,
    )
}

/// A Gmsh 4.1 mesh from Gmsh 4.8: quads and triangles, surfaces "Fat" and tag 7, curve "Bottom".
fn msh() -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../femu-mesh/tests/data/gmsh_two_surfaces.msh"),
    )
    .unwrap()
}

const MSH_STUDY: &str = "element = \"CPE4H\"
[materials.Fat]
c10_kpa = 0.8
d_per_mpa = 30.8
[materials.surface_7]
c10_kpa = 1.75
d_per_mpa = 18.0
[[fixed]]
curve = \"Bottom\"
[[pressure]]
curve = \"Bottom\"
mmhg = 20
";

fn solve_msh(name: &'static str, mesh: &str, study: &str, expect: &[&'static str]) -> Case {
    case(
        name,
        vec![text("mesh.msh", mesh), text("study.toml", study)],
        &[
            "solve",
            "mesh.msh",
            "--study",
            "study.toml",
            "--out",
            "out",
            "-q",
        ],
        expect,
    )
}

/// A study of a small model (checked in full before anything runs).
const STUDY: &str = "[model]
elements = 700
element = \"cpe4h\"
[materials.FAT]
c10_kpa = 0.8
d_per_mpa = 30.8
[[test]]
kind = \"contention\"
pressure_mmhg = 20.0
[[test]]
kind = \"compression\"
side = \"anterior\"
force_n_per_mm = 0.1
[grid]
counts = [16, 16]
[noise]
sigma_mm = 0.0176
[measurement]
source = \"virtual\"
[identification]
test = \"compression\"
grouped = true
bounds_factor = 4.0
starts = 1
";

fn study_with(from: &str, to: &str) -> String {
    assert!(STUDY.contains(from), "{from}");
    STUDY.replacen(from, to, 1)
}

fn run_study(name: &'static str, study: &str, expect: &[&'static str]) -> Case {
    case(
        name,
        vec![text("study.toml", study)],
        &["run", "study.toml", "--out", "out", "-q"],
        expect,
    )
}

/// A measured field: the header and `rows` (x, y, ux, uy in mm).
fn csv(rows: &[&str]) -> String {
    let mut s = String::from("# a measured field\nx,y,ux,uy\n");
    for r in rows {
        s.push_str(r);
        s.push('\n');
    }
    s
}

/// Rows of points in the tissue of the built-in thigh (fat and muscles around the femur).
fn tissue_rows() -> Vec<String> {
    let mut v = Vec::new();
    for i in 0..12 {
        for j in 0..12 {
            let (x, y) = (-45.0 + 4.0 * i as f64, -40.0 + 3.0 * j as f64);
            v.push(format!("{x},{y},0.01,-0.02"));
        }
    }
    v
}

fn identify_csv(name: &'static str, field: &str, expect: &[&'static str]) -> Case {
    case(
        name,
        vec![text("field.csv", field)],
        &[
            "identify",
            "--measured",
            "field.csv",
            "--elements",
            "700",
            "--starts",
            "1",
            "--out",
            "out",
            "-q",
        ],
        expect,
    )
}

/// A PNG of `img` (8-bit grey).
fn png(img: &femu_dic::GreyImage) -> Vec<u8> {
    let p = std::env::temp_dir().join(format!(
        "femu-bad-inputs-{}-{}.png",
        std::process::id(),
        PNGS.fetch_add(1, Ordering::Relaxed)
    ));
    img.save_png(&p).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    std::fs::remove_file(&p).ok();
    bytes
}

static PNGS: AtomicUsize = AtomicUsize::new(0);

/// A reference speckle image and the same speckle shifted by (0.4, -0.25) px (192 x 160 px).
fn speckle_pair() -> (Vec<u8>, Vec<u8>) {
    use femu_dic::lab::{self, Speckle};
    let s = Speckle::new(192, 160, 1.5, 3);
    let f = lab::quantize_8bit(&s.reference());
    let g = lab::quantize_8bit(&s.deformed(&lab::translation(0.4, -0.25)));
    (png(&f), png(&g))
}

fn dic(
    name: &'static str,
    files: Vec<(&'static str, Vec<u8>)>,
    args: &[&str],
    expect: &[&'static str],
) -> Case {
    let mut a = vec!["dic"];
    a.extend_from_slice(args);
    a.extend_from_slice(&["--out", "out", "-q"]);
    case(name, files, &a, expect)
}

/// A DICOM file (explicit VR little endian) holding `frames` frames of 64 x 48 8-bit grey
/// pixels.
fn dicom(frames: usize) -> Vec<u8> {
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_dictionary_std::tags;
    use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
    let (w, h) = (64u16, 48u16);
    let mut obj = InMemDicomObject::new_empty();
    let mut put = |tag, vr, v: PrimitiveValue| obj.put(DataElement::new(tag, vr, v));
    put(tags::SOP_CLASS_UID, VR::UI, US_IMAGE.into());
    put(tags::SOP_INSTANCE_UID, VR::UI, "1.2.3.4.5.6".into());
    put(tags::SAMPLES_PER_PIXEL, VR::US, PrimitiveValue::from(1u16));
    put(
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        "MONOCHROME2".into(),
    );
    put(tags::NUMBER_OF_FRAMES, VR::IS, frames.to_string().into());
    put(tags::ROWS, VR::US, PrimitiveValue::from(h));
    put(tags::COLUMNS, VR::US, PrimitiveValue::from(w));
    put(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(8u16));
    put(tags::BITS_STORED, VR::US, PrimitiveValue::from(8u16));
    put(tags::HIGH_BIT, VR::US, PrimitiveValue::from(7u16));
    put(
        tags::PIXEL_REPRESENTATION,
        VR::US,
        PrimitiveValue::from(0u16),
    );
    let pixels: Vec<u8> = (0..frames * w as usize * h as usize)
        .map(|k| ((k * 37) % 251) as u8)
        .collect();
    put(tags::PIXEL_DATA, VR::OB, PrimitiveValue::from(pixels));
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax("1.2.840.10008.1.2.1")
                .media_storage_sop_class_uid(US_IMAGE),
        )
        .unwrap();
    let mut bytes = Vec::new();
    file.write_all(&mut bytes).unwrap();
    bytes
}

/// A DICOM file whose meta group declares `transfer_syntax` (and holds no data set).
fn dicom_meta_only(transfer_syntax: &str) -> Vec<u8> {
    let meta = dicom_object::FileMetaTableBuilder::new()
        .transfer_syntax(transfer_syntax)
        .media_storage_sop_class_uid(US_IMAGE)
        .media_storage_sop_instance_uid("1.2.3.4.5")
        .build()
        .unwrap();
    let mut bytes = vec![0u8; 128];
    bytes.extend_from_slice(b"DICM");
    meta.write(&mut bytes).unwrap();
    bytes
}

/// Ultrasound Multi-frame Image Storage.
const US_IMAGE: &str = "1.2.840.10008.5.1.4.1.1.6.1";

/// A label image of 120 x 100 px: background 0, fat 1 (a disk), muscle 2 inside, bone 7 at the
/// centre; `relabel` maps labels before writing.
fn labels(relabel: impl Fn(u32) -> u32) -> Vec<u8> {
    let (w, h) = (120usize, 100usize);
    let mut data = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            let r = ((i as f64 - 60.0).powi(2) + (j as f64 - 50.0).powi(2)).sqrt();
            let l = if r < 8.0 {
                7
            } else if r < 30.0 {
                2
            } else if r < 40.0 {
                1
            } else {
                0
            };
            data[j * w + i] = relabel(l) as f64;
        }
    }
    png(&femu_dic::GreyImage::new(w, h, data).unwrap())
}

/// Two label images of `labels` side by side (two thighs in one slice): 240 x 100 px.
fn two_bodies() -> Vec<u8> {
    let (w, h) = (240usize, 100usize);
    let mut data = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            let r = ((i as f64 % 120.0 - 60.0).powi(2) + (j as f64 - 50.0).powi(2)).sqrt();
            data[j * w + i] = if r < 8.0 {
                7.0
            } else if r < 30.0 {
                2.0
            } else if r < 40.0 {
                1.0
            } else {
                0.0
            };
        }
    }
    png(&femu_dic::GreyImage::new(w, h, data).unwrap())
}

fn mesh_labels(name: &'static str, image: Vec<u8>, args: &[&str], expect: &[&'static str]) -> Case {
    let mut a = vec!["mesh", "labels", "labels.png"];
    if !args.contains(&"--pixel-size") {
        a.extend_from_slice(&["--pixel-size", "0.5"]);
    }
    a.extend_from_slice(args);
    a.extend_from_slice(&["--out", "out", "-q"]);
    case(name, vec![("labels.png", image)], &a, expect)
}

// ---------------------------------------------------------------------------------------------
// The catalogue.

fn deck_cases() -> Vec<Case> {
    vec![
        solve_deck("deck: empty", "", &["deck.inp", "no *STEP"]),
        solve_deck(
            "deck: truncated in *ELEMENT",
            &DECK[..DECK.find("2, 2, 3, 6").unwrap() + 6],
            &["deck.inp:12", "element 2 needs 4 node labels, got 1"],
        ),
        solve_deck(
            "deck: not text",
            "\u{0}\u{1}garbage\n",
            &["deck.inp:1", "data line before the first keyword"],
        ),
        solve_deck(
            "deck: unknown keyword",
            &deck_with("*STEP, NLGEOM", "*PLASTIC\n0.1, 0.0\n*STEP, NLGEOM"),
            &["deck.inp:21", "*PLASTIC is not supported"],
        ),
        solve_deck(
            "deck: element on a missing node",
            &deck_with("2, 2, 3, 6, 5", "2, 2, 3, 16, 5"),
            &["deck.inp:12", "node 16, which is not defined"],
        ),
        solve_deck(
            "deck: duplicate node label",
            &deck_with("6, 2.0, 1.0", "6, 2.0, 1.0\n5, 1.5, 1.0"),
            &["deck.inp:10", "node 5 is defined twice"],
        ),
        solve_deck(
            "deck: duplicate element label",
            &deck_with("2, 2, 3, 6, 5", "1, 2, 3, 6, 5"),
            &["deck.inp:12", "element 1 is defined twice"],
        ),
        solve_deck(
            "deck: inverted element",
            &deck_with("2, 2, 3, 6, 5", "2, 2, 5, 6, 3"),
            &["deck.inp:12", "element 2 is inverted or degenerate"],
        ),
        solve_deck(
            "deck: zero-area element",
            &deck_with("6, 2.0, 1.0", "6, 3.0, 0.0"),
            &[
                "deck.inp:12",
                "element 2 is inverted or degenerate",
                "signed area 0",
            ],
        ),
        solve_deck(
            "deck: NaN coordinate",
            &deck_with("6, 2.0, 1.0", "6, nan, 1.0"),
            &["deck.inp:9", "'nan'", "a finite decimal"],
        ),
        solve_deck(
            "deck: infinite coordinate",
            &deck_with("6, 2.0, 1.0", "6, inf, 1.0"),
            &["deck.inp:9", "'inf'", "a finite decimal"],
        ),
        solve_deck(
            "deck: coordinate 1e308",
            &deck_with("6, 2.0, 1.0", "6, 1e308, 1.0"),
            &["deck.inp:9", "node 6", "1e308", "beyond ±1e6 mm"],
        ),
        solve_deck(
            "deck: C10 = 0",
            &deck_with("0.0008, 30.8", "0.0, 30.8"),
            &["deck.inp", "line 15", "C10 = 0 MPa", "must be > 0"],
        ),
        solve_deck(
            "deck: C10 < 0",
            &deck_with("0.0008, 30.8", "-0.0008, 30.8"),
            &["line 15", "C10 = -0.0008 MPa", "must be > 0"],
        ),
        solve_deck(
            "deck: D = 0",
            &deck_with("0.0008, 30.8", "0.0008, 0"),
            &["line 15", "D1 = 0", "≥ 0.000001"],
        ),
        solve_deck(
            "deck: D < 0",
            &deck_with("0.0008, 30.8", "0.0008, -1"),
            &["line 15", "D1 = -1", "≥ 0.000001"],
        ),
        solve_deck(
            "deck: pressure on a missing element",
            &deck_with("2, P2, 0.0005", "7, P2, 0.0005"),
            &["deck.inp:25", "*DLOAD: element 7 is not defined"],
        ),
        solve_deck(
            "deck: pressure on a face that does not exist",
            &deck_with("2, P2, 0.0005", "2, P7, 0.0005"),
            &["deck.inp:25", "'P7'", "P1..P4"],
        ),
        solve_deck(
            "deck: floating body",
            &deck_with("*BOUNDARY\nLEFT, 1, 2\n", ""),
            &[
                "deck.inp",
                "no prescribed displacement",
                "rigid-body motion",
            ],
        ),
        solve_deck(
            "deck: label beyond 64 bits",
            &deck_with("6, 2.0, 1.0", "99999999999999999999999, 2.0, 1.0"),
            &["deck.inp:9", "'99999999999999999999999'", "an integer"],
        ),
        solve_deck(
            "deck: GENERATE over 4e12 labels",
            &deck_with(
                "*NSET, NSET=LEFT\n1, 4",
                "*NSET, NSET=LEFT, GENERATE\n1, 4000000000000, 1",
            ),
            &[
                "deck.inp:18",
                "GENERATE",
                "4000000000000 members",
                "above the limit",
            ],
        ),
        solve_deck(
            "deck: GENERATE step 0",
            &deck_with(
                "*NSET, NSET=LEFT\n1, 4",
                "*NSET, NSET=LEFT, GENERATE\n1, 4, 0",
            ),
            &["deck.inp:18", "step >= 1"],
        ),
        solve_deck(
            "deck: unsupported element type",
            &deck_with("TYPE=CPE4H", "TYPE=CPE8"),
            &["deck.inp:10", "'CPE8'", "supported: CPE4, CPE4H, CPE3"],
        ),
        solve_deck(
            "deck: point load on a missing node",
            &deck_with("*END STEP", "*CLOAD\n77, 2, 0.1\n*END STEP"),
            &["deck.inp:27", "node 77 is not defined"],
        ),
        solve_deck(
            "deck: text in a number field",
            &deck_with("0.1, 1.0", "zero, 1.0"),
            &["deck.inp:23", "'zero'", "a finite decimal"],
        ),
        solve_deck(
            "deck: section with an undefined material",
            &deck_with("MATERIAL=FATMAT", "MATERIAL=MUSCLE"),
            &["deck.inp:16", "material 'MUSCLE' is not defined"],
        ),
        solve_deck(
            "deck: element without a section",
            &deck_with("*SOLID SECTION, ELSET=FAT, MATERIAL=FATMAT\n", ""),
            &["deck.inp:11", "element 1 has no *SOLID SECTION"],
        ),
        solve_deck(
            "deck: boundary on an undefined set",
            &deck_with("LEFT, 1, 2", "RIGHT, 1, 2"),
            &["deck.inp:20", "node set 'RIGHT' is not defined"],
        ),
        solve_deck(
            "deck: negative initial increment",
            &deck_with("0.1, 1.0", "-0.1, 1.0"),
            &["deck.inp:23", "initial increment must be > 0"],
        ),
        case(
            "deck: missing file",
            vec![],
            &["solve", "nowhere.inp", "--out", "out", "-q"],
            &["nowhere.inp", "No such file"],
        ),
        case(
            "deck: unknown input type",
            vec![text("deck.txt", DECK)],
            &["solve", "deck.txt", "--out", "out", "-q"],
            &["deck.txt", "expected .inp or .msh"],
        ),
    ]
}

fn gmsh_cases() -> Vec<Case> {
    let m = msh();
    vec![
        solve_msh(
            "gmsh: empty",
            "",
            MSH_STUDY,
            &["mesh.msh", "no $MeshFormat"],
        ),
        solve_msh(
            "gmsh: MSH 2.2",
            &m.replacen("4.1 0 8", "2.2 0 8", 1),
            MSH_STUDY,
            &["mesh.msh:2", "MSH version 2.2", "MSH 4.1"],
        ),
        solve_msh(
            "gmsh: truncated",
            &m[..m.find("$Elements").unwrap() + 30],
            MSH_STUDY,
            &["mesh.msh", "$Elements has no $EndElements"],
        ),
        solve_msh(
            "gmsh: element on a missing node",
            &m.replacen("5 7 8 3 9 \n", "5 7 8 3 99 \n", 1),
            MSH_STUDY,
            &["mesh.msh:78", "node 99, which is not in $Nodes"],
        ),
        solve_msh(
            "gmsh: NaN coordinate",
            &m.replacen("2\n2 0 0\n", "2\nnan 0 0\n", 1),
            MSH_STUDY,
            &["mesh.msh:34", "'nan'", "a finite number"],
        ),
        solve_msh(
            "gmsh: coordinate 1e308",
            &m.replacen("2\n2 0 0\n", "2\n1e308 0 0\n", 1),
            MSH_STUDY,
            &["mesh.msh:34", "1e308", "beyond ±1e6 mm"],
        ),
        solve_msh(
            "gmsh: a region the mesh does not have",
            &m,
            &MSH_STUDY.replacen("[materials.Fat]", "[materials.Muscle]", 1),
            &[
                "mesh.msh",
                "study.toml",
                "'Muscle'",
                "available: Fat, surface_7",
            ],
        ),
        solve_msh(
            "gmsh: a curve the mesh does not have",
            &m,
            &MSH_STUDY.replacen("curve = \"Bottom\"", "curve = \"Top\"", 1),
            &["mesh.msh", "'Top'", "available: Bottom"],
        ),
        case(
            "gmsh: no study file",
            vec![text("mesh.msh", &m)],
            &["solve", "mesh.msh", "--out", "out", "-q"],
            &["mesh.msh", "needs --study"],
        ),
    ]
}

fn study_cases() -> Vec<Case> {
    vec![
        run_study(
            "study: unknown key",
            &study_with("[noise]\n", "[noise]\nsigma_px = 1.5\n"),
            &["study.toml", "line 17", "sigma_px", "expected `sigma_mm`"],
        ),
        run_study(
            "study: unknown table",
            &format!("{STUDY}[optimizer]\nname = \"lm\"\n"),
            &["study.toml", "optimizer", "expected one of"],
        ),
        run_study(
            "study: wrong type",
            &study_with("elements = 700", "elements = \"many\""),
            &["study.toml", "line 2", "expected usize"],
        ),
        run_study(
            "study: wrong unit",
            &study_with("c10_kpa = 0.8", "c10_psi = 0.8"),
            &[
                "study.toml",
                "c10_psi",
                "line 5",
                "valid keys: c10_kpa, c10_mpa",
            ],
        ),
        run_study(
            "study: negative force",
            &study_with("force_n_per_mm = 0.1", "force_n_per_mm = -0.1"),
            &[
                "study.toml",
                "force_n_per_mm",
                "line 13",
                "must be positive",
            ],
        ),
        run_study(
            "study: zero grid count",
            &study_with("counts = [16, 16]", "counts = [0, 16]"),
            &["study.toml", "[grid] counts", "at least 2 x 2"],
        ),
        run_study(
            "study: absurd grid count",
            &study_with("counts = [16, 16]", "counts = [100000, 100000]"),
            &[
                "study.toml",
                "[grid] counts",
                "line 15",
                "at most 4000000 points",
                "1.0e10",
            ],
        ),
        run_study(
            "study: bounds_factor = 1",
            &study_with("bounds_factor = 4.0", "bounds_factor = 1.0"),
            &["study.toml", "bounds_factor", "line 23", "must be above 1"],
        ),
        run_study(
            "study: image_normalization_px < 0",
            &study_with(
                "bounds_factor = 4.0",
                "bounds_factor = 4.0\nimage_normalization_px = -1.0",
            ),
            &[
                "study.toml",
                "image_normalization_px",
                "line 24",
                "[0.5, 32]",
            ],
        ),
        run_study(
            "study: image_normalization_px below a pixel",
            &study_with(
                "bounds_factor = 4.0",
                "bounds_factor = 4.0\nimage_normalization_px = 0.2",
            ),
            &[
                "study.toml",
                "image_normalization_px",
                "line 24",
                "must be 0 or",
            ],
        ),
        run_study(
            "study: image_pairing unknown",
            &study_with(
                "bounds_factor = 4.0",
                "bounds_factor = 4.0\nimage_pairing = \"neighbours\"",
            ),
            &[
                "study.toml",
                "image_pairing",
                "line 24",
                "both, consecutive, reference",
            ],
        ),
        run_study(
            "study: starts = 0",
            &study_with("starts = 1", "starts = 0"),
            &["study.toml", "starts", "line 24", "[1, 64]"],
        ),
        run_study(
            "study: contradictory keys",
            &study_with("elements = 700", "elements = 700\nsize_mm = 1.0"),
            &[
                "study.toml",
                "size_mm",
                "give elements or size_mm, not both",
            ],
        ),
        run_study(
            "study: TOML syntax",
            &study_with("[grid]", "[grid"),
            &["study.toml", "line 14", "invalid table header"],
        ),
        run_study(
            "study: not text",
            "\u{0}\u{1}\u{2}",
            &["study.toml", "line 1", "invalid key"],
        ),
        run_study(
            "study: unknown test kind",
            &study_with("kind = \"contention\"", "kind = \"tension\""),
            &[
                "study.toml",
                "kind",
                "'tension'",
                "contention, compression, indentation",
            ],
        ),
        run_study(
            "study: negative noise",
            &study_with("sigma_mm = 0.0176", "sigma_mm = -0.01"),
            &["study.toml", "sigma_mm", "must be positive"],
        ),
        run_study(
            "study: identification of a test not run",
            &study_with("test = \"compression\"", "test = \"shear\""),
            &[
                "study.toml",
                "no test 'shear'",
                "tests: contention, compression-anterior",
            ],
        ),
        run_study(
            "study: elements = 0",
            &study_with("elements = 700", "elements = 0"),
            &["study.toml", "elements", "[100, 500000]"],
        ),
        run_study(
            "study: NaN parameter",
            &study_with("c10_kpa = 0.8", "c10_kpa = nan"),
            &["study.toml", "c10_kpa", "out of range", "> 0"],
        ),
        run_study(
            "study: D < 0",
            &study_with("d_per_mpa = 30.8", "d_per_mpa = -30.8"),
            &["study.toml", "d_per_mpa = -30.8", "≥ 0.000001"],
        ),
        run_study(
            "study: unknown side",
            &study_with("side = \"anterior\"", "side = \"upward\""),
            &[
                "study.toml",
                "'upward'",
                "anterior, posterior, lateral, medial",
            ],
        ),
        run_study(
            "study: side 1e300 degrees",
            &study_with("side = \"anterior\"", "side = \"1e300\""),
            &["study.toml", "'1e300'", "within ±360"],
        ),
        run_study(
            "study: grouped = maybe",
            &study_with("grouped = true", "grouped = \"maybe\""),
            &[
                "study.toml",
                "grouped",
                "'maybe'",
                "true, false or \"both\"",
            ],
        ),
        run_study(
            "study: unknown optimizer",
            &study_with("starts = 1", "starts = 1\noptimizer = \"newton\""),
            &["study.toml", "'newton'", "lm, bfgs, bfgs-fd"],
        ),
        run_study(
            "study: negative pressure",
            &study_with("pressure_mmhg = 20.0", "pressure_mmhg = -20.0"),
            &["study.toml", "pressure_mmhg", "must be positive"],
        ),
        run_study(
            "study: two geometries",
            &study_with(
                "[materials.FAT]",
                "deck = \"model.inp\"\n[thigh]\nfat_thickness_mm = 8.0\n[materials.FAT]",
            ),
            &["study.toml", "give one geometry", "[thigh]", "[model] deck"],
        ),
        case(
            "study: missing study file",
            vec![],
            &["run", "nowhere.toml", "--out", "out", "-q"],
            &["nowhere.toml", "No such file"],
        ),
        case(
            "study: convergence with a bad mesh sequence",
            vec![text(
                "study.toml",
                "[convergence]\ntarget_elements = [3000, 1500]\n",
            )],
            &["convergence", "study.toml", "--out", "out", "-q"],
            &["study.toml", "target_elements"],
        ),
    ]
}

fn csv_cases() -> Vec<Case> {
    let rows = tissue_rows();
    let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
    let with = |k: usize, row: &str| {
        let mut r = rows.clone();
        r.insert(k, row);
        csv(&r)
    };
    vec![
        identify_csv(
            "csv: missing column",
            "x,y,ux\n1,2,3\n",
            &["field.csv:1", "x,y,ux,uy", "got 'x,y,ux'"],
        ),
        identify_csv(
            "csv: text in a number",
            &with(10, "1.0,abc,0.1,0.2"),
            &["field.csv:13", "column y", "'abc' is not a number"],
        ),
        identify_csv(
            "csv: NaN",
            &with(10, "1.0,2.0,nan,0.2"),
            &["field.csv:13", "column ux", "not finite"],
        ),
        identify_csv("csv: empty", "", &["field.csv", "no data row", "x,y,ux,uy"]),
        identify_csv(
            "csv: header only",
            "x,y,ux,uy\n",
            &["field.csv", "no data row", "x,y,ux,uy"],
        ),
        identify_csv(
            "csv: short row",
            &with(3, "1.0,2.0,0.1"),
            &["field.csv:6", "3 cells, the header has 4"],
        ),
        identify_csv(
            "csv: negative standard deviation",
            "x,y,ux,uy,sx,sy\n-40,0,0.1,0.1,-0.01,0.01\n",
            &["field.csv:2", "sx, sy must be positive"],
        ),
        identify_csv(
            "csv: one point",
            &csv(&["-40,0,0.01,0.02"]),
            &[
                "2 measured components for 8 free parameters",
                "not enough data",
            ],
        ),
        identify_csv(
            "csv: every point outside the tissue",
            &csv(&[
                "1000,1000,0.1,0.1",
                "1001,1000,0.1,0.1",
                "1002,1000,0.1,0.1",
            ]),
            &["no measured point lies in the tissue", "3 points masked"],
        ),
        identify_csv(
            "csv: not text",
            "\u{0}\u{ff}\u{fe} garbage\n",
            &["field.csv"],
        ),
        case(
            "csv: missing file",
            vec![],
            &[
                "identify",
                "--measured",
                "nowhere.csv",
                "--out",
                "out",
                "-q",
            ],
            &["nowhere.csv", "No such file"],
        ),
    ]
}

fn image_cases() -> Vec<Case> {
    let (f, g) = speckle_pair();
    let pair = || vec![("ref.png", f.clone()), ("def.png", g.clone())];
    let with = |name: &'static str, bytes: Vec<u8>| {
        let mut v = pair();
        v.push((name, bytes));
        v
    };
    let small = png(&femu_dic::GreyImage::new(64, 64, vec![10.0; 64 * 64]).unwrap());
    let one = png(&femu_dic::GreyImage::new(1, 1, vec![7.0]).unwrap());
    let flat = png(&femu_dic::GreyImage::new(192, 160, vec![90.0; 192 * 160]).unwrap());
    vec![
        dic(
            "image: 0 bytes",
            with("empty.png", Vec::new()),
            &["empty.png", "def.png"],
            &["empty.png", "cannot read the image"],
        ),
        dic(
            "image: truncated PNG",
            with("cut.png", f[..f.len() / 2].to_vec()),
            &["cut.png", "def.png"],
            &["cut.png", "cannot read the image"],
        ),
        dic(
            "image: 1 x 1 px",
            with("one.png", one.clone()),
            &["one.png", "one.png"],
            &["larger than the region of interest", "1 x 1 px"],
        ),
        dic(
            "image: not an image",
            with("text.png", b"this is not an image\n".to_vec()),
            &["text.png", "def.png"],
            &["text.png", "cannot read the image"],
        ),
        dic(
            "image: sizes differ",
            with("small.png", small),
            &["ref.png", "small.png"],
            &["differ in size", "(192, 160)", "(64, 64)"],
        ),
        dic(
            "image: ROI outside",
            pair(),
            &["ref.png", "def.png", "--roi", "300,10,50x50"],
            &[
                "region of interest",
                "300,10,50x50",
                "outside the 192 x 160 px image",
            ],
        ),
        dic(
            "image: element larger than the ROI",
            pair(),
            &[
                "ref.png",
                "def.png",
                "--roi",
                "0,0,40x40",
                "--element",
                "64",
            ],
            &["64 px is larger than the region of interest", "40 x 40 px"],
        ),
        dic(
            "image: element 0",
            pair(),
            &["ref.png", "def.png", "--element", "0"],
            &["element size", "0 px is below 4 px"],
        ),
        dic(
            "image: ROI not x,y,WxH",
            pair(),
            &["ref.png", "def.png", "--roi", "10,10,-5x20"],
            &["'10,10,-5x20'", "give x,y,WxH in pixels"],
        ),
        dic(
            "image: no texture",
            with("flat.png", flat),
            &["flat.png", "def.png"],
            &["no texture"],
        ),
        dic(
            "image: missing file",
            pair(),
            &["ref.png", "nowhere.png"],
            &["nowhere.png", "No such file"],
        ),
        dic(
            "image: frame of a PNG",
            pair(),
            &["ref.png", "def.png", "--frame-ref", "1"],
            &["ref.png", "frame 1", "single frame"],
        ),
        dic(
            "image: mask of another size",
            with("mask.png", one),
            &["ref.png", "def.png", "--mask", "mask.png"],
            &["mask.png", "1 x 1 px", "192 x 160 px"],
        ),
    ]
}

fn dicom_cases() -> Vec<Case> {
    let good = dicom(1);
    let half = good[..good.len() / 2].to_vec();
    vec![
        dic(
            "dicom: truncated",
            vec![("a.dcm", half.clone()), ("b.dcm", half)],
            &["a.dcm", "b.dcm"],
            &["a.dcm"],
        ),
        dic(
            "dicom: not DICOM",
            vec![
                ("a.dcm", b"not a DICOM file at all\n".to_vec()),
                ("b.dcm", good.clone()),
            ],
            &["a.dcm", "b.dcm"],
            &["a.dcm"],
        ),
        dic(
            "dicom: frame out of range",
            vec![("a.dcm", good.clone()), ("b.dcm", good.clone())],
            &["a.dcm", "b.dcm", "--frame-ref", "3"],
            &[
                "a.dcm",
                "frame 3 requested",
                "1 frame(s)",
                "numbered from 0",
            ],
        ),
        dic(
            "dicom: JPEG 2000",
            vec![
                ("a.dcm", dicom_meta_only("1.2.840.10008.1.2.4.91")),
                ("b.dcm", good),
            ],
            &["a.dcm", "b.dcm"],
            &["a.dcm", "JPEG 2000", "not supported"],
        ),
    ]
}

fn label_cases() -> Vec<Case> {
    let map = ["--map", "1=fat,2=quadriceps", "--bone", "7"];
    vec![
        mesh_labels(
            "labels: all background",
            labels(|_| 0),
            &map,
            &[
                "labels.png",
                "no pixel holds a tissue label",
                "labels present: 0",
            ],
        ),
        mesh_labels(
            "labels: no bone",
            labels(|l| if l == 7 { 2 } else { l }),
            &map,
            &[
                "labels.png",
                "bone label 7 does not occur",
                "labels present: 0, 1, 2",
            ],
        ),
        mesh_labels(
            "labels: a mapped label absent",
            labels(|l| if l == 2 { 1 } else { l }),
            &map,
            &[
                "labels.png",
                "label 2 (mapped to QUADRICEPS) does not occur",
                "labels present: 0, 1, 7",
            ],
        ),
        mesh_labels(
            "labels: an unmapped label",
            labels(|l| if l == 2 { 5 } else { l }),
            &map,
            &["labels.png", "label 5", "has no mapping", "--map 5=NAME"],
        ),
        mesh_labels(
            "labels: map syntax",
            labels(|l| l),
            &["--map", "1fat", "--bone", "7"],
            &["--map", "'1fat' is not LABEL=REGION"],
        ),
        mesh_labels(
            "labels: pixel size 0",
            labels(|l| l),
            &[
                "--map",
                "1=fat,2=quadriceps",
                "--bone",
                "7",
                "--pixel-size",
                "0",
            ],
            &["--pixel-size", "positive"],
        ),
        mesh_labels(
            "labels: a slice of a PNG",
            labels(|l| l),
            &["--map", "1=fat,2=quadriceps", "--bone", "7", "--slice", "2"],
            &[
                "labels.png",
                "slice index is only meaningful for a NIfTI volume",
            ],
        ),
        mesh_labels(
            "labels: bone and background the same label",
            labels(|l| l),
            &["--map", "1=fat,2=quadriceps", "--bone", "0"],
            &["label 0 is given twice (bone and background)"],
        ),
    ]
}

fn manifest_cases() -> Vec<Case> {
    let (f, _) = speckle_pair();
    let small = png(&femu_dic::GreyImage::new(64, 64, vec![10.0; 64 * 64]).unwrap());
    let us = |name: &'static str, files: Vec<(&'static str, Vec<u8>)>, expect| {
        case(
            name,
            files,
            &["us-settings", "manifest.csv", "--out", "out", "-q"],
            expect,
        )
    };
    vec![
        us(
            "manifest: missing column",
            vec![text(
                "manifest.csv",
                "file,frequency_mhz,gain_db\na.png,9,34\n",
            )],
            &["manifest.csv", "no 'dynamic_db' column"],
        ),
        us(
            "manifest: missing image",
            vec![text(
                "manifest.csv",
                "file,frequency_mhz,gain_db,dynamic_db\nnowhere.png,9,34,42\n",
            )],
            &["manifest.csv", "nowhere.png"],
        ),
        us(
            "manifest: images of different sizes",
            vec![
                text(
                    "manifest.csv",
                    "file,frequency_mhz,gain_db,dynamic_db\na.png,9,34,42\nb.png,9,38,42\n",
                ),
                ("a.png", f),
                ("b.png", small),
            ],
            &["b.png", "64 x 64"],
        ),
    ]
}

fn command_line_cases() -> Vec<Case> {
    vec![
        case(
            "command line: --starts 0",
            vec![],
            &["identify", "--starts", "0", "--out", "out", "-q"],
            &["--starts", "[1, 64]", "got 0"],
        ),
        case(
            "command line: --repeat 0",
            vec![],
            &["identify", "--repeat", "0", "--out", "out", "-q"],
            &["--repeat", "[1, 1000]", "got 0"],
        ),
        case(
            "command line: --elements 0",
            vec![],
            &["synth", "--elements", "0", "--out", "out", "-q"],
            &["elements", "[100, 500000]"],
        ),
        case(
            "command line: unknown test",
            vec![],
            &["forward", "--tests", "shear", "--out", "out", "-q"],
            &["'shear'", "contention, compression, indentation"],
        ),
        case(
            "command line: report of a folder that is not a run",
            vec![text("notes.txt", "mine")],
            &["report", "."],
            &["not the folder of a femu run", "no steps.json"],
        ),
        case(
            "command line: init over an existing file",
            vec![text("study.toml", "# mine\n")],
            &["init", "study.toml", "-q"],
            &["study.toml exists", "--force"],
        ),
    ]
}

fn output_folder_cases() -> Vec<Case> {
    vec![
        case(
            "output: --out an existing file (solve)",
            vec![text("deck.inp", DECK), text("taken", "a file")],
            &["solve", "deck.inp", "--out", "taken", "-q"],
            &["taken", "is a file, not a folder"],
        ),
        case(
            "output: --out an existing file (run)",
            vec![text("study.toml", STUDY), text("taken", "a file")],
            &["run", "study.toml", "--out", "taken", "-q"],
            &["taken", "a file of that name exists"],
        ),
        case(
            "output: --out an existing file (dic)",
            {
                let (f, g) = speckle_pair();
                vec![("ref.png", f), ("def.png", g), text("taken", "a file")]
            },
            &["dic", "ref.png", "def.png", "--out", "taken", "-q"],
            &["taken", "is a file, not a folder"],
        ),
        case(
            "output: --out under a file (unwritable)",
            vec![text("deck.inp", DECK), text("taken", "a file")],
            &["solve", "deck.inp", "--out", "taken/out", "-q"],
            &["taken/out", "a part of the path is a file"],
        ),
        case(
            "output: --out an input's folder that is not a run's",
            vec![text("study.toml", STUDY), text("model/keep.txt", "data")],
            &["run", "study.toml", "--out", ".", "-q"],
            &[
                "already holds model",
                "not the folder of an earlier femu run",
            ],
        ),
    ]
}

/// `femu design` on `study`.
fn design_study(name: &'static str, study: &str, expect: &[&'static str]) -> Case {
    case(
        name,
        vec![text("study.toml", study)],
        &["design", "study.toml", "--out", "out", "-q"],
        expect,
    )
}

/// `STUDY` with its `[measurement]` table replaced by `measurements`.
fn study_measuring(measurements: &str) -> String {
    study_with("[measurement]\nsource = \"virtual\"\n", measurements)
}

/// Keys checked with the whole study, before anything runs, whether or not a step uses them;
/// a measured field given twice; binary and badly labelled decks.
fn whole_study_cases() -> Vec<Case> {
    let field = csv(&tissue_rows().iter().map(String::as_str).collect::<Vec<_>>());
    vec![
        design_study(
            "study: design spacing far below a pixel",
            &format!("{STUDY}[design]\nspacing_mm = 1e-4\n"),
            &[
                "study.toml",
                "[design] spacing_mm (line 26)",
                "above the limit of 2000000",
            ],
        ),
        design_study(
            "study: design of too many window sizes",
            &format!(
                "{STUDY}[design]\nmax_measurements = 4\nwindows_mm = [{}]\n",
                (10..50)
                    .map(|k| format!("[{k}, 20]"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            &[
                "study.toml",
                "[design] max_measurements (line 26)",
                "above the limit of 200000",
            ],
        ),
        design_study(
            "study: design window larger than the thigh",
            &format!("{STUDY}[design]\nwindows_mm = [[200.0, 200.0]]\n"),
            &[
                "study.toml",
                "[design] windows_mm (line 26)",
                "200 x 200 mm window",
                "larger than the model seen from the anterior side: 140.0 mm across",
            ],
        ),
        case(
            "study: one measured file in two measurements",
            vec![
                text(
                    "study.toml",
                    &study_measuring(
                        "[[measurement]]\nfile = \"field.csv\"\n[[measurement]]\nfile = \"./sub/../field.csv\"\n",
                    ),
                ),
                text("field.csv", &field),
                text("sub/keep.txt", "a folder"),
            ],
            &["run", "study.toml", "--out", "out", "-q"],
            &[
                "study.toml",
                "[[measurement]] 2 file (line 21)",
                "field.csv is already read by [[measurement]] 1 file (line 19)",
                "count its points twice",
            ],
        ),
        run_study(
            "study: measurement window spacing larger than the window",
            &study_measuring("[measurement]\nwindow = \"anterior\"\nspacing_mm = 500\n"),
            &[
                "study.toml",
                "[measurement] spacing_mm (line 20)",
                "larger than the 40 x 40 mm window",
            ],
        ),
        case(
            "study: measured field placed 1e300 mm away",
            vec![
                text(
                    "study.toml",
                    &study_measuring("[measurement]\nfile = \"field.csv\"\norigin_mm = [1e300, 0.0]\n"),
                ),
                text("field.csv", &field),
            ],
            &["run", "study.toml", "--out", "out", "-q"],
            &[
                "study.toml",
                "[measurement] origin_mm (line 20)",
                "beyond ±1e6 mm",
            ],
        ),
        run_study(
            "study: ultrasound frequency 0 in a virtual study",
            &format!("{STUDY}[ultrasound]\nfrequency_mhz = 0\n"),
            &[
                "study.toml",
                "[ultrasound] frequency_mhz (line 26)",
                "outside [1, 30]",
            ],
        ),
        run_study(
            "study: ultrasound frequency 0 in an ultrasound study",
            &format!(
                "{}[ultrasound]\nfrequency_mhz = 0\n",
                study_with("source = \"virtual\"", "source = \"ultrasound\"")
            ),
            &[
                "study.toml",
                "[ultrasound] frequency_mhz (line 26)",
                "outside [1, 30]",
            ],
        ),
        run_study(
            "study: probe of 0 px per mm",
            &format!("{STUDY}[probe]\npx_per_mm = 0\nwidth_mm = 40\n"),
            &["study.toml", "[probe] px_per_mm (line 26)", "outside (1, 40]"],
        ),
        run_study(
            "study: probe of negative width",
            &format!("{STUDY}[probe]\nwidth_mm = -5\n"),
            &["study.toml", "[probe] width_mm (line 26)", "outside (0, 200]"],
        ),
        solve_deck(
            "deck: binary garbage",
            "*HEADING\n\u{0}\u{1}",
            &["deck.inp:2", "not a text deck", "not UTF-8"],
        )
        .with_bytes("deck.inp", b"*HEADING\n\xff\xfe\x00\x01binary\n"),
        mesh_labels(
            "labels: two bodies",
            two_bodies(),
            &["--map", "1=fat,2=quadriceps", "--bone", "7"],
            &[
                "labels.png",
                "2 separate bodies of 1205.0, 1205.0 mm²",
                "crop the image",
            ],
        ),
        solve_deck(
            "deck: node label 0",
            &deck_with("1, 0.0, 0.0", "0, 0.0, 0.0"),
            &["deck.inp:4", "node label 0", "positive integers"],
        ),
        solve_deck(
            "deck: node label -5",
            &deck_with("1, 0.0, 0.0", "-5, 0.0, 0.0"),
            &["deck.inp:4", "node label -5", "positive integers"],
        ),
    ]
}

impl Case {
    /// The case with the bytes of its file `name` replaced (input that is not text).
    fn with_bytes(mut self, name: &'static str, bytes: &[u8]) -> Case {
        let f = self.files.iter_mut().find(|f| f.0 == name).unwrap();
        f.1 = bytes.to_vec();
        self
    }
}

fn catalogue() -> Vec<Case> {
    [
        deck_cases(),
        gmsh_cases(),
        study_cases(),
        csv_cases(),
        image_cases(),
        dicom_cases(),
        label_cases(),
        manifest_cases(),
        command_line_cases(),
        output_folder_cases(),
        whole_study_cases(),
    ]
    .into_iter()
    .flatten()
    .collect()
}

// ---------------------------------------------------------------------------------------------
// Running a case.

/// Every file and folder under `dir` but `skip`: its size and content (a hash).
fn snapshot(dir: &Path, skip: &Path) -> BTreeMap<PathBuf, (u64, u64)> {
    use std::hash::{Hash, Hasher};
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.starts_with(skip) {
                continue;
            }
            if p.is_dir() {
                out.insert(p.clone(), (0, 0));
                stack.push(p);
            } else {
                let bytes = std::fs::read(&p).unwrap_or_default();
                let mut h = std::collections::hash_map::DefaultHasher::new();
                bytes.hash(&mut h);
                out.insert(p, (bytes.len() as u64, h.finish()));
            }
        }
    }
    out
}

/// Runs `c` in its folder under `root`; `Err` says what is wrong.
fn run_case(root: &Path, k: usize, c: &Case) -> Result<(), String> {
    let dir = root.join(format!("case{k:03}"));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bytes) in &c.files {
        let p = dir.join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, bytes).unwrap();
    }
    // The folder the command may write: its --out (for `report`, nothing).
    let out = c
        .args
        .iter()
        .position(|a| a == "--out")
        .map(|i| dir.join(&c.args[i + 1]));
    let skip = match &out {
        // `--out .` may write nothing at all (the case expects a refusal): compare everything.
        Some(o) if o == &dir.join(".") => root.join("nothing-skipped"),
        Some(o) => o.clone(),
        None => root.join("nothing-skipped"),
    };
    let before = snapshot(&dir, &skip);
    let o = Command::new(env!("CARGO_BIN_EXE_femu"))
        .args(&c.args)
        .current_dir(&dir)
        .output()
        .expect("the femu binary runs");
    let err = String::from_utf8_lossy(&o.stderr);
    if std::env::var_os("FEMU_CATALOGUE_SHOW").is_some() {
        // The messages a user sees, to review them: FEMU_CATALOGUE_SHOW=1 cargo test ...
        eprintln!("{}:\n    {}", c.name, err.trim().replace('\n', "\n    "));
    }
    let mut problems = Vec::new();
    match o.status.code() {
        Some(0) => problems.push("exit 0".to_string()),
        Some(101) | None => problems.push(format!("exit {:?} (a panic or a signal)", o.status)),
        _ => {}
    }
    if err.contains("panicked") {
        problems.push("panicked".into());
    }
    for f in &c.expect {
        if !err.contains(f) {
            problems.push(format!("lacks '{f}'"));
        }
    }
    let after = snapshot(&dir, &skip);
    if before != after {
        let changed: Vec<String> = before
            .keys()
            .chain(after.keys())
            .filter(|p| before.get(*p) != after.get(*p))
            .map(|p| p.strip_prefix(&dir).unwrap_or(p).display().to_string())
            .collect();
        problems.push(format!("wrote outside --out: {changed:?}"));
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{}: {} (femu {}):\n    {}",
            c.name,
            problems.join("; "),
            c.args.join(" "),
            err.trim().replace('\n', "\n    ")
        ))
    }
}

#[test]
fn every_bad_input_gets_a_clear_error_and_writes_nothing_outside_out() {
    let cases = catalogue();
    assert!(cases.len() >= 60, "{} cases", cases.len());
    let root = scratch("catalogue");
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Vec::new());
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get().clamp(2, 4));
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(c) = cases.get(k) else { break };
                if let Err(e) = run_case(&root, k, c) {
                    failures.lock().unwrap().push(e);
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    eprintln!("{} cases, {} failed", cases.len(), failures.len());
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
    std::fs::remove_dir_all(&root).ok();
}
