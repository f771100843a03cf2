//! The schema's checks: defaults, every kind of mistake named with its key and line, the
//! views, the older layouts.

use super::*;
use femu_mech::loading::{Compression, Contention, Loading, Side};
use std::path::PathBuf;

fn err(text: &str) -> String {
    format!("{}", parse(text, Path::new("/data")).unwrap_err())
}

#[test]
fn defaults_are_the_seed() {
    let p = Study::default();
    assert_eq!(p.tests.len(), 3);
    assert_eq!(p.measurement.grid.counts, [64, 64]);
    assert_eq!(p.measurement.sigma_mm, SEED_SIGMA_MM);
    let pts = p.measurement.grid.points([-70.0, -60.0], [70.0, 60.0]);
    assert_eq!(pts.len(), 64 * 64);
    assert!((pts[0][0] + 70.0).abs() < 1e-12 && (pts[63][0] - 70.0).abs() < 1e-12);
    assert_eq!(p.groups, seed_groups());
    assert_eq!(p.identification.grouping, Grouping::Both);
}

#[test]
fn reads_keys_and_names_bad_ones() {
    let p = parse(
        "[model]\nelements = 800\nelement = \"cpe4\"\n[materials.fat]\nc10_kpa = 1.0\n\
         [[test]]\nkind = \"compression\"\nside = \"lateral\"\nforce_n_per_mm = 0.2\n\
         [noise]\nsigma_mm = 0.01\n[parameters]\ngroups = [[\"D_ISCHIO\", \"D_GRACILIS\"]]\n",
        Path::new("."),
    )
    .unwrap();
    assert_eq!(p.model.resolution, Resolution::Elements(800));
    assert_eq!(p.model.element, QuadElement::Cpe4);
    assert_eq!(p.model.materials.len(), 1);
    assert_eq!(p.model.materials[0].region, "fat");
    assert_eq!(
        p.model.materials[0].keys,
        vec![("c10_kpa".to_string(), 1.0)]
    );
    assert!(p.model.materials[0].law.is_none());
    assert_eq!(p.tests.len(), 1);
    assert_eq!(p.groups.len(), 1);
    let e = err("[model]\nelemnts = 3\n");
    assert!(e.contains("elemnts") && e.contains("line 2"), "{e}");
    assert!(err("[[test]]\nkind = \"stretch\"\n").contains("stretch"));
    assert!(err("[[test]]\nkind = \"compression\"\n").contains("force_n_per_mm"));
    assert!(err("[noise]\nsigma_mm = -1\n").contains("sigma_mm"));
    assert!(err("[materials.fat]\nc10_kpa = 1\nc10_mpa = 1\n").contains("given twice"));
    assert!(err("[[test]]\nkind = \"contention\"\nforce_n_per_mm = 1\n")
        .contains("not a key of a contention test"));
    let e = err("[materials.fat]\nc10_kpa = 0.8\nd = 30.8\n");
    assert!(
        e.contains("'d' is not a parameter key") && e.contains("line 3"),
        "{e}"
    );
    let e = err("[materials.fat]\nc10_kpa = \"soft\"\n");
    assert!(e.contains("must be a number"), "{e}");
    // The registry's laws and keys, named with their line.
    let e = err("[materials.fat]\nlaw = \"ogden\"\n");
    assert!(
        e.contains("[materials.fat] law (line 2)") && e.contains("mooney"),
        "{e}"
    );
    let e = err("[materials.fat]\nlaw = \"mooney-rivlin\"\nc10_kpa = 1\nd_per_mpa = 18\n");
    assert!(e.contains("C01") && e.contains("c01_kpa"), "{e}");
    let e = err("[materials.fat]\nc10_kpa = 1e300\n");
    assert!(
        e.contains("[materials.fat] c10_kpa (line 2)") && e.contains("out of range"),
        "{e}"
    );
    let e = err("[materials.fat]\nc01_kpa = 1\n");
    assert!(e.contains("[materials.fat] c01_kpa (line 2)"), "{e}");
    let mr = parse(
        "[materials.fat]\nlaw = \"mooney-rivlin\"\nc10_kpa = 0.5\nc01_kpa = 0.3\nd_per_mpa = 30\n",
        Path::new("."),
    )
    .unwrap();
    let m = mr.model.materials[0].build().unwrap();
    assert_eq!(m.spec().name, "mooney-rivlin");
    assert_eq!(m.parameters(), vec![0.5e-3, 0.3e-3, 30.0]);
}

