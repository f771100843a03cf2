//! Every numeric key of the study schema against the values users get wrong: the example study
//! (`femu init`'s [`EXAMPLE_STUDY`], with its commented-out keys written in) has each of its
//! numbers set in turn to 0, −1, NaN and 1e300, and the study loader
//! ([`femu_study::schema::read_for_model`], which writes nothing) must refuse it with an error
//! naming the key, unless the value is listed below as legitimate for that key, with the reason.
//! Whatever the loader accepts is what a command then runs with, so a key missing here would be
//! found only when (and if) a step uses it.

use femu_study::schema::{self, EXAMPLE_STUDY};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The values tried.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Bad {
    Zero,
    MinusOne,
    NaN,
    Huge,
}

const BAD: [Bad; 4] = [Bad::Zero, Bad::MinusOne, Bad::NaN, Bad::Huge];

/// Values a key legitimately takes among those tried, and why.
const ACCEPTED: &[(&str, &str, &[Bad], &str)] = &[
    (
        "thigh",
        "femur_center_mm",
        &[Bad::Zero, Bad::MinusOne],
        "an offset of the femur from the skin's centre: any small signed value",
    ),
    (
        "thigh",
        "lateral_septum_deg",
        &[Bad::Zero, Bad::MinusOne],
        "an angle: any value within a turn",
    ),
    (
        "thigh",
        "medial_septum_deg",
        &[Bad::Zero, Bad::MinusOne],
        "an angle: any value within a turn",
    ),
    (
        "thigh",
        "sartorius_angle_deg",
        &[Bad::Zero, Bad::MinusOne],
        "an angle: any value within a turn",
    ),
    (
        "thigh",
        "gracilis_angle_deg",
        &[Bad::Zero, Bad::MinusOne],
        "an angle: any value within a turn",
    ),
    (
        "grid",
        "origin_mm",
        &[Bad::Zero, Bad::MinusOne],
        "a position in the model frame: any finite value near the model",
    ),
    (
        "measurement",
        "origin_mm",
        &[Bad::Zero, Bad::MinusOne],
        "the model position of the file's (0, 0): any finite value near the model",
    ),
    (
        "measurement",
        "x_axis",
        &[Bad::Zero, Bad::MinusOne],
        "one component of a unit vector: 0 and -1 are components of the unit vectors (0, 1) \
         and (-1, 0) (the other component, a unit vector or not, is checked)",
    ),
    (
        "measurement",
        "y_axis",
        &[Bad::Zero, Bad::MinusOne],
        "one component of a unit vector, as x_axis",
    ),
    (
        "measurement",
        "travel_mm",
        &[Bad::Zero, Bad::MinusOne],
        "the measured travel of the plate: 0 (no motion measured) and a sign against the \
         expected one are data, which the fit weighs with travel_sigma_mm",
    ),
    (
        "measurement",
        "frame_times_s",
        &[Bad::Zero, Bad::MinusOne],
        "a time on the frames' clock: any finite value, the times increasing (whether the \
         force log covers them is checked, naming frame_times_s)",
    ),
    (
        "measurement",
        "force_log_offset_s",
        &[Bad::Zero, Bad::MinusOne],
        "the force log's clock minus the frames': any finite value (whether the log then \
         covers the frames is checked, naming force_log_offset_s)",
    ),
    (
        "identification",
        "image_normalization_px",
        &[Bad::Zero],
        "the frames' grey levels as recorded, not normalized",
    ),
    (
        "identification",
        "seed",
        &[Bad::Zero],
        "any unsigned integer seeds the generator",
    ),
    (
        "ultrasound",
        "seed",
        &[Bad::Zero],
        "any unsigned integer seeds the generator",
    ),
    (
        "ultrasound",
        "gain_db",
        &[Bad::Zero, Bad::MinusOne],
        "a gain in dB, within [-20, 100]",
    ),
    (
        "ultrasound",
        "black_level_db",
        &[Bad::Zero, Bad::MinusOne],
        "a level in dB, within [-100, 100]",
    ),
    (
        "ultrasound",
        "noise_db",
        &[Bad::Zero, Bad::MinusOne],
        "the electronic noise's level in dB, within [-200, 40]",
    ),
    (
        "ultrasound",
        "tgc_db_per_cm_mhz",
        &[Bad::Zero],
        "no time-gain compensation",
    ),
    (
        "ultrasound",
        "tgc_max_db",
        &[Bad::Zero],
        "no time-gain compensation",
    ),
    (
        "ultrasound",
        "decorrelation",
        &[Bad::Zero],
        "no scatterer renewed between load steps (the ideal in-plane motion)",
    ),
    (
        "labels",
        "slice",
        &[Bad::Zero],
        "the first axial slice of a volume",
    ),
    (
        "labels",
        "min_island_mm2",
        &[Bad::Zero],
        "no island merged into its neighbour",
    ),
    (
        "labels",
        "bone",
        &[Bad::Zero],
        "a label value: 0 may be the femur's label (when background is another)",
    ),
    (
        "labels",
        "background",
        &[Bad::Zero],
        "a label value: 0 is the usual background",
    ),
];

