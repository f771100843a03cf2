//! The probe's pose refined from the unloaded frame, on frames with a known pose:
//!
//! 1. femu's own renderer: unloaded frames of the built-in thigh (rendered from the thigh at
//!    16 000 elements) at 9 and 11 MHz, one scatterer seed per realization;
//! 2. pymust's frames in `out/indep/seed_*/frame_0.png` (an independent simulator; the true
//!    placement in each `manifest.json`).
//!
//! Each start is the true pose moved by 1.5 mm along the skin, 1 mm in depth and 3° about
//! the probe face's centre, with the signs of the three cycling over the realizations; the
//! model outlines are those of the built-in thigh at 4 000 elements (a user's model). Prints
//! the recovered pose's error, the predicted sd and their spread over the realizations, and
//! writes an overlay figure of the first realization of each campaign.
//!
//! ```text
//! cargo run -p femu-ultrasound --profile test --example pose_check -- [--seeds N] [--out DIR] [--indep DIR]
//! ```
//!
//! Environment knobs for studies: `POSE_BONE` (the bone's weight), `POSE_SCALES` (the scales,
//! mm, comma-separated), `POSE_NOSUPPORT` (set: report every fit, found or not),
//! `POSE_RENDER_ELEMENTS` (the mesh femu's frames are rendered from, default 16 000).

use femu_dic::GreyImage;
use femu_geometry::parametric::{parametric_thigh, ThighParams};
use femu_mesh::ElementKind;
use femu_ultrasound::pose::{self, ImagePose, Outline, PoseOptions};
use femu_ultrasound::probe::probe_on_skin;
use femu_ultrasound::{render, Acoustics, Phantom, Scanner, Transducer};
use std::path::{Path, PathBuf};

/// The perturbation of the brief: along the skin (mm), depth (mm), tilt (degrees).
const OFF: [f64; 3] = [1.5, 1.0, 3.0];

struct Row {
    label: String,
    start: [f64; 3],
    error: [f64; 3],
    sd: [f64; 3],
    seconds: f64,
    found: String,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut seeds = 10usize;
    let mut out = PathBuf::from("/tmp/pose_check");
    let mut indep = PathBuf::from("out/indep");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seeds" => seeds = args.next().ok_or("--seeds N")?.parse()?,
            "--out" => out = args.next().ok_or("--out DIR")?.into(),
            "--indep" => indep = args.next().ok_or("--indep DIR")?.into(),
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    std::fs::create_dir_all(&out)?;
    let (outlines, _) = thigh_outlines(4000)?;
    let mut opts = PoseOptions::default();
    if let Ok(v) = std::env::var("POSE_BONE") {
        opts.bone_weight = v.parse()?;
    }
    if let Ok(v) = std::env::var("POSE_SCALES") {
        opts.scales_mm = v.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?;
    }
    if std::env::var("POSE_NOSUPPORT").is_ok() {
        opts.min_response = 0.0;
        opts.min_z = 0.0;
    }

    // 1. femu's renderer.
    let render_elements: usize = match std::env::var("POSE_RENDER_ELEMENTS") {
        Ok(v) => v.parse()?,
        Err(_) => 16000,
    };
    let (_, render_model) = thigh_outlines(render_elements)?;
    let (mesh, skin, bone) = render_model;
    let probe = probe_on_skin(&mesh, &skin, [0.0, 1.0], 40.0, 40.0, 10.0)?;
    let truth = ImagePose::from_probe(&probe);
    let mut rows = Vec::new();
    for f in [9.0, 11.0] {
        for seed in 1..=seeds as u64 {
            let ph = Phantom::generate(&mesh, &bone, &Acoustics::default(), &probe, 3.0, seed)?;
            let tx = Transducer {
                frequency_mhz: f,
                ..Default::default()
            };
            let frame = render(&ph, &ph.reference(), &probe, &tx, &Scanner::default(), seed)?;
            let label = format!("femu {f:>4} MHz seed {seed:>2}");
            let row = check(
                &label,
                &frame.image,
                &truth,
                &outlines,
                &opts,
                seed as usize - 1,
                (seed == 1 && f == 9.0).then(|| out.join("overlay_femu.png")),
            );
            match row {
                Ok(r) => rows.push(r),
                Err(e) => println!("{label}: FAILED: {e}"),
            }
        }
    }
    report(
        "femu's renderer (rendered at 16 000 elements, outlines at 4 000)",
        &rows,
    );