/// The example of `femu init` is valid and spells out the defaults.
#[test]
fn the_example_study_is_the_default() {
    let e = parse(EXAMPLE_STUDY, Path::new(".")).unwrap();
    let d = Study::default();
    assert_eq!(e.model.geometry, d.model.geometry);
    assert_eq!(e.tests, d.tests);
    assert_eq!(e.measurement, d.measurement);
    assert_eq!(e.measurements, d.measurements);
    assert_eq!(e.identification, d.identification);
    assert_eq!(e.design, d.design);
    assert_eq!(e.steps, d.steps);
    assert_eq!(e.groups, seed_groups());
    assert_eq!(e.model.resolution, Resolution::Elements(6000));
    // Every Table 1 value restated.
    for m in &e.model.materials {
        let t = super::table1()
            .into_iter()
            .find(|t| t.name.eq_ignore_ascii_case(&m.region))
            .expect("a Table 1 region");
        assert!(*m.apply(&*t.law).unwrap() == *t.law, "{}", m.region);
    }
}

/// Each kind of mistake names the key and its line.
#[test]
fn mistakes_name_the_key_and_line() {
    // Out of range, with the line.
    let e = err("[noise]\n\nsigma_mm = -1\n");
    assert!(e.contains("[noise] sigma_mm (line 3)"), "{e}");
    let e = err(
        "[[test]]\nkind = \"contention\"\n[[test]]\nkind = \"compression\"\nforce_n_per_mm = 0\n",
    );
    assert!(e.contains("[[test]] 2 force_n_per_mm (line 5)"), "{e}");
    // Wrong unit: an unknown unit suffix is an unknown key.
    let e = err("[[test]]\nkind = \"contention\"\npressure_kpa = 2.6\n");
    assert!(e.contains("pressure_kpa") && e.contains("line 3"), "{e}");
    let e = err("[measurement]\nsource = \"file\"\nfile = \"f.csv\"\nunits = \"inch\"\n");
    assert!(e.contains("[measurement] units (line 4)"), "{e}");
    // Missing value.
    let e = err("[measurement]\nsource = \"file\"\nunits = \"px\"\n");
    assert!(e.contains("needs file"), "{e}");
    let e = err("[measurement]\nfile = \"f.csv\"\nunits = \"px\"\n");
    assert!(e.contains("needs pixel_size_mm"), "{e}");
    let e = err("[labels]\nimage = \"a.png\"\nbone = [7]\n");
    assert!(e.contains("map"), "{e}");
    // Geometry conflicts and dimensions.
    assert!(err("[model]\ndeck = \"a.inp\"\n[thigh]\n").contains("one geometry"));
    let e = err("[thigh]\nfat_thickness_mm = 100\n");
    assert!(e.contains("[thigh]") && e.contains("fat_thickness"), "{e}");
    let e = err("[identification]\ngrouped = \"maybe\"\n");
    assert!(e.contains("[identification] grouped (line 2)"), "{e}");
    let e = err("[identification]\noptimizer = \"nelder\"\n");
    assert!(e.contains("optimizer") && e.contains("lm, bfgs"), "{e}");
    let e = err("[model]\nelements = 5\n");
    assert!(e.contains("[model] elements (line 2)"), "{e}");
    // Issue 32.7: a thigh too coarse to keep its regions (100 elements gave no femur).
    let e = err("[model]\nelements = 300\n");
    assert!(
        e.contains("[model] elements (line 2)") && e.contains("at least 622"),
        "{e}"
    );
    let e = err("[model]\nsize_mm = 6\n");
    assert!(
        e.contains("[model] size_mm (line 2)") && e.contains("at most 4.50 mm"),
        "{e}"
    );
    let e = err("[thigh]\ngracilis_semi_axes_mm = [13, 4]\n[model]\nelements = 1000\n");
    assert!(e.contains("at least 3145"), "{e}");
    let e = err("[model]\nelements = 1500\n[identification]\ncoarse_elements = 400\n");
    assert!(
        e.contains("[identification] coarse_elements (line 4)") && e.contains("at least 622"),
        "{e}"
    );
    // Issue 28.4: an absurd grid is refused with its size and the limit, a huge one without
    // overflowing the product.
    let e = err("[grid]\ncounts = [100000, 100000]\n");
    assert!(
        e.contains("[grid] counts (line 2)")
            && e.contains("1.0e10 points")
            && e.contains("4000000"),
        "{e}"
    );
    let e = err("[grid]\ncounts = [9223372036854775807, 9223372036854775807]\n");
    assert!(e.contains("[grid] counts"), "{e}");
    // Issue 32.11: a side that is no angle (it used to pass).
    let e = err("[[test]]\nkind = \"compression\"\nside = \"1e300\"\nforce_n_per_mm = 0.1\n");
    assert!(
        e.contains("side (line 3)") && e.contains("not a side"),
        "{e}"
    );
    let e = load(None, Some(300)).unwrap_err().to_string();
    assert!(
        e.contains("--elements") && e.contains("at least 622"),
        "{e}"
    );
    // A multilevel identification whose coarse mesh is finer than the model's.
    let e = err("[model]\nelements = 1500\n[identification]\ncoarse_elements = 100000\n");
    assert!(
        e.contains("[identification] coarse_elements (line 4)") && e.contains("not coarser"),
        "{e}"
    );
    // An empty test list is not the default list.
    assert!(err("test = []\n").contains("at least one"));
    // Boundary tables.
    let e = err("[[fixed]]\ncurve = \"femur\"\ndofs = [3]\n");
    assert!(e.contains("[[fixed]] 1 dofs (line 3)"), "{e}");
    let e = err("[step]\ninitial_increment = 2\n");
    assert!(e.contains("[step] initial_increment (line 2)"), "{e}");
}