/// The keys the example leaves commented out, with their example values, in tables that the
/// example study can hold together.
const COMMENTED_OUT: &str = r#"
[grid]
origin_mm = [-70.0, -60.0]
spacing_mm = 2.2
[identification]
coarse_elements = 2000
[design]
spacing_mm = 1.6
[probe]
width_mm = 40.0
depth_mm = 40.0
px_per_mm = 10.0
[ultrasound]
frequency_mhz = 9.0
cycles = 2.0
f_number = 3.0
gain_db = 34.0
dynamic_db = 42.0
black_level_db = 15.0
tgc_db_per_cm_mhz = 0.6
tgc_max_db = 45.0
noise_db = -65.0
seed = 1
render_refine = 2
decorrelation = 0.05
"#;

/// A convergence study (its meshes replace `[model]`'s).
const CONVERGENCE: &str = r#"
[convergence]
target_elements = [1500, 3000, 6000]
tolerance_mm = 1e-4
d_scale = 1e-3
locking_meshes = 2
raster_mm = 0.13
"#;

/// A measurement through a probe window (its own keys).
const WINDOW: &str = r#"
[measurement]
source = "virtual"
test = "compression"
window = "anterior"
window_mm = [40.0, 40.0]
spacing_mm = 1.6
sigma_mm = 0.0176
travel_sigma_mm = 0.01
"#;

/// A measured field in pixels (its frame and actuator term).
const FILE: &str = r#"
[measurement]
source = "file"
file = "field.csv"
units = "px"
pixel_size_mm = 0.0117
origin_mm = [-20.0, 60.0]
x_axis = [1.0, 0.0]
y_axis = [0.0, -1.0]
travel_mm = 6.99
travel_sigma_mm = 0.01
"#;

/// Recorded frames (PNG files) with their times and a force log, placed by the frame keys.
const FRAMES: &str = r#"
[measurement]
source = "frames"
frames = ["f0.png", "f1.png", "f2.png"]
units = "px"
pixel_size_mm = 0.1
origin_mm = [-20.0, 60.0]
x_axis = [1.0, 0.0]
y_axis = [0.0, -1.0]
frame_times_s = [0.5, 1.0, 2.0]
force_log = "force.csv"
force_log_offset_s = 0.25
"#;

/// Recorded frames with a load per loaded frame.
const FRAME_LOADS: &str = r#"
[measurement]
source = "frames"
frames = ["f0.png", "f1.png", "f2.png"]
pixel_size_mm = 0.1
loads_n_per_mm = [0.05, 0.1]
"#;

/// A segmented image instead of the built-in thigh.
const LABELS: &str = r#"
[labels]
image = "labels.png"
map = "1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=ischio"
bone = [7]
background = [0]
pixel_size_mm = 0.7422
slice = 0
min_island_mm2 = 5.0
"#;

/// `over` merged into `base`, table by table (its keys replace the base's).
fn merged(mut base: Table, over: &str) -> Table {
    let over: Table = over.parse().unwrap();
    for (name, value) in over {
        match (base.get_mut(&name), value) {
            (Some(Value::Table(b)), Value::Table(o)) => b.extend(o),
            (_, value) => {
                base.insert(name, value);
            }
        }
    }
    base
}

/// The studies whose numbers are tried: the example with its commented-out keys, with a probe
/// window, with a measured field, and on a label image.
fn variants() -> Vec<(&'static str, Table)> {
    let example: Table = EXAMPLE_STUDY.parse().unwrap();
    let full = merged(example.clone(), COMMENTED_OUT);
    let mut labels = merged(example.clone(), LABELS);
    labels.remove("thigh");
    labels.insert(
        "model".into(),
        Value::Table("size_mm = 1.0".parse().unwrap()),
    );
    let mut no_mesh = example.clone();
    no_mesh["model"].as_table_mut().unwrap().remove("elements");
    // Its comparison points: the seed's window, or a [grid] with origin and spacing.
    no_mesh.remove("grid");
    let by_size = merged(
        no_mesh.clone(),
        "[convergence]\nelement_size_mm = [4.0, 2.0, 1.0]\n",
    );
    vec![
        ("example", full),
        ("window", merged(example.clone(), WINDOW)),
        ("file", merged(example.clone(), FILE)),
        ("frames", merged(example.clone(), FRAMES)),
        ("frame loads", merged(example, FRAME_LOADS)),
        ("labels", labels),
        ("convergence", merged(no_mesh, CONVERGENCE)),
        ("convergence sizes", by_size),
    ]
}

/// A step from a table to one of its numbers: a key or an array index.
#[derive(Debug, Clone)]
enum Step {
    Key(String),
    Index(usize),
}

