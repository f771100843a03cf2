//! The simulated ultrasound experiment (`femu us-sim`, `femu us-scan`, and `[measurement]
//! source = "ultrasound"` of `femu run`): B-mode images of the thigh under the study's
//! `[probe]` and `[ultrasound]`, everything numerical in `femu-ultrasound`.

use crate::bail;
use crate::error::{Context, Result};
use crate::output::create_dir;
use crate::progress::Progress;
use crate::schema::{
    Geometry, ModelSpec, ProbeSection, Resolution, Study, DEFAULT_ELEMENTS, DEFAULT_LABEL_SIZE_MM,
};
use femu_dic::{Brightness, DicOptions};
use femu_identify::weighted::FieldCovariance;
use femu_mech::loading::{apply_loading, Side};
use femu_mech::{SolverOptions, StaticSolver};
use femu_ultrasound::manifest::fmt_num;
use femu_ultrasound::settings;
use femu_ultrasound::{experiment, probe, Acoustics, Phantom, Probe, Scanner, Transducer};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// The options of `femu us-sim` beyond the study.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// DIC element size (px).
    pub element: usize,
    /// DIC regularization length (px).
    pub regularization: Option<f64>,
    /// Spacing of the measured grid (px).
    pub grid_step: f64,
    /// DIC pyramid levels above the full image.
    pub levels: usize,
    /// Load steps imaged and correlated in succession (incremental DIC).
    pub steps: usize,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            element: 16,
            regularization: None,
            grid_step: 16.0,
            levels: 3,
            steps: 4,
        }
    }
}

/// The options of `femu us-scan` beyond the study.
#[derive(Debug, Clone)]
pub struct ScanOptions {
    pub frequencies: Vec<f64>,
    pub gains: Vec<f64>,
    pub dynamics: Vec<f64>,
    pub repeats: usize,
    pub correlation: f64,
    pub subjects: usize,
}

/// The probe of `[probe]` on the skin.
pub fn place_probe(
    mesh: &femu_mesh::Mesh,
    skin: &[(usize, usize)],
    section: &ProbeSection,
) -> Result<Probe> {
    let side = Side::parse(&section.side).map_err(|e| crate::input!("[probe] side: {e}"))?;
    Ok(probe::probe_on_skin(
        mesh,
        skin,
        side.direction(),
        section.width_mm,
        section.depth_mm,
        section.px_per_mm,
    )?)
}

/// Bone faces: the mesh outline minus the skin.
pub fn bone_faces(mesh: &femu_mesh::Mesh, skin: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let skin: std::collections::HashSet<_> = skin.iter().copied().collect();
    mesh.boundary_faces()
        .into_iter()
        .filter(|f| !skin.contains(f))
        .collect()
}

/// The model the images are rendered from: `spec` with its element size divided by `refine`
/// (`refine²` times the elements of the built-in thigh), so that the identification does not
/// fit the very mesh that made its data. A deck cannot be refined here: its own mesh is used,
/// with a note saying so.
pub fn render_model_spec(spec: &ModelSpec, refine: usize) -> (ModelSpec, Option<String>) {
    let r = refine.max(1);
    let resolution = match (&spec.geometry, spec.resolution) {
        (Geometry::Deck(_), _) => {
            let note = (r > 1).then(|| {
                format!(
                    "[ultrasound] render_refine = {r}: a deck's mesh cannot be refined here; the images are rendered from the deck's own mesh, the one identified (an inverse crime: errors will look smaller than on real images)"
                )
            });
            return (spec.clone(), note);
        }
        (_, Resolution::Elements(n)) => Resolution::Elements(n * r * r),
        (_, Resolution::SizeMm(h)) => Resolution::SizeMm(h / r as f64),
        (Geometry::Thigh(_), Resolution::Default) => Resolution::Elements(DEFAULT_ELEMENTS * r * r),
        (_, Resolution::Default) => Resolution::SizeMm(DEFAULT_LABEL_SIZE_MM / r as f64),
    };
    (
        ModelSpec {
            resolution,
            ..spec.clone()
        },
        None,
    )
}