#[test]
fn measurement_frame_and_files_are_relative_to_the_study() {
    let p = parse(
        "[measurement]\nfile = \"dic/field.csv\"\nunits = \"px\"\npixel_size_mm = 0.1\n\
         origin_mm = [-20, 60]\ny_axis = [0, -1]\n[labels]\nimage = \"l.png\"\n\
         map = \"1=fat,2=quadriceps\"\nbone = [7]\n[model]\nsize_mm = 2.0\n",
        Path::new("/data/s"),
    )
    .unwrap();
    let MeasurementSource::File { path, frame } = &p.measurement.source else {
        panic!("a file measurement");
    };
    assert_eq!(path, &PathBuf::from("/data/s/dic/field.csv"));
    assert_eq!(frame.scale, 0.1);
    assert_eq!(frame.origin, [-20.0, 60.0]);
    assert_eq!(frame.y_axis, [0.0, -1.0]);
    let Geometry::Labels(l) = &p.model.geometry else {
        panic!("labels");
    };
    assert_eq!(l.image, PathBuf::from("/data/s/l.png"));
    assert_eq!(l.background, vec![0]);
}

/// The Gmsh study's older layout (top-level `element`, `[compression]`) reads as the schema's
/// `[model] element` and a `[[test]]` with its curve; its mistakes keep their line.
#[test]
fn the_gmsh_layout_is_a_view_of_the_schema() {
    let s = parse(
        "element = \"CPE4\"\n[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n[[fixed]]\ncurve = \"femur\"\n[[pressure]]\ncurve = \"skin\"\nmmhg = 20\n",
        Path::new("."),
    )
    .unwrap();
    assert_eq!(s.model.element, QuadElement::Cpe4);
    assert_eq!(s.model.materials[0].build().unwrap().parameter(0), 0.8e-3);
    assert!((s.boundary.pressures[0].pressure - 2.666e-3).abs() < 1e-6);
    assert_eq!(s.boundary.fixed[0].dofs, vec![0, 1]);
    let s = parse(
        "[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n[compression]\ncurve = \"skin\"\nside = \"medial\"\nforce_n_per_mm = 0.1\n",
        Path::new("."),
    )
    .unwrap();
    assert_eq!(s.tests.len(), 1);
    assert_eq!(s.tests[0].curve.as_deref(), Some("skin"));
    assert_eq!(
        s.tests[0].loading,
        Loading::new(Compression {
            side: Side::Medial,
            force: 0.1
        })
    );
    let e = err("[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n[indentation]\ncurve = \"skin\"\nside = \"up\"\nforce_n_per_mm = 0.1\nradius_mm = 5\n");
    assert!(e.contains("side (line 6)") && e.contains("'up'"), "{e}");
    let e = err("element = \"CPE8\"\n[materials.fat]\nc10_kpa = 0.8\nd_per_mpa = 30.8\n");
    assert!(
        e.contains("[model] element (line 1)") && e.contains("cpe8"),
        "{e}"
    );
}