    // 2. pymust.
    let mut rows = Vec::new();
    for seed in 1..=seeds {
        let dir = indep.join(format!("seed_{seed:02}"));
        let manifest = dir.join("manifest.json");
        if !manifest.exists() {
            eprintln!("{}: missing, skipped", manifest.display());
            continue;
        }
        let m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&manifest)?)?;
        let meas = &m["measurement"];
        let v2 = |k: &str| -> [f64; 2] {
            [
                meas[k][0].as_f64().unwrap_or(f64::NAN),
                meas[k][1].as_f64().unwrap_or(f64::NAN),
            ]
        };
        let truth = ImagePose::new(
            v2("origin_mm"),
            v2("x_axis"),
            v2("y_axis"),
            meas["pixel_size_mm"].as_f64().unwrap_or(f64::NAN),
        )?;
        let image = GreyImage::open(&dir.join("frame_0.png"), 0)?;
        let label = format!("pymust seed {seed:>2}");
        let row = check(
            &label,
            &image,
            &truth,
            &outlines,
            &opts,
            seed - 1,
            (seed == 1).then(|| out.join("overlay_pymust.png")),
        );
        match row {
            Ok(r) => rows.push(r),
            Err(e) => println!("{label}: FAILED: {e}"),
        }
    }
    if !rows.is_empty() {
        report(
            "pymust (rendered at 16 000 elements, outlines at 4 000)",
            &rows,
        );
    }
    Ok(())
}

type RenderModel = (femu_mesh::Mesh, Vec<(usize, usize)>, Vec<(usize, usize)>);

/// The built-in thigh's outlines at about `elements` elements, and its mesh, skin and bone.
fn thigh_outlines(
    elements: usize,
) -> Result<(Vec<Outline>, RenderModel), Box<dyn std::error::Error>> {
    let t = parametric_thigh(
        &ThighParams {
            target_elements: Some(elements),
            ..Default::default()
        },
        ElementKind::Cpe4h,
    )?;
    let skin = t.mesh.surfaces["SKIN"].clone();
    let skin_set: std::collections::HashSet<_> = skin.iter().copied().collect();
    let bone: Vec<(usize, usize)> = t
        .mesh
        .mesh
        .boundary_faces()
        .into_iter()
        .filter(|f| !skin_set.contains(f))
        .collect();
    let outlines = pose::model_outlines(&t.mesh.mesh, &t.regions, &bone);
    Ok((outlines, (t.mesh.mesh, skin, bone)))
}

/// Refines from the truth moved by the signed perturbation number `k` (signs cycle over the
/// eight combinations) and returns the error of the refined pose.
fn check(
    label: &str,
    image: &GreyImage,
    truth: &ImagePose,
    outlines: &[Outline],
    opts: &PoseOptions,
    k: usize,
    overlay: Option<PathBuf>,
) -> Result<Row, Box<dyn std::error::Error>> {
    let pivot = pose::probe_face_pivot(image.width);
    let sign = |b: usize| if (k >> b) & 1 == 0 { 1.0 } else { -1.0 };
    let start = [
        sign(0) * OFF[0],
        sign(1) * OFF[1],
        sign(2) * OFF[2].to_radians(),
    ];
    let initial = truth.moved(pivot, start);
    let fit = pose::refine_pose(image, &initial, outlines, opts)?;
    let e = fit.pose.offset_from(truth, pivot);
    if let Some(path) = overlay {
        write_overlay(&path, image, &fit, outlines, truth)?;
        println!("overlay: {}", path.display());
    }
    Ok(Row {
        label: label.into(),
        start: [start[0], start[1], start[2].to_degrees()],
        error: [e[0], e[1], e[2].to_degrees()],
        sd: fit.sd,
        seconds: fit.seconds,
        found: format!("{:?} ", fit.iterations)
            + &fit
                .support
                .iter()
                .map(|s| {
                    format!(
                        "{}{}:{:.1}",
                        if s.found { "" } else { "!" },
                        short(&s.name),
                        s.response
                    )
                })
                .collect::<Vec<_>>()
                .join(" "),
    })
}