/// `summary.json` of `femu us-sim`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SimSummary {
    pub command: String,
    pub version: String,
    pub test: String,
    pub elements: usize,
    pub probe: Probe,
    pub transducer: Transducer,
    pub psf: femu_ultrasound::Psf,
    pub scanner: Scanner,
    pub acoustics: Acoustics,
    pub scatterers: usize,
    pub image_px: (usize, usize),
    pub roi_pixels: usize,
    pub dic_steps: usize,
    pub dic_elements: usize,
    pub dic_converged: bool,
    pub dic_iterations: usize,
    pub dic_residual_rms: f64,
    pub error: experiment::FieldError,
    pub max_fe_displacement_mm: f64,
    pub timings_s: SimTimings,
    /// Elements of the mesh the images were rendered from (`[ultrasound] render_refine`
    /// times finer than `[model]`; absent in summaries written before it existed).
    #[serde(default)]
    pub render_elements: usize,
    #[serde(default = "one")]
    pub render_refine: usize,
    /// Fraction of the scatterers renewed per load step.
    #[serde(default)]
    pub decorrelation: f64,
    /// The image sequence: one file per state, the unloaded one first (`frame_00.png`, ...),
    /// and the load fraction of each loaded frame.
    #[serde(default)]
    pub frames: Vec<String>,
    #[serde(default)]
    pub load_fractions: Vec<f64>,
}

fn one() -> usize {
    1
}

/// Where the time of `femu us-sim` went (s).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct SimTimings {
    pub mesh_and_solve: f64,
    pub phantom: f64,
    pub render_reference: f64,
    pub render_deformed: f64,
    /// Every DIC increment.
    pub dic: f64,
    /// The measured field's covariance (`measured_covariance.mtx`).
    #[serde(default)]
    pub covariance: f64,
    pub total: f64,
}