/// The paths of every number under `v`.
fn numbers(v: &Value, path: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    match v {
        Value::Integer(_) | Value::Float(_) => out.push(path.clone()),
        Value::Array(items) => {
            for (k, item) in items.iter().enumerate() {
                path.push(Step::Index(k));
                numbers(item, path, out);
                path.pop();
            }
        }
        Value::Table(t) => {
            for (key, item) in t {
                path.push(Step::Key(key.clone()));
                numbers(item, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

fn at<'a>(v: &'a mut Value, path: &[Step]) -> &'a mut Value {
    path.iter().fold(v, |v, s| match s {
        Step::Key(k) => v.as_table_mut().unwrap().get_mut(k).unwrap(),
        Step::Index(i) => &mut v.as_array_mut().unwrap()[*i],
    })
}

/// The table (`materials.FAT`, `test`) and key of a number's path.
fn table_and_key(path: &[Step]) -> (String, String) {
    let keys: Vec<&str> = path
        .iter()
        .filter_map(|s| match s {
            Step::Key(k) => Some(k.as_str()),
            Step::Index(_) => None,
        })
        .collect();
    let (key, tables) = keys.split_last().unwrap();
    (tables.join("."), key.to_string())
}

fn bad_value(old: &Value, bad: Bad) -> Value {
    match (old, bad) {
        (Value::Integer(_), Bad::Zero) => Value::Integer(0),
        (Value::Integer(_), Bad::MinusOne) => Value::Integer(-1),
        (_, Bad::Zero) => Value::Float(0.0),
        (_, Bad::MinusOne) => Value::Float(-1.0),
        (_, Bad::NaN) => Value::Float(f64::NAN),
        (_, Bad::Huge) => Value::Float(1e300),
    }
}

/// A folder with the files the variants name: a measured field and a label image.
fn folder() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("femu-numeric-keys-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut csv = String::from("x,y,ux,uy\n");
    for i in 0..10 {
        for j in 0..10 {
            csv.push_str(&format!("{},{},0.5,-0.25\n", 40 * i, 40 * j));
        }
    }
    std::fs::write(dir.join("field.csv"), csv).unwrap();
    // Recorded frames and their force log (the frames at 0.75 to 2.25 s on its clock).
    for k in 0..3 {
        let data = (0..48 * 32)
            .map(|i| ((i * 37 + 11 * k) % 251) as f64)
            .collect();
        femu_dic::GreyImage::new(48, 32, data)
            .unwrap()
            .save_png(&dir.join(format!("f{k}.png")))
            .unwrap();
    }
    std::fs::write(
        dir.join("force.csv"),
        "# units: s, N/mm\ntime,force\n0,0\n1,0.04\n3,0.12\n",
    )
    .unwrap();
    let (w, h) = (40usize, 40usize);
    let data = (0..w * h)
        .map(|k| {
            let (i, j) = ((k % w) as f64 - 20.0, (k / w) as f64 - 20.0);
            let r = i.hypot(j);
            if r < 4.0 {
                7.0
            } else if r < 14.0 {
                2.0
            } else if r < 18.0 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    femu_dic::GreyImage::new(w, h, data)
        .unwrap()
        .save_png(&dir.join("labels.png"))
        .unwrap();
    dir
}

/// Loads `study` as every command does, from a file in `dir`.
fn load(dir: &Path, name: &str, study: &Table) -> Result<schema::Study, String> {
    let path = dir.join(name);
    std::fs::write(&path, toml::to_string(study).unwrap()).unwrap();
    schema::read_for_model(&path).map_err(|e| e.to_string())
}

#[test]
fn every_numeric_key_refuses_zero_negative_nan_and_huge_values_or_says_why_not() {
    let dir = folder();
    let mut unchecked = Vec::new();
    let mut unnamed = Vec::new();
    let mut tried = 0;
    for (variant, study) in variants() {
        // The variant itself is a valid study.
        if let Err(e) = load(&dir, "study.toml", &study) {
            panic!("the {variant} variant is refused: {e}");
        }
        let root = Value::Table(study);
        let mut paths = Vec::new();
        numbers(&root, &mut Vec::new(), &mut paths);
        for path in paths {
            let (table, key) = table_and_key(&path);
            for bad in BAD {
                let mut changed = root.clone();
                let leaf = at(&mut changed, &path);
                *leaf = bad_value(leaf, bad);
                let Value::Table(changed) = changed else {
                    unreachable!()
                };
                tried += 1;
                let accepted = ACCEPTED
                    .iter()
                    .any(|(t, k, values, _)| *t == table && *k == key && values.contains(&bad));
                match load(&dir, "study.toml", &changed) {
                    Ok(_) if accepted => {}
                    Ok(_) => {
                        unchecked.push(format!("{variant}: [{table}] {key} {path:?} = {bad:?}"))
                    }
                    Err(e) if !e.contains(&key) => unnamed.push(format!(
                        "{variant}: [{table}] {key} {path:?} = {bad:?}: {e}"
                    )),
                    Err(_) => {}
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    eprintln!("{tried} values tried");
    assert!(tried > 400, "only {tried} values tried");
    assert!(
        unchecked.is_empty() && unnamed.is_empty(),
        "accepted without a reason:\n{}\nrefused without naming the key:\n{}",
        unchecked.join("\n"),
        unnamed.join("\n")
    );
}