fn short(name: &str) -> String {
    name.replace("fascia ", "")
        .replace("QUADRICEPS", "Q")
        .replace("SARTORIUS", "S")
}

fn report(title: &str, rows: &[Row]) {
    println!("\n{title}");
    println!(
        "{:<24} {:>22} {:>26} {:>24} {:>6}  outlines (response)",
        "realization", "start (mm, mm, deg)", "error (mm, mm, deg)", "pred. sd (mm, mm, deg)", "s"
    );
    for r in rows {
        println!(
            "{:<24} {:>6.2} {:>6.2} {:>7.2}   {:>7.3} {:>7.3} {:>8.3}   {:>6.3} {:>6.3} {:>7.3}  {:>6.2}  {}",
            r.label, r.start[0], r.start[1], r.start[2], r.error[0], r.error[1], r.error[2],
            r.sd[0], r.sd[1], r.sd[2], r.seconds, r.found
        );
    }
    let n = rows.len() as f64;
    let mut line = String::new();
    for c in 0..3 {
        let e: Vec<f64> = rows.iter().map(|r| r.error[c]).collect();
        let mean = e.iter().sum::<f64>() / n;
        let sd = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
        let worst = e.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let rms_pred = (rows.iter().map(|r| r.sd[c].powi(2)).sum::<f64>() / n).sqrt();
        line += &format!(
            "  [{}] mean {:+.3} sd {:.3} worst |{:.3}| predicted sd {:.3}\n",
            ["t_x mm", "t_y mm", "theta deg"][c],
            mean,
            sd,
            worst,
            rms_pred
        );
    }
    let ok = rows
        .iter()
        .filter(|r| r.error[0].abs() <= 0.2 && r.error[1].abs() <= 0.2 && r.error[2].abs() <= 0.5)
        .count();
    print!("{line}");
    println!(
        "  within 0.2 mm and 0.5 deg: {ok} of {}; mean time {:.2} s",
        rows.len(),
        rows.iter().map(|r| r.seconds).sum::<f64>() / n
    );
}

fn write_overlay(
    path: &Path,
    image: &GreyImage,
    fit: &pose::PoseFit,
    outlines: &[Outline],
    truth: &ImagePose,
) -> Result<(), Box<dyn std::error::Error>> {
    let to_px = |p: &ImagePose| -> Vec<Vec<[[f64; 2]; 2]>> {
        outlines
            .iter()
            .map(|o| {
                o.segments
                    .iter()
                    .map(|s| [p.model_to_pixel(s[0]), p.model_to_pixel(s[1])])
                    .collect()
            })
            .collect()
    };
    let flat = |v: Vec<Vec<[[f64; 2]; 2]>>| v.into_iter().flatten().collect::<Vec<_>>();
    femu_plot::overlay::outline_overlay_png(
        path,
        &image.data,
        image.width,
        image.height,
        fit.pose.pixel_size_mm,
        &[
            femu_plot::overlay::OutlineSet {
                label: "initial pose".into(),
                segments_px: flat(to_px(&fit.initial)),
                color: (230, 60, 40),
                dashed: true,
            },
            femu_plot::overlay::OutlineSet {
                label: "true pose".into(),
                segments_px: flat(to_px(truth)),
                color: (60, 220, 60),
                dashed: true,
            },
            femu_plot::overlay::OutlineSet {
                label: "refined pose".into(),
                segments_px: flat(to_px(&fit.pose)),
                color: (40, 200, 255),
                dashed: false,
            },
        ],
        &femu_plot::overlay::OverlayOptions {
            title: "Model outlines on the unloaded frame".into(),
            ..Default::default()
        },
    )?;
    Ok(())
}
