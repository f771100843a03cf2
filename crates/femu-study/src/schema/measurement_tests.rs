//! `[[measurement]]` (joint identification), `[design]` and a deck's `*DLOAD` pressure: read,
//! defaulted, and every mistake named with its key and line.

use super::*;
use femu_mech::loading::{contention, Contention, Loading};

fn err(text: &str) -> String {
    format!("{}", parse(text, Path::new("/data")).unwrap_err())
}

/// One `[measurement]` (or none) is a joint study of one: the identification test on the
/// grid, the [noise]; the single table's keys keep working.
#[test]
fn a_single_measurement_is_a_joint_study_of_one() {
    let s = Study::default();
    assert_eq!(s.measurements.len(), 1);
    assert!(!s.measurement_list());
    let m = &s.measurements[0];
    assert_eq!(s.tests[m.test].loading.name(), "compression-anterior");
    assert_eq!(m.region, Region::Grid);
    assert_eq!(m.sigma_mm, SEED_SIGMA_MM);
    assert_eq!(m.source, MeasurementSource::Virtual);
    let s = parse(
        "[noise]\nsigma_mm = 0.02\n[measurement]\nsource = \"virtual\"\ntravel_sigma_mm = 0.01\n",
        Path::new("."),
    )
    .unwrap();
    assert_eq!(s.measurements[0].sigma_mm, 0.02);
    assert_eq!(s.measurement.travel.unwrap().sigma_mm, 0.01);
    assert_eq!(s.measurements[0].travel, s.measurement.travel);
    // A single table may name its window and test too.
    let s = parse(
        "[measurement]\ntest = \"contention\"\nwindow = \"lateral\"\nwindow_mm = [30, 20]\n",
        Path::new("."),
    )
    .unwrap();
    let Region::Window(w) = &s.measurements[0].region else {
        panic!("a window");
    };
    assert_eq!(
        (w.side.as_str(), w.width_mm, w.depth_mm),
        ("lateral", 30.0, 20.0)
    );
    // 16 px of the default probe (10 px/mm).
    assert_eq!(w.spacing_mm, 1.6);
}

#[test]
fn a_list_of_measurements_is_read_in_order() {
    let s = parse(
        "[probe]\npx_per_mm = 8\n[noise]\nsigma_mm = 0.02\n\
         [[measurement]]\ntest = \"contention\"\nwindow = \"anterior\"\n\
         [[measurement]]\ntest = \"compression\"\nwindow = \"lateral\"\nsigma_mm = 0.03\n\
         spacing_mm = 2.5\ntravel_sigma_mm = 0.01\n\
         [[measurement]]\ntest = \"compression\"\n",
        Path::new("."),
    )
    .unwrap();
    assert!(s.measurement_list());
    let names: Vec<&str> = s.measurements.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "contention_anterior",
            "compression-anterior_lateral",
            "compression-anterior_grid"
        ]
    );
    assert_eq!(s.measurements[0].sigma_mm, 0.02);
    assert_eq!(s.measurements[1].sigma_mm, 0.03);
    let Region::Window(w) = &s.measurements[0].region else {
        panic!("a window");
    };
    assert_eq!((w.width_mm, w.depth_mm, w.spacing_mm), (40.0, 40.0, 2.0));
    assert!(s.measurements[1].travel.is_some());
    assert_eq!(
        s.measurements[0].label(&s.tests),
        "contention, anterior 40 x 40 mm"
    );
    // The legacy view: [noise] and the first measurement's source.
    assert_eq!(s.measurement.sigma_mm, 0.02);
    assert_eq!(s.measurement.source, MeasurementSource::Virtual);
}

