//! Recorded frames (`[measurement] source = "frames"`) against the simulated experiment
//! (`source = "ultrasound"`) on the same frames: `femu run` renders a compression sequence with
//! femu's simulator and identifies it (its measurement step writes the frames as
//! `frame_KK.png`); the same PNG files, with the probe's pose given exactly (`origin_mm`,
//! `x_axis`, `y_axis`, `pixel_size_mm` printed with every digit) and the loads of the steps, are
//! read as recorded frames by the frames' measurement step.
//!
//! - The inputs of the integrated DIC are the same to the bit: every frame's grey levels (8-bit
//!   PNG written and read), the image-to-model frame, the force of every step's model.
//! - The integrated DIC of the recorded frames, started where the ultrasound route starts it (the
//!   optima of its DIC → FEMU fits, read from their `summary.json`), gives the ultrasound route's
//!   parameters to the last printed digit (`parameters.csv`, `{:.9e}`): the routes share the
//!   engine, intervals included.
//! - What the recorded-frame route does not share: its own start. The simulator's DIC correlates
//!   over the tissue its renderer knows; recorded frames are correlated over the tissue the
//!   frames show (`femu_dic::sequence`, or a fixed-option chain when that fails), and the
//!   integrated DIC then starts from another point. The campaign on independent frames
//!   (`bench/independent_us/idic_campaign.py`) runs that route end to end.
//!
//! The study is small so that the test runs in well under a minute (622 elements, a 24 x 20 mm
//! window at 6 px/mm): too small a window to identify the fat well (the estimates are far from
//! Table 1); what is tested is the equality of the two routes, not their accuracy.
//!
//! The same frames written as one multi-frame DICOM (explicit VR little endian, Frame Time, a
//! Sequence of Ultrasound Regions with the pixel size and the region's bounds, annotations in a
//! border outside the region) with a force log in ms and mN/mm read at the frames' times on
//! another clock give the same frames, frame and loads.

use femu_identify::idic::ImageFrame;
use femu_study::progress::Quiet;
use femu_study::schema;
use femu_study::steps::parameters::IdentificationInputs;
use femu_study::steps::{frames, images};
use std::path::{Path, PathBuf};

const STUDY: &str = r#"
[model]
elements = 622
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[probe]
width_mm = 24.0
depth_mm = 20.0
px_per_mm = 6.0
[ultrasound]
render_refine = 1
seed = 3
[identification]
test = "compression"
grouped = true
starts = 2
[run]
forward = false
sensitivity = false
"#;

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("femu-frames-rt-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn fmt2(v: [f64; 2]) -> String {
    format!("[{:?}, {:?}]", v[0], v[1])
}

/// The frames study of the simulated run in `sim` (its frames, the probe's pose, the loads).
fn frames_study(sim: &Path, frame: &ImageFrame, fractions: &[f64]) -> String {
    let files: Vec<String> = (0..=fractions.len())
        .map(|k| format!("\"{}\"", sim.join(format!("frame_{k:02}.png")).display()))
        .collect();
    let loads: Vec<String> = fractions.iter().map(|f| format!("{:?}", 0.1 * f)).collect();
    let measurement = format!(
        "[measurement]\nsource = \"frames\"\nframes = [{}]\npixel_size_mm = {:?}\norigin_mm = {}\nx_axis = {}\ny_axis = {}\nloads_n_per_mm = [{}]\n",
        files.join(", "),
        frame.mm_per_px,
        fmt2(frame.origin_mm),
        fmt2(frame.x_axis),
        fmt2(frame.y_axis),
        loads.join(", ")
    );
    format!("{STUDY}{measurement}")
}

/// `parameters.csv`'s name and identified columns, as printed.
fn printed(path: &Path) -> Vec<(String, String)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (c[0].to_string(), c[2].to_string())
        })
        .collect()
}