/// `femu us-sim`: the virtual experiment with images of the study's identification test,
/// written into `out` (`ref.png`, `def.png`, `measured.csv`, `true_field.csv`, maps,
/// `summary.json`).
pub fn sim(
    study: &Study,
    args: &SimOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<SimSummary> {
    let t0 = Instant::now();
    let (probe_s, us) = (&study.probe, &study.ultrasound);
    create_dir(out)?;
    if args.steps == 0 || args.steps > 20 {
        bail!("--steps {} must be in [1, 20]", args.steps);
    }
    let test = study.identification_test().loading.clone();
    let (render_spec, render_note) = render_model_spec(&study.model, us.render_refine);
    if let Some(note) = &render_note {
        progress.warn(note);
    }
    let built = crate::model::build(&render_spec)?;
    // The loaded state and `steps - 1` intermediate loads (incremental DIC).
    let fractions: Vec<f64> = (1..=args.steps)
        .map(|k| k as f64 / args.steps as f64)
        .collect();
    let mut stages: Vec<Vec<f64>> = Vec::new();
    let mut model = None;
    let mut skin = Vec::new();
    for (k, &fraction) in fractions.iter().enumerate() {
        let (mut m, sk) = (built.model.clone(), built.skin.clone());
        let load = test.scaled(fraction);
        apply_loading(&mut m, &sk, &load).with_context(|| format!("test {}", test.name()))?;
        let mut solver = StaticSolver::new(&m, SolverOptions::default())?;
        let sol = solver
            .solve_with(&m, stages.last().map(|v| v.as_slice()), &mut |_| {})
            .map_err(|e| {
                crate::input!(
                    "test {} at {}/{} of the load: {e}",
                    test.name(),
                    k + 1,
                    args.steps
                )
            })?;
        stages.push(sol.u[..2 * m.node_count()].to_vec());
        skin = sk;
        model = Some(m);
    }
    let model = model.context("no load step")?;
    let u = stages.last().context("no load step")?;
    let umax = u.chunks(2).map(|c| c[0].hypot(c[1])).fold(0.0, f64::max);
    let mut timings = SimTimings {
        mesh_and_solve: t0.elapsed().as_secs_f64(),
        ..Default::default()
    };
    progress.note(&format!(
        "{}: images rendered from {} elements (render_refine {}) solved in {:.2} s, largest displacement {:.3} mm",
        test.name(),
        model.mesh.elements.len(),
        us.render_refine,
        timings.mesh_and_solve,
        umax
    ));
    let probe = place_probe(&model.mesh, &skin, probe_s)?;
    let t = Instant::now();
    let acoustics = Acoustics::default();
    let bone = bone_faces(&model.mesh, &skin);
    let phantom = Phantom::generate(&model.mesh, &bone, &acoustics, &probe, 3.0 + umax, us.seed)?;
    timings.phantom = t.elapsed().as_secs_f64();
    let opts = experiment::ExperimentOptions {
        transducer: us.transducer(),
        scanner: us.scanner(),
        dic: DicOptions {
            element_size: args.element,
            regularization_length: args.regularization,
            brightness: Brightness::Global,
            pyramid_levels: Some(args.levels),
            ..Default::default()
        },
        grid_step_px: args.grid_step,
        noise_seed: us.seed,
        decorrelation: us.decorrelation,
        ..Default::default()
    };
    let exp = experiment::run_incremental(&phantom, &stages, &probe, &opts)?;
    timings.render_reference = exp.reference.seconds;
    timings.render_deformed = exp.deformed.seconds;
    // Every increment's correlation (the first alone was reported before: 1/4 of the time).
    timings.dic = exp.increments.iter().map(|d| d.timings.total_s).sum();
    let save = |img: &femu_dic::GreyImage, name: &str| -> Result<()> {
        img.save_png(&out.join(name))
            .with_context(|| format!("cannot write {}", out.join(name).display()))
    };
    save(&exp.reference.image, "ref.png")?;
    save(&exp.deformed.image, "def.png")?;
    let frames: Vec<String> = (0..exp.frames.len())
        .map(|k| format!("frame_{k:02}.png"))
        .collect();
    for (img, name) in exp.frames.iter().zip(&frames) {
        save(img, name)?;
    }
    let comments = vec![
        format!(
            "femu us-sim {}: DIC of simulated B-mode images, {} test, {} MHz, gain {} dB, dynamic {} dB",
            env!("CARGO_PKG_VERSION"),
            test.name(),
            fmt_num(us.frequency_mhz),
            fmt_num(us.gain_db),
            fmt_num(us.dynamic_db)
        ),
        format!(
            "model frame (mm); probe centre {:?} mm, beam {:?}, {} px/mm",
            probe.centre_mm, probe.direction, probe.px_per_mm
        ),
    ];
    experiment::write_field_csv(&out.join("measured.csv"), &exp.points, false, &comments)?;
    experiment::write_field_csv(
        &out.join("true_field.csv"),
        &exp.points,
        true,
        &["FE displacement at the DIC grid points (mm, model frame)".into()],
    )?;
    // The composed field's covariance (weighted FEMU reads it beside measured.csv).
    let t = Instant::now();
    let all: Vec<usize> = (0..exp.points.len()).collect();
    let cov = FieldCovariance::new(all.len(), experiment::grid_covariance(&exp, &all, &probe)?)?;
    let cov_path = out.join("measured_covariance.mtx");
    cov.write_mtx(
        &cov_path,
        &[
            format!(
                "femu us-sim {}: covariance of measured.csv's components (ux, uy per point, in its order), mm^2, model frame",
                env!("CARGO_PKG_VERSION")
            ),
            "sum over the DIC increments of N A^-1 M_sigma A^-1 N^T at each point's position in that increment (femu_dic::quality)".into(),
        ],
    )
    .with_context(|| format!("cannot write {}", cov_path.display()))?;
    timings.covariance = t.elapsed().as_secs_f64();
    // Maps over the reference image.
    let maps = experiment::pixel_maps(&exp, &phantom, u, &probe, args.grid_step);
    let (w, h) = (exp.reference.width, exp.reference.height);
    let grey = &exp.reference.image.data;
    let err: [Vec<f64>; 2] = [0, 1].map(|c| {
        maps[c]
            .iter()
            .zip(&maps[c + 2])
            .map(|(d, t)| d - t)
            .collect()
    });
    let plots: [(&str, &str, &Vec<f64>, bool); 6] = [
        (
            "ux_true.png",
            "FE displacement ux (lateral)",
            &maps[2],
            true,
        ),
        (
            "uy_true.png",
            "FE displacement uy (depth, down)",
            &maps[3],
            true,
        ),
        (
            "ux_dic.png",
            "DIC displacement ux (lateral)",
            &maps[0],
            true,
        ),
        (
            "uy_dic.png",
            "DIC displacement uy (depth, down)",
            &maps[1],
            true,
        ),
        ("error_ux.png", "DIC - FE, ux", &err[0], true),
        ("error_uy.png", "DIC - FE, uy", &err[1], true),
    ];
    for (name, title, values, diverging) in plots {
        let p = out.join(name);
        femu_plot::image_field_png(
            &p,
            grey,
            w,
            h,
            values,
            &femu_plot::ImageField {
                title: format!("{title} over the reference image"),
                value_label: if name.starts_with("error") {
                    "DIC - FE (px)".into()
                } else {
                    "displacement (px)".into()
                },
                diverging,
                ..Default::default()
            },
        )
        .with_context(|| format!("cannot write {}", p.display()))?;
    }
    timings.total = t0.elapsed().as_secs_f64();
    let e = exp.error;
    let summary = SimSummary {
        command: "us-sim".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        test: test.name(),
        elements: model.mesh.elements.len(),
        probe,
        transducer: opts.transducer,
        psf: opts.transducer.psf(),
        scanner: opts.scanner,
        acoustics,
        scatterers: exp.phantom_scatterers,
        image_px: (w, h),
        roi_pixels: exp.roi.iter().filter(|&&b| b).count(),
        dic_steps: exp.steps,
        dic_elements: exp.dic.mesh.n_elements(),
        dic_converged: exp.dic.converged,
        dic_iterations: exp.dic.iterations,
        dic_residual_rms: exp.dic.residual_rms,
        error: e,
        max_fe_displacement_mm: umax,
        timings_s: timings,
        render_elements: model.mesh.elements.len(),
        render_refine: us.render_refine,
        decorrelation: us.decorrelation,
        frames,
        load_fractions: fractions,
    };
    settings::write_json(&out.join("summary.json"), &summary)?;
    progress.note(&format!(
            "images {w} x {h} px ({} scatterers) rendered in {:.2} + {:.2} s; DIC {} elements in {:.2} s; \
             error over {} points in tissue: RMS ({:.3}, {:.3}) px = ({:.4}, {:.4}) mm, max ({:.2}, {:.2}) px \
             for displacements up to {:.1} px -> {}",
            exp.phantom_scatterers,
            exp.reference.seconds,
            exp.deformed.seconds,
            exp.dic.mesh.n_elements(),
            exp.dic.timings.total_s,
            e.points,
            e.rms_px[0],
            e.rms_px[1],
            e.rms_mm[0],
            e.rms_mm[1],
            e.max_abs_px[0],
            e.max_abs_px[1],
            e.max_true_px,
            out.join("measured.csv").display()
        ));
    Ok(summary)
}

/// `femu us-scan`: images of the unloaded built-in thigh over a grid of settings, with the
/// manifest that `us-settings` and `us-noise` read.
pub fn scan(study: &Study, args: &ScanOptions, out: &Path, progress: &dyn Progress) -> Result<()> {
    let t0 = Instant::now();
    if args.repeats == 0 || args.subjects == 0 {
        bail!("--repeats and --subjects must be at least 1");
    }
    let n = args.frequencies.len()
        * args.gains.len()
        * args.dynamics.len()
        * args.repeats
        * args.subjects;
    if n > 2000 {
        bail!("{n} images requested: at most 2000");
    }
    let (probe_s, us) = (&study.probe, &study.ultrasound);
    create_dir(out)?;
    let built = crate::model::build(&study.model)?;
    let (model, skin) = (&built.model, &built.skin);
    let probe = place_probe(&model.mesh, skin, probe_s)?;
    let bone = bone_faces(&model.mesh, skin);
    let mut manifest = String::from("file,frequency_mhz,gain_db,dynamic_db,subject\n");
    for s in 0..args.subjects {
        let base = Phantom::generate(
            &model.mesh,
            &bone,
            &Acoustics::default(),
            &probe,
            3.0,
            us.seed.wrapping_add(1000 * s as u64),
        )?;
        let state = base.reference();
        // One phantom per acquisition, shared by every setting (the same frames re-displayed
        // with each setting would hide the setting's effect on the decorrelation; the seed
        // acquired each setting separately, so each setting gets its own frames).
        for &f in &args.frequencies {
            for &g in &args
                .dynamics
                .iter()
                .flat_map(|&d| args.gains.iter().map(move |&g| (g, d)))
                .collect::<Vec<_>>()
            {
                let (gain, dynamic) = g;
                let mut ph = base.clone();
                for r in 0..args.repeats {
                    if r > 0 {
                        ph = ph.decorrelated(
                            args.correlation,
                            us.seed
                                ^ (((s * 7919 + r) as u64) << 20)
                                ^ ((gain * 1e3) as u64)
                                ^ ((dynamic * 1e6) as u64),
                        )?;
                    }
                    let scanner = Scanner {
                        gain_db: gain,
                        dynamic_db: dynamic,
                        ..us.scanner()
                    };
                    let transducer = Transducer {
                        frequency_mhz: f,
                        ..us.transducer()
                    };
                    let frame = femu_ultrasound::render(
                        &ph,
                        &state,
                        &probe,
                        &transducer,
                        &scanner,
                        us.seed + (r as u64) * 31 + s as u64 * 7,
                    )?;
                    let name = format!(
                        "s{}_f{}_g{}_d{}_{:02}.png",
                        s + 1,
                        fmt_num(f),
                        fmt_num(gain),
                        fmt_num(dynamic),
                        r + 1
                    );
                    frame
                        .image
                        .save_png(&out.join(&name))
                        .with_context(|| format!("cannot write {}", out.join(&name).display()))?;
                    manifest += &format!(
                        "{name},{},{},{},s{}\n",
                        fmt_num(f),
                        fmt_num(gain),
                        fmt_num(dynamic),
                        s + 1
                    );
                }
            }
        }
    }
    let mp = out.join("manifest.csv");
    femu_mesh::atomic::write(&mp, manifest)
        .with_context(|| format!("cannot write {}", mp.display()))?;
    progress.note(&format!(
        "{n} images in {:.1} s -> {}",
        t0.elapsed().as_secs_f64(),
        mp.display()
    ));
    Ok(())
}