#[test]
fn mistakes_in_a_measurement_list_are_named_with_their_entry_and_line() {
    let e = err("[[measurement]]\ntest = \"contention\"\n[[measurement]]\ntest = \"stretch\"\n");
    assert!(
        e.contains("[[measurement]] 2 test (line 4)") && e.contains("no test 'stretch'"),
        "{e}"
    );
    let e = err("[[measurement]]\nwindow = \"up\"\n");
    assert!(e.contains("[[measurement]] 1 window (line 2)"), "{e}");
    let e = err("[[measurement]]\ntest = \"contention\"\n[[measurement]]\nwindw = \"lateral\"\n");
    assert!(
        e.contains("[[measurement]] 2 windw (line 4)") && e.contains("unknown field"),
        "{e}"
    );
    let e = err("[measurement]\nwindw = \"lateral\"\n");
    assert!(e.contains("[measurement] windw (line 2)"), "{e}");
    let e = err("[[measurement]]\nwindow = \"lateral\"\nwindow_mm = [0, 40]\n");
    assert!(
        e.contains("window_mm (line 3)") && e.contains("width"),
        "{e}"
    );
    let e = err("[[measurement]]\nspacing_mm = 2\n");
    assert!(
        e.contains("spacing_mm (line 2)") && e.contains("side"),
        "{e}"
    );
    let e = err("[[measurement]]\nfile = \"f.csv\"\nwindow = \"lateral\"\n");
    assert!(
        e.contains("window (line 3)") && e.contains("own points"),
        "{e}"
    );
    let e = err("[[measurement]]\nfile = \"f.csv\"\nsigma_mm = 0.01\n");
    assert!(
        e.contains("sigma_mm (line 3)") && e.contains("sx,sy"),
        "{e}"
    );
    let e = err("[[measurement]]\ntest = \"contention\"\ntravel_sigma_mm = 0.01\n");
    assert!(
        e.contains("travel_sigma_mm (line 3)") && e.contains("rigid body"),
        "{e}"
    );
    let e = err(
        "[[measurement]]\ntest = \"compression\"\ntravel_sigma_mm = 0.01\n\
         [[measurement]]\ntest = \"compression\"\nwindow = \"lateral\"\ntravel_sigma_mm = 0.02\n",
    );
    assert!(
        e.contains("[[measurement]] 2 travel_sigma_mm (line 7)") && e.contains("once per test"),
        "{e}"
    );
    assert!(err("measurement = []\n").contains("at least one"));
    let e = err("[[measurement]]\nsigma_mm = -1\n");
    assert!(e.contains("[[measurement]] 1 sigma_mm (line 2)"), "{e}");
}

#[test]
fn design_candidates_are_read_and_checked() {
    let s = Study::default();
    assert_eq!(s.design.tests, vec![0, 1, 2]);
    assert_eq!(s.design.sides.len(), 4);
    assert_eq!(s.design.max_measurements, 2);
    let s = parse(
        "[design]\ntests = [\"contention\", \"compression\"]\nsides = [\"lateral\", \"30\"]\nwindows_mm = [[50, 30]]\nmax_measurements = 3\n",
        Path::new("."),
    )
    .unwrap();
    assert_eq!(s.design.tests, vec![0, 1]);
    assert_eq!(s.design.windows_mm, vec![[50.0, 30.0]]);
    let e = err("[design]\nsides = [\"up\"]\n");
    assert!(e.contains("[design] sides (line 2)"), "{e}");
    let e = err("[design]\nmax_measurements = 9\n");
    assert!(e.contains("[design] max_measurements (line 2)"), "{e}");
    let e = err("[design]\ntests = [\"stretch\"]\n");
    assert!(e.contains("[design] tests (line 2)"), "{e}");
}