#[test]
fn recorded_frames_give_the_simulated_experiments_inputs_and_parameters() {
    let t0 = std::time::Instant::now();
    let base = dir("run");
    // 1. The simulated experiment, identified by integrated DIC.
    let sim_study = base.join("ultrasound.toml");
    std::fs::write(
        &sim_study,
        format!("{STUDY}[measurement]\nsource = \"ultrasound\"\n"),
    )
    .unwrap();
    let us_out = base.join("ultrasound");
    femu_study::steps::run::run(&sim_study, &us_out, &Quiet).unwrap();
    let t_us = t0.elapsed().as_secs_f64();
    let sim = us_out.join("measurement");
    let us_seq = images::read_sequence(&sim).unwrap();

    // 2. Its frames as recorded frames, the pose given exactly.
    let frames_file = base.join("frames.toml");
    std::fs::write(
        &frames_file,
        frames_study(&sim, &us_seq.frame, &us_seq.load_fractions),
    )
    .unwrap();
    let study = schema::read_for_model(&frames_file).unwrap();
    let m = &study.measurements[0];
    let schema::MeasurementSource::Frames(spec) = &m.source else {
        panic!("not frames");
    };
    let built = femu_study::model::build(&study.model).unwrap();
    let measured = base.join("frames-measurement");
    let recorded = frames::measure(
        &study.tests[m.test],
        &study.probe,
        &built,
        spec,
        &measured,
        &Quiet,
    )
    .unwrap();
    assert!(
        recorded.record.dic.is_some() && recorded.measured.is_some(),
        "no DIC of the sequence: {:?}",
        recorded.record.notes
    );
    // The composed field's covariance, mapped to the model frame as the field is: its
    // diagonal is each point's sx², sy² (measured.csv, 7 digits), the frame's axes being the
    // model's here (up to sign).
    let cov = recorded
        .covariance
        .as_ref()
        .expect("the composed field's covariance (a small grid)");
    let (field, _) = recorded.measured.as_ref().unwrap();
    assert_eq!(cov.points, field.points.len());
    assert!(measured.join("measured_covariance.mtx").is_file());
    let m2 = 2 * cov.points;
    for (i, p) in field.points.iter().enumerate() {
        for c in 0..2 {
            if p.weight[c] > 0.0 {
                let var = cov.values[(2 * i + c) * m2 + 2 * i + c];
                let sd2 = 1.0 / p.weight[c];
                assert!(
                    (var - sd2).abs() <= 1e-5 * sd2,
                    "point {i}, component {c}: covariance {var:e} against sd² {sd2:e}"
                );
            }
        }
    }
    let fr_seq = recorded.sequence();
    // Without the pose keys the frames are placed by [probe] on the model's skin: the same
    // placement as the simulator's (its mesh is the model's here, render_refine = 1), to
    // rounding (the probe's px/mm is the reciprocal of the frames' pixel size).
    let mut by_probe = (**spec).clone();
    by_probe.placement = None;
    let (p, from) = frames::placement(
        &study.probe,
        &built,
        &by_probe,
        &by_probe.resolve().unwrap(),
    )
    .unwrap();
    assert!(from.starts_with("[probe]"), "{from}");
    let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()) < 1e-9;
    assert!(
        close(p.origin_mm, us_seq.frame.origin_mm)
            && close(p.x_axis, us_seq.frame.x_axis)
            && close(p.y_axis, us_seq.frame.y_axis)
            && (p.mm_per_px - us_seq.frame.mm_per_px).abs() < 1e-12,
        "{p:?} against {:?}",
        us_seq.frame
    );

    // The placement refined from the unloaded frame (`pose = "refined"`), started 1 mm along
    // the image's columns, 0.5 mm along its rows and 2° off: it comes back to the simulator's
    // pose within three of its own standard deviations (and 0.05 mm, the rendering's own
    // resolution) at the probe face's centre, and writes its fit and overlay.
    let truth = us_seq.frame;
    let turn = |v: [f64; 2], a: f64| {
        [
            v[0] * a.cos() - v[1] * a.sin(),
            v[0] * a.sin() + v[1] * a.cos(),
        ]
    };
    let a = 2f64.to_radians();
    let mut off = (**spec).clone();
    off.placement = Some(schema::frames::Placement {
        origin_mm: [
            truth.origin_mm[0] + truth.x_axis[0] + 0.5 * truth.y_axis[0],
            truth.origin_mm[1] + truth.x_axis[1] + 0.5 * truth.y_axis[1],
        ],
        x_axis: turn(truth.x_axis, a),
        y_axis: turn(truth.y_axis, a),
    });
    off.refine_pose = true;
    let posed = base.join("frames-pose");
    let refined = frames::measure(
        &study.tests[m.test],
        &study.probe,
        &built,
        &off,
        &posed,
        &Quiet,
    )
    .unwrap();
    let pose = refined.record.pose.as_ref().expect("the pose was refined");
    let r = refined.record.placement;
    let w = fr_seq.frames[0].width as f64;
    let face = |f: &ImageFrame| {
        let (x, y) = (0.5 * (w - 1.0) * f.mm_per_px, -0.5 * f.mm_per_px);
        [
            f.origin_mm[0] + x * f.x_axis[0] + y * f.y_axis[0],
            f.origin_mm[1] + x * f.x_axis[1] + y * f.y_axis[1],
        ]
    };
    let (fr, ft) = (face(&r), face(&truth));
    let d = [fr[0] - ft[0], fr[1] - ft[1]];
    let along = d[0] * truth.x_axis[0] + d[1] * truth.x_axis[1];
    let depth = d[0] * truth.y_axis[0] + d[1] * truth.y_axis[1];
    let angle = (truth.x_axis[0] * r.x_axis[1] - truth.x_axis[1] * r.x_axis[0])
        .asin()
        .to_degrees();
    eprintln!(
        "refined pose: error along {along:+.3} mm, depth {depth:+.3} mm, angle {angle:+.3}°; predicted sd {:.3} mm, {:.3} mm, {:.3}°; outlines {:?}",
        pose.sd[0], pose.sd[1], pose.sd[2], pose.found
    );
    for (name, err, sd) in [
        ("along", along, pose.sd[0]),
        ("depth", depth, pose.sd[1]),
        ("angle", angle, pose.sd[2]),
    ] {
        assert!(
            err.abs() <= 3.0 * sd + 0.05,
            "{name}: error {err}, predicted sd {sd}"
        );
    }
    assert!(posed.join("pose.json").is_file() && posed.join("pose_overlay.png").is_file());

    // The identification from the frames at the refined placement carries the placement's
    // uncertainty: a pose term (the sensitivity to each of the pose's three components, times
    // the refinement's covariance) in every seen parameter's interval, its own column of
    // parameters.csv; at a given placement none, and a note saying it is taken as exact.
    let inputs = IdentificationInputs::of(&study);
    let t_pose = std::time::Instant::now();
    let pose_id = frames::identify_frames(
        &inputs,
        m,
        true,
        &built,
        &refined,
        &base.join("frames-pose-idic"),
        &Quiet,
    )
    .unwrap();
    let term = pose_id.pose_term.as_ref().expect("a pose term");
    assert_eq!(term.steps.len(), 3, "{:?}", pose.covariance);
    for p in &pose_id.parameters {
        let Some(sd) = p.pose_sd else {
            panic!("{}: no pose sd", p.name);
        };
        eprintln!(
            "{}: identified {:.4e}, sd {:.4} (pose {:.4}, statistical {:.4})",
            p.name, p.identified, p.relative_sd, sd, p.sd_statistical
        );
        assert!(sd.is_finite() && sd >= 0.0, "{}: pose sd {sd}", p.name);
        assert!(p.relative_sd >= sd, "{}", p.name);
    }
    // The fat lies under the skin, the outline the placement is refined on: its shear
    // modulus moves with the placement (on this small window, whose skin and fascia pin the
    // placement only weakly along the skin, the pose term dominates its interval: measured
    // 0.63 in ln θ against a statistical 0.014).
    let fat = pose_id
        .parameters
        .iter()
        .find(|p| p.name == "C10_FAT")
        .expect("C10_FAT is free");
    assert!(
        fat.pose_sd.unwrap() > fat.sd_statistical,
        "C10_FAT: pose sd {:?}, statistical {}",
        fat.pose_sd,
        fat.sd_statistical
    );
    // DIC -> weighted FEMU beside the integrated DIC, for comparison (the report's column),
    // weighted by the composed field's covariance. (On this small window its 8 points in the
    // tissue determine none of the parameters well, by either DIC -> FEMU route: only that the
    // route ran on the same points is asserted here.)
    let summary = |d: &str| -> femu_study::steps::identify::IdentificationSummary {
        femu_study::output::read_json(&base.join("frames-pose-idic").join(d).join("summary.json"))
            .unwrap()
    };
    let (plain, weighted) = (summary("dic"), summary("dic-weighted"));
    assert_eq!(weighted.parameters.len(), pose_id.parameters.len());
    assert_eq!(weighted.points_in_tissue, plain.points_in_tissue);
    assert!(
        weighted.measured.ends_with("weighted by its covariance"),
        "{}",
        weighted.measured
    );
    let header = std::fs::read_to_string(base.join("frames-pose-idic/parameters.csv")).unwrap();
    assert!(header.lines().next().unwrap().contains(",pose_sd,"));
    eprintln!(
        "identification at the refined placement, with its pose term: {:.1} s (pose term {:.2} s)",
        t_pose.elapsed().as_secs_f64(),
        pose_id.pose_s
    );

    // The inputs, to the bit.
    assert_eq!(fr_seq.frames.len(), us_seq.frames.len());
    for (k, (a, b)) in fr_seq.frames.iter().zip(&us_seq.frames).enumerate() {
        assert_eq!((a.width, a.height), (b.width, b.height));
        assert!(a.data == b.data, "frame {k} differs");
    }
    assert_eq!(fr_seq.frame, us_seq.frame);
    let force = 0.1;
    for (a, b) in fr_seq.load_fractions.iter().zip(&us_seq.load_fractions) {
        assert_eq!(force * a, force * b, "the load of a step differs");
    }

    // The integrated DIC of the recorded frames from the ultrasound route's starts: its
    // parameters, to the last printed digit.
    let grouped = us_out.join("identify/grouped");
    let starts: Vec<Vec<f64>> = ["dic", "dic-weighted"]
        .iter()
        .map(|d| {
            let s: femu_study::steps::identify::IdentificationSummary =
                femu_study::output::read_json(&grouped.join(d).join("summary.json")).unwrap();
            s.parameters.iter().map(|p| p.identified).collect()
        })
        .collect();
    let mut once = study.identification.clone();
    once.starts = 0;
    let route = images::ImageRouteOptions::for_study(&study);
    let t1 = std::time::Instant::now();
    let fr = base.join("frames-idic");
    images::identify_images(
        &inputs.with(&once),
        true,
        &fr_seq,
        false,
        starts,
        &route,
        &fr,
        &Quiet,
    )
    .unwrap();
    let us_params = printed(&grouped.join("parameters.csv"));
    let fr_params = printed(&fr.join("parameters.csv"));
    for ((name, u), (_, f)) in us_params.iter().zip(&fr_params) {
        eprintln!("{name:<34} ultrasound {u}  frames {f}");
    }
    assert_eq!(us_params, fr_params);
    eprintln!(
        "ultrasound route (femu run) {t_us:.1} s, integrated DIC of the recorded frames {:.1} s",
        t1.elapsed().as_secs_f64()
    );

    // The same frames as one multi-frame DICOM and a force log.
    dicom_round_trip(&base, &us_seq, &frames_file);

    std::fs::remove_dir_all(&base).ok();
}