/// The convergence study's older layout (top-level keys, `[contention]`) reads as
/// `[convergence]` and a `[[test]]`; its ranges are checked with their lines.
#[test]
fn the_convergence_layout_is_a_view_of_the_schema() {
    let s = parse(
        "elements = [\"CPE4\"]\ntarget_elements = [700, 1000, 2000]\nlocking = false\n[contention]\nmmhg = 10.0\n[materials.quadriceps]\nc10_kpa = 2.0\n",
        Path::new("."),
    )
    .unwrap();
    let c = s.convergence_study().unwrap();
    assert_eq!(c.elements, vec![femu_mesh::ElementKind::Cpe4]);
    assert!(!c.locking);
    assert_eq!(
        c.loading,
        Loading::new(Contention {
            pressure: 10.0 * femu_mesh::MMHG_IN_MPA
        })
    );
    let q = c.materials.iter().find(|m| m.name == "QUADRICEPS").unwrap();
    assert_eq!(q.law.parameter(0), 2e-3);
    let e = err("target_elements = [500, 1000]\n");
    assert!(
        e.contains("target_elements (line 1)") && e.contains("at least 3"),
        "{e}"
    );
    let e = err("[convergence]\nd_scale = 2.0\n");
    assert!(e.contains("[convergence] d_scale (line 2)"), "{e}");
    let e = err("[convergence]\n[grid]\ncounts = [8, 8]\n");
    assert!(e.contains("origin_mm and spacing_mm"), "{e}");
    let e = err("[convergence]\nelement_types = [\"CPE9\"]\n");
    assert!(e.contains("CPE9"), "{e}");
}

/// Issues 32.11 and 32.13: what needs the files and the model's regions is checked before
/// anything runs — files that do not exist, a region with no material, a `[materials]` table
/// with no region, unknown names in `fixed` and `groups` (even ungrouped) — and a label-map
/// region outside Table 1 takes the material its table gives.
#[test]
fn files_regions_and_parameter_names_are_checked_before_anything_runs() {
    let dir = std::env::temp_dir().join(format!("femu-schema-inputs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("l.png"), b"an image").unwrap();
    let check = |text: &str| {
        parse(text, &dir)
            .and_then(|s| s.check_model_inputs())
            .map_err(|e| e.to_string())
    };
    let labels = "[labels]\nimage = \"l.png\"\nmap = \"1=fat,6=adductor\"\nbone = [7]\n";
    let e = check(labels).unwrap_err();
    assert!(
        e.contains("[labels] map (line 3)") && e.contains("add a [materials.ADDUCTOR] table"),
        "{e}"
    );
    let e = check(&format!("{labels}[materials.ADDUCTOR]\nc10_kpa = 2.5\n")).unwrap_err();
    assert!(
        e.contains("[materials.ADDUCTOR]") && e.contains("d_per_mpa"),
        "{e}"
    );
    let full = format!("{labels}[materials.ADDUCTOR]\nc10_kpa = 2.5\nd_per_mpa = 20\n");
    check(&full).unwrap();
    check(&format!(
        "{full}[identification]\nfixed = [\"D_ADDUCTOR\"]\n"
    ))
    .unwrap();
    // The seed's grouping names regions this map lacks: only groups the study gives are checked.
    let e = check(&format!(
        "{full}[parameters]\ngroups = [[\"D_ADDUCTOR\", \"D_ISCHIO\"]]\n"
    ))
    .unwrap_err();
    assert!(
        e.contains("[parameters] groups (line 9)") && e.contains("'D_ISCHIO'"),
        "{e}"
    );
    let e = check("[materials.ADDUCTOR]\nc10_kpa = 2\nd_per_mpa = 18\n").unwrap_err();
    assert!(
        e.contains("no region ADDUCTOR in the built-in thigh"),
        "{e}"
    );
    let e = check("[identification]\ngrouped = false\n[parameters]\ngroups = [[\"D_NOPE\"]]\n")
        .unwrap_err();
    assert!(
        e.contains("[parameters] groups (line 4)") && e.contains("'D_NOPE'"),
        "{e}"
    );
    let e = check("[materials.QUADRICEPS]\nlaw = \"mooney-rivlin\"\nc10_kpa = 1\nc01_kpa = 0.5\nd_per_mpa = 18\n[identification]\nfixed = [\"C01_FAT\"]\n").unwrap_err();
    assert!(
        e.contains("'C01_FAT'") && e.contains("C01_QUADRICEPS"),
        "{e}"
    );
    // Files that do not exist, named with their key.
    for (text, at) in [
        (
            "[labels]\nimage = \"none.png\"\nmap = \"1=fat\"\nbone = [7]\n",
            "[labels] image (line 2)",
        ),
        ("[model]\ndeck = \"none.inp\"\n", "[model] deck (line 2)"),
        (
            "[measurement]\nfile = \"none.csv\"\n",
            "[measurement] file (line 2)",
        ),
    ] {
        let e = check(text).unwrap_err();
        assert!(e.contains(at) && e.contains("does not exist"), "{e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