/// A deck at 0.004 MPa: its contention runs at 0.004 MPa (it ran at 20 mmHg without a word);
/// a study that sets 20 mmHg is stopped with both values; a deck whose pressure is zero only
/// marks the skin.
#[test]
fn a_decks_pressure_is_kept_or_the_conflict_named() {
    let dir = std::env::temp_dir().join(format!("femu-deck-loads-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let deck = |p: f64| {
        format!(
            "*NODE\n1, 0, 0\n2, 1, 0\n3, 1, 1\n4, 0, 1\n*ELEMENT, TYPE=CPE4, ELSET=FAT\n1, 1, 2, 3, 4\n\
             *MATERIAL, NAME=FAT\n*HYPERELASTIC, NEO HOOKE\n0.0008, 30.8\n*SOLID SECTION, ELSET=FAT, MATERIAL=FAT\n\
             *BOUNDARY\n1, 1, 2\n2, 1, 2\n*STEP, NLGEOM\n*STATIC\n0.1, 1.0\n*DLOAD\n1, P3, {p}\n*END STEP\n"
        )
    };
    std::fs::write(dir.join("d.inp"), deck(0.004)).unwrap();
    std::fs::write(dir.join("z.inp"), deck(0.0)).unwrap();
    let contention_of = |s: &Study| {
        s.tests
            .iter()
            .find(|t| t.loading.is(&contention::KIND))
            .unwrap()
            .loading
            .skin_pressure()
            .unwrap()
    };
    // The seed's tests, and a [[test]] without a pressure: the deck's.
    let s = parse("[model]\ndeck = \"d.inp\"\n", &dir).unwrap();
    assert_eq!(contention_of(&s), 0.004);
    let s = parse(
        "[model]\ndeck = \"d.inp\"\n[[test]]\nkind = \"contention\"\n",
        &dir,
    )
    .unwrap();
    assert_eq!(
        s.tests[0].loading,
        Loading::new(Contention { pressure: 0.004 })
    );
    // The same value given: accepted.
    let s = parse(
        "[model]\ndeck = \"d.inp\"\n[[test]]\nkind = \"contention\"\npressure_mpa = 0.004\n",
        &dir,
    )
    .unwrap();
    assert_eq!(contention_of(&s), 0.004);
    // Another value: both named, with the key's line.
    let e = format!(
        "{}",
        parse(
            "[model]\ndeck = \"d.inp\"\n[[test]]\nkind = \"contention\"\npressure_mmhg = 20\n",
            &dir
        )
        .unwrap_err()
    );
    assert!(
        e.contains("[[test]] 1 pressure_mmhg (line 5)")
            && e.contains("0.004 MPa")
            && e.contains("20.0000 mmHg")
            && e.contains("d.inp"),
        "{e}"
    );
    // A zero pressure marks the skin: the test keeps its 20 mmHg.
    let s = parse("[model]\ndeck = \"z.inp\"\n", &dir).unwrap();
    assert!((contention_of(&s) - 20.0 * femu_mesh::MMHG_IN_MPA).abs() < 1e-15);
    let e = err("[model]\ndeck = \"missing.inp\"\n");
    assert!(
        e.contains("[model] deck (line 2)") && e.contains("does not exist"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `[measurement] weighting`: estimated by default with a covariance, per point without; the
/// covariance alone only with one; a weighting that would leave a covariance unused, an unknown
/// one, or one on a measurement that is not a file: named errors.
#[test]
fn a_measured_files_weighting_is_read_and_checked() {
    let file = "[measurement]\nsource = \"file\"\nfile = \"f.csv\"\n";
    let weighting = |extra: &str| {
        let s = parse(&format!("{file}{extra}"), Path::new("/data")).unwrap();
        match &s.measurements[0].source {
            MeasurementSource::File { weighting, .. } => *weighting,
            other => panic!("a file, got {other:?}"),
        }
    };
    assert_eq!(weighting(""), Weighting::PerPoint);
    assert_eq!(weighting("covariance = \"c.mtx\"\n"), Weighting::Estimated);
    assert_eq!(
        weighting("covariance = \"c.mtx\"\nweighting = \"covariance\"\n"),
        Weighting::Covariance
    );
    assert_eq!(
        weighting("weighting = \"estimated\"\n"),
        Weighting::Estimated
    );
    let e = err(&format!("{file}weighting = \"covariance\"\n"));
    assert!(
        e.contains("weighting") && e.contains("needs covariance"),
        "{e}"
    );
    let e = err(&format!(
        "{file}covariance = \"c.mtx\"\nweighting = \"per-point\"\n"
    ));
    assert!(e.contains("weighting") && e.contains("unused"), "{e}");
    let e = err(&format!("{file}weighting = \"robust\"\n"));
    assert!(e.contains("unknown weighting 'robust'"), "{e}");
    let e = err("[measurement]\nweighting = \"estimated\"\n");
    assert!(e.contains("weighting") && e.contains("virtual"), "{e}");
}

/// `[measurement] speckle_*`: the frames' imaging read with its defaults (sound speed 1540 m/s,
/// the scale fitted), placed by the file's frame (depth along its +y from its origin); a
/// frequency without a resolution (or the other way round), a key on a measurement that is
/// not a file, a bad value or word: named errors.
#[test]
fn a_measured_files_speckle_shift_is_read_and_checked() {
    let file = "[measurement]\nsource = \"file\"\nfile = \"f.csv\"\norigin_mm = [-20.0, 60.0]\ny_axis = [0.0, -1.0]\n";
    let speckle = |extra: &str| {
        let s = parse(&format!("{file}{extra}"), Path::new("/data")).unwrap();
        match &s.measurements[0].source {
            MeasurementSource::File { speckle, frame, .. } => (*speckle, *frame),
            other => panic!("a file, got {other:?}"),
        }
    };
    assert_eq!(speckle("").0, None);
    let (s, frame) = speckle("speckle_frequency_mhz = 9\nspeckle_resolution_mm = 0.9\n");
    let s = s.unwrap();
    assert_eq!(
        (
            s.frequency_mhz,
            s.resolution_mm,
            s.sound_speed_m_s,
            s.fitted
        ),
        (9.0, 0.9, 1540.0, true)
    );
    let shift = s.in_frame(&frame);
    assert_eq!(shift.face, [-20.0, 60.0]);
    assert_eq!(shift.depth([-10.0, 52.5]), 7.5);
    assert_eq!(shift.scale, femu_identify::speckle::ShiftScale::Fitted);
    let (s, _) = speckle(
        "speckle_frequency_mhz = 9\nspeckle_resolution_mm = 0.9\nspeckle_sound_speed_m_s = 1500\nspeckle_shift = \"fixed\"\n",
    );
    let s = s.unwrap();
    assert_eq!((s.sound_speed_m_s, s.fitted), (1500.0, false));
    assert_eq!(
        s.in_frame(&Frame::model()).scale,
        femu_identify::speckle::ShiftScale::Fixed(1.0)
    );
    // A held scale of the user's (a calibration).
    let (s, _) = speckle(
        "speckle_frequency_mhz = 9\nspeckle_resolution_mm = 0.9\nspeckle_shift = \"fixed\"\nspeckle_scale = 0.66\n",
    );
    assert_eq!(
        s.unwrap().in_frame(&Frame::model()).scale,
        femu_identify::speckle::ShiftScale::Fixed(0.66)
    );
    for (extra, key, says) in [
        (
            "speckle_frequency_mhz = 9\n",
            "speckle_frequency_mhz",
            "needs speckle_resolution_mm",
        ),
        (
            "speckle_resolution_mm = 0.9\n",
            "speckle_resolution_mm",
            "needs speckle_frequency_mhz",
        ),
        (
            "speckle_shift = \"fixed\"\n",
            "speckle_shift",
            "needs speckle_frequency_mhz and speckle_resolution_mm",
        ),
        (
            "speckle_frequency_mhz = -9\nspeckle_resolution_mm = 0.9\n",
            "speckle_frequency_mhz",
            "positive",
        ),
        (
            "speckle_frequency_mhz = 9\nspeckle_resolution_mm = 0.9\nspeckle_shift = \"free\"\n",
            "speckle_shift",
            "fitted, fixed",
        ),
        (
            "speckle_frequency_mhz = 9\nspeckle_resolution_mm = 0.9\nspeckle_scale = 0.5\n",
            "speckle_scale",
            "speckle_shift = \"fixed\"",
        ),
        (
            "speckle_frequency_mhz = 9\nspeckle_resolution_mm = 0.9\nspeckle_shift = \"fixed\"\nspeckle_scale = -1\n",
            "speckle_scale",
            "at least 0",
        ),
    ] {
        let e = err(&format!("{file}{extra}"));
        assert!(e.contains(key) && e.contains(says), "{extra}: {e}");
    }
    let e = err("[measurement]\nsource = \"virtual\"\nspeckle_frequency_mhz = 9\n");
    assert!(
        e.contains("speckle_frequency_mhz") && e.contains("source = \"file\""),
        "{e}"
    );
}