/// Border (px) of scanner annotations around the ultrasound region: left, top, right, bottom.
const BORDER: [usize; 4] = [7, 5, 3, 4];

/// Writes `frames` (8-bit grey) as a multi-frame DICOM, explicit VR little endian, one frame
/// every 100 ms, each inside a border of annotations outside its ultrasound region (whose
/// physical deltas give `mm_per_px`).
fn write_cine(path: &Path, frames: &[femu_dic::GreyImage], mm_per_px: f64) {
    use dicom_core::value::DataSetSequence;
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_dictionary_std::tags;
    use dicom_object::InMemDicomObject;
    let (w, h) = (frames[0].width, frames[0].height);
    let (cw, ch) = (w + BORDER[0] + BORDER[2], h + BORDER[1] + BORDER[3]);
    let mut pixels = Vec::with_capacity(cw * ch * frames.len());
    for (k, f) in frames.iter().enumerate() {
        for y in 0..ch {
            for x in 0..cw {
                let inside = (BORDER[0]..BORDER[0] + w).contains(&x)
                    && (BORDER[1]..BORDER[1] + h).contains(&y);
                pixels.push(if inside {
                    let v = f.data[(y - BORDER[1]) * w + x - BORDER[0]];
                    assert!(v == v.round() && (0.0..=255.0).contains(&v));
                    v as u8
                } else {
                    // Text and a scale that change from frame to frame.
                    ((x * 37 + y * 11 + 53 * k) % 7 * 40) as u8
                });
            }
        }
    }
    let us = |v: u16| PrimitiveValue::from(v);
    let ul = |v: usize| PrimitiveValue::from(v as u32);
    let region = InMemDicomObject::from_element_iter([
        DataElement::new(tags::REGION_SPATIAL_FORMAT, VR::US, us(1)),
        DataElement::new(tags::REGION_DATA_TYPE, VR::US, us(1)),
        DataElement::new(tags::REGION_LOCATION_MIN_X0, VR::UL, ul(BORDER[0])),
        DataElement::new(tags::REGION_LOCATION_MIN_Y0, VR::UL, ul(BORDER[1])),
        DataElement::new(tags::REGION_LOCATION_MAX_X1, VR::UL, ul(BORDER[0] + w - 1)),
        DataElement::new(tags::REGION_LOCATION_MAX_Y1, VR::UL, ul(BORDER[1] + h - 1)),
        DataElement::new(tags::PHYSICAL_UNITS_X_DIRECTION, VR::US, us(3)),
        DataElement::new(tags::PHYSICAL_UNITS_Y_DIRECTION, VR::US, us(3)),
        DataElement::new(
            tags::PHYSICAL_DELTA_X,
            VR::FD,
            PrimitiveValue::from(mm_per_px / 10.0),
        ),
        DataElement::new(
            tags::PHYSICAL_DELTA_Y,
            VR::FD,
            PrimitiveValue::from(mm_per_px / 10.0),
        ),
    ]);
    let obj = InMemDicomObject::from_element_iter([
        DataElement::new(tags::SOP_CLASS_UID, VR::UI, "1.2.840.10008.5.1.4.1.1.3.1"),
        DataElement::new(tags::SOP_INSTANCE_UID, VR::UI, "1.2.3.4.5.6.7"),
        DataElement::new(tags::SAMPLES_PER_PIXEL, VR::US, us(1)),
        DataElement::new(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2"),
        DataElement::new(
            tags::NUMBER_OF_FRAMES,
            VR::IS,
            PrimitiveValue::from(frames.len().to_string()),
        ),
        DataElement::new(tags::FRAME_TIME, VR::DS, PrimitiveValue::from("100")),
        DataElement::new(tags::ROWS, VR::US, us(ch as u16)),
        DataElement::new(tags::COLUMNS, VR::US, us(cw as u16)),
        DataElement::new(tags::BITS_ALLOCATED, VR::US, us(8)),
        DataElement::new(tags::BITS_STORED, VR::US, us(8)),
        DataElement::new(tags::HIGH_BIT, VR::US, us(7)),
        DataElement::new(tags::PIXEL_REPRESENTATION, VR::US, us(0)),
        DataElement::new(
            tags::SEQUENCE_OF_ULTRASOUND_REGIONS,
            VR::SQ,
            DataSetSequence::from(vec![region]),
        ),
        DataElement::new(tags::PIXEL_DATA, VR::OB, PrimitiveValue::from(pixels)),
    ]);
    obj.with_meta(dicom_object::FileMetaTableBuilder::new().transfer_syntax("1.2.840.10008.1.2.1"))
        .unwrap()
        .write_to_file(path)
        .unwrap();
}

/// The sequence `seq` as a cine (frames at 0, 0.1, ... s) and a force log in ms and mN/mm
/// (the loads at the frames' times, 0 before the first load, a ramp in between), read by a
/// study that chooses the frames by time: the same frames, frame and loads as `seq`.
fn dicom_round_trip(base: &Path, seq: &images::ImageSequence, png_study: &Path) {
    let cine = base.join("loop.dcm");
    write_cine(&cine, &seq.frames, seq.frame.mm_per_px);
    let n = seq.frames.len();
    let mut log = String::from("# units: ms, mN/mm\ntime_ms,force_mn_per_mm\n-50,0\n");
    let loads: Vec<f64> = std::iter::once(0.0)
        .chain(seq.load_fractions.iter().map(|f| 0.1 * f))
        .collect();
    for (k, l) in loads.iter().enumerate() {
        // The frames' times on the log's clock (offset 0.25 s), the force half-way between.
        log += &format!("{},{}\n", 100 * k + 250, 1000.0 * l);
        if k + 1 < n {
            log += &format!("{},{}\n", 100 * k + 300, 500.0 * (l + loads[k + 1]));
        }
    }
    std::fs::write(base.join("force.csv"), log).unwrap();
    let times: Vec<String> = (0..n).map(|k| format!("{:?}", 0.1 * k as f64)).collect();
    let text = std::fs::read_to_string(png_study).unwrap();
    let measurement = text.split("[measurement]").nth(1).unwrap();
    let pose: String = measurement
        .lines()
        .filter(|l| {
            l.starts_with("origin_mm") || l.starts_with("x_axis") || l.starts_with("y_axis")
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let study_text = |pixel: &str| {
        format!(
            "{STUDY}[measurement]\nsource = \"frames\"\ncine = \"loop.dcm\"\nframe_times_s = [{}]\nforce_log = \"force.csv\"\nforce_log_offset_s = 0.25\n{pose}{pixel}",
            times.join(", ")
        )
    };
    // The pixel size from the ultrasound region (cm in the file: equal to 1e-15).
    let path = base.join("cine.toml");
    std::fs::write(&path, study_text("")).unwrap();
    let study = schema::read_for_model(&path).unwrap();
    let schema::MeasurementSource::Frames(spec) = &study.measurements[0].source else {
        panic!("not frames");
    };
    let r = spec.resolve().unwrap();
    assert!(r.pixel_size_from.starts_with("SequenceOfUltrasoundRegions"));
    assert!((r.pixel_size_mm / seq.frame.mm_per_px - 1.0).abs() < 1e-15);
    // ... and exactly from the key.
    std::fs::write(
        &path,
        study_text(&format!("pixel_size_mm = {:?}\n", seq.frame.mm_per_px)),
    )
    .unwrap();
    let study = schema::read_for_model(&path).unwrap();
    let schema::MeasurementSource::Frames(spec) = &study.measurements[0].source else {
        panic!("not frames");
    };
    let r = spec.resolve().unwrap();
    assert_eq!(
        r.region.map(|g| g.size()),
        Some((seq.frames[0].width, seq.frames[0].height))
    );
    assert_eq!(r.times_s.as_deref().map(|t| t.len()), Some(n));
    for (a, b) in r.loads_n_per_mm.iter().zip(&loads[1..]) {
        assert!(
            (a - b).abs() <= 1e-15 * b,
            "force log at the frames: {a} for {b}"
        );
    }
    let frames = frames::read_frames(&r).unwrap();
    for (k, (a, b)) in frames.iter().zip(&seq.frames).enumerate() {
        assert!(a.data == b.data, "cine frame {k} differs from the PNG");
    }
    let built = femu_study::model::build(&study.model).unwrap();
    let (frame, _) = frames::placement(&study.probe, &built, spec, &r).unwrap();
    assert_eq!(frame, seq.frame);
}
